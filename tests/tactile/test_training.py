"""Tests for the one trainer (event_transforms.tactile.training): ``train`` and what the protocol
and ``event-transforms train`` share through it, timing, collation, scores, atomic files.

The optimiser loop (``training.fit_ensemble``) is tested in ``test_ensemble.py``; distributed
protocol runs in ``test_cli.py``.
"""

from __future__ import annotations

import json
import os

import pytest
import torch
from torch import nn
from torch.utils.data import Dataset

import event_transforms as et

from event_transforms.tactile.training import collate, mse, phase_mse, write_json_atomic
from event_transforms.tactile.stopwatch import Stopwatch, TimedTransform


pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest.py


class FakeGrasps(Dataset):
    """Tiny stand-in for TactileGrasps: ``(frames, force, meta)`` with a learnable link.

    Force ramps up over the first 4 frames, holds, and falls over the last 4; the contact
    strip's event rate follows the force, its width the bolt diameter.
    """

    def __init__(self, n: int, diameters=(12.0, 18.0), steps: int = 14, size=(16, 12), seed: int = 0):
        g = torch.Generator().manual_seed(seed)
        h, w = size
        self.items = []
        for i in range(n):
            diameter = diameters[i % len(diameters)]
            peak = 5.0 + 20.0 * torch.rand((), generator=g).item()
            profile = torch.ones(steps)
            profile[:4] = torch.linspace(0.25, 1.0, 4)
            profile[-4:] = torch.linspace(0.75, 0.0, 4)
            force = (peak * profile).float()
            rate = torch.full((steps, 2, h, w), 0.05)
            half = max(1, int(diameter / 6))
            rate[:, :, :, w // 2 - half : w // 2 + half] += force.view(steps, 1, 1, 1) / 5
            frames = torch.poisson(rate, generator=g)
            meta = {"diameter_mm": diameter, "gripper": "parallel", "seed": seed, "index": i}
            self.items.append((frames, force, meta))

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int):
        return self.items[index]


@pytest.fixture(scope="module")
def data():
    return FakeGrasps(8, seed=1), FakeGrasps(4, diameters=(15.0,), seed=2)


class TestMetrics:
    def test_phase_mse_against_loops(self):
        g = torch.Generator().manual_seed(0)
        pred, target = torch.rand(3, 13, generator=g), torch.rand(3, 13, generator=g)
        got = phase_mse(pred, target)

        def loop(frames):
            errs = [(pred[n, t] - target[n, t]).item() ** 2 for n in range(3) for t in frames]
            return sum(errs) / len(errs)

        assert got["grasp"] == pytest.approx(loop(range(5)))
        assert got["hold"] == pytest.approx(loop(range(5, 8)))
        assert got["release"] == pytest.approx(loop(range(8, 13)))
        assert got["all"] == pytest.approx(loop(range(13))) == pytest.approx(mse(pred, target))
        with pytest.raises(ValueError, match="frames"):
            phase_mse(pred[:, :10], target[:, :10])

    def test_collate(self, data):
        train, _ = data
        frames, force, metas = collate([train[0], train[1]])
        assert frames.shape == (2, 14, 2, 16, 12) and force.shape == (2, 14)
        assert metas[1]["index"] == 1

    def test_timed_transform_passes_through(self):
        watch = Stopwatch()
        timed = TimedTransform(nn.Identity(), watch)
        x = torch.rand(2, 2, 3, 3)
        assert torch.equal(timed(x), x) and watch.calls == 2  # the draw and the application
        frames = torch.poisson(torch.full((3, 4, 2, 5, 5), 0.5))
        rotation = et.RandomRotation(30.0)
        params = TimedTransform(rotation).make_params(frames.shape, generator=torch.Generator().manual_seed(0))
        assert torch.equal(TimedTransform(rotation)(frames, params=params), rotation(frames, params=params))
        with pytest.raises(TypeError, match="transform must be an EventTransform or a callable, got int"):
            TimedTransform(3)


class TestAtomicWrite:
    def test_text_and_bytes_and_a_failed_block(self, tmp_path):
        from event_transforms.tactile._files import atomic_write

        path = tmp_path / "sub" / "a.bin"
        with atomic_write(path, "wb") as handle:
            handle.write(b"old")
        with pytest.raises(RuntimeError, match="half-way"):
            with atomic_write(path, "wb") as handle:
                handle.write(b"new, half")
                raise RuntimeError("half-way")
        assert path.read_bytes() == b"old" and os.listdir(path.parent) == ["a.bin"]
        with pytest.raises(ValueError, match="mode must be 'w' or 'wb', got 'a'"):
            with atomic_write(path, "a"):
                pass

    def test_atomic_write_keeps_old_file(self, tmp_path):
        path = tmp_path / "r.json"
        write_json_atomic(path, {"a": 1})
        with pytest.raises(TypeError):
            write_json_atomic(path, {"a": object()})
        assert json.loads(path.read_text()) == {"a": 1}
        assert os.listdir(tmp_path) == ["r.json"]


@pytest.fixture(scope="module")
def scene_data():
    from tests.tactile.test_cli import fake_data

    return fake_data("paper")


class TestOneTrainer:
    """``train`` is the one place a scene's methods are trained: the protocol's unit and
    ``event-transforms train`` reach the same numbers through it."""

    SETTINGS = {"steps": 4, "batch_size": 4, "eval_every": 2, "hidden_channels": (2,), "input_pool": 4}

    def test_defaults_are_the_protocols(self):
        import dataclasses
        import inspect

        from event_transforms.tactile.protocol import ProtocolConfig
        from event_transforms.tactile.training import train

        defaults = {n: p.default for n, p in inspect.signature(train).parameters.items()
                    if p.default is not inspect.Parameter.empty}
        config = ProtocolConfig()
        fields = config.training_settings()
        assert set(fields) <= set(defaults)
        # one exception: a protocol run draws fresh data per seed (its intervals cover new data),
        # a model trained alone reads every item of the data it is given
        assert config.resample == "fresh" and defaults["resample"] == "none"
        assert {n: tuple(v) if isinstance(v, tuple) else v for n, v in fields.items() if n != "resample"} == {
            n: defaults[n] for n in fields if n != "resample"}
        # every setting of ProtocolConfig that training reads is passed on (paper_split is the evaluation's)
        assert set(fields) == {f.name for f in dataclasses.fields(config)} - {"paper_split"}

    def test_train_model_and_run_unit_train_the_same_model(self, scene_data):
        from event_transforms.tactile.deployment import train_model
        from event_transforms.tactile.protocol import ProtocolConfig, run_unit

        for method in ("none", "fs2"):
            unit = run_unit("paper", [method], [3], ProtocolConfig(**self.SETTINGS, resample="none"), scene_data,
                            progress=False)
            model, summary = train_model(scene_data, method, seed=3, **self.SETTINGS)
            record = unit[method][0]
            assert summary["test_mse"] == record["test_mse"] and summary["val_mse"] == record["val_mse"]
            assert summary["holdout_mse"] == record["holdout_mse"] and summary["kept_step"] == record["best_step"]
            assert summary["train_items"] == record["train_items"]

    def test_a_resampled_unit_trains_and_scores_each_seed_on_its_own_resample(self, scene_data):
        from event_transforms.tactile.protocol import ProtocolConfig, run_unit
        from event_transforms.tactile.resampling import bootstrap_indices
        from event_transforms.tactile.training import evaluate, phase_mse, train

        config = ProtocolConfig(**self.SETTINGS, resample="bootstrap")
        unit = run_unit("paper", ["none", "fs2"], [3, 4], config, scene_data, progress=False)
        trained = train(scene_data, ["none", "fs2"], [3, 4], progress=False, **config.training_settings())
        fixed = train(scene_data, ["none", "fs2"], [3, 4], progress=False,
                      **{**config.training_settings(), "resample": "none"})
        pred, target = evaluate(trained.model, scene_data.test)
        plain, _ = evaluate(fixed.model, scene_data.test)
        assert not torch.equal(pred, plain)  # the resample changed what the members trained on
        for index, (method, seed) in enumerate([("none", 3), ("none", 4), ("fs2", 3), ("fs2", 4)]):
            pick = bootstrap_indices(len(scene_data.test), seed, "test")
            record = next(r for r in unit[method] if r["seed"] == seed)
            assert record["test_mse"] == phase_mse(pred[index][pick], target[pick])["all"]
            # the paper's split reads the first sequences as they are
            assert record["test_mse_paper_split"] == phase_mse(pred[index, :6], target[:6])["all"]
        with pytest.raises(ValueError, match="needs paired=True"):
            ProtocolConfig(**{**self.SETTINGS, "paired": False, "resample": "bootstrap"})
        with pytest.raises(ValueError, match="resample must be one of"):
            ProtocolConfig(**self.SETTINGS, resample="jackknife")

    def test_members_are_method_major_and_evaluate_matches_the_member(self, scene_data):
        from event_transforms.tactile.training import evaluate, force_stats, train

        trained = train(scene_data, ["none", "fs2"], [0, 5], progress=False, **self.SETTINGS)
        assert [m.name for m in trained.methods] == ["none", "none", "fs2", "fs2"]
        assert trained.seeds == [0, 5, 0, 5] and trained.model.members == 4
        assert trained.train_items == [6, 6, 12, 12]  # fs2: one copy per item
        offset, scale = force_stats(scene_data.train)
        assert (trained.force_offset, trained.force_scale) == (offset, scale)
        pred, target = evaluate(trained.model, scene_data.test)
        frames = torch.stack([scene_data.test[i][0] for i in range(len(scene_data.test))])
        member = trained.model.to("cpu").member(2).eval()
        with torch.no_grad():
            torch.testing.assert_close(pred[2].float(), member(frames), atol=1e-4, rtol=1e-4)
        assert torch.equal(target, torch.stack([scene_data.test[i][1] for i in range(len(scene_data.test))]).double())

    def test_bad_methods_and_seeds_are_refused_by_name(self, scene_data):
        from event_transforms.tactile.training import train

        with pytest.raises(ValueError, match="methods must be a non-empty sequence of method names, got 'none'"):
            train(scene_data, "none", [0], **self.SETTINGS)
        with pytest.raises(ValueError, match=r"seeds must be a non-empty sequence of ints, got \[\]"):
            train(scene_data, ["none"], [], **self.SETTINGS)
        with pytest.raises(ValueError, match="seeds must be a non-negative integer, got -1"):
            train(scene_data, ["none"], [-1], **self.SETTINGS)
        with pytest.raises(ValueError, match="unknown method 'tes'"):
            train(scene_data, ["tes"], [0], **self.SETTINGS)

    def test_each_name_has_one_module(self):
        from event_transforms.tactile import ensemble, protocol
        from event_transforms.tactile.protocol import run, unit

        for name in ("fit_ensemble", "shuffled_batches", "clip_grad_norm_per_member_", "MemberRecord", "EnsembleResult"):
            assert not hasattr(ensemble, name)  # the trainer's names are the trainer's (tactile.training)
        assert unit.run_unit is protocol.run_unit
        assert protocol.run_protocol is run.run_protocol
        with pytest.raises(AttributeError, match="no attribute 'train'"):
            ensemble.train  # noqa: B018 - the entry point lives in training only
