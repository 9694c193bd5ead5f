"""Tests for ``event_transforms.functional.events.events_to_frames``."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from event_transforms.functional.events import EventsOutsideSensorWarning, events_to_frames

TONIC_DTYPE = [("x", int), ("y", int), ("t", int), ("p", int)]


def reference(x, y, t, p, *, t_start, frame_ms, n_frames, sensor_size, crop=None, pool=1):
    """Slow, obvious reference: one event at a time."""
    height, width = sensor_size
    top, left, crop_h, crop_w = crop if crop is not None else (0, 0, height, width)
    out = np.zeros((n_frames, 2, crop_h // pool, crop_w // pool), dtype=np.int64)
    for xi, yi, ti, pi in zip(x, y, t, p):
        xi, yi = math.floor(xi), math.floor(yi)
        if not (0 <= xi < width and 0 <= yi < height):
            continue
        if not (top <= yi < top + crop_h and left <= xi < left + crop_w):
            continue
        for i in range(n_frames):
            lo = t_start + i * frame_ms * 1000
            hi = t_start + (i + 1) * frame_ms * 1000
            if lo <= ti < hi:
                channel = 1 if pi > 0 else 0
                out[i, channel, (yi - top) // pool, (xi - left) // pool] += 1
    return torch.from_numpy(out)


def random_events(rng, n, *, sensor_size=(17, 11), t_max=400_000, margin=3):
    height, width = sensor_size
    x = rng.integers(-margin, width + margin, n)
    y = rng.integers(-margin, height + margin, n)
    t = rng.integers(-20_000, t_max, n)
    p = rng.integers(0, 2, n)
    return x, y, t, p


def structured(x, y, t, p):
    events = np.zeros(len(x), dtype=TONIC_DTYPE)
    events["x"], events["y"], events["t"], events["p"] = x, y, t, p
    return events


class TestEventsToFrames:
    def test_matches_reference_with_out_of_range_unsorted_events(self):
        rng = np.random.default_rng(0)
        x, y, t, p = random_events(rng, 3000)  # unsorted timestamps, some off-sensor
        kwargs = dict(t_start=5_000, frame_ms=10.0, n_frames=36, sensor_size=(17, 11))
        expected = reference(x, y, t, p, **kwargs)
        with pytest.warns(EventsOutsideSensorWarning, match="events lie outside sensor_size"):
            got = events_to_frames(structured(x, y, t, p), **kwargs)
        assert got.dtype == torch.float32 and got.shape == (36, 2, 17, 11)
        torch.testing.assert_close(got, expected.float(), rtol=0, atol=0)

    def test_bin_edges_are_half_open(self):
        edges = [0, 9_999, 10_000, 19_999, 20_000, 29_999, 30_000, -1]
        events = {"x": [0] * 8, "y": [0] * 8, "t": edges, "p": [1] * 8}
        got = events_to_frames(events, t_start=0, n_frames=3, sensor_size=(1, 1))
        assert got[:, 1, 0, 0].tolist() == [2.0, 2.0, 2.0]
        assert got.sum().item() == 6

    def test_anchored_at_t_start_not_first_event(self):
        events = {"x": [0, 0], "y": [0, 0], "t": [1_000_025_000, 1_000_031_000], "p": [0, 1]}
        got = events_to_frames(events, t_start=1_000_000_000, n_frames=4, sensor_size=(1, 1))
        assert got[2, 0, 0, 0] == 1 and got[3, 1, 0, 0] == 1 and got.sum() == 2

    def test_crop_and_pool_match_reference(self):
        rng = np.random.default_rng(1)
        x, y, t, p = random_events(rng, 5000, sensor_size=(180, 240), t_max=360_000)
        crop = (20, 45, 140, 150)
        with pytest.warns(EventsOutsideSensorWarning):
            got = events_to_frames(
                structured(x, y, t, p), t_start=0, n_frames=36, crop=crop, pool=2, dtype=torch.int64
            )
        expected = reference(
            x, y, t, p, t_start=0, frame_ms=10.0, n_frames=36, sensor_size=(180, 240),
            crop=crop, pool=2,
        )
        assert got.shape == (36, 2, 70, 75)
        assert torch.equal(got, expected)

    def test_pool_sums_blocks(self):
        rng = np.random.default_rng(2)
        x, y, t, p = random_events(rng, 2000, sensor_size=(8, 6), margin=0)
        full = events_to_frames(
            structured(x, y, t, p), t_start=0, n_frames=36, sensor_size=(8, 6), dtype=torch.int64
        )
        pooled = events_to_frames(
            structured(x, y, t, p), t_start=0, n_frames=36, sensor_size=(8, 6), pool=2, dtype=torch.int64
        )
        summed = full.view(36, 2, 4, 2, 3, 2).sum(dim=(3, 5))
        assert torch.equal(pooled, summed)

    def test_empty_input(self):
        got = events_to_frames(np.zeros(0, dtype=TONIC_DTYPE), n_frames=5, sensor_size=(3, 4))
        assert got.shape == (5, 2, 3, 4) and got.sum() == 0
        got = events_to_frames(torch.zeros(0, 4), n_frames=2, sensor_size=(3, 4))
        assert got.shape == (2, 2, 3, 4) and got.sum() == 0

    @pytest.mark.parametrize("on, off", [(1, 0), (1, -1), (True, False)])
    def test_polarity_conventions(self, on, off):
        events = {"x": [0, 0, 0], "y": [0, 0, 0], "t": [0, 1, 2], "p": np.array([on, off, off])}
        got = events_to_frames(events, n_frames=1, sensor_size=(1, 1))
        assert got.flatten().tolist() == [2.0, 1.0]  # channel 0 = OFF, channel 1 = ON

    def test_bad_polarity_raises(self):
        with pytest.raises(ValueError, match="polarity"):
            events_to_frames({"x": [0], "y": [0], "t": [0], "p": [2]}, sensor_size=(1, 1))

    def test_tensor_and_structured_inputs_agree(self):
        rng = np.random.default_rng(3)
        x, y, t, p = random_events(rng, 1000)
        rows = torch.tensor(np.stack([x, y, t, p], axis=1), dtype=torch.float64)
        with pytest.warns(EventsOutsideSensorWarning):
            a = events_to_frames(rows, sensor_size=(17, 11), t_start=1_000)
            b = events_to_frames(structured(x, y, t, p), sensor_size=(17, 11), t_start=1_000)
            c = events_to_frames(
                {"x": torch.tensor(x), "y": torch.tensor(y), "t": torch.tensor(t), "p": torch.tensor(p)},
                sensor_size=(17, 11),
                t_start=1_000,
            )
        assert torch.equal(a, b) and torch.equal(b, c)

    def test_narrow_structured_fields(self):
        events = np.zeros(4, dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("p", "?")])
        events["x"], events["y"], events["t"], events["p"] = [0, 1, 1, 2], [0, 0, 1, 1], [0, 5, 9, 11], [
            True, False, True, True,
        ]
        got = events_to_frames(events, t_start=0, frame_ms=0.01, n_frames=2, sensor_size=(2, 3))
        assert got.sum() == 4 and got[1, 1, 1, 2] == 1

    def test_batch_with_lengths_equals_per_stream(self):
        rng = np.random.default_rng(4)
        streams = [random_events(rng, n) for n in (0, 1, 700, 300)]
        longest = max(len(s[0]) for s in streams)
        padded = torch.full((4, longest, 4), -7.0, dtype=torch.float64)  # garbage padding
        for i, s in enumerate(streams):
            padded[i, : len(s[0])] = torch.tensor(np.stack(s, axis=1), dtype=torch.float64)
        lengths = torch.tensor([len(s[0]) for s in streams])
        starts = torch.tensor([0, 10_000, 20_000, 0])
        kwargs = dict(n_frames=36, sensor_size=(17, 11))
        with pytest.warns(EventsOutsideSensorWarning):
            got = events_to_frames(padded, lengths=lengths, t_start=starts, **kwargs)
        mask = torch.arange(longest) < lengths[:, None]
        with pytest.warns(EventsOutsideSensorWarning):
            via_mask = events_to_frames(padded, mask=mask, t_start=starts, chunk_size=64, **kwargs)
        assert got.shape == (4, 36, 2, 17, 11) and torch.equal(got, via_mask)
        for i, s in enumerate(streams):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", EventsOutsideSensorWarning)
                one = events_to_frames(structured(*s), t_start=int(starts[i]), **kwargs)
            assert torch.equal(got[i], one)

    def test_batch_of_zero_streams(self):
        got = events_to_frames(torch.zeros(0, 5, 4), n_frames=36, lengths=torch.zeros(0, dtype=torch.long))
        assert got.shape == (0, 36, 2, 180, 240)

    @pytest.mark.parametrize(
        "dtype", [torch.uint8, torch.int16, torch.int32, torch.int64, torch.float16,
                  torch.bfloat16, torch.float64]
    )
    def test_dtypes(self, dtype):
        events = {"x": [0] * 5, "y": [0] * 5, "t": [0] * 5, "p": [1] * 5}
        got = events_to_frames(events, n_frames=1, sensor_size=(1, 1), dtype=dtype)
        assert got.dtype == dtype and got[0, 1, 0, 0].item() == 5

    def test_count_too_large_for_dtype_raises(self):
        n = 300
        events = {"x": [0] * n, "y": [0] * n, "t": [0] * n, "p": [1] * n}
        with pytest.raises(ValueError, match="uint8"):
            events_to_frames(events, n_frames=1, sensor_size=(1, 1), dtype=torch.uint8)

    def test_one_pixel_with_a_million_events(self):
        n = 10**6
        events = torch.zeros(n, 4, dtype=torch.int64)
        events[:, 3] = 1
        got = events_to_frames(events, n_frames=1, sensor_size=(1, 1))
        assert got[0, 1, 0, 0].item() == n and got[0, 0, 0, 0].item() == 0

    def test_float_coordinates_are_floored(self):
        events = torch.tensor([[0.9, 1.5, 0.0, 1.0], [-0.5, 0.0, 0.0, 1.0]])
        with pytest.warns(EventsOutsideSensorWarning, match="1 of 2 events"):
            got = events_to_frames(events, n_frames=1, sensor_size=(2, 2))
        assert got[0, 1, 1, 0] == 1 and got.sum() == 1  # x = -0.5 is off the sensor

    def test_input_unchanged(self):
        events = torch.tensor([[1, 1, 5, 0], [0, 0, 15_000, 1]])
        before, version = events.clone(), events._version
        events_to_frames(events, sensor_size=(2, 2), chunk_size=1)
        assert torch.equal(events, before) and events._version == version

    @pytest.mark.parametrize(
        "kwargs, match",
        [
            (dict(crop=(0, 0, 3, 3)), "divisible"),
            (dict(crop=(0, 0, 5, 4), pool=1), "inside the sensor"),
            (dict(crop=(0, 0, 2)), "four integers"),
            (dict(frame_ms=0), "frame_ms"),
            (dict(n_frames=0), "n_frames"),
            (dict(sensor_size=(4,)), "sensor_size"),
            (dict(sensor_size=(4, 4, 2)), r"tonic_sensor_size=\(4, 4, 2\)"),
            (dict(t_start="last"), "t_start"),
            (dict(chunk_size=0), "chunk_size"),
            (dict(pool=0), "pool"),
        ],
    )
    def test_bad_options_raise(self, kwargs, match):
        kwargs.setdefault("pool", 2)
        with pytest.raises(ValueError, match=match):
            events_to_frames(torch.zeros(1, 4), sensor_size=kwargs.pop("sensor_size", (4, 4)), **kwargs)

    def test_bad_events_raise(self):
        with pytest.raises(ValueError, match=r"\(N, 4\)"):
            events_to_frames(torch.zeros(3, 3))
        with pytest.raises(TypeError, match="events"):
            events_to_frames([1, 2, 3, 4])
        with pytest.raises(ValueError, match="fields"):
            events_to_frames(np.zeros(2, dtype=[("x", int), ("y", int), ("t", int)]))
        with pytest.raises(ValueError, match="lengths"):
            events_to_frames(torch.zeros(5, 4), lengths=[5])
        with pytest.raises(ValueError, match="lengths"):
            events_to_frames(torch.zeros(2, 5, 4), lengths=[5, 6])
        with pytest.raises(ValueError, match="mask"):
            events_to_frames(torch.zeros(2, 5, 4), mask=torch.ones(2, 4, dtype=torch.bool))


class TestEventsToFramesProperties:
    @settings(max_examples=60, deadline=None)
    @given(
        seed=st.integers(0, 2**32 - 1),
        n=st.integers(0, 300),
        t_start=st.integers(-50_000, 50_000),
        frame_ms=st.sampled_from([0.5, 1.0, 10.0, 33.3]),
        n_frames=st.integers(1, 12),
        size=st.tuples(st.integers(1, 9), st.integers(1, 9)),
    )
    def test_counts_every_event_in_the_window_once(self, seed, n, t_start, frame_ms, n_frames, size):
        rng = np.random.default_rng(seed)
        x, y, t, p = random_events(rng, n, sensor_size=size, t_max=200_000)
        inside = (x >= 0) & (x < size[1]) & (y >= 0) & (y < size[0])
        rel = (t - t_start) / (frame_ms * 1000)
        in_window = (rel >= 0) & (np.floor(rel) < n_frames)
        inside &= in_window
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EventsOutsideSensorWarning)
            if n and not in_window.any():
                with pytest.raises(ValueError, match="t_start"):
                    events_to_frames(structured(x, y, t, p), t_start=t_start, frame_ms=frame_ms,
                                     n_frames=n_frames, sensor_size=size)
                return
            got = events_to_frames(
                structured(x, y, t, p), t_start=t_start, frame_ms=frame_ms, n_frames=n_frames,
                sensor_size=size, dtype=torch.int64, chunk_size=97,
            )
        assert int(got.sum()) == int(inside.sum())
        assert int(got[:, 1].sum()) == int((inside & (p == 1)).sum())
