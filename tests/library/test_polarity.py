"""Polarity: flip and merged polarities, against slow references (Python loops over frames
and channels)."""

from __future__ import annotations


import pytest
import torch

import event_transforms as et
from event_transforms import functional as F

from tests.support.event_data import check_hard_cases, frames_of, make_batch, rows
from tests.support.checkers import H, W, check_not_modified, sparse_frames


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


class TestFlipPolarity:
    def test_against_reference(self):
        frames = sparse_frames(2, 4, 2, H, W, density=0.3, dtype=torch.int16)
        out = check_not_modified(F.flip_polarity, frames)
        for n in range(2):
            for t in range(4):
                assert torch.equal(out[n, t, 0], frames[n, t, 1]) and torch.equal(out[n, t, 1], frames[n, t, 0])

    def test_random_flips_the_drawn_samples(self):
        frames = sparse_frames(8, 3, 2, H, W, density=0.3)
        module = et.RandomFlipPolarity()
        params = module.make_params(frames.shape, generator=_g(2))
        out = module(frames, params=params)
        for n in range(8):
            assert torch.equal(out[n], frames[n].flip(1) if params["apply"][n] else frames[n])


class TestMergePolarities:
    @pytest.mark.parametrize("dtype", [torch.uint8, torch.int64, torch.bfloat16, torch.float64])
    def test_against_reference(self, dtype):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3, dtype=dtype)
        out = check_not_modified(et.MergePolarities(), frames)
        assert out.shape == frames.shape and out.dtype == dtype
        for n in range(2):
            for t in range(3):
                assert torch.equal(out[n, t, 0], frames[n, t, 0] + frames[n, t, 1])
                assert not out[n, t, 1].any()
        one = F.merge_polarities(frames, keepdim=False)
        assert one.shape == (2, 3, 1, H, W) and torch.equal(one[:, :, 0], out[:, :, 0])

    def test_equals_tonic_merge_then_to_frame(self):
        pytest.importorskip("tonic")
        import numpy as np
        import tonic.transforms as T

        rng = np.random.default_rng(0)
        events = np.zeros(200, dtype=[("x", "<i8"), ("y", "<i8"), ("t", "<i8"), ("p", "<i8")])
        events["x"], events["y"] = rng.integers(0, 9, 200), rng.integers(0, 7, 200)
        events["t"], events["p"] = np.sort(rng.integers(0, 30_000, 200)), rng.integers(0, 2, 200)
        to_frame = T.ToFrame(sensor_size=(9, 7, 2), time_window=10_000)
        merged = to_frame(T.MergePolarities()(events.copy()))
        ours = F.merge_polarities(torch.from_numpy(to_frame(events.copy()).astype(np.int64)))
        assert np.array_equal(ours.numpy(), merged)

    def test_overflow_raises(self):
        frames = torch.full((1, 2, 1, 1), 200, dtype=torch.uint8)
        with pytest.raises(ValueError, match="wider dtype"):
            F.merge_polarities(frames)
        with pytest.raises(TypeError, match="keepdim"):
            F.merge_polarities(frames, keepdim=1)

# --------------------------------------------------------------------------- on events (EventBatch kernels)


class TestOnEvents:
    """The event kernels of this topic: slow per-event references, and equality with the
    frame kernel after binning where the semantics coincide."""

    def test_flip_polarity_matches_frames(self):
        batch = make_batch()
        frames = frames_of(batch)
        assert torch.equal(frames_of(et.FlipPolarity()(batch)), frames.flip(2))
        flags = torch.tensor([False, True, True, False])
        assert torch.equal(frames_of(F.flip_polarity(batch, flags)), F.flip_polarity(frames, flags))


class TestMergePolaritiesOnEvents:
    def test_against_reference(self):
        batch = make_batch()
        out = et.MergePolarities()(batch)
        for b in range(len(batch)):
            assert rows(out, b) == [(x, y, t, 0) for x, y, t, _ in rows(batch, b)]  # every event OFF
        assert out.p.dtype == torch.int8 and batch.p.sum() > 0  # the input is untouched

    def test_equals_frames_after_binning(self):
        batch = make_batch()
        assert torch.equal(frames_of(F.merge_polarities(batch)), F.merge_polarities(frames_of(batch)))

    def test_keepdim_false_refused(self):
        with pytest.raises(ValueError, match="keepdim=False"):
            F.merge_polarities(make_batch(), keepdim=False)

    def test_hard_cases(self):
        check_hard_cases(lambda: et.MergePolarities())


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "FlipPolarity": lambda t, h, w: et.FlipPolarity(),
    "RandomFlipPolarity": lambda t, h, w: et.RandomFlipPolarity(0.5),
    "MergePolarities": lambda t, h, w: et.MergePolarities(),
}

EVENT_BATTERY = {
    "FlipPolarity": lambda: et.FlipPolarity(),
    "RandomFlipPolarity": lambda: et.RandomFlipPolarity(),
    "MergePolarities": lambda: et.MergePolarities(),
    "MergePolarities p": lambda: et.MergePolarities(p=0.5),
}
