"""Cleaning kernels: hot pixels by rate and a frame-level denoising filter.

Both only find or zero entries, so counts can only fall and the dtype is kept. Neither
reads values back to the host. Removing pixels (given, hot or random) is in
:mod:`event_transforms.functional.drop`.
"""

from __future__ import annotations

import torch
from torch import Tensor

from .._validation import as_batch, as_number, check_frames, check_positive
from ._dispatch import kernel_for, register_kernel

__all__ = ["hot_pixels", "denoise", "denoise_frames"]


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

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: bool ``(H, W)`` or ``(B, H, W)`` on the frames' device.

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

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> frames = torch.zeros(3, 2, 5, 5, dtype=torch.int16)
        >>> frames[1, 1, 0, 0] = 2  # alone
        >>> frames[0, 0, 3, 3] = frames[1, 1, 4, 4] = 1  # neighbours in space and time
        >>> denoise(frames).nonzero().tolist()
        [[0, 0, 3, 3], [1, 1, 4, 4]]
    """
    kernel = kernel_for(denoise, frames)
    batch, unbatch = as_batch(check_frames(frames))
    spatial = as_number(radius, "radius", integer=True, low=0)
    temporal = as_number(temporal_radius, "temporal_radius", integer=True, low=0)
    return unbatch(kernel(batch, spatial, temporal))


def _box_sum(values: Tensor, dim: int, radius: int) -> Tensor:
    """Sum over ``[i - radius, i + radius]`` along ``dim`` (zeros outside), by a cumulative sum."""
    if radius == 0:
        return values
    size = values.shape[dim]
    radius = min(radius, size)  # a wider window adds only zeros
    pad = [0, 0] * (values.dim() - 1 - dim % values.dim()) + [radius + 1, radius]
    total = torch.nn.functional.pad(values, pad).cumsum(dim)
    return total.narrow(dim, 2 * radius + 1, size) - total.narrow(dim, 0, size)


@register_kernel(denoise, Tensor)
def denoise_frames(batch: Tensor, radius: int, temporal_radius: int) -> Tensor:
    """Kernel of :func:`denoise` for frames: keep the counts of a pixel only if another
    pixel within ``radius`` (space) and ``temporal_radius`` frames (time) holds an event.

    Args:
        batch: frames ``(B, T, 2, H, W)``.
        radius: the spatial neighbourhood in pixels.
        temporal_radius: the temporal neighbourhood in frames.

    Shape:
        - batch: ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> frames = torch.zeros(1, 1, 2, 3, 3)
        >>> frames[0, 0, 0, 0, 0] = 1  # alone: removed
        >>> int(denoise_frames(frames, 1, 0).sum())
        0
    """
    if batch.numel() == 0:
        return batch.clone()
    occupied = batch > 0  # (B, T, 2, H, W)
    # occupied entries per (t, y, x), both polarities: whole numbers, exact in float32
    window = occupied.sum(dim=2, dtype=torch.float32)
    window = _box_sum(_box_sum(_box_sum(window, 1, temporal_radius), 2, radius), 3, radius)
    others = window.unsqueeze(2) - occupied.to(torch.float32)  # the entry itself excluded
    return batch.masked_fill(occupied & (others < 0.5), 0)
