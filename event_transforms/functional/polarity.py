"""Polarity kernels: polarity flip, merged polarities.

Both move or add whole counts: the dtype is kept. Channel 0 is OFF and channel 1 is ON
(tonic's convention), so flipping the polarity swaps the channels. Time reversal, which
also swaps them, is in :mod:`event_transforms.functional.temporal`.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from .._validation import as_batch, check_frames
from ..events.batch import EventBatch
from ._dispatch import batch_of, call_kernel, kernel_for, register_kernel
from ._event_ops import _mirrored
from ._frame_ops import _flagged_rows, _flags, _sum_in

__all__ = [
    "flip_polarity", "flip_polarity_frames", "flip_polarity_events", "merge_polarities", "merge_polarities_frames",
    "merge_polarities_events",
]


def flip_polarity(inputs: Tensor | EventBatch, flip: Tensor | None = None) -> Tensor | EventBatch:
    """Swap the OFF and ON channels of every frame. Counts and dtype are kept.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch
            (``p -> 1 - p``).
        flip: ``(B,)`` bool, the samples to flip (default: all).

    Shape:
        - inputs: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        - output: same shape, dtype and device.

    Example:
        >>> flip_polarity(torch.tensor([[[[1]], [[5]]]]))[0, :, 0, 0].tolist()
        [5, 1]
    """
    batch, b, restore = batch_of(inputs)
    return restore(call_kernel(flip_polarity, batch, _flags(flip, b)))


@register_kernel(flip_polarity, Tensor)
def flip_polarity_frames(frames: Tensor, flip: Tensor | None = None) -> Tensor:
    """Kernel of :func:`flip_polarity` for frames ``(B, T, 2, H, W)``: the flagged samples flipped.

    Args:
        frames: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        flip: ``(B,)`` bool, the samples to flip (default: all).

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`flip_polarity` gives for a batch.
    """
    order = np.arange(frames.shape[1] * frames.shape[2]) ^ 1  # rows (frame, polarity): p -> 1 - p
    return _flagged_rows(frames, flip, lambda f: f.flip(-3), order)


@register_kernel(flip_polarity, EventBatch)
def flip_polarity_events(batch: EventBatch, flip: Tensor | None = None) -> EventBatch:
    """Kernel of :func:`flip_polarity` for an EventBatch: ON and OFF swapped in the flagged samples. Sync-free.

    Args:
        batch: the event streams.
        flip: ``(B,)`` bool, the samples whose polarities swap (``None``: all).

    Shape:
        - batch: B streams, N events.
        - flip: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> flip_polarity_events(batch, torch.tensor([True, False])).p.tolist()
        [0, 1, 0]
    """
    swapped = _mirrored(batch, flip, batch.p, 1)
    return batch if swapped is None else batch._replace(p=swapped.to(torch.int8))


def merge_polarities(frames: Tensor | EventBatch, *, keepdim: bool = True) -> Tensor | EventBatch:
    """Count events regardless of polarity.

    With ``keepdim=True`` (default) the frames keep the library's ``(T, 2, H, W)`` contract
    so every other transform still applies: channel 0 holds all the events and channel 1 is
    zero, exactly what tonic's ``ToFrame`` makes of events after its ``MergePolarities``
    (which sets every polarity to 0) on a two-polarity sensor. The total count is kept.
    With ``keepdim=False`` the result is ``(T, 1, H, W)``, for a model's input; it is the
    end of a pipeline, since the transforms here need two channels.

    The sum is taken in a wide dtype and returned in the input dtype; 8/16-bit integer
    frames whose sum would overflow raise instead of wrapping, float16/bfloat16 frames whose
    sum passes the dtype's range raise instead of giving ``inf`` (one host synchronisation,
    those dtypes only).

    On an EventBatch (:func:`merge_polarities_events`) every event becomes OFF (``p = 0``),
    tonic's ``MergePolarities``: binned, it equals the frame kernel with ``keepdim=True``.
    ``keepdim=False`` needs frames (an EventBatch always has two polarities).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        keepdim: keep two channels (channel 1 zero) or return one (frames only).

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
    kernel = kernel_for(merge_polarities, frames)
    if isinstance(frames, EventBatch):
        return kernel(frames, keepdim)
    batch, unbatch = as_batch(check_frames(frames))
    return unbatch(kernel(batch, keepdim))


@register_kernel(merge_polarities, Tensor)
def merge_polarities_frames(batch: Tensor, keepdim: bool = True) -> Tensor:
    """Kernel of :func:`merge_polarities` for frames ``(B, T, 2, H, W)``.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        keepdim: keep two channels (channel 1 zero) or return one.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`merge_polarities` gives for a batch.
    """
    merged = _sum_in(batch, 2, "merge_polarities", keepdim=True)
    if not keepdim:
        return merged
    return torch.cat([merged, torch.zeros_like(merged)], dim=2)


@register_kernel(merge_polarities, EventBatch)
def merge_polarities_events(batch: EventBatch, keepdim: bool = True) -> EventBatch:
    """Kernel of :func:`merge_polarities` for an EventBatch: every event's polarity set to 0
    (OFF), so binned, channel 0 holds all events and channel 1 none, as on frames. Sync-free.

    Args:
        batch: the event streams.
        keepdim: must be true (one channel is a frame layout).

    Shape:
        - batch: B streams, N events.
        - output: the same streams and events, ``p`` all 0.

    Raises:
        ValueError: ``keepdim=False`` (one channel is a frame layout; bin first).

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 5, 1], [1, 0, 6, 0]])], sensor_size=(2, 2))
        >>> merge_polarities_events(batch).p.tolist()
        [0, 0]
    """
    if not keepdim:
        raise ValueError(
            "merge_polarities(keepdim=False) makes one-channel frames; an EventBatch keeps two polarities: "
            "bin the events first (EventsToFrames), or use keepdim=True"
        )
    return batch._replace(p=torch.zeros_like(batch.p))
