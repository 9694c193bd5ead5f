"""Cleaning: hot pixels and the frame-level denoising filter against slow references (Python
loops over entries and windows), and the filter's invariant (hypothesis)."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import functional as F

from .checkers import H, W, check_not_modified, count_shapes, random_counts, sparse_frames


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


def _reference_denoise(frames, radius, temporal_radius):
    b, t, p, h, w = frames.shape
    out = frames.clone()
    for n in range(b):
        for i in range(t):
            for c in range(p):
                for y in range(h):
                    for x in range(w):
                        if frames[n, i, c, y, x] <= 0:
                            continue
                        found = False
                        for j in range(max(0, i - temporal_radius), min(t, i + temporal_radius + 1)):
                            for d in range(p):
                                for yy in range(max(0, y - radius), min(h, y + radius + 1)):
                                    for xx in range(max(0, x - radius), min(w, x + radius + 1)):
                                        if (j, d, yy, xx) != (i, c, y, x) and frames[n, j, d, yy, xx] > 0:
                                            found = True
                        if not found:
                            out[n, i, c, y, x] = 0
    return out


class TestDenoise:
    @pytest.mark.parametrize("radius, temporal_radius", [(1, 1), (0, 0), (2, 0), (1, 5)])
    def test_against_reference(self, radius, temporal_radius):
        frames = sparse_frames(2, 4, 2, 9, 7, density=0.04, dtype=torch.int32)
        out = F.denoise(frames, radius=radius, temporal_radius=temporal_radius)
        assert torch.equal(out, _reference_denoise(frames, radius, temporal_radius))

    def test_module_and_counts(self):
        frames = sparse_frames(2, 6, 2, H, W, density=0.05, dtype=torch.uint8)
        out = check_not_modified(et.Denoise(), frames)
        assert out.dtype == torch.uint8
        kept = out > 0
        assert torch.equal(out[kept], frames[kept]) and int(out.sum()) < int(frames.sum())

    def test_named_errors(self):
        with pytest.raises(ValueError, match="radius"):
            et.Denoise(-1)
        with pytest.raises(TypeError, match="temporal_radius"):
            F.denoise(torch.zeros(1, 2, 3, 3), temporal_radius=0.5)


@settings(max_examples=40, deadline=None)
@given(count_shapes, st.integers(0, 2**31), st.integers(0, 3), st.integers(0, 3))
def test_denoise_only_removes_whole_entries(shape, seed, radius, temporal_radius):
    frames = random_counts(shape, seed) * (torch.rand(shape[0], shape[1], 2, shape[2], shape[3], generator=torch.Generator().manual_seed(seed)) < 0.2)
    out = F.denoise(frames, radius=radius, temporal_radius=temporal_radius)
    kept = out > 0
    assert torch.equal(out[kept], frames[kept]) and bool((out <= frames).all())


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/test_battery.py on frames,
# tests/test_shape_battery.py for size-changing modules, tests/test_event_batch.py on events).

BATTERY = {
    "Denoise": lambda t, h, w: et.Denoise(),
}
