"""Spatial transform modules: rotation, resize, flips.

Rotation and resize are one affine warp per sequence (every frame of a grasp keeps the
same orientation), about the event centroid by default. Bilinear sampling returns the
input dtype for float input and float32 for integer input; ``mode="nearest"`` keeps the
dtype. Values are moved or interpolated, never inspected.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .. import functional as F
from .._validation import INTERPOLATIONS, as_number, check_choice, check_pair, check_positive, on_host
from ..functional.spatial import Center, _affine, _check_center
from .base import EventTransform, Param, Params, choice, uniform

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


class _Affine(EventTransform):
    """Shared settings of the rotation and resize modules: ``params`` hold angle and/or scale."""

    def __init__(self, *, center: Center, mode: str, p: float) -> None:
        super().__init__(p=p)
        self.center = _check_center(center)
        self.mode = check_choice(mode, "mode", INTERPOLATIONS)

    def _warp(self, frames: Tensor, *, angle: Tensor | None = None, scale: Tensor | None = None) -> Tensor:
        return _affine(frames, angle, scale, self.center, self.mode)

    def _common(self) -> str:
        return f"center={self.center!r}, mode={self.mode!r}"


class _Rotation(_Affine):
    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"angle": Param("float")}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return self._warp(frames, angle=params["angle"])


class _Zoom(_Affine):
    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"scale": Param("float", low=float.fromhex("0x1p-1022"))}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return self._warp(frames, scale=params["scale"])


class Rotate(_Rotation):
    """Rotate every frame by a fixed angle about the sequence's centre.

    Args:
        angle: degrees, counter-clockwise on the displayed image (finite).
        center: ``"mass"`` (event centroid of the sequence), ``"image"`` or ``(y, x)``.
        mode: ``"bilinear"`` (float output: input dtype for floats, float32 for integers)
            or ``"nearest"`` (dtype kept).
        p: probability that a sample is rotated.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged.

    Example:
        >>> frames = torch.zeros(2, 1, 2, 5, 5)
        >>> frames[:, 0, 1, 2, 4] = 1.0
        >>> Rotate(90.0, center="image")(frames)[:, 0, 1].nonzero().tolist()
        [[0, 0, 2], [1, 0, 2]]
    """

    def __init__(self, angle: float, *, center: Center = "mass", mode: str = "bilinear", p: float = 1.0) -> None:
        super().__init__(center=center, mode=mode, p=p)
        self.angle = as_number(angle, "angle")

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"angle": torch.full((shape[0],), self.angle, dtype=torch.float64)}

    def _settings(self) -> str:
        return f"angle={self.angle}, {self._common()}"


class RandomRotation(_Rotation):
    """Rotate each sequence by its own random angle, the same for all its frames.

    Args:
        degrees: ``d`` for U(-d, d), or a ``(min, max)`` range, in degrees.
        center, mode: as in :class:`Rotate`.
        p: probability that a sample is rotated.

    Example:
        >>> transform = RandomRotation(45.0)
        >>> transform.make_params((3, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))["angle"]
        tensor([42.3048, 18.7038, -3.6555], dtype=torch.float64)
    """

    def __init__(
        self, degrees: float | Sequence[float], *, center: Center = "mass", mode: str = "bilinear", p: float = 1.0
    ) -> None:
        super().__init__(center=center, mode=mode, p=p)
        self.degrees = check_pair(degrees, "degrees", symmetric=True)

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"angle": uniform(*self.degrees, shape[0], generator)}

    def _settings(self) -> str:
        return f"degrees={self.degrees}, {self._common()}"


class Resize(_Zoom):
    """Zoom every frame by a fixed factor about the sequence's centre (H×W kept, zero margin).

    Args:
        scale: the paper's β = target size / source size (finite, > 0).
        center, mode: as in :class:`Rotate`.
        p: probability that a sample is resized.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5)
        >>> frames[0, 0, 2, 3] = 1.0
        >>> Resize(2.0, center="image")(frames)[0, 0, 2].tolist()
        [0.0, 0.0, 0.0, 0.5, 1.0]
    """

    def __init__(self, scale: float, *, center: Center = "mass", mode: str = "bilinear", p: float = 1.0) -> None:
        super().__init__(center=center, mode=mode, p=p)
        self.scale = check_positive(scale, "scale")

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"scale": torch.full((shape[0],), self.scale, dtype=torch.float64)}

    def _settings(self) -> str:
        return f"scale={self.scale}, {self._common()}"


class RandomResize(_Zoom):
    """Zoom each sequence by its own random factor about its centre.

    Give either ``scale``, a ``(min, max)`` range drawn uniformly, or ``choices``, a set
    of factors drawn with equal probability — e.g. the paper's ``(15/18, 15/12)``.

    Args:
        scale: ``(min, max)`` zoom range, both > 0.
        choices: zoom factors, all > 0.
        center, mode: as in :class:`Rotate`.
        p: probability that a sample is resized.

    Example:
        >>> transform = RandomResize(choices=(15 / 18, 15 / 12))
        >>> transform.make_params((4, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))["scale"]
        tensor([0.8333, 1.2500, 1.2500, 0.8333], dtype=torch.float64)
    """

    def __init__(
        self,
        scale: Sequence[float] | None = None,
        *,
        choices: Sequence[float] | None = None,
        center: Center = "mass",
        mode: str = "bilinear",
        p: float = 1.0,
    ) -> None:
        super().__init__(center=center, mode=mode, p=p)
        if (scale is None) == (choices is None):
            raise ValueError(f"give exactly one of scale or choices, got scale={scale!r}, choices={choices!r}")
        self.scale = None if scale is None else check_pair(scale, "scale")
        if self.scale is not None and self.scale[0] <= 0:
            raise ValueError(f"scale must be > 0, got {scale!r}")
        self.choices = None
        if choices is not None:
            if isinstance(choices, (str, bytes)) or not isinstance(choices, Sequence) or not choices:
                raise TypeError(f"choices must be a non-empty sequence of factors > 0, got {choices!r}")
            self.choices = tuple(check_positive(c, "choices") for c in choices)
            self._choices = torch.tensor(self.choices, dtype=torch.float64)  # CPU, drawn from in make_params

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        if self.choices is not None:
            return {"scale": choice(self._choices, shape[0], generator)}
        assert self.scale is not None
        return {"scale": uniform(*self.scale, shape[0], generator)}

    def _settings(self) -> str:
        setting = f"choices={self.choices}" if self.choices is not None else f"scale={self.scale}"
        return f"{setting}, {self._common()}"


def _flip(frames: Tensor, params: Params, axis: int) -> Tensor:
    """Mirror along ``axis`` (-1: W, -2: H) the samples whose ``params["apply"]`` is set
    (all without a gate), in one pass over the batch: ``flip`` when every sample is
    mirrored, else one gather of whole rows (H) or of columns (W) by a per-sample index
    built on the host. No host synchronisation."""
    gate = params.get("apply")
    if gate is not None and not on_host(gate):  # compiling, or a gate on an accelerator
        flip = gate.to(frames.device, torch.bool).view(-1, 1, 1, 1, 1)
        return torch.where(flip, frames.flip(axis), frames)
    flags = None if gate is None else np.asarray(gate.tolist(), dtype=bool).reshape(frames.shape[0])
    if flags is None or flags.all():
        return frames.flip(axis)
    if not flags.any():
        return frames.clone(memory_format=torch.contiguous_format)
    b, t, p, h, w = frames.shape
    if axis == -2:
        # Rows of W values: out row (b, c, y) = in row (b, c, y or H - 1 - y).
        ys = np.where(flags[:, None], np.arange(h)[::-1], np.arange(h))  # (B, H)
        rows = (np.arange(b)[:, None, None] * (t * p * h) + np.arange(t * p)[None, :, None] * h + ys[:, None, :]).reshape(-1)
        out = frames.reshape(b * t * p * h, w).index_select(0, torch.from_numpy(rows).to(frames.device))
        return out.view(frames.shape)
    xs = np.where(flags[:, None], np.arange(w)[::-1], np.arange(w))  # (B, W)
    index = torch.from_numpy(xs).to(frames.device).view(b, 1, w).expand(b, t * p * h, w)
    return frames.reshape(b, t * p * h, w).gather(2, index).view(frames.shape)


class HorizontalFlip(EventTransform):
    """Mirror every frame left-right. Counts and dtype are kept.

    Args:
        p: probability that a sample is mirrored.

    Example:
        >>> HorizontalFlip()(torch.arange(4.).reshape(1, 2, 1, 2))[0, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """

    _gates_itself = True

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _flip(frames, params, -1)


class VerticalFlip(EventTransform):
    """Mirror every frame top-bottom. Counts and dtype are kept.

    Args:
        p: probability that a sample is mirrored.

    Example:
        >>> VerticalFlip()(torch.arange(4.).reshape(1, 2, 2, 1))[0, :, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """

    _gates_itself = True

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _flip(frames, params, -2)


class RandomHorizontalFlip(HorizontalFlip):
    """Mirror each sequence left-right with probability ``p`` (per sample; default 0.5).

    Example:
        >>> frames = torch.arange(8.).reshape(2, 1, 2, 1, 2)
        >>> RandomHorizontalFlip(p=1.0)(frames)[:, 0, 0, 0].tolist()
        [[1.0, 0.0], [5.0, 4.0]]
    """

    def __init__(self, p: float = 0.5) -> None:
        super().__init__(p=p)

    def _settings(self) -> str:
        return "" if self.p < 1 else "p=1.0"


class RandomVerticalFlip(VerticalFlip):
    """Mirror each sequence top-bottom with probability ``p`` (per sample; default 0.5).

    Example:
        >>> frames = torch.arange(8.).reshape(2, 1, 2, 2, 1)
        >>> RandomVerticalFlip(p=1.0)(frames)[:, 0, 0, :, 0].tolist()
        [[1.0, 0.0], [5.0, 4.0]]
    """

    def __init__(self, p: float = 0.5) -> None:
        super().__init__(p=p)

    def _settings(self) -> str:
        return "" if self.p < 1 else "p=1.0"
