"""Cleaning kernels: pixel removal (given pixels, hot pixels by rate, random pixel dropout)
and a frame-level denoising filter.

All of them only zero entries, so counts can only fall and the dtype is kept. None reads
values back to the host: masks are computed on the frames' device.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import as_batch, as_number, check_frames, check_positive, describe, per_sample

__all__ = ["hot_pixels", "drop_pixel", "random_pixel_mask", "denoise"]

_MASK32 = 0xFFFFFFFF


def hot_pixels(frames: Tensor, rate_hz: float, *, frame_ms: float = 10.0) -> Tensor:
    """Pixels whose event rate over the sequence exceeds ``rate_hz`` (hot pixels), per sample.

    The rate of a pixel is its event count over all frames and both polarities divided by
    the sequence's duration ``T · frame_ms`` (tonic's ``identify_hot_pixel`` on frames).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        rate_hz: events per second above which a pixel is hot (> 0).
        frame_ms: the duration of one frame in milliseconds.

    Returns:
        bool ``(H, W)`` or ``(B, H, W)`` on the frames' device.

    Example:
        >>> frames = torch.zeros(10, 2, 2, 3)
        >>> frames[:, 1, 0, 2] = 1.0  # one event per 10 ms frame: 100 Hz
        >>> hot_pixels(frames, 50.0).nonzero().tolist()
        [[0, 2]]
    """
    batch, unbatch = as_batch(check_frames(frames))
    rate = check_positive(rate_hz, "rate_hz")
    duration = check_positive(frame_ms, "frame_ms") / 1000.0
    return unbatch(_hot_pixels(batch, rate * duration))


def _hot_pixels(batch: Tensor, events_per_frame: float) -> Tensor:
    """(B, H, W): total count over T and P > ``events_per_frame`` · T."""
    acc = torch.float64 if batch.dtype in (torch.float64, torch.int32, torch.int64) else torch.float32
    total = batch.to(acc).sum(dim=(1, 2))
    return total > events_per_frame * batch.shape[1]


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
    """
    pixel = torch.arange(height * width, dtype=torch.int64, device=device)
    seed = seed.to(device, non_blocking=True).unsqueeze(1)
    low, high = seed & _MASK32, (seed >> 32) & _MASK32
    x = _hash32(_hash32(pixel ^ low) + high)
    u = (x.to(torch.float64) + 0.5) / 2.0**32  # (B, H*W) in (0, 1)
    return (u < fraction.to(device, torch.float64, non_blocking=True).unsqueeze(1)).view(-1, height, width)


def denoise(frames: Tensor, *, radius: int = 1, temporal_radius: int = 1) -> Tensor:
    """Remove events with no other event nearby (background-activity filter on frames).

    An entry (t, p, y, x) with events is kept when some *other* entry within
    ``|y' - y| <= radius``, ``|x' - x| <= radius`` and ``|t' - t| <= temporal_radius``, of
    either polarity, holds events; otherwise its events are removed. This is tonic's
    ``Denoise`` (a neighbour within ``filter_time``) on frames, with a symmetric window in
    time (a frame cannot tell earlier from later events inside it). Values > 0 count as
    events. Counts kept are unchanged; the dtype is kept.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        radius: spatial half-width of the window in pixels (>= 0).
        temporal_radius: temporal half-width in frames (>= 0).

    Example:
        >>> frames = torch.zeros(3, 2, 5, 5, dtype=torch.int16)
        >>> frames[1, 1, 0, 0] = 2  # alone
        >>> frames[0, 0, 3, 3] = frames[1, 1, 4, 4] = 1  # neighbours in space and time
        >>> denoise(frames).nonzero().tolist()
        [[0, 0, 3, 3], [1, 1, 4, 4]]
    """
    batch, unbatch = as_batch(check_frames(frames))
    spatial = as_number(radius, "radius", integer=True, low=0)
    temporal = as_number(temporal_radius, "temporal_radius", integer=True, low=0)
    return unbatch(_denoise(batch, spatial, temporal))


def _box_sum(values: Tensor, dim: int, radius: int) -> Tensor:
    """Sum over ``[i - radius, i + radius]`` along ``dim`` (zeros outside), by a cumulative sum."""
    if radius == 0:
        return values
    size = values.shape[dim]
    radius = min(radius, size)  # a wider window adds only zeros
    pad = [0, 0] * (values.dim() - 1 - dim % values.dim()) + [radius + 1, radius]
    total = torch.nn.functional.pad(values, pad).cumsum(dim)
    return total.narrow(dim, 2 * radius + 1, size) - total.narrow(dim, 0, size)


def _denoise(batch: Tensor, radius: int, temporal_radius: int) -> Tensor:
    if batch.numel() == 0:
        return batch.clone()
    occupied = batch > 0  # (B, T, 2, H, W)
    # occupied entries per (t, y, x), both polarities: whole numbers, exact in float32
    window = occupied.sum(dim=2, dtype=torch.float32)
    window = _box_sum(_box_sum(_box_sum(window, 1, temporal_radius), 2, radius), 3, radius)
    others = window.unsqueeze(2) - occupied.to(torch.float32)  # the entry itself excluded
    return batch.masked_fill(occupied & (others < 0.5), 0)
