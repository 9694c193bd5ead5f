"""The one binning kernel against a slow, obvious reference, bin by bin.

Every binning entry point (``events_to_frames``, ``iter_frames``, ``bin_events``,
``EventsToFrames``) is compared with :func:`reference`, a Python loop over events in exact
integer arithmetic, on random streams: crop and pool, each ``t_start`` rule, ``n_frames``
windows, events off the sensor, narrow dtypes at and past their limits, empty streams,
one event, a million events in one pixel; and with tonic's ``ToFrame`` where tonic
defines the same frames.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from event_transforms import EventBatch, EventsToFrames
from event_transforms.events.binning import events_to_frames
from event_transforms.events.binning import bin_events
from event_transforms.events.streaming import iter_frames

EPOCH_US = 1_700_000_000_000_000
STRUCT = np.dtype([("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "?")])


def reference(events, *, sensor, frame_us, t_start="floor", n_frames=None, crop=None, pool=1):
    """Frames (T, 2, H', W') int64 by a loop over events, in Python integers."""
    height, width = sensor
    top, left, crop_h, crop_w = crop if crop is not None else (0, 0, height, width)
    times = [int(t) for t in events["t"]]
    if t_start == "first":
        start = min(times) if times else 0
    elif t_start == "floor":
        start = (min(times) // frame_us) * frame_us if times else 0
    else:
        start = int(t_start)
    if n_frames is None:
        n_frames = max(((t - start) // frame_us + 1 for t in times if t >= start), default=0)
    out = np.zeros((n_frames, 2, crop_h // pool, crop_w // pool), dtype=np.int64)
    for x, y, t, p in zip(events["x"].tolist(), events["y"].tolist(), times, events["p"].tolist()):
        if not (0 <= x < width and 0 <= y < height):
            continue
        if not (top <= y < top + crop_h and left <= x < left + crop_w):
            continue
        frame = (t - start) // frame_us
        if 0 <= frame < n_frames:
            out[frame, int(p > 0), (y - top) // pool, (x - left) // pool] += 1
    return torch.from_numpy(out)


def random_stream(seed, n, *, sensor=(18, 24), span_us=95_000, margin=2, sort=True, epoch=EPOCH_US):
    rng = np.random.default_rng(seed)
    events = np.zeros(n, dtype=STRUCT)
    events["x"] = rng.integers(-margin, sensor[1] + margin, n)
    events["y"] = rng.integers(-margin, sensor[0] + margin, n)
    t = epoch + rng.integers(0, span_us, n)
    events["t"] = np.sort(t) if sort else t
    events["p"] = rng.random(n) < 0.5
    return events


def quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kwargs)


CASES = [
    dict(),
    dict(t_start="first"),
    dict(t_start=EPOCH_US + 20_000, n_frames=4),
    dict(n_frames=3),
    dict(crop=(2, 4, 12, 16), pool=2),
    dict(crop=(0, 0, 18, 24), pool=3, t_start="first", n_frames=7),
    dict(crop=(5, 1, 9, 9), pool=3, t_start=EPOCH_US - 30_000),
]


class TestAgainstReference:
    @pytest.mark.parametrize("seed", range(4))
    @pytest.mark.parametrize("options", CASES, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "default")
    def test_every_entry_point_equals_the_reference(self, seed, options):
        sensor = (18, 24)
        events = random_stream(seed, 50 + 300 * seed, sensor=sensor)
        expected = reference(events, sensor=sensor, frame_us=10_000, **options)
        got = quiet(events_to_frames, events, sensor_size=sensor, dtype=torch.int64, **options)
        assert torch.equal(got, expected)
        small_chunks = quiet(events_to_frames, events, sensor_size=sensor, dtype=torch.int64, chunk_size=37, **options)
        assert torch.equal(small_chunks, expected)
        chunks = [events[i : i + 41] for i in range(0, len(events), 41)]
        streamed = quiet(lambda: list(iter_frames(chunks, sensor_size=sensor, dtype=torch.int64, frames_per_step=2,
                                                  **options)))
        assert torch.equal(torch.stack(streamed) if streamed else expected[:0], expected)
        grid = {k: v for k, v in options.items() if k in ("t_start", "n_frames")}
        batch = EventBatch.from_streams([events, events[: len(events) // 2]], sensor_size=sensor, frame_ms=10.0, **grid)
        frames = bin_events(batch, n_frames=expected.shape[0], crop=options.get("crop"), pool=options.get("pool", 1),
                            dtype=torch.int64)
        assert torch.equal(frames[0], expected)
        module = EventsToFrames(sensor, n_frames=expected.shape[0], crop=options.get("crop"), pool=options.get("pool", 1),
                                dtype=torch.int64, **{k: v for k, v in options.items() if k == "t_start"})
        assert torch.equal(quiet(module, events), expected)

    @pytest.mark.parametrize("seed", range(3))
    def test_unsorted_float_columns(self, seed):
        rng = np.random.default_rng(seed)
        n = 400
        x, y = rng.uniform(-1.5, 25.5, n), rng.uniform(-1.5, 19.5, n)
        t = EPOCH_US + rng.integers(0, 80_000, n)
        p = rng.choice([-1, 1], n)
        events = {"x": torch.from_numpy(x), "y": torch.from_numpy(y), "t": torch.from_numpy(t), "p": torch.from_numpy(p)}
        floored = np.zeros(n, dtype=[("x", "<i8"), ("y", "<i8"), ("t", "<i8"), ("p", "<i8")])
        floored["x"], floored["y"], floored["t"], floored["p"] = np.floor(x), np.floor(y), t, p
        for options in CASES:
            expected = reference(floored, sensor=(18, 24), frame_us=10_000, **options)
            got = quiet(events_to_frames, events, sensor_size=(18, 24), dtype=torch.int64, **options)
            assert torch.equal(got, expected), options

    def test_batch_of_padded_streams_equals_each_stream(self):
        streams = [random_stream(s, n) for s, n in ((0, 30), (1, 0), (2, 77))]
        rows = torch.zeros(3, 77, 4, dtype=torch.int64)
        for b, s in enumerate(streams):
            for k, name in enumerate("xytp"):
                rows[b, : len(s), k] = torch.from_numpy(s[name].astype(np.int64))
        got = quiet(events_to_frames, rows, sensor_size=(18, 24), lengths=[30, 0, 77], crop=(2, 4, 12, 16), pool=2,
                    dtype=torch.int64, t_start="first", n_frames=9)
        for b, s in enumerate(streams):
            assert torch.equal(got[b], reference(s, sensor=(18, 24), frame_us=10_000, t_start="first", n_frames=9,
                                                 crop=(2, 4, 12, 16), pool=2))

    @pytest.mark.parametrize(
        "frame_ms, last_us", [(1.0, 8_300_000), (10.0, 20_000_000), (7.3, 14_000_000), (0.0015, 3_000)],
        ids=["float32 quotient", "float64 quotient", "float64, 7.3 ms", "fractional microseconds"],
    )
    def test_bin_edges_exact(self, frame_ms, last_us):
        # events one microsecond either side of every edge, up to last_us (float32 quotient under 2**23 µs)
        frame_us = frame_ms * 1000
        edges = {round(k * frame_us) for k in range(1, int(last_us / frame_us), 37)}
        t = np.array(sorted({e + d for e in edges for d in (-1, 0, 1)} | {last_us}), dtype=np.int64)
        events = np.zeros(len(t), dtype=STRUCT)
        events["t"] = t
        if float(frame_us).is_integer():
            expected = reference(events, sensor=(1, 1), frame_us=int(frame_us), t_start=0)
        else:  # floor(t / frame) with the float64 quotient, as documented
            bins = np.floor(t / frame_us).astype(np.int64)
            expected = torch.zeros(int(bins.max()) + 1, 2, 1, 1, dtype=torch.int64)
            np.add.at(expected.numpy(), (bins, 0, 0, 0), 1)
        got = events_to_frames(events, sensor_size=(1, 1), t_start=0, frame_ms=frame_ms, dtype=torch.int64)
        assert torch.equal(got, expected)
        batch = EventBatch.from_streams([events], sensor_size=(1, 1), frame_ms=frame_ms, t_start=0)
        assert torch.equal(bin_events(batch, dtype=torch.int64)[0], expected)


class TestCountsAndDtypes:
    @pytest.mark.parametrize(
        "dtype, limit", [(torch.uint8, 255), (torch.int8, 127), (torch.int16, 32767), (torch.float16, 2048),
                         (torch.bfloat16, 256)]
    )
    def test_narrow_dtypes_hold_their_limit_and_refuse_one_more(self, dtype, limit):
        for n, fits in ((limit, True), (limit + 1, False)):
            events = np.zeros(n + 5, dtype=STRUCT)
            events["x"][n:] = 1  # a few events elsewhere: the total passes the limit either way
            events["p"] = True
            if fits:
                got = events_to_frames(events, sensor_size=(1, 2), dtype=dtype)
                assert got.dtype == dtype and got[0, 1, 0, 0].item() == limit and got[0, 1, 0, 1].item() == 5
                batch = EventBatch.from_streams([events], sensor_size=(1, 2))
                assert torch.equal(bin_events(batch, dtype=dtype)[0], got)
                assert torch.equal(next(iter_frames([events], sensor_size=(1, 2), dtype=dtype)), got[0])
            else:
                with pytest.raises(ValueError, match=str(dtype)):
                    events_to_frames(events, sensor_size=(1, 2), dtype=dtype)
                with pytest.raises(ValueError, match=str(dtype)):
                    bin_events(EventBatch.from_streams([events], sensor_size=(1, 2)), dtype=dtype)
                with pytest.raises(ValueError, match=str(dtype)):
                    next(iter_frames([events[: n // 2], events[n // 2 :]], sensor_size=(1, 2), dtype=dtype))

    def test_a_million_events_in_one_pixel(self):
        n = 10**6
        events = np.zeros(n, dtype=STRUCT)
        events["p"] = True
        got = events_to_frames(events, sensor_size=(2, 3))
        assert got.dtype == torch.float32 and got[0, 1, 0, 0].item() == n and got.sum().item() == n
        streamed = list(iter_frames([events[: n // 3], events[n // 3 :]], sensor_size=(2, 3)))
        assert len(streamed) == 1 and torch.equal(streamed[0], got[0])
        assert torch.equal(bin_events(EventBatch.from_streams([events], sensor_size=(2, 3)))[0], got)

    def test_empty_and_one_event(self):
        empty = np.zeros(0, dtype=STRUCT)
        assert events_to_frames(empty, sensor_size=(2, 3)).shape == (0, 2, 2, 3)
        assert events_to_frames(empty, sensor_size=(2, 3), n_frames=2).sum() == 0
        assert list(iter_frames([empty], sensor_size=(2, 3))) == []
        one = np.zeros(1, dtype=STRUCT)
        one["x"], one["y"], one["t"], one["p"] = 2, 1, EPOCH_US + 12_345, True
        got = events_to_frames(one, sensor_size=(2, 3))
        assert got.shape == (1, 2, 2, 3) and got[0, 1, 1, 2] == 1 and got.sum() == 1
        assert torch.equal(torch.stack(list(iter_frames([one], sensor_size=(2, 3)))), got)
        assert torch.equal(bin_events(EventBatch.from_streams([one, empty], sensor_size=(2, 3)))[0], got)

    def test_input_is_not_modified(self):
        events = random_stream(3, 200)
        tensor = torch.from_numpy(np.stack([events[k].astype(np.int64) for k in "xytp"], 1))
        before = tensor.clone()
        quiet(events_to_frames, tensor, sensor_size=(18, 24), crop=(2, 4, 12, 16), pool=2)
        assert torch.equal(tensor, before)


class TestAgainstTonic:
    @pytest.mark.parametrize("seed, n, span_us", [(0, 1, 5_000), (1, 500, 55_000), (2, 5_000, 1_000_000)])
    def test_equals_tonic_to_frame(self, seed, n, span_us):
        pytest.importorskip("tonic")
        from tonic.transforms import ToFrame

        events = random_stream(seed, n, sensor=(24, 32), span_us=span_us, margin=0)
        expected = ToFrame(sensor_size=(32, 24, 2), time_window=10_000.0)(events)  # (T, P, H, W), from the first event
        # tonic leaves out the last, partial window: n_frames drops the same events (with a warning)
        got = quiet(events_to_frames, events, sensor_size=(24, 32), t_start="first", n_frames=len(expected),
                    dtype=torch.int64)
        assert torch.equal(got, torch.from_numpy(expected.astype(np.int64)))


def _same_batch(a, b):
    return all(torch.equal(getattr(a, k), getattr(b, k)) for k in ("x", "y", "t", "p", "offsets")) and (
        a.t.dtype == b.t.dtype
    )


class TestFromStreamsValidation:
    FORMS = {
        "int16 struct": lambda s: s,
        "aedat4 (titled p, uint64 t, uint16 x/y)": lambda s: _aedat4(s),
        "int8 polarity -1/1": lambda s: _signed(s),
        "(N, 4) tensor": lambda s: torch.from_numpy(np.stack([s[k].astype(np.int64) for k in "xytp"], 1)),
        "float mapping": lambda s: {k: s[k].astype(np.float64) + (0.5 if k in "xy" else 0) for k in "xytp"},
    }

    @pytest.mark.parametrize("form", list(FORMS))
    def test_validate_false_gives_the_same_batch(self, form):
        streams = [self.FORMS[form](random_stream(s, n, margin=0)) for s, n in ((0, 40), (1, 0), (2, 300))]
        checked = EventBatch.from_streams(streams, sensor_size=(18, 24), frame_ms=10.0)
        trusted = EventBatch.from_streams(streams, sensor_size=(18, 24), frame_ms=10.0, validate=False)
        assert _same_batch(checked, trusted) and torch.equal(checked.t_start, trusted.t_start)
        # and both equal the column parser's reading of each stream
        for b, stream in enumerate(streams):
            expected = events_to_frames(stream, sensor_size=(18, 24), t_start=int(checked.t_start[b]),
                                        n_frames=12, dtype=torch.int64)
            assert torch.equal(bin_events(checked, n_frames=12, dtype=torch.int64)[b], expected)

    @pytest.mark.parametrize(
        "field, value, match",
        [("x", 40_000, "x must fit int16"), ("y", 2**15, "y must fit int16"), ("p", 2, "polarity"),
         ("t", 2**63 + 5, "past 2\\*\\*63")],
    )
    @pytest.mark.parametrize("form", ["aedat4", "int64 struct", "tensor"])
    def test_validate_refuses_each_bad_column_by_name(self, field, value, match, form):
        good = random_stream(0, 20, margin=0)
        if form == "aedat4":
            bad = _aedat4(good)
        else:
            bad = np.zeros(20, dtype=[("x", "<i8"), ("y", "<i8"), ("t", "<u8" if field == "t" else "<i8"), ("p", "<i8")])
            for k in "xytp":
                bad[k] = good[k]
        if form == "aedat4" and field == "p":
            bad = bad.astype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
        bad[field][3] = value
        if form == "tensor":
            if field == "t":
                pytest.skip("a tensor holds no uint64 past 2**63 in int64")
            bad = torch.from_numpy(np.stack([bad[k].astype(np.int64) for k in "xytp"], 1))
        with pytest.raises(ValueError, match=match):
            EventBatch.from_streams([good, bad], sensor_size=(18, 24))

    def test_collate_events_passes_validate(self):
        from event_transforms.events.batch import collate_events

        streams = [random_stream(s, 30, margin=0) for s in range(3)]
        checked, labels = collate_events([(s, float(i)) for i, s in enumerate(streams)], sensor_size=(18, 24))
        trusted, _ = collate_events([(s, float(i)) for i, s in enumerate(streams)], sensor_size=(18, 24),
                                    validate=False)
        assert _same_batch(checked, trusted) and labels.tolist() == [0.0, 1.0, 2.0]


def _aedat4(stream):
    out = np.zeros(len(stream), dtype=[("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])
    out["t"], out["x"], out["y"], out["p"] = stream["t"], stream["x"], stream["y"], stream["p"]
    return out


def _signed(stream):
    out = np.zeros(len(stream), dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "i1")])
    out["x"], out["y"], out["t"] = stream["x"], stream["y"], stream["t"]
    out["p"] = np.where(stream["p"], 1, -1)
    return out
