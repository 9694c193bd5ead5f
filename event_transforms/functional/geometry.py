"""Geometry kernels that move whole pixels: flips, integer translation (rolling), crops, sum-pooling.

Warps that interpolate (rotation, resize, the general affine warp) are in
:mod:`event_transforms.functional.affine`. :func:`horizontal_flip` and
:func:`vertical_flip` mirror every frame, :func:`translate` moves whole pixels (counts and
dtype kept), :func:`crop` cuts a window and optionally resizes it back to H×W, and
:func:`downsample` sums k×k blocks (the paper's "adding the closest neighbourhoods").
None of them reads the values, so none waits
for an accelerator, except :func:`downsample` on 8/16-bit integer frames, which checks once
that the block sums fit the dtype. Per-sample parameters are CPU tensors; they reach the
frames' device by non-blocking copies (the same holds for the polarity, mixing and cleaning
kernels).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import INTERPOLATIONS, as_batch, as_number, check_choice, check_frames, describe, per_sample, per_sample_pairs
from .affine import _output_dtype, _work_dtype

__all__ = ["horizontal_flip", "vertical_flip", "translate", "crop", "center_crop", "downsample"]

Scalars = float | Sequence[float] | Tensor
Pairs = Sequence[float] | Tensor
#: How :func:`downsample` treats the rows and columns left over when H or W is not a multiple.
REMAINDERS = ("drop", "keep")
_NARROW_INTEGERS = (torch.uint8, torch.int8, torch.int16)


# --------------------------------------------------------------------------- translate


def _translate(batch: Tensor, shift: Tensor) -> Tensor:
    """:func:`translate` on a batch with a (B, 2) int64 CPU ``shift`` of (dy, dx)."""
    b, t, p, height, width = batch.shape
    if batch.numel() == 0:
        return batch.clone()
    device = batch.device
    shift = shift.to(device, non_blocking=True)
    rows = torch.arange(height, device=device) - shift[:, :1]  # (B, H) source rows
    cols = torch.arange(width, device=device) - shift[:, 1:]  # (B, W)
    valid = ((rows >= 0) & (rows < height)).unsqueeze(2) & ((cols >= 0) & (cols < width)).unsqueeze(1)
    source = rows.clamp(0, height - 1).unsqueeze(2) * width + cols.clamp(0, width - 1).unsqueeze(1)
    return _gather_pixels(batch, source, valid)


def _gather_pixels(batch: Tensor, source: Tensor, valid: Tensor | None = None) -> Tensor:
    """``out[b, ..., i, j] = batch[b, ..., source[b, i, j]]`` (flat pixel index), zero where not ``valid``.

    One gather over the flattened pixels serves all T·2 frames of a sequence (twice as
    fast on the CPU as a gather per axis).
    """
    b, t, p = batch.shape[:3]
    h, w = source.shape[1:]
    flat = batch.reshape(b, t * p, batch.shape[-2] * batch.shape[-1])
    out = flat.gather(2, source.reshape(b, 1, h * w).expand(b, t * p, h * w))
    if valid is not None:
        out.masked_fill_(~valid.reshape(b, 1, h * w), 0)
    return out.view(b, t, p, h, w)


def translate(frames: Tensor, shift: Pairs) -> Tensor:
    """Move every frame of each sequence by whole pixels, filling the vacated border with zeros.

    Neuromorphic Data Augmentation's "rolling", without the wrap-around: events moved past
    the border are dropped, so the count can only fall. Counts and dtype are kept.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        shift: ``(dy, dx)`` integer pixels (down, right), or a ``(B, 2)`` integer tensor.

    Returns:
        The moved frames, same shape, dtype and device.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - shift: a pair or ``(B, 2)``.

    Example:
        >>> frames = torch.arange(1, 7).reshape(1, 1, 2, 3).expand(1, 2, 2, 3)
        >>> translate(frames, (1, -1))[0, 0].tolist()
        [[0, 0, 0], [2, 3, 0]]
    """
    batch, unbatch = as_batch(check_frames(frames))
    return unbatch(_translate(batch, per_sample_pairs(shift, batch.shape[0], "shift", dtype=torch.int64)))


# --------------------------------------------------------------------------- crop


def _size(value: object, name: str) -> tuple[int, int]:
    """``n`` or ``(h, w)`` positive integers as (h, w)."""
    if isinstance(value, (Sequence, Tensor)) and not isinstance(value, (str, bytes)):
        if len(value) != 2:
            raise ValueError(f"{name} must be a positive integer or an (h, w) pair, got {describe(value)}")
        pair = tuple(as_number(v, name, integer=True) for v in value)
    else:
        number = as_number(value, name, integer=True)
        pair = (number, number)
    if min(pair) < 1:
        raise ValueError(f"{name} must be positive, got {describe(value)}")
    return pair  # type: ignore[return-value]


def _crop(batch: Tensor, top: Tensor, left: Tensor, size: tuple[int, int], resize: bool, mode: str) -> Tensor:
    """Crop ``size`` at per-sample (B,) int64 CPU ``top``/``left``; optionally resize back to H×W."""
    b, t, p, height, width = batch.shape
    h, w = size
    device = batch.device
    rows = top.to(device, non_blocking=True).unsqueeze(1) + torch.arange(h, device=device)  # (B, h)
    cols = left.to(device, non_blocking=True).unsqueeze(1) + torch.arange(w, device=device)  # (B, w)
    out = _gather_pixels(batch, rows.unsqueeze(2) * width + cols.unsqueeze(1))
    if not resize:
        return out
    out_dtype = _output_dtype(batch.dtype, mode)
    if out.numel() == 0:
        return batch.new_zeros(batch.shape, dtype=out_dtype)
    work = _work_dtype(batch.dtype, mode)
    folded = out.reshape(b, t * p, h, w).to(work)
    if mode == "bilinear":
        grown = torch.nn.functional.interpolate(folded, size=(height, width), mode="bilinear", align_corners=False)
    else:
        grown = torch.nn.functional.interpolate(folded, size=(height, width), mode="nearest")
    return grown.reshape(b, t, p, height, width).to(out_dtype)


def _check_corner(value: Scalars, batch: int, name: str, room: int) -> Tensor:
    corner = per_sample(value, batch, name, dtype=torch.int64)
    if corner.numel() and bool(((corner < 0) | (corner > room)).any()):
        raise ValueError(f"{name} must lie in [0, {room}] for the crop to fit, got {describe(value)}")
    return corner


def _check_fits(size: tuple[int, int], height: int, width: int) -> None:
    if size[0] > height or size[1] > width:
        raise ValueError(f"size must fit in the frames' (H, W) = ({height}, {width}), got {size}")


def crop(
    frames: Tensor,
    top: Scalars,
    left: Scalars,
    size: int | Sequence[int],
    *,
    resize: bool = False,
    mode: str = "bilinear",
) -> Tensor:
    """Cut an ``(h, w)`` window at ``(top, left)`` out of every frame of each sequence.

    By default the output is ``(…, h, w)`` (torchvision's ``crop``). With ``resize=True``
    the window is resized back to H×W (torchvision's ``resized_crop``): values are
    interpolated as an image, so the total count grows by about ``H·W / (h·w)``.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        top, left: the window's first row and column, integers or ``(B,)``; the window
            must fit inside the frame.
        size: ``n`` or ``(h, w)``, the window's size.
        resize: resize the window back to H×W.
        mode: ``"bilinear"`` or ``"nearest"``, for ``resize=True``.

    Returns:
        The cropped frames on the same device. Without resizing the dtype is kept; with
        it, as in :func:`~event_transforms.functional.resize` (float32 for integer input
        under ``bilinear``).

    Shape:
        ``(B, T, 2, H, W)`` -> ``(B, T, 2, h, w)``, or unchanged with ``resize=True``.

    Example:
        >>> frames = torch.arange(12).reshape(1, 1, 3, 4).expand(1, 2, 3, 4)
        >>> crop(frames, 1, 2, 2)[0, 0].tolist()
        [[6, 7], [10, 11]]
    """
    batch, unbatch = as_batch(check_frames(frames))
    b, _, _, height, width = batch.shape
    hw = _size(size, "size")
    _check_fits(hw, height, width)
    check_choice(mode, "mode", INTERPOLATIONS)
    top_t = _check_corner(top, b, "top", height - hw[0])
    left_t = _check_corner(left, b, "left", width - hw[1])
    return unbatch(_crop(batch, top_t, left_t, hw, bool(resize), mode))


def center_crop(frames: Tensor, size: int | Sequence[int], *, resize: bool = False, mode: str = "bilinear") -> Tensor:
    """:func:`crop` at the image centre (the top-left corner rounds down, as in torchvision).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        size: ``n`` or ``(h, w)`` pixels, at most the frame size.
        resize: resize the window back to ``H × W`` (see :func:`crop`).
        mode: ``"bilinear"`` or ``"nearest"``, for ``resize=True``.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: ``(..., h, w)``, dtype kept; with ``resize=True`` the frames' shape (dtype as in
          :func:`resize`).

    Example:
        >>> center_crop(torch.ones(3, 2, 7, 8), (3, 4)).shape
        torch.Size([3, 2, 3, 4])
    """
    batch = check_frames(frames)
    height, width = batch.shape[-2:]
    hw = _size(size, "size")
    _check_fits(hw, height, width)
    return crop(frames, (height - hw[0]) // 2, (width - hw[1]) // 2, hw, resize=resize, mode=mode)


# --------------------------------------------------------------------------- downsample


def downsampled_size(height: int, width: int, factor: tuple[int, int], remainder: str) -> tuple[int, int]:
    """The (H', W') that :func:`downsample` returns."""
    rounding = math.floor if remainder == "drop" else math.ceil
    return rounding(height / factor[0]), rounding(width / factor[1])


def _downsample(batch: Tensor, factor: tuple[int, int], remainder: str) -> Tensor:
    b, t, p, height, width = batch.shape
    fy, fx = factor
    h, w = downsampled_size(height, width, factor, remainder)
    if remainder == "drop":
        body = batch[..., : h * fy, : w * fx]
    else:
        body = torch.nn.functional.pad(batch, (0, w * fx - width, 0, h * fy - height)) if batch.numel() else batch.new_zeros(
            b, t, p, h * fy, w * fx
        )
    return _sum_in(body.reshape(b, t, p, h, fy, w, fx), (4, 6), "downsample")


def _sum_in(values: Tensor, dim: int | tuple[int, ...], owner: str, *, keepdim: bool = False) -> Tensor:
    """Sum counts over ``dim`` in a wide dtype and return them in ``values``' dtype.

    8/16-bit integer sums that would not fit raise (one host synchronisation, those dtypes
    only) instead of wrapping.
    """
    dtype = values.dtype
    if dtype.is_floating_point:
        acc = torch.float64 if dtype == torch.float64 else torch.float32
    else:
        acc = torch.int64
    total = values.to(acc).sum(dim=dim, keepdim=keepdim)
    if dtype in _NARROW_INTEGERS and total.numel():
        info = torch.iinfo(dtype)
        high = total.max()
        if bool(high > info.max):
            raise ValueError(
                f"{owner}: a sum ({int(high)}) does not fit frames of dtype {dtype} "
                f"(max {info.max}); convert the frames to a wider dtype first"
            )
    return total.to(dtype)


def _factor(value: object) -> tuple[int, int]:
    return _size(value, "factor")


def downsample(frames: Tensor, factor: int | Sequence[int], *, remainder: str = "drop") -> Tensor:
    """Sum each ``fy × fx`` block of pixels into one (sum-pooling): counts are conserved.

    The paper's "adding the closest neighbourhoods" (140×150 pooled 2×2 to 70×75). When H
    or W is not a multiple of the factor, ``remainder="drop"`` (default, as in pooling with
    floor rounding) discards the last ``H mod fy`` rows and ``W mod fx`` columns and their
    events; ``"keep"`` sums them into a last, partial block (ceil rounding), so every event
    is kept. The sums are taken in int64/float32/float64 and returned in the input dtype;
    8/16-bit integer frames whose block sums would overflow raise instead of wrapping.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        factor: ``k`` or ``(fy, fx)``, positive integers.
        remainder: ``"drop"`` or ``"keep"``.

    Returns:
        ``(…, H', W')`` with ``H' = H // fy`` (``"drop"``) or ``ceil(H / fy)`` (``"keep"``);
        dtype and device kept.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: ``(..., H // fy, W // fx)`` (``"keep"``: rounded up), dtype and device kept.

    Example:
        >>> frames = torch.ones(1, 2, 5, 4, dtype=torch.int32)
        >>> downsample(frames, 2)[0, 0].tolist(), downsample(frames, 2, remainder="keep")[0, 0].tolist()
        ([[4, 4], [4, 4]], [[4, 4], [4, 4], [2, 2]])
    """
    batch, unbatch = as_batch(check_frames(frames))
    return unbatch(_downsample(batch, _factor(factor), check_choice(remainder, "remainder", REMAINDERS)))


# --------------------------------------------------------------------------- flips


def horizontal_flip(frames: Tensor) -> Tensor:
    """Mirror every frame left-right (along W). Counts and dtype are kept.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> horizontal_flip(torch.arange(4.).reshape(1, 2, 1, 2))[0, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    return check_frames(frames).flip(-1)

def vertical_flip(frames: Tensor) -> Tensor:
    """Mirror every frame top-bottom (along H). Counts and dtype are kept.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> vertical_flip(torch.arange(4.).reshape(1, 2, 2, 1))[0, :, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    return check_frames(frames).flip(-2)
