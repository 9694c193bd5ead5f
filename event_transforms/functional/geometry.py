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

import numpy as np

from .._params import SEED, Param, check_args
from .._validation import INTERPOLATIONS, as_batch, check_choice, check_frames, on_host
from ..events.batch import EventBatch
from ._dispatch import batch_of, call_kernel, kernel_for, register_kernel
from ._event_ops import JITTER, _mirrored, _per_event, _round_to
from ._random import EventStream
from ._frame_ops import _output_dtype, _work_dtype, factor_pair
from ._frame_ops import _by_runs_on, _flags, _rows_by_flags, _samples_by_runs, _sum_in
from ._frame_ops import frame_size

__all__ = [
    "horizontal_flip", "horizontal_flip_frames", "horizontal_flip_events",
    "vertical_flip", "vertical_flip_frames", "vertical_flip_events",
    "translate", "translate_frames", "translate_events",
    "crop", "crop_frames", "crop_events", "center_crop",
    "downsample", "downsample_frames", "downsample_events",
    "spatial_jitter", "spatial_jitter_events",
]

Scalars = float | Sequence[float] | Tensor
Pairs = Sequence[float] | Tensor
#: How :func:`downsample` treats the rows and columns left over when H or W is not a multiple.
REMAINDERS = ("drop", "keep")

# --------------------------------------------------------------------------- declarations
# Each operation's per-sample arguments, declared once: the dispatcher checks its arguments
# against it (check_args), the module's params_spec returns it (check_tree).

#: :func:`translate`: whole pixels (dy, dx).
TRANSLATE_SPEC = {"shift": Param("int", shape=(2,))}
#: :func:`spatial_jitter`: the standard deviation in pixels and the seed of the noise.
SPATIAL_JITTER_SPEC = {"sigma": Param("float", low=0.0), "seed": SEED}


def crop_spec(shape: Sequence[int], size: tuple[int, int]) -> dict[str, Param]:
    """:func:`crop`'s window corner for a batch ``shape`` (B, T, 2, H, W) and a window ``size``
    (h, w) that fits: ``top`` in [0, H - h], ``left`` in [0, W - w]."""
    return {"top": Param("int", low=0, high=shape[-2] - size[0]), "left": Param("int", low=0, high=shape[-1] - size[1])}


# --------------------------------------------------------------------------- translate


def translate_frames(batch: Tensor, shift: Tensor) -> Tensor:
    """:func:`translate` on a batch with a (B, 2) int64 CPU ``shift`` of (dy, dx).

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        shift: ``(dy, dx)`` integer pixels (down, right), or a ``(B, 2)`` integer tensor.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`translate` gives for a batch.
    """
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


def translate(inputs: Tensor | EventBatch, shift: Pairs) -> Tensor | EventBatch:
    """Move every frame of each sequence by whole pixels, filling the vacated border with zeros.

    Neuromorphic Data Augmentation's "rolling", without the wrap-around: events moved past
    the border are dropped, so the count can only fall. Counts and dtype are kept.

    On an EventBatch (:func:`translate_events`) events moved off the sensor are kept and
    dropped when binned.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
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
    batch, b, restore = batch_of(inputs)
    return restore(call_kernel(translate, batch, check_args("translate", TRANSLATE_SPEC, b, shift=shift)["shift"]))


register_kernel(translate, Tensor)(translate_frames)


@register_kernel(translate, EventBatch)
def translate_events(batch: EventBatch, shift: Tensor) -> EventBatch:
    """Move sample b's events by ``shift[b] = (dy, dx)`` whole pixels (int). Sync-free.

    Args:
        batch: the event streams.
        shift: ``(B, 2)`` integer ``(dy, dx)`` per sample (down, right).

    Shape:
        - batch: B streams, N events.
        - shift: ``(B, 2)``.
        - output: the same streams and events (events may leave the sensor).

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> moved = translate_events(batch, torch.tensor([[1, 0], [0, -1]]))
        >>> moved.y.tolist(), moved.x.tolist()
        ([2, 1, 1], [0, 2, 0])
    """
    shift = shift.to(torch.int16)
    x = batch.x + _per_event(shift[:, 1].contiguous(), batch)
    y = batch.y + _per_event(shift[:, 0].contiguous(), batch)
    return batch._replace(x=x, y=y)


# --------------------------------------------------------------------------- crop


def crop_frames(batch: Tensor, top: Tensor, left: Tensor, size: tuple[int, int], resize: bool = False, mode: str = "bilinear") -> Tensor:
    """Crop ``size`` at per-sample (B,) int64 CPU ``top``/``left``; optionally resize back to H×W.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        top: the window's first row and column, integers or ``(B,)``; the window
            must fit inside the frame.
        left: the window's first row and column, integers or ``(B,)``; the window
            must fit inside the frame.
        size: ``n`` or ``(h, w)``, the window's size.
        resize: resize the window back to H×W.
        mode: ``"bilinear"`` or ``"nearest"``, for ``resize=True``.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`crop` gives for a batch.
    """
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


def _check_fits(size: tuple[int, int], height: int, width: int) -> None:
    if size[0] > height or size[1] > width:
        raise ValueError(f"size must fit in the frames' (H, W) = ({height}, {width}), got {size}")


def crop(
    inputs: Tensor | EventBatch,
    top: Scalars,
    left: Scalars,
    size: int | Sequence[int],
    *,
    resize: bool = False,
    mode: str = "bilinear",
) -> Tensor | EventBatch:
    """Cut an ``(h, w)`` window at ``(top, left)`` out of every frame of each sequence.

    By default the output is ``(…, h, w)`` (torchvision's ``crop``). With ``resize=True``
    the window is resized back to H×W (torchvision's ``resized_crop``): values are
    interpolated as an image, so the total count grows by about ``H·W / (h·w)``. On an
    EventBatch (:func:`crop_events`, ``resize=False`` only) coordinates move and the
    batch's sensor becomes the window.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
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
    batch, b, restore = batch_of(inputs)
    height, width = batch.sensor_size if isinstance(batch, EventBatch) else batch.shape[-2:]
    hw = frame_size(size, "size")
    _check_fits(hw, height, width)
    check_choice(mode, "mode", INTERPOLATIONS)
    corner = check_args("crop", crop_spec((height, width), hw), b, top=top, left=left)
    return restore(call_kernel(crop, batch, corner["top"], corner["left"], hw, bool(resize), mode))


register_kernel(crop, Tensor)(crop_frames)


@register_kernel(crop, EventBatch)
def crop_events(
    batch: EventBatch, top: Tensor, left: Tensor, size: tuple[int, int], resize: bool = False, mode: str = "bilinear"
) -> EventBatch:
    """Crop sample b to the window ``top[b], left[b]`` of ``size`` (H, W): coordinates move
    by ``(-top, -left)`` and the batch's sensor becomes ``size``. Events outside the window
    are kept (dropped when binned, as the frame crop drops them). ``resize=True``
    interpolates frames and is refused. Sync-free.

    Args:
        batch: the event streams.
        top, left: ``(B,)`` the window's first row and column per sample.
        size: ``(h, w)`` of the window, the new sensor size.
        resize: must be ``False`` (resizing interpolates frames).
        mode: unused on events.

    Shape:
        - batch: B streams, N events.
        - top, left: ``(B,)``.
        - output: the same streams and events on an ``(h, w)`` sensor.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> cropped = crop_events(batch, torch.tensor([0, 1]), torch.tensor([1, 1]), (1, 2))
        >>> cropped.sensor_size, cropped.x.tolist(), cropped.y.tolist()
        ((1, 2), [-1, 1, 0], [1, 0, 0])
    """
    if resize:
        raise ValueError("crop(resize=True) interpolates frames; on events crop with resize=False")
    x = batch.x - _per_event(left.to(torch.int16), batch)
    y = batch.y - _per_event(top.to(torch.int16), batch)
    return batch._replace(x=x, y=y, sensor_size=tuple(int(s) for s in size))


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
    hw = frame_size(size, "size")
    _check_fits(hw, height, width)
    out = crop(frames, (height - hw[0]) // 2, (width - hw[1]) // 2, hw, resize=resize, mode=mode)
    assert isinstance(out, Tensor)  # frames in, frames out
    return out


# --------------------------------------------------------------------------- downsample


def downsampled_size(height: int, width: int, factor: tuple[int, int], remainder: str) -> tuple[int, int]:
    """The (H', W') that :func:`downsample` returns."""
    rounding = math.floor if remainder == "drop" else math.ceil
    return rounding(height / factor[0]), rounding(width / factor[1])


def downsample_frames(batch: Tensor, factor: tuple[int, int], remainder: str = "drop") -> Tensor:
    """Kernel of :func:`downsample` for frames: sum-pooling by ``factor`` (rows, columns).

    Args:
        batch: frames ``(B, T, 2, H, W)``.
        factor: the pooling factor ``(fy, fx)``.
        remainder: ``"drop"`` the leftover rows/columns or ``"keep"`` them in a partial block.

    Shape:
        - batch: ``(B, T, 2, H, W)``.
        - output: ``(B, T, 2, H', W')`` (:func:`downsampled_size`), the dtype kept.

    Example:
        >>> downsample_frames(torch.ones(1, 1, 2, 4, 4), (2, 2)).shape
        torch.Size([1, 1, 2, 2, 2])
    """
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


def downsample(frames: Tensor | EventBatch, factor: int | Sequence[int], *, remainder: str = "drop") -> Tensor | EventBatch:
    """Sum each ``fy × fx`` block of pixels into one (sum-pooling): counts are conserved.

    The paper's "adding the closest neighbourhoods" (140×150 pooled 2×2 to 70×75). When H
    or W is not a multiple of the factor, ``remainder="drop"`` (default, as in pooling with
    floor rounding) discards the last ``H mod fy`` rows and ``W mod fx`` columns and their
    events; ``"keep"`` sums them into a last, partial block (ceil rounding), so every event
    is kept. The sums are taken in int64/float32/float64 and returned in the input dtype;
    8/16-bit integer frames whose block sums would overflow raise instead of wrapping, and
    float16/bfloat16 frames whose sums pass the dtype's range raise instead of giving ``inf``.

    On an EventBatch (:func:`downsample_events`) each event moves to its block,
    ``(y // fy, x // fx)``, and the sensor becomes ``(H', W')``: binned, the result equals
    the frame kernel's. Under ``"drop"`` the events of the discarded rows and columns land
    just outside the new sensor and the binning drops them, with its warning.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
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
    kernel = kernel_for(downsample, frames)
    if isinstance(frames, EventBatch):
        return kernel(frames, factor_pair(factor), check_choice(remainder, "remainder", REMAINDERS))
    batch, unbatch = as_batch(check_frames(frames))
    return unbatch(kernel(batch, factor_pair(factor), check_choice(remainder, "remainder", REMAINDERS)))


register_kernel(downsample, Tensor)(downsample_frames)


@register_kernel(downsample, EventBatch)
def downsample_events(batch: EventBatch, factor: tuple[int, int], remainder: str = "drop") -> EventBatch:
    """Kernel of :func:`downsample` for an EventBatch: each event to its block, the sensor to
    ``(H', W')``. Sync-free; counts kept (binned, equal to :func:`downsample_frames`).

    A coordinate ``c`` on an axis of ``n`` pixels and factor ``f`` becomes ``c // f``; one
    already outside the sensor stays outside (``c < 0`` floors below 0, ``c >= n`` goes to
    ``n' + (c - n) // f``), so a partial last block under ``"keep"`` does not take it in.

    Args:
        batch: the event streams.
        factor: ``(fy, fx)`` positive integers.
        remainder: ``"drop"`` or ``"keep"``, as in :func:`downsample` (sets the new sensor size).

    Shape:
        - batch: B streams, N events on an ``(H, W)`` sensor.
        - output: the same streams and events on ``(H', W')``.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[3, 4, 0, 1], [5, 1, 0, 0]])], sensor_size=(5, 6))
        >>> out = downsample_events(batch, (2, 2))
        >>> out.sensor_size, out.x.tolist(), out.y.tolist()
        ((2, 3), [1, 2], [2, 0])
    """
    height, width = batch.sensor_size
    new_h, new_w = downsampled_size(height, width, factor, remainder)
    y = _pool_coordinate(batch.y, factor[0], height, new_h)
    x = _pool_coordinate(batch.x, factor[1], width, new_w)
    return batch._replace(x=x, y=y, sensor_size=(new_h, new_w))


def _pool_coordinate(column: Tensor, factor: int, size: int, new_size: int) -> Tensor:
    """``column // factor`` (floor), with coordinates ``>= size`` kept beyond ``new_size``."""
    pooled = torch.div(column, factor, rounding_mode="floor")
    if size % factor == 0:
        return pooled  # c >= size already gives c // f >= new_size
    beyond = torch.div(column - size, factor, rounding_mode="floor") + new_size
    return torch.where(column >= size, beyond, pooled).to(torch.int16)


# --------------------------------------------------------------------------- flips


def horizontal_flip(inputs: Tensor | EventBatch, flip: Tensor | None = None) -> Tensor | EventBatch:
    """Mirror every frame left-right (along W). Counts and dtype are kept.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch
            (``x -> W - 1 - x``, equal to the frame flip after binning).
        flip: ``(B,)`` bool, the samples to mirror (default: all).

    Shape:
        - inputs: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        - output: same shape, dtype and device.

    Example:
        >>> horizontal_flip(torch.arange(4.).reshape(1, 2, 1, 2))[0, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    batch, b, restore = batch_of(inputs)
    return restore(call_kernel(horizontal_flip, batch, _flags(flip, b)))


def vertical_flip(inputs: Tensor | EventBatch, flip: Tensor | None = None) -> Tensor | EventBatch:
    """Mirror every frame top-bottom (along H). Counts and dtype are kept.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch
            (``y -> H - 1 - y``).
        flip: ``(B,)`` bool, the samples to mirror (default: all).

    Shape:
        - inputs: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        - output: same shape, dtype and device.

    Example:
        >>> vertical_flip(torch.arange(4.).reshape(1, 2, 2, 1))[0, :, :, 0].tolist()
        [[1.0, 0.0], [3.0, 2.0]]
    """
    batch, b, restore = batch_of(inputs)
    return restore(call_kernel(vertical_flip, batch, _flags(flip, b)))


@register_kernel(horizontal_flip, Tensor)
def horizontal_flip_frames(frames: Tensor, flip: Tensor | None = None) -> Tensor:
    """Kernel of :func:`horizontal_flip` for frames ``(B, T, 2, H, W)``.

    Args:
        frames: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        flip: ``(B,)`` bool, the samples to mirror (default: all).

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`horizontal_flip` gives for a batch.
    """
    return _flip_frames(frames, flip, -1)


@register_kernel(vertical_flip, Tensor)
def vertical_flip_frames(frames: Tensor, flip: Tensor | None = None) -> Tensor:
    """Kernel of :func:`vertical_flip` for frames ``(B, T, 2, H, W)``.

    Args:
        frames: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        flip: ``(B,)`` bool, the samples to mirror (default: all).

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`vertical_flip` gives for a batch.
    """
    return _flip_frames(frames, flip, -2)


def _flip_frames(frames: Tensor, gate: Tensor | None, axis: int) -> Tensor:
    """Mirror along ``axis`` (-1: W, -2: H) the samples whose ``gate`` is set
    (all without a gate), in one pass over the batch: ``flip`` when every sample is
    mirrored; else, for H, one gather of whole rows by a host-built index, and for W, on
    the CPU, one ``flip`` per mirrored sample and one copy per run of adjacent others
    (elsewhere one gather of columns). No host synchronisation."""
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
        order = (np.arange(t * p)[:, None] * h + np.arange(h)[::-1][None, :]).reshape(-1)
        return _rows_by_flags(frames, flags, order)
    if _by_runs_on(frames.device):
        return _samples_by_runs(frames, flags, lambda run: run.flip(-1))
    xs = np.where(flags[:, None], np.arange(w)[::-1], np.arange(w))  # (B, W)
    index = torch.from_numpy(xs).to(frames.device).view(b, 1, w).expand(b, t * p * h, w)
    return frames.reshape(b, t * p * h, w).gather(2, index).view(frames.shape)


@register_kernel(horizontal_flip, EventBatch)
def horizontal_flip_events(batch: EventBatch, flip: Tensor | None = None) -> EventBatch:
    """Kernel of :func:`horizontal_flip` for an EventBatch: ``x -> W - 1 - x``. Sync-free.

    Args:
        batch: the event streams.
        flip: ``(B,)`` bool, the samples to mirror (``None``: all).

    Shape:
        - batch: B streams, N events.
        - flip: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> horizontal_flip_events(batch, torch.tensor([True, False])).x.tolist()  # x -> 2 - x in stream 0
        [2, 0, 1]
    """
    return _flip_events(batch, flip, axis="x")


@register_kernel(vertical_flip, EventBatch)
def vertical_flip_events(batch: EventBatch, flip: Tensor | None = None) -> EventBatch:
    """Kernel of :func:`vertical_flip` for an EventBatch: ``y -> H - 1 - y``. Sync-free.

    Args:
        batch: the event streams.
        flip: ``(B,)`` bool, the samples to mirror (``None``: all).

    Shape:
        - batch: B streams, N events.
        - flip: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> vertical_flip_events(batch, torch.tensor([True, False])).y.tolist()  # y -> 1 - y in stream 0
        [0, 1, 1]
    """
    return _flip_events(batch, flip, axis="y")


def _flip_events(batch: EventBatch, flip: Tensor | None, *, axis: str = "x") -> EventBatch:
    """Mirror the samples whose ``flip`` (B,) bool is set: ``x -> W - 1 - x`` (``axis="x"``,
    a horizontal flip) or ``y -> H - 1 - y``. Sync-free; equal to the frame flip after binning.
    """
    column = batch.x if axis == "x" else batch.y
    size = batch.sensor_size[1] if axis == "x" else batch.sensor_size[0]
    mirrored = _mirrored(batch, flip, column, size - 1)
    return batch if mirrored is None else batch._replace(**{axis: mirrored.to(torch.int16)})


# --------------------------------------------------------------------------- spatial jitter (events only)


def spatial_jitter(batch: EventBatch, sigma: Tensor | float, seed: Tensor | int) -> EventBatch:
    """Move every event by Gaussian noise of ``sigma`` pixels in x and y, rounded to whole pixels.

    An event-only operation (frames are refused by name). Events leaving the sensor are
    kept and dropped when binned. Sync-free.

    Args:
        batch: an EventBatch.
        sigma: standard deviation in pixels (>= 0), a number or ``(B,)``.
        seed: the per-sample seeds of the noise, an integer or ``(B,)`` int64 in [0, 2**63).

    Shape:
        - batch: an EventBatch of B streams with N events.
        - sigma, seed: a number or ``(B,)``.
        - output: an EventBatch of the same B streams, sensor and grid, N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[5, 5, 0, 1]])], sensor_size=(10, 10))
        >>> spatial_jitter(batch, 0.0, 7).x.tolist()
        [5]
    """
    kernel = kernel_for(spatial_jitter, batch)
    b = len(batch)
    args = check_args("spatial_jitter", SPATIAL_JITTER_SPEC, b, sigma=sigma, seed=seed)
    return kernel(batch, args["sigma"], args["seed"])


@register_kernel(spatial_jitter, EventBatch)
def spatial_jitter_events(batch: EventBatch, sigma: Tensor, seed: Tensor) -> EventBatch:
    """Add Gaussian noise of standard deviation ``sigma[b]`` pixels to x and y, rounded to
    whole pixels (events leaving the sensor are dropped when binned). The normals come from
    the sample's counter-based stream (``seed[b]`` and the event's position in its sample).
    Sync-free; the same ops whatever B.

    Args:
        batch: the event streams.
        sigma: ``(B,)`` standard deviations in pixels (>= 0).
        seed: ``(B,)`` int64 per-sample seeds.

    Shape:
        - batch: B streams, N events.
        - sigma, seed: ``(B,)``.
        - output: the same streams and events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> jittered = spatial_jitter_events(batch, torch.tensor([0.0, 2.0]), torch.tensor([1, 2]))
        >>> jittered.x[:2].tolist(), jittered.t.tolist()  # sigma 0 moves nothing; times kept
        ([0, 2], [100, 15000, 50])
    """
    noise_x, noise_y = EventStream.of_batch(batch, seed).normal_pair(JITTER)  # float32
    scale = _per_event(sigma.to(torch.float32), batch)
    x = torch.addcmul(batch.x.to(torch.float32), noise_x, scale)
    y = torch.addcmul(batch.y.to(torch.float32), noise_y, scale)
    return batch._replace(x=_round_to(x, torch.int16), y=_round_to(y, torch.int16))
