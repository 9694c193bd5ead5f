"""Polarity and time kernels: polarity flip, time reversal, merged polarities, temporal crop.

All of them move or add whole counts: the dtype is kept. Channel 0 is OFF and channel 1 is
ON (tonic's convention), so flipping the polarity swaps the channels, and reversing time
reverses the frames *and* swaps the channels, because a brightness increase played
backwards is a decrease.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import as_batch, as_number, check_frames, describe, per_sample
from .geometry import _sum_in

__all__ = ["flip_polarity", "time_reversal", "merge_polarities", "crop_time"]

Scalars = float | Sequence[float] | Tensor


def flip_polarity(frames: Tensor) -> Tensor:
    """Swap the OFF and ON channels of every frame. Counts and dtype are kept.

    Example:
        >>> flip_polarity(torch.tensor([[[[1]], [[5]]]]))[0, :, 0, 0].tolist()
        [5, 1]
    """
    return check_frames(frames).flip(-3)


def time_reversal(frames: Tensor) -> Tensor:
    """Play each sequence backwards: reverse the frames and swap the polarities.

    Frame t goes to T - 1 - t, and an ON event becomes an OFF event (a brightness change
    reversed in time has the opposite sign), as tonic's ``RandomTimeReversal`` does with
    ``flip_polarities=True``. Counts and dtype are kept.

    Example:
        >>> frames = torch.zeros(3, 2, 1, 1, dtype=torch.int8)
        >>> frames[0, 1] = 4  # ON events in the first frame
        >>> time_reversal(frames)[:, :, 0, 0].tolist()
        [[0, 0], [0, 0], [4, 0]]
    """
    return check_frames(frames).flip(-4, -3)


def merge_polarities(frames: Tensor, *, keepdim: bool = True) -> Tensor:
    """Count events regardless of polarity.

    With ``keepdim=True`` (default) the frames keep the library's ``(T, 2, H, W)`` contract
    so every other transform still applies: channel 0 holds all the events and channel 1 is
    zero, exactly what tonic's ``ToFrame`` makes of events after its ``MergePolarities``
    (which sets every polarity to 0) on a two-polarity sensor. The total count is kept.
    With ``keepdim=False`` the result is ``(T, 1, H, W)``, for a model's input; it is the
    end of a pipeline, since the transforms here need two channels.

    The sum is taken in a wide dtype and returned in the input dtype; 8/16-bit integer
    frames whose sum would overflow raise instead of wrapping (one host synchronisation,
    those dtypes only).

    Example:
        >>> frames = torch.tensor([[[[1, 0]], [[2, 3]]]])
        >>> merge_polarities(frames)[0, :, 0].tolist(), merge_polarities(frames, keepdim=False).shape
        ([[3, 3], [0, 0]], torch.Size([1, 1, 1, 2]))
    """
    if not isinstance(keepdim, bool):
        raise TypeError(f"keepdim must be a bool, got {keepdim!r}")
    batch, unbatch = as_batch(check_frames(frames))
    return unbatch(_merge_polarities(batch, keepdim))


def _merge_polarities(batch: Tensor, keepdim: bool) -> Tensor:
    merged = _sum_in(batch, 2, "merge_polarities", keepdim=True)
    if not keepdim:
        return merged
    return torch.cat([merged, torch.zeros_like(merged)], dim=2)


def _check_length(length: object, frames: int) -> int:
    value = as_number(length, "length", integer=True)
    if not 1 <= value <= frames:
        raise ValueError(f"length must lie in [1, {frames}] (the number of frames T), got {length!r}")
    return value


def crop_time(frames: Tensor, start: Scalars, length: int) -> Tensor:
    """Keep frames ``[start, start + length)`` of each sequence (a temporal window).

    tonic's ``CropTime`` on frames: the window is counted in frames, not microseconds.
    Labels per frame (force) must be cut with the same window:
    ``labels.gather(1, start.view(-1, 1) + torch.arange(length))``.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        start: first kept frame, an integer or ``(B,)``, with ``start + length <= T``.
        length: number of kept frames, in [1, T].

    Returns:
        ``(length, 2, H, W)`` or ``(B, length, 2, H, W)``; dtype and device kept.

    Example:
        >>> frames = torch.arange(5).view(5, 1, 1, 1).expand(5, 2, 1, 1)
        >>> crop_time(frames, 1, 3)[:, 0, 0, 0].tolist()
        [1, 2, 3]
    """
    batch, unbatch = as_batch(check_frames(frames))
    b, t = batch.shape[:2]
    size = _check_length(length, t)
    start_t = per_sample(start, b, "start", dtype=torch.int64)
    if start_t.numel() and bool(((start_t < 0) | (start_t > t - size)).any()):
        raise ValueError(f"start must lie in [0, {t - size}] for a window of {size} of {t} frames, got {describe(start)}")
    return unbatch(_crop_time(batch, start_t, size))


def _crop_time(batch: Tensor, start: Tensor, length: int) -> Tensor:
    """Frames ``[start, start + length)`` with a (B,) int64 CPU ``start``."""
    b, t, p, h, w = batch.shape
    index = (start.unsqueeze(1) + torch.arange(length)).to(batch.device, non_blocking=True)  # (B, length)
    if b == 0 or batch.numel() == 0:
        return batch.new_zeros((b, length, p, h, w))
    return batch.gather(1, index.view(b, length, 1, 1, 1).expand(b, length, p, h, w))
