"""Tests for ``event_transforms.tactile.datasets``."""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader, default_collate

import event_transforms as et
from event_transforms.tactile import datasets
from event_transforms.data import AugmentedDataset
from event_transforms.scenes import metadata_values
from event_transforms.tactile.datasets import TactileGrasps, noise_bank
from event_transforms.tactile._files import default_cache_dir
from event_transforms.tactile.benchmark_scenes import get_scene
from event_transforms.tactile.simulation import SimulatorConfig


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(scope="module")
def train(root):
    return TactileGrasps("train", root=root)


class TestTactileGrasps:
    def test_split_sizes_and_bolts(self, root, train):
        val, test = TactileGrasps("val", root=root), TactileGrasps("test", root=root)
        assert (len(train), len(val), len(test)) == (48, 24, 96)
        diameters = [train.meta(i)["diameter_mm"] for i in range(48)]
        assert diameters.count(12.0) == 24 and diameters.count(18.0) == 24
        assert {val.meta(i)["diameter_mm"] for i in range(24)} == {15.0}
        assert {test.meta(i)["diameter_mm"] for i in range(96)} == {15.0}
        seeds = [d.meta(i)["seed"] for d in (train, val, test) for i in range(len(d))]
        assert len(set(seeds)) == 168  # no sequence is shared between splits
        # continuous hold forces, spread over the range (no two gripper settings)
        peaks = torch.cat([train.forces, test.forces]).amax(1)
        assert peaks.min() < 5 and peaks.max() > 20 and len(set(peaks.round().tolist())) > 15

    def test_holdout_from_training_session_and_a_fresh_test_block(self, root, train):
        holdout, test = TactileGrasps("holdout", root=root), TactileGrasps("test", root=root)
        assert len(holdout) == 24 and holdout.session == train.session  # the stopping rule's data
        assert {holdout.meta(i)["diameter_mm"] for i in range(24)} == {12.0, 18.0}
        train_seeds = {train.meta(i)["seed"] for i in range(48)}
        assert not train_seeds & {holdout.meta(i)["seed"] for i in range(24)}  # new sequences
        # the test block is drawn from seeds no earlier run used (the old block was 20000-20095)
        assert [test.meta(i)["seed"] for i in (0, 95)] == [40_000, 40_095]

    def test_paper_split_is_nested(self, root):
        small, large = TactileGrasps("test", root=root, paper_split=True), TactileGrasps("test", root=root)
        assert len(small) == 6 and small.path == large.path
        assert torch.equal(small.frames, large.frames[:6])
        assert len(TactileGrasps("train", root=root, paper_split=True)) == 48

    def test_scenes_share_training_data(self, root, train):
        timing = TactileGrasps("train", root=root, scene="timing")
        assert timing.path == TactileGrasps("train", root=root, scene="control").path  # one session, one file
        assert timing.path != train.path and {timing.meta(i)["diameter_mm"] for i in range(48)} == {15.0}
        other = TactileGrasps("train", root=root, scene="size-extrapolation")
        assert {other.meta(i)["diameter_mm"] for i in range(48)} == {12.0, 15.0}
        deploy = TactileGrasps("val", root=root, scene="timing")
        assert all(16.0 <= deploy.recording(i).grasp.delay_ms <= 24.0 for i in range(2))

    def test_item_contract(self, train):
        frames, force, meta = train[5]
        assert frames.shape == (36, 2, 70, 75) and frames.dtype == torch.float32
        assert torch.equal(frames, frames.round()) and frames.min() >= 0 and frames.sum() > 0
        assert force.shape == (36,) and force.dtype == torch.float32
        assert 0 <= float(force.min()) and float(force.max()) <= 25.0
        assert meta == {"diameter_mm": 18.0, "seed": 5, "index": 5}
        assert [type(v) for v in meta.values()] == [float, int, int]
        assert train[-1][2]["index"] == 47
        with pytest.raises(IndexError):
            train[48]

    def test_collates_and_loads(self, train):
        frames, force, meta = next(iter(DataLoader(train, batch_size=4)))
        assert frames.shape == (4, 36, 2, 70, 75) and force.shape == (4, 36)
        assert meta["diameter_mm"].dtype == torch.float64 and meta["index"].tolist() == [0, 1, 2, 3]
        batch = default_collate([train[0], train[1]])
        assert batch[0].shape == (2, 36, 2, 70, 75)

    def test_whole_split_tensors(self, train):
        assert train.frames.shape == (48, 36, 2, 70, 75) and train.frames.dtype == torch.float32
        assert torch.equal(train.frames[7], train[7][0])
        assert torch.equal(train.forces[7], train[7][1])

    def test_cache_is_reused(self, root, train, monkeypatch):
        def fail(*args, **kwargs):
            raise AssertionError("regenerated although the cache exists")

        monkeypatch.setattr(datasets, "generate", fail)
        again = TactileGrasps("train", root=root)
        assert again.path == train.path and torch.equal(again[3][0], train[3][0])

    def test_cache_key_follows_settings(self, root, train):
        session = get_scene("paper").train
        names = {
            datasets._cache_name(session, range(0, 48), (140, 150), 2),
            datasets._cache_name(session, range(100, 148), (140, 150), 2),
            datasets._cache_name(session, range(0, 48), (140, 150), 1),
            datasets._cache_name(session.replace(lag_ms=(1.0, 2.0)), range(0, 48), (140, 150), 2),
            datasets._cache_name(session.replace(diameters_mm=(12.0,)), range(0, 48), (140, 150), 2),
        }
        assert len(names) == 5 and train.path.name in names

    def test_interrupted_generation_leaves_no_cache(self, tmp_path, monkeypatch):
        def interrupted(obj, stream):
            stream.write(b"half a file")
            raise KeyboardInterrupt

        monkeypatch.setattr(datasets.torch, "save", interrupted)
        with pytest.raises(KeyboardInterrupt):
            TactileGrasps("val", root=tmp_path, scene="noise")
        assert list(tmp_path.iterdir()) == []  # neither the cache nor its temporary file

    def test_recording_resimulates_the_item(self, root):
        test = TactileGrasps("val", root=root)
        recording = test.recording(2)
        frames = recording.frames(crop=recording.sensor_crop(), pool=2)
        assert torch.equal(frames, test[2][0])
        assert np.array_equal(recording.force, test[2][1].numpy())

    def test_transform_receives_metadata(self, root):
        val = TactileGrasps("val", root=root, transform=ScaleBySize())
        plain = TactileGrasps("val", root=root)
        torch.testing.assert_close(val[0][0], plain[0][0] * 15.0)

    def test_bad_split_or_scene_raises(self, root):
        with pytest.raises(ValueError, match="split"):
            TactileGrasps("validation", root=root)
        with pytest.raises(ValueError, match="scene"):
            TactileGrasps("val", root=root, scene="tilted")

    def test_default_cache_dir(self, monkeypatch, tmp_path):
        monkeypatch.setenv("EVENT_TRANSFORMS_CACHE", str(tmp_path / "a"))
        assert default_cache_dir() == tmp_path / "a"
        monkeypatch.delenv("EVENT_TRANSFORMS_CACHE")
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        assert default_cache_dir() == tmp_path / "xdg" / "event-transforms"
        monkeypatch.delenv("XDG_CACHE_HOME")
        assert str(default_cache_dir()) == os.path.join(os.path.expanduser("~"), ".cache", "event-transforms")


class TestNoiseBank:
    def test_shape_and_rate(self):
        bank = noise_bank(50, seed=0)
        assert bank.shape == (50, 2, 70, 75) and bank.dtype == torch.float32
        config = SimulatorConfig(hot_pixels=False)
        low, high = config.shot_noise_hz
        quiet = noise_bank(50, seed=0, config=config)
        rate = float(quiet.sum()) / (140 * 150 * 0.5)
        assert rate == pytest.approx((high - low) / np.log(high / low), rel=0.1)

    def test_seeded(self):
        assert torch.equal(noise_bank(5, seed=1), noise_bank(5, seed=1))
        assert not torch.equal(noise_bank(5, seed=1), noise_bank(5, seed=2))

    def test_bad_length_raises(self):
        with pytest.raises(ValueError, match="n_frames"):
            noise_bank(0)


class _Base(torch.utils.data.Dataset):
    def __init__(self, n=3):
        self.n = n

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        return torch.full((4, 2, 3, 5), float(i)), torch.tensor([float(i)]), {"diameter_mm": 12.0 + i, "index": i}


class AddUniform(et.EventTransform):
    """A random transform with the library's contract: its draw lives in make_params."""

    def sample_params(self, shape, *, generator=None, metadata=None):
        return {"noise": torch.rand(shape, generator=generator)}

    def params_spec(self, shape):
        return {"noise": et.Param("float", shape=tuple(shape[1:]))}

    def apply_transform(self, frames, params):
        return frames + params["noise"]


class ScaleBySize(et.EventTransform):
    """Reads each sample's size from the metadata, as ResizeToTarget does."""

    def sample_params(self, shape, *, generator=None, metadata=None):
        return {"size": metadata_values(metadata, "diameter_mm", shape[0])}

    def params_spec(self, shape):
        return {"size": et.Param("float")}

    def apply_transform(self, frames, params):
        return frames * params["size"].view(-1, 1, 1, 1, 1).to(frames.dtype)


add_noise = AddUniform()


class TestAugmentedDataset:
    def test_length_and_originals(self):
        data = AugmentedDataset(_Base(), add_noise, copies=2)
        assert len(data) == 9
        for i in range(3):
            frames, label, meta = data[i]
            assert torch.equal(frames, _Base()[i][0]) and meta["index"] == i

    def test_copies_keep_labels_and_metadata(self):
        data = AugmentedDataset(_Base(), add_noise, copies=2)
        for i in range(3, 9):
            frames, label, meta = data[i]
            source = i % 3
            assert label.item() == source and meta == {"diameter_mm": 12.0 + source, "index": source}
            assert not torch.equal(frames, _Base()[source][0])

    def test_fixed_copies_are_deterministic(self):
        a, b = AugmentedDataset(_Base(), add_noise, seed=3), AugmentedDataset(_Base(), add_noise, seed=3)
        assert torch.equal(a[4][0], a[4][0]) and torch.equal(a[4][0], b[4][0])
        assert not torch.equal(a[4][0] - 1, a[3][0])  # copies of different items differ
        assert not torch.equal(a[4][0], AugmentedDataset(_Base(), add_noise, seed=4)[4][0])

    def test_fresh_copies_use_the_global_rng(self):
        data = AugmentedDataset(_Base(), add_noise, fixed=False)
        torch.manual_seed(0)
        first = data[3][0]
        assert not torch.equal(first, data[3][0])
        torch.manual_seed(0)
        assert torch.equal(first, data[3][0])

    def test_metadata_reaches_the_transform(self):
        data = AugmentedDataset(_Base(), ScaleBySize())
        assert data[4][0].max().item() == 1.0 * 13.0

    def test_plain_callable_and_zero_copies(self):
        data = AugmentedDataset(_Base(), lambda frames: frames + 1, copies=1)
        assert data[3][0].min().item() == 1.0
        assert len(AugmentedDataset(_Base(), add_noise, copies=0)) == 3

    def test_data_loader(self):
        loader = DataLoader(AugmentedDataset(_Base(), add_noise), batch_size=6)
        frames, labels, meta = next(iter(loader))
        assert frames.shape == (6, 4, 2, 3, 5) and labels.shape == (6, 1)

    def test_with_tactile_grasps(self, train):
        from event_transforms import HorizontalFlip

        data = AugmentedDataset(train, HorizontalFlip())
        assert len(data) == 96
        assert torch.equal(data[48][0], train[0][0].flip(-1)) and data[48][2] == train[0][2]

    @pytest.mark.parametrize("kwargs", [dict(copies=-1), dict(seed=-2)])
    def test_bad_arguments_raise(self, kwargs):
        with pytest.raises(ValueError):
            AugmentedDataset(_Base(), add_noise, **kwargs)
        with pytest.raises(TypeError):
            AugmentedDataset(_Base(), "flip")
