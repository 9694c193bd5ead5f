"""Helpers shared by the event kernels (``<op>_events`` in the topic files of :mod:`event_transforms.functional`).

Each event kernel takes a batch and per-sample parameters (``(B,)`` CPU tensors, as
:meth:`~event_transforms.EventTransform.make_params` draws them) and returns a new batch on
the same device; nothing is modified in place. Coordinates stay int16, timestamps keep
their dtype, polarity stays int8.

**Per-sample randomness.** Kernels that draw (TES, event drop, jitter, Poisson noise) use
one generator per sample, seeded with that sample's 63-bit seed from the params (Philox
on CUDA, a counter-based stream; Mersenne Twister on the CPU), and draw that sample's
numbers in event order, one slice per sample (B small draws per call). So a stream's output
depends only on its own events and its own seed: ``kernel(batch[i:i+1], params[i:i+1])``
equals ``kernel(batch, params)[i]``. CPU and CUDA draws differ (different engines); each is
reproducible.

**Where events and frames differ.** A rotated, resized or jittered event lands in one
pixel (rounded to the nearest), so counts are conserved; a bilinear warp of frames
spreads each count over up to four pixels (and a zoom by β multiplies the total by about
β²). Events moved outside the sensor are kept (no host synchronisation, counts kept) and
dropped when binned; a later transform that moves them back brings them back, which
frames cannot. The perspective and elastic warps are the exception: they drop the events
they move off the sensor, with the binning's warning (a homography sends points near its
horizon past any int16 coordinate, and the elastic field is defined on the sensor only). Frame shift and TES drop the events they push out of the grid's window,
as the frame kernels do.

Host synchronisations: none, except where the output size depends on the data (event
drop, frame shift/TES dropping events pushed out of the window, refractory period,
decimation: one read of the kept counts per stream, plus the compaction) and in exact TES
(the fix-up reads the per-group surplus, then gathers the events near the threshold).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from .._validation import read_host
from ..events.batch import EventBatch
from ..events.binning import _frame_us

__all__: list[str] = []


def _per_event(values: Tensor, batch: EventBatch, dtype: torch.dtype | None = None) -> Tensor:
    """(N,) ``values[sample of each event]`` on the batch's device."""
    values = values.to(device=batch.device, dtype=dtype or values.dtype, non_blocking=True)
    return values.index_select(0, batch.sample_index())


def _generator(seed: int, device: torch.device) -> torch.Generator:
    generator = torch.Generator(device=device)
    generator.manual_seed(int(seed) & (2**63 - 1))
    return generator


def _compact(batch: EventBatch, keep: Tensor, **changes: Any) -> EventBatch:
    """The events where ``keep`` holds (one host read of the kept counts per stream)."""
    sample = batch.sample_index()
    kept = torch.zeros(len(batch), dtype=torch.int64, device=batch.device).index_add_(0, sample, keep.to(torch.int64))
    lengths = read_host(kept)  # the output size depends on the data: the one read
    offsets = torch.tensor([0, *np.cumsum(lengths, dtype=np.int64).tolist()], dtype=torch.int64)
    index = _kept_index(keep, sum(lengths))
    columns = {k: changes.pop(k, getattr(batch, k)).index_select(0, index) for k in ("x", "y", "t", "p")}
    return batch._replace(**columns, offsets=offsets, _sample=sample.index_select(0, index), **changes)


def _kept_index(keep: Tensor, size: int) -> Tensor:
    """The positions where ``keep`` holds, ``size`` of them (known): a cumulative sum and one
    scatter, so no ``nonzero`` (which reads its size back on an accelerator)."""
    if size == keep.shape[0]:
        return torch.arange(size, device=keep.device)
    target = torch.cumsum(keep, 0).sub_(1).masked_fill_(~keep, size)
    out = torch.empty(size + 1, dtype=torch.int64, device=keep.device)
    return out.scatter_(0, target, torch.arange(keep.shape[0], device=keep.device))[:size]


def _require_grid(batch: EventBatch, owner: str, *, frames: bool = True) -> tuple[Tensor, float | int, int]:
    if batch.frame_ms is None or (frames and batch.n_frames is None):
        need = "frame_ms and n_frames" if frames else "frame_ms"
        raise ValueError(
            f"{owner} on events needs the batch's frame grid ({need}): build the batch with "
            f"EventBatch.from_streams(..., frame_ms=..., n_frames=...) or call batch.with_grid(...)"
        )
    return batch.t_start, _frame_us(batch.frame_ms), batch.n_frames  # type: ignore[return-value]  # n_frames may be None when frames=False


def _round_to(values: Tensor, dtype: torch.dtype) -> Tensor:
    """Nearest whole pixel, clamped to int16 (in place on ``values``, a temporary)."""
    return values.round_().clamp_(-(2**15 - 1), 2**15 - 1).to(dtype)


def _keys(batch: EventBatch, seed: Tensor, fraction: Tensor) -> tuple[Tensor, Tensor]:
    """Per event a float32 uniform key from its sample's generator, and ``key < ζ_b``
    (compared slice by slice against the sample's ζ: no per-event gather)."""
    bounds = batch.offsets.tolist()
    u = torch.empty(batch.num_events, dtype=torch.float32, device=batch.device)
    below = torch.empty(batch.num_events, dtype=torch.bool, device=batch.device)
    for b, (s, zeta) in enumerate(zip(seed.tolist(), fraction.tolist())):
        lo, hi = bounds[b], bounds[b + 1]
        if hi > lo:
            piece = u[lo:hi].uniform_(generator=_generator(s, batch.device))
            torch.lt(piece, zeta, out=below[lo:hi])
    return u, below


def _append(batch: EventBatch, added: Sequence[tuple[Tensor, Tensor, Tensor, Tensor]]) -> EventBatch:
    """``batch`` with ``added[b]`` (x, y, t, p columns) after stream b's own events."""
    bounds = batch.offsets.tolist()
    cols = []
    for k, name in enumerate(("x", "y", "t", "p")):
        column = getattr(batch, name)
        pieces = []
        for b in range(len(batch)):
            pieces += [column[bounds[b] : bounds[b + 1]], added[b][k]]
        cols.append(torch.cat(pieces) if pieces else column)
    lengths = [bounds[b + 1] - bounds[b] + int(added[b][0].shape[0]) for b in range(len(batch))]
    offsets = torch.tensor([0, *np.cumsum(lengths, dtype=np.int64).tolist()], dtype=torch.int64)
    return batch._replace(x=cols[0], y=cols[1], t=cols[2], p=cols[3], offsets=offsets, _sample=None)


def warn_dropped(
    batch: EventBatch,
    *,
    outside_sensor: Tensor | None = None,
    outside_window: Tensor | None = None,
    window: str = "",
    stacklevel: int = 3,
) -> None:
    """Warn, as :func:`~event_transforms.functional.events_to_frames` does, about the events of
    ``batch`` that a kernel or the binning drops: ``outside_sensor`` and ``outside_window`` are
    per-event bool masks. One host read of the counts (and of the coordinate span, for the
    sensor warning); nothing when no event is dropped. ``window`` describes the grid."""
    import warnings

    from ..events.binning import EventsOutsideWindowWarning, _SensorSize, _Tally, _warn_outside

    if batch.num_events == 0 or (outside_sensor is None and outside_window is None):
        return
    sample = batch.sample_index()
    rows = []
    for mask in (outside_sensor, outside_window):
        if mask is None:
            rows.append(torch.zeros(len(batch), dtype=torch.int64, device=batch.device))
        else:
            rows.append(torch.zeros(len(batch), dtype=torch.int64, device=batch.device).index_add_(
                0, sample, mask.to(torch.int64)))
    sensor_counts, window_counts = (r.tolist() for r in torch.stack(rows).cpu())  # the one read
    if sum(sensor_counts):
        tally = _Tally(len(batch))
        tally.outside = sum(sensor_counts)
        x, y = batch.x, batch.y
        tally.x_range = [int(x.min()), int(x.max())]
        tally.y_range = [int(y.min()), int(y.max())]
        _warn_outside(tally, batch.num_events, _SensorSize(*batch.sensor_size), stacklevel=stacklevel + 1)
    if sum(window_counts):
        streams = ", ".join(f"{d:,} of {n:,}" for d, n in zip(window_counts, batch.lengths))
        warnings.warn(
            EventsOutsideWindowWarning(
                f"{sum(window_counts):,} events lie outside the window {window} and were dropped "
                f"(per stream: {streams})"
            ),
            stacklevel=stacklevel,
        )
