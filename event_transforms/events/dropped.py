"""Events dropped by design, counted; events dropped against the caller's declaration, warned.

Two kinds of drop, two treatments:

* **By design.** An augmentation whose meaning moves events off the sensor or out of the
  time window (rotation, translation, jitter, perspective and elastic warps, frame shift,
  TES past either end) keeps its output on the sensor and the grid: the events that leave
  are dropped when the kernel or the binning of an :class:`~event_transforms.EventBatch`
  meets them, as each docstring says. That happens on every batch of a training loop, so
  it is never a warning: it is counted, for whoever wants the count, inside a
  :func:`count_dropped` block (outside one, nothing is counted and nothing is read from
  the device).
* **Unasked.** Events of the caller's own input that lie outside the sensor or window the
  caller declared (:func:`~event_transforms.functional.events_to_frames`,
  :func:`~event_transforms.functional.iter_frames`, :meth:`EventBatch.from_streams
  <event_transforms.EventBatch.from_streams>`) warn with
  :class:`~event_transforms.events.EventsOutsideSensorWarning` or
  :class:`~event_transforms.events.EventsOutsideWindowWarning`: a fixed message, the
  counts as attributes of the warning, and the caller's line as its location, so Python's
  default filter shows it once per line of user code, however many batches pass.

Example:
    >>> import torch
    >>> import event_transforms as et
    >>> batch = et.EventBatch.from_streams([torch.tensor([[0, 0, 0, 1], [4, 4, 0, 0]])], sensor_size=(5, 5))
    >>> with et.count_dropped() as dropped:
    ...     moved = et.functional.translate(batch, torch.tensor([[0.0, 3.0]]))  # (dy, dx): x + 3
    ...     frames = et.functional.bin_events(moved, frame_ms=10.0)
    >>> dropped.counts(), int(frames.sum())
    ({'off_sensor': 1}, 1)
"""

from __future__ import annotations

import os
import sys
import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import torch
from torch import Tensor

__all__ = [
    "count_dropped", "DroppedEvents", "DROP_CAUSES", "EventsOutsideSensorWarning", "EventsOutsideWindowWarning",
]

#: The causes a count is kept under: events moved off the sensor, events moved out of the
#: time window of the batch's grid.
DROP_CAUSES = ("off_sensor", "out_of_window")

_active = threading.local()


class DroppedEvents:
    """The events dropped by design inside one :func:`count_dropped` block, per cause.

    Counts are kept on the device as they come (no host synchronisation inside the block);
    :meth:`counts` reads them.

    Example:
        >>> import torch
        >>> import event_transforms as et
        >>> batch = et.EventBatch.from_streams([torch.tensor([[2, 2, 0, 1]])], sensor_size=(4, 4))
        >>> with et.count_dropped() as dropped:
        ...     _ = et.functional.bin_events(et.functional.translate(batch, torch.tensor([[0.0, 5.0]])), frame_ms=10.0)
        >>> dropped.counts(), dropped.total
        ({'off_sensor': 1}, 1)
    """

    def __init__(self) -> None:
        self._parts: dict[str, list[Tensor]] = {}

    def _add(self, cause: str, count: Tensor) -> None:
        self._parts.setdefault(cause, []).append(count)

    def counts(self) -> dict[str, int]:
        """``{cause: events}`` for every cause that dropped at least one event (one host read each)."""
        out = {cause: int(torch.stack([c.to("cpu", torch.int64) for c in parts]).sum()) for cause, parts in self._parts.items()}
        return {cause: n for cause, n in out.items() if n}

    @property
    def total(self) -> int:
        """Events dropped by design in the block, all causes together."""
        return sum(self.counts().values())

    def __repr__(self) -> str:
        return f"DroppedEvents({self.counts()})"


@contextmanager
def count_dropped() -> Iterator[DroppedEvents]:
    """Count the events that transforms and the binning of an EventBatch drop by design.

    Inside the block, every event kernel that drops events as its docstring says (off the
    sensor, out of the window) adds the number to the :class:`DroppedEvents` it yields;
    blocks nest (each counts what happens inside it). Per thread: a DataLoader worker counts
    its own. Outside any block the kernels count nothing and read nothing.

    Example:
        >>> import torch
        >>> import event_transforms as et
        >>> batch = et.EventBatch.from_streams([torch.tensor([[1, 1, 0, 1], [1, 1, 15_000, 1]])],
        ...                                    sensor_size=(3, 3), frame_ms=10.0, n_frames=2)
        >>> with et.count_dropped() as dropped:
        ...     shifted = et.functional.frame_shift(batch, 1)  # the event of bin 1 leaves the window
        >>> dropped.counts()
        {'out_of_window': 1}
    """
    counter = DroppedEvents()
    stack = getattr(_active, "stack", None)
    if stack is None:
        stack = _active.stack = []
    stack.append(counter)
    try:
        yield counter
    finally:
        stack.remove(counter)


def counting() -> bool:
    """Whether a :func:`count_dropped` block is open on this thread (kernels skip the count otherwise)."""
    return bool(getattr(_active, "stack", None))


def record_dropped(cause: str, dropped: Tensor) -> None:
    """Add the events a kernel dropped by design (a bool mask over events, or a count tensor) to
    every open :func:`count_dropped` block. Nothing happens outside a block."""
    stack = getattr(_active, "stack", None)
    if not stack:
        return
    if cause not in DROP_CAUSES:  # pragma: no cover - a programming error
        raise ValueError(f"cause must be one of {DROP_CAUSES}, got {cause!r}")
    count = dropped.sum() if dropped.dtype == torch.bool else dropped
    for counter in stack:
        counter._add(cause, count.detach())


_HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the event_transforms package
_TORCH = os.path.dirname(os.path.abspath(torch.__file__))


def _internal(filename: str) -> bool:
    return filename.startswith(_HERE) or filename.startswith(_TORCH)


def warn_at_caller(warning: Warning) -> None:
    """Issue ``warning`` at the first frame of the stack outside this package and torch (the
    caller's own line, through ``nn.Module.__call__`` and containers).

    The message carries the numbers of this call, yet Python's ``"default"`` filter still shows
    a warning of this class once per line of user code, however many batches pass: where the
    filter registers the warning (``"default"``, ``"module"``, ``"once"``), the class's fixed
    ``MESSAGE`` is registered for that line too and later warnings of the class there are
    skipped. Under ``"always"`` every call warns; ``"error"`` raises as usual.
    """
    frame = sys._getframe(1)
    while frame.f_back is not None and _internal(frame.f_code.co_filename):
        frame = frame.f_back
    category = type(warning)
    fixed = getattr(category, "MESSAGE", None)
    module_globals = frame.f_globals
    registry = module_globals.setdefault("__warningregistry__", {})
    lineno = frame.f_lineno
    # the filters as they stand: a line's entry holds only while they are unchanged (a new
    # catch_warnings list or a new filter shows the warning again, as Python's own registry does)
    state = (id(warnings.filters), tuple(warnings.filters))
    key = (fixed, category, lineno, "event_transforms")
    if fixed is not None and registry.get(key) == state:
        return
    module = module_globals.get("__name__", "<string>")
    warnings.warn_explicit(warning, category, frame.f_code.co_filename, lineno, module=module,
                           registry=registry, module_globals=module_globals)
    if fixed is not None and registry.get((str(warning), category, lineno)):
        registry[key] = state


def _count(dropped: int, total: int) -> str:
    share = f" ({100 * dropped / total:.1f} %)" if total else ""
    return f"{dropped:,} of {total:,} events{share}"


class EventsOutsideSensorWarning(UserWarning):
    """Events of the caller's input lay outside the declared ``sensor_size`` and were dropped
    (usually a wrong sensor size, or x and y swapped).

    The message gives the counts, the span of the coordinates and the size they fit; where
    the events fit the sensor with height and width exchanged, it names the swap (a W-first
    ``sensor_size``, or rows whose first two columns are y, x: ``columns="yxtp"``). Python's
    default filter shows it once per line of the caller's code (see :func:`warn_at_caller`);
    the numbers are attributes too. Events that a transform moves off the sensor are not
    warned about: :func:`~event_transforms.count_dropped` counts them.

    Attributes:
        dropped: events dropped. total: events read. sensor_size: the declared (H, W).
        x_range, y_range: the span of the coordinates read, ``(low, high)``.
        suggested_sensor_size: the (H, W) the events fit (the declared size exchanged when
            ``swapped``), or ``None`` for negative coordinates.
        swapped: the events fit the declared size with height and width exchanged.

    Example:
        >>> import warnings
        >>> import event_transforms as et
        >>> events = torch.tensor([[1, 2, 100, 1], [300, 4, 2000, 0]])  # x, y, t (µs), p
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     frames = et.functional.events_to_frames(events, sensor_size=(10, 10))
        >>> w = caught[0].message
        >>> type(w).__name__, w.dropped, w.total, w.suggested_sensor_size, int(frames.sum())
        ('EventsOutsideSensorWarning', 1, 2, (10, 301), 1)
        >>> str(w)
        'events outside sensor_size were dropped: 1 of 2 events (50.0 %) lie outside sensor_size=(10, 10) (H, W); x spans 1 to 300, y 2 to 4, which fit sensor_size=(10, 301)'
    """

    #: The fixed head of every message (registered once per line by the default filter).
    MESSAGE = "events outside sensor_size were dropped"

    def __init__(self, dropped: int = 0, total: int = 0, sensor_size: tuple[int, int] = (0, 0),
                 x_range: tuple[Any, Any] = (None, None), y_range: tuple[Any, Any] = (None, None)) -> None:
        self.dropped, self.total, self.sensor_size = dropped, total, sensor_size
        self.x_range, self.y_range = x_range, y_range
        self.suggested_sensor_size: tuple[int, int] | None = None
        self.swapped = False
        height, width = sensor_size
        text = f"{self.MESSAGE}: {_count(dropped, total)} lie outside sensor_size={tuple(sensor_size)} (H, W)"
        if x_range[0] is not None and y_range[0] is not None:
            text += f"; x spans {x_range[0]} to {x_range[1]}, y {y_range[0]} to {y_range[1]}"
            if x_range[0] >= 0 and y_range[0] >= 0:
                self.swapped = height != width and x_range[1] < height and y_range[1] < width
                if self.swapped:
                    self.suggested_sensor_size = (width, height)
                    landscape = width >= height  # sensors are wider than high: then the columns are swapped
                    size = (f"sensor_size is (H, W), height first: a sensor {height} wide and {width} high is "
                            f"sensor_size=({width}, {height})")
                    columns = "if the rows are (y, x, t, p), pass columns='yxtp' (or name the columns)"
                    first, second = (columns, size) if landscape else (size, columns)
                    text += (f", which fit sensor_size={tuple(sensor_size)} with x and y exchanged: {first}; "
                             f"or {second}")
                else:
                    self.suggested_sensor_size = (max(y_range[1] + 1, height), max(x_range[1] + 1, width))
                    text += f", which fit sensor_size={self.suggested_sensor_size}"
        super().__init__(text)


class EventsOutsideWindowWarning(UserWarning):
    """Events of the caller's input lay outside the time window the caller asked for
    (``t_start``, ``n_frames``) and were dropped, as asked; the warning counts them.

    The message gives the counts and the window; Python's default filter shows it once per
    line of the caller's code (see :func:`warn_at_caller`); the numbers are attributes too.
    Events that a transform shifts out of the window are not warned about:
    :func:`~event_transforms.count_dropped` counts them.

    Attributes:
        dropped: events dropped. total: events read. per_stream: ``[(dropped, events), ...]``
        per stream. window: the window, in the call's words. hint: what may fix it (or ``""``).

    Example:
        >>> import warnings
        >>> import event_transforms as et
        >>> events = torch.tensor([[1, 2, 100, 1], [3, 4, 25_000, 0]])  # the second in bin 2
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     frames = et.functional.events_to_frames(events, sensor_size=(10, 10), n_frames=1)
        >>> w = caught[0].message
        >>> type(w).__name__, w.dropped, w.per_stream, frames.shape
        ('EventsOutsideWindowWarning', 1, [(1, 2)], torch.Size([1, 2, 10, 10]))
    """

    #: The fixed head of every message (registered once per line by the default filter).
    MESSAGE = "events outside the requested time window are dropped, as asked"

    def __init__(self, dropped: int = 0, total: int = 0, per_stream: list[tuple[int, int]] | None = None,
                 window: str = "", hint: str = "") -> None:
        self.dropped, self.total, self.per_stream, self.window = dropped, total, per_stream or [], window
        self.hint = hint
        text = f"{self.MESSAGE}: {_count(dropped, total)} lie outside {window or 'the window'}"
        if hint:
            text += f"; {hint}"
        super().__init__(text)
