"""Helpers shared by the event kernels (``<op>_events`` in the topic files of :mod:`event_transforms.functional`).

Each event kernel takes a batch and per-sample parameters (``(B,)`` CPU tensors, as
:meth:`~event_transforms.EventTransform.make_params` draws them) and returns a new batch on
the same device; nothing is modified in place. Coordinates stay int16, timestamps keep
their dtype, polarity stays int8.

**Per-sample randomness.** Kernels that draw (TES, event drop, jitter, Poisson noise)
use the counter-based streams of :mod:`._random` (:class:`~._random.EventStream`): each
number is a hash of the sample's 63-bit seed from the params, the event's position within
its sample and the draw's purpose. So a stream's output depends only on its own events and
its own seed (``kernel(batch[i:i+1], params[i:i+1])`` equals ``kernel(batch, params)[i]``),
the numbers are the same on every device (int32 arithmetic, no engine), and a call costs
the same ops whatever B (no loop over samples).

**Where events and frames differ.** A rotated, resized or jittered event lands in one
pixel (rounded to the nearest), so counts are conserved; a bilinear warp of frames
spreads each count over up to four pixels (and a zoom by β multiplies the total by about
β²). Events moved outside the sensor are kept (no host synchronisation, counts kept) and
dropped when binned; a later transform that moves them back brings them back, which
frames cannot. The perspective and elastic warps are the exception: they drop the events
they move off the sensor (a homography sends points near its horizon past any int16
coordinate, and the elastic field is defined on the sensor only). Frame shift and TES drop
the events they push out of the grid's window, as the frame kernels do. Every such drop is
the operation's documented meaning: it is never warned, and
:func:`~event_transforms.count_dropped` counts it.

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
from ._frame_ops import _by_runs_on, _runs
from ._random import EventStream
from ..events.batch import EventBatch
from ..events._ingest import bin_width_us

__all__: list[str] = []


def _per_event(values: Tensor, batch: EventBatch, dtype: torch.dtype | None = None) -> Tensor:
    """(N,) ``values[sample of each event]`` on the batch's device."""
    values = values.to(device=batch.device, dtype=dtype or values.dtype, non_blocking=True)
    return values.index_select(0, batch.sample_index())


def _mirrored(
    batch: EventBatch, flip: Tensor | None, column: Tensor, around: Tensor | int, *, by_streams: bool = False
) -> Tensor | None:
    """``around - column`` on the events of the streams flagged in ``flip`` ((B,) bool CPU,
    ``None``: all), ``column`` elsewhere, in the dtype of ``around - column``; ``None`` when no
    stream is flagged (the column is kept). ``around`` is a number or (B,) per-stream values.

    Every stream: one subtraction (per event gathers of a (B,) ``around``; with
    ``by_streams``, on the CPU, one subtraction per stream instead). Some: on the CPU one
    subtraction per flagged stream (per run of them for a number) and one copy per run of the
    others (slices, no per-event index); elsewhere one ``where`` over a per-event gather of the flags, whatever B. The
    same values either way; no host read of device data."""
    flags = np.ones(len(batch), dtype=bool) if flip is None else np.asarray(flip.tolist(), dtype=bool).reshape(-1)
    if not flags.any():
        return None
    by_runs = _by_runs_on(column.device)
    if flags.all() and not (by_streams and by_runs and isinstance(around, Tensor)):
        return (around if isinstance(around, int) else _per_event(around, batch)) - column
    if not by_runs:
        assert flip is not None  # not every flag is set, so flip was given
        whole = (around if isinstance(around, int) else _per_event(around, batch)) - column
        return torch.where(_per_event(flip, batch), whole, column)
    values = torch.as_tensor(around, dtype=column.dtype if isinstance(around, int) else around.dtype)
    dtype = torch.result_type(values.reshape(-1)[:1] if values.dim() else values, column)
    bounds = batch.offsets.tolist()
    out = torch.empty(column.shape, dtype=dtype, device=column.device)
    for flag, first, end in _runs(flags):
        if not flag:
            out[bounds[first] : bounds[end]].copy_(column[bounds[first] : bounds[end]])
            continue
        if not values.dim():  # one number for every stream: one subtraction per run
            torch.sub(values, column[bounds[first] : bounds[end]], out=out[bounds[first] : bounds[end]])
            continue
        for i in range(first, end):
            torch.sub(values[i], column[bounds[i] : bounds[i + 1]], out=out[bounds[i] : bounds[i + 1]])
    return out


def _compact(batch: EventBatch, keep: Tensor, **changes: Any) -> EventBatch:
    """The events where ``keep`` holds (one host read of the kept counts per stream)."""
    index, offsets = _kept(batch, keep)
    columns = {k: changes.pop(k, getattr(batch, k)).index_select(0, index) for k in ("x", "y", "t", "p")}
    return batch._replace(**columns, offsets=offsets, _sample=None, **changes)


def _kept(batch: EventBatch, keep: Tensor) -> tuple[Tensor, Tensor]:
    """The positions where ``keep`` holds and the kept batch's offsets (CPU).

    One cumulative sum of ``keep`` gives both the kept counts (read at the stream ends: the
    one host read, no per-event scatter) and each kept event's place; one scatter of
    positions then (no ``nonzero``, which reads its size back on an accelerator; on the
    CPU, where it makes nothing wait, one ``nonzero`` and a search of the stream starts). Positions
    and sums are int32 below 2**31 events (half the bytes); the output's sample index is
    rebuilt on demand by a run fill, not gathered."""
    dtype = torch.int32 if keep.shape[0] < 2**31 else torch.int64
    device = keep.device
    if device.type == "cpu" and not torch.compiler.is_compiling():
        # on the CPU nothing waits: one nonzero gives the ascending kept positions, and the
        # kept counts before each stream's start are a search of them (2-3x fewer passes)
        index = keep.nonzero().squeeze(1)
        return index, torch.searchsorted(index, batch.offsets)
    running = torch.cumsum(keep, 0, dtype=dtype)
    at_ends = torch.cat([running.new_zeros(1), running]).index_select(0, batch.offsets.to(device))
    lengths = read_host(at_ends.diff())  # the output size depends on the data: the one read
    offsets = torch.tensor([0, *np.cumsum(lengths, dtype=np.int64).tolist()], dtype=torch.int64)
    size = sum(lengths)
    if size == keep.shape[0]:
        return torch.arange(size, dtype=torch.int64, device=device), offsets
    target = running.sub_(1).masked_fill_(~keep, size).to(torch.int64)
    del running
    out = torch.empty(size + 1, dtype=dtype, device=device)
    out.scatter_(0, target, torch.arange(keep.shape[0], dtype=dtype, device=device))
    return out[:size], offsets


def _require_grid(batch: EventBatch, owner: str, *, frames: bool = True) -> tuple[Tensor, float | int, int]:
    if batch.frame_ms is None or (frames and batch.n_frames is None):
        need = "frame_ms and n_frames" if frames else "frame_ms"
        raise ValueError(
            f"{owner} on events needs the batch's frame grid ({need}): build the batch with "
            f"EventBatch.from_streams(..., frame_ms=..., n_frames=...) or call batch.with_grid(...)"
        )
    return batch.t_start, bin_width_us(batch.frame_ms), batch.n_frames  # type: ignore[return-value]  # n_frames may be None when frames=False


def _round_to(values: Tensor, dtype: torch.dtype) -> Tensor:
    """Nearest whole pixel, clamped to int16 (in place on ``values``, a temporary)."""
    return values.round_().clamp_(-(2**15 - 1), 2**15 - 1).to(dtype)


#: Purposes of the event kernels' draws (:class:`~._random.EventStream`): each kernel names its own.
DROP_KEYS, TES_KEYS = 1, 2
POISSON_COUNT, POISSON_X, POISSON_Y, POISSON_T, POISSON_P = 3, 4, 5, 6, 7
TIME_JITTER, JITTER = 10, 11  # normals (each owns two uniform purposes; jitter takes the pair for x and y)


def _keys(batch: EventBatch, seed: Tensor, fraction: Tensor, purpose: int) -> tuple[Tensor, Tensor]:
    """Per event a float32 uniform key from its sample's counter-based stream (named by the
    sample's seed and the event's position in the sample), and ``key < ζ_b``."""
    u = EventStream.of_batch(batch, seed).uniform32(purpose)
    return u, u < _per_event(fraction.to(torch.float32), batch)


def _append(batch: EventBatch, columns: Sequence[Tensor], counts: Tensor) -> EventBatch:
    """``batch`` with the added events (``columns`` x, y, t, p, sorted by sample, ``counts``
    (B,) of them per sample, a CPU tensor) after stream b's own events.

    Two scatters per column, whatever B: an event of the batch moves by the events added
    before its sample, an added one lands after its sample's own events (the shifts are
    filled run by run, no per-event gather)."""
    counts = counts.to(torch.int64).cpu()
    added = sum(counts.tolist())  # CPU: no device read
    added_before = counts.cumsum(0) - counts
    offsets = batch.offsets + torch.cat([added_before, torch.tensor([added])])
    device = batch.device
    total = batch.num_events + added
    lengths = batch.offsets.diff()
    own = torch.arange(batch.num_events, device=device).add_(
        torch.repeat_interleave(added_before.to(device), lengths.to(device), output_size=batch.num_events))
    extra = torch.arange(added, device=device).add_(
        torch.repeat_interleave(batch.offsets[1:].to(device), counts.to(device), output_size=added))
    cols = []
    for name, column_added in zip(("x", "y", "t", "p"), columns):
        column = getattr(batch, name)
        out = torch.empty(total, dtype=column.dtype, device=device)
        out.index_copy_(0, own, column)
        out.index_copy_(0, extra, column_added.to(column.dtype))
        cols.append(out)
    return batch._replace(x=cols[0], y=cols[1], t=cols[2], p=cols[3], offsets=offsets, _sample=None)
