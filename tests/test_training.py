"""Tests for the training utilities (event_transforms.tactile.training): timing, collation, scores, atomic files.

The trainer itself (``ensemble.fit_ensemble``) is tested in ``test_ensemble.py``; distributed
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

from event_transforms.tactile.training import (
    Stopwatch,
    TimedTransform,
    collate,
    mse,
    phase_mse,
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
    def test_atomic_write_keeps_old_file(self, tmp_path):
        path = tmp_path / "r.json"
        write_json_atomic(path, {"a": 1})
        with pytest.raises(TypeError):
            write_json_atomic(path, {"a": object()})
        assert json.loads(path.read_text()) == {"a": 1}
        assert os.listdir(tmp_path) == ["r.json"]
