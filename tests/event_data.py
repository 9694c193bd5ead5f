"""Event streams and batches shared by the tests of the event kernels (one per topic file)."""

from __future__ import annotations

import torch

from event_transforms.functional import EventBatch, bin_events

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
