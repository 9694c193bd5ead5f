"""Measurement helpers shared by ``benchmarks/`` and the tests (private): op and host-sync counts
of a call (``torch.profiler`` on the CPU, the device-free proxy for launch overhead) and sparse
synthetic event frames."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import torch

__all__ = ["HOST_SYNC_OPS", "OpCounts", "count_ops", "synthetic_frames"]


def synthetic_frames(
    shape: Sequence[int],
    *,
    density: float = 0.05,
    mean_count: float = 1.5,
    dtype: torch.dtype = torch.float32,
    seed: int = 0,
) -> torch.Tensor:
    """Sparse event counts: a ``density`` share of pixels non-zero, counts ``1 + Poisson(mean_count - 1)``.

    Stand-in for real frames (the paper's 70×75 pooled frames have a few per cent
    of active pixels per 10 ms, with counts of a few events).
    """
    g = torch.Generator().manual_seed(seed)
    active = torch.rand(tuple(shape), generator=g) < density
    counts = 1.0 + torch.poisson(torch.full(tuple(shape), max(mean_count - 1.0, 0.0)), generator=g)
    return (active * counts).to(dtype)


#: aten calls that make the host wait for the device (they read a value or a
#: data-dependent size): ``.item()``/``bool()``/``int()`` (``_local_scalar_dense``),
#: ``nonzero``, ``masked_select`` and ``unique``.
HOST_SYNC_OPS = ("aten::_local_scalar_dense", "aten::nonzero", "aten::masked_select")


@dataclass(frozen=True)
class OpCounts:
    """Host synchronisations and top-level aten calls of one call, from ``torch.profiler``."""

    syncs: int
    ops: int
    sync_names: tuple[str, ...] = ()
    op_names: tuple[str, ...] = ()

    def __str__(self) -> str:
        return f"{self.syncs} syncs, {self.ops} ops"


def _is_sync(name: str) -> bool:
    from event_transforms._validation import HOST_READ

    return name in HOST_SYNC_OPS or name == HOST_READ or name.startswith(("aten::unique", "aten::_unique"))


def count_ops(fn: Callable[[], Any], *, warmup: bool = True) -> OpCounts:
    """Count the host syncs and top-level aten ops of ``fn()`` with ``torch.profiler`` (CPU).

    *Ops* are the aten calls made directly from Python (events whose parent is not an aten
    call), views and metadata calls (``view``, ``slice``, ``resolve_conj``) included: each
    is at least one dispatch, and most are a kernel launch on an accelerator, so the count
    is an upper bound of the launches. *Host syncs* are calls, at any depth, of
    ``_local_scalar_dense`` (``.item()``, ``bool(tensor)``, ``int(tensor)``), ``nonzero``,
    ``masked_select`` or ``unique*``, plus the library's own reads of device values
    (``event_transforms._validation.read_host``, a profiler range: ``tolist`` dispatches
    nothing countable on the CPU): on an accelerator each makes the host wait for the
    device. Reads of parameters drawn on the CPU are not syncs and are not counted, nor
    are the host-side checks of a user-given params tree (the profiler range
    ``event_transforms::check_params``: CPU tensors, no device work). On
    the CPU these counts are deterministic for a given input and parameters, so they serve
    as a device-free proxy for launch overhead.

    ``fn`` is called once first (``warmup``) so lazy imports and caches are not counted.
    """
    from torch.profiler import ProfilerActivity, profile

    from event_transforms.transforms._tree import CHECK_RANGE

    if warmup:
        fn()
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        fn()
    everything = list(prof.events())
    events = [e for e in everything if e.name.startswith("aten::")]

    def top_level(event: Any) -> bool:
        parent = event.cpu_parent
        while parent is not None:
            if parent.name.startswith("aten::") or parent.name == CHECK_RANGE:
                return False
            parent = parent.cpu_parent
        return True

    def checking(event: Any) -> bool:  # host reads of a user-given CPU params tree
        parent = event.cpu_parent
        while parent is not None:
            if parent.name == CHECK_RANGE:
                return True
            parent = parent.cpu_parent
        return False

    syncs = tuple(e.name for e in everything if _is_sync(e.name) and not checking(e))
    ops = tuple(e.name for e in events if top_level(e))
    return OpCounts(syncs=len(syncs), ops=len(ops), sync_names=syncs, op_names=ops)
