"""Cleaning modules: frame-level denoising.

It only zeros entries: counts can only fall, and the dtype is kept. Removing given, hot or
random pixels is in :mod:`event_transforms.transforms.drop`.
"""

from __future__ import annotations

from torch import Tensor

from .._validation import as_number
from .. import functional as F
from ..events.batch import EventBatch
from ..functional._dispatch import call_kernel
from .base import EventTransform, Params

__all__ = ["Denoise"]


class Denoise(EventTransform):
    """Remove events with no other event within ``radius`` pixels and ``temporal_radius`` frames.

    See :func:`~event_transforms.functional.denoise`. Counts kept are unchanged; the
    dtype is kept. On an EventBatch (which needs a frame grid) the same rule is applied
    event by event, with the neighbourhood counted in the grid's bins, so binned the result
    equals the frame result.

    Args:
        radius: spatial half-width of the neighbourhood (pixels, >= 0).
        temporal_radius: temporal half-width (frames, >= 0).
        p: probability that a sample is denoised.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.

    Example:
        >>> import torch
        >>> frames = torch.zeros(3, 2, 5, 5)
        >>> frames[1, 1, 0, 0] = 2.0
        >>> frames[0, 0, 3, 3] = frames[2, 1, 4, 4] = 1.0
        >>> Denoise()(frames).sum().item(), Denoise(temporal_radius=2)(frames).sum().item()
        (0.0, 2.0)
    """

    def __init__(self, radius: int = 1, *, temporal_radius: int = 1, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.radius = as_number(radius, "radius", integer=True, low=0)
        self.temporal_radius = as_number(temporal_radius, "temporal_radius", integer=True, low=0)

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.denoise, inputs, self.radius, self.temporal_radius)

    def _settings(self) -> str:
        return f"radius={self.radius}, temporal_radius={self.temporal_radius}"
