"""Geometry modules: a random affine warp, translation (rolling), crops and sum-pooling.

:class:`RandomAffine` draws rotation, scale, translation and shear per sequence and warps
all its frames with one matrix (rotation and resize are its special cases).
:class:`RandomTranslate` moves whole pixels with zero fill (Neuromorphic Data
Augmentation's rolling, without wrap-around). :class:`RandomCrop` and :class:`CenterCrop`
change the size by default, as torchvision's do; ``resize=True`` resizes the window back to
H×W. :class:`Downsample` sums blocks of pixels and changes the size.

Modules that change the size cannot leave some samples of a batch untouched, so they take
no ``p`` (wrap a size-keeping variant in :class:`~event_transforms.RandomApply` instead).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import INTERPOLATIONS, as_number, check_choice, check_pair
from ..functional.geometry import (
    REMAINDERS,
    _affine,
    _crop,
    _downsample,
    _factor,
    _pairs,
    _size,
    _translate,
    downsampled_size,
)
from ..functional.spatial import Center, _check_center
from .base import EventTransform, Param, Params, integers, uniform

__all__ = ["Affine", "RandomAffine", "Translate", "RandomTranslate", "RandomCrop", "CenterCrop", "Downsample"]


def _zeros(batch: int, *size: int) -> Tensor:
    return torch.zeros(batch, *size, dtype=torch.float64)


class _AffineWarp(EventTransform):
    """Applies ``params`` angle (B,), scale (B,), translate (B, 2) and shear (B, 2)."""

    def __init__(self, *, center: Center, mode: str, p: float) -> None:
        super().__init__(p=p)
        self.center = _check_center(center)
        self.mode = check_choice(mode, "mode", INTERPOLATIONS)

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {
            "angle": Param("float"), "scale": Param("float", low=float.fromhex("0x1p-1022")),
            "translate": Param("float", shape=(2,)), "shear": Param("float", shape=(2,)),
        }

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _affine(
            frames, params["angle"], params["scale"], params["translate"], params["shear"], self.center, self.mode
        )

    def _common(self) -> str:
        return f"center={self.center!r}, mode={self.mode!r}"


class Affine(_AffineWarp):
    """A fixed affine warp of every frame about the sequence's centre.

    Args:
        angle: degrees, counter-clockwise on the displayed image.
        translate: ``(dy, dx)`` pixels.
        scale: zoom factor > 0.
        shear: ``(x, y)`` shear angles in degrees, each in (-90, 90).
        center: ``"mass"`` (event centroid of the sequence), ``"image"`` or ``(y, x)``.
        mode: ``"bilinear"`` (float output: input dtype for floats, float32 for integers)
            or ``"nearest"`` (dtype kept).
        p: probability that a sample is warped.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5)
        >>> frames[0, 1, 2, 4] = 1.0
        >>> Affine(angle=90.0, center="image")(frames)[0, 1].nonzero().tolist()
        [[0, 2]]
    """

    def __init__(
        self,
        *,
        angle: float = 0.0,
        translate: Sequence[float] = (0.0, 0.0),
        scale: float = 1.0,
        shear: Sequence[float] = (0.0, 0.0),
        center: Center = "mass",
        mode: str = "bilinear",
        p: float = 1.0,
    ) -> None:
        super().__init__(center=center, mode=mode, p=p)
        self.angle = as_number(angle, "angle")
        self.scale = as_number(scale, "scale")
        if self.scale <= 0:
            raise ValueError(f"scale must be > 0, got {scale!r}")
        self.translate = tuple(_pairs(translate, 1, "translate")[0].tolist())
        self.shear = tuple(_pairs(shear, 1, "shear")[0].tolist())
        if max(abs(s) for s in self.shear) >= 90:
            raise ValueError(f"shear must lie in (-90, 90) degrees, got {shear!r}")

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        b = shape[0]
        return {
            "angle": torch.full((b,), self.angle, dtype=torch.float64),
            "scale": torch.full((b,), self.scale, dtype=torch.float64),
            "translate": torch.tensor(self.translate, dtype=torch.float64).expand(b, 2).clone(),
            "shear": torch.tensor(self.shear, dtype=torch.float64).expand(b, 2).clone(),
        }

    def _settings(self) -> str:
        return f"angle={self.angle}, translate={self.translate}, scale={self.scale}, shear={self.shear}, {self._common()}"


class RandomAffine(_AffineWarp):
    """Warp each sequence by its own random rotation, scale, translation and shear.

    Every parameter is drawn per sample on the CPU and shared by all frames of the
    sample; one ``grid_sample`` serves the whole batch (the warp of rotation and resize). Leave a range at its default to
    keep that part fixed.

    Args:
        degrees: ``d`` for U(-d, d), or a ``(min, max)`` range, in degrees.
        translate: ``(fy, fx)`` largest shifts as fractions of H and W: dy ~ U(-fy·H, fy·H),
            dx ~ U(-fx·W, fx·W) (torchvision's meaning, in (H, W) order); ``None`` for none.
        scale: ``(min, max)`` zoom range (> 0); ``None`` for 1.
        shear: ``s`` for an x shear in U(-s, s), a ``(min, max)`` x range, or
            ``(xmin, xmax, ymin, ymax)`` for both axes, in degrees inside (-90, 90);
            ``None`` for none.
        center, mode: as in :class:`Affine`.
        p: probability that a sample is warped.

    Example:
        >>> transform = RandomAffine(10.0, translate=(0.1, 0.1), scale=(0.9, 1.1), shear=5.0)
        >>> params = transform.make_params((2, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))
        >>> sorted(params), params["translate"].shape
        (['angle', 'scale', 'shear', 'translate'], torch.Size([2, 2]))
    """

    def __init__(
        self,
        degrees: float | Sequence[float] = 0.0,
        *,
        translate: Sequence[float] | None = None,
        scale: Sequence[float] | None = None,
        shear: float | Sequence[float] | None = None,
        center: Center = "mass",
        mode: str = "bilinear",
        p: float = 1.0,
    ) -> None:
        super().__init__(center=center, mode=mode, p=p)
        self.degrees = check_pair(degrees, "degrees", symmetric=True)
        self.translate = None
        if translate is not None:
            fractions = _pairs(translate, 1, "translate")[0].tolist()
            if not all(0 <= f <= 1 for f in fractions):
                raise ValueError(f"translate fractions must lie in [0, 1], got {translate!r}")
            self.translate = tuple(fractions)
        self.scale = None if scale is None else check_pair(scale, "scale")
        if self.scale is not None and self.scale[0] <= 0:
            raise ValueError(f"scale must be > 0, got {scale!r}")
        self.shear = None
        if shear is not None:
            if isinstance(shear, Sequence) and len(shear) == 4:
                ranges = check_pair(shear[:2], "shear", low=-89.999, high=89.999) + check_pair(
                    shear[2:], "shear", low=-89.999, high=89.999
                )
            else:
                ranges = check_pair(shear, "shear", symmetric=True, low=-89.999, high=89.999) + (0.0, 0.0)
            self.shear = ranges

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        b, _, _, height, width = shape
        params: Params = {"angle": uniform(*self.degrees, b, generator)}
        params["scale"] = torch.ones(b, dtype=torch.float64) if self.scale is None else uniform(*self.scale, b, generator)
        if self.translate is None:
            params["translate"] = _zeros(b, 2)
        else:
            fy, fx = self.translate
            params["translate"] = torch.stack(
                [uniform(-fy * height, fy * height, b, generator), uniform(-fx * width, fx * width, b, generator)], 1
            )
        if self.shear is None:
            params["shear"] = _zeros(b, 2)
        else:
            x0, x1, y0, y1 = self.shear
            params["shear"] = torch.stack([uniform(x0, x1, b, generator), uniform(y0, y1, b, generator)], 1)
        return params

    def _settings(self) -> str:
        return (
            f"degrees={self.degrees}, translate={self.translate}, scale={self.scale}, shear={self.shear}, "
            f"{self._common()}"
        )


class _Roll(EventTransform):
    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"shift": Param("int", shape=(2,))}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _translate(frames, params["shift"])


class Translate(_Roll):
    """Move every frame by a fixed ``(dy, dx)`` of whole pixels, zero fill. Counts and dtype kept.

    Example:
        >>> Translate((0, 1))(torch.ones(1, 2, 1, 3))[0, 0].tolist()
        [[0.0, 1.0, 1.0]]
    """

    def __init__(self, shift: Sequence[int], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.shift = tuple(_pairs(shift, 1, "shift", dtype=torch.int64)[0].tolist())

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"shift": torch.tensor(self.shift, dtype=torch.int64).expand(shape[0], 2).clone()}

    def _settings(self) -> str:
        return f"shift={self.shift}"


class RandomTranslate(_Roll):
    """Move each sequence by its own whole-pixel shift, zero fill (rolling without wrap-around).

    Neuromorphic Data Augmentation's rolling; in a tactile scene, a contact centre that
    moves between recordings. dy and dx are drawn uniformly among the integers in
    ``[-max_dy, max_dy]`` and ``[-max_dx, max_dx]``. Counts moved past the border are lost;
    the dtype is kept.

    Args:
        max_shift: ``m`` for both axes or ``(max_dy, max_dx)``, non-negative integers (pixels).
        p: probability that a sample is moved.

    Example:
        >>> transform = RandomTranslate((2, 3))
        >>> transform.make_params((3, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))["shift"].tolist()
        [[2, 3], [1, 1], [0, 2]]
    """

    def __init__(self, max_shift: int | Sequence[int], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        if isinstance(max_shift, (Sequence, Tensor)) and not isinstance(max_shift, (str, bytes)):
            pair = tuple(_pairs(max_shift, 1, "max_shift", dtype=torch.int64)[0].tolist())
        else:
            pair = (as_number(max_shift, "max_shift", integer=True),) * 2
        if min(pair) < 0:
            raise ValueError(f"max_shift must be non-negative, got {max_shift!r}")
        self.max_shift = pair

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        b = shape[0]
        my, mx = self.max_shift
        dy = integers(2 * my + 1, b, generator) - my
        dx = integers(2 * mx + 1, b, generator) - mx
        return {"shift": torch.stack([dy, dx], 1)}

    def _settings(self) -> str:
        return f"max_shift={self.max_shift}"


class _Crop(EventTransform):
    """Crops ``params`` top/left (B,) int64 to ``size``; resizes back if ``resize``."""

    def __init__(self, size: int | Sequence[int], *, resize: bool, mode: str, p: float) -> None:
        super().__init__(p=p)
        if not isinstance(resize, bool):
            raise TypeError(f"resize must be a bool, got {resize!r}")
        if not resize and self.p < 1:
            raise ValueError(
                f"p < 1 needs resize=True: a batch cannot mix cropped and uncropped sizes, got p={p!r}"
            )
        self.size = _size(size, "size")
        self.resize = resize
        self.mode = check_choice(mode, "mode", INTERPOLATIONS)

    def _room(self, shape: Sequence[int]) -> tuple[int, int]:
        height, width = shape[-2:]
        if self.size[0] > height or self.size[1] > width:
            raise ValueError(f"{type(self).__name__}: size {self.size} does not fit frames of (H, W) = ({height}, {width})")
        return height - self.size[0], width - self.size[1]

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        rows, cols = self._room(shape)
        return {"top": Param("int", low=0, high=rows), "left": Param("int", low=0, high=cols)}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        self._room(frames.shape)
        return _crop(frames, params["top"], params["left"], self.size, self.resize, self.mode)

    def output_shape(self, shape: torch.Size) -> torch.Size:
        return shape if self.resize else torch.Size((*shape[:-2], *self.size))

    def _settings(self) -> str:
        setting = f"size={self.size}, resize={self.resize}"
        return f"{setting}, mode={self.mode!r}" if self.resize else setting


class RandomCrop(_Crop):
    """Cut a window of ``size`` at a random place of each sequence (the same for all its frames).

    By default the output has the window's size, as torchvision's ``RandomCrop``;
    ``resize=True`` resizes the window back to H×W (like ``RandomResizedCrop`` with a fixed
    window), interpolating the values (float32 for integer input under ``bilinear``).

    Args:
        size: ``n`` or ``(h, w)``, at most the frames' (H, W).
        resize: resize the window back to H×W (keeps the shape; allows ``p < 1``).
        mode: ``"bilinear"`` or ``"nearest"``, for ``resize=True``.
        p: probability that a sample is cropped (``resize=True`` only).

    Shape:
        ``(B, T, 2, H, W)`` -> ``(B, T, 2, h, w)``, or unchanged with ``resize=True``.

    Example:
        >>> RandomCrop((4, 5))(torch.ones(3, 6, 2, 17, 11), generator=torch.Generator().manual_seed(0)).shape
        torch.Size([3, 6, 2, 4, 5])
    """

    def __init__(self, size: int | Sequence[int], *, resize: bool = False, mode: str = "bilinear", p: float = 1.0) -> None:
        super().__init__(size, resize=resize, mode=mode, p=p)

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        rows, cols = self._room(shape)
        return {"top": integers(rows + 1, shape[0], generator), "left": integers(cols + 1, shape[0], generator)}


class CenterCrop(_Crop):
    """Cut the central window of ``size`` (top-left corner rounded down, as in torchvision).

    Args:
        size, resize, mode, p: as in :class:`RandomCrop`.

    Example:
        >>> CenterCrop(3)(torch.arange(25.).reshape(1, 1, 5, 5).expand(1, 2, 5, 5))[0, 0].tolist()
        [[6.0, 7.0, 8.0], [11.0, 12.0, 13.0], [16.0, 17.0, 18.0]]
    """

    def __init__(self, size: int | Sequence[int], *, resize: bool = False, mode: str = "bilinear", p: float = 1.0) -> None:
        super().__init__(size, resize=resize, mode=mode, p=p)

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        rows, cols = self._room(shape)
        b = shape[0]
        return {"top": torch.full((b,), rows // 2, dtype=torch.int64), "left": torch.full((b,), cols // 2, dtype=torch.int64)}


class Downsample(EventTransform):
    """Sum each ``fy × fx`` block of pixels into one; counts conserved, dtype kept.

    The paper's 2×2 pooling of its 140×150 crop to 70×75. See
    :func:`~event_transforms.functional.downsample` for the remainder rule: ``"drop"``
    (default) discards the last ``H mod fy`` rows and ``W mod fx`` columns, ``"keep"``
    sums them into a partial last block.

    Args:
        factor: ``k`` or ``(fy, fx)``.
        remainder: ``"drop"`` or ``"keep"``.

    Shape:
        ``(B, T, 2, H, W)`` -> ``(B, T, 2, H', W')``.

    Example:
        >>> Downsample(2)(torch.ones(36, 2, 140, 150, dtype=torch.int16)).shape
        torch.Size([36, 2, 70, 75])
    """

    def __init__(self, factor: int | Sequence[int], *, remainder: str = "drop") -> None:
        super().__init__()
        self.factor = _factor(factor)
        self.remainder = check_choice(remainder, "remainder", REMAINDERS)

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _downsample(frames, self.factor, self.remainder)

    def output_shape(self, shape: torch.Size) -> torch.Size:
        return torch.Size((*shape[:-2], *downsampled_size(shape[-2], shape[-1], self.factor, self.remainder)))

    def _settings(self) -> str:
        return f"factor={self.factor}, remainder={self.remainder!r}"
