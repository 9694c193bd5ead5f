"""EventBatch, device binning, and the shared battery of every transform on events.

Each topic's event kernels are tested beside its frame kernels (``test_<topic>.py``,
class ``TestOnEvents``)."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
import torch

import event_transforms as et
from event_transforms.functional import EventBatch, bin_events, collate_events, events_to_frames
from event_transforms import functional as F
from event_transforms.functional import to_voxel_grid
from event_transforms.events import batch as batch_module
from event_transforms.events.batch import merge_streams, replace_streams
from event_transforms.transforms.base import slice_params

from tests.support.topics import collect
from tests.support.event_data import SENSOR, T, frames_of, make_batch, make_streams, rows

# --------------------------------------------------------------------------- EventBatch


class TestEventBatch:
    def test_tonic_dtypes_and_layout(self):
        aedat4 = np.dtype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])
        a = np.zeros(3, dtype=aedat4)
        a["t"] = 1_700_000_000_000_000 + np.array([0, 12_000, 25_000])
        a["x"], a["y"], a["p"] = [0, 16, 3], [10, 0, 2], [True, False, True]
        signed = {"x": np.array([1]), "y": np.array([2]), "t": np.array([7]), "polarity": np.array([-1])}
        batch = EventBatch.from_streams([a, signed, torch.zeros(0, 4)], sensor_size=SENSOR)
        assert len(batch) == 3 and batch.lengths == [3, 1, 0]
        assert (batch.x.dtype, batch.y.dtype, batch.t.dtype, batch.p.dtype) == (torch.int16, torch.int16, torch.int64, torch.int8)
        assert batch.p.tolist() == [1, 0, 1, 0]
        assert batch.nbytes == 13 * 4
        assert batch.offsets.device.type == "cpu"

    def test_indexing(self):
        batch = make_batch(5)
        assert rows(batch[1:3], 0) == rows(batch, 1)
        assert batch[-1].lengths == [batch.lengths[-1]]
        picked = batch[[4, 0]]
        assert picked.lengths == [batch.lengths[4], batch.lengths[0]]
        assert rows(picked, 0) == rows(batch, 4)
        assert picked.t_start.tolist() == [0, 0]
        assert len(batch[2:2]) == 0
        with pytest.raises(IndexError, match="out of range"):
            batch[5]

    def test_errors_name_the_argument(self):
        with pytest.raises(TypeError, match="sensor_size"):
            EventBatch.from_streams(make_streams(1))
        with pytest.raises(ValueError, match="offsets"):
            EventBatch(*(torch.zeros(2, dtype=d) for d in (torch.int16, torch.int16, torch.int64, torch.int8)),
                       torch.tensor([0, 3]), SENSOR)
        with pytest.raises(TypeError, match="column x"):
            EventBatch(torch.zeros(2), torch.zeros(2, dtype=torch.int16), torch.zeros(2, dtype=torch.int64),
                       torch.zeros(2, dtype=torch.int8), torch.tensor([0, 2]), SENSOR)

    def test_to_and_pin_memory(self):
        batch = make_batch(2)
        moved = batch.to("cpu")
        assert torch.equal(moved.t, batch.t) and moved.offsets is batch.offsets
        if torch.cuda.is_available():  # pragma: no cover - needs an accelerator
            assert batch.pin_memory().x.is_pinned()

    def test_collate_in_a_dataloader(self):
        streams = [s.numpy() for s in make_streams(5)]
        data = [(s, float(i)) for i, s in enumerate(streams)]
        loader = torch.utils.data.DataLoader(
            data, batch_size=2, collate_fn=partial(collate_events, sensor_size=SENSOR, frame_ms=1.0, n_frames=T))
        batches = list(loader)
        assert [len(b) for b, _ in batches] == [2, 2, 1]
        assert batches[1][1].tolist() == [2.0, 3.0]
        assert batches[0][0].n_frames == T

    @pytest.mark.parametrize("slices", [True, False], ids=["cpu-slices", "index"])
    @pytest.mark.parametrize("positions", [[], [2], [0, 3], [1, 2, 3, 0], [3, 1]])
    def test_replace_streams_against_a_loop(self, positions, slices, monkeypatch):
        monkeypatch.setattr(batch_module, "SLICES_ON_CPU", slices)
        batch = make_batch(4)
        part = make_batch(len(positions), seed=5)
        out = replace_streams(batch, np.asarray(positions, dtype=np.int64), part)
        assert len(out) == 4 and out.sensor_size == batch.sensor_size
        for i in range(4):
            expected = part[positions.index(i)] if i in positions else batch[i]
            assert rows(out, i) == rows(expected, 0)

    @pytest.mark.parametrize("slices", [True, False], ids=["cpu-slices", "index"])
    def test_gathers_agree_on_both_paths(self, slices, monkeypatch):
        monkeypatch.setattr(batch_module, "SLICES_ON_CPU", slices)
        batch, part = make_batch(6), make_batch(3, seed=3)
        picked = batch.index_select(torch.tensor([4, 0, 4, 5]))
        assert [rows(picked, i) for i in range(4)] == [rows(batch, i) for i in (4, 0, 4, 5)]
        merged = merge_streams([([1, 3, 5], part), ([0, 2, 4], batch.index_select(torch.tensor([0, 2, 4])))], 6, batch)
        expected = [rows(batch, 0), rows(part, 0), rows(batch, 2), rows(part, 1), rows(batch, 4), rows(part, 2)]
        assert [rows(merged, i) for i in range(6)] == expected

    def test_gathers_do_not_grow_with_the_batch(self, monkeypatch):
        """index_select, merge_streams and replace_streams on the accelerator path: one
        index_select per field at any B (the CPU copies runs of events as slices)."""
        monkeypatch.setattr(batch_module, "SLICES_ON_CPU", False)
        from event_transforms._profiling import count_ops
        from tests.support.event_data import OP_COUNTS_CHECKED

        if not OP_COUNTS_CHECKED:
            pytest.skip("op counts are budgeted on torch >= 2.14")
        def ops(b):
            batch, part = make_batch(b), make_batch(b // 2, seed=3)
            index = torch.arange(0, b, 2)
            picked = np.arange(1, b, 2)
            return [count_ops(call).ops for call in (
                lambda: batch.index_select(index),
                lambda: merge_streams([(list(range(0, b, 2)), batch.index_select(index)), (picked.tolist(), part)], b, batch),
                lambda: replace_streams(batch, picked, part),
            )]

        small, large = ops(4), ops(32)
        assert small == large, (small, large)

    def test_merge_streams_restores_order(self):
        batch = make_batch(4)
        parts = [([1, 3], batch[[1, 3]]), ([0, 2], batch[[0, 2]])]
        merged = merge_streams(parts, 4, batch)
        assert merged.lengths == batch.lengths and torch.equal(merged.t, batch.t)


# --------------------------------------------------------------------------- binning


class TestBinning:
    @pytest.mark.parametrize("t_start, crop, pool, n_frames", [
        ("floor", None, 1, None), ("first", None, 1, 8), (-300, (1, 2, 8, 12), 2, 7), ("floor", (0, 0, 10, 16), 2, None),
    ])
    def test_equals_events_to_frames_per_stream(self, t_start, crop, pool, n_frames):
        streams = make_streams(4, seed=1)
        if isinstance(t_start, str):
            streams[1][:, 2] += 1_700_000_000_000_000  # absolute timestamps in one stream
        batch = EventBatch.from_streams(streams, sensor_size=SENSOR)
        out = bin_events(batch, frame_ms=1.0, t_start=t_start, n_frames=n_frames, crop=crop, pool=pool)
        singles = [events_to_frames(s, sensor_size=SENSOR, frame_ms=1.0, t_start=t_start, n_frames=n_frames,
                                    crop=crop, pool=pool) for s in streams]
        for b, single in enumerate(singles):
            t = single.shape[0]
            assert torch.equal(out[b, :t], single)
            assert out[b, t:].sum() == 0
        # events_to_frames dispatches on the batch like every other operation
        assert torch.equal(events_to_frames(batch, frame_ms=1.0, t_start=t_start, n_frames=n_frames, crop=crop,
                                            pool=pool), out)

    def test_events_to_frames_of_a_batch_refuses_reading_options_by_name(self):
        batch = make_batch(2)
        assert torch.equal(events_to_frames(batch), bin_events(batch))  # the batch's own grid
        with pytest.raises(TypeError, match="takes no sensor_size, time_unit"):
            events_to_frames(batch, sensor_size=SENSOR, time_unit="us")

    def test_grid_is_used_and_module_matches(self):
        batch = make_batch(3)
        to_frames = et.EventsToFrames(SENSOR, frame_ms=1.0, n_frames=T, dtype=torch.int16)
        out = to_frames(batch)
        assert out.dtype == torch.int16 and out.shape == (3, T, 2, *SENSOR)
        assert torch.equal(out.long(), frames_of(batch))
        with pytest.raises(ValueError, match="frame_ms"):
            bin_events(batch, frame_ms=2.0)

    def test_outside_sensor_dropped_and_empty(self):
        with pytest.warns(F.EventsOutsideSensorWarning) as record:  # the caller's input: warned once, when built
            batch = EventBatch.from_streams([torch.tensor([[-1, 0, 0, 1], [17, 0, 0, 1], [3, 4, 0, 0]]),
                                             torch.zeros(0, 4)], sensor_size=SENSOR)
        assert (record[0].message.dropped, record[0].message.total) == (2, 3)
        with et.count_dropped() as dropped:  # binning drops them without a second warning, and counts them
            out = bin_events(batch, frame_ms=1.0, n_frames=2)
        assert dropped.counts() == {"off_sensor": 2}
        assert out.sum().item() == 1 and out[0, 0, 0, 4, 3] == 1
        assert bin_events(batch[1:], frame_ms=1.0, n_frames=2).sum() == 0
        assert bin_events(batch[:0], frame_ms=1.0, n_frames=2).shape == (0, 2, 2, *SENSOR)

    def test_lost_events_are_counted_not_warned(self):
        """Binning an EventBatch drops what transforms moved off the sensor or out of the window by
        design: counted in a count_dropped block, never warned (the caller's own input is warned about
        once, when the batch is built)."""
        import warnings

        rows_ = torch.tensor([[1, 1, 0, 1], [2, 2, 5_000, 0], [-3, 1, 100, 1], [4, 4, 900, 0]])
        with pytest.warns(F.EventsOutsideSensorWarning):
            batch = EventBatch.from_streams([rows_, rows_[[0, 3]]], sensor_size=SENSOR)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with et.count_dropped() as dropped:
                out = bin_events(batch, frame_ms=1.0, n_frames=2)
        assert dropped.counts() == {"off_sensor": 1, "out_of_window": 1} and dropped.total == 2
        assert out.sum().item() == 4  # the two kept events of each stream
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # nothing lost: no warning; a crop is asked for, not lost
            bin_events(batch[1:], frame_ms=1.0, n_frames=2)
            bin_events(batch[1:], frame_ms=1.0, n_frames=2, crop=(0, 0, 2, 2))
            bin_events(batch[:0], frame_ms=1.0, n_frames=2)

    def test_voxel_grid(self):
        batch = make_batch(3)
        padded, lengths = batch.to_padded()
        assert torch.equal(to_voxel_grid(batch, n_bins=4), to_voxel_grid(padded, n_bins=4, sensor_size=SENSOR, lengths=lengths))


# --------------------------------------------------------------------------- kernels vs references




# --------------------------------------------------------------------------- shared invariants

# name -> factory: each topic test file holds its own entries (EVENT_BATTERY in test_<topic>.py)
FACTORIES = collect("EVENT_BATTERY")
EVENT_ONLY = ("SpatialJitter", "TimeJitter", "TimeSkew", "RefractoryPeriod", "Decimation")


def same(a: EventBatch, b: EventBatch) -> bool:
    return a.lengths == b.lengths and all(torch.equal(getattr(a, k), getattr(b, k)) for k in ("x", "y", "t", "p"))


@pytest.mark.parametrize("name", list(FACTORIES))
class TestBattery:
    def test_dtype_device_no_in_place(self, name):
        batch = make_batch()
        versions = [getattr(batch, k)._version for k in ("x", "y", "t", "p")]
        copy = [getattr(batch, k).clone() for k in ("x", "y", "t", "p")]
        out = FACTORIES[name]()(batch, generator=torch.Generator().manual_seed(0))
        assert isinstance(out, EventBatch) and len(out) == len(batch)
        assert (out.x.dtype, out.y.dtype, out.t.dtype, out.p.dtype) == (torch.int16, torch.int16, torch.int64, torch.int8)
        sensor = tuple(FACTORIES[name]().output_shape(batch.frame_shape)[-2:])  # Downsample pools the sensor
        assert out.device == batch.device and out.sensor_size == sensor
        assert [getattr(batch, k)._version for k in ("x", "y", "t", "p")] == versions
        assert all(torch.equal(c, getattr(batch, k)) for c, k in zip(copy, ("x", "y", "t", "p")))

    def test_sample_alone_equals_sample_in_batch(self, name):
        batch = make_batch(5)
        transform = FACTORIES[name]()
        if transform.couples_samples:
            pytest.skip("couples_samples: a sample depends on its partner by design (tested in test_mixing.py)")
        params = transform.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(2))
        whole = transform(batch, params=params)
        for i in range(5):
            alone = transform(batch[i : i + 1], params=slice_params(params, torch.tensor([i])))
            assert same(alone, whole[i])

    def test_seeded_and_replay(self, name):
        batch = make_batch()
        transform = FACTORIES[name]()
        a = transform(batch, generator=torch.Generator().manual_seed(7))
        b = transform(batch, generator=torch.Generator().manual_seed(7))
        params = transform.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(7))
        torch.manual_seed(123)
        assert same(a, b) and same(a, transform(batch, params=params))

    def test_edge_sizes(self, name):
        transform = FACTORIES[name]()
        empty = make_batch(0)
        assert len(transform(empty)) == 0
        one = EventBatch.from_streams([torch.tensor([[3, 4, 1500, 1]]), torch.zeros(0, 4)], sensor_size=SENSOR,
                                      frame_ms=1.0, t_start=0, n_frames=T)
        out = transform(one, generator=torch.Generator().manual_seed(0))
        assert len(out) == 2 and out.lengths[0] <= 1 + (10**6 if name in ("AddPoissonNoise", "AddNoise p") else 0)

    def test_in_containers(self, name):
        batch = make_batch()
        g = lambda: torch.Generator().manual_seed(1)  # noqa: E731
        sensor = tuple(FACTORIES[name]().output_shape(batch.frame_shape)[-2:])
        to_frames = et.EventsToFrames(sensor, frame_ms=1.0, n_frames=T)
        pipeline = et.Compose([FACTORIES[name](), to_frames, et.RandomFrameShift((-1, 1))])
        assert pipeline(batch, generator=g()).shape == (4, T, 2, *sensor)
        if FACTORIES[name]().couples_samples:
            return  # OneOf and RandomApply refuse a coupled transform at construction (test_containers.py)
        for container in (et.OneOf([FACTORIES[name](), et.HorizontalFlip()]), et.RandomApply(FACTORIES[name](), p=0.5)):
            params = container.make_params(batch.frame_shape, generator=g())
            out = container(batch, params=params)
            assert isinstance(out, EventBatch) and same(out, container(batch, params=params))

    def test_frames_refused_by_event_only(self, name):
        if name not in EVENT_ONLY:
            pytest.skip("has a frame kernel")
        with pytest.raises(TypeError, match=name.split()[0]):
            FACTORIES[name]()(torch.zeros(2, T, 2, *SENSOR))


@pytest.mark.parametrize("name", list(FACTORIES))
def test_gate_leaves_skipped_streams_unchanged(name):
    """The one gating rule on events, for every module: the kept streams are the ungated
    call's (same params), the others the input's, and the output is one EventBatch."""
    batch = make_batch(6)
    transform = FACTORIES[name]()
    if transform.output_shape(batch.frame_shape) != batch.frame_shape:
        pytest.skip("changes the grid (Downsample): a skipped stream could not keep its own grid")
    transform.p = 0.5
    params = transform.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(4))
    out = transform(batch, params=params)
    gate = params["apply"].tolist()
    assert any(gate) and not all(gate)
    transform.p = 1.0
    ungated = transform(batch, params={k: v for k, v in params.items() if k != "apply"})
    if isinstance(out, tuple):  # CutMix/MixUp hand back (events, labels) only with labels
        out, ungated = out[0], ungated[0]
    for i, applied in enumerate(gate):
        assert same(out[i], ungated[i] if applied else batch[i]), (i, applied)


def test_frame_only_transform_refuses_events():
    """Every transform has an event kernel now; a Lambda (a function of frames) still refuses."""
    with pytest.raises(TypeError, match="Lambda has no kernel for an EventBatch"):
        et.Lambda(lambda frames: frames)(make_batch())


def test_order_stops_mattering():
    """On events, TES and event drop can follow a rotation (on frames they raise once it fired)."""
    batch = make_batch()
    pipeline = et.Compose([et.RandomRotation(30.0, p=0.5), et.RandomTemporalEventShift((-1,), 0.5),
                           et.RandomEventDrop(0.2), et.EventsToFrames(SENSOR, frame_ms=1.0, n_frames=T)])
    for seed in range(5):
        assert pipeline(batch, generator=torch.Generator().manual_seed(seed)).shape == (4, T, 2, *SENSOR)


def test_events_to_frames_first_takes_an_event_batch():
    batch = make_batch()
    pipeline = et.Compose([et.EventsToFrames(SENSOR, frame_ms=1.0, n_frames=T), et.HorizontalFlip()])
    assert torch.equal(pipeline(batch), bin_events(batch).flip(-1))


def test_modules_still_move_with_to():
    """The input-type dispatch must not shadow ``nn.Module._apply`` (used by ``.to``)."""
    rotation = et.RandomRotation(10.0).to("cpu", torch.float64)
    noise = et.AddNoise(torch.zeros(8, 2, *SENSOR)).to(torch.float64)
    assert noise.bank.dtype == torch.float64 and isinstance(rotation, et.RandomRotation)


def test_torchvision_refuses_an_event_batch():
    """torchvision's v2 transforms pass unknown types through untouched; an EventBatch is refused."""
    v2 = pytest.importorskip("torchvision.transforms.v2")
    batch = make_batch(2)
    for transform in (v2.RandomRotation(30.0), v2.RandomHorizontalFlip(1.0), v2.Compose([v2.RandomCrop(4)])):
        with pytest.raises(TypeError, match="EventBatch .* torchvision's transforms would pass it through"):
            transform(batch)
    with pytest.raises(TypeError, match="EventBatch"):
        v2.RandomHorizontalFlip(1.0)(torch.zeros(1, 2, 4, 4), batch)
