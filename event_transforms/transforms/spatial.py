"""Spatial transform modules: rotation, resize, flips."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .. import functional as F
from .._validation import check_number
from ..functional.spatial import Center
from .base import EventTransform, Params, apply_by_group, bernoulli, check_range, choice, uniform

__all__ = [
    "Rotate",
    "RandomRotation",
    "Resize",
    "RandomResize",
    "HorizontalFlip",
    "VerticalFlip",
    "RandomHorizontalFlip",
    "RandomVerticalFlip",
]


def _check_center(center: Center) -> Center:
    if isinstance(center, str) and center not in ("mass", "image"):
        raise ValueError(f"center must be 'mass', 'image' or (y, x), got {center!r}")
    if not isinstance(center, (str, Sequence, Tensor)):
        raise TypeError(f"center must be 'mass', 'image' or (y, x), got {center!r}")
    return center


def _check_mode(mode: str) -> str:
    if mode not in ("bilinear", "nearest"):
        raise ValueError(f"mode must be 'bilinear' or 'nearest', got {mode!r}")
    return mode


class _Affine(EventTransform):
    """Shared settings of the rotation and resize modules."""

    def __init__(self, *, center: Center, mode: str) -> None:
        super().__init__()
        self.center = _check_center(center)
        self.mode = _check_mode(mode)

    def _extra(self) -> str:
        return f"center={self.center!r}, mode={self.mode!r}"


class Rotate(_Affine):
    """Rotate every frame by a fixed angle about the sequence's centre.

    Args:
        angle: degrees, counter-clockwise on the displayed image.
        center: ``"mass"`` (event centroid of the sequence), ``"image"`` or ``(y, x)``.
        mode: ``"bilinear"`` (float output: input dtype for floats, float32 for integers)
            or ``"nearest"`` (dtype kept).

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged.

    Example:
        >>> frames = torch.zeros(2, 1, 2, 5, 5)
        >>> frames[:, 0, 1, 2, 4] = 1.0
        >>> Rotate(90.0, center="image")(frames)[:, 0, 1].nonzero().tolist()
        [[0, 0, 2], [1, 0, 2]]
    """

    def __init__(self, angle: float, *, center: Center = "mass", mode: str = "bilinear") -> None:
        super().__init__(center=center, mode=mode)
        self.angle = check_number(angle, "angle")

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return {"angle": torch.full((batch_size,), self.angle, dtype=torch.float64)}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.rotate(frames, params["angle"], center=self.center, mode=self.mode)

    def extra_repr(self) -> str:
        return f"angle={self.angle}, {self._extra()}"


class RandomRotation(_Affine):
    """Rotate each sequence by its own random angle, the same for all its frames.

    Args:
        degrees: ``d`` for U(-d, d), or a ``(min, max)`` range, in degrees.
        center, mode: as in :class:`Rotate`.

    Example:
        >>> transform = RandomRotation(45.0)
        >>> transform.make_params(3, generator=torch.Generator().manual_seed(0))["angle"]
        tensor([42.3048, 18.7038, -3.6555], dtype=torch.float64)
    """

    def __init__(
        self, degrees: float | Sequence[float], *, center: Center = "mass", mode: str = "bilinear"
    ) -> None:
        super().__init__(center=center, mode=mode)
        self.degrees = check_range(degrees, "degrees", symmetric=True)

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return {"angle": uniform(*self.degrees, batch_size, generator)}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.rotate(frames, params["angle"], center=self.center, mode=self.mode)

    def extra_repr(self) -> str:
        return f"degrees={self.degrees}, {self._extra()}"


class Resize(_Affine):
    """Zoom every frame by a fixed factor about the sequence's centre (H×W kept).

    Args:
        scale: the paper's β = target size / source size (> 0).
        center, mode: as in :class:`Rotate`.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5)
        >>> frames[0, 0, 2, 3] = 1.0
        >>> Resize(2.0, center="image")(frames)[0, 0, 2].tolist()
        [0.0, 0.0, 0.0, 0.5, 1.0]
    """

    def __init__(self, scale: float, *, center: Center = "mass", mode: str = "bilinear") -> None:
        super().__init__(center=center, mode=mode)
        self.scale = check_number(scale, "scale", low=0.0)
        if self.scale == 0:
            raise ValueError(f"scale must be > 0, got {scale!r}")

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return {"scale": torch.full((batch_size,), self.scale, dtype=torch.float64)}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.resize(frames, params["scale"], center=self.center, mode=self.mode)

    def extra_repr(self) -> str:
        return f"scale={self.scale}, {self._extra()}"


class RandomResize(_Affine):
    """Zoom each sequence by its own random factor about its centre.

    Give either ``scale``, a ``(min, max)`` range drawn uniformly, or ``choices``, a set
    of factors drawn with equal probability — e.g. the paper's ``(15/18, 15/12)``.

    Args:
        scale: ``(min, max)`` zoom range, both > 0.
        choices: zoom factors, all > 0.
        center, mode: as in :class:`Rotate`.

    Example:
        >>> transform = RandomResize(choices=(15 / 18, 15 / 12))
        >>> transform.make_params(4, generator=torch.Generator().manual_seed(0))["scale"]
        tensor([0.8333, 1.2500, 1.2500, 0.8333], dtype=torch.float64)
    """

    def __init__(
        self,
        scale: Sequence[float] | None = None,
        *,
        choices: Sequence[float] | None = None,
        center: Center = "mass",
        mode: str = "bilinear",
    ) -> None:
        super().__init__(center=center, mode=mode)
        if (scale is None) == (choices is None):
            raise ValueError(f"give exactly one of scale or choices, got scale={scale!r}, choices={choices!r}")
        self.scale = None if scale is None else check_range(scale, "scale")
        self.choices = None if choices is None else tuple(float(c) for c in choices)
        if self.scale is not None and self.scale[0] <= 0:
            raise ValueError(f"scale must be > 0, got {scale!r}")
        if self.choices is not None and (not self.choices or min(self.choices) <= 0):
            raise ValueError(f"choices must be a non-empty set of factors > 0, got {choices!r}")

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        if self.choices is not None:
            return {"scale": choice(torch.tensor(self.choices, dtype=torch.float64), batch_size, generator)}
        assert self.scale is not None
        return {"scale": uniform(*self.scale, batch_size, generator)}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.resize(frames, params["scale"], center=self.center, mode=self.mode)

    def extra_repr(self) -> str:
        setting = f"choices={self.choices}" if self.choices is not None else f"scale={self.scale}"
        return f"{setting}, {self._extra()}"


class HorizontalFlip(EventTransform):
    """Mirror every frame left-right. Counts and dtype are kept.

    Example:
        >>> HorizontalFlip()(torch.arange(4.).reshape(1, 2, 1, 2))[0, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.horizontal_flip(frames)


class VerticalFlip(EventTransform):
    """Mirror every frame top-bottom. Counts and dtype are kept.

    Example:
        >>> VerticalFlip()(torch.arange(4.).reshape(1, 2, 2, 1))[0, :, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.vertical_flip(frames)


class _RandomFlip(EventTransform):
    def __init__(self, p: float = 0.5) -> None:
        super().__init__()
        self.p = check_number(p, "p", low=0.0, high=1.0)

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return {"flip": bernoulli(self.p, batch_size, generator)}

    def extra_repr(self) -> str:
        return f"p={self.p}"


class RandomHorizontalFlip(_RandomFlip):
    """Mirror each sequence left-right with probability ``p`` (per sample).

    Example:
        >>> frames = torch.arange(8.).reshape(2, 1, 2, 1, 2)
        >>> RandomHorizontalFlip(p=1.0)(frames)[:, 0, 0, 0].tolist()
        [[1.0, 0.0], [5.0, 4.0]]
    """

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        flip = lambda sub, _: F.horizontal_flip(sub)  # noqa: E731
        return apply_by_group(frames, params["flip"].long(), [None, flip])


class RandomVerticalFlip(_RandomFlip):
    """Mirror each sequence top-bottom with probability ``p`` (per sample).

    Example:
        >>> frames = torch.arange(8.).reshape(2, 1, 2, 2, 1)
        >>> RandomVerticalFlip(p=1.0)(frames)[:, 0, 0, :, 0].tolist()
        [[1.0, 0.0], [5.0, 4.0]]
    """

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        flip = lambda sub, _: F.vertical_flip(sub)  # noqa: E731
        return apply_by_group(frames, params["flip"].long(), [None, flip])
