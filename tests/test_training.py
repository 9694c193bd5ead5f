"""Tests for the training loop (event_transforms.tactile.training) and the protocol (event_transforms.tactile.protocol)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest
import torch
from torch import nn
from torch.utils.data import Dataset

import event_transforms as et

from event_transforms.tactile.models import ForceRegressor
from event_transforms.tactile.training import (
    Stopwatch,
    TimedTransform,
    collate,
    fit,
    mse,
    phase_mse,
    predict,
    run_seeds,
    seed_everything,
    write_json_atomic,
)


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


class OnTheFly(Dataset):
    """Applies ``transform`` with torch's global RNG at every access."""

    def __init__(self, base: Dataset, transform: nn.Module):
        self.base, self.transform = base, transform

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, index: int):
        frames, force, meta = self.base[index]
        return self.transform(frames), force, meta


class Jitter(et.EventTransform):
    """A random transform drawing from the global RNG (for determinism tests)."""

    def sample_params(self, shape, *, generator=None, metadata=None):
        return {"noise": torch.poisson(torch.full(shape, 0.1), generator=generator)}

    def apply(self, frames, params):
        return frames + params["noise"].to(frames.dtype)


class Constant(nn.Module):
    """Predicts zero whatever its weights: the validation loss never changes."""

    def __init__(self):
        super().__init__()
        self.weight = nn.Parameter(torch.ones(1))

    def forward(self, frames):
        return 0 * self.weight * frames.sum((2, 3, 4))


def tiny_model(seed: int = 0) -> ForceRegressor:
    seed_everything(seed)
    return ForceRegressor(hidden_channels=(3,), input_pool=2)


@pytest.fixture(scope="module")
def data():
    return FakeGrasps(8, seed=1), FakeGrasps(4, diameters=(15.0,), seed=2)


class TestFit:
    def test_learns_and_restores_best_weights(self, data):
        train, val = data
        model = tiny_model()
        model.set_force_scaling(10.0, 8.0)
        before = mse(*predict(model, val)[:2])
        result = fit(model, train, val, epochs=8, patience=8, lr=1e-2, batch_size=4, progress=False)
        assert result.best_val_loss < before
        assert result.best_val_loss == min(r.val_loss for r in result.history)
        assert result.history[result.best_epoch].val_loss == result.best_val_loss
        # The model holds the best epoch's weights, not the last epoch's.
        assert mse(*predict(model, val)[:2]) == pytest.approx(result.best_val_loss, rel=1e-6)
        assert result.epochs_run == len(result.history) <= 8
        assert all(math.isfinite(r.train_loss) and r.train_s > 0 for r in result.history)

    def test_early_stopping_patience(self, data):
        train, val = data
        result = fit(Constant(), train, val, epochs=50, patience=3, progress=False)
        assert result.epochs_run == 4 and result.best_epoch == 0 and result.stopped_early
        result = fit(Constant(), train, val, epochs=2, patience=3, progress=False)
        assert result.epochs_run == 2 and not result.stopped_early

    def test_seed_fixes_everything(self, data):
        train, val = data

        def run(seed):
            model = tiny_model(seed)
            watch = Stopwatch()
            aug = OnTheFly(train, TimedTransform(Jitter(), watch))
            result = fit(model, aug, val, epochs=2, patience=2, batch_size=4, seed=seed,
                         stopwatch=watch, progress=False)
            return result, model.state_dict()

        (a, sa), (b, sb), (c, _) = run(5), run(5), run(6)
        assert [r.train_loss for r in a.history] == [r.train_loss for r in b.history]
        assert [r.val_loss for r in a.history] == [r.val_loss for r in b.history]
        for key in sa:
            assert torch.equal(sa[key], sb[key]), key
        assert [r.train_loss for r in a.history] != [r.train_loss for r in c.history]

    def test_augmentation_time_recorded(self, data):
        train, val = data
        watch = Stopwatch()
        aug = OnTheFly(train, TimedTransform(Jitter(), watch))
        result = fit(tiny_model(), aug, val, epochs=2, patience=2, stopwatch=watch, progress=False)
        assert watch.calls == 2 * 2 * len(train)  # 2 epochs; each call times its draw and its application
        assert all(r.augmentation_s > 0 for r in result.history)
        assert sum(r.augmentation_s for r in result.history) == pytest.approx(watch.seconds)
        assert result.augmentation_s_per_epoch <= result.train_s_per_epoch
        plain = fit(tiny_model(), train, val, epochs=1, patience=1, progress=False)
        assert plain.history[0].augmentation_s == 0
        assert set(plain.to_dict()) >= {"history", "train_s_per_epoch", "augmentation_s_per_epoch"}

    def test_quiet_without_terminal(self, data, capsys):
        train, val = data
        fit(tiny_model(), train, val, epochs=1, patience=1, progress=None)
        captured = capsys.readouterr()
        assert captured.err == "" and captured.out == ""

    def test_float64_model(self, data):
        train, val = data
        model = tiny_model().double()
        result = fit(model, train, val, epochs=1, patience=1, progress=False)
        assert math.isfinite(result.best_val_loss)
        assert predict(model, val)[0].dtype == torch.float64

    def test_bad_arguments(self, data):
        train, val = data
        for kwargs, match in [
            ({"epochs": 0}, "epochs"), ({"patience": 0}, "patience"),
            ({"batch_size": 1.5}, "batch_size"), ({"lr": -1.0}, "lr"), ({"lr": math.nan}, "lr"),
        ]:
            with pytest.raises(ValueError, match=match):
                fit(tiny_model(), train, val, progress=False, **kwargs)
        with pytest.raises(TypeError, match="seed"):
            seed_everything(1.5)


class TestPredictAndMetrics:
    def test_predict_matches_model(self, data):
        _, val = data
        model = tiny_model()
        pred, target, metas = predict(model, val, batch_size=3)
        frames = torch.stack([val[i][0] for i in range(len(val))])
        with torch.no_grad():
            torch.testing.assert_close(pred, model(frames).double())
        assert target.dtype == torch.float64 and pred.shape == target.shape == (4, 14)
        assert [m["index"] for m in metas] == [0, 1, 2, 3]
        assert model.training  # predict restores the mode

    def test_predict_empty(self):
        with pytest.raises(ValueError, match="empty"):
            predict(tiny_model(), FakeGrasps(0))

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


class TestResume:
    def test_interrupted_run_resumes_without_loss(self, tmp_path):
        calls = []

        def run_one(seed):
            calls.append(seed)
            if seed == 2 and calls.count(2) == 1:
                raise KeyboardInterrupt  # killed between seed 1 and seed 2
            return {"seed": seed, "mse": seed * 1.5}

        with pytest.raises(KeyboardInterrupt):
            run_seeds(run_one, [0, 1, 2, 3], tmp_path)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["seed-0.json", "seed-1.json"]
        results = run_seeds(run_one, [0, 1, 2, 3], tmp_path)
        assert calls == [0, 1, 2, 2, 3]
        assert results == [{"seed": s, "mse": s * 1.5} for s in range(4)]
        assert run_seeds(run_one, [0, 1, 2, 3], tmp_path) == results
        assert calls == [0, 1, 2, 2, 3]

    def test_atomic_write_keeps_old_file(self, tmp_path):
        path = tmp_path / "r.json"
        write_json_atomic(path, {"a": 1})
        with pytest.raises(TypeError):
            write_json_atomic(path, {"a": object()})
        assert json.loads(path.read_text()) == {"a": 1}
        assert os.listdir(tmp_path) == ["r.json"]

    def test_on_done_reports_resumed(self, tmp_path):
        seen = []
        run_seeds(lambda s: {"s": s}, [0], tmp_path, on_done=lambda *a: seen.append(a))
        run_seeds(lambda s: {"s": s}, [0, 1], tmp_path, on_done=lambda *a: seen.append(a))
        assert seen == [(0, {"s": 0}, False), (0, {"s": 0}, True), (1, {"s": 1}, False)]
        assert isinstance(Path(tmp_path / "seed-1.json").read_text(), str)


def _ddp_worker(rank: int, world: int, port: int, out: str) -> None:
    """One rank of a data-parallel ``fit`` (module level, so spawned processes can import it)."""
    import torch.distributed as dist

    from event_transforms.tactile.models import ForceRegressor
    from event_transforms.tactile.training import fit, seed_everything

    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    try:
        seed_everything(rank)  # different initial weights per rank: DDP must broadcast rank 0's
        model = ForceRegressor(hidden_channels=(2,), input_pool=4)
        train = OnTheFly(FakeGrasps(8, seed=1), et.RandomFrameShift((-1, 1)))
        result = fit(model, train, FakeGrasps(3, seed=2), epochs=3, patience=3, batch_size=2, seed=7, progress=False)
        first_draw = torch.rand(()).item()  # the rank's augmentation stream after training
        torch.save({"state": model.state_dict(), "history": [h.train_loss for h in result.history],
                    "draw": first_draw}, f"{out}/rank{rank}.pt")
    finally:
        dist.destroy_process_group()


@pytest.mark.slow
class TestDistributedFit:
    def _run(self, tmp_path):
        import socket

        import torch.multiprocessing as mp

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        mp.spawn(_ddp_worker, args=(2, port, str(tmp_path)), nprocs=2, join=True)
        return [torch.load(tmp_path / f"rank{r}.pt") for r in range(2)]

    def test_two_gloo_ranks_train_one_model_reproducibly(self, tmp_path):
        (tmp_path / "a").mkdir()
        first = self._run(tmp_path / "a")
        for key, value in first[0]["state"].items():  # DDP keeps the ranks' weights identical
            assert torch.equal(value, first[1]["state"][key]), key
        assert first[0]["history"] == first[1]["history"]  # the all-reduced training loss
        assert first[0]["draw"] != first[1]["draw"]  # each rank has its own augmentation stream
        (tmp_path / "b").mkdir()
        again = self._run(tmp_path / "b")
        for key, value in first[0]["state"].items():  # the same seed, the same run
            assert torch.equal(value, again[0]["state"][key]), key
