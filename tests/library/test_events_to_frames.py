"""Tests for ``event_transforms.functional.events_to_frames`` (``event_transforms.events.events_to_frames``)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms.events.binning import events_to_frames
from event_transforms.events.dropped import EventsOutsideSensorWarning, EventsOutsideWindowWarning
from event_transforms.events.streaming import iter_frames

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
        with pytest.warns(EventsOutsideSensorWarning, match="events outside sensor_size were dropped") as record:
            got = events_to_frames(structured(x, y, t, p), **kwargs)
        sensor = [w.message for w in record if isinstance(w.message, EventsOutsideSensorWarning)][0]
        assert sensor.dropped == int(((x < 0) | (x >= 11) | (y < 0) | (y >= 17)).sum()) > 0 and sensor.total == 3000
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
                structured(x, y, t, p), sensor_size=(180, 240), t_start=0, n_frames=36, crop=crop, pool=2,
                dtype=torch.int64,
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
        got = events_to_frames(torch.zeros(0, 5, 4), sensor_size=(180, 240), n_frames=36, lengths=torch.zeros(0, dtype=torch.long))
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
        with pytest.warns(EventsOutsideSensorWarning) as record:
            got = events_to_frames(events, n_frames=1, sensor_size=(2, 2))
        assert (record[0].message.dropped, record[0].message.total) == (1, 2)
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
            events_to_frames(sensor_size=(180, 240), events=torch.zeros(5, 4), lengths=[5])
        with pytest.raises(ValueError, match="lengths"):
            events_to_frames(sensor_size=(180, 240), events=torch.zeros(2, 5, 4), lengths=[5, 6])
        with pytest.raises(ValueError, match="mask"):
            events_to_frames(sensor_size=(180, 240), events=torch.zeros(2, 5, 4), mask=torch.ones(2, 4, dtype=torch.bool))


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


# --------------------------------------------------------------------------- real recordings

#: ``tonic.io.read_aedat4`` on a DVXplorer file: the polarity field is named ``on``, titled ``p``.
AEDAT4_DTYPE = np.dtype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])
#: ``tonic.io.events_struct`` (tonic 1.7), written out so the tests need no tonic.
TONIC_EVENTS_STRUCT = np.dtype([("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "?")])
EPOCH_US = 1_700_000_000_000_000  # 2023-11-14 in microseconds since the epoch


def slow_start(t, mode, frame_us):
    """The first bin's start in Python integers."""
    first = int(min(int(v) for v in t))
    return first if mode == "first" else (first // frame_us) * frame_us


def slow_reference(x, y, t, p, *, t_start, frame_us, n_frames, sensor_size, crop=None, pool=1):
    """Bin by bin in Python integers: frame i holds t_start + i*frame_us <= t < t_start + (i+1)*frame_us."""
    height, width = sensor_size
    top, left, crop_h, crop_w = crop if crop is not None else (0, 0, height, width)
    out = np.zeros((n_frames, 2, crop_h // pool, crop_w // pool), dtype=np.int64)
    for i in range(n_frames):
        lo, hi = t_start + i * frame_us, t_start + (i + 1) * frame_us
        for xi, yi, ti, pi in zip(x.tolist(), y.tolist(), t.tolist(), p.tolist()):
            if lo <= int(ti) < hi and top <= yi < top + crop_h and left <= xi < left + crop_w:
                out[i, int(pi > 0), (yi - top) // pool, (xi - left) // pool] += 1
    return torch.from_numpy(out)


def recording(rng, n, *, dtype=AEDAT4_DTYPE, sensor_size=(240, 320), span_us=95_000, start=EPOCH_US + 4_321,
              sort=True, polarity=(False, True)):
    """``n`` events of a ``sensor_size`` sensor at absolute times, in a structured array of ``dtype``."""
    height, width = sensor_size
    events = np.zeros(n, dtype=dtype)
    t = start + rng.integers(0, span_us, n, dtype=np.int64)
    events["t"] = np.sort(t) if sort else t
    events["x"] = rng.integers(0, width, n)
    events["y"] = rng.integers(0, height, n)
    events["p"] = rng.choice(np.array(polarity), n)
    return events


class TestRealRecordings:
    @pytest.mark.parametrize("mode", ["floor", "first"])
    @pytest.mark.parametrize("dtype", [AEDAT4_DTYPE, TONIC_EVENTS_STRUCT], ids=["aedat4", "events_struct"])
    def test_tonic_dtypes_with_absolute_timestamps_match_reference(self, mode, dtype):
        events = recording(np.random.default_rng(0), 400, dtype=dtype)
        t0 = slow_start(events["t"], mode, 10_000)
        last = int(events["t"].max())
        n_frames = (last - t0) // 10_000 + 1
        expected = slow_reference(
            events["x"], events["y"], events["t"], events["p"], t_start=t0, frame_us=10_000,
            n_frames=n_frames, sensor_size=(240, 320),
        )
        got = events_to_frames(events, sensor_size=(240, 320), t_start=mode, dtype=torch.int64)
        assert got.shape == (n_frames, 2, 240, 320)
        assert torch.equal(got, expected) and int(got.sum()) == len(events)  # nothing lost

    def test_floor_default_puts_bins_on_the_clock_grid(self):
        events = recording(np.random.default_rng(1), 300)
        floor = events_to_frames(events, sensor_size=(240, 320), dtype=torch.int64)
        explicit = events_to_frames(
            events, sensor_size=(240, 320), t_start=np.uint64(EPOCH_US), dtype=torch.int64
        )  # EPOCH_US is a multiple of 10 ms, and the first event lies after it
        assert torch.equal(floor, explicit)

    def test_events_exactly_on_absolute_bin_edges(self):
        t = np.array([EPOCH_US + k * 10_000 + d for k in range(4) for d in (-1, 0, 1)], dtype=np.uint64)
        events = np.zeros(len(t), dtype=AEDAT4_DTYPE)
        events["t"], events["p"] = t, True
        got = events_to_frames(events, sensor_size=(1, 1), t_start=EPOCH_US, n_frames=3, dtype=torch.int64)
        # frame k holds EPOCH_US + k*10 ms exactly, and the microsecond before the next edge
        assert got[:, 1, 0, 0].tolist() == [3, 3, 3]
        floor = events_to_frames(events, sensor_size=(1, 1), dtype=torch.int64)  # first is EPOCH_US - 1
        assert floor[:, 1, 0, 0].tolist() == [1, 3, 3, 3, 2]

    def test_timestamps_near_2_63_stay_exact(self):
        base = 2**62 + 3  # float64 would round this to a multiple of 1024
        events = {"x": [0, 0, 0], "y": [0, 0, 0], "t": np.array([base, base + 9_999, base + 10_000], np.uint64),
                  "p": [1, 1, 1]}
        with pytest.raises(ValueError, match="nanoseconds. Pass time_unit='ns'"):  # past the year 5138 as µs
            events_to_frames(events, sensor_size=(1, 1), t_start="first", dtype=torch.int64)
        got = events_to_frames(events, sensor_size=(1, 1), t_start="first", dtype=torch.int64, time_unit="us")
        assert got[:, 1, 0, 0].tolist() == [2, 1]

    def test_uint64_rows_numpy_and_torch(self):
        events = recording(np.random.default_rng(2), 200)
        rows = np.stack([events["x"], events["y"], events["t"], events["p"]], axis=1).astype(np.uint64)
        expected = events_to_frames(events, sensor_size=(240, 320))
        assert torch.equal(events_to_frames(rows, sensor_size=(240, 320)), expected)
        assert torch.equal(events_to_frames(torch.from_numpy(rows), sensor_size=(240, 320)), expected)
        as_int64 = torch.from_numpy(rows.astype(np.int64))
        assert torch.equal(events_to_frames(as_int64, sensor_size=(240, 320), chunk_size=33), expected)

    def test_uint64_past_int64_is_refused_by_name(self):
        rows = np.array([[0, 0, 2**63 + 5, 1]], dtype=np.uint64)
        with pytest.raises(ValueError, match=r"events\['t'\].*2\*\*63"):
            events_to_frames(rows, sensor_size=(1, 1))
        with pytest.raises(ValueError, match=r"events\['t'\].*2\*\*63"):
            events_to_frames(torch.from_numpy(rows), sensor_size=(1, 1))
        with pytest.raises(ValueError, match="t_start"):
            events_to_frames(rows[:, :] * 0, sensor_size=(1, 1), t_start=np.uint64(2**64 - 1))

    @pytest.mark.parametrize(
        "fields",
        [
            [("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")],
            [("t", "<u4"), ("x", "<u1"), ("y", "<u1"), ("p", "<i2")],
            [("x", "<i8"), ("y", "<i8"), ("p", "<u1"), ("t", "<f8")],
            [("y", ">u2"), ("x", ">u2"), ("timestamp", ">i8"), ("polarity", "?")],
        ],
    )
    def test_any_integer_width_and_field_order(self, fields):
        rng = np.random.default_rng(3)
        x, y = rng.integers(0, 11, 300), rng.integers(0, 9, 300)
        t, p = rng.integers(0, 2**31, 300), rng.integers(0, 2, 300)
        events = np.zeros(300, dtype=fields)
        names = events.dtype.names
        events[names[names.index("x")]], events["y"] = x, y
        events["timestamp" if "timestamp" in names else "t"] = t
        events["polarity" if "polarity" in names else "p"] = p
        kwargs = dict(sensor_size=(9, 11), t_start=0, frame_ms=100_000.0, n_frames=22, dtype=torch.int64)
        expected = events_to_frames({"x": x, "y": y, "t": t, "p": p}, **kwargs)
        assert torch.equal(events_to_frames(events, **kwargs), expected) and int(expected.sum()) == 300

    @pytest.mark.parametrize(
        "on, off", [(True, False), (1, 0), (1, -1), (1.0, 0.0), (1.0, -1.0), (np.uint8(1), np.uint8(0))]
    )
    def test_polarity_conventions_against_reference(self, on, off):
        rng = np.random.default_rng(4)
        events = recording(rng, 200, dtype=[("t", "<i8"), ("x", "<i4"), ("y", "<i4"), ("p", "<f8")])
        is_on = rng.random(200) < 0.5
        p = np.where(is_on, on, off)
        columns = {"x": events["x"], "y": events["y"], "t": events["t"], "p": p}
        got = events_to_frames(columns, sensor_size=(240, 320), t_start=EPOCH_US, n_frames=10, dtype=torch.int64)
        expected = slow_reference(events["x"], events["y"], events["t"], is_on.astype(int), t_start=EPOCH_US,
                                  frame_us=10_000, n_frames=10, sensor_size=(240, 320))
        assert torch.equal(got, expected)

    @pytest.mark.parametrize("p, match", [([2, 0], "got 2"), ([0.5, 1], "got 0.5"), ([-1, 0, 1], "mixes")])
    def test_other_polarities_are_refused_by_name(self, p, match):
        events = {"x": [0] * len(p), "y": [0] * len(p), "t": list(range(len(p))), "p": p}
        with pytest.raises(ValueError, match=f"polarity p.*{match}"):
            events_to_frames(events, sensor_size=(1, 1))

    def test_mixed_polarity_conventions_across_chunks_are_refused(self):
        events = {"x": [0] * 4, "y": [0] * 4, "t": [0, 1, 2, 3], "p": [0, 1, -1, 1]}
        with pytest.raises(ValueError, match="mixes"):
            events_to_frames(events, sensor_size=(1, 1), chunk_size=2)

    def test_numpy_scalars_for_every_numeric_argument(self):
        events = recording(np.random.default_rng(5), 300)
        kwargs = dict(t_start=EPOCH_US, frame_ms=10.0, n_frames=9, sensor_size=(240, 320),
                      crop=(40, 60, 140, 150), pool=2, chunk_size=2**20)
        expected = events_to_frames(events, **kwargs)
        scalars = dict(
            t_start=np.uint64(EPOCH_US), frame_ms=np.float32(10.0), n_frames=np.int64(9),
            sensor_size=(np.uint16(240), np.int32(320)), crop=tuple(np.int16(v) for v in (40, 60, 140, 150)),
            pool=np.uint8(2), chunk_size=np.int64(2**20),
        )
        assert torch.equal(events_to_frames(events, **scalars), expected)
        tensors = dict(kwargs, t_start=torch.tensor(EPOCH_US), frame_ms=torch.tensor(10.0), n_frames=torch.tensor(9))
        assert torch.equal(events_to_frames(events, **tensors), expected)
        assert torch.equal(events_to_frames(events, **dict(kwargs, t_start=float(EPOCH_US))), expected)

    def test_old_default_t_start_zero_gives_a_named_error_not_zeros(self):
        events = recording(np.random.default_rng(6), 50)
        with pytest.raises(ValueError, match=r"\[0, 360000\) µs set by t_start=0, frame_ms=10.0, n_frames=36.*span t = 17000000000"):
            events_to_frames(events, sensor_size=(240, 320), t_start=0, n_frames=36)

    def test_empty_window_names_the_stream_of_a_batch(self):
        rows = torch.tensor([[[0, 0, 5, 1], [0, 0, 6, 1]], [[0, 0, 10**9, 1], [0, 0, 10**9 + 1, 0]]])
        with pytest.raises(ValueError, match="stream 1 falls in the time window"):
            events_to_frames(rows, sensor_size=(1, 1), t_start=0, n_frames=5)

    def test_empty_input_is_not_an_error(self):
        empty = np.zeros(0, dtype=AEDAT4_DTYPE)
        assert events_to_frames(empty, sensor_size=(2, 3)).shape == (0, 2, 2, 3)
        assert events_to_frames(empty, sensor_size=(2, 3), n_frames=4).sum() == 0

    def test_n_frames_none_follows_each_stream_and_the_longest_sets_t(self):
        rows = torch.tensor([[[0, 0, 5, 1], [0, 0, 6, 1]], [[0, 0, 10_000, 1], [0, 0, 55_000, 0]]])
        got = events_to_frames(rows, sensor_size=(1, 1), dtype=torch.int64)  # floors per stream
        assert got.shape == (2, 5, 2, 1, 1)  # stream 1: bins from 10 ms, its last event in bin 4
        assert got[0, 0, 1].item() == 2 and got[1, 0, 1].item() == 1 and got[1, 4, 0].item() == 1

    def test_nanoseconds_read_as_microseconds_ask_for_n_frames(self):
        events = {"x": [0, 0], "y": [0, 0], "t": [0, 3_000_000_000], "p": [1, 1]}  # 3 s in ns
        with pytest.raises(ValueError, match="microseconds.*n_frames"):
            events_to_frames(events, sensor_size=(1, 1))

    def test_wrong_sensor_warns_with_counts_and_the_fitting_size(self):
        events = recording(np.random.default_rng(7), 1000)  # a 240×320 DVXplorer
        with pytest.warns(EventsOutsideSensorWarning) as record:
            got = events_to_frames(events, sensor_size=(180, 240))  # the paper's DAVIS240
        outside = int(((events["x"] >= 240) | (events["y"] >= 180)).sum())
        warning = record[0].message
        assert (warning.dropped, warning.total, warning.sensor_size) == (outside, 1000, (180, 240))
        assert warning.suggested_sensor_size == (240, 320) and not warning.swapped
        assert f"{outside:,} of 1,000 events" in str(warning) and "fit sensor_size=(240, 320)" in str(warning)
        assert int(got.sum()) == 1000 - outside

    def test_no_sensor_size_is_refused_as_by_the_module(self):
        """No silent DAVIS240 (issue 44): the function asks for the size as EventsToFrames does."""
        events = recording(np.random.default_rng(7), 100)
        with pytest.raises(TypeError, match=r"events_to_frames needs sensor_size=\(H, W\) or tonic_sensor_size"):
            events_to_frames(events)
        with pytest.raises(TypeError, match=r"EventsToFrames needs sensor_size=\(H, W\)"):
            et.EventsToFrames(n_frames=4)
        with pytest.raises(TypeError, match="iter_frames needs sensor_size"):
            list(et.functional.iter_frames([events]))

    def test_no_warning_for_the_crop_and_a_count_for_the_window_asked_for(self):
        """A crop drops events by design (no warning); a window the caller asked for drops
        them as asked, with their count reported (issue 19)."""
        events = recording(np.random.default_rng(8), 500)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = events_to_frames(events, sensor_size=(240, 320), crop=(100, 100, 20, 30))
        with pytest.warns(EventsOutsideWindowWarning) as record:
            got = events_to_frames(events, sensor_size=(240, 320), crop=(100, 100, 20, 30), n_frames=2)
        warning = record[0].message
        assert (warning.dropped, warning.per_stream) == (425, [(425, 500)]) and "n_frames=2" in warning.window
        assert got.shape == (2, 2, 20, 30)

    def test_tonic_sensor_size_by_name(self):
        events = recording(np.random.default_rng(9), 300)
        expected = events_to_frames(events, sensor_size=(240, 320))
        assert torch.equal(events_to_frames(events, tonic_sensor_size=(320, 240, 2)), expected)
        with pytest.raises(ValueError, match=r"sensor_size=\(240, 320\) or tonic_sensor_size=\(320, 240, 2\)"):
            events_to_frames(events, sensor_size=(320, 240, 2))
        with pytest.raises(ValueError, match="not both"):
            events_to_frames(events, sensor_size=(240, 320), tonic_sensor_size=(320, 240, 2))
        with pytest.raises(ValueError, match="P = 2"):
            events_to_frames(events, tonic_sensor_size=(320, 240, 1))

    def test_chunks_bound_what_is_converted_at_once(self, monkeypatch):
        import event_transforms.events._ingest as module

        seen = []
        original = module._column

        def spy(values, name):
            seen.append(len(values) if not isinstance(values, (np.ndarray, torch.Tensor)) else values.shape[-1])
            return original(values, name)

        monkeypatch.setattr(module, "_column", spy)
        events = recording(np.random.default_rng(10), 1000)
        chunked = events_to_frames(events, sensor_size=(240, 320), chunk_size=64)
        assert max(seen) == 64
        monkeypatch.setattr(module, "_column", original)
        assert torch.equal(chunked, events_to_frames(events, sensor_size=(240, 320)))

    def test_structured_input_unchanged(self):
        events = recording(np.random.default_rng(11), 100, sort=False)
        before = events.copy()
        events_to_frames(events, sensor_size=(240, 320), chunk_size=7)
        assert np.array_equal(events, before)

    def test_matches_tonic_to_frame(self):
        tonic = pytest.importorskip("tonic")
        from tonic.io import events_struct, make_structured_array
        from tonic.transforms import ToFrame

        rng = np.random.default_rng(12)
        n = 2000
        t = np.sort(EPOCH_US + rng.integers(0, 123_456, n))
        events = make_structured_array(rng.integers(0, 320, n), rng.integers(0, 240, n), t, rng.integers(0, 2, n),
                                       dtype=events_struct)
        expected = ToFrame(sensor_size=(320, 240, 2), time_window=10_000)(events)  # (T, P, H, W)
        got = events_to_frames(events, sensor_size=(240, 320), t_start="first", n_frames=len(expected),
                               dtype=torch.int64)
        assert tonic.__version__ and torch.equal(got, torch.from_numpy(expected.astype(np.int64)))
        assert events.dtype == TONIC_EVENTS_STRUCT  # the hand-written copy is tonic's dtype


# --------------------------------------------------------------------------- streaming


def chunked(events, sizes):
    """Cut ``events`` into consecutive pieces of the given sizes (cycled)."""
    out, i, k = [], 0, 0
    while i < len(events):
        out.append(events[i : i + sizes[k % len(sizes)]])
        i, k = i + sizes[k % len(sizes)], k + 1
    return out


class TestIterFrames:
    @pytest.mark.parametrize("sizes", [[1], [7, 1, 300], [10**6]])
    @pytest.mark.parametrize("t_start", ["floor", "first", EPOCH_US - 25_000])
    def test_equals_events_to_frames_on_the_whole_stream(self, sizes, t_start):
        events = recording(np.random.default_rng(13), 600, sensor_size=(9, 11), span_us=230_000)
        kwargs = dict(sensor_size=(9, 11), t_start=t_start, crop=(1, 1, 8, 10), pool=2, dtype=torch.int64)
        expected = events_to_frames(events, **kwargs)
        frames = list(iter_frames(iter(chunked(events, sizes)), frames_per_step=3, **kwargs))
        assert len(frames) == len(expected) and all(f.shape == (2, 4, 5) for f in frames)
        assert torch.equal(torch.stack(frames), expected)

    @pytest.mark.parametrize("n_frames", [1, 5, 40])
    def test_n_frames_equals_events_to_frames(self, n_frames):
        events = recording(np.random.default_rng(19), 900, sensor_size=(5, 6), span_us=230_000)
        kwargs = dict(sensor_size=(5, 6), n_frames=n_frames, dtype=torch.int64)
        frames = list(iter_frames(chunked(events, [50, 3]), frames_per_step=2, **kwargs))
        assert torch.equal(torch.stack(frames), events_to_frames(events, **kwargs))

    def test_gaps_give_empty_frames_and_n_frames_pads_and_stops(self):
        events = {"x": [0, 0, 0], "y": [0, 0, 0], "t": [0, 55_000, 99_000], "p": [1, 0, 1]}
        got = [f[:, 0, 0].tolist() for f in iter_frames([events], sensor_size=(1, 1), dtype=torch.int64)]
        assert got == [[0, 1], [0, 0], [0, 0], [0, 0], [0, 0], [1, 0], [0, 0], [0, 0], [0, 0], [0, 1]]
        padded = list(iter_frames([{k: v[:1] for k, v in events.items()}], sensor_size=(1, 1), n_frames=3))
        assert len(padded) == 3 and padded[0].sum() == 1 and padded[2].sum() == 0

    def test_stops_reading_once_n_frames_are_complete(self):
        def source():
            yield {"x": [0, 0], "y": [0, 0], "t": [0, 25_000], "p": [1, 1]}
            raise AssertionError("read past the window")

        frames = list(iter_frames(source(), sensor_size=(1, 1), n_frames=2))
        assert [int(f.sum()) for f in frames] == [1, 0]

    def test_frames_are_yielded_before_the_stream_ends(self):
        chunks = iter([{"x": [0], "y": [0], "t": [t], "p": [1]} for t in (0, 10_000, 20_000, 30_000)])
        stream = iter_frames(chunks, sensor_size=(1, 1))
        next(stream)
        assert len(list(chunks)) == 2  # the first frame needed two chunks, no more

    def test_unsorted_chunks_raise(self):
        chunks = [{"x": [0], "y": [0], "t": [20_000], "p": [1]}, {"x": [0], "y": [0], "t": [10_000], "p": [1]}]
        with pytest.raises(ValueError, match="sorted by t"):
            list(iter_frames(chunks, sensor_size=(1, 1)))

    def test_empty_window_and_outside_sensor(self):
        with pytest.raises(ValueError, match="t_start=0"):
            list(iter_frames([recording(np.random.default_rng(14), 5)], sensor_size=(240, 320), t_start=0,
                             n_frames=3))
        events = recording(np.random.default_rng(15), 100)
        with pytest.warns(EventsOutsideSensorWarning) as record:
            list(iter_frames(chunked(events, [30]), sensor_size=(180, 240)))
        assert record[0].message.suggested_sensor_size == (240, 320)

    def test_feeds_force_regressor_step(self):
        from event_transforms.tactile.models import ForceRegressor

        torch.manual_seed(0)
        model = ForceRegressor(hidden_channels=(4,), input_pool=4).eval()
        events = recording(np.random.default_rng(16), 3000, sensor_size=(16, 24), span_us=120_000)
        frames = events_to_frames(events, sensor_size=(16, 24))
        state, forces = None, []
        with torch.no_grad():
            for frame in iter_frames(chunked(events, [500]), sensor_size=(16, 24)):
                force, state = model.step(frame.unsqueeze(0), state)
                forces.append(force)
            whole = model(frames.unsqueeze(0))
        torch.testing.assert_close(torch.stack(forces, dim=1), whole)


# --------------------------------------------------------------------------- module


class TestEventsToFramesModule:
    def test_equals_the_functional(self):
        import event_transforms as et

        events = recording(np.random.default_rng(17), 500)
        module = et.EventsToFrames((240, 320), n_frames=8, crop=(40, 60, 140, 150), pool=2)
        got = module(events)
        expected = events_to_frames(events, sensor_size=(240, 320), n_frames=8, crop=(40, 60, 140, 150), pool=2)
        assert got.shape == (8, 2, 70, 75) and torch.equal(got, expected)
        assert torch.equal(et.EventsToFrames(tonic_sensor_size=(320, 240, 2), n_frames=8, crop=(40, 60, 140, 150),
                                             pool=2)(events), expected)

    def test_needs_a_sensor_size(self):
        import event_transforms as et

        with pytest.raises(TypeError, match="sensor_size"):
            et.EventsToFrames()
        with pytest.raises(ValueError, match="tonic_sensor_size"):
            et.EventsToFrames((320, 240, 2))
        with pytest.raises(ValueError, match="t_start"):
            et.EventsToFrames((2, 2), t_start="start")
        with pytest.raises(TypeError, match="dtype"):
            et.EventsToFrames((2, 2), dtype=torch.uint16)

    def test_composes_with_frame_transforms(self):
        import event_transforms as et

        events = recording(np.random.default_rng(18), 2000, sensor_size=(30, 40))
        to_frames = et.EventsToFrames((30, 40), n_frames=6)
        augment = et.Compose([et.RandomRotation(30.0), et.RandomFrameShift((-1, 1))])
        pipeline = et.Compose([to_frames, augment])
        got = pipeline(events, generator=torch.Generator().manual_seed(3))
        expected = augment(to_frames(events), generator=torch.Generator().manual_seed(3))
        assert got.shape == (6, 2, 30, 40) and torch.equal(got, expected)
        params = pipeline.make_params((1, 6, 2, 30, 40), generator=torch.Generator().manual_seed(4))
        assert torch.equal(pipeline(events, params=params), pipeline(events, params=params))
        frames, label = pipeline(events, 7.5)  # extra inputs pass through
        assert frames.shape == (6, 2, 30, 40) and label == 7.5
        nested = et.Compose([et.Compose([to_frames, et.HorizontalFlip()]), et.VerticalFlip()])
        assert torch.equal(nested(events), to_frames(events).flip(-1).flip(-2))

    def test_only_in_a_compose(self):
        import event_transforms as et

        to_frames = et.EventsToFrames((4, 4))
        et.Compose([et.HorizontalFlip(), to_frames])  # allowed: an EventBatch is binned mid-pipeline
        for make in (
            lambda: et.OneOf([to_frames, et.HorizontalFlip()]),
            lambda: et.RandomApply(to_frames),
        ):
            with pytest.raises(TypeError, match="EventsToFrames"):
                make()
        with pytest.raises(TypeError, match="event stream"):
            to_frames(torch.zeros(3, 2, 4, 4))

    def test_tonic_style_dataset_in_a_dataloader(self):
        import pickle

        import event_transforms as et

        class Recordings(torch.utils.data.Dataset):  # tonic's calling convention: transform(events)
            def __init__(self, transform):
                self.transform = transform

            def __len__(self):
                return 3

            def __getitem__(self, index):
                return self.transform(recording(np.random.default_rng(index), 300, sensor_size=(12, 16))), index

        transform = et.Compose([et.EventsToFrames((12, 16), n_frames=10), et.RandomHorizontalFlip()])
        transform = pickle.loads(pickle.dumps(transform))  # what a spawned worker receives
        frames, labels = next(iter(torch.utils.data.DataLoader(Recordings(transform), batch_size=3)))
        assert frames.shape == (3, 10, 2, 12, 16) and labels.tolist() == [0, 1, 2]
        assert frames.sum(dim=(1, 2, 3, 4)).tolist() == [300.0, 300.0, 300.0]

    def test_repr(self):
        import event_transforms as et

        module = et.EventsToFrames((180, 240), crop=(20, 45, 140, 150), pool=2, dtype=torch.int16)
        assert repr(module) == (
            "EventsToFrames(sensor_size=(180, 240), frame_ms=10.0, n_frames=None, t_start='floor', "
            "crop=(20, 45, 140, 150), pool=2, dtype=torch.int16)"
        )


class TestNoSilentLoss:
    """Issue 19, item 4: binning bounds memory by bytes, refuses dtypes that cannot hold the
    counts, and reports the events a requested window drops."""

    @staticmethod
    def _stream(n, t_high, seed=0, t_low=0):
        g = torch.Generator().manual_seed(seed)
        t = torch.sort(torch.randint(t_low, t_high, (n,), generator=g)).values
        return torch.stack([torch.randint(0, 240, (n,), generator=g), torch.randint(0, 180, (n,), generator=g), t, torch.randint(0, 2, (n,), generator=g)], 1)

    @pytest.mark.parametrize("t_high", [300_000_000, 400_000_000], ids=["300 s in us", "0.4 s in ns"])
    def test_long_recording_refused_quickly_by_bytes(self, t_high):
        import time

        start = time.perf_counter()
        with pytest.raises(ValueError, match=r"GB \([0-9,]+ bytes\) .*max_bytes=4,294,967,296.*iter_frames.*n_frames"):
            events_to_frames(self._stream(1000, t_high), sensor_size=(180, 240))
        assert time.perf_counter() - start < 2.0
        with pytest.raises(ValueError, match=r"n_frames asks for 40,000 frames"):
            events_to_frames(self._stream(1000, 10_000), sensor_size=(180, 240), n_frames=40_000)
        small = events_to_frames(self._stream(1000, 100_000), sensor_size=(180, 240), max_bytes=10**8)
        assert small.shape == (10, 2, 180, 240)
        with pytest.raises(ValueError, match="max_bytes=1,000"):
            events_to_frames(self._stream(1000, 100_000), sensor_size=(180, 240), max_bytes=1000)

    def test_bfloat16_that_cannot_hold_the_count_is_refused(self):
        one_pixel = torch.tensor([[3, 4, 10, 1]] * 257)
        with pytest.raises(ValueError, match=r"a pixel holds 257 events, more than dtype=torch.bfloat16 holds exactly \(256: 257 would become 256\)"):
            events_to_frames(one_pixel, sensor_size=(8, 8), dtype=torch.bfloat16)
        assert events_to_frames(one_pixel[:256], sensor_size=(8, 8), dtype=torch.bfloat16).sum().item() == 256
        assert events_to_frames(one_pixel, sensor_size=(8, 8), dtype=torch.int16).sum().item() == 257

    @pytest.mark.parametrize("dtype", [torch.uint16, torch.uint32])
    def test_unsigned_wide_dtypes_refused_by_name(self, dtype):
        with pytest.raises(TypeError, match=rf"dtype must be one the transforms take.*got {dtype}"):
            events_to_frames(torch.tensor([[3, 4, 10, 1]]), sensor_size=(8, 8), dtype=dtype)

    def test_floored_window_reports_the_events_it_drops(self):
        # a 360 ms window of a recording with absolute stamps: the floored grid needs a 37th bin
        events = self._stream(2000, 1_000_365_000, seed=3, t_low=1_000_005_000)
        with pytest.warns(EventsOutsideWindowWarning) as record:
            frames = events_to_frames(events, sensor_size=(180, 240), n_frames=36)
        assert "t_start='floor', n_frames=36" in record[0].message.window and "one more frame" in record[0].message.hint
        dropped = record[0].message.dropped
        assert dropped > 0 and int(frames.sum()) == 2000 - dropped
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert int(events_to_frames(events, sensor_size=(180, 240), n_frames=37).sum()) == 2000
