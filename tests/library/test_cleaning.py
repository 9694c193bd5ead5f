"""Cleaning: hot pixels and the frame-level denoising filter against slow references (Python
loops over entries and windows), and the filter's invariant (hypothesis)."""

from __future__ import annotations

import warnings

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import EventBatch
from event_transforms import functional as F

from tests.support.event_data import SENSOR, T, check_hard_cases, frames_of, make_streams, rows
from tests.support.checkers import H, W, check_not_modified, count_shapes, random_counts, sparse_frames


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
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "Denoise": lambda t, h, w: et.Denoise(),
}


# --------------------------------------------------------------------------- on events (EventBatch kernels)


def reference_denoise_events(batch, b: int, radius: int, temporal_radius: int) -> list[tuple]:
    """Slow per-event reference: an event in the grid's window and on the sensor survives when
    some event of its stream in another entry (pixel, bin, polarity) lies within ``radius``
    pixels and ``temporal_radius`` bins; events outside the window or the sensor are kept."""
    height, width = batch.sensor_size
    frame_us = int(batch.frame_ms * 1000)
    start = int(batch.t_start[b])
    events = rows(batch, b)

    def entry(event):
        x, y, t, p = event
        k = (t - start) // frame_us
        if not (0 <= x < width and 0 <= y < height and 0 <= k < batch.n_frames):
            return None
        return (k, p, y, x)

    entries = [entry(e) for e in events]
    kept = []
    for event, own in zip(events, entries):
        if own is None:
            kept.append(event)
            continue
        k, _, y, x = own
        if any(other is not None and other != own and abs(other[0] - k) <= temporal_radius
               and abs(other[2] - y) <= radius and abs(other[3] - x) <= radius for other in entries):
            kept.append(event)
    return kept


class TestDenoiseOnEvents:
    @pytest.mark.parametrize("radius, temporal_radius", [(1, 1), (0, 0), (2, 0), (1, 3)])
    def test_against_reference_and_frames(self, radius, temporal_radius):
        # sparse streams, plus an event outside the window and one off the sensor (both kept)
        streams = [torch.cat([s[:40], torch.tensor([[2, 2, 10 * T * 1000, 1], [-1, 3, 500, 0]])])
                   for s in make_streams(3, seed=4)]
        batch = EventBatch.from_streams(streams, sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)
        out = F.denoise(batch, radius=radius, temporal_radius=temporal_radius)
        removed = 0
        for b in range(len(batch)):
            expected = reference_denoise_events(batch, b, radius, temporal_radius)
            assert rows(out, b) == expected
            removed += len(rows(batch, b)) - len(expected)
        assert removed > 0 or radius == 2  # the case removes something
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the two events binning drops
            assert torch.equal(frames_of(out), F.denoise(frames_of(batch), radius=radius, temporal_radius=temporal_radius))

    def test_module_same_entry_does_not_count(self):
        """Two events in one entry are one entry (as on frames): alone, both go."""
        twins = torch.tensor([[4, 4, 100, 1], [4, 4, 200, 1], [9, 9, 100, 0], [9, 9, 200, 1]])
        batch = EventBatch.from_streams([twins], sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)
        out = et.Denoise()(batch)
        assert rows(out, 0) == [(9, 9, 100, 0), (9, 9, 200, 1)]  # other polarity: another entry

    def test_needs_a_grid(self):
        batch = EventBatch.from_streams(make_streams(2), sensor_size=SENSOR)
        with pytest.raises(ValueError, match="denoise on events needs the batch's frame grid"):
            F.denoise(batch)

    def test_hard_cases(self):
        check_hard_cases(lambda: et.Denoise(temporal_radius=0))


EVENT_BATTERY = {
    "Denoise": lambda: et.Denoise(),
    "Denoise p": lambda: et.Denoise(2, temporal_radius=0, p=0.5),
}
