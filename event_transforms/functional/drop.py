"""Drop kernels: events (EventDrop: a random fraction, a time window, an area) and pixels
(given pixels, random pixel dropout).

Dropping follows EventDrop (Gu et al., 2021) for events. All of these only remove counts:
the dtype is kept (``drop_events(mode="expected")`` scales instead and returns floats).
Pixel masks are computed on the frames' device; :func:`random_pixel_mask` is a
counter-based draw, so a sample's mask depends on its own seed only.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import DROP_MODES, as_batch, check_choice, check_frames, check_generator, count_stats, describe, per_sample
from ._hypergeometric import _EXPAND_MAX, Stream, binomial_counts
from ._random import draw_seeds

__all__ = ["drop_events", "drop_by_time", "drop_by_area", "drop_pixel", "random_pixel_mask"]

Scalars = float | Sequence[float] | Tensor


# --------------------------------------------------------------------------- events


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

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - fraction: a number or ``(B,)``.

    Example:
        >>> frames = torch.full((4, 2, 8, 8), 10, dtype=torch.int32)
        >>> out = drop_events(frames, 0.5, generator=torch.Generator().manual_seed(0))
        >>> out.dtype, int(out.sum()), bool((out <= frames).all())
        (torch.int32, 2523, True)
    """
    batch, unbatch = as_batch(check_frames(frames))
    check_choice(mode, "mode", DROP_MODES)
    check_generator(generator, frames.device)
    fraction_t = per_sample(fraction, batch.shape[0], "fraction")
    if fraction_t.numel() and bool(((fraction_t < 0) | (fraction_t > 1)).any()):
        raise ValueError(f"fraction must lie in [0, 1], got {describe(fraction)}")
    seeds = draw_seeds(batch.shape[0], generator) if mode == "binomial" else None
    return unbatch(_drop_events(batch, fraction_t, mode, seeds))

_DROP_HINT = 'drop events before interpolating transforms (bilinear rotate/resize), or use mode="expected"'

def _drop_events(batch: Tensor, fraction: Tensor, mode: str, seeds: Tensor | None, hint: str = _DROP_HINT) -> Tensor:
    """``drop_events`` on a (B, T, 2, H, W) batch with (B,) CPU fractions and (B,) int64
    per-sample ``seeds``; ``hint`` ends the error raised for fractional counts.

    Each event's fate is a counter-based uniform named by its sample's seed and its
    position in the sample (:class:`~._hypergeometric.Stream`), so a sample's result does
    not depend on its batch. One ``nonzero`` and one host read (the check and the numbers
    the sampler needs)."""
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
    if index.numel() == 0:
        return batch.clone()
    counts = values.to(torch.int64)
    high, events = count_stats(values, counts, hint=hint, extra=[counts.clamp_max(_EXPAND_MAX).sum()])
    volume = batch[0].numel()
    sample = torch.div(index, volume, rounding_mode="floor")
    stream = Stream.of_samples(seeds, sample, index - sample * volume, 0)
    prob = keep.view(-1).to(batch.device, torch.float64)
    kept = binomial_counts(counts, prob, sample, stream=stream, largest=int(high), events=events, dtype=batch.dtype)
    out = torch.zeros_like(flat).index_copy_(0, index, kept)
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

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - start, length: integers or ``(B,)``.

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

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - top, left, height, width: integers or ``(B,)``.

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


# --------------------------------------------------------------------------- pixels

_MASK32 = 0xFFFFFFFF


def _pixel_mask(pixels: object, batch: int, height: int, width: int, device: torch.device) -> Tensor:
    """``(N, 2)`` (y, x) coordinates, an ``(H, W)`` or ``(B, H, W)`` bool mask -> (B or 1, H, W) bool."""
    if not isinstance(pixels, Tensor):
        try:
            pixels = torch.as_tensor(pixels)
        except (TypeError, ValueError, RuntimeError):
            raise TypeError(f"pixels must be (N, 2) (y, x) coordinates or a bool mask, got {pixels!r}") from None
    if pixels.dtype == torch.bool:
        if tuple(pixels.shape) not in ((height, width), (batch, height, width)):
            raise ValueError(
                f"a pixel mask must have shape ({height}, {width}) or ({batch}, {height}, {width}), got {tuple(pixels.shape)}"
            )
        return pixels.to(device, non_blocking=True).reshape(-1, height, width)
    if pixels.is_floating_point() or pixels.is_complex():
        raise TypeError(f"pixel coordinates must be integers, got dtype {pixels.dtype}")
    if pixels.dim() != 2 or pixels.shape[1] != 2:
        raise ValueError(f"pixel coordinates must have shape (N, 2) as (y, x), got {tuple(pixels.shape)}")
    ys, xs = pixels[:, 0].cpu(), pixels[:, 1].cpu()
    if pixels.numel() and bool(((ys < 0) | (ys >= height) | (xs < 0) | (xs >= width)).any()):
        raise ValueError(f"pixel coordinates must lie inside (H, W) = ({height}, {width}), got {describe(pixels)}")
    mask = torch.zeros(height * width, dtype=torch.bool)
    mask[ys * width + xs] = True
    return mask.view(1, height, width).to(device, non_blocking=True)

def drop_pixel(frames: Tensor, pixels: Tensor | Sequence[Sequence[int]]) -> Tensor:
    """Remove every event of the given pixels, in all frames and both polarities.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        pixels: ``(N, 2)`` integer ``(y, x)`` coordinates (every sample), or a bool mask
            ``(H, W)`` (every sample) or ``(B, H, W)`` (per sample), e.g. from
            :func:`hot_pixels`.

    Returns:
        The frames with those pixels zeroed; dtype and device kept.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - pixels: ``(N, 2)`` integers, or a bool ``(H, W)`` or ``(B, H, W)`` mask.

    Example:
        >>> drop_pixel(torch.ones(1, 2, 2, 3, dtype=torch.uint8), [[0, 1], [1, 2]])[0, 0].tolist()
        [[1, 0, 1], [1, 1, 0]]
    """
    batch, unbatch = as_batch(check_frames(frames))
    b, _, _, height, width = batch.shape
    return unbatch(_drop_mask(batch, _pixel_mask(pixels, b, height, width, batch.device)))

def _drop_mask(batch: Tensor, mask: Tensor) -> Tensor:
    """Zero the (B or 1, H, W) ``mask`` pixels in every frame."""
    return batch.masked_fill(mask.unsqueeze(1).unsqueeze(1), 0)

def _hash32(x: Tensor) -> Tensor:
    """A 32-bit integer mix (in int64, no overflow), the same on every device."""
    x = x & _MASK32
    x = (((x >> 16) ^ x) * 0x45D9F3B) & _MASK32
    x = (((x >> 16) ^ x) * 0x45D9F3B) & _MASK32
    return (x >> 16) ^ x

def random_pixel_mask(seed: Tensor, fraction: Tensor, height: int, width: int, device: torch.device) -> Tensor:
    """(B, H, W) bool: each pixel dropped with probability ``fraction[b]``, from ``seed[b]`` alone.

    A counter-based draw: a pixel's uniform number is a hash of the sample's 63-bit seed
    and the pixel's index, so a sample's mask depends on its own seed only (a batch gives
    what its samples give alone) and is the same on the CPU and on CUDA.

    Args:
        seed: ``(B,)`` int64 seeds (CPU).
        fraction: ``(B,)`` drop probabilities in [0, 1] (CPU).
        height, width: the frame size.
        device: where the mask is built.

    Shape:
        - seed, fraction: ``(B,)``.
        - output: bool ``(B, height, width)`` on ``device``.

    Example:
        >>> mask = random_pixel_mask(torch.tensor([1, 2]), torch.tensor([0.5, 0.0]), 3, 4, torch.device("cpu"))
        >>> mask.shape, mask[1].any().item()  # nothing dropped at fraction 0
        (torch.Size([2, 3, 4]), False)
        >>> alone = random_pixel_mask(torch.tensor([1]), torch.tensor([0.5]), 3, 4, torch.device("cpu"))
        >>> torch.equal(mask[:1], alone)  # a sample's mask depends on its own seed only
        True
    """
    pixel = torch.arange(height * width, dtype=torch.int64, device=device)
    seed = seed.to(device, non_blocking=True).unsqueeze(1)
    low, high = seed & _MASK32, (seed >> 32) & _MASK32
    x = _hash32(_hash32(pixel ^ low) + high)
    u = (x.to(torch.float64) + 0.5) / 2.0**32  # (B, H*W) in (0, 1)
    return (u < fraction.to(device, torch.float64, non_blocking=True).unsqueeze(1)).view(-1, height, width)
