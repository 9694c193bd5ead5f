"""Time spent in sections of a run: :class:`Stopwatch` and :class:`TimedTransform` (an augmentation
whose calls a stopwatch times). The protocol's time columns and the copies read them; their
names are also importable from :mod:`event_transforms.tactile.training`."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import torch
from torch import Tensor, nn

from ..events.batch import EventBatch
from ..transforms.base import EventTransform, Param, Params, Spec, as_transform



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
