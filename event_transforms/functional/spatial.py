"""Spatial kernels: rotation and resize about a centre (one affine warp per sequence), flips.

Rotation and resize fold the T·2 frames of a sequence into channels and call kornia's
``warp_affine`` once with a (B, 2, 3) matrix, so one sampling grid serves every frame of a
sequence (the grasp keeps its orientation) and no (B·T) grids are built.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import INTERPOLATIONS, as_batch, check_choice, check_frames, describe, per_sample

__all__ = [
    "center_of_mass",
    "rotate",
    "resize",
    "horizontal_flip",
    "vertical_flip",
]

Center = str | Sequence[float] | Tensor


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
    batch, unbatch = as_batch(check_frames(frames))
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
    ys = torch.arange(height, dtype=torch.float64, device=batch.device)
    xs = torch.arange(width, dtype=torch.float64, device=batch.device)
    rows = weight.sum(dim=2)
    total = rows.sum(dim=1, keepdim=True)
    moments = torch.stack([rows @ ys, weight.sum(dim=1) @ xs], dim=1)  # (B, 2)
    image = torch.tensor([(height - 1) / 2, (width - 1) / 2], dtype=torch.float64, device=batch.device)
    return torch.where(total > 0, moments / total.clamp_min(1e-300), image)


def _check_center(center: object, batch: int | None = None) -> Center:
    """``"mass"``, ``"image"``, a ``(y, x)`` pair, or (with ``batch``) a ``(B, 2)`` tensor."""
    if isinstance(center, str):
        return check_choice(center, "center", ("mass", "image"))
    try:
        value = torch.as_tensor(center, dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"center must be 'mass', 'image' or (y, x), got {center!r}") from None
    shapes = [(2,)] if batch is None else [(2,), (batch, 2)]
    if tuple(value.shape) not in shapes:
        expected = "'mass', 'image' or (y, x)" + ("" if batch is None else f" or a ({batch}, 2) tensor")
        raise ValueError(f"center must be {expected}, got {describe(center)}")
    if not bool(value.isfinite().all()):
        raise ValueError(f"center must be finite, got {describe(center)}")
    return center


def _resolve_center(batch: Tensor, center: Center) -> Tensor:
    """(B, 2) float64 (y, x) centres on the batch's device."""
    b, _, _, height, width = batch.shape
    if isinstance(center, str):
        if center == "mass":
            return _center_of_mass(batch)
        center = ((height - 1) / 2, (width - 1) / 2)
    value = torch.as_tensor(center, dtype=torch.float64).to(batch.device)
    return value.expand(b, 2) if value.dim() == 1 else value


def _work_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if dtype == torch.float64 or (mode == "nearest" and dtype in (torch.int32, torch.int64)):
        return torch.float64  # exact for large counts
    return torch.float32


def _output_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if mode == "nearest" or dtype.is_floating_point:
        return dtype
    return torch.float32


def _affine(batch: Tensor, angle: Tensor, scale: Tensor, center: Center, mode: str) -> Tensor:
    """Rotate by ``angle`` degrees and zoom by ``scale`` about ``center``, per sample.

    ``angle`` and ``scale`` are (B,) float64 CPU tensors. The forward map of sample b is
    ``dst = s R(θ) (src - c) + c`` (OpenCV's and kornia's convention); its 2×3 matrix is
    built from host numbers and the device centre, and one kornia ``warp_affine`` samples
    all T·2 frames of a sequence, folded into channels.
    """
    b, t, p, height, width = batch.shape
    out_dtype = _output_dtype(batch.dtype, mode)
    if batch.numel() == 0:
        return batch.to(out_dtype, copy=True)
    from kornia.geometry.transform import warp_affine  # imported on first use: keeps imports light

    work = _work_dtype(batch.dtype, mode)
    radians = torch.deg2rad(angle.to(torch.float64))
    alpha = (scale * torch.cos(radians)).to(batch.device, work)  # (B,)
    beta = (scale * torch.sin(radians)).to(batch.device, work)
    yx = _resolve_center(batch, center).to(work)
    cy, cx = yx[:, 0], yx[:, 1]
    matrix = torch.stack(
        [
            torch.stack([alpha, beta, (1 - alpha) * cx - beta * cy], dim=1),
            torch.stack([-beta, alpha, beta * cx + (1 - alpha) * cy], dim=1),
        ],
        dim=1,
    )  # (B, 2, 3)
    folded = batch.reshape(b, t * p, height, width).to(work)
    warped = warp_affine(folded, matrix, (height, width), mode=mode, padding_mode="zeros", align_corners=True)
    return warped.reshape(b, t, p, height, width).to(out_dtype)


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
    batch, unbatch = as_batch(check_frames(frames))
    angle_t = per_sample(angle, batch.shape[0], "angle")
    if not bool(angle_t.isfinite().all()):
        raise ValueError(f"angle must be finite, got {describe(angle)}")
    check_choice(mode, "mode", INTERPOLATIONS)
    center = _check_center(center, batch.shape[0])
    return unbatch(_affine(batch, angle_t, torch.ones_like(angle_t), center, mode))


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
    batch, unbatch = as_batch(check_frames(frames))
    scale_t = per_sample(scale, batch.shape[0], "scale")
    if not bool((scale_t.isfinite() & (scale_t > 0)).all()):
        raise ValueError(f"scale must be finite and > 0, got {describe(scale)}")
    check_choice(mode, "mode", INTERPOLATIONS)
    center = _check_center(center, batch.shape[0])
    return unbatch(_affine(batch, torch.zeros_like(scale_t), scale_t, center, mode))


def horizontal_flip(frames: Tensor) -> Tensor:
    """Mirror every frame left-right (along W). Counts and dtype are kept.

    Example:
        >>> horizontal_flip(torch.arange(4.).reshape(1, 2, 1, 2))[0, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    return check_frames(frames).flip(-1)


def vertical_flip(frames: Tensor) -> Tensor:
    """Mirror every frame top-bottom (along H). Counts and dtype are kept.

    Example:
        >>> vertical_flip(torch.arange(4.).reshape(1, 2, 2, 1))[0, :, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    return check_frames(frames).flip(-2)
