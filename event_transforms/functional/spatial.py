"""Spatial kernels: rotation and resize about a centre (one affine warp per sequence), flips.

Rotation and resize fold the T·2 frames of a sequence into channels and call kornia's
``warp_affine`` once with a (B, 2, 3) matrix, so one sampling grid serves every frame of a
sequence (the grasp keeps its orientation) and no (B·T) grids are built.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from kornia.geometry.transform import get_rotation_matrix2d, warp_affine
from torch import Tensor

from .._validation import as_batch, check_frames, per_sample

__all__ = [
    "center_of_mass",
    "rotate",
    "resize",
    "horizontal_flip",
    "vertical_flip",
]

Center = str | Sequence[float] | Tensor

_MODES = ("bilinear", "nearest")


def center_of_mass(frames: Tensor) -> Tensor:
    """Event centroid of each sequence, both polarities and all frames, as (y, x).

    Computed in float64 whatever the input dtype; an empty sequence falls back to the
    image centre ((H - 1) / 2, (W - 1) / 2).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.

    Returns:
        float64 tensor ``(2,)`` for one sequence or ``(B, 2)`` for a batch, on the
        frames' device, in pixel coordinates (row, column).

    Example:
        >>> frames = torch.zeros(3, 2, 5, 7)
        >>> frames[0, 1, 1, 2] = 1.0
        >>> frames[2, 0, 3, 4] = 3.0
        >>> center_of_mass(frames)
        tensor([2.5000, 3.5000], dtype=torch.float64)
    """
    check_frames(frames, check_values=False)
    batch, unbatch = as_batch(frames)
    return unbatch(_center_of_mass(batch))


def _center_of_mass(batch: Tensor) -> Tensor:
    b, t, p, height, width = batch.shape
    # Sum the T·2 frames of each sequence with one batched matrix product (much faster
    # than a strided reduction); float32 is exact for whole counts below 2**24 per pixel,
    # float64 is used for float64 and 32/64-bit integer input.
    exact = batch.dtype in (torch.float64, torch.int32, torch.int64)
    acc = torch.float64 if exact else torch.float32
    ones = torch.ones(1, t * p, dtype=acc, device=batch.device)
    weight = torch.matmul(ones, batch.reshape(b, t * p, height * width).to(acc))
    weight = weight.reshape(b, height, width).to(torch.float64)
    total = weight.sum(dim=(1, 2))
    ys = torch.arange(height, dtype=torch.float64, device=batch.device)
    xs = torch.arange(width, dtype=torch.float64, device=batch.device)
    y = (weight.sum(dim=2) * ys).sum(dim=1)
    x = (weight.sum(dim=1) * xs).sum(dim=1)
    image = torch.tensor([(height - 1) / 2, (width - 1) / 2], dtype=torch.float64, device=batch.device)
    empty = (total == 0).unsqueeze(1)
    centroid = torch.stack([y, x], dim=1) / torch.where(total == 0, 1.0, total).unsqueeze(1)
    return torch.where(empty, image, centroid)


def _resolve_center(batch: Tensor, center: Center) -> Tensor:
    """(B, 2) float64 (y, x) centres on the batch's device."""
    b, _, _, height, width = batch.shape
    if isinstance(center, str):
        if center == "mass":
            return _center_of_mass(batch)
        if center == "image":
            return torch.tensor(
                [[(height - 1) / 2, (width - 1) / 2]], dtype=torch.float64, device=batch.device
            ).expand(b, 2)
        raise ValueError(f"center must be 'mass', 'image', (y, x) or a (B, 2) tensor, got {center!r}")
    value = torch.as_tensor(center, dtype=torch.float64)
    if value.shape == (2,):
        value = value.expand(b, 2)
    if value.shape != (b, 2):
        raise ValueError(
            f"center must be 'mass', 'image', (y, x) or a ({b}, 2) tensor, got shape {tuple(value.shape)}"
        )
    if not bool(torch.isfinite(value).all()):
        raise ValueError(f"center must be finite, got {value.tolist()}")
    return value.to(batch.device)


def _work_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if dtype == torch.float64 or (mode == "nearest" and dtype in (torch.int32, torch.int64)):
        return torch.float64  # exact for large counts
    return torch.float32


def _output_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if mode == "nearest" or dtype.is_floating_point:
        return dtype
    return torch.float32


def _affine(frames: Tensor, angle: Tensor, scale: Tensor, center: Center, mode: str) -> Tensor:
    """Rotate by ``angle`` degrees and zoom by ``scale`` about ``center``, per sample."""
    if mode not in _MODES:
        raise ValueError(f"mode must be one of {_MODES}, got {mode!r}")
    batch, unbatch = as_batch(frames)
    b, t, p, height, width = batch.shape
    out_dtype = _output_dtype(batch.dtype, mode)
    if batch.numel() == 0:
        return unbatch(batch.to(out_dtype, copy=True))
    work = _work_dtype(batch.dtype, mode)
    yx = _resolve_center(batch, center)
    matrix = get_rotation_matrix2d(
        yx.flip(1),  # kornia wants (x, y)
        angle.to(device=batch.device, dtype=torch.float64),
        scale.to(device=batch.device, dtype=torch.float64).unsqueeze(1).expand(b, 2),
    )
    folded = batch.reshape(b, t * p, height, width).to(work)
    warped = warp_affine(
        folded, matrix.to(work), (height, width), mode=mode, padding_mode="zeros", align_corners=True
    )
    return unbatch(warped.reshape(b, t, p, height, width).to(out_dtype))


def rotate(
    frames: Tensor,
    angle: float | Sequence[float] | Tensor,
    *,
    center: Center = "mass",
    mode: str = "bilinear",
) -> Tensor:
    """Rotate every frame of each sequence by the sequence's angle about its centre.

    Positive angles turn counter-clockwise on the displayed image (row 0 at the top), as
    in torchvision and kornia. Pixels that come from outside the frame are zero.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        angle: degrees, a number or one per sample ``(B,)``.
        center: ``"mass"`` (event centroid of the whole sequence, image centre when
            empty), ``"image"``, a ``(y, x)`` pair, or a ``(B, 2)`` tensor of pairs.
        mode: ``"bilinear"`` (counts are interpolated, totals change slightly) or
            ``"nearest"``.

    Returns:
        The rotated frames, same shape and device. ``bilinear`` returns the input dtype
        for float input and float32 for integer input; ``nearest`` keeps the dtype.

    Shape:
        ``(T, 2, H, W)`` -> ``(T, 2, H, W)``; ``(B, T, 2, H, W)`` -> same.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5, dtype=torch.int16)
        >>> frames[0, 1, 2, 4] = 7  # right of the centre
        >>> out = rotate(frames, 90.0, center="image", mode="nearest")
        >>> out.dtype, out[0, 1].nonzero().tolist(), int(out.sum())
        (torch.int16, [[0, 2]], 7)
    """
    check_frames(frames)
    angle_t = per_sample(angle, 1 if frames.dim() == 4 else frames.shape[0], "angle")
    if not bool(torch.isfinite(angle_t).all()):
        raise ValueError(f"angle must be finite, got {angle_t.tolist()}")
    return _affine(frames, angle_t, torch.ones_like(angle_t), center, mode)


def resize(
    frames: Tensor,
    scale: float | Sequence[float] | Tensor,
    *,
    center: Center = "mass",
    mode: str = "bilinear",
) -> Tensor:
    """Zoom each sequence by ``scale`` about its centre, keeping H×W (zero margin).

    ``scale`` is the paper's β = target object size / source object size: 1.25 makes a
    12 mm bolt's contact look like a 15 mm bolt's, 0.83 shrinks an 18 mm one. With
    bilinear sampling the total count scales by about β² as in image resizing; shrinking
    samples the source without anti-aliasing, as the paper's linear resize does.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        scale: zoom factor > 0, a number or one per sample ``(B,)``.
        center: ``"mass"``, ``"image"``, ``(y, x)`` or a ``(B, 2)`` tensor (see :func:`rotate`).
        mode: ``"bilinear"`` or ``"nearest"``.

    Returns:
        The resized frames, same shape and device; dtype as in :func:`rotate`.

    Shape:
        ``(T, 2, H, W)`` -> ``(T, 2, H, W)``; ``(B, T, 2, H, W)`` -> same.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5)
        >>> frames[0, 0, 2, 3] = 1.0  # one pixel right of the centre
        >>> resize(frames, 2.0, center="image")[0, 0, 2].tolist()
        [0.0, 0.0, 0.0, 0.5, 1.0]
    """
    check_frames(frames)
    scale_t = per_sample(scale, 1 if frames.dim() == 4 else frames.shape[0], "scale")
    if not bool((torch.isfinite(scale_t) & (scale_t > 0)).all()):
        raise ValueError(f"scale must be finite and > 0, got {scale_t.tolist()}")
    return _affine(frames, torch.zeros_like(scale_t), scale_t, center, mode)


def horizontal_flip(frames: Tensor) -> Tensor:
    """Mirror every frame left-right (along W). Counts and dtype are kept.

    Example:
        >>> horizontal_flip(torch.arange(4.).reshape(1, 2, 1, 2))[0, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    check_frames(frames)
    return frames.flip(-1)


def vertical_flip(frames: Tensor) -> Tensor:
    """Mirror every frame top-bottom (along H). Counts and dtype are kept.

    Example:
        >>> vertical_flip(torch.arange(4.).reshape(1, 2, 2, 1))[0, :, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    check_frames(frames)
    return frames.flip(-2)
