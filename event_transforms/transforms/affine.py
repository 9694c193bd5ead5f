"""Warp modules: rotation, resize, the general affine warp, perspective and elastic warps.

:class:`Rotate`, :class:`RandomRotation`, :class:`Resize`, :class:`RandomResize`,
:class:`Affine` and :class:`RandomAffine` are one affine warp per sequence (every frame of
a sequence keeps the same orientation), about the event centroid by default; rotation and
resize are special cases of the affine warp. :class:`RandomPerspective` and
:class:`RandomElastic` warp all frames of a sequence with one homography or one smooth
displacement field. Bilinear sampling returns the
input dtype for float input and float32 for integer input; ``mode="nearest"`` keeps the
dtype. Values are moved or interpolated, never inspected.
"""

from __future__ import annotations

from typing import Any

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import INTERPOLATIONS, as_number, check_choice, check_pair, check_positive
from .._params import check_args
from .. import functional as F
from ..events.batch import EventBatch
from ..functional._dispatch import call_kernel
from ..functional.affine import AFFINE_SPEC, RESIZE_SPEC, ROTATE_SPEC
from ..functional.elastic import elastic_spec
from ..functional.perspective import PERSPECTIVE_SPEC
from ..functional._warp import Center, check_center, image_corners
from .base import EventTransform, Param, Params, choice, uniform

__all__ = [
    "Rotate",
    "RandomRotation",
    "Resize",
    "RandomResize",
    "Affine",
    "RandomAffine",
    "RandomPerspective",
    "RandomElastic",
]


def _zeros(batch: int, *size: int) -> Tensor:
    return torch.zeros(batch, *size, dtype=torch.float64)


class _Warp(EventTransform):
    """Shared setting of every warp: the interpolation mode."""

    def __init__(self, *, mode: str, p: float) -> None:
        super().__init__(p=p)
        self.mode = check_choice(mode, "mode", INTERPOLATIONS)


class _Affine(_Warp):
    """Shared settings of the affine modules (centre, interpolation mode) and their one warp."""

    def __init__(self, *, center: Center, mode: str, p: float) -> None:
        super().__init__(mode=mode, p=p)
        self.center = check_center(center)

    def _common(self) -> str:
        return f"center={self.center!r}, mode={self.mode!r}"


class _Rotation(_Affine):
    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return ROTATE_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.rotate, inputs, params["angle"], center=self.center, mode=self.mode)


class _Zoom(_Affine):
    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return RESIZE_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.resize, inputs, params["scale"], center=self.center, mode=self.mode)


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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"angle": torch.full((shape[0],), self.angle, dtype=torch.float64)}

    def _settings(self) -> str:
        return f"angle={self.angle}, {self._common()}"


class RandomRotation(_Rotation):
    """Rotate each sequence by its own random angle, the same for all its frames.

    Args:
        degrees: ``d`` for U(-d, d), or a ``(min, max)`` range, in degrees.
        center, mode: as in :class:`Rotate`.
        p: probability that a sample is rotated.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (each event moved to its
        nearest pixel).

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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"angle": uniform(*self.degrees, shape[0], generator)}

    def _settings(self) -> str:
        return f"degrees={self.degrees}, {self._common()}"


class Resize(_Zoom):
    """Zoom every frame by a fixed factor about the sequence's centre (H×W kept, zero margin).

    Args:
        scale: the paper's β = target size / source size (finite, > 0).
        center, mode: as in :class:`Rotate`.
        p: probability that a sample is resized.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (each event moved to its
        nearest pixel).

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5)
        >>> frames[0, 0, 2, 3] = 1.0
        >>> Resize(2.0, center="image")(frames)[0, 0, 2].tolist()
        [0.0, 0.0, 0.0, 0.5, 1.0]
    """

    def __init__(self, scale: float, *, center: Center = "mass", mode: str = "bilinear", p: float = 1.0) -> None:
        super().__init__(center=center, mode=mode, p=p)
        self.scale = check_positive(scale, "scale")

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
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

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (each event moved to its
        nearest pixel).

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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        if self.choices is not None:
            return {"scale": choice(self._choices, shape[0], generator)}
        assert self.scale is not None
        return {"scale": uniform(*self.scale, shape[0], generator)}

    def _settings(self) -> str:
        setting = f"choices={self.choices}" if self.choices is not None else f"scale={self.scale}"
        return f"{setting}, {self._common()}"


class _AffineWarp(_Affine):
    """Applies ``params`` angle (B,), scale (B,), translate (B, 2) and shear (B, 2)."""

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return AFFINE_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(
            F.affine, inputs, params["angle"], params["scale"], shear=params["shear"], translate=params["translate"],
            center=self.center, mode=self.mode,
        )


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

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (each event moved to its
        nearest pixel; no shear).

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
        # one value for every sample, checked against the operation's declaration
        settings = check_args("Affine", AFFINE_SPEC, 1, angle=angle, scale=scale, translate=translate, shear=shear)
        self.angle, self.scale = float(settings["angle"][0]), float(settings["scale"][0])
        self.translate = tuple(settings["translate"][0].tolist())
        self.shear = tuple(settings["shear"][0].tolist())

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
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

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (each event moved to its
        nearest pixel; no shear).

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
            fractions = check_args(type(self).__name__, {"translate": Param("float", shape=(2,))}, 1,
                                   translate=translate)["translate"][0].tolist()
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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
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


class RandomPerspective(_Warp):
    """Warp each sequence by its own random perspective (one homography for all its frames).

    Each corner of the frame moves inwards by up to ``distortion_scale`` times half the
    frame's height and width (torchvision's ``RandomPerspective``, drawn per sample on the
    CPU); the homography that takes the corners there warps all T·2 frames of the sequence
    at once (see :func:`~event_transforms.functional.perspective`). On an EventBatch each
    event moves by the homography to the nearest pixel; events warped off the sensor are
    dropped with a warning.

    Args:
        distortion_scale: in [0, 1): how far the corners may move (0: identity).
        mode: ``"bilinear"`` (float output: input dtype for floats, float32 for integers)
            or ``"nearest"`` (dtype kept).
        p: probability that a sample is warped.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).

    Example:
        >>> transform = RandomPerspective(0.3)
        >>> frames = torch.ones(2, 4, 2, 9, 11)
        >>> params = transform.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
        >>> params["corners"].shape, transform(frames, params=params).shape
        (torch.Size([2, 4, 2]), torch.Size([2, 4, 2, 9, 11]))
    """

    def __init__(self, distortion_scale: float = 0.5, *, mode: str = "bilinear", p: float = 1.0) -> None:
        super().__init__(mode=mode, p=p)
        self.distortion_scale = as_number(distortion_scale, "distortion_scale")
        if not 0 <= self.distortion_scale < 1:
            raise ValueError(f"distortion_scale must lie in [0, 1), got {distortion_scale!r}")

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b, _, _, height, width = shape
        reach = self.distortion_scale * torch.tensor([(height - 1) / 2, (width - 1) / 2], dtype=torch.float64)
        inwards = torch.tensor([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]], dtype=torch.float64)
        moves = uniform(0.0, 1.0, b * 8, generator).view(b, 4, 2) * reach * inwards
        return {"corners": image_corners(height, width) + moves}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return PERSPECTIVE_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.perspective, inputs, params["corners"].detach().to("cpu", torch.float64), self.mode)

    def _settings(self) -> str:
        return f"distortion_scale={self.distortion_scale}, mode={self.mode!r}"


class RandomElastic(_Warp):
    """Displace the pixels of each sequence by its own smooth random field (elastic distortion).

    Per sample, raw displacements U(-1, 1) per pixel and axis and a strength from
    ``alpha`` are drawn on the CPU; the field (``alpha`` times the displacements smoothed
    by a Gaussian of ``sigma`` pixels) is shared by all frames of the sequence, which are
    warped together (see :func:`~event_transforms.functional.elastic`; torchvision's
    ``ElasticTransform`` with one field per sequence). On an EventBatch each event moves by
    the inverse of the frames' map (fixed-point steps), to the nearest pixel; events warped
    off the sensor are dropped with a warning.

    Args:
        alpha: strength in pixels (>= 0), or a ``(min, max)`` range drawn per sample.
        sigma: smoothness of the field in pixels (> 0).
        mode: ``"bilinear"`` (float output: input dtype for floats, float32 for integers)
            or ``"nearest"`` (dtype kept).
        p: probability that a sample is warped.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).

    Example:
        >>> transform = RandomElastic(alpha=20.0, sigma=3.0)
        >>> frames = torch.ones(2, 4, 2, 9, 11)
        >>> params = transform.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
        >>> sorted(params), params["noise"].shape
        (['alpha', 'noise'], torch.Size([2, 2, 9, 11]))
    """

    def __init__(
        self,
        alpha: float | Sequence[float] = 50.0,
        sigma: float = 5.0,
        *,
        mode: str = "bilinear",
        p: float = 1.0,
    ) -> None:
        super().__init__(mode=mode, p=p)
        self.alpha = check_pair(alpha, "alpha", low=0.0, single=True)
        self.sigma = check_positive(sigma, "sigma")

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b, _, _, height, width = shape
        noise = uniform(-1.0, 1.0, b * 2 * height * width, generator).view(b, 2, height, width)
        return {"alpha": uniform(*self.alpha, b, generator), "noise": noise}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return elastic_spec(shape)

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        alpha = params["alpha"].detach().to("cpu", torch.float64)
        return call_kernel(F.elastic, inputs, params["noise"], alpha, self.sigma, self.mode)

    def _settings(self) -> str:
        return f"alpha={self.alpha}, sigma={self.sigma}, mode={self.mode!r}"
