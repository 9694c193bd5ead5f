"""Polarity modules: polarity flip, merged polarities.

Counts and dtype are kept by both. :class:`MergePolarities` keeps the two-channel layout
(see :func:`~event_transforms.functional.merge_polarities`). Time reversal, which also
swaps the polarities, is in :mod:`event_transforms.transforms.temporal`.
"""

from __future__ import annotations

from torch import Tensor

from .. import functional as F
from ..events.batch import EventBatch
from ..functional._dispatch import call_kernel
from .base import EventTransform, Params

__all__ = ["FlipPolarity", "RandomFlipPolarity", "MergePolarities"]


class FlipPolarity(EventTransform):
    """Swap the OFF and ON channels. Counts and dtype are kept.

    Args:
        p: probability that a sample is flipped.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

    Example:
        >>> import torch
        >>> FlipPolarity()(torch.tensor([[[[1]], [[5]]]]))[0, :, 0, 0].tolist()
        [5, 1]
    """

    gates_in_kernel = True  # the kernel takes the gate as its flags: no gather, no put-back

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.flip_polarity, inputs, params.get("apply"))


class RandomFlipPolarity(FlipPolarity):
    """Swap the polarities of each sequence with probability ``p`` (per sample; default 0.5).

    Args:
        p: probability that a sample is flipped (default 0.5).

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

    Example:
        >>> import torch
        >>> frames = torch.tensor([[[[1]], [[5]]]]).expand(4, 1, 2, 1, 1)
        >>> RandomFlipPolarity()(frames, generator=torch.Generator().manual_seed(0))[:, 0, :, 0, 0].tolist()
        [[1, 5], [1, 5], [5, 1], [1, 5]]
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

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept. Channel 1 comes back zero.

    Example:
        >>> import torch
        >>> MergePolarities()(torch.tensor([[[[1, 0]], [[2, 3]]]]))[0, :, 0].tolist()
        [[3, 3], [0, 0]]
    """

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.merge_polarities, inputs, True)


