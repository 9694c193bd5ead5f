"""Polarity and time modules: polarity flip, time reversal, merged polarities, temporal crop.

Counts and dtype are kept by all of them.
:class:`CropTime` and :class:`RandomCropTime` change T for every sample, so they take no
``p``; :class:`MergePolarities` keeps the two-channel layout (see
:func:`~event_transforms.functional.merge_polarities`).
"""

from __future__ import annotations

import torch
from torch import Tensor

from .._validation import as_number
from ..functional.polarity import _check_length, _crop_time, _merge_polarities
from .base import EventTransform, Param, Params, integers

__all__ = [
    "FlipPolarity",
    "RandomFlipPolarity",
    "TimeReversal",
    "RandomTimeReversal",
    "MergePolarities",
    "CropTime",
    "RandomCropTime",
]


class FlipPolarity(EventTransform):
    """Swap the OFF and ON channels. Counts and dtype are kept.

    Args:
        p: probability that a sample is flipped.

    Example:
        >>> FlipPolarity()(torch.tensor([[[[1]], [[5]]]]))[0, :, 0, 0].tolist()
        [5, 1]
    """

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return frames.flip(2)


class RandomFlipPolarity(FlipPolarity):
    """Swap the polarities of each sequence with probability ``p`` (per sample; default 0.5).

    Example:
        >>> frames = torch.tensor([[[[1]], [[5]]]]).expand(4, 1, 2, 1, 1)
        >>> RandomFlipPolarity()(frames, generator=torch.Generator().manual_seed(0))[:, 0, :, 0, 0].tolist()
        [[1, 5], [1, 5], [5, 1], [1, 5]]
    """

    def __init__(self, p: float = 0.5) -> None:
        super().__init__(p=p)

    def _settings(self) -> str:
        return "" if self.p < 1 else "p=1.0"


class TimeReversal(EventTransform):
    """Play each sequence backwards: frames reversed and polarities swapped.

    See :func:`~event_transforms.functional.time_reversal`. Per-frame labels (force)
    are *not* reversed (extra inputs pass through); reverse them yourself if a reversed
    sequence should keep its pairing, or do not use it where time has a direction (a grasp
    never plays backwards: a tactile scene declares no time reversal).

    Args:
        p: probability that a sample is reversed.

    Example:
        >>> frames = torch.zeros(3, 2, 1, 1)
        >>> frames[0, 1] = 4.0
        >>> TimeReversal()(frames)[:, :, 0, 0].tolist()
        [[0.0, 0.0], [0.0, 0.0], [4.0, 0.0]]
    """

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return frames.flip(1, 2)


class RandomTimeReversal(TimeReversal):
    """Reverse each sequence in time (and swap polarities) with probability ``p`` (default 0.5).

    Example:
        >>> RandomTimeReversal(p=1.0)(torch.arange(4.).view(2, 2, 1, 1))[:, :, 0, 0].tolist()
        [[3.0, 2.0], [1.0, 0.0]]
    """

    def __init__(self, p: float = 0.5) -> None:
        super().__init__(p=p)

    def _settings(self) -> str:
        return "" if self.p < 1 else "p=1.0"


class MergePolarities(EventTransform):
    """Count events regardless of polarity: channel 0 holds all events, channel 1 is zero.

    The ``(T, 2, H, W)`` layout is kept so that later transforms still apply (tonic's
    ``MergePolarities`` then ``ToFrame`` with two polarities gives the same frames); the
    total count and the dtype are kept. For a one-channel model input use
    ``event_transforms.functional.merge_polarities(frames, keepdim=False)`` at the end.

    Args:
        p: probability that a sample's polarities are merged.

    Example:
        >>> MergePolarities()(torch.tensor([[[[1, 0]], [[2, 3]]]]))[0, :, 0].tolist()
        [[3, 3], [0, 0]]
    """

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _merge_polarities(frames, True)


class _CropTime(EventTransform):
    """Keeps frames ``[params["start"], params["start"] + length)``."""

    def __init__(self, length: int) -> None:
        super().__init__()
        self.length = as_number(length, "length", integer=True)
        if self.length < 1:
            raise ValueError(f"length must be >= 1, got {length!r}")

    def _room(self, shape) -> int:
        return shape[1] - _check_length(self.length, shape[1])

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"start": Param("int", low=0, high=self._room(shape))}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        self._room(frames.shape)
        return _crop_time(frames, params["start"], self.length)

    def output_shape(self, shape: torch.Size) -> torch.Size:
        return torch.Size((shape[0], self.length, *shape[2:]))


class CropTime(_CropTime):
    """Keep frames ``[start, start + length)`` of every sequence (tonic's ``CropTime``, in frames).

    Per-frame labels pass through uncut: cut them with the same window.

    Args:
        start: first kept frame (>= 0).
        length: number of kept frames.

    Shape:
        ``(B, T, 2, H, W)`` -> ``(B, length, 2, H, W)``.

    Example:
        >>> CropTime(2, 3)(torch.zeros(36, 2, 70, 75)).shape
        torch.Size([3, 2, 70, 75])
    """

    def __init__(self, start: int, length: int) -> None:
        super().__init__(length)
        self.start = as_number(start, "start", integer=True, low=0)

    def _room(self, shape) -> int:
        room = super()._room(shape)
        if self.start > room:
            raise ValueError(
                f"CropTime: start {self.start} + length {self.length} exceeds the {shape[1]} frames"
            )
        return room

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        self._room(shape)
        return {"start": torch.full((shape[0],), self.start, dtype=torch.int64)}

    def _settings(self) -> str:
        return f"start={self.start}, length={self.length}"


class RandomCropTime(_CropTime):
    """Keep a window of ``length`` frames at a random start per sequence.

    The starts are returned in ``params["start"]``: cut per-frame labels with them,
    ``labels.gather(1, params["start"].view(-1, 1) + torch.arange(length))``.

    Args:
        length: number of kept frames (at most T).

    Example:
        >>> transform = RandomCropTime(30)
        >>> transform.make_params((3, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))["start"].tolist()
        [6, 4, 3]
    """

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"start": integers(self._room(shape) + 1, shape[0], generator)}

    def _settings(self) -> str:
        return f"length={self.length}"
