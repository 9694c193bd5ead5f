"""Cleaning modules: remove given or hot pixels, random pixel dropout, frame-level denoising.

They only zero entries: counts can only fall, and the dtype is kept. Masks are computed on
the frames' device; nothing is read back to the host.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import as_number, check_pair, check_positive
from ..functional.cleaning import _denoise, _drop_mask, _hot_pixels, _pixel_mask, random_pixel_mask
from .base import EventTransform, Param, Params, seeds, uniform

__all__ = ["DropPixel", "RandomDropPixel", "Denoise"]


class DropPixel(EventTransform):
    """Remove given pixels, or each sequence's hot pixels, in all frames and polarities.

    Give exactly one of ``pixels`` (the same for every sample: known dead or hot pixels of
    a sensor) or ``rate_hz`` (per sample: pixels whose rate over the sequence, both
    polarities, exceeds ``rate_hz``; see :func:`~event_transforms.functional.hot_pixels`).

    Args:
        pixels: ``(N, 2)`` integer ``(y, x)`` coordinates, or an ``(H, W)`` bool mask.
        rate_hz: hot-pixel threshold in events per second.
        frame_ms: the duration of one frame, for ``rate_hz``.
        p: probability that a sample is cleaned.

    Example:
        >>> frames = torch.zeros(10, 2, 2, 3, dtype=torch.int32)
        >>> frames[:, 1, 0, 2] = 1  # 100 Hz
        >>> frames[3, 0, 1, 1] = 1
        >>> DropPixel(rate_hz=50.0)(frames).nonzero().tolist()
        [[3, 0, 1, 1]]
        >>> DropPixel([[1, 1]])(frames).sum().item()
        10
    """

    def __init__(
        self,
        pixels: Tensor | Sequence[Sequence[int]] | None = None,
        *,
        rate_hz: float | None = None,
        frame_ms: float = 10.0,
        p: float = 1.0,
    ) -> None:
        super().__init__(p=p)
        if (pixels is None) == (rate_hz is None):
            raise ValueError(f"give exactly one of pixels or rate_hz, got pixels={pixels!r}, rate_hz={rate_hz!r}")
        self.pixels = None
        if pixels is not None:
            pixels = pixels if isinstance(pixels, Tensor) else torch.as_tensor(pixels)
            if pixels.dtype == torch.bool and pixels.dim() != 2:
                raise ValueError(f"a pixel mask must have shape (H, W), got {tuple(pixels.shape)}")
            self.pixels = pixels.detach().cpu().clone()
        self.rate_hz = None if rate_hz is None else check_positive(rate_hz, "rate_hz")
        self.frame_ms = check_positive(frame_ms, "frame_ms")

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        b, _, _, height, width = frames.shape
        if self.pixels is not None:
            mask = _pixel_mask(self.pixels, b, height, width, frames.device)
        else:
            mask = _hot_pixels(frames, self.rate_hz * self.frame_ms / 1000.0)
        return _drop_mask(frames, mask)

    def _settings(self) -> str:
        if self.pixels is not None:
            shown = f"mask {tuple(self.pixels.shape)}" if self.pixels.dtype == torch.bool else self.pixels.tolist()
            return f"pixels={shown}"
        return f"rate_hz={self.rate_hz}, frame_ms={self.frame_ms}"


class RandomDropPixel(EventTransform):
    """Remove a random set of pixels per sequence (pixel dropout), in all its frames.

    Each pixel of sample b is dropped independently with probability ``fraction[b]``,
    drawn per sample from ``fraction`` (a number or a ``(min, max)`` range). The mask comes
    from the sample's ``params["seed"]`` alone (a counter-based hash), so it replays, a
    batch gives what its samples give alone, and CPU and CUDA drop the same pixels.

    Args:
        fraction: share of pixels dropped, in [0, 1], or a ``(min, max)`` range.
        p: probability that a sample is thinned.

    Example:
        >>> out = RandomDropPixel(0.5)(torch.ones(2, 3, 2, 20, 20), generator=torch.Generator().manual_seed(0))
        >>> [round(f, 2) for f in (out[:, 0, 0] == 0).float().mean((1, 2)).tolist()]
        [0.48, 0.55]
    """

    def __init__(self, fraction: float | Sequence[float], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.fraction = check_pair(fraction, "fraction", single=True, low=0.0, high=1.0)

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        b = shape[0]
        return {"fraction": uniform(*self.fraction, b, generator), "seed": seeds(b, generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"fraction": Param("float", low=0.0, high=1.0), "seed": Param("int", low=0, high=2**63 - 1)}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        height, width = frames.shape[-2:]
        mask = random_pixel_mask(params["seed"], params["fraction"], height, width, frames.device)
        return _drop_mask(frames, mask)

    def _settings(self) -> str:
        return f"fraction={self.fraction}"


class Denoise(EventTransform):
    """Remove events with no other event within ``radius`` pixels and ``temporal_radius`` frames.

    See :func:`~event_transforms.functional.denoise`. Counts kept are unchanged; the
    dtype is kept.

    Args:
        radius: spatial half-width of the neighbourhood (pixels, >= 0).
        temporal_radius: temporal half-width (frames, >= 0).
        p: probability that a sample is denoised.

    Example:
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

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _denoise(frames, self.radius, self.temporal_radius)

    def _settings(self) -> str:
        return f"radius={self.radius}, temporal_radius={self.temporal_radius}"
