"""Event streams and batches shared by the tests of the event kernels (one per topic file)."""

from __future__ import annotations

import torch

from event_transforms.functional import EventBatch, bin_events

#: Aten op counts depend on the torch version that dispatches them (torch 2.3 decomposes some batched
#: linear algebra differently by batch size): like tests/library/test_host_syncs.py, which .ci/floor leaves
#: out, the "ops do not grow with B" check runs on the torch the budgets were measured on (2.14+).
OP_COUNTS_CHECKED = tuple(int(v) for v in torch.__version__.split("+")[0].split(".")[:2]) >= (2, 14)

SENSOR = (11, 17)  # non-square, H first
T = 6
FRAME_US = 1000


def make_streams(batch: int = 4, seed: int = 0, *, n: int | None = None) -> list[torch.Tensor]:
    """Sorted (N, 4) int64 streams of (x, y, t, p) on SENSOR, t in [0, T ms)."""
    g = torch.Generator().manual_seed(seed)
    out = []
    for b in range(batch):
        size = n if n is not None else int(torch.randint(20, 200, (1,), generator=g))
        t = torch.sort(torch.randint(0, T * FRAME_US, (size,), generator=g)).values
        x = torch.randint(0, SENSOR[1], (size,), generator=g)
        y = torch.randint(0, SENSOR[0], (size,), generator=g)
        p = torch.randint(0, 2, (size,), generator=g)
        out.append(torch.stack([x, y, t, p], 1))
    return out


def make_batch(batch: int = 4, seed: int = 0, **kwargs) -> EventBatch:
    return EventBatch.from_streams(make_streams(batch, seed, **kwargs), sensor_size=SENSOR, frame_ms=1.0,
                                   t_start=0, n_frames=T)


def frames_of(batch: EventBatch, dtype=torch.int64) -> torch.Tensor:
    return bin_events(batch, dtype=dtype)


def rows(batch: EventBatch, b: int) -> list[tuple[int, int, int, int]]:
    one = batch[b]
    return list(zip(one.x.tolist(), one.y.tolist(), one.t.tolist(), one.p.tolist()))


def same_events(a: EventBatch, b: EventBatch) -> bool:
    """Equal streams: lengths, sensor and every column, in order."""
    return a.lengths == b.lengths and a.sensor_size == b.sensor_size and all(
        torch.equal(getattr(a, k), getattr(b, k)) for k in ("x", "y", "t", "p"))


def check_hard_cases(make, *, coupled: bool = False) -> None:
    """The hard cases every event kernel meets, through its module ``make()``: an empty batch
    (B = 0), one event beside an empty stream, a grid of one frame (T = 1), and a stream with
    no events between two others, which (for a transform that does not couple samples) gives
    each stream alone what it gives it in the batch; and the aten ops and host syncs of a call
    (counted on the CPU) are the same at B = 4 and B = 32: no loop over the samples."""
    import warnings

    from event_transforms._profiling import count_ops
    from event_transforms.transforms.base import slice_params

    from event_transforms.events.dropped import EventsOutsideSensorWarning

    def run(batch, **kwargs):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EventsOutsideSensorWarning)  # warps may push events off
            return make()(batch, **kwargs)

    empty = run(make_batch(0), generator=torch.Generator().manual_seed(0))
    assert isinstance(empty, EventBatch) and len(empty) == 0 and empty.num_events == 0
    one = EventBatch.from_streams([torch.tensor([[3, 4, 1500, 1]]), torch.zeros(0, 4)], sensor_size=SENSOR,
                                  frame_ms=1.0, t_start=0, n_frames=T)
    out = run(one, generator=torch.Generator().manual_seed(0))
    assert len(out) == 2 and out.num_events <= 1 and out.t.dtype == torch.int64
    single = EventBatch.from_streams(make_streams(3, seed=5), sensor_size=SENSOR, frame_ms=float(T), t_start=0,
                                     n_frames=1)
    out = run(single, generator=torch.Generator().manual_seed(1))
    assert len(out) == 3 and out.n_frames == 1 and out.num_events <= 2 * single.num_events
    streams = make_streams(3, seed=6)
    holed = EventBatch.from_streams([streams[0], torch.zeros(0, 4, dtype=torch.int64), streams[2]],
                                    sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)
    transform = make()
    params = transform.make_params(holed.frame_shape, generator=torch.Generator().manual_seed(2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EventsOutsideSensorWarning)
        whole = transform(holed, params=params)
        assert len(whole) == 3
        if not coupled:
            assert whole.lengths[1] == 0
            for i in range(3):
                alone = transform(holed[i : i + 1], params=slice_params(params, torch.tensor([i])))
                assert same_events(alone, whole[i])
    if not OP_COUNTS_CHECKED:
        return
    counts = []
    for size in (4, 32):
        batch = make_batch(size, seed=3)
        params = transform.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(0))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EventsOutsideSensorWarning)
            counted = count_ops(lambda batch=batch, params=params: transform(batch, params=params))
        counts.append((counted.ops, counted.syncs))
    assert counts[0] == counts[1], f"ops and syncs at B = 4 and 32: {counts}"
