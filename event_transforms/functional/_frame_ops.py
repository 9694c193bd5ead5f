"""Small frame helpers shared by the topic files (private): the work and output dtypes of the
warps, the flags of the flips and the per-sample selections they drive, count sums in a wide
dtype, and the ``n`` or ``(h, w)`` size check."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import torch
from torch import Tensor

from .._validation import as_number, describe, on_host
from ..events import batch as _batch_module

#: Integer dtypes whose additions are checked for overflow.
SMALL_INTEGERS = (torch.uint8, torch.int8, torch.int16, torch.int32)
#: Integer frame dtypes whose sums are checked against their range.
_NARROW_INTEGERS = (torch.uint8, torch.int8, torch.int16)


def _work_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if dtype == torch.float64 or (mode == "nearest" and dtype in (torch.int32, torch.int64)):
        return torch.float64  # exact for large counts
    return torch.float32


def _output_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if mode == "nearest" or dtype.is_floating_point:
        return dtype
    return torch.float32


def _sum_in(values: Tensor, dim: int | tuple[int, ...], owner: str, *, keepdim: bool = False) -> Tensor:
    """Sum counts over ``dim`` in a wide dtype and return them in ``values``' dtype.

    8/16-bit integer sums that would not fit raise (one host synchronisation, those dtypes
    only) instead of wrapping; float16/bfloat16 sums past the dtype's largest finite value
    raise the same way instead of becoming ``inf``.
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
    if dtype in (torch.float16, torch.bfloat16) and total.numel():
        largest = torch.finfo(dtype).max
        high = total.abs().max()
        if bool(high > largest):
            raise ValueError(
                f"{owner}: a sum ({float(high):g}) does not fit frames of dtype {dtype} "
                f"(largest finite value {largest:g}); convert the frames to a wider dtype first"
            )
    return total.to(dtype)


def _flags(flip: object, batch: int, name: str = "flip") -> Tensor | None:
    """``None``, a bool, or ``(B,)`` bools as a (B,) bool CPU tensor."""
    if flip is None:
        return None
    try:
        value = torch.as_tensor(flip)
    except (TypeError, ValueError, RuntimeError):
        value = None
    if value is None or value.dtype != torch.bool or tuple(value.shape) not in ((), (batch,)):
        raise ValueError(f"{name} must be a bool or a ({batch},) bool tensor, got {describe(flip)}")
    return value.detach().cpu().expand(batch)


def _runs(flags: np.ndarray) -> list[tuple[bool, int, int]]:
    """The runs of equal consecutive ``flags`` (a host bool array): ``(flag, first, end)`` each."""
    if flags.size == 0:
        return []
    starts = np.flatnonzero(np.concatenate(([True], flags[1:] != flags[:-1])))
    ends = np.append(starts[1:], flags.size)
    return [(bool(flags[a]), int(a), int(b)) for a, b in zip(starts.tolist(), ends.tolist())]


def _by_runs_on(device: torch.device) -> bool:
    """Whether a per-sample selection goes run by run (slices of adjacent samples, the CPU:
    a copy each, no per-element index) or as one gather (elsewhere, and when tests count the
    accelerator path's ops with ``events.batch.SLICES_ON_CPU`` off)."""
    return _batch_module.SLICES_ON_CPU and device.type == "cpu"


def _rows_by_flags(frames: Tensor, flags: np.ndarray, order: np.ndarray) -> Tensor:
    """``frames`` (B, ...) seen as B samples of ``order.size`` equal rows: the rows of the samples
    flagged in ``flags`` (host bools) taken in ``order`` (a permutation), the others' kept. One
    ``index_select`` of whole rows by a host-built index: no host read of the frames."""
    b, rows = frames.shape[0], order.size
    if frames.numel() == 0:
        return frames.clone(memory_format=torch.contiguous_format)
    picks = np.where(flags[:, None], order[None, :], np.arange(rows)[None, :]) + rows * np.arange(b)[:, None]
    index = torch.from_numpy(picks.reshape(-1).astype(np.int64)).to(frames.device)
    return frames.reshape(b * rows, frames.numel() // (b * rows)).index_select(0, index).view(frames.shape)


def _flagged_rows(frames: Tensor, gate: Tensor | None, change: Callable[[Tensor], Tensor], order: np.ndarray) -> Tensor:
    """``change(frames)`` on the samples flagged in ``gate`` ((B,) bool, ``None``: all), the
    others unchanged, for a ``change`` that permutes rows (``order``, as :func:`_rows_by_flags`):
    ``change`` of the whole batch when every sample is flagged, else one gather of rows; a gate
    that cannot be read on the host (compiling, on an accelerator) selects with ``where``."""
    if gate is not None and not on_host(gate):
        return torch.where(gate.to(frames.device, torch.bool).view(-1, *([1] * (frames.dim() - 1))), change(frames), frames)
    flags = None if gate is None else np.asarray(gate.tolist(), dtype=bool).reshape(frames.shape[0])
    if flags is None or flags.all():
        return change(frames)
    return _rows_by_flags(frames, flags, order)


def _samples_by_runs(frames: Tensor, flags: np.ndarray, change: Callable[[Tensor], Tensor]) -> Tensor:
    """``change`` of the samples flagged in ``flags`` (host bools), the others copied, into one
    new contiguous batch: one copy per run of adjacent unflagged samples, one ``change`` and
    copy per flagged sample (its temporary, one sample, stays in the cache for the copy)."""
    out = torch.empty(frames.shape, dtype=frames.dtype, device=frames.device)
    for flag, first, end in _runs(flags):
        if not flag:
            out[first:end].copy_(frames[first:end])
            continue
        for i in range(first, end):
            out[i].copy_(change(frames[i : i + 1])[0])
    return out


def frame_size(value: object, name: str) -> tuple[int, int]:
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
    return pair


def check_classes(labels: Tensor, num_classes: int | None) -> int | None:
    if num_classes is not None:
        num_classes = as_number(num_classes, "num_classes", integer=True, low=1)
    if labels.dtype == torch.bool or labels.is_complex():
        raise TypeError(f"labels must be float targets or integer class indices, got dtype {labels.dtype}")
    if not labels.is_floating_point():
        if num_classes is None:
            raise TypeError(
                f"labels of dtype {labels.dtype} are class indices: give num_classes to mix them as "
                "soft targets (or pass float targets)"
            )
        if labels.dim() != 1:
            raise ValueError(f"class indices must have shape (B,), got {tuple(labels.shape)}")
        if labels.numel() and bool(((labels < 0) | (labels >= num_classes)).any()):
            raise ValueError(f"class indices must lie in [0, {num_classes}), got {describe(labels)}")
    return num_classes


def blend_labels(labels: Tensor, partner: Tensor, weight: Tensor, num_classes: int | None) -> Tensor:
    if not labels.is_floating_point():
        labels = torch.nn.functional.one_hot(labels.long(), -1 if num_classes is None else num_classes).to(torch.float32)
    work = torch.float64 if labels.dtype == torch.float64 else torch.float32
    w = weight.to(labels.device, work, non_blocking=True).view(-1, *([1] * (labels.dim() - 1)))
    own = labels.to(work)
    other = own.index_select(0, partner.to(labels.device, non_blocking=True))
    return (other + w * (own - other)).to(labels.dtype)


def check_length(length: object, frames: int) -> int:
    value = as_number(length, "length", integer=True)
    if not 1 <= value <= frames:
        raise ValueError(f"length must lie in [1, {frames}] (the number of frames T), got {length!r}")
    return value


def factor_pair(value: object) -> tuple[int, int]:
    return frame_size(value, "factor")


def pixel_mask(pixels: object, batch: int, height: int, width: int, device: torch.device) -> Tensor:
    """``(N, 2)`` (y, x) coordinates, an ``(H, W)`` or ``(B, H, W)`` bool mask -> (B or 1, H, W) bool."""
    if not isinstance(pixels, Tensor):
        try:
            pixels = torch.as_tensor(pixels)
        except (TypeError, ValueError, RuntimeError):
            raise TypeError(f"pixels must be (N, 2) (y, x) coordinates or a bool mask, got {pixels!r}") from None
    if pixels.dtype == torch.bool:
        if tuple(pixels.shape) not in ((height, width), (batch, height, width)):
            raise ValueError(
                f"a pixel mask must have shape ({height}, {width}) or ({batch}, {height}, {width}), got {tuple(pixels.shape)}"
            )
        return pixels.to(device, non_blocking=True).reshape(-1, height, width)
    if pixels.is_floating_point() or pixels.is_complex():
        raise TypeError(f"pixel coordinates must be integers, got dtype {pixels.dtype}")
    if pixels.dim() != 2 or pixels.shape[1] != 2:
        raise ValueError(f"pixel coordinates must have shape (N, 2) as (y, x), got {tuple(pixels.shape)}")
    ys, xs = pixels[:, 0].cpu(), pixels[:, 1].cpu()
    if pixels.numel() and bool(((ys < 0) | (ys >= height) | (xs < 0) | (xs >= width)).any()):
        raise ValueError(f"pixel coordinates must lie inside (H, W) = ({height}, {width}), got {describe(pixels)}")
    mask = torch.zeros(height * width, dtype=torch.bool)
    mask[ys * width + xs] = True
    return mask.view(1, height, width).to(device, non_blocking=True)


def add_entries(frames: Tensor, target: Tensor, values: Tensor, name: str) -> Tensor:
    """A copy of ``frames`` with ``values`` added at the distinct flat positions ``target``.

    Integer dtypes narrower than int64 are checked for overflow first (one host
    synchronisation, for those dtypes only); float dtypes need none.
    """
    out = frames.clone(memory_format=torch.contiguous_format)
    flat = out.view(-1)
    if frames.dtype in SMALL_INTEGERS and target.numel():
        limit = torch.iinfo(frames.dtype).max
        high = (flat.index_select(0, target).to(torch.int64) + values.to(torch.int64)).max()
        if bool(high > limit):
            raise ValueError(
                f"adding {name} overflows {frames.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    return flat.index_add_(0, target, values.to(out.dtype)).view(frames.shape)


def poisson_totals(lam: Tensor, shape: torch.Size, generator: torch.Generator | None) -> Tensor | None:
    """Per-sample totals Poisson(λ·cells) (int64 CPU) for sparse noise, or ``None`` if dense.

    ``lam`` is the (B,) mean count per cell (CPU float64). Below one event per cell the noise
    is placed event by event (the totals, then uniform positions); otherwise cell by cell.
    """
    if lam.numel() == 0 or max(lam.tolist()) >= 1.0:
        return None
    cells = float(torch.Size(shape[1:]).numel())
    return torch.poisson(lam * cells, generator=generator).to(torch.int64)
