"""Small frame helpers shared by the topic files (private): the work and output dtypes of the
warps, the flags of the flips, count sums in a wide dtype, and the ``n`` or ``(h, w)`` size check."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import as_number, describe

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
    return pair
