"""Representations from events: voxel grid (bilinear in time) and time surface against slow
references (a Python loop over events), and against tonic where tonic is installed."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from event_transforms import functional as F


def _events(n=200, h=7, w=9, span=50_000, seed=0):
    rng = np.random.default_rng(seed)
    events = np.zeros(n, dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<u8"), ("p", "?")])
    events["x"], events["y"] = rng.integers(0, w, n), rng.integers(0, h, n)
    events["t"] = np.sort(rng.integers(0, span, n))
    events["p"] = rng.integers(0, 2, n).astype(bool)
    return events


def _reference_voxel(events, n_bins, h, w, split):
    grid = np.zeros((n_bins, 2 if split else 1, h, w))
    t = events["t"].astype(np.float64)
    t0, t1 = t.min(), t.max()
    for e, tt in zip(events, t):
        scaled = (n_bins - 1) * (tt - t0) / (t1 - t0) if t1 > t0 else 0.0
        c = int(e["p"]) if split else 0
        sign = 1.0 if split else (1.0 if e["p"] else -1.0)
        for k in range(n_bins):
            weight = max(0.0, 1.0 - abs(scaled - k))
            grid[k, c, e["y"], e["x"]] += sign * weight
    return torch.from_numpy(grid).float()


def _reference_surface(events, tau_ms, frame_ms, n_frames, h, w, t_start=0):
    surface = np.zeros((n_frames, 2, h, w))
    for i in range(n_frames):
        end = t_start + (i + 1) * frame_ms * 1000
        for e in events:
            tt = float(e["t"])
            if t_start <= tt < min(end, t_start + n_frames * frame_ms * 1000):
                c = int(e["p"])
                value = math.exp(-(end - tt) / (tau_ms * 1000))
                surface[i, c, e["y"], e["x"]] = max(surface[i, c, e["y"], e["x"]], value)
    return torch.from_numpy(surface).float()


class TestVoxelGrid:
    @pytest.mark.parametrize("polarity", ["signed", "split"])
    @pytest.mark.parametrize("n_bins", [1, 5])
    def test_against_reference(self, polarity, n_bins):
        events = _events()
        grid = F.to_voxel_grid(events, n_bins=n_bins, sensor_size=(7, 9), polarity=polarity)
        ref = _reference_voxel(events, n_bins, 7, 9, polarity == "split")
        torch.testing.assert_close(grid, ref, atol=1e-5, rtol=1e-5)
        if polarity == "split":
            torch.testing.assert_close(grid.sum(), torch.tensor(float(len(events))))

    def test_batch_with_lengths_equals_each_stream(self):
        a, b = _events(seed=1), _events(n=120, seed=2)
        rows = [np.stack([e["x"], e["y"], e["t"], e["p"]], 1).astype(np.int64) for e in (a, b)]
        padded = np.zeros((2, 200, 4), dtype=np.int64)
        padded[0], padded[1, :120] = rows[0], rows[1]
        grid = F.to_voxel_grid(torch.from_numpy(padded), n_bins=4, sensor_size=(7, 9), lengths=[200, 120])
        for k, e in enumerate((a, b)):
            torch.testing.assert_close(grid[k], F.to_voxel_grid(e, n_bins=4, sensor_size=(7, 9)))

    def test_hard_cases(self):
        empty = torch.zeros(0, 4, dtype=torch.int64)
        assert F.to_voxel_grid(empty, n_bins=3, sensor_size=(2, 2)).abs().sum() == 0
        same_time = torch.tensor([[0, 0, 7, 1], [1, 1, 7, 0]])
        grid = F.to_voxel_grid(same_time, n_bins=3, sensor_size=(2, 2))
        assert grid[0, 0].tolist() == [[1.0, 0.0], [0.0, -1.0]] and grid[1:].abs().sum() == 0
        outside = torch.tensor([[5, 0, 0, 1], [0, 0, 10, 1]])
        assert F.to_voxel_grid(outside, n_bins=2, sensor_size=(2, 2)).sum() == 1
        with pytest.raises(ValueError, match="n_bins"):
            F.to_voxel_grid(same_time, n_bins=0, sensor_size=(2, 2))
        with pytest.raises(ValueError, match="polarity"):
            F.to_voxel_grid(same_time, n_bins=2, sensor_size=(2, 2), polarity="both")

    def test_against_tonic(self):
        # tonic 1.7 scales time by n_bins, not n_bins - 1 as Zhu et al. (and its own
        # docstring) do, so the events at the last timestamp fall past its last bin: its grid
        # of n bins is ours of n + 1 bins without the last one.
        functional = _tonic_functional()
        events = _events()
        expected = functional.to_voxel_grid_numpy(_int_polarity(events), (9, 7, 2), n_time_bins=5)
        grid = F.to_voxel_grid(events, n_bins=6, sensor_size=(7, 9))[:5]
        torch.testing.assert_close(grid, torch.as_tensor(np.asarray(expected), dtype=torch.float32), atol=1e-5, rtol=1e-5)


def _int_polarity(events):
    """A copy with integer polarity: tonic 1.7's voxel grid rewrites the polarity of its
    input in place (0 -> -1), which a bool field turns into all ON."""
    out = np.zeros(len(events), dtype=[("x", "<i8"), ("y", "<i8"), ("t", "<i8"), ("p", "<i8")])
    for name in ("x", "y", "t", "p"):
        out[name] = events[name]
    return out


def _tonic_functional():
    pytest.importorskip("tonic")
    import tonic.functional

    return tonic.functional


class TestTimeSurface:
    @pytest.mark.parametrize("tau_ms", [5.0, 40.0])
    def test_against_reference(self, tau_ms):
        events = _events(span=70_000)
        out = F.to_time_surface(events, tau_ms=tau_ms, frame_ms=10.0, n_frames=6, sensor_size=(7, 9))
        torch.testing.assert_close(out, _reference_surface(events, tau_ms, 10.0, 6, 7, 9), atol=1e-6, rtol=1e-5)
        assert out.shape == (6, 2, 7, 9) and bool(((out >= 0) & (out <= 1)).all())

    def test_start_and_batch(self):
        a, b = _events(seed=3), _events(seed=4)
        rows = np.stack([np.stack([e["x"], e["y"], e["t"], e["p"]], 1).astype(np.int64) for e in (a, b)])
        out = F.to_time_surface(torch.from_numpy(rows), tau_ms=20.0, t_start=[0, 10_000], n_frames=3, sensor_size=(7, 9))
        torch.testing.assert_close(out[0], _reference_surface(a, 20.0, 10.0, 3, 7, 9))
        torch.testing.assert_close(out[1], _reference_surface(b, 20.0, 10.0, 3, 7, 9, t_start=10_000))

    def test_absolute_timestamps_bin_like_relative_ones(self):
        """The default t_start="floor" anchors at the first event's frame: a recording at
        1.7e15 µs gives the surface of the same events at small times, not zeros."""
        events = _events(span=50_000)
        offset = 1_700_000_000_000_000  # a multiple of the 10 ms frame
        shifted = events.copy()
        shifted["t"] = shifted["t"].astype(np.int64) + offset
        relative = F.to_time_surface(events, tau_ms=20.0, n_frames=5, sensor_size=(7, 9), t_start=0)
        absolute = F.to_time_surface(shifted, tau_ms=20.0, n_frames=5, sensor_size=(7, 9))
        torch.testing.assert_close(absolute, relative)
        assert float(absolute.sum()) > 0
        first = F.to_time_surface(shifted, tau_ms=20.0, n_frames=5, sensor_size=(7, 9), t_start="first")
        anchored = F.to_time_surface(shifted, tau_ms=20.0, n_frames=5, sensor_size=(7, 9),
                                     t_start=int(shifted["t"].min()))
        torch.testing.assert_close(first, anchored)

    def test_window_without_events_is_refused(self):
        events = torch.tensor([[0, 0, 1_700_000_000_000_000, 1]], dtype=torch.int64)
        with pytest.raises(ValueError, match="t_start.*frame_ms.*n_frames"):
            F.to_time_surface(events, tau_ms=10.0, t_start=0, sensor_size=(1, 1))
        with pytest.raises(ValueError, match="t_start"):
            F.to_time_surface(events, tau_ms=10.0, t_start="last", sensor_size=(1, 1))
        empty = F.to_time_surface(torch.zeros(0, 4, dtype=torch.int64), tau_ms=10.0, n_frames=2, sensor_size=(1, 1))
        assert empty.shape == (2, 2, 1, 1) and float(empty.sum()) == 0  # no events: zeros, no error

    def test_named_errors(self):
        events = torch.tensor([[0, 0, 0, 1]])
        with pytest.raises(ValueError, match="tau_ms"):
            F.to_time_surface(events, tau_ms=0.0, sensor_size=(1, 1))
        with pytest.raises(ValueError, match="polarity"):
            F.to_time_surface(torch.tensor([[0, 0, 0, 2]]), tau_ms=1.0, sensor_size=(1, 1))

    def test_against_tonic(self):
        # tonic anchors its slices at the first event and drops the last, incomplete one
        functional = _tonic_functional()
        events = _events(span=60_000)
        expected = np.asarray(functional.to_timesurface_numpy(_int_polarity(events), (9, 7, 2), dt=10_000, tau=20_000))
        out = F.to_time_surface(
            events, tau_ms=20.0, frame_ms=10.0, n_frames=len(expected), sensor_size=(7, 9), t_start=int(events["t"][0])
        )
        torch.testing.assert_close(out, torch.as_tensor(expected, dtype=torch.float32), atol=1e-6, rtol=1e-5)
