"""Training utilities of the protocol: timing, batching, scores and atomic result files.

The one trainer is :func:`~event_transforms.tactile.ensemble.fit_ensemble` (a model is an
ensemble of one). This module holds what it and the protocol share: a :class:`Stopwatch` and
a :class:`TimedTransform` that reports the time spent inside an augmentation to it,
:func:`collate` for ``(frames, force, meta)`` items, :func:`mse` and :func:`phase_mse`, and
:func:`write_json_atomic` (temporary file + :func:`os.replace`), which makes every finished
unit of a protocol run a file that an interrupted run reads back.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn

from ..events.batch import EventBatch
from ..transforms.base import EventTransform, Param, Params, Spec, as_transform

__all__ = [
    "Stopwatch",
    "TimedTransform",
    "collate",
    "mse",
    "phase_mse",
    "write_json_atomic",
]


class Stopwatch:
    """Accumulates seconds spent in timed sections (``with stopwatch: ...``).

    Example:
        >>> watch = Stopwatch()
        >>> with watch:
        ...     _ = sum(range(10))
        >>> watch.calls, watch.seconds >= 0
        (1, True)
    """

    def __init__(self) -> None:
        self.seconds = 0.0
        self.calls = 0
        self._start: float | None = None

    def __enter__(self) -> Stopwatch:
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._start is None:
            raise RuntimeError("Stopwatch exited without being entered")
        self.seconds += time.perf_counter() - self._start
        self.calls += 1
        self._start = None

    def __repr__(self) -> str:
        return f"Stopwatch(seconds={self.seconds:.6f}, calls={self.calls})"


class TimedTransform(EventTransform):
    """Wrap a transform so the time spent inside it is added to ``stopwatch``.

    A measuring device, not a transform: it draws and applies exactly what the wrapped
    transform does (its parameter tree is the wrapped one's), timing both steps. The
    stopwatch counts only calls made in this process (load data with ``num_workers=0``).

    Args:
        transform: an event transform, or a callable ``frames -> frames``.
        stopwatch: where the seconds go; a new one if ``None``.

    Example:
        >>> import event_transforms as et
        >>> timed = TimedTransform(et.FrameShift(-1))
        >>> out = timed(torch.ones(3, 2, 4, 5))
        >>> timed.stopwatch.calls, out[:, 0, 0, 0].tolist()
        (2, [1.0, 1.0, 0.0])
    """

    def __init__(self, transform: nn.Module, stopwatch: Stopwatch | None = None) -> None:
        super().__init__()
        self.transform = as_transform(transform)
        self.stopwatch = Stopwatch() if stopwatch is None else stopwatch

    def sample_params(
        self,
        shape: torch.Size,
        *,
        generator: torch.Generator | None = None,
        metadata: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None = None,
    ) -> Params:
        with self.stopwatch:
            return self.transform.make_params(shape, generator=generator, metadata=metadata)

    def params_spec(self, shape: torch.Size) -> Spec:
        # the wrapped transform's tree, as it is (its own gate included)
        return {**self.transform.params_spec(shape), "apply": Param("bool", optional=True)}

    def output_shape(self, shape: torch.Size) -> torch.Size:
        return self.transform.output_shape(shape)

    def apply_transform(self, frames: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        with self.stopwatch:
            return self.transform(frames, params=params)


def collate(items: Sequence[tuple]) -> tuple[Tensor, Tensor, list]:
    """Stack ``(frames, force, meta)`` items into ``(B, T, 2, H, W)``, ``(B, T)``, metas."""
    frames = torch.stack([torch.as_tensor(item[0]) for item in items])
    force = torch.stack([torch.as_tensor(item[1]) for item in items]).float()
    metas = [item[2] if len(item) > 2 else {} for item in items]
    return frames, force, metas


def mse(pred: Tensor, target: Tensor) -> float:
    """Mean squared error over every frame of every sequence, in float64."""
    return float((pred.double() - target.double()).square().mean())


def phase_mse(pred: Tensor, target: Tensor, *, edge: int = 5) -> dict[str, float]:
    """MSE per grasp phase: ``grasp`` (first ``edge`` frames), ``hold``, ``release`` (last).

    Args:
        pred: predicted force ``(N, T)``.
        target: measured force ``(N, T)``.
        edge: frames in the grasp and release phases; needs ``T > 2 * edge``.

    Example:
        >>> target = torch.zeros(1, 12)
        >>> pred = torch.tensor([[1.0] * 5 + [0.0] * 2 + [2.0] * 5])
        >>> phase_mse(pred, target)
        {'grasp': 1.0, 'hold': 0.0, 'release': 4.0, 'all': 2.0833333333333335}
    """
    steps = pred.shape[-1]
    if steps <= 2 * edge:
        raise ValueError(f"phase_mse needs more than 2 * edge = {2 * edge} frames, got {steps}")
    err = (pred.double() - target.double()).square()
    return {
        "grasp": float(err[..., :edge].mean()),
        "hold": float(err[..., edge:-edge].mean()),
        "release": float(err[..., -edge:].mean()),
        "all": float(err.mean()),
    }


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as JSON to ``path`` so readers see the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as handle:
            json.dump(obj, handle, indent=2)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
