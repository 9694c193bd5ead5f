"""Geometry modules that move whole pixels: flips, translation (rolling), crops and sum-pooling.

Warps that interpolate (rotation, resize, the general affine warp) are in
:mod:`event_transforms.transforms.affine`. The flips mirror every frame of a sample
(counts and dtype kept). :class:`RandomTranslate` moves whole pixels with zero fill (Neuromorphic Data
Augmentation's rolling, without wrap-around). :class:`RandomCrop` and :class:`CenterCrop`
change the size by default, as torchvision's do; ``resize=True`` resizes the window back to
H×W. :class:`Downsample` sums blocks of pixels and changes the size.

Modules that change the size cannot leave some samples of a batch untouched, so they take
no ``p`` (wrap a size-keeping variant in :class:`~event_transforms.RandomApply` instead).
"""

from __future__ import annotations

from typing import Any

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import INTERPOLATIONS, as_number, check_choice, check_pair
from .._params import check_args
from .. import functional as F
from ..events.batch import EventBatch
from ..functional._dispatch import call_kernel
from ..functional.geometry import SPATIAL_JITTER_SPEC, TRANSLATE_SPEC, REMAINDERS, crop_spec, downsampled_size
from ..functional._frame_ops import factor_pair, frame_size
from .base import EventTransform, Param, Params, integers, seeds, uniform

__all__ = [
    "HorizontalFlip", "VerticalFlip", "RandomHorizontalFlip", "RandomVerticalFlip",
    "Translate", "RandomTranslate", "RandomCrop", "CenterCrop", "Downsample", "SpatialJitter",
]


class _Roll(EventTransform):
    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return TRANSLATE_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.translate, inputs, params["shift"])


class Translate(_Roll):
    """Move every frame by a fixed ``(dy, dx)`` of whole pixels, zero fill. Counts and dtype kept.

    Args:
        shift: ``(dy, dx)`` whole pixels (positive: down, right).
        p: probability that a sample is moved.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (whole sensor pixels).

    Example:
        >>> Translate((0, 1))(torch.ones(1, 2, 1, 3))[0, 0].tolist()
        [[0.0, 1.0, 1.0]]
    """

    def __init__(self, shift: Sequence[int], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.shift = tuple(check_args("Translate", TRANSLATE_SPEC, 1, shift=shift)["shift"][0].tolist())

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"shift": torch.tensor(self.shift, dtype=torch.int64).expand(shape[0], 2).clone()}

    def _settings(self) -> str:
        return f"shift={self.shift}"


class RandomTranslate(_Roll):
    """Move each sequence by its own whole-pixel shift, zero fill (rolling without wrap-around).

    Neuromorphic Data Augmentation's rolling; in a scene, a contact centre that
    moves between recordings. dy and dx are drawn uniformly among the integers in
    ``[-max_dy, max_dy]`` and ``[-max_dx, max_dx]``. Counts moved past the border are lost;
    the dtype is kept.

    Args:
        max_shift: ``m`` for both axes or ``(max_dy, max_dx)``, non-negative integers (pixels).
        p: probability that a sample is moved.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (whole sensor pixels).

    Example:
        >>> transform = RandomTranslate((2, 3))
        >>> transform.make_params((3, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))["shift"].tolist()
        [[2, 3], [1, 1], [0, 2]]
    """

    def __init__(self, max_shift: int | Sequence[int], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        if isinstance(max_shift, (Sequence, Tensor)) and not isinstance(max_shift, (str, bytes)):
            pair = tuple(check_args(type(self).__name__, {"max_shift": Param("int", shape=(2,))}, 1,
                                    max_shift=max_shift)["max_shift"][0].tolist())
        else:
            pair = (as_number(max_shift, "max_shift", integer=True),) * 2
        if min(pair) < 0:
            raise ValueError(f"max_shift must be non-negative, got {max_shift!r}")
        self.max_shift = pair

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
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
        self.size = frame_size(size, "size")
        self.resize = resize
        self.mode = check_choice(mode, "mode", INTERPOLATIONS)

    def _room(self, shape: Sequence[int]) -> tuple[int, int]:
        height, width = shape[-2:]
        if self.size[0] > height or self.size[1] > width:
            raise ValueError(f"{type(self).__name__}: size {self.size} does not fit frames of (H, W) = ({height}, {width})")
        return height - self.size[0], width - self.size[1]

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        self._room(shape)
        return crop_spec(shape, self.size)

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        if isinstance(inputs, EventBatch) and self.resize:
            raise ValueError(f"{type(self).__name__}(resize=True) interpolates frames; on events crop with resize=False")
        self._room(inputs.frame_shape if isinstance(inputs, EventBatch) else inputs.shape)
        return call_kernel(F.crop, inputs, params["top"], params["left"], self.size, self.resize, self.mode)

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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        rows, cols = self._room(shape)
        return {"top": integers(rows + 1, shape[0], generator), "left": integers(cols + 1, shape[0], generator)}


class CenterCrop(_Crop):
    """Cut the central window of ``size`` (top-left corner rounded down, as in torchvision).

    Args:
        size, resize, mode, p: as in :class:`RandomCrop`.

    Shape:
        ``(B, T, 2, H, W)`` -> ``(B, T, 2, h, w)``, or unchanged with ``resize=True``.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` whose sensor is the crop
        (``resize=False``).

    Example:
        >>> CenterCrop(3)(torch.arange(25.).reshape(1, 1, 5, 5).expand(1, 2, 5, 5))[0, 0].tolist()
        [[6.0, 7.0, 8.0], [11.0, 12.0, 13.0], [16.0, 17.0, 18.0]]
    """

    def __init__(self, size: int | Sequence[int], *, resize: bool = False, mode: str = "bilinear", p: float = 1.0) -> None:
        super().__init__(size, resize=resize, mode=mode, p=p)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        rows, cols = self._room(shape)
        b = shape[0]
        return {"top": torch.full((b,), rows // 2, dtype=torch.int64), "left": torch.full((b,), cols // 2, dtype=torch.int64)}


class Downsample(EventTransform):
    """Sum each ``fy × fx`` block of pixels into one; counts conserved, dtype kept.

    The paper's 2×2 pooling of its 140×150 crop to 70×75. See
    :func:`~event_transforms.functional.downsample` for the remainder rule: ``"drop"``
    (default) discards the last ``H mod fy`` rows and ``W mod fx`` columns, ``"keep"``
    sums them into a partial last block. On an EventBatch each event moves to its block and
    the batch's sensor becomes ``(H', W')`` (binned, equal to the frame result).

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
        self.factor = factor_pair(factor)
        self.remainder = check_choice(remainder, "remainder", REMAINDERS)

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.downsample, inputs, self.factor, self.remainder)

    def output_shape(self, shape: torch.Size) -> torch.Size:
        return torch.Size((*shape[:-2], *downsampled_size(shape[-2], shape[-1], self.factor, self.remainder)))

    def _settings(self) -> str:
        return f"factor={self.factor}, remainder={self.remainder!r}"


class HorizontalFlip(EventTransform):
    """Mirror every frame left-right. Counts and dtype are kept.

    Args:
        p: probability that a sample is mirrored.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

    Example:
        >>> HorizontalFlip()(torch.arange(4.).reshape(1, 2, 1, 2))[0, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """

    gates_in_kernel = True  # the kernel takes the gate as its flags: no gather, no put-back

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.horizontal_flip, inputs, params.get("apply"))

class VerticalFlip(EventTransform):
    """Mirror every frame top-bottom. Counts and dtype are kept.

    Args:
        p: probability that a sample is mirrored.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

    Example:
        >>> VerticalFlip()(torch.arange(4.).reshape(1, 2, 2, 1))[0, :, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """

    gates_in_kernel = True  # the kernel takes the gate as its flags: no gather, no put-back

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.vertical_flip, inputs, params.get("apply"))

class RandomHorizontalFlip(HorizontalFlip):
    """Mirror each sequence left-right with probability ``p`` (per sample; default 0.5).

    Args:
        p: probability that a sample is mirrored (default 0.5).

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

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

    Args:
        p: probability that a sample is mirrored (default 0.5).

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

    Example:
        >>> frames = torch.arange(8.).reshape(2, 1, 2, 2, 1)
        >>> RandomVerticalFlip(p=1.0)(frames)[:, 0, 0, :, 0].tolist()
        [[1.0, 0.0], [5.0, 4.0]]
    """

    def __init__(self, p: float = 0.5) -> None:
        super().__init__(p=p)

    def _settings(self) -> str:
        return "" if self.p < 1 else "p=1.0"


# --------------------------------------------------------------------------- events only


class SpatialJitter(EventTransform):
    """Move every event by Gaussian noise of ``sigma`` pixels in x and y (rounded to whole pixels).

    Events only (frames raise a named ``TypeError``); see
    :func:`~event_transforms.functional.spatial_jitter`. ``sigma`` is drawn per sample from
    ``(min, max)`` (a number is fixed); the noise comes from the sample's own seed
    (``params["seed"]``), so a sample alone equals the sample in a batch. Events jittered
    off the sensor are dropped when binned. Sync-free.

    Args:
        sigma: standard deviation in pixels, or a ``(min, max)`` range.
        p: probability that a sample is jittered.

    Shape:
        An :class:`~event_transforms.EventBatch` of B streams in, an ``EventBatch`` out:
        the same streams and events (moved). Frames raise ``TypeError`` (an event-only augmentation).

    Example:
        >>> import event_transforms as et
        >>> batch = et.EventBatch.from_streams([torch.tensor([[5, 5, 0, 1]] * 4)], sensor_size=(10, 10))
        >>> out = et.SpatialJitter(1.0)(batch, generator=torch.Generator().manual_seed(0))
        >>> out.x.tolist(), out.y.tolist()
        ([5, 6, 6, 4], [3, 4, 5, 5])
    """

    def __init__(self, sigma: float | Sequence[float] = 1.0, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        low, high = check_pair(sigma, "sigma", low=0.0, single=True)
        self.sigma = (float(low), float(high))

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"sigma": uniform(*self.sigma, shape[0], generator), "seed": seeds(shape[0], generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return SPATIAL_JITTER_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.spatial_jitter, inputs, params["sigma"], params["seed"])

    def _settings(self) -> str:
        return f"sigma={self.sigma}"
