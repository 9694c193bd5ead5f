"""Polarity kernels: polarity flip, merged polarities.

Both move or add whole counts: the dtype is kept. Channel 0 is OFF and channel 1 is ON
(tonic's convention), so flipping the polarity swaps the channels. Time reversal, which
also swaps them, is in :mod:`event_transforms.functional.temporal`.
"""

from __future__ import annotations

import torch
from torch import Tensor

from .._validation import as_batch, check_frames
from .geometry import _sum_in

__all__ = ["flip_polarity", "merge_polarities"]


def flip_polarity(frames: Tensor) -> Tensor:
    """Swap the OFF and ON channels of every frame. Counts and dtype are kept.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> flip_polarity(torch.tensor([[[[1]], [[5]]]]))[0, :, 0, 0].tolist()
        [5, 1]
    """
    return check_frames(frames).flip(-3)


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

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        keepdim: keep two channels (channel 1 zero) or return one.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: the same shape with ``keepdim=True``; ``(..., T, 1, H, W)`` otherwise. Dtype and
          device kept.

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


