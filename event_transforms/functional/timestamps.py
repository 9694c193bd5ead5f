"""Operations on event timestamps alone (events only): Gaussian time jitter and a linear
clock skew. Frames have no timestamps to move: both refuse frames by name."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from .._params import SEED, Param, check_args
from ..events.batch import EventBatch
from ._dispatch import kernel_for, register_kernel
from ._event_ops import TIME_JITTER, _per_event
from ._random import EventStream

__all__ = ["time_jitter", "time_jitter_events", "time_skew", "time_skew_events"]

Scalars = float | Sequence[float] | Tensor
ShiftArg = int | Sequence[int] | Tensor


#: :func:`time_jitter`: the standard deviation in µs and the seed of the noise.
TIME_JITTER_SPEC = {"std_us": Param("float", low=0.0), "seed": SEED}


#: :func:`time_skew`: the coefficient (> 0) and the offset in µs.
TIME_SKEW_SPEC = {
    "coefficient": Param("float", low=0.0, low_open=True), "offset_us": Param("float"),
}


def time_jitter(batch: EventBatch, std_us: Scalars, seed: ShiftArg) -> EventBatch:
    """Add Gaussian noise of ``std_us`` microseconds to every timestamp (events only).

    Rounded for integer timestamps; streams are no longer time-sorted. Sync-free.

    Args:
        batch: an EventBatch.
        std_us: standard deviation in µs (>= 0), a number or ``(B,)``.
        seed: per-sample seeds, an integer or ``(B,)`` int64 in [0, 2**63).

    Shape:
        - batch: an EventBatch of B streams with N events.
        - output: an EventBatch of the same B streams, sensor and grid, N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 1000, 1]])], sensor_size=(2, 2))
        >>> time_jitter(batch, 0.0, 3).t.tolist()
        [1000]
    """
    kernel = kernel_for(time_jitter, batch)
    args = check_args("time_jitter", TIME_JITTER_SPEC, len(batch), std_us=std_us, seed=seed)
    return kernel(batch, args["std_us"], args["seed"])


@register_kernel(time_jitter, EventBatch)
def time_jitter_events(batch: EventBatch, std_us: Tensor, seed: Tensor) -> EventBatch:
    """Add Gaussian noise of ``std_us[b]`` microseconds to the timestamps (rounded for
    integer timestamps). Streams are no longer time-sorted. The normals come from the
    sample's counter-based stream (``seed[b]`` and the event's position in its sample).
    Sync-free; the same ops whatever B.

    Args:
        batch: the event streams.
        std_us: ``(B,)`` standard deviations in microseconds (>= 0).
        seed: ``(B,)`` int64 per-sample seeds.

    Shape:
        - batch: B streams, N events.
        - std_us, seed: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> jittered = time_jitter_events(batch, torch.tensor([0.0, 30.0]), torch.tensor([1, 2]))
        >>> jittered.t[:2].tolist(), jittered.x.tolist()  # std 0 moves nothing; pixels kept
        ([100, 15000], [0, 2, 1])
    """
    noise = EventStream.of_batch(batch, seed).normal(TIME_JITTER).to(torch.float64).mul_(
        _per_event(std_us.to(torch.float64), batch))
    if batch.t.is_floating_point():
        return batch._replace(t=batch.t + noise)
    return batch._replace(t=batch.t + torch.round(noise).to(torch.int64))


def time_skew(batch: EventBatch, coefficient: Scalars, offset_us: Scalars = 0.0) -> EventBatch:
    """Stretch time: ``t -> t0 + coefficient (t - t0) + offset_us`` per sample (events only).

    ``t0`` is the stream's grid start (the first event without a grid). Sync-free.

    Args:
        batch: an EventBatch.
        coefficient: factor > 0, a number or ``(B,)``.
        offset_us: shift in µs, a number or ``(B,)``.

    Shape:
        - batch: an EventBatch of B streams with N events.
        - output: an EventBatch of the same B streams, sensor and grid, N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 100, 1], [0, 0, 300, 0]])], sensor_size=(2, 2))
        >>> time_skew(batch, 2.0, 10.0).t.tolist()
        [110, 510]
    """
    kernel = kernel_for(time_skew, batch)
    args = check_args("time_skew", TIME_SKEW_SPEC, len(batch), coefficient=coefficient, offset_us=offset_us)
    return kernel(batch, args["coefficient"], args["offset_us"])


@register_kernel(time_skew, EventBatch)
def time_skew_events(batch: EventBatch, coefficient: Tensor, offset_us: Tensor) -> EventBatch:
    """``t -> t0 + coefficient[b] (t - t0) + offset_us[b]`` about the stream's grid start
    ``t0`` (the first event's time without a grid), rounded for integer timestamps. Sync-free.

    Args:
        batch: the event streams.
        coefficient: ``(B,)`` time stretch factors.
        offset_us: ``(B,)`` shifts in microseconds.

    Shape:
        - batch: B streams, N events.
        - coefficient, offset_us: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> time_skew_events(batch, torch.tensor([2.0, 1.0]), torch.tensor([0.0, 10.0])).t.tolist()  # about t0 = 0
        [200, 30000, 60]
    """
    if batch.t_start is not None:
        origin = _per_event(batch.t_start.to(torch.float64), batch)
    else:
        sample = batch.sample_index().to(torch.int64)
        big = torch.full((len(batch),), math.inf, dtype=torch.float64, device=batch.device)
        first = big.scatter_reduce(0, sample, batch.t.to(torch.float64), reduce="amin")
        origin = first.index_select(0, sample)
    t = batch.t.to(torch.float64)
    skewed = origin + _per_event(coefficient.to(torch.float64), batch) * (t - origin) + _per_event(
        offset_us.to(torch.float64), batch)
    return batch._replace(t=skewed if batch.t.is_floating_point() else torch.round(skewed).to(torch.int64))
