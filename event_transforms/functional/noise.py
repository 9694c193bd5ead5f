"""Event-level noise kernels: adding static-scene or Poisson background events, dropping events.

Adding keeps the frames' dtype (integer counts stay integer; an integer result that would
not fit the dtype raises instead of wrapping). Dropping follows EventDrop (Gu et al., 2021):
a random fraction of events, every event in a time window, or every event in an area.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import (
    DROP_MODES,
    as_batch,
    check_choice,
    check_counts,
    check_frames,
    check_generator,
    check_positive,
    describe,
    per_sample,
)

__all__ = [
    "add_noise",
    "add_poisson_noise",
    "drop_events",
    "drop_by_time",
    "drop_by_area",
]

_SMALL_INTEGERS = (torch.uint8, torch.int8, torch.int16, torch.int32)
Scalars = float | Sequence[float] | Tensor


def _add_counts(frames: Tensor, counts: Tensor, name: str) -> Tensor:
    """``frames + counts`` in the frames' dtype; raises if an integer dtype would overflow."""
    if frames.dtype in _SMALL_INTEGERS and frames.numel():
        limit = torch.iinfo(frames.dtype).max
        high = (frames.to(torch.int64) + counts.to(torch.int64)).max()
        if bool(high > limit):
            raise ValueError(
                f"adding {name} overflows {frames.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    return frames + counts.to(frames.dtype)


def _add_entries(frames: Tensor, target: Tensor, values: Tensor, name: str) -> Tensor:
    """A copy of ``frames`` with ``values`` added at the distinct flat positions ``target``.

    Integer dtypes narrower than int64 are checked for overflow first (one host
    synchronisation, for those dtypes only); float dtypes need none.
    """
    out = frames.clone(memory_format=torch.contiguous_format)
    flat = out.view(-1)
    if frames.dtype in _SMALL_INTEGERS and target.numel():
        limit = torch.iinfo(frames.dtype).max
        high = (flat.index_select(0, target).to(torch.int64) + values.to(torch.int64)).max()
        if bool(high > limit):
            raise ValueError(
                f"adding {name} overflows {frames.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    return flat.index_add_(0, target, values.to(out.dtype)).view(frames.shape)


def _add_events(batch: Tensor, flat_index: Tensor) -> Tensor:
    """Add one event at each flat position (repeats accumulate): O(events) beyond a clone.

    No host synchronisation for float and int64 frames; narrower integer dtypes are
    checked for overflow (``unique`` and one read).
    """
    out = batch.clone(memory_format=torch.contiguous_format)
    flat = out.view(-1)
    if batch.dtype in _SMALL_INTEGERS and flat_index.numel():
        cell, added = torch.unique(flat_index, return_counts=True)
        high = (flat.index_select(0, cell).to(torch.int64) + added).max()
        limit = torch.iinfo(batch.dtype).max
        if bool(high > limit):
            raise ValueError(
                f"adding Poisson noise overflows {batch.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    ones = torch.ones((), dtype=out.dtype, device=out.device).expand(flat_index.shape)
    return flat.index_add_(0, flat_index, ones).view(batch.shape)


def add_noise(frames: Tensor, noise: Tensor) -> Tensor:
    """Add noise frames (e.g. recorded from a static scene) to event frames.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        noise: non-negative counts of the same shape, or ``(T, 2, H, W)`` added to every
            sample of a batch. For integer ``frames`` the noise must be integer-valued.

    Returns:
        ``frames + noise`` in the frames' dtype, on the frames' device.

    Example:
        >>> frames = torch.zeros(2, 2, 3, 4, dtype=torch.int16)
        >>> noise = torch.ones(2, 2, 3, 4, dtype=torch.int16)
        >>> out = add_noise(frames, noise)
        >>> out.dtype, int(out.sum())
        (torch.int16, 48)
    """
    check_frames(frames)
    check_frames(noise, "noise")
    if noise.shape != frames.shape and noise.shape != frames.shape[-4:]:
        raise ValueError(
            f"noise must have the frames' shape {tuple(frames.shape)} or {tuple(frames.shape[-4:])}, "
            f"got {tuple(noise.shape)}"
        )
    hint = None if frames.is_floating_point() else "integer frames need whole noise counts"
    check_counts(noise, "noise", whole=hint)
    return _add_counts(frames, noise.to(frames.device), "noise")


def add_poisson_noise(
    frames: Tensor,
    rate_hz: Scalars,
    *,
    frame_ms: float = 10.0,
    generator: torch.Generator | None = None,
) -> Tensor:
    """Add background activity: independent Poisson counts per pixel, polarity and frame.

    Each pixel and polarity fires at ``rate_hz`` (per sample), so a frame of
    ``frame_ms`` milliseconds receives Poisson(λ) events with λ = rate_hz · frame_ms / 1000.
    For sparse noise (λ < 1, the usual 0.1–10 Hz) the total per sample is drawn from
    Poisson(λ·n) and its events placed uniformly at random among the n cells; this is
    exactly independent Poisson(λ) per cell (Poissonisation) and costs O(events), not
    O(n). Denser noise draws every cell with ``torch.poisson``.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        rate_hz: events per second per pixel and polarity (>= 0), a number or ``(B,)``.
        frame_ms: frame length in milliseconds (> 0).
        generator: a ``torch.Generator`` on the frames' device, or ``None``.

    Returns:
        Frames plus noise counts, in the frames' dtype.

    Example:
        >>> frames = torch.zeros(36, 2, 70, 75)
        >>> out = add_poisson_noise(frames, 5.0, generator=torch.Generator().manual_seed(0))
        >>> int(out.sum())  # expected 5 Hz * 0.36 s * 2 * 70 * 75 = 18900
        18884
    """
    batch, unbatch = as_batch(check_frames(frames))
    frame_ms = check_positive(frame_ms, "frame_ms")
    check_generator(generator, frames.device)
    rate = per_sample(rate_hz, batch.shape[0], "rate_hz")
    if rate.numel() and not bool((rate.isfinite() & (rate >= 0)).all()):
        raise ValueError(f"rate_hz must be finite and >= 0, got {describe(rate_hz)}")
    return unbatch(_add_poisson_noise(batch, rate * (frame_ms / 1000.0), generator=generator))


def _poisson_totals(lam: Tensor, shape: torch.Size, generator: torch.Generator | None) -> Tensor | None:
    """Per-sample totals Poisson(λ·cells) (int64 CPU) for sparse noise, or ``None`` if dense.

    ``lam`` is the (B,) mean count per cell (CPU float64). Below one event per cell the noise
    is placed event by event (the totals, then uniform positions); otherwise cell by cell.
    """
    if lam.numel() == 0 or max(lam.tolist()) >= 1.0:
        return None
    cells = float(torch.Size(shape[1:]).numel())
    return torch.poisson(lam * cells, generator=generator).to(torch.int64)


def _add_poisson_noise(
    batch: Tensor, lam: Tensor, *, totals: Tensor | None = None, generator: torch.Generator | None
) -> Tensor:
    """Add Poisson(λ_b) counts per cell to a (B, T, 2, H, W) batch; ``lam`` (B,) CPU float64.

    With ``totals`` (B,) (CPU int64, from :func:`poisson_totals`) the events are placed
    uniformly among the cells: exactly independent Poisson(λ) per cell (Poissonisation), in
    O(events) work and with no host synchronisation. Without, sparse noise draws its totals
    here and dense noise draws every cell with ``torch.poisson``.
    """
    if batch.numel() == 0:
        return batch.clone()
    device = batch.device
    cells = batch[0].numel()
    if totals is None and lam.numel() and max(lam.tolist()) < 1.0:
        totals = torch.poisson((lam * cells).to(device), generator=generator).long().cpu()
    if totals is not None:
        count = sum(totals.tolist())  # a CPU tensor: read on the host
        position = torch.randint(cells, (count,), generator=generator, device=device)
        sample = torch.repeat_interleave(
            torch.arange(batch.shape[0], device=device), totals.to(device), output_size=count
        )
        return _add_events(batch, sample * cells + position)
    rates = lam.to(device=device, dtype=torch.float64).view(-1, 1, 1, 1, 1).expand(batch.shape)
    noise = torch.poisson(rates.contiguous(), generator=generator)
    return _add_counts(batch, noise, "Poisson noise")


def drop_events(
    frames: Tensor,
    fraction: Scalars,
    *,
    mode: str = "binomial",
    generator: torch.Generator | None = None,
) -> Tensor:
    """Drop a random fraction of the events (EventDrop's *random drop*), per sample.

    ``mode="binomial"`` drops each event independently with probability ``fraction``
    (counts stay integer, dtype kept; needs integer-valued counts). ``mode="expected"``
    scales the counts by ``1 - fraction`` (float output: input dtype for floats, float32
    for integers) and accepts any counts, e.g. after an interpolating transform.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        fraction: probability of dropping an event, in [0, 1], a number or ``(B,)``.
        mode: ``"binomial"`` or ``"expected"``.
        generator: a ``torch.Generator`` on the frames' device, or ``None``.

    Example:
        >>> frames = torch.full((4, 2, 8, 8), 10, dtype=torch.int32)
        >>> out = drop_events(frames, 0.5, generator=torch.Generator().manual_seed(0))
        >>> out.dtype, int(out.sum()), bool((out <= frames).all())
        (torch.int32, 2562, True)
    """
    batch, unbatch = as_batch(check_frames(frames))
    check_choice(mode, "mode", DROP_MODES)
    check_generator(generator, frames.device)
    fraction_t = per_sample(fraction, batch.shape[0], "fraction")
    if fraction_t.numel() and bool(((fraction_t < 0) | (fraction_t > 1)).any()):
        raise ValueError(f"fraction must lie in [0, 1], got {describe(fraction)}")
    return unbatch(_drop_events(batch, fraction_t, mode, generator))


_DROP_HINT = 'drop events before interpolating transforms (bilinear rotate/resize), or use mode="expected"'


def _drop_events(
    batch: Tensor, fraction: Tensor, mode: str, generator: torch.Generator | None, hint: str = _DROP_HINT
) -> Tensor:
    """``drop_events`` on a (B, T, 2, H, W) batch with (B,) CPU fractions; ``hint`` ends the
    error raised for fractional counts."""
    keep = (1.0 - fraction).view(-1, 1, 1, 1, 1)
    if mode == "expected":
        dtype = batch.dtype if batch.is_floating_point() else torch.float32
        return (batch.to(torch.float64) * keep.to(batch.device)).to(dtype)
    if batch.numel() == 0:
        return batch.clone()
    # Binomial thinning on the non-zero pixels only: frames are sparse.
    flat = batch.reshape(-1)
    index = flat.nonzero().squeeze(1)
    values = flat.index_select(0, index)
    check_counts(values, "frames", whole=hint)
    sample = torch.div(index, batch[0].numel(), rounding_mode="floor")
    prob = keep.view(-1).to(batch.device).index_select(0, sample)
    kept = torch.binomial(values.to(torch.float64), prob, generator=generator)
    out = torch.zeros_like(flat).index_copy_(0, index, kept.to(batch.dtype))
    return out.reshape(batch.shape)


def _window_mask(start: Tensor, length: Tensor, size: int, device: torch.device) -> Tensor:
    """(B, size) bool: True inside [start, start + length) per sample."""
    position = torch.arange(size, device=device)
    start = start.to(device).unsqueeze(1)
    return (position >= start) & (position < start + length.to(device).unsqueeze(1))


def _check_window(value: Scalars, batch: int, name: str) -> Tensor:
    t = per_sample(value, batch, name, dtype=torch.int64)
    if t.numel() and bool((t < 0).any()):
        raise ValueError(f"{name} must be non-negative integers, got {describe(value)}")
    return t


def drop_by_time(frames: Tensor, start: Scalars, length: Scalars) -> Tensor:
    """Remove every event in frames ``[start, start + length)`` of each sample (EventDrop's *drop by time*).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        start: first dropped frame, a non-negative integer or ``(B,)``.
        length: number of dropped frames (a window past the end stops at the end).

    Returns:
        Frames with the window zeroed; dtype kept.

    Example:
        >>> frames = torch.ones(5, 2, 1, 1, dtype=torch.uint8)
        >>> drop_by_time(frames, 1, 2)[:, 0, 0, 0].tolist()
        [1, 0, 0, 1, 1]
    """
    batch, unbatch = as_batch(check_frames(frames))
    b = batch.shape[0]
    return unbatch(_drop_by_time(batch, _check_window(start, b, "start"), _check_window(length, b, "length")))


def _drop_by_time(batch: Tensor, start: Tensor, length: Tensor) -> Tensor:
    b, t = batch.shape[:2]
    mask = _window_mask(start, length, t, batch.device)
    return batch.masked_fill(mask.view(b, t, 1, 1, 1), 0)


def drop_by_area(frames: Tensor, top: Scalars, left: Scalars, height: Scalars, width: Scalars) -> Tensor:
    """Remove every event in a rectangle of each sample, in all frames (EventDrop's *drop by area*).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        top, left: the rectangle's first row and column, non-negative integers or ``(B,)``.
        height, width: its size in pixels (a rectangle past the border stops there).

    Returns:
        Frames with the rectangle zeroed; dtype kept.

    Example:
        >>> frames = torch.ones(1, 2, 3, 4)
        >>> drop_by_area(frames, 1, 1, 2, 2)[0, 0].tolist()
        [[1.0, 1.0, 1.0, 1.0], [1.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0]]
    """
    batch, unbatch = as_batch(check_frames(frames))
    b = batch.shape[0]
    window = [_check_window(v, b, n) for v, n in ((top, "top"), (left, "left"), (height, "height"), (width, "width"))]
    return unbatch(_drop_by_area(batch, *window))


def _drop_by_area(batch: Tensor, top: Tensor, left: Tensor, height: Tensor, width: Tensor) -> Tensor:
    b, _, _, h, w = batch.shape
    rows = _window_mask(top, height, h, batch.device)
    cols = _window_mask(left, width, w, batch.device)
    mask = (rows.unsqueeze(2) & cols.unsqueeze(1)).view(b, 1, 1, h, w)
    return batch.masked_fill(mask, 0)
