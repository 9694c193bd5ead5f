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
    as_batch,
    check_fraction,
    check_frames,
    check_generator,
    check_integer_valued,
    check_number,
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


def _add_events(batch: Tensor, flat_index: Tensor) -> Tensor:
    """Add one event at each flat position (repeats accumulate): O(events) beyond a clone."""
    out = batch.clone()
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
    flat.index_put_((flat_index,), torch.ones((), dtype=out.dtype, device=out.device).expand(flat_index.shape), accumulate=True)
    return out


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
    if not frames.is_floating_point():
        check_integer_valued(noise, "noise", "integer frames need integer-valued noise counts")
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
    check_frames(frames)
    frame_ms = check_number(frame_ms, "frame_ms", low=0.0)
    if frame_ms == 0:
        raise ValueError(f"frame_ms must be > 0, got {frame_ms!r}")
    check_generator(generator, frames.device)
    batch, unbatch = as_batch(frames)
    b = batch.shape[0]
    rate = per_sample(rate_hz, b, "rate_hz")
    if rate.numel() and not bool((torch.isfinite(rate) & (rate >= 0)).all()):
        raise ValueError(f"rate_hz must be finite and >= 0, got {rate.tolist()}")
    if batch.numel() == 0:
        return frames.clone()
    lam = rate * (frame_ms / 1000.0)  # (B,) float64, CPU
    cells = batch[0].numel()
    device = batch.device
    if float(lam.max()) < 1.0:
        totals = torch.poisson((lam * cells).to(device), generator=generator).long()
        count = int(totals.sum())
        position = torch.randint(cells, (count,), generator=generator, device=device)
        sample = torch.repeat_interleave(torch.arange(b, device=device), totals, output_size=count)
        return unbatch(_add_events(batch, sample * cells + position))
    else:
        rates = lam.to(device=device, dtype=torch.float64).view(b, 1, 1, 1, 1).expand(batch.shape)
        noise = torch.poisson(rates.contiguous(), generator=generator)
    return unbatch(_add_counts(batch, noise, "Poisson noise"))


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
    check_frames(frames)
    if mode not in ("binomial", "expected"):
        raise ValueError(f"mode must be 'binomial' or 'expected', got {mode!r}")
    check_generator(generator, frames.device)
    batch, unbatch = as_batch(frames)
    fraction_t = per_sample(fraction, batch.shape[0], "fraction")
    check_fraction(fraction_t)
    keep = (1.0 - fraction_t).view(-1, 1, 1, 1, 1)
    if mode == "expected":
        dtype = batch.dtype if batch.is_floating_point() else torch.float32
        return unbatch((batch.to(torch.float64) * keep.to(batch.device)).to(dtype))
    check_integer_valued(
        batch, "frames", 'drop events before interpolating transforms, or use mode="expected"'
    )
    if batch.numel() == 0:
        return frames.clone()
    # Binomial thinning on the non-zero pixels only: frames are sparse.
    flat = batch.reshape(-1)
    index = flat.nonzero().squeeze(1)
    counts = flat.index_select(0, index).to(torch.float64)
    sample = torch.div(index, batch[0].numel(), rounding_mode="floor")
    prob = keep.view(-1).to(batch.device).index_select(0, sample)
    kept = torch.binomial(counts, prob, generator=generator)
    out = torch.zeros_like(flat).index_copy_(0, index, kept.to(batch.dtype))
    return unbatch(out.reshape(batch.shape))


def _window_mask(start: Tensor, length: Tensor, size: int, device: torch.device) -> Tensor:
    """(B, size) bool: True inside [start, start + length) per sample."""
    position = torch.arange(size, device=device)
    start = start.to(device).unsqueeze(1)
    return (position >= start) & (position < start + length.to(device).unsqueeze(1))


def _check_window(value: Scalars, batch: int, name: str) -> Tensor:
    t = per_sample(value, batch, name, dtype=torch.float64)
    if not bool((t == t.round()).all()) or bool((t < 0).any()):
        raise ValueError(f"{name} must be non-negative integers, got {t.tolist()}")
    return t.long()


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
    check_frames(frames)
    batch, unbatch = as_batch(frames)
    b, t = batch.shape[:2]
    mask = _window_mask(_check_window(start, b, "start"), _check_window(length, b, "length"), t, batch.device)
    return unbatch(batch.masked_fill(mask.view(b, t, 1, 1, 1), 0))


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
    check_frames(frames)
    batch, unbatch = as_batch(frames)
    b, _, _, h, w = batch.shape
    rows = _window_mask(_check_window(top, b, "top"), _check_window(height, b, "height"), h, batch.device)
    cols = _window_mask(_check_window(left, b, "left"), _check_window(width, b, "width"), w, batch.device)
    mask = (rows.unsqueeze(2) & cols.unsqueeze(1)).view(b, 1, 1, h, w)
    return unbatch(batch.masked_fill(mask, 0))
