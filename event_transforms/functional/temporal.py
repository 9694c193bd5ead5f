"""Temporal kernels: frame shifting (FS), temporal event shifting (TES), time reversal and
temporal crop.

Sign convention (as in the README): ``shift = j`` moves frame (or events) t to t + j; j < 0 is
earlier ("left"). The paper's best settings are FS-1 = ``frame_shift(frames, -1)`` and
TES-2(0.50) = ``temporal_event_shift(frames, -2, 0.5)``. Whatever leaves the sequence
through either end is dropped; vacated frames are zero.

:func:`time_reversal` plays a sequence backwards: it reverses the frames *and* swaps the
polarity channels (0 = OFF, 1 = ON), because a brightness increase played backwards is a
decrease. :func:`crop_time` keeps a window of frames. All of these keep the dtype
(``temporal_event_shift(mode="expected")`` aside).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .._params import Param, check_args
from .._validation import (
    HOST_READ, TES_MODES, check_choice, check_counts, check_generator, count_stats, on_host, read_host,
)
from ..events.batch import EventBatch
from ..events._ingest import bin_width_us
from ._frame_ops import check_length
from ._dispatch import batch_of, call_kernel, register_kernel, shape_of
from ..events.dropped import counting, record_dropped
from ._event_ops import TES_KEYS, _kept, _mirrored, _keys, _per_event, _require_grid
from ._random import draw_seeds
from ._hypergeometric import (
    _EXPAND_MAX, Stream, binomial_counts, level_stats, multivariate_hypergeometric, segment_sum,
)

__all__ = [
    "frame_shift", "frame_shift_frames", "frame_shift_events",
    "temporal_event_shift", "temporal_event_shift_frames", "temporal_event_shift_events",
    "time_reversal", "time_reversal_frames", "time_reversal_events",
    "crop_time", "crop_time_frames", "crop_time_events",
]

ShiftArg = int | Sequence[int] | Tensor
FractionArg = float | Sequence[float] | Tensor
Scalars = float | Sequence[float] | Tensor

_TES_HINT = (
    "temporal_event_shift(mode='exact' or 'binomial') moves whole events; apply it before "
    "interpolating transforms (bilinear rotate/resize) or use mode='expected'"
)
# A view of float bits as integers of the same width: non-zero bits <=> non-zero value
# (except -0.0, which becomes an entry with count 0, harmlessly). nonzero() is faster on it.
_BITS = {
    torch.float16: torch.int16,
    torch.bfloat16: torch.int16,
    torch.float32: torch.int32,
    torch.float64: torch.int64,
}
#: Dtypes whose CPU ``nonzero`` goes through numpy (:func:`_entries`).
_NUMPY_NONZERO = (torch.bool, torch.uint8, torch.int8, torch.int16, torch.int32, torch.int64)


# --------------------------------------------------------------------------- declarations
# Each operation's per-sample arguments, declared once: the dispatcher checks its arguments
# against it (check_args), the module's params_spec returns it (check_tree).

#: :func:`frame_shift`: whole frames j.
FRAME_SHIFT_SPEC = {"shift": Param("int")}
#: :func:`temporal_event_shift`: whole frames j and the fraction ζ of the events moved.
TEMPORAL_EVENT_SHIFT_SPEC = {"shift": Param("int"), "fraction": Param("float", low=0.0, high=1.0)}


def crop_time_spec(shape: Sequence[int], length: int) -> dict[str, Param]:
    """:func:`crop_time`'s first frame for a batch ``shape`` (B, T, 2, H, W) and a window of
    ``length`` frames (in [1, T]): ``start`` in [0, T - length]."""
    return {"start": Param("int", low=0, high=shape[1] - length)}


# --------------------------------------------------------------------------- frame shift


def frame_shift(inputs: Tensor | EventBatch, shift: ShiftArg) -> Tensor | EventBatch:
    """Frame shifting FS-j: move every frame of a sequence ``shift`` bins in time.

    Output frame t is input frame t - j; frames shifted past either end are dropped and
    vacated frames are zero. |j| >= T gives all zeros. Values are moved, not inspected,
    so any dtype works and the dtype and device are kept. The ground truth (labels) is
    not touched (the paper keeps the ground truth).

    Cost: one copy of the input (a concatenation with zero frames when the whole batch
    shares one shift; otherwise one gather of whole frames plus zeroing the few vacated
    frames). A ``shift`` tensor on an accelerator is read on the host once.

    On an EventBatch (:func:`frame_shift_events`) every event moves j bins of the batch's
    frame grid and events pushed out of the grid's window are dropped.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        shift: whole frames j, an int or a ``(B,)`` integer tensor/sequence (one per
            sample). j < 0 moves frames earlier (the paper's FS-1 is ``shift=-1``).

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> frames = torch.zeros(4, 2, 1, 2, dtype=torch.int64)
        >>> frames[:, 1, 0, 0] = torch.tensor([1, 2, 3, 4])
        >>> frame_shift(frames, -1)[:, 1, 0, 0]
        tensor([2, 3, 4, 0])
        >>> frame_shift(torch.stack([frames, frames]), torch.tensor([1, 5]))[:, :, 1, 0, 0]
        tensor([[0, 1, 2, 3],
                [0, 0, 0, 0]])
    """
    batch, b, restore = batch_of(inputs)
    return restore(call_kernel(frame_shift, batch, check_args("frame_shift", FRAME_SHIFT_SPEC, b, shift=shift)["shift"]))


@register_kernel(frame_shift, Tensor)
def frame_shift_frames(batch: Tensor, shifts: Tensor) -> Tensor:
    """Kernel of :func:`frame_shift` on a (B, T, 2, H, W) batch with (B,) int64 CPU shifts.

    The shifts are read on the host (no device synchronisation). One shift for the whole
    batch: one concatenation with zero frames. Per-sample shifts: one gather of whole
    frames by a host-built row index, then zeroing the few vacated frames.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        shifts: ``(B,)`` integer shifts in frames (``j``: frame t moves to t + j).

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`frame_shift` gives for a batch.
    """
    b, t = batch.shape[:2]
    if batch.numel() == 0:
        return batch.clone()
    if not on_host(shifts):  # compiling, or shifts on an accelerator: tensor ops only
        source = torch.arange(t, device=batch.device) - shifts.to(batch.device).view(b, 1)  # (B, T)
        vacated = (source < 0) | (source >= t)
        rows = (source.clamp(0, t - 1) + t * torch.arange(b, device=batch.device).view(b, 1)).view(-1)
        out = batch.reshape(b * t, -1).index_select(0, rows).view(batch.shape)
        return out.masked_fill(vacated.view(b, t, *([1] * (batch.dim() - 2))), 0)
    values = np.clip(np.asarray(shifts.tolist(), dtype=np.int64).reshape(b), -t, t)
    first = int(values[0])
    if (values == first).all():
        if first == 0:
            return batch.clone(memory_format=torch.contiguous_format)
        zeros = batch.new_zeros((b, abs(first), *batch.shape[2:]))
        if first > 0:
            return torch.cat([zeros, batch[:, : t - first]], dim=1)
        return torch.cat([batch[:, -first:], zeros], dim=1)
    origin = np.arange(t)[None, :] - values[:, None]  # (B, T)
    emptied = np.flatnonzero((origin < 0) | (origin >= t))
    picks = (np.clip(origin, 0, t - 1) + t * np.arange(b)[:, None]).reshape(-1)
    out = batch.reshape(b * t, -1).index_select(0, torch.from_numpy(picks).to(batch.device))
    if emptied.size:
        out.index_fill_(0, torch.from_numpy(emptied).to(batch.device), 0)
    return out.view(batch.shape)


# --------------------------------------------------------------------------- TES


def temporal_event_shift(
    inputs: Tensor | EventBatch,
    shift: ShiftArg,
    fraction: FractionArg,
    *,
    mode: str = "exact",
    generator: torch.Generator | None = None,
) -> Tensor | EventBatch:
    """Temporal event shifting TES-j(ζ): move a fraction of each frame's events j frames.

    For every sample, frame t and polarity with N events X_t (per pixel), a subset
    Z_t <= X_t is chosen and moved to frame t + j:
    ``out_t = X_t - Z_t + Z_{t-j}``; events moved past either end are dropped, as in
    :func:`frame_shift`. ``fraction = 1`` equals ``frame_shift`` exactly and
    ``fraction = 0`` is the identity.

    Modes:

    - ``"exact"`` (default, the paper's TES): Z_t is a uniformly random subset of
      k = round(ζ N) of the N events (multivariate hypergeometric per pixel), so
      ΣZ_t = k exactly and 0 <= Z_t <= X_t. Rounding is ``torch.round`` (half to even:
      ζ N = 2.5 gives 2, 3.5 gives 4). Drawn without expanding events: a binomial draw
      Z' ~ Binomial(X, k / N) followed by an exact hypergeometric correction of the
      ~sqrt(N) surplus or deficit, recursively, finished by drawing distinct event
      positions (see ``_hypergeometric.multivariate_hypergeometric`` for the proof of
      exactness and the cost).
    - ``"binomial"``: every event moves independently with probability ζ
      (Z ~ Binomial(X, ζ)); ΣZ_t = ζ N only in expectation. Faster.
    - ``"expected"``: Z_t = ζ X_t deterministically (fractional counts).

    Cost: all modes work on the non-zero pixels only (one ``nonzero`` over the input,
    then vectors of that length, one copy of the input for the output), never on single
    events: extra memory is a few int64 vectors over the non-zero pixels whatever N
    (10**7 events in one pixel cost one entry). Host synchronisations: a handful per call
    (value checks; in exact mode one per recursion level and per round of the final
    draw, about 10-15 in all), none per frame or sample.

    Dtype: ``"exact"`` and ``"binomial"`` conserve counts and keep the dtype; they need
    integer-valued counts (integer dtypes, or floats holding whole numbers up to 2**53)
    and raise ``ValueError`` otherwise. ``"expected"`` returns the input dtype for float
    input and float32 for integer input. The device is kept. Counts are added in a wide
    dtype where the input's could overflow or round (uint8 at 250, int16 at 32,760,
    bfloat16 above 256): a result that the input dtype cannot hold exactly raises
    ``ValueError`` with the largest count, never wraps. With a ``torch.Generator`` the
    result is a deterministic function of the input and the generator state: it draws
    one seed per sample, and each sample's events are chosen from a counter-based stream
    keyed by that seed (:mod:`._random`), so a sample's result does not depend on the
    rest of its batch.

    On an EventBatch (:func:`temporal_event_shift_events`, modes ``"exact"`` and
    ``"binomial"``) the same law moves events on the batch's frame grid.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, non-negative, or an EventBatch.
        shift: whole frames j, an int or a ``(B,)`` integer tensor (one per sample);
            j < 0 moves events earlier (the paper's TES-2(0.50) is ``shift=-2``).
        fraction: ζ in [0, 1], a float or a ``(B,)`` tensor (one per sample).
        mode: ``"exact"``, ``"binomial"`` or ``"expected"``.
        generator: source of randomness on the frames' device; ``None`` uses torch's
            global RNG.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape.

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> frames = torch.zeros(3, 2, 4, 4, dtype=torch.int64)
        >>> frames[1, 1] = 2  # 32 ON events in frame 1
        >>> out = temporal_event_shift(frames, -1, 0.5, generator=g)
        >>> out[:, 1].sum(dim=(-2, -1))  # exactly 16 of them moved one frame earlier
        tensor([16, 16,  0])
        >>> bool((out[1, 1] <= frames[1, 1]).all())
        True
        >>> temporal_event_shift(frames, -1, 0.25, mode="expected")[:, 1, 0, 0]
        tensor([0.5000, 1.5000, 0.0000])
    """
    batch, b, restore = batch_of(inputs)
    check_choice(mode, "mode", TES_MODES)
    args = check_args("temporal_event_shift", TEMPORAL_EVENT_SHIFT_SPEC, b, shift=shift, fraction=fraction)
    check_generator(generator, batch.device)
    seeds = None if mode == "expected" else draw_seeds(b, generator)
    return restore(call_kernel(temporal_event_shift, batch, args["shift"], args["fraction"], mode, seeds))


@register_kernel(temporal_event_shift, Tensor)
@torch.compiler.disable
def temporal_event_shift_frames(
    batch: Tensor,
    shifts: Tensor,
    fractions: Tensor,
    mode: str,
    seeds: Tensor | None,
    hint: str = _TES_HINT,
) -> Tensor:
    """Kernel of :func:`temporal_event_shift` on a (B, T, 2, H, W) batch with checked (B,) CPU parameters
    and (B,) int64 per-sample ``seeds`` (any device; unused in mode ``"expected"``);
    ``hint`` ends the error raised for fractional counts.

    Under :func:`torch.compile` it runs eagerly (``torch.compiler.disable``: one silent graph
    break, not one warned break per host read of its draw); ``fullgraph=True`` cannot hold it.

    Host synchronisations: one ``nonzero`` (the active pixels), then one read that checks
    their values and brings back what the sampler needs (the largest count; in exact mode
    also the largest draw of any frame), then in exact mode the sampler's own (see
    :func:`~._hypergeometric.multivariate_hypergeometric`).

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        shifts: ``(B,)`` integer shifts in frames (``j``: frame t moves to t + j).
        fractions: ``(B,)`` ζ in [0, 1], the share of each frame's and polarity's events moved.
        mode: ``"exact"``, ``"binomial"`` or ``"expected"``.
        seeds: ``(B,)`` int64 per-sample seeds of the counter-based streams.
        hint: the advice in the error message when the counts are not whole.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`temporal_event_shift` gives for a batch.
    """
    index, sample, values = _entries(batch)
    if mode == "expected":
        check_counts(values, "frames")
        dtype = batch.dtype if batch.is_floating_point() else torch.float32
        out = batch.to(dtype, memory_format=torch.contiguous_format, copy=True)
        values = values.to(dtype)
        moved = values * fractions.to(device=batch.device, dtype=dtype).index_select(0, sample)
        return _move(out, index, sample, moved, shifts)
    out = batch.clone(memory_format=torch.contiguous_format)
    if index.numel() == 0:
        return out
    if seeds is None:
        raise ValueError(f"temporal_event_shift with mode={mode!r} needs seeds (one int64 seed per sample)")
    moved, high = _draw_moved(batch.shape, index, sample, values, fractions, mode, seeds, hint)
    exact = _exact_limit(batch.dtype)
    if 2 * high <= exact:  # X - Z + Z' <= 2 max X: the dtype holds every result
        return _move(out, index, sample, moved, shifts)
    wide = batch.to(torch.float64 if batch.is_floating_point() else torch.int64, memory_format=torch.contiguous_format)
    wide = _move(wide, index, sample, moved, shifts)
    peak = read_host(wide.max())
    if peak > exact:
        raise ValueError(
            f"temporal_event_shift: the shifted frames hold up to {peak:g} events in a pixel, more than "
            f"{batch.dtype} holds exactly ({exact:g}); convert the frames to a wider dtype first "
            "(e.g. frames.to(torch.int32))"
        )
    return wide.to(batch.dtype)


def _exact_limit(dtype: torch.dtype) -> float:
    """The largest count ``dtype`` holds exactly (and every count below it)."""
    if dtype.is_floating_point:
        return float(2 / torch.finfo(dtype).eps)  # 2**(mantissa bits + 1)
    return float(torch.iinfo(dtype).max)


def _entries(batch: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """The non-zero pixels of a (B, T, 2, H, W) batch: sorted flat indices, sample indices
    and values (one ``nonzero``, the only data-dependent size of the kernel).

    The float bits are read as integers of the same width (a faster ``nonzero``); -0.0
    becomes an entry holding 0, harmlessly. Only these values can be negative, NaN or
    fractional, so checking them costs O(non-zero pixels).
    """
    b, t, p, h, w = batch.shape
    flat = batch.reshape(-1)
    bits = flat.view(_BITS[flat.dtype]) if flat.dtype in _BITS else flat
    if bits.device.type == "cpu" and bits.dtype in _NUMPY_NONZERO and not torch.compiler.is_compiling():
        # numpy's ``!= 0`` then ``flatnonzero`` of the bools: about half the time of torch's
        # ``nonzero`` on one CPU thread (a host read of the data-dependent size, as nonzero)
        with torch.profiler.record_function(HOST_READ):
            index = torch.from_numpy(np.flatnonzero(bits.detach().numpy() != 0).astype(np.int64, copy=False))
    else:
        index = bits.nonzero(as_tuple=True)[0]
    return index, index.div(t * p * h * w, rounding_mode="floor"), flat.index_select(0, index)


def _draw_moved(
    shape: torch.Size,
    index: Tensor,
    sample: Tensor,
    values: Tensor,
    fractions: Tensor,
    mode: str,
    seeds: Tensor,
    hint: str = _TES_HINT,
) -> tuple[Tensor, float]:
    """Check the values X of the non-zero pixels ``index`` (whole, non-negative, finite) and
    draw the moved counts Z (0 <= Z <= X), ``mode`` ``"exact"`` (int64) or ``"binomial"``
    (in the values' dtype, ready to subtract).

    One host synchronisation checks the values and reads what the sampler needs (the
    largest count and the events to expand; in exact mode also the largest draw and the
    widest frame), so the sampler's top level asks the device for nothing. Returns Z and
    the largest count X (read with the check).

    The draws come from per-sample streams (``seeds``): an entry is named by its position
    within its sample, a row by its frame and polarity, so a sample's Z does not depend on
    the other samples.
    """
    b, t, p, h, w = shape
    counts = values.to(torch.int64)  # used only once the check below has passed
    if index.numel() == 0:
        return counts, 0.0
    counter = index - sample * (t * p * h * w)  # the entry's place in its sample
    # int32 counters when they fit: the same hash (its high word is 0), three passes fewer
    stream = Stream.of_samples(seeds, sample, counter.to(torch.int32) if t * p * h * w < 2**31 else counter, t * p)
    limit = min(2**53, 2**62 // (h * w))  # float64-exact counts; row totals fit in int64
    if mode == "binomial":
        high, events = count_stats(values, counts, hint=hint, extra=[counts.clamp_max(_EXPAND_MAX).sum()])
        _check_limit(high, limit)
        prob = fractions.to(values.device, torch.float64)
        return binomial_counts(
            counts, prob, sample, stream=stream, largest=high, events=events, dtype=values.dtype
        ), high
    row = index.div(h * w, rounding_mode="floor")  # (sample, frame, polarity), sorted
    total = segment_sum(counts, row, b * t * p)
    row_fraction = fractions.repeat_interleave(t * p)  # ζ per row (float64), on the host
    size = torch.round(row_fraction.to(values.device, torch.float64) * total).to(torch.int64)
    # The top level's numbers come with the check; the binomial level's only where it runs.
    needs = level_stats(size, total) + [counts.clamp_max(_EXPAND_MAX).sum()]
    high, *stats = count_stats(values, counts, hint=hint, extra=needs)
    _check_limit(high, limit)
    return multivariate_hypergeometric(
        counts, row, size, total=total, stream=stream, stats=int(stats[0]), expansion=(high, int(stats[1])),
    ), high


def _check_limit(high: float, limit: int) -> None:
    if high > limit:
        raise ValueError(f"frames: counts above {limit} per pixel are not supported, got {high}")


def _move(out: Tensor, index: Tensor, sample: Tensor, moved: Tensor, shifts: Tensor) -> Tensor:
    """Turn ``out`` (a contiguous copy of X) into ``X - Z + frame_shift(Z)`` in place.

    Z (``moved``) is given on the non-zero pixels ``index``; it moves to
    ``index + j * frame`` unless that leaves the sample's sequence (then it is dropped).
    Two ``index_add_`` calls; no data-dependent shape, no host synchronisation.
    """
    if index.numel() == 0:
        return out
    t = out.shape[1]
    frame = math.prod(out.shape[2:])
    flat = out.view(-1)
    moved = moved if moved.dtype == out.dtype else moved.to(out.dtype)
    flat.index_add_(0, index, moved, alpha=-1)  # X - Z on the non-zero pixels
    step = shifts.clamp(-t, t).to(out.device)  # CPU parameters, moved once
    target = torch.add(index, step.index_select(0, sample), alpha=frame)
    dropped = target.div(t * frame, rounding_mode="floor") != sample
    # Dropped events add 0 to their own pixel (no data-dependent shapes, no sync).
    flat.index_add_(0, torch.where(dropped, index, target), moved.masked_fill_(dropped, 0))
    return out


# --------------------------------------------------------------------------- reversal and crop


def time_reversal(inputs: Tensor | EventBatch, reverse: Tensor | None = None) -> Tensor | EventBatch:
    """Play each sequence backwards: reverse the frames and swap the polarities.

    Frame t goes to T - 1 - t, and an ON event becomes an OFF event (a brightness change
    reversed in time has the opposite sign), as tonic's ``RandomTimeReversal`` does with
    ``flip_polarities=True``. Counts and dtype are kept. On an EventBatch
    (:func:`time_reversal_events`) times are mirrored in the batch's frame grid.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        reverse: ``(B,)`` bool, the samples to reverse (default: all).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> frames = torch.zeros(3, 2, 1, 1, dtype=torch.int8)
        >>> frames[0, 1] = 4  # ON events in the first frame
        >>> time_reversal(frames)[:, :, 0, 0].tolist()
        [[0, 0], [0, 0], [4, 0]]
    """
    from ._frame_ops import _flags

    batch, b, restore = batch_of(inputs)
    return restore(call_kernel(time_reversal, batch, _flags(reverse, b, "reverse")))


@register_kernel(time_reversal, Tensor)
def time_reversal_frames(frames: Tensor, reverse: Tensor | None = None) -> Tensor:
    """Kernel of :func:`time_reversal` for frames ``(B, T, 2, H, W)``: the flagged samples reversed.

    Args:
        frames: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        reverse: ``(B,)`` bool, the samples to reverse (default: all).

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`time_reversal` gives for a batch.
    """
    from ._frame_ops import _flagged_rows

    rows = frames.shape[1] * frames.shape[2]  # (frame, polarity) t, p -> T - 1 - t, 1 - p: the rows reversed
    return _flagged_rows(frames, reverse, lambda f: f.flip(-4, -3), np.arange(rows)[::-1].copy())


@register_kernel(time_reversal, EventBatch)
def time_reversal_events(batch: EventBatch, reverse: Tensor | None = None) -> EventBatch:
    """Kernel of :func:`time_reversal` for an EventBatch: bin i goes to T - 1 - i (integer
    timestamps: ``t -> 2 t0 + T frame - 1 - t``, so the binned frames are exactly the frame
    kernel's reversal) and polarities are swapped, for the flagged samples. Sync-free.

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        reverse: ``(B,)`` bool, the samples to reverse (``None``: all).

    Shape:
        - batch: B streams, N events.
        - reverse: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> time_reversal_events(batch, torch.tensor([True, False])).t.tolist()  # t -> 19999 - t
        [19899, 4999, 50]
    """
    from .polarity import flip_polarity_events

    flip = None if reverse is None else reverse.to(torch.bool)
    return flip_polarity_events(_reverse_times(batch, flip), flip)


def _reverse_times(batch: EventBatch, reverse: Tensor | None) -> EventBatch:
    """Times mirrored in the grid's window for the samples flagged in ``reverse`` (``None``: all)."""
    starts, frame_us, n_frames = _require_grid(batch, "TimeReversal")
    end = starts.to(batch.t.dtype) * 2 + n_frames * frame_us - (0 if batch.t.is_floating_point() else 1)
    t = _mirrored(batch, reverse, batch.t, end, by_streams=True)
    return batch if t is None else batch._replace(t=t.to(batch.t.dtype))

def crop_time(inputs: Tensor | EventBatch, start: Scalars, length: int) -> Tensor | EventBatch:
    """Keep frames ``[start, start + length)`` of each sequence (a temporal window).

    tonic's ``CropTime`` on frames: the window is counted in frames, not microseconds.
    Labels per frame (force) must be cut with the same window:
    ``labels.gather(1, start.view(-1, 1) + torch.arange(length))``.

    On an EventBatch (:func:`crop_time_events`) times move ``start`` bins earlier and the
    batch's grid becomes ``length`` bins.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch with a grid.
        start: first kept frame, an integer or ``(B,)``, with ``start + length <= T``.
        length: number of kept frames, in [1, T].

    Returns:
        ``(length, 2, H, W)`` or ``(B, length, 2, H, W)``; dtype and device kept.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - start: an integer or ``(B,)``.
        - output: ``(length, 2, H, W)`` or ``(B, length, 2, H, W)``, dtype and device kept.

    Example:
        >>> frames = torch.arange(5).view(5, 1, 1, 1).expand(5, 2, 1, 1)
        >>> crop_time(frames, 1, 3)[:, 0, 0, 0].tolist()
        [1, 2, 3]
    """
    batch, b, restore = batch_of(inputs)
    shape = shape_of(batch)
    size = check_length(length, shape[1])
    start_t = check_args("crop_time", crop_time_spec(shape, size), b, start=start)["start"]
    return restore(call_kernel(crop_time, batch, start_t, size))


@register_kernel(crop_time, Tensor)
def crop_time_frames(batch: Tensor, start: Tensor, length: int) -> Tensor:
    """Kernel of :func:`crop_time`: frames ``[start, start + length)`` with a (B,) int64 CPU ``start``.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        start: first kept frame, an integer or ``(B,)``, with ``start + length <= T``.
        length: number of kept frames, in [1, T].

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`crop_time` gives for a batch.
    """
    b, t, p, h, w = batch.shape
    index = (start.unsqueeze(1) + torch.arange(length)).to(batch.device, non_blocking=True)  # (B, length)
    if b == 0 or batch.numel() == 0:
        return batch.new_zeros((b, length, p, h, w))
    return batch.gather(1, index.view(b, length, 1, 1, 1).expand(b, length, p, h, w))


@register_kernel(crop_time, EventBatch)
def crop_time_events(batch: EventBatch, start: Tensor, length: int) -> EventBatch:
    """Keep bins ``[start[b], start[b] + length)`` of the grid: times move ``start[b]`` bins
    earlier and the grid becomes ``length`` bins long (events outside it are dropped when
    binned; equal to the frame kernel after binning). Sync-free.

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        start: ``(B,)`` first kept bin per sample.
        length: number of kept bins.

    Shape:
        - batch: B streams, N events.
        - start: ``(B,)``.
        - output: the same streams and events, the grid ``length`` bins long.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> cropped = crop_time_events(batch, torch.tensor([1, 0]), 1)
        >>> cropped.t.tolist(), cropped.n_frames
        ([-9900, 5000, 50], 1)
    """
    _, frame_us, n_frames = _require_grid(batch, "CropTime")
    if isinstance(frame_us, int) and not batch.t.is_floating_point():
        t = batch.t - _per_event(start.to(torch.int64) * frame_us, batch)
    else:
        t = (batch.t.to(torch.float64) - _per_event(start.to(torch.float64) * frame_us, batch)).to(batch.t.dtype)
    return batch._replace(t=t, n_frames=int(length))


# --------------------------------------------------------------------------- FS and TES on events


@register_kernel(frame_shift, EventBatch)
def frame_shift_events(batch: EventBatch, shifts: Tensor) -> EventBatch:
    """Kernel of :func:`frame_shift` for an EventBatch with a frame grid: every event moves
    ``shifts[b]`` bins (``t += j * frame``); events pushed out of the window are dropped.

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        shifts: ``(B,)`` integer bins ``j`` (``t += j * frame``).

    Shape:
        - batch: B streams, N events.
        - shifts: ``(B,)``.
        - output: B streams, at most N events (those pushed out of the window dropped).

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> shifted = frame_shift_events(batch, torch.tensor([1, 1]))  # a bin later
        >>> shifted.t.tolist(), shifted.lengths  # the event in the last bin left the window
        ([10100, 10050], [1, 1])
    """
    return _shift_events(batch, shifts)


@register_kernel(temporal_event_shift, EventBatch)
def temporal_event_shift_events(
    batch: EventBatch,
    shifts: Tensor,
    fractions: Tensor,
    mode: str,
    seeds: Tensor | None,
    hint: str = _TES_HINT,
) -> EventBatch:
    """Kernel of :func:`temporal_event_shift` for an EventBatch with a frame grid (modes
    ``"exact"`` and ``"binomial"``; ``"expected"`` moves fractions of events and is refused).

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        shifts: ``(B,)`` integer bins ``j``.
        fractions: ``(B,)`` ζ in [0, 1], the share of each bin's and polarity's events moved.
        mode: ``"exact"`` (exactly round(ζ N)) or ``"binomial"``; ``"expected"`` is refused.
        seeds: ``(B,)`` int64 per-sample seeds.
        hint: the advice in the error for ``mode="expected"``.

    Shape:
        - batch: B streams, N events.
        - shifts, fractions, seeds: ``(B,)``.
        - output: B streams, at most N events (those pushed out of the window dropped).

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> out = temporal_event_shift_events(batch, torch.tensor([1, 1]), torch.tensor([0.0, 1.0]), "exact",
        ...                                   torch.tensor([1, 2]))
        >>> out.t.tolist()  # ζ = 0 moves nothing; ζ = 1 moves every event a bin later
        [100, 15000, 10050]
    """
    if mode == "expected":
        raise ValueError("TES mode='expected' moves fractions of events, which events cannot hold; "
                         "use mode='exact' or 'binomial' on an EventBatch")
    return _shift_events(batch, shifts, fractions, seed=seeds, mode=mode)


def _groups(batch: EventBatch) -> tuple[Tensor, int]:
    """Per event its group ``(sample * T + bin) * 2 + p`` (int32; ``G`` outside the grid's
    window) and the number of groups G."""
    starts, frame_us, n_frames = _require_grid(batch, "frame shift / TES")
    from ..events._kernel import relative_times
    from ..events._kernel import bins_of

    sample = batch.sample_index()
    bins, inside = bins_of(relative_times(batch, starts), frame_us, n_frames)
    groups = len(batch) * n_frames * 2
    index = torch.int32 if groups < 2**31 - 1 else torch.int64
    group = sample.to(index).mul(n_frames).add_(bins).mul_(2).add_(batch.p)  # a new tensor: the cached index is kept
    return group.masked_fill_(~inside, groups), groups


def _shift_events(
    batch: EventBatch,
    shift: Tensor,
    fraction: Tensor | None = None,
    *,
    seed: Tensor | None = None,
    mode: str = "exact",
) -> EventBatch:
    """Frame shift (``fraction=None``) or TES-j(ζ) on events, on the batch's frame grid.

    In every sample, bin and polarity holding N events (of the grid's window), ``"exact"``
    moves a uniformly random subset of exactly k = round(ζ N) of them (``torch.round``,
    half to even, as the frame kernel) by ``shift[b]`` bins (``t += j * frame``), the
    same law as :func:`~event_transforms.functional.temporal_event_shift` in exact mode;
    ``"binomial"`` moves each event with probability ζ. Events pushed out of the window
    are dropped (as in the frame kernels); events outside the window never move.

    Exact selection: each event gets a float32 uniform key u from its sample's
    counter-based stream (seed and position in the sample); the k events with the
    smallest keys of a group are the ones moved (ties, at 2**-23,
    are broken by position). A binomial level (u < ζ) picks all but a ~sqrt(N) surplus or
    deficit per group, fixed by ranking only the events whose keys lie in a narrow band
    next to ζ (no full sort). Host syncs: one read of the per-group surplus, one band
    gather (retried wider only if a band held too few events), one read of the kept counts.
    """
    group, groups = _groups(batch)
    frame_us = bin_width_us(batch.frame_ms)
    n_frames = _require_grid(batch, "frame shift / TES")[2]  # an int: _groups checked the grid
    device = batch.device
    inside = group < groups
    if fraction is None:
        moved = inside
    else:
        if seed is None:
            raise ValueError(f"temporal_event_shift on events with mode={mode!r} needs seed (one int64 per sample)")
        u, below = _keys(batch, seed, fraction, TES_KEYS)
        moved = below.logical_and_(inside)
        del below, inside
        if mode == "exact":
            moved = _exact_fixup(group, groups, u, moved, fraction, n_frames)
        del u
    # a group's events all land in bin + j: whether they leave the window is per group
    jump = shift.to(torch.int64)
    group_bin = torch.arange(n_frames).repeat(len(batch)).repeat_interleave(2)
    leaving = group_bin + jump.repeat_interleave(2 * n_frames)
    leaving = torch.cat([(leaving < 0) | (leaving >= n_frames), torch.zeros(1, dtype=torch.bool)]).to(device)
    keep = leaving.index_select(0, group).logical_and_(moved).logical_not_()
    del group
    if counting():  # shifted out of the window by design: counted in a count_dropped block, never warned
        record_dropped("out_of_window", ~keep)
    # compact first, then move the kept events' times (the temporaries are the output's size)
    index, offsets = _kept(batch, keep)
    del keep
    out = batch._replace(**{k: getattr(batch, k).index_select(0, index) for k in ("x", "y", "t", "p")},
                         offsets=offsets, _sample=None)
    moved = moved.index_select(0, index)
    del index
    if isinstance(frame_us, int) and not batch.t.is_floating_point():
        t = out.t.add_(_per_event(jump * frame_us, out).mul_(moved))  # int64 times stay exact
    else:
        t = (out.t.to(torch.float64) + _per_event(jump.to(torch.float64) * frame_us, out).mul_(moved)).to(out.t.dtype)
    return out._replace(t=t)


def _exact_fixup(group: Tensor, groups: int, u: Tensor, moved: Tensor, fraction: Tensor, n_frames: int) -> Tensor:
    """Turn the binomial choice ``moved`` into exactly round(ζ N) smallest keys per group."""
    device = group.device
    # events and chosen events per group in one scatter: 1 + 2**32 per chosen event, 1 per other
    # (a group holds fewer than 2**31 events: the low word counts them, the high word the chosen)
    both = torch.zeros(groups + 1, dtype=torch.int64, device=device).index_add_(
        0, group, torch.where(moved, 2**32 + 1, 1))[:groups]
    total, chosen = both & 0xFFFFFFFF, both >> 32
    group_zeta = fraction.to(torch.float64).repeat_interleave(n_frames * 2).to(device)
    want = torch.round(group_zeta * total.to(torch.float64)).to(torch.int64)
    surplus = chosen - want
    if groups == 0 or read_host(surplus.abs().amax().reshape(1))[0] == 0:
        return moved
    need = surplus.abs()
    zeta = group_zeta.to(torch.float32)
    width = (need + 3 * need.sqrt() + 4) / total.clamp_min(1)
    empty = torch.full((1,), 2.0, dtype=torch.float32, device=device)
    while True:
        # surplus groups un-move the largest keys in [ζ - w, ζ); deficit groups move the
        # smallest keys in [ζ, ζ + w); other groups (and events outside the window) none
        low = torch.where(surplus > 0, zeta - width, torch.where(surplus < 0, zeta, 2.0)).to(torch.float32)
        high = torch.where(surplus > 0, zeta, torch.where(surplus < 0, zeta + width, 2.0)).to(torch.float32)
        key_low, key_high = torch.cat([low, empty]), torch.cat([high, empty])
        band = ((u >= key_low.index_select(0, group)) & (u < key_high.index_select(0, group))).nonzero().squeeze(1)
        band_group = group.index_select(0, band)
        have = torch.zeros(groups + 1, dtype=torch.int64, device=device).index_add_(
            0, band_group, torch.ones_like(band_group, dtype=torch.int64))[:groups]
        short = (have < need) & (width < 2)
        if not read_host(short.any().reshape(1))[0]:
            break
        width = torch.where(short, width * 4, width)
    # one sort by group, then key (largest first for a surplus): 2 g + key in float64
    key = u.index_select(0, band).to(torch.float64)
    key = torch.where(surplus.index_select(0, band_group) > 0, 1.0 - key, key) + 2.0 * band_group
    order = torch.argsort(key, stable=True)
    sorted_group = band_group.index_select(0, order)
    first = torch.cumsum(have, 0) - have
    rank = torch.arange(order.shape[0], device=device) - first.index_select(0, sorted_group)
    flip = rank < need.index_select(0, sorted_group)
    target = band.index_select(0, order)
    out = moved.clone()
    out.index_put_((target,), flip ^ out.index_select(0, target))
    return out





