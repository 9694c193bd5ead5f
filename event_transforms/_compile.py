"""The opt-in compiled path: ``torch.compile`` of the hot kernels, eager by default.

A kernel marked :func:`compilable` is a pure tensor function (no host read, no Python
branch on a tensor's value): eager, it runs as written; with compiled kernels on
(:func:`set_compiled_kernels`, or the :func:`compiled_kernels` context manager) the
same function runs through ``torch.compile(fn, dynamic=True, fullgraph=True)``, compiled
once per kernel on first use. ``dynamic=True`` keeps event counts symbolic, so a batch
with another number of events reuses the compiled code instead of compiling again, and
``fullgraph=True`` turns any graph break into an error instead of a silent fallback.

The switch is process-wide (like ``torch.backends.cudnn.benchmark``), read at each call:
a ``DataLoader`` worker inherits it when forked, or sets it itself. Outputs equal eager
ones: bit for bit where the kernel counts, gathers and hashes (binning, the counter-based
uniforms), to a float tolerance where inductor may order float arithmetic differently
(interpolating warps, Box-Muller normals); ``tests/library/test_compiled_kernels.py`` holds both.
"""

from __future__ import annotations

import contextlib
import functools
import os
import shutil
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import torch

__all__ = ["compilable", "compiled_kernels", "compiled_kernels_enabled", "set_compiled_kernels", "unavailable_reason"]

F = TypeVar("F", bound=Callable[..., Any])

_ENABLED = False


def unavailable_reason() -> str | None:
    """Why ``torch.compile`` cannot run here, or ``None`` if it can (dynamo supported, and for
    the CPU a C++ compiler on the path: inductor writes C++ and builds it)."""
    try:
        from torch._dynamo import is_dynamo_supported
    except ImportError:  # pragma: no cover - every supported torch has it
        return "torch._dynamo is missing from this torch build"
    if not is_dynamo_supported():
        return f"torch.compile is not supported on this Python/platform (torch {torch.__version__})"
    compilers = [os.environ.get("CXX", ""), "g++", "c++", "clang++"]
    if not any(c and shutil.which(c) for c in compilers):
        return "no C++ compiler (g++, c++ or clang++, or $CXX) on the PATH: inductor needs one for CPU kernels"
    return None


def set_compiled_kernels(enabled: bool) -> None:
    """Run the hot kernels through ``torch.compile`` (``True``) or eagerly (``False``, the default).

    The compiled kernels: batch binning (:class:`~event_transforms.EventsToFrames` and
    :func:`~event_transforms.functional.bin_events` on an
    :class:`~event_transforms.EventBatch`), the affine warp of frames (rotation, resize,
    affine, stretch), spatial and time jitter of events and the counter-based uniforms
    behind event drop, Poisson noise and TES. Each compiles on its first call (seconds on
    the CPU) and serves every later event count without compiling again.

    Args:
        enabled: whether to compile.

    Raises:
        RuntimeError: ``enabled`` but ``torch.compile`` cannot run here (the reason is named).
        TypeError: ``enabled`` is not a bool.

    Example:
        >>> import event_transforms as et
        >>> et.set_compiled_kernels(False)
        >>> et.compiled_kernels_enabled()
        False
    """
    global _ENABLED
    if not isinstance(enabled, bool):
        raise TypeError(f"enabled must be a bool, got {enabled!r}")
    if enabled:
        reason = unavailable_reason()
        if reason is not None:
            raise RuntimeError(f"compiled kernels are unavailable: {reason}")
    _ENABLED = enabled


def compiled_kernels_enabled() -> bool:
    """Whether the hot kernels run compiled (see :func:`set_compiled_kernels`).

    Example:
        >>> import event_transforms as et
        >>> et.compiled_kernels_enabled()  # eager unless switched on
        False
    """
    return _ENABLED


@contextlib.contextmanager
def compiled_kernels(enabled: bool = True) -> Iterator[None]:
    """Context manager: compiled kernels on (or off) inside the block, the previous setting after.

    Args:
        enabled: the setting inside the block.

    Example:
        >>> import torch, event_transforms as et
        >>> with et.compiled_kernels(False):  # eager inside, as by default
        ...     et.compiled_kernels_enabled()
        False
    """
    previous = _ENABLED
    set_compiled_kernels(enabled)
    try:
        yield
    finally:
        set_compiled_kernels(previous)


def compilable(fn: F) -> F:
    """Mark a pure tensor kernel: eager as written, compiled (dynamic shapes, one graph) when
    compiled kernels are on. Inside another compiled region it is inlined, not compiled again."""
    compiled: list[Callable[..., Any]] = []

    @functools.wraps(fn)
    def run(*args: Any, **kwargs: Any) -> Any:
        if not _ENABLED or torch.compiler.is_compiling():
            return fn(*args, **kwargs)
        if not compiled:
            compiled.append(torch.compile(fn, dynamic=True, fullgraph=True))
        return compiled[0](*args, **kwargs)

    run.eager = fn  # type: ignore[attr-defined]
    return run  # type: ignore[return-value]
