"""The exact and binomial kernels draw from per-sample seeds: a direct kernel call without
them is refused by name (the dispatchers always pass them), never a failure deep inside."""

from __future__ import annotations

import pytest
import torch

from event_transforms import EventBatch
from event_transforms.functional.drop import drop_random_events, drop_random_frames
from event_transforms.functional.temporal import temporal_event_shift_events, temporal_event_shift_frames


@pytest.fixture
def frames():
    return torch.ones(2, 3, 2, 2, 2)


@pytest.fixture
def batch():
    return EventBatch.from_streams(
        [torch.tensor([[0, 1, 100, 1], [1, 0, 15_000, 0]]), torch.tensor([[1, 1, 50, 0]])],
        sensor_size=(2, 3), frame_ms=10.0, t_start=0, n_frames=2,
    )


@pytest.mark.parametrize("mode", ["exact", "binomial"])
def test_tes_frames_without_seeds(frames, mode):
    with pytest.raises(ValueError, match=f"temporal_event_shift with mode='{mode}' needs seeds"):
        temporal_event_shift_frames(frames, torch.tensor([1, 1]), torch.tensor([0.5, 0.5]), mode, None)


def test_tes_events_without_seeds(batch):
    with pytest.raises(ValueError, match="temporal_event_shift on events with mode='exact' needs seed"):
        temporal_event_shift_events(batch, torch.tensor([1, 1]), torch.tensor([0.5, 0.5]), "exact", None)


def test_drop_without_seeds(frames, batch):
    with pytest.raises(ValueError, match="drop_random with mode='binomial' needs seeds"):
        drop_random_frames(frames, torch.tensor([0.5, 0.5]), "binomial", None)
    with pytest.raises(ValueError, match="drop_random on events needs seeds"):
        drop_random_events(batch, torch.tensor([0.5, 0.5]), seeds=None)


def test_expected_mode_needs_no_seeds(frames):
    out = temporal_event_shift_frames(frames, torch.tensor([0, 0]), torch.tensor([0.0, 0.0]), "expected", None)
    assert torch.equal(out, frames)
    assert torch.equal(drop_random_frames(frames, torch.tensor([0.0, 0.0]), "expected", None), frames)
