"""The one gating rule, pinned against its slow obvious reference on every gated module: a gated
call equals the ungated module on each kept sample alone (with that sample's
slice of the tree) and the input elsewhere, promoted to the output dtype, on frames and on an
EventBatch, whether the module gathers and puts back or hands the gate to its kernel
(``gates_in_kernel``): mixed gates, every sample gated off, every sample on, B = 0, one event."""

from __future__ import annotations

import warnings

import pytest
import torch

from event_transforms.events import batch as batch_module
from event_transforms.events.batch import EventBatch
from event_transforms.events.dropped import EventsOutsideSensorWarning
from event_transforms.transforms.base import slice_params

from tests.support.topics import collect
from tests.support.checkers import H, W, sparse_frames
from tests.support.event_data import SENSOR, T, make_batch, make_streams, same_events

FRAME_BATTERY = collect("BATTERY")
EVENT_BATTERY = collect("EVENT_BATTERY")
B = 5
GATES = {
    "mixed": [True, False, False, True, True],
    "alternate": [False, True, False, True, False],
    "all off": [False] * B,
    "all on": [True] * B,
}
GATED_IN_KERNEL = {"HorizontalFlip", "VerticalFlip", "RandomHorizontalFlip", "RandomVerticalFlip", "TimeReversal",
                   "RandomTimeReversal", "FlipPolarity", "RandomFlipPolarity"}


def _gated(make):
    module = make()
    if type(module).__name__ == "Downsample":
        pytest.skip("Downsample takes no p: it changes the sensor size, which a gate cannot mix")
    if module.couples_samples:
        pytest.skip("a coupled module reads its partners: pinned by test_battery's test_p_gates_each_sample")
    module.p = 0.5
    always = make()
    always.p = 1.0
    return module, always


def _ungated(params):
    return {k: v for k, v in params.items() if k != "apply"}


def _frames_reference(always, frames, params, gate):
    """The slow obvious rule: the ungated module on each kept sample alone, the input elsewhere."""
    own = _ungated(params)
    alone = [always(frames[i : i + 1], params=slice_params(own, torch.tensor([i]))) for i in range(len(gate))]
    dtype = frames.dtype
    for result in alone:  # every branch's dtype counts, kept or not (as the empty sub-batch's did)
        dtype = torch.promote_types(dtype, result.dtype)
    rows = [(alone[i] if on else frames[i : i + 1]).to(dtype) for i, on in enumerate(gate)]
    return torch.cat(rows)


@pytest.mark.parametrize("slices", [True, False], ids=["cpu-slices", "one-gather"])
@pytest.mark.parametrize("gate", sorted(GATES))
@pytest.mark.parametrize("name", sorted(FRAME_BATTERY))
def test_gated_frames_equal_the_reference(name, gate, slices, monkeypatch):
    monkeypatch.setattr(batch_module, "SLICES_ON_CPU", slices)
    if not slices and name not in GATED_IN_KERNEL:
        pytest.skip("the switch changes only the kernels that take the gate")
    module, always = _gated(lambda: FRAME_BATTERY[name](6, H, W))
    frames = sparse_frames(B, 6, 2, H, W, density=0.2, seed=3)
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(4))
    params["apply"] = torch.tensor(GATES[gate])
    out = module(frames, params=params)
    expected = _frames_reference(always, frames, params, GATES[gate])
    assert out.dtype == expected.dtype and torch.equal(out, expected)


@pytest.mark.parametrize("dtype", [torch.uint8, torch.int16, torch.float16, torch.bfloat16, torch.float64])
@pytest.mark.parametrize("name", sorted(GATED_IN_KERNEL))
def test_kernels_that_take_the_gate_keep_every_dtype(name, dtype):
    module, always = _gated(lambda: FRAME_BATTERY[name](6, H, W))
    frames = sparse_frames(B, 6, 2, H, W, density=0.3, high=9, seed=5, dtype=dtype)
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(1))
    params["apply"] = torch.tensor(GATES["mixed"])
    out = module(frames, params=params)
    assert out.dtype == dtype and torch.equal(out, _frames_reference(always, frames, params, GATES["mixed"]))
    strided = frames.transpose(-1, -2).contiguous().transpose(-1, -2)  # not contiguous: the same values
    assert torch.equal(module(strided, params=params), out)


@pytest.mark.parametrize("name", sorted(FRAME_BATTERY))
def test_gated_frames_of_an_empty_batch(name):
    module, always = _gated(lambda: FRAME_BATTERY[name](6, H, W))
    frames = sparse_frames(0, 6, 2, H, W)
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    out = module(frames, params=params)
    expected = always(frames, params=_ungated(params))
    assert out.shape == expected.shape and out.dtype == expected.dtype


def _events_reference(always, batch, params, gate):
    own = _ungated(params)
    return [
        always(batch[i : i + 1], params=slice_params(own, torch.tensor([i]))) if on else batch[i : i + 1]
        for i, on in enumerate(gate)
    ]


def _same_streams(out: EventBatch, expected: list[EventBatch]) -> None:
    assert len(out) == len(expected)
    for i, stream in enumerate(expected):
        assert same_events(out[i], stream), i
    assert out.offsets.dtype == torch.int64


@pytest.mark.parametrize("slices", [True, False], ids=["cpu-slices", "one-gather"])
@pytest.mark.parametrize("gate", sorted(GATES))
@pytest.mark.parametrize("name", sorted(EVENT_BATTERY))
def test_gated_events_equal_the_reference(name, gate, slices, monkeypatch):
    monkeypatch.setattr(batch_module, "SLICES_ON_CPU", slices)
    module, always = _gated(EVENT_BATTERY[name])
    streams = make_streams(B, seed=7)
    streams[2] = streams[2][:0]  # an empty stream among the others
    batch = EventBatch.from_streams(streams, sensor_size=SENSOR, frame_ms=1.0, t_start=[0, 0, 0, 1000, 0], n_frames=T)
    params = module.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(8))
    params["apply"] = torch.tensor(GATES[gate])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EventsOutsideSensorWarning)
        out = module(batch, params=params)
        _same_streams(out, _events_reference(always, batch, params, GATES[gate]))
    assert out.t_start is not None and torch.equal(out.t_start, batch.t_start)


@pytest.mark.parametrize("name", sorted(EVENT_BATTERY))
def test_gated_events_of_an_empty_batch_and_one_event(name):
    module, always = _gated(EVENT_BATTERY[name])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EventsOutsideSensorWarning)
        empty = make_batch(0)
        out = module(empty, generator=torch.Generator().manual_seed(0))
        assert isinstance(out, EventBatch) and len(out) == 0 and out.num_events == 0
        one = EventBatch.from_streams([torch.tensor([[3, 4, 1500, 1]]), torch.zeros(0, 4, dtype=torch.int64)],
                                      sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)
        for gate in ([True, False], [False, True], [False, False], [True, True]):
            params = module.make_params(one.frame_shape, generator=torch.Generator().manual_seed(2))
            params["apply"] = torch.tensor(gate)
            _same_streams(module(one, params=params), _events_reference(always, one, params, gate))


def test_float_times_and_a_fractional_grid_reverse_as_the_reference():
    """Time reversal's per-stream subtraction on the CPU gives the per-event gather's values for
    float64 times and for integer times on a grid whose bin width is not a whole microsecond."""
    import event_transforms as et

    streams = make_streams(4, seed=9)
    for frame_ms, as_float in ((1.0, True), (0.7, False), (0.7, True)):
        columns = [{"x": s[:, 0], "y": s[:, 1], "t": s[:, 2].double() if as_float else s[:, 2], "p": s[:, 3]}
                   for s in streams]
        batch = EventBatch.from_streams(columns, sensor_size=SENSOR, frame_ms=frame_ms, t_start=[0, 700, 0, 1400],
                                        n_frames=T)
        module = et.RandomTimeReversal(0.5)
        params = module.make_params(batch.frame_shape)
        for gate in ([True, False, True, True], [True] * 4):
            params["apply"] = torch.tensor(gate)
            expected = [et.TimeReversal()(batch[i : i + 1]) if on else batch[i : i + 1] for i, on in enumerate(gate)]
            for slices in (True, False):
                batch_module.SLICES_ON_CPU = slices
                try:
                    out = module(batch, params=params)
                finally:
                    batch_module.SLICES_ON_CPU = True
                assert out.t.dtype == batch.t.dtype
                _same_streams(out, expected)
