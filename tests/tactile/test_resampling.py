"""Each seed of a protocol run reads its own bootstrap resample of the data."""

from __future__ import annotations

import pytest
import torch

from event_transforms.tactile.resampling import (
    bootstrap_indices,
    check_resample,
    item_groups,
    resample_batches,
    split_resample,
)


class TestBootstrapIndices:
    def test_deterministic_in_range_and_a_stream_per_seed_and_split(self):
        a = bootstrap_indices(48, 3, "train")
        assert a.dtype == torch.int64 and a.shape == (48,) and int(a.min()) >= 0 and int(a.max()) < 48
        assert torch.equal(a, bootstrap_indices(48, 3, "train"))
        assert not torch.equal(a, bootstrap_indices(48, 4, "train"))
        assert not torch.equal(a, bootstrap_indices(48, 3, "test"))
        # with replacement: about 1 - 1/e of the items are drawn at least once
        draws = torch.cat([bootstrap_indices(96, s, "test") for s in range(20)])
        share = sum(len(bootstrap_indices(96, s, "test").unique()) for s in range(20)) / (20 * 96)
        assert 0.58 < share < 0.69 and torch.bincount(draws, minlength=96).min() > 0

    def test_one_item(self):
        assert bootstrap_indices(1, 0, "val").tolist() == [0]

    def test_groups_are_drawn_whole(self):
        groups = ["r0"] * 4 + ["r1"] * 3 + ["r2"] * 5
        for seed in range(10):
            picked = bootstrap_indices(12, seed, "test", groups).tolist()
            assert len(picked) == 12
            # the items come in runs of whole recordings (in order), the last one possibly cut short
            runs, k = [], 0
            while k < len(picked):
                label = groups[picked[k]]
                run = [i for i, g in enumerate(groups) if g == label]
                assert picked[k:k + len(run)] == run[:len(picked) - k]
                runs.append(label)
                k += len(run)
            assert len(runs) >= 3

    def test_bad_input_is_named(self):
        with pytest.raises(ValueError, match="n must be a positive int.*0"):
            bootstrap_indices(0, 0, "train")
        with pytest.raises(ValueError, match="n must be a positive int.*True"):
            bootstrap_indices(True, 0, "train")
        with pytest.raises(ValueError, match="split must be one of.*holdout"):
            bootstrap_indices(4, 0, "holdout")
        with pytest.raises(ValueError, match="groups must hold one label per item \\(4\\), got 3"):
            bootstrap_indices(4, 0, "test", ["a", "b", "c"])
        with pytest.raises(ValueError, match="resample must be one of"):
            check_resample("Bootstrap")


class TestResampleBatches:
    def test_copies_follow_their_original(self):
        items, indices = 5, bootstrap_indices(5, 1, "train")
        batches = torch.arange(15).view(3, 5)  # originals, first copies, second copies
        out = resample_batches(batches, items, indices)
        assert torch.equal(out % items, indices.expand(3, 5)) and torch.equal(out // items, batches // items)

    def test_wrong_indices_are_refused(self):
        with pytest.raises(ValueError, match="one index per item \\(4\\)"):
            resample_batches(torch.zeros(2, 2, dtype=torch.int64), 4, torch.zeros(3, dtype=torch.int64))


class TestGroups:
    class Folder:
        def __init__(self, labels):
            self.labels = labels

        def __len__(self):
            return len(self.labels)

        def meta(self, index):
            return {"recording": self.labels[index], "row": index}

    def test_a_folder_is_resampled_by_recording_and_simulated_grasps_one_by_one(self):
        folder = self.Folder(["a.npy", "a.npy", "b.npy", "b.npy"])
        assert item_groups(folder) == ["a.npy", "a.npy", "b.npy", "b.npy"]
        assert torch.equal(split_resample(folder, 2, "test"), bootstrap_indices(4, 2, "test", folder.labels))
        assert item_groups([1, 2, 3]) is None  # a plain list of items has no recordings
        assert item_groups(self.Folder(["a.npy", None])) is None
        assert torch.equal(split_resample([1, 2, 3], 2, "val"), bootstrap_indices(3, 2, "val"))


def test_resampled_baselines_average_the_seeds_resamples():
    from event_transforms.tactile.baselines import evaluate_baselines, stack_items
    from event_transforms.tactile.copies import SceneData
    from event_transforms.tactile.protocol.statistics import _baselines
    from event_transforms.tactile.benchmark_scenes import get_scene

    g = torch.Generator().manual_seed(0)

    def items(n):
        frames = torch.poisson(torch.full((n, 6, 2, 4, 4), 0.8), generator=g)
        return [(f, f.sum((1, 2, 3)) / 5 + torch.rand(6, generator=g), {"diameter_mm": 15.0}) for f in frames]

    data = SceneData(get_scene("paper"), items(12), items(8), items(10), holdout=items(4))
    fixed = _baselines(data)
    boot = _baselines(data, [0, 1, 2], "bootstrap")
    assert set(fixed) == set(boot)
    train, val, test = (stack_items(d) for d in (data.train, data.val, data.test))
    expected = []
    for seed in (0, 1, 2):
        pick = {s: bootstrap_indices(n, seed, s) for s, n in (("train", 12), ("val", 8), ("test", 10))}
        scores = evaluate_baselines((train[0][pick["train"]], train[1][pick["train"]]),
                                    (val[0][pick["val"]], val[1][pick["val"]]),
                                    (test[0][pick["test"]], test[1][pick["test"]]))
        expected.append(scores["physics least-squares"]["test_mse"])
    physics = boot["physics least-squares"]
    assert physics["test_mse_per_seed"] == pytest.approx(expected)
    assert physics["test_mse"] == pytest.approx(sum(expected) / 3) and physics["resample"] == "bootstrap"
