"""Kernels on an :class:`~event_transforms.functional.EventBatch`: the event side of the transforms.

Each kernel takes a batch and per-sample parameters (``(B,)`` CPU tensors, as
:meth:`~event_transforms.EventTransform.make_params` draws them) and returns a new batch on
the same device; nothing is modified in place. Coordinates stay int16, timestamps keep
their dtype, polarity stays int8.

**Per-sample randomness.** Kernels that draw (TES, event drop, jitter, Poisson noise) use
one generator per sample, seeded with that sample's 63-bit seed from the params (Philox
on CUDA, a counter-based stream; Mersenne Twister on the CPU), and draw that sample's
numbers in event order, one slice per sample (B small draws per call). So a stream's output depends only on its own events and its own
seed: ``kernel(batch[i:i+1], params[i:i+1])`` equals ``kernel(batch, params)[i]``. CPU and
CUDA draws differ (different engines); each is reproducible.

**Where events and frames differ.** A rotated, resized or jittered event lands in one
pixel (rounded to the nearest), so counts are conserved; a bilinear warp of frames
spreads each count over up to four pixels (and a zoom by β multiplies the total by about
β²). Events moved outside the sensor are kept (no host synchronisation, counts kept) and
dropped when binned; a later transform that moves them back brings them back, which
frames cannot. Frame shift and TES drop the events they push out of the grid's window,
as the frame kernels do.

Host synchronisations: none, except where the output size depends on the data (event
drop, frame shift/TES dropping events pushed out of the window, refractory period,
decimation: one read of the kept counts per stream, plus the compaction) and in exact TES
(the fix-up reads the per-group surplus, then gathers the events near the threshold).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from .._validation import read_host
from ..events.batch import EventBatch
from ..events.binning import _frame_us

__all__ = [
    "flip_events", "translate_events", "affine_events", "shift_events", "drop_events_random",
    "flip_polarity_events", "time_reversal_events", "poisson_noise_events", "spatial_jitter",
    "time_jitter", "time_skew", "refractory_period", "decimation", "event_centroid", "drop_window",
    "crop_events", "crop_time_events", "drop_pixels_events", "bank_noise_events",
]


# --------------------------------------------------------------------------- helpers


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
    return batch.t_start, _frame_us(batch.frame_ms), batch.n_frames


def _round_to(values: Tensor, dtype: torch.dtype) -> Tensor:
    """Nearest whole pixel, clamped to int16 (in place on ``values``, a temporary)."""
    return values.round_().clamp_(-(2**15 - 1), 2**15 - 1).to(dtype)


# --------------------------------------------------------------------------- space


def flip_events(batch: EventBatch, flip: Tensor, *, axis: str = "x") -> EventBatch:
    """Mirror the samples whose ``flip`` (B,) bool is set: ``x -> W - 1 - x`` (``axis="x"``,
    a horizontal flip) or ``y -> H - 1 - y``. Sync-free; equal to the frame flip after binning.

    Args:
        batch: the event streams.
        flip: ``(B,)`` bool, the samples to mirror.
        axis: ``"x"`` (left-right) or ``"y"`` (top-bottom).

    Shape:
        - batch: B streams, N events.
        - flip: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> flip_events(batch, torch.tensor([True, False])).x.tolist()  # W = 3: x -> 2 - x in stream 0
        [2, 0, 1]
    """
    column = batch.x if axis == "x" else batch.y
    size = batch.sensor_size[1] if axis == "x" else batch.sensor_size[0]
    flags = flip.tolist()
    if not any(flags):
        return batch
    if all(flags):
        mirrored = (size - 1) - column
    else:
        mirrored = torch.where(_per_event(flip, batch), (size - 1) - column, column)
    return batch._replace(**{axis: mirrored.to(torch.int16)})


def translate_events(batch: EventBatch, shift: Tensor) -> EventBatch:
    """Move sample b's events by ``shift[b] = (dy, dx)`` whole pixels (int). Sync-free.

    Args:
        batch: the event streams.
        shift: ``(B, 2)`` integer ``(dy, dx)`` per sample (down, right).

    Shape:
        - batch: B streams, N events.
        - shift: ``(B, 2)``.
        - output: the same streams and events (events may leave the sensor).

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> moved = translate_events(batch, torch.tensor([[1, 0], [0, -1]]))
        >>> moved.y.tolist(), moved.x.tolist()
        ([2, 1, 1], [0, 2, 0])
    """
    shift = shift.to(torch.int16)
    x = batch.x + _per_event(shift[:, 1].contiguous(), batch)
    y = batch.y + _per_event(shift[:, 0].contiguous(), batch)
    return batch._replace(x=x, y=y)


def event_centroid(batch: EventBatch) -> Tensor:
    """(B, 2) float64 ``(y, x)`` mean event position per stream on the batch's device; an
    empty stream gets the image centre ``((H - 1) / 2, (W - 1) / 2)``. Sync-free.

    Args:
        batch: the event streams.

    Shape:
        - batch: B streams, N events.
        - output: ``(B, 2)`` float64 ``(y, x)`` on the batch's device.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> event_centroid(batch).tolist()
        [[0.5, 1.0], [1.0, 1.0]]
    """
    height, width = batch.sensor_size
    lengths = torch.tensor(batch.lengths, dtype=torch.int64)
    device = batch.device
    if batch.num_events == 0 or len(batch) == 0:
        return torch.tensor([[(height - 1) / 2, (width - 1) / 2]], dtype=torch.float64, device=device).expand(len(batch), 2)
    on_device = lengths.to(device, non_blocking=True)
    if device.type == "cpu":  # slice sums: no per-event index, no float64 copy of the columns
        bounds = batch.offsets.tolist()
        sums = torch.stack([torch.stack([batch.y[lo:hi].sum(dtype=torch.float64), batch.x[lo:hi].sum(dtype=torch.float64)])
                            for lo, hi in zip(bounds, bounds[1:])])
    else:
        sample = batch.sample_index()
        sums = torch.zeros(len(batch), 2, dtype=torch.float64, device=device)
        sums[:, 0].index_add_(0, sample, batch.y.to(torch.float64))
        sums[:, 1].index_add_(0, sample, batch.x.to(torch.float64))
    image = torch.tensor([(height - 1) / 2, (width - 1) / 2], dtype=torch.float64, device=device)
    count = on_device.to(torch.float64).unsqueeze(1)
    return torch.where(count > 0, sums / count.clamp_min(1), image)


def affine_events(
    batch: EventBatch,
    *,
    angle: Tensor | None = None,
    scale: Tensor | None = None,
    center: str | Sequence[float] = "mass",
) -> EventBatch:
    """Rotate by ``angle`` (degrees, counter-clockwise as in :func:`~event_transforms.functional.rotate`)
    and scale by ``scale`` about the centre, per sample; each event moves to the nearest pixel.

    The map is the frame kernel's forward map: ``(x', y') = c + s R (x - c, y - c)`` with
    ``R = [[cos, sin], [-sin, cos]]`` in (x, y) order (y down), ``c`` the event centroid
    of the stream (``center="mass"``, float64, all events), the image centre
    (``"image"``) or a given ``(y, x)``. Count-conserving (a bilinear frame warp spreads
    counts instead). Sync-free: a handful of per-event ops whatever B.

    Args:
        batch: the event streams.
        angle: ``(B,)`` degrees, counter-clockwise; ``None`` for 0.
        scale: ``(B,)`` zoom factors > 0; ``None`` for 1.
        center: ``"mass"`` (each stream's event centroid), ``"image"`` or ``(y, x)``.

    Shape:
        - batch: B streams, N events.
        - angle, scale: ``(B,)``.
        - output: the same streams and events, each at its nearest pixel.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[2, 1, 0, 1]])], sensor_size=(3, 3))
        >>> turned = affine_events(batch, angle=torch.tensor([90.0]), center="image")
        >>> turned.y.tolist(), turned.x.tolist()  # (y, x) = (1, 2) -> (0, 1) about (1, 1)
        ([0], [1])
    """
    b = len(batch)
    radians = np.deg2rad(np.asarray(angle.tolist() if angle is not None else [0.0] * b, dtype=np.float64))
    s = np.asarray(scale.tolist() if scale is not None else [1.0] * b, dtype=np.float64)
    cos, sin = np.cos(radians) * s, np.sin(radians) * s
    height, width = batch.sensor_size
    device = batch.device
    if center == "mass":
        c = event_centroid(batch)
    elif center == "image":
        c = torch.tensor([[(height - 1) / 2, (width - 1) / 2]], dtype=torch.float64, device=device).expand(b, 2)
    else:
        c = torch.as_tensor(center, dtype=torch.float64).to(device).reshape(-1, 2).expand(b, 2)
    if batch.num_events == 0:
        return batch
    linear = torch.from_numpy(np.stack([cos, sin, -sin, cos], 1)).to(device)  # (B, 4): x' row, y' row
    cy, cx = c[:, 0], c[:, 1]
    # x' = a x + b y + e,  y' = c x + d y + f  with e, f folding the centre in
    e = cx - linear[:, 0] * cx - linear[:, 1] * cy
    f = cy - linear[:, 2] * cx - linear[:, 3] * cy
    coefficients = torch.cat([linear, e.unsqueeze(1), f.unsqueeze(1)], 1).to(torch.float32).t().contiguous()
    x, y = batch.x.to(torch.float32), batch.y.to(torch.float32)
    if device.type == "cpu":
        # per-sample slices with the sample's six numbers: no per-event gathers (on the CPU
        # the coefficients are host memory; float32 arithmetic as on accelerators, which may
        # round the last bit differently)
        new_x, new_y = torch.empty_like(x), torch.empty_like(y)
        bounds = batch.offsets.tolist()
        for i, (a, bb, cc, d, ee, ff) in enumerate(coefficients.t().tolist()):
            lo, hi = bounds[i], bounds[i + 1]
            if hi > lo:
                xs, ys = x[lo:hi], y[lo:hi]
                torch.mul(xs, a, out=new_x[lo:hi]).add_(ee).add_(ys, alpha=bb)
                torch.mul(xs, cc, out=new_y[lo:hi]).add_(ff).add_(ys, alpha=d)
    else:  # accelerators: six gathers and four fused ops for the whole batch, whatever B
        sample = batch.sample_index()
        a, bb, cc, d, ee, ff = (coefficients[i].index_select(0, sample) for i in range(6))
        new_x = torch.addcmul(torch.addcmul(ee, a, x), bb, y)
        new_y = torch.addcmul(torch.addcmul(ff, cc, x), d, y)
    return batch._replace(x=_round_to(new_x, torch.int16), y=_round_to(new_y, torch.int16))


# --------------------------------------------------------------------------- time


def _groups(batch: EventBatch) -> tuple[Tensor, int]:
    """Per event its group ``(sample * T + bin) * 2 + p`` (int32; ``G`` outside the grid's
    window) and the number of groups G."""
    starts, frame_us, n_frames = _require_grid(batch, "frame shift / TES")
    from ..events.batch import _bins_of, _relative_times

    sample = batch.sample_index()
    bins, inside = _bins_of(_relative_times(batch, starts), frame_us, n_frames)
    groups = len(batch) * n_frames * 2
    group = sample.mul(n_frames).add_(bins).mul_(2).add_(batch.p)
    return group.masked_fill_(~inside, groups), groups


def shift_events(
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

    Exact selection: each event gets a float32 uniform key u from its sample's generator;
    the k events with the smallest keys of a group are the ones moved (ties, at 2**-24,
    are broken by position). A binomial level (u < ζ) picks all but a ~sqrt(N) surplus or
    deficit per group, fixed by ranking only the events whose keys lie in a narrow band
    next to ζ (no full sort). Host syncs: one read of the per-group surplus, one band
    gather (retried wider only if a band held too few events), one read of the kept counts.

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        shift: ``(B,)`` integer bins ``j`` (``t += j * frame``).
        fraction: ``(B,)`` ζ in [0, 1] for TES; ``None`` moves every event (frame shift).
        seed: ``(B,)`` int64 per-sample seeds (with ``fraction``).
        mode: ``"exact"`` or ``"binomial"``.

    Shape:
        - batch: B streams, N events.
        - shift, fraction, seed: ``(B,)``.
        - output: B streams, at most N events (those pushed out of the window dropped).

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> shifted = shift_events(batch, torch.tensor([1, 1]))  # FS+1: a bin later
        >>> shifted.t.tolist(), shifted.lengths  # the event in the last bin left the window
        ([10100, 10050], [1, 1])
    """
    group, groups = _groups(batch)
    frame_us = _frame_us(batch.frame_ms)
    n_frames = batch.n_frames
    device = batch.device
    inside = group < groups
    if fraction is None:
        moved = inside
    else:
        u, below = _keys(batch, seed, fraction)
        moved = below & inside
        if mode == "exact":
            moved = _exact_fixup(group, groups, u, moved, fraction, n_frames)
    # a group's events all land in bin + j: whether they leave the window is per group
    jump = shift.to(torch.int64)
    group_bin = torch.arange(n_frames).repeat(len(batch)).repeat_interleave(2)
    leaving = group_bin + jump.repeat_interleave(2 * n_frames)
    leaving = torch.cat([(leaving < 0) | (leaving >= n_frames), torch.zeros(1, dtype=torch.bool)]).to(device)
    keep = ~(moved & leaving.index_select(0, group))
    if isinstance(frame_us, int) and not batch.t.is_floating_point():
        t = batch.t + _per_event(jump * frame_us, batch) * moved  # int64 times stay exact
    else:
        t = (batch.t.to(torch.float64) + _per_event(jump.to(torch.float64) * frame_us, batch) * moved).to(batch.t.dtype)
    return _compact(batch, keep, t=t)


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


def _exact_fixup(group: Tensor, groups: int, u: Tensor, moved: Tensor, fraction: Tensor, n_frames: int) -> Tensor:
    """Turn the binomial choice ``moved`` into exactly round(ζ N) smallest keys per group."""
    device = group.device
    ones = torch.ones((), dtype=torch.int64, device=device).expand(group.shape[0])
    total = torch.zeros(groups + 1, dtype=torch.int64, device=device).index_add_(0, group, ones)[:groups]
    chosen = torch.zeros(groups + 1, dtype=torch.int64, device=device).index_add_(0, group, moved.to(torch.int64))[:groups]
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


def time_reversal_events(batch: EventBatch, reverse: Tensor) -> EventBatch:
    """Reverse time in the grid's window for the samples flagged in ``reverse``: bin i goes to
    T - 1 - i (integer timestamps: ``t -> 2 t0 + T frame - 1 - t``, so the binned frames
    are exactly the frame kernel's reversal). Sync-free.

    Args:
        batch: the event streams, with a frame grid.
        reverse: ``(B,)`` bool, the samples to reverse.

    Shape:
        - batch: B streams, N events.
        - reverse: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> time_reversal_events(batch, torch.tensor([True, False])).t.tolist()  # t -> 19999 - t
        [19899, 4999, 50]
    """
    starts, frame_us, n_frames = _require_grid(batch, "TimeReversal")
    end = starts.to(batch.t.dtype) * 2 + n_frames * frame_us - (0 if batch.t.is_floating_point() else 1)
    mirrored = _per_event(end, batch) - batch.t
    flags = reverse.tolist()
    t = mirrored if all(flags) else torch.where(_per_event(reverse, batch), mirrored, batch.t)
    return batch._replace(t=t.to(batch.t.dtype))


# --------------------------------------------------------------------------- polarity, drop, noise


def flip_polarity_events(batch: EventBatch, flip: Tensor) -> EventBatch:
    """Swap ON and OFF in the samples flagged in ``flip``. Sync-free.

    Args:
        batch: the event streams.
        flip: ``(B,)`` bool, the samples whose polarities swap.

    Shape:
        - batch: B streams, N events.
        - flip: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> flip_polarity_events(batch, torch.tensor([True, False])).p.tolist()
        [0, 1, 0]
    """
    flags = flip.tolist()
    if not any(flags):
        return batch
    swapped = 1 - batch.p
    p = swapped if all(flags) else torch.where(_per_event(flip, batch), swapped, batch.p)
    return batch._replace(p=p.to(torch.int8))


def drop_events_random(batch: EventBatch, fraction: Tensor, seed: Tensor) -> EventBatch:
    """Drop each event of sample b with probability ``fraction[b]`` (its own uniform, from
    the sample's generator). One host read of the kept counts.

    Args:
        batch: the event streams.
        fraction: ``(B,)`` drop probabilities in [0, 1].
        seed: ``(B,)`` int64 per-sample seeds.

    Shape:
        - batch: B streams, N events.
        - fraction, seed: ``(B,)``.
        - output: B streams, at most N events.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> drop_events_random(batch, torch.tensor([1.0, 0.0]), torch.tensor([3, 4])).lengths
        [0, 1]
    """
    _, dropped = _keys(batch, seed, fraction)  # u < fraction, compared per sample slice
    return _compact(batch, ~dropped)


def drop_pixels_events(batch: EventBatch, mask: Tensor) -> EventBatch:
    """Drop the events of stream b that fall on a pixel where ``mask[b]`` holds.

    ``mask`` is ``(B, H, W)`` or ``(1, H, W)`` bool in sensor pixels (``batch.sensor_size``).
    Events outside the sensor (moved off it by an earlier transform) are kept: binning drops
    them. One host read of the kept counts.


    Args:
        batch: the event streams.
        mask: bool, ``True`` on the pixels whose events go: ``(B, H, W)`` per stream or
            ``(1, H, W)`` for all.

    Shape:
        - batch: B streams, N events.
        - mask: ``(B, H, W)`` or ``(1, H, W)``, the sensor's size.
        - output: B streams, at most N events.
    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 5, 1], [1, 0, 6, 0]])], sensor_size=(2, 2))
        >>> mask = torch.tensor([[[False, True], [False, False]]])  # pixel (y=0, x=1)
        >>> drop_pixels_events(batch, mask).x.tolist()
        [0]
    """
    height, width = batch.sensor_size
    if batch.num_events == 0:
        return batch
    x, y = batch.x.to(torch.int64), batch.y.to(torch.int64)
    inside = (x >= 0) & (x < width) & (y >= 0) & (y < height)
    pixel = y.clamp(0, height - 1) * width + x.clamp(0, width - 1)
    mask = mask.to(batch.device).reshape(-1, height * width)
    if mask.shape[0] == 1:
        dropped = mask[0].index_select(0, pixel)
    else:
        dropped = mask.reshape(-1).index_select(0, batch.sample_index().to(torch.int64) * (height * width) + pixel)
    return _compact(batch, ~(dropped & inside))


def poisson_noise_events(batch: EventBatch, rate_hz: Tensor, seed: Tensor) -> EventBatch:
    """Add background events: per pixel and polarity a Poisson process of ``rate_hz[b]``
    over the grid's window, i.e. Poisson(rate · T · frame · 2HW) events of uniform pixel,
    polarity and time. The counts are drawn on the host from the seeds (NumPy), so sizes
    are known without a host synchronisation; positions come from the sample's generator.
    Added events follow the sample's own events (the stream is no longer time-sorted).

    Args:
        batch: the event streams, with a frame grid.
        rate_hz: ``(B,)`` events per second per pixel and polarity (>= 0).
        seed: ``(B,)`` int64 per-sample seeds.

    Shape:
        - batch: B streams, N events.
        - rate_hz, seed: ``(B,)``.
        - output: B streams, N events plus the noise.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> noisy = poisson_noise_events(batch, torch.tensor([0.0, 1000.0]), torch.tensor([1, 2]))
        >>> noisy.lengths[0], noisy.lengths[1] > 1  # 1000 Hz x 20 ms x 12 pixel-polarities: about 240 added
        (2, True)
    """
    starts, frame_us, n_frames = _require_grid(batch, "AddPoissonNoise")
    height, width = batch.sensor_size
    seeds = [int(s) for s in seed.tolist()]
    rates = rate_hz.tolist()
    span = n_frames * frame_us
    counts = [int(np.random.default_rng(s).poisson(r * span * 1e-6 * 2 * height * width)) for s, r in zip(seeds, rates)]
    first = starts.tolist()
    device = batch.device
    noise = []
    for b, (s, n) in enumerate(zip(seeds, counts)):
        g = _generator(s ^ 0x5DEECE66D, device)
        u = torch.rand(n, 4, generator=g, device=device, dtype=torch.float64)
        x = (u[:, 0] * width).to(torch.int16)
        y = (u[:, 1] * height).to(torch.int16)
        t = first[b] + u[:, 2] * span
        t = t.floor().to(batch.t.dtype)
        p = (u[:, 3] < 0.5).to(torch.int8)
        noise.append((x, y, t, p))
    return _append(batch, noise)


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


def bank_noise_events(batch: EventBatch, bank: Tensor, offset: Tensor) -> EventBatch:
    """Add the events of a static-scene bank: stream b gets frames ``offset[b] .. offset[b] + T``
    of ``bank`` ``(N, 2, H, W)`` (sensor-sized whole counts) as events, each at the centre of
    its bin on the batch's grid (a frame bank has no finer timing), so binning gives the
    stream's frames plus that window, as :class:`~event_transforms.AddNoise` does on frames.
    Deterministic; one host read of the window's event count per stream.


    Args:
        batch: the event streams, with a frame grid of ``n_frames`` bins.
        bank: ``(N, 2, H, W)`` whole counts of a static scene, the sensor's size.
        offset: ``(B,)`` the first bank frame of each stream's window.

    Shape:
        - batch: B streams, N events.
        - bank: ``(N, 2, H, W)``; offset: ``(B,)``.
        - output: B streams, N events plus the window's counts.
    Example:
        >>> batch = EventBatch.from_streams([torch.zeros(0, 4)], sensor_size=(1, 2), frame_ms=1.0,
        ...                                 t_start=0, n_frames=2)
        >>> bank = torch.zeros(3, 2, 1, 2)
        >>> bank[2, 1, 0, 1] = 2  # two ON events at x = 1 in the bank's third frame
        >>> out = bank_noise_events(batch, bank, torch.tensor([1]))
        >>> out.x.tolist(), out.t.tolist(), out.p.tolist()
        ([1, 1], [1500, 1500], [1, 1])
    """
    starts, frame_us, n_frames = _require_grid(batch, "AddNoise")
    height, width = batch.sensor_size
    if tuple(bank.shape[-2:]) != (height, width):
        raise ValueError(
            f"bank: AddNoise on events needs a bank of the sensor's size (H, W) = ({height}, {width}), "
            f"got {tuple(bank.shape)}"
        )
    device = batch.device
    per_pixel = 2 * height * width
    first_t = starts.tolist()
    added = []
    for b, first in enumerate(offset.tolist()):
        window = bank[first : first + n_frames].to(device).reshape(-1)
        counts = window.to(torch.int64)
        entries = (counts > 0).nonzero().squeeze(1)  # the output size depends on the bank
        repeats = counts.index_select(0, entries)
        index = torch.repeat_interleave(entries, repeats)
        frame, rest = index // per_pixel, index % per_pixel
        p, pixel = rest // (height * width), rest % (height * width)
        t = first_t[b] + frame * frame_us + frame_us // 2
        added.append(((pixel % width).to(torch.int16), (pixel // width).to(torch.int16),
                      t.to(batch.t.dtype), p.to(torch.int8)))
    return _append(batch, added)


# --------------------------------------------------------------------------- event-only


def spatial_jitter(batch: EventBatch, sigma: Tensor, seed: Tensor) -> EventBatch:
    """Add Gaussian noise of standard deviation ``sigma[b]`` pixels to x and y, rounded to
    whole pixels (events leaving the sensor are dropped when binned). Sync-free.

    Args:
        batch: the event streams.
        sigma: ``(B,)`` standard deviations in pixels (>= 0).
        seed: ``(B,)`` int64 per-sample seeds.

    Shape:
        - batch: B streams, N events.
        - sigma, seed: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> jittered = spatial_jitter(batch, torch.tensor([0.0, 2.0]), torch.tensor([1, 2]))
        >>> jittered.x[:2].tolist(), jittered.t.tolist()  # sigma 0 moves nothing; times kept
        ([0, 2], [100, 15000, 50])
    """
    lengths = batch.lengths
    bounds = batch.offsets.tolist()
    noise_x = torch.empty(batch.num_events, dtype=torch.float32, device=batch.device)
    noise_y = torch.empty_like(noise_x)
    for b, (s, n) in enumerate(zip(seed.tolist(), lengths)):
        if n:  # sample b's generator: its n x offsets, then its n y offsets
            g = _generator(s, batch.device)
            noise_x[bounds[b] : bounds[b + 1]].normal_(generator=g)
            noise_y[bounds[b] : bounds[b + 1]].normal_(generator=g)
    scale = _per_event(sigma.to(torch.float32), batch)
    x = torch.addcmul(batch.x.to(torch.float32), noise_x, scale)
    y = torch.addcmul(batch.y.to(torch.float32), noise_y, scale)
    return batch._replace(x=_round_to(x, torch.int16), y=_round_to(y, torch.int16))


def time_jitter(batch: EventBatch, std_us: Tensor, seed: Tensor) -> EventBatch:
    """Add Gaussian noise of ``std_us[b]`` microseconds to the timestamps (rounded for
    integer timestamps). Streams are no longer time-sorted. Sync-free.

    Args:
        batch: the event streams.
        std_us: ``(B,)`` standard deviations in microseconds (>= 0).
        seed: ``(B,)`` int64 per-sample seeds.

    Shape:
        - batch: B streams, N events.
        - std_us, seed: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> jittered = time_jitter(batch, torch.tensor([0.0, 30.0]), torch.tensor([1, 2]))
        >>> jittered.t[:2].tolist(), jittered.x.tolist()  # std 0 moves nothing; pixels kept
        ([100, 15000], [0, 2, 1])
    """
    bounds = batch.offsets.tolist()
    noise = torch.empty(batch.num_events, dtype=torch.float64, device=batch.device)
    for b, (s, std) in enumerate(zip(seed.tolist(), std_us.tolist())):
        if bounds[b + 1] > bounds[b]:  # the sample's generator, scaled by its own std: no gather
            noise[bounds[b] : bounds[b + 1]].normal_(generator=_generator(s, batch.device)).mul_(std)
    if batch.t.is_floating_point():
        return batch._replace(t=batch.t + noise)
    return batch._replace(t=batch.t + torch.round(noise).to(torch.int64))


def time_skew(batch: EventBatch, coefficient: Tensor, offset_us: Tensor) -> EventBatch:
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
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> time_skew(batch, torch.tensor([2.0, 1.0]), torch.tensor([0.0, 10.0])).t.tolist()  # about t0 = 0
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


def _pixel_runs(batch: EventBatch) -> tuple[Tensor, Tensor, Tensor]:
    """Events ordered by (sample, pixel, time): the order, each ordered event's pixel key,
    and its rank inside its pixel's run (two stable sorts)."""
    sample = batch.sample_index().to(torch.int64)
    key = ((sample << 16) + batch.y.to(torch.int64) + 2**15 << 16) + batch.x.to(torch.int64) + 2**15  # any int16 pixel
    order = torch.argsort(batch.t, stable=True)
    order = order.index_select(0, torch.argsort(key.index_select(0, order), stable=True))
    sorted_key = key.index_select(0, order)
    start = torch.ones_like(sorted_key, dtype=torch.bool)
    start[1:] = sorted_key[1:] != sorted_key[:-1]
    position = torch.arange(order.shape[0], device=order.device)
    run_start = torch.cummax(torch.where(start, position, 0), 0).values
    return order, start, position - run_start


def refractory_period(batch: EventBatch, period_us: Tensor) -> EventBatch:
    """Drop an event when its pixel (either polarity) had an event less than ``period_us[b]``
    before it (the previous event, kept or not: a pixel's dead time restarts with every
    event it saw). The first event of each pixel is kept. Output in (time) order of the
    input. One host read of the kept counts.

    Args:
        batch: the event streams.
        period_us: ``(B,)`` dead time of a pixel in microseconds.

    Shape:
        - batch: B streams, N events.
        - period_us: ``(B,)``.
        - output: B streams, at most N events, in input order.

    Example:
        >>> events = torch.tensor([[0, 0, 0, 1], [0, 0, 400, 0], [0, 0, 1_000, 1], [1, 0, 10, 1]])
        >>> batch = EventBatch.from_streams([events], sensor_size=(1, 2))
        >>> refractory_period(batch, torch.tensor([500.0])).t.tolist()  # 400 follows 0 too soon
        [0, 1000, 10]
    """
    if batch.num_events == 0:
        return batch
    order, start, _ = _pixel_runs(batch)
    t = batch.t.index_select(0, order).to(torch.float64)
    gap = torch.empty_like(t)
    gap[0] = math.inf
    gap[1:] = t[1:] - t[:-1]
    period = _per_event(period_us.to(torch.float64), batch).index_select(0, order)
    keep_sorted = start | (gap >= period)
    keep = torch.empty_like(keep_sorted).index_put_((order,), keep_sorted)
    return _compact(batch, keep)


def decimation(batch: EventBatch, n: Tensor) -> EventBatch:
    """Keep every ``n[b]``-th event of each pixel (the n-th, 2n-th, ... in time), as tonic's
    ``Decimation``. One host read of the kept counts.

    Args:
        batch: the event streams.
        n: ``(B,)`` positive integers: keep each pixel's n-th, 2n-th, ... event.

    Shape:
        - batch: B streams, N events.
        - n: ``(B,)``.
        - output: B streams, at most N events, in input order.

    Example:
        >>> events = torch.tensor([[0, 0, 0, 1], [0, 0, 400, 0], [0, 0, 1_000, 1], [1, 0, 10, 1]])
        >>> batch = EventBatch.from_streams([events], sensor_size=(1, 2))
        >>> decimation(batch, torch.tensor([2])).t.tolist()  # pixel x = 0: its 2nd event; x = 1 has one
        [400]
    """
    if batch.num_events == 0:
        return batch
    order, _, rank = _pixel_runs(batch)
    every = _per_event(n.to(torch.int64), batch).index_select(0, order)
    keep_sorted = (rank + 1) % every == 0
    keep = torch.empty_like(keep_sorted).index_put_((order,), keep_sorted)
    return _compact(batch, keep)


def drop_window(
    batch: EventBatch,
    *,
    time: tuple[Tensor, Tensor] | None = None,
    area: tuple[Tensor, Tensor, Tensor, Tensor] | None = None,
) -> EventBatch:
    """Drop sample b's events in bins ``[start[b], start[b] + length[b])`` of the grid
    (``time``) or in the sensor rectangle ``top, left, height, width`` (``area``): the
    event form of ``drop_by_time``/``drop_by_area``. One host read of the kept counts.

    Args:
        batch: the event streams (with a frame grid for ``time``).
        time: ``(start, length)``, each ``(B,)`` bins.
        area: ``(top, left, height, width)``, each ``(B,)`` sensor pixels.

    Shape:
        - batch: B streams, N events.
        - the entries of time or area: ``(B,)``.
        - output: B streams, at most N events.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> drop_window(batch, time=(torch.tensor([1, 0]), torch.tensor([1, 1]))).t.tolist()
        [100]
    """
    if time is not None:
        from ..events.batch import _bins_of, _relative_times

        starts, frame_us, n_frames = _require_grid(batch, "RandomEventDrop (time)")
        bins, inside = _bins_of(_relative_times(batch, starts), frame_us, n_frames)
        start, length = (_per_event(v.to(torch.int32), batch) for v in time)
        hit = inside & (bins >= start) & (bins < start + length)
    else:
        top, left, height, width = (_per_event(v.to(torch.int64), batch) for v in area)
        y, x = batch.y.to(torch.int64), batch.x.to(torch.int64)
        hit = (y >= top) & (y < top + height) & (x >= left) & (x < left + width)
    return _compact(batch, ~hit)


def crop_events(batch: EventBatch, top: Tensor, left: Tensor, size: tuple[int, int]) -> EventBatch:
    """Crop sample b to the window ``top[b], left[b]`` of ``size`` (H, W): coordinates move
    by ``(-top, -left)`` and the batch's sensor becomes ``size``. Events outside the window
    are kept (dropped when binned, as the frame crop drops them). Sync-free.

    Args:
        batch: the event streams.
        top, left: ``(B,)`` the window's first row and column per sample.
        size: ``(h, w)`` of the window, the new sensor size.

    Shape:
        - batch: B streams, N events.
        - top, left: ``(B,)``.
        - output: the same streams and events on an ``(h, w)`` sensor.

    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> cropped = crop_events(batch, torch.tensor([0, 1]), torch.tensor([1, 1]), (1, 2))
        >>> cropped.sensor_size, cropped.x.tolist(), cropped.y.tolist()
        ((1, 2), [-1, 1, 0], [1, 0, 0])
    """
    x = batch.x - _per_event(left.to(torch.int16), batch)
    y = batch.y - _per_event(top.to(torch.int16), batch)
    return batch._replace(x=x, y=y, sensor_size=tuple(int(s) for s in size))


def crop_time_events(batch: EventBatch, start: Tensor, length: int) -> EventBatch:
    """Keep bins ``[start[b], start[b] + length)`` of the grid: times move ``start[b]`` bins
    earlier and the grid becomes ``length`` bins long (events outside it are dropped when
    binned; equal to the frame kernel after binning). Sync-free.

    Args:
        batch: the event streams, with a frame grid.
        start: ``(B,)`` first kept bin per sample.
        length: number of kept bins.

    Shape:
        - batch: B streams, N events.
        - start: ``(B,)``.
        - output: the same streams and events, the grid ``length`` bins long.

    Example:
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
