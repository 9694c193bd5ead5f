"""Accumulate event streams (x, y, t, p) into event frames (T, 2, H, W).

Events come as a ``(N, 4)`` array or tensor of ``(x, y, t, p)`` rows (any integer or float
dtype, uint64 included), a ``(B, N, 4)`` batch of padded streams with ``lengths`` or
``mask``, a mapping of columns, or a numpy structured array, tonic's own dtypes included:
``tonic.io.read_aedat4`` returns ``[('t', '<u8'), ('x', '<u2'), ('y', '<u2'),
(('p', 'on'), '?')]``, whose polarity field is named ``on`` and titled ``p``. Columns are
found by name: ``x``, ``y``, ``t`` (or ``timestamp``), ``p`` (or ``on``, ``polarity``).
A pandas or polars DataFrame is read by column name too, and an ``(N, k)`` array in another
order is named with ``columns="txyp"`` (``"_"`` skips a column). Timestamps are in
microseconds unless ``time_unit=`` says ``"ns"``, ``"ms"`` or ``"s"``; ``timedelta64`` and
``datetime64`` columns (polars ``Duration``) carry their own unit. Two silent traps are
refused by name: float timestamps with fractions spanning less than 1e6, which look like
seconds read as microseconds (every event would land in one bin; pass ``time_unit``), and
float timestamps too large for their dtype to hold microseconds (float32 past 2**24 µs);
a recording of integer timestamps whose span and count say milliseconds is refused the same way.
Polarity is bool, {0, 1} or {-1, 1}, with ON (``True``,
``1``) in channel 1 and OFF (``False``, ``0``, ``-1``) in channel 0, tonic's convention.

Where the bins start (``t_start``):

* ``"floor"`` (default): at the first event's timestamp rounded down to a multiple of the
  bin width. Real recordings carry absolute timestamps (microseconds since the epoch,
  about 1.7e15), so a fixed start such as 0 would put every event outside the bins.
  Rounding down to the bin grid keeps every event, puts the bins of every piece of a
  recording (and of force samples taken on the same clock every ``frame_ms``) on one
  grid, so pieces binned apart concatenate exactly, and gives the old ``t_start=0`` bins
  for streams that start within their first bin.
* ``"first"``: at the first event's timestamp (tonic's ``ToFrame`` with ``time_window``).
* a number, or one per stream for a batch: at that time, to stay in step with force
  samples on the same clock.

``n_frames=None`` (default) makes as many bins as it takes to hold the last event, so no
event is lost to the time window. Events outside a window you asked for (an explicit
``t_start``, ``n_frames`` or ``crop``) are dropped, as asked; if a stream holds events and
none of them falls in the time window, :class:`ValueError` names ``t_start``, ``frame_ms``
and ``n_frames`` and the time span of the events. Events outside the sensor are dropped
with an :class:`EventsOutsideSensorWarning` that counts them and proposes the sensor size
they fit. Sizes are (H, W), height first; tonic writes ``sensor_size=(W, H, P)``, which is
accepted as ``tonic_sensor_size=``.

Memory: the input is read in chunks of ``chunk_size`` events (2**20 by default), so the
extra memory is a few times the chunk plus the output, whatever N is.
:func:`~event_transforms.functional.iter_frames` (in :mod:`.streaming`) bins a stream
that arrives in chunks by the same rules.
"""

from __future__ import annotations

__all__ = ["events_to_frames", "EventsOutsideSensorWarning", "EventsOutsideWindowWarning", "CHUNK_EVENTS", "MAX_BYTES"]

import math
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, NamedTuple, cast

import numpy as np
import torch
from torch import Tensor
from .._validation import FRAME_DTYPES

#: Events read per chunk by default: the extra memory of a call is a few times this many
#: 64-bit values plus the output.
CHUNK_EVENTS = 2**20

_INT64_MAX = 2**63 - 1
_FIELDS = ("x", "y", "t", "p")
#: Names under which each column is looked up, in order.
_ALIASES = {"x": ("x",), "y": ("y",), "t": ("t", "timestamp"), "p": ("p", "on", "polarity")}
_T_STARTS = ("floor", "first")
#: Largest number of bins ``n_frames=None`` infers before it asks for ``n_frames`` (a
#: recording in nanoseconds read as microseconds spans 1,000 times too many bins).
_MAX_INFERRED_FRAMES = 100_000


#: Default bound of the memory :func:`events_to_frames` may allocate (the output, plus an
#: int32 counting buffer when the dtype may not hold a count exactly), in bytes: 4 GiB. A longer recording is refused by name, quickly.
MAX_BYTES = 2**32


class EventsOutsideSensorWarning(UserWarning):
    """Events lay outside ``sensor_size`` and were dropped (usually a wrong sensor size).

    Example:
        >>> import warnings
        >>> events = torch.tensor([[1, 2, 100, 1], [300, 4, 2000, 0]])  # x, y, t (µs), p
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     frames = events_to_frames(events, sensor_size=(10, 10))
        >>> caught[0].category.__name__, int(frames.sum())
        ('EventsOutsideSensorWarning', 1)
    """


class EventsOutsideWindowWarning(UserWarning):
    """Events lay outside the time window the caller asked for (``t_start``, ``n_frames``)
    and were dropped, as asked; the warning counts them.

    Example:
        >>> import warnings
        >>> events = torch.tensor([[1, 2, 100, 1], [3, 4, 25_000, 0]])  # the second in bin 2
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     frames = events_to_frames(events, sensor_size=(10, 10), n_frames=1)
        >>> caught[0].category.__name__, frames.shape
        ('EventsOutsideWindowWarning', torch.Size([1, 2, 10, 10]))
    """


# --------------------------------------------------------------------------- columns

#: Microseconds per unit of ``time_unit``.
_TIME_UNITS: dict[str, float | int] = {"ns": 1e-3, "us": 1, "ms": 1_000, "s": 1_000_000}
#: Float timestamps with a fractional part spanning less than this (in the unit read, 1 s of
#: microseconds) look like seconds: refused unless ``time_unit`` is given.
_SECONDS_SPAN = 1e6
#: Values read to decide whether float timestamps have fractional parts.
_FRACTION_PROBE = 1 << 16


def _time_unit(time_unit: object) -> str | None:
    if time_unit is None:
        return None
    if not isinstance(time_unit, str) or time_unit not in _TIME_UNITS:
        raise ValueError(f"time_unit must be one of {', '.join(map(repr, _TIME_UNITS))} or None, got {time_unit!r}")
    return time_unit


def _time_typed(array: np.ndarray, name: str, time_unit: str | None) -> tuple[np.ndarray, str]:
    """A ``timedelta64``/``datetime64`` column as int64 counts of its own unit (checked)."""
    unit, count = np.datetime_data(array.dtype)
    if unit not in _TIME_UNITS or count != 1:
        raise ValueError(
            f"events[{name!r}] has dtype {array.dtype}; timestamps in ns, us, ms or s are accepted "
            f"(cast it, e.g. .astype('{array.dtype.kind == 'm' and 'timedelta64' or 'datetime64'}[us]'))"
        )
    if time_unit is not None and time_unit != unit:
        raise ValueError(
            f"time_unit={time_unit!r} contradicts events[{name!r}], whose dtype {array.dtype} carries its unit; "
            "leave time_unit out for time-typed columns"
        )
    values = array.view(np.int64)
    if values.size and bool((values == np.iinfo(np.int64).min).any()):
        raise ValueError(f"events[{name!r}] holds NaT (a missing time)")
    return values, unit


def _column(values: Any, name: str) -> Tensor:
    """One field as a tensor: int64 for bool and integer input, float64 for float input.

    Raises:
        TypeError: a dtype that holds no real numbers.
        ValueError: unsigned 64-bit values past 2**63 - 1, or NaN/Inf.
    """
    if isinstance(values, Tensor):
        if values.dtype == torch.bool:
            return values.to(torch.int64)
        if values.dtype == torch.uint64:
            signed = values.view(torch.int64)
            if signed.numel() and bool((signed < 0).any()):
                raise ValueError(f"events[{name!r}] holds uint64 values past 2**63 - 1, which int64 cannot hold")
            return signed
        if values.is_complex():
            raise TypeError(f"events[{name!r}] must hold real numbers, got dtype {values.dtype}")
        column = values.to(torch.float64) if values.is_floating_point() else values.to(torch.int64)
    else:
        array = np.asarray(values)
        kind = array.dtype.kind
        if kind == "u" and array.dtype.itemsize == 8 and array.size and int(array.max()) > _INT64_MAX:
            raise ValueError(
                f"events[{name!r}] holds {int(array.max())}, past 2**63 - 1, which int64 cannot hold"
            )
        if kind in "biu":
            array = array.astype(np.int64)
        elif kind == "f":
            array = array.astype(np.float64)
        elif kind in "mM" and name == "t":
            array = array.view(np.int64).astype(np.int64)  # a copy; the unit was read (and checked) by _source
        else:
            raise TypeError(f"events[{name!r}] must hold numbers, got numpy dtype {array.dtype}")
        column = torch.from_numpy(np.ascontiguousarray(array))
    if column.is_floating_point() and column.numel() and not bool(torch.isfinite(column).all()):
        raise ValueError(f"events[{name!r}] must be finite, got NaN or Inf")
    return column


def _check_float_times(t: Any, unit: str | None) -> None:
    """Refuse float timestamps that lost precision or look like seconds read as microseconds.

    ``t`` is the whole timestamp column (a view); integer columns are never checked.
    """
    if isinstance(t, Tensor):
        if not t.is_floating_point() or not t.numel():
            return
        low, high = float(t.min()), float(t.max())
        eps = torch.finfo(t.dtype).eps
        probe = t.reshape(-1)[:_FRACTION_PROBE]
        fractional = bool((probe != probe.floor()).any())
        dtype_name = str(t.dtype)
    else:
        array = np.asarray(t)
        if array.dtype.kind != "f" or not array.size:
            return
        low, high = float(array.min()), float(array.max())
        eps = float(np.finfo(array.dtype).eps)
        head = array.reshape(-1)[:_FRACTION_PROBE]
        fractional = bool((head != np.floor(head)).any())
        dtype_name = str(array.dtype)
    if not (math.isfinite(low) and math.isfinite(high)):
        return  # _column names the NaN/Inf
    scale = _TIME_UNITS[unit or "us"]
    magnitude = max(abs(low), abs(high))
    spacing_us = 2.0 ** math.floor(math.log2(magnitude)) * eps * scale if magnitude else 0.0
    if spacing_us > 1:
        raise ValueError(
            f"events['t'] is {dtype_name} with values up to {magnitude:.7g} {unit or 'us'}, where {dtype_name} "
            f"steps {spacing_us:g} us: the timestamps have already lost microseconds. Read them as int64 or "
            "float64 (or subtract the first timestamp before casting)"
        )
    if unit is None and fractional and high - low < _SECONDS_SPAN:
        raise ValueError(
            f"events['t'] holds float timestamps with fractions spanning {high - low:.6g}, which looks like "
            "seconds (timestamps are read as microseconds, so every event would fall in one bin); pass "
            "time_unit='s' (or 'ms', 'ns'), or time_unit='us' if they are microseconds"
        )


# Integer milliseconds read as microseconds (issue 35): checked from the first and last
# timestamps and the count only, never a pass over the column.
#: Integer timestamps spanning less than this (1 s as microseconds) ...
_MS_SPAN = 1_000_000
#: ... with at least this many events per unit (5e7 events/s as microseconds) ...
_MS_RATE = 50
#: ... and at least this many events, spanning at least ``_MS_MIN_SPAN`` units (a shorter
#: span is one 10 ms frame in either unit), look like milliseconds.
_MS_EVENTS = 1000
_MS_MIN_SPAN = 10


def _millisecond_advice(count: int, first: float, last: float) -> str | None:
    """Why integer timestamps look like milliseconds read as microseconds, or ``None``."""
    span = last - first
    if count < _MS_EVENTS or not _MS_MIN_SPAN <= span < _MS_SPAN or count < _MS_RATE * (span + 1):
        return None
    rate = count / (span + 1)
    return (f"{count:,} integer timestamps spanning {span:,.0f} look like milliseconds, not microseconds "
            f"({rate:.0f} events per unit: {rate:.3g} million events per second as microseconds, a "
            f"{span / 1000:.3g} s recording as milliseconds)")


def _check_integer_times(t: Any, unit: str | None) -> None:
    """Refuse a 1-D integer timestamp column on the CPU that looks like milliseconds (``unit`` None)."""
    if unit is not None or getattr(t, "ndim", 0) != 1 or len(t) < _MS_EVENTS:
        return
    if isinstance(t, Tensor):
        if t.is_floating_point() or t.device.type != "cpu" or t.dtype == torch.bool:
            return
    elif np.asarray(t[:1]).dtype.kind not in "iu":
        return
    advice = _millisecond_advice(len(t), float(t[0]), float(t[-1]))
    if advice is not None:
        raise ValueError(f"events['t']: {advice}; pass time_unit='ms', or time_unit='us' if they are microseconds")


def _to_microseconds(t: Tensor, unit: str) -> Tensor:
    """An int64/float64 timestamp column in ``unit`` as microseconds (ns are floored to whole µs)."""
    if unit == "us":
        return t
    if unit == "ns":
        return t / 1000 if t.is_floating_point() else torch.div(t, 1000, rounding_mode="floor")
    factor = int(_TIME_UNITS[unit])
    if t.is_floating_point():
        return t * factor
    if t.numel() and int(t.abs().max()) > _INT64_MAX // factor:
        raise ValueError(f"events['t'] in {unit} holds {int(t.abs().max())}, past what int64 microseconds hold")
    return t * factor


def _field(names: Iterable[str], column: str) -> str | None:
    """The name under which ``column`` is stored, or None."""
    names = set(names)
    return next((alias for alias in _ALIASES[column] if alias in names), None)


def _order_names(columns: object) -> list[str]:
    """``columns`` ("txyp", or a sequence of one-letter names) checked: x, y, t, p once each, '_' to skip."""
    names = list(columns) if isinstance(columns, (str, Sequence)) else None
    if (
        names is None or not all(isinstance(n, str) for n in names)
        or sorted(n for n in names if n != "_") != ["p", "t", "x", "y"]
    ):
        raise ValueError(
            "columns must name each column of the events with each of x, y, t, p once and '_' for a "
            f"column to skip (e.g. 'txyp'), got {columns!r}"
        )
    return names


def _order(columns: object, width: int) -> list[int]:
    """Indices of x, y, t, p among the ``width`` columns of an (N, k) array (``columns="txyp"``)."""
    if columns is None:
        if width != 4:
            raise ValueError(
                f"events: expected (N, 4) or (B, N, 4) rows of (x, y, t, p), got {width} columns; "
                "pass columns= (e.g. columns='txyp', '_' for a column to skip) to name them"
            )
        return [0, 1, 2, 3]
    names = _order_names(columns)
    if len(names) != width:
        raise ValueError(f"columns={columns!r} names {len(names)} columns, but the events have {width}")
    return [names.index(c) for c in _FIELDS]


def _frame_columns(events: Any) -> dict[str, Any] | None:
    """A pandas or polars DataFrame as a dict of numpy columns (only x, y, t, p); None for others."""
    library = type(events).__module__.split(".")[0]
    if library not in ("pandas", "polars") or not hasattr(events, "columns"):
        return None
    names = [str(c) for c in events.columns]
    found = {c: _field(names, c) for c in _FIELDS}
    return {f: events[f].to_numpy() for f in found.values() if f is not None} | {
        f: None for f in names if f not in found.values()  # kept (empty) so that errors list every column
    }


@dataclass
class _Source:
    """Events of B streams of length N, read ``(start, stop)`` along N as columns (B, n).

    Timestamps are read in microseconds whatever ``time_unit`` the input came in.
    """

    batch: int
    length: int
    batched: bool
    read: Callable[[int, int, Sequence[str]], dict[str, Tensor]]
    device: torch.device


def _source(events: Any, *, time_unit: str | None = None, columns: str | Sequence[str] | None = None,
            whole: bool = False) -> _Source:
    """Wrap any accepted form of ``events`` without converting it as a whole.

    ``time_unit`` (None: microseconds, checked for float timestamps that look like seconds)
    and ``columns`` (the order of an (N, k) array's columns) as in :func:`events_to_frames`;
    ``whole``: the events are a whole recording (not a chunk of a stream), so integer
    timestamps that look like milliseconds are refused.
    """
    time_unit = _time_unit(time_unit)
    source, t_whole = _raw_source(events, columns)
    unit = time_unit
    if isinstance(t_whole, np.ndarray) and t_whole.dtype.kind in "mM":
        _, unit = _time_typed(t_whole, "t", time_unit)
    else:
        _check_float_times(t_whole, time_unit)
        if whole:
            _check_integer_times(t_whole, time_unit)
    if unit is None or unit == "us":
        return source
    raw = source.read

    def read(i: int, j: int, names: Sequence[str]) -> dict[str, Tensor]:
        out = raw(i, j, names)
        if "t" in out:
            out["t"] = _to_microseconds(out["t"], unit)
        return out

    return _Source(source.batch, source.length, source.batched, read, source.device)


def _raw_source(events: Any, columns: str | Sequence[str] | None) -> tuple[_Source, Any]:
    """The source in the input's own time unit, and its whole timestamp column (a view)."""
    cpu = torch.device("cpu")
    frame = _frame_columns(events)
    if frame is not None:
        events = frame
    if columns is not None and not isinstance(events, (np.ndarray, Tensor)) or (
        isinstance(events, np.ndarray) and events.dtype.names is not None and columns is not None
    ):
        raise ValueError(
            "columns= names the columns of an (N, k) array or tensor; mappings, data frames and structured "
            f"arrays are read by name, got {type(events).__name__} with columns={columns!r}"
        )
    if isinstance(events, np.ndarray) and events.dtype.names is not None:
        fields = events.dtype.fields or {}
        found = {c: _field(fields, c) for c in _FIELDS}
        missing = [c for c, f in found.items() if f is None]
        if missing:
            raise ValueError(
                f"events structured array needs fields x, y, t (or timestamp) and p (or on, "
                f"polarity), got {events.dtype.names} (missing {', '.join(missing)})"
            )
        if events.ndim != 1:
            raise ValueError(f"events structured array must be 1-D, got shape {events.shape}")

        def read_struct(i: int, j: int, names: Sequence[str]) -> dict[str, Tensor]:
            return {c: _column(events[found[c]][i:j], c).unsqueeze(0) for c in names}

        return _Source(1, len(events), False, read_struct, cpu), events[found["t"]]
    if isinstance(events, Mapping):
        found = {c: _field(events.keys(), c) for c in _FIELDS}
        missing = [c for c, f in found.items() if f is None]
        if missing:
            raise ValueError(
                f"events mapping needs keys x, y, t (or timestamp) and p (or on, polarity), "
                f"got {sorted(map(str, events))} (missing {', '.join(missing)})"
            )
        data = {c: events[found[c]] for c in _FIELDS}
        data = {c: v if isinstance(v, (Tensor, np.ndarray)) else np.asarray(v) for c, v in data.items()}
        for c, v in data.items():
            if v.ndim != 1:
                raise ValueError(f"events[{c!r}] must be 1-D, got shape {tuple(v.shape)}")
        lengths = {int(v.shape[0]) for v in data.values()}
        if len(lengths) != 1:
            raise ValueError(f"events x, y, t, p must have equal lengths, got {sorted(lengths)}")
        tensors = [v for v in data.values() if isinstance(v, Tensor)]
        device = tensors[0].device if tensors else cpu

        def read_mapping(i: int, j: int, names: Sequence[str]) -> dict[str, Tensor]:
            return {c: _column(data[c][i:j], c).to(device).unsqueeze(0) for c in names}

        return _Source(1, lengths.pop(), False, read_mapping, device), data["t"]
    if not isinstance(events, (np.ndarray, Tensor)):
        raise TypeError(
            "events must be a (N, 4) or (B, N, 4) array or tensor, a mapping of x, y, t, p "
            f"columns, a pandas/polars DataFrame or a numpy structured array, got {type(events).__name__}"
        )
    if events.ndim not in (2, 3):
        raise ValueError(
            f"events: expected (N, 4) or (B, N, 4) rows of (x, y, t, p), got {tuple(events.shape)}"
        )
    order = _order(columns, int(events.shape[-1]))
    if isinstance(events, Tensor) and events.is_complex() or (
        isinstance(events, np.ndarray) and events.dtype.kind not in "biuf"
    ):
        raise TypeError(f"events must hold real numbers, got dtype {events.dtype}")
    batched = events.ndim == 3
    rows = events if batched else events[None]

    def read_rows(i: int, j: int, names: Sequence[str]) -> dict[str, Tensor]:
        return {c: _column(rows[:, i:j, order[_FIELDS.index(c)]], c) for c in names}

    device = events.device if isinstance(events, Tensor) else cpu
    return _Source(int(rows.shape[0]), int(rows.shape[1]), batched, read_rows, device), rows[..., order[2]]


def _columns(
    events: Any, *, time_unit: str | None = None, columns: str | Sequence[str] | None = None
) -> tuple[list[Tensor], bool]:
    """All of x, y, t, p as (B, N) columns at once (t in microseconds), and whether the input was a batch.

    For kernels that need a whole stream in memory (voxel grids, time surfaces); the
    columns are int64 (bool and integer input) or float64, as :func:`_column` makes them.
    """
    source = _source(events, time_unit=time_unit, columns=columns)
    read = source.read(0, source.length, _FIELDS)
    return [read[c] for c in _FIELDS], source.batched


def _pair(value: object, name: str) -> tuple[Any, Any]:
    """Two entries of a size ``(H, W)``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise ValueError(f"{name} must be a pair (H, W), got {value!r}")
    return value[0], value[1]


def _positive_int(value: object, name: str) -> int:
    """An integer >= 1 (Python, numpy or 0-d tensor)."""
    return _integer(value, name)


# --------------------------------------------------------------------------- options


def _integer(value: object, name: str, *, low: int = 1) -> int:
    """A Python, numpy or 0-d tensor integer >= ``low``."""
    if isinstance(value, Tensor) and value.dim() == 0 and not value.is_floating_point():
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Integral) or int(value) < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def _sensor(sensor_size: object, tonic_sensor_size: object) -> tuple[int, int]:
    """(H, W) from ``sensor_size`` (H, W) or ``tonic_sensor_size`` (W, H, P)."""
    if tonic_sensor_size is not None:
        if sensor_size is not None:
            raise ValueError(
                f"give sensor_size (H, W) or tonic_sensor_size (W, H, P), not both; got "
                f"sensor_size={sensor_size!r} and tonic_sensor_size={tonic_sensor_size!r}"
            )
        if isinstance(tonic_sensor_size, (str, bytes)) or not isinstance(tonic_sensor_size, Sequence) or len(
            tonic_sensor_size
        ) != 3:
            raise ValueError(f"tonic_sensor_size must be tonic's (W, H, P), got {tonic_sensor_size!r}")
        width, height, polarities = (_integer(v, "tonic_sensor_size") for v in tonic_sensor_size)
        if polarities != 2:
            raise ValueError(
                f"tonic_sensor_size (W, H, P) must have P = 2 polarities, got {tonic_sensor_size!r}"
            )
        return height, width
    if sensor_size is None:
        return 180, 240  # the paper's DAVIS240
    if isinstance(sensor_size, (str, bytes)) or not isinstance(sensor_size, Sequence):
        raise ValueError(f"sensor_size must be a pair (H, W), got {sensor_size!r}")
    if len(sensor_size) == 3:
        w, h = sensor_size[0], sensor_size[1]
        raise ValueError(
            f"sensor_size is (H, W), height first; got the triple {tuple(sensor_size)!r}, which looks "
            f"like tonic's (W, H, P): pass sensor_size=({h}, {w}) or tonic_sensor_size={tuple(sensor_size)!r}"
        )
    if len(sensor_size) != 2:
        raise ValueError(f"sensor_size must be a pair (H, W), got {sensor_size!r}")
    height, width = (_integer(v, "sensor_size") for v in sensor_size)
    return height, width


def _frame_us(frame_ms: object) -> float | int:
    """Bin width in microseconds: an int when it is a whole number of microseconds."""
    if isinstance(frame_ms, Tensor) and frame_ms.dim() == 0:
        frame_ms = frame_ms.item()
    # a numbers.Real compares like a float (typeshed gives Real no comparison operators)
    if isinstance(frame_ms, (bool, np.bool_)) or not isinstance(frame_ms, Real) or not (
        math.isfinite(frame_ms) and cast(float, frame_ms) > 0
    ):
        raise ValueError(f"frame_ms must be a positive finite number, got {frame_ms!r}")
    width = float(frame_ms) * 1000.0
    whole = round(width)
    return int(whole) if whole >= 1 and abs(width - whole) <= 1e-9 * width else width


def _check_crop(crop: object, height: int, width: int, pool: int) -> tuple[int, int, int, int]:
    if crop is None:
        top, left, crop_h, crop_w = 0, 0, height, width
    else:
        if (
            isinstance(crop, (str, bytes))
            or not isinstance(crop, Sequence)
            or len(crop) != 4
            or any(isinstance(v, (bool, np.bool_)) or not isinstance(v, Integral) for v in crop)
        ):
            raise ValueError(f"crop must be four integers (top, left, height, width), got {crop!r}")
        top, left, crop_h, crop_w = (int(v) for v in crop)
        if top < 0 or left < 0 or crop_h < 1 or crop_w < 1 or top + crop_h > height or (
            left + crop_w > width
        ):
            raise ValueError(
                f"crop (top, left, height, width) must lie inside the sensor ({height}, {width}), "
                f"got {crop!r}"
            )
    if crop_h % pool or crop_w % pool:
        raise ValueError(f"the cropped size ({crop_h}, {crop_w}) must be divisible by pool={pool}")
    return top, left, crop_h, crop_w


def _check_dtype(dtype: object) -> torch.dtype:
    if not isinstance(dtype, torch.dtype) or dtype == torch.bool or dtype.is_complex:
        raise TypeError(f"dtype must be an integer or float torch.dtype, got {dtype!r}")
    if dtype not in FRAME_DTYPES:
        raise TypeError(
            f"dtype must be one the transforms take, {[str(d) for d in FRAME_DTYPES]}, got {dtype} "
            "(torch's unsigned 16/32/64-bit types lack the arithmetic the kernels need)"
        )
    return dtype


def _explicit_starts(t_start: object, batch: int) -> Tensor:
    """A number or (B,) values as a (B,) CPU tensor: int64 if whole numbers, else float64."""
    if isinstance(t_start, Tensor) and t_start.dim() == 0:
        t_start = t_start.item()
    if isinstance(t_start, np.ndarray) and t_start.ndim == 0:
        t_start = t_start.item()
    if isinstance(t_start, (bool, np.bool_)):
        raise TypeError(f"t_start must be 'floor', 'first', a number or one per stream, got {t_start!r}")
    if isinstance(t_start, Real):
        values: list[Any] = [t_start] * batch
    elif isinstance(t_start, (Tensor, np.ndarray, Sequence)) and not isinstance(t_start, (str, bytes)):
        values = t_start.tolist() if isinstance(t_start, (Tensor, np.ndarray)) else list(t_start)
        if len(values) != batch or any(isinstance(v, list) for v in values):
            raise ValueError(f"t_start must be a number or have one entry per stream ({batch}), got {t_start!r}")
    else:
        raise TypeError(f"t_start must be 'floor', 'first', a number or one per stream, got {t_start!r}")
    for v in values:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, Real):
            raise TypeError(f"t_start must hold numbers, got {v!r}")
        if not math.isfinite(v):
            raise ValueError(f"t_start must be finite, got {t_start!r}")
        if abs(cast(float, v)) > _INT64_MAX:  # a numbers.Real (exact for ints past 2**53)
            raise ValueError(f"t_start must lie within int64 microseconds, got {v!r}")
    if all(float(v).is_integer() for v in values):
        return torch.tensor([int(v) for v in values], dtype=torch.int64)
    return torch.tensor([float(v) for v in values], dtype=torch.float64)


def _floor_to_grid(values: Tensor, frame_us: float | int) -> Tensor:
    if isinstance(frame_us, int) and not values.is_floating_point():
        return torch.div(values, frame_us, rounding_mode="floor") * frame_us
    return torch.floor(values.to(torch.float64) / frame_us) * frame_us


def _bin_of(t: Any, start: Any, frame_us: float | int) -> int:
    """:func:`_time_bins` of one time, in Python arithmetic (the same float64 operations)."""
    if isinstance(t, float) or isinstance(start, float):
        return math.floor((float(t) - float(start)) / frame_us)
    if isinstance(frame_us, int):
        return (t - start) // frame_us
    return math.floor(float(t - start) / frame_us)


def _time_bins(t: Tensor, starts: Tensor, frame_us: float | int) -> Tensor:
    """Bin index ``floor((t - start) / frame)`` per event, exact in int64 where possible."""
    starts = starts.to(t.device).unsqueeze(1)
    if isinstance(frame_us, int) and not t.is_floating_point() and not starts.is_floating_point():
        return torch.div(t - starts, frame_us, rounding_mode="floor")
    if not t.is_floating_point() and not starts.is_floating_point():
        return torch.floor((t - starts).to(torch.float64) / frame_us).to(torch.int64)
    return torch.floor((t.to(torch.float64) - starts.to(torch.float64)) / frame_us).to(torch.int64)


# --------------------------------------------------------------------------- binning


@dataclass
class _Grid:
    """Everything a chunk needs to be binned: sensor, crop, pool, bins, dtype."""

    height: int
    width: int
    top: int
    left: int
    crop_h: int
    crop_w: int
    pool: int
    frame_us: float | int
    dtype: torch.dtype

    @property
    def out_h(self) -> int:
        return self.crop_h // self.pool

    @property
    def out_w(self) -> int:
        return self.crop_w // self.pool

    @property
    def frame_size(self) -> int:
        return 2 * self.out_h * self.out_w


def _grid(
    sensor_size: object, tonic_sensor_size: object, crop: object, pool: object, frame_ms: object, dtype: object
) -> _Grid:
    height, width = _sensor(sensor_size, tonic_sensor_size)
    pool = _integer(pool, "pool")
    top, left, crop_h, crop_w = _check_crop(crop, height, width, pool)
    return _Grid(height, width, top, left, crop_h, crop_w, pool, _frame_us(frame_ms), _check_dtype(dtype))


class _Tally:
    """Per-stream counts and ranges gathered while binning, for the errors and the warning."""

    def __init__(self, batch: int) -> None:
        # host counters (numpy: a small torch op costs more than the kernel's passes on a short stream)
        self.events = np.zeros(batch, dtype=np.int64)
        self.in_window = np.zeros(batch, dtype=np.int64)
        self.t_min: list[Any] = [None] * batch
        self.t_max: list[Any] = [None] * batch
        self.outside = 0
        self.x_range: list[Any] = [None, None]
        self.y_range: list[Any] = [None, None]
        self.polarities: set[int] = set()

    def add_times(self, t: Tensor, valid: Tensor | None) -> None:
        """Record the per-stream time range of the valid events of a (B, n) chunk."""
        if t.numel() == 0:
            return
        if valid is None:
            low, high = (v.tolist() for v in torch.aminmax(t, dim=1))
            present = [True] * t.shape[0]
        else:
            big = math.inf if t.is_floating_point() else _INT64_MAX
            low = torch.where(valid, t, torch.full_like(t, big)).amin(dim=1).tolist()
            high = torch.where(valid, t, torch.full_like(t, -big)).amax(dim=1).tolist()
            present = valid.any(dim=1).tolist()
        for b, here in enumerate(present):
            if here:
                self.t_min[b] = low[b] if self.t_min[b] is None else min(self.t_min[b], low[b])
                self.t_max[b] = high[b] if self.t_max[b] is None else max(self.t_max[b], high[b])


def _merge(bounds: list[Any], low: Any, high: Any) -> None:
    bounds[0] = low if bounds[0] is None else min(bounds[0], low)
    bounds[1] = high if bounds[1] is None else max(bounds[1], high)


def _check_polarity(p: Tensor, valid: Tensor | None, tally: _Tally | None = None) -> None:
    """Refuse polarities other than bool, {0, 1} or {-1, 1} (and a mix of 0 and -1 for OFF).

    ``tally`` remembers the OFF values seen in earlier chunks of the same call.
    """
    tally = _Tally(0) if tally is None else tally
    checked = p if valid is None else p[valid]
    if not checked.numel():
        return
    low, high = (v.item() for v in torch.aminmax(checked))
    whole = not checked.is_floating_point() or bool((checked == checked.round()).all())
    if low < -1 or high > 1 or not whole:
        bad = (checked != 0) & (checked != 1) & (checked != -1)
        raise ValueError(
            f"events polarity p must be bool, {{0, 1}} or {{-1, 1}}, got {checked[bad].flatten()[0].item()!r}"
        )
    if low == -1:
        tally.polarities.add(-1)
    if low == 0 or (low == -1 and 0 not in tally.polarities and bool((checked == 0).any())):
        tally.polarities.add(0)
    if tally.polarities == {-1, 0}:
        raise ValueError(
            "events polarity p mixes the {0, 1} and {-1, 1} conventions (it holds both -1 and 0); "
            "OFF must be either 0 or -1"
        )


def _polarity_channel(p: Tensor, valid: Tensor | None, tally: _Tally | None = None) -> Tensor:
    """Channel per event: 1 for ON (p > 0), 0 for OFF (p in {0, -1}); refuses anything else."""
    _check_polarity(p, valid, tally)
    return (p > 0).to(torch.int64)


# The one binning kernel. Every binning path (events_to_frames, iter_frames, bin_events and
# so EventsToFrames) turns columns into flat int32 indices with the same three steps and
# adds ones straight into the output dtype:
#
# * time: ``(t - t_start) / frame`` in float32 (exact for a window under 2**23 µs and whole
#   microsecond bins) or float64 (exact under 2**52 µs), int64 floor division past that;
# * pixel: one gather from an int32 table over the sensor plus a one-pixel border, crop
#   and pool folded in (-1 outside the crop, -2 outside the sensor);
# * count: ``index_add_`` of an expanded one into the output (no int64 buffer, no
#   bincount); only a count that may not fit the output dtype goes through int32 and a
#   checked cast, the one place that reads a maximum.

#: Largest whole number each float dtype counts to exactly.
_EXACT_FLOAT = {torch.float16: 2**11, torch.bfloat16: 2**8, torch.float32: 2**24, torch.float64: 2**53}
#: Pixel table entries: an output pixel ``row * W' + col``, or one of these.
_OUTSIDE_CROP, _OUTSIDE_SENSOR = -1, -2
_TABLES: dict[tuple, Tensor] = {}


def _exact_count(dtype: torch.dtype) -> int:
    """Largest count ``dtype`` holds exactly."""
    return _EXACT_FLOAT[dtype] if dtype.is_floating_point else torch.iinfo(dtype).max


def _accumulator(dtype: torch.dtype, n_events: int) -> torch.dtype:
    """The dtype to count ``n_events`` in: the output's own when no pixel can pass what it
    holds exactly, else int32 (int64 past 2**31 events) and a checked cast at the end."""
    if n_events <= _exact_count(dtype):
        return dtype
    return torch.int32 if n_events < 2**31 else torch.int64


def _pixel_table(grid: _Grid, device: torch.device) -> Tensor:
    """((H + 2) * (W + 2),) int32: the output pixel ``row * W' + col`` of each sensor pixel
    after crop and pool, -1 outside the crop, and a border of -2 (coordinates clamped to
    [-1, H] and [-1, W] land there): one gather replaces the sensor and crop tests and two
    divisions per event."""
    key = (grid.height, grid.width, grid.top, grid.left, grid.crop_h, grid.crop_w, grid.pool, str(device))
    table = _TABLES.get(key)
    if table is None:
        rows = torch.arange(-1, grid.height + 1)
        cols = torch.arange(-1, grid.width + 1)
        on_sensor = ((rows >= 0) & (rows < grid.height)).unsqueeze(1) & ((cols >= 0) & (cols < grid.width)).unsqueeze(0)
        rows, cols = rows - grid.top, cols - grid.left
        keep = ((rows >= 0) & (rows < grid.crop_h)).unsqueeze(1) & ((cols >= 0) & (cols < grid.crop_w)).unsqueeze(0)
        pooled = torch.div(rows, grid.pool, rounding_mode="floor").unsqueeze(1) * grid.out_w + torch.div(
            cols, grid.pool, rounding_mode="floor").unsqueeze(0)
        table = torch.where(keep, pooled, _OUTSIDE_CROP)
        table = torch.where(on_sensor, table, _OUTSIDE_SENSOR).to(torch.int32).reshape(-1).to(device)
        if len(_TABLES) > 32:
            _TABLES.clear()
        _TABLES[key] = table
    return table


def _relative(t: Tensor, starts: Tensor) -> Tensor:
    """``t - start`` (starts broadcast against ``t``): int64 when both are whole, else float64."""
    starts = starts.to(t.device)
    if t.is_floating_point() or starts.is_floating_point():
        return t.to(torch.float64) - starts.to(torch.float64)
    return t - starts


def _bins_of(rel: Tensor, frame_us: float | int, n_frames: int) -> tuple[Tensor, Tensor]:
    """``floor(rel / frame_us)`` and whether ``0 <= rel < n_frames * frame_us``.

    Integer times over a window with ``n_frames * frame_us < 2**23`` (8.4 s): float32 true
    division is correctly rounded, and for whole ``rel`` and ``frame`` the quotient of an
    ``rel`` just below a multiple ``k * frame`` is at least ``1 / frame`` below ``k``, more
    than float32's spacing at ``k`` when ``k * frame < 2**23``; so the floor is exact (4x
    cheaper than int64 floor division on the CPU). The same holds in float64 under
    ``2**52``; past that, int64 floor division. Float times: ``floor`` of the float64
    quotient, as :func:`_time_bins`. The bins are int32 (int64 on the last path) and
    meaningful only where inside (truncation = floor there).
    """
    quotient = _quotient(rel, frame_us, n_frames)
    inside = (quotient >= 0) & (quotient < n_frames)
    return (quotient if quotient.dtype == torch.int64 else quotient.to(torch.int32)), inside


def _quotient(rel: Tensor, frame_us: float | int, n_frames: int) -> Tensor:
    """``rel / frame_us`` in float32 or float64 where that floors exactly (see
    :func:`_bins_of`), else the int64 floor quotient."""
    span = n_frames * frame_us
    if not rel.is_floating_point() and isinstance(frame_us, int) and span >= 2**52:
        return torch.div(rel, frame_us, rounding_mode="floor")
    if isinstance(frame_us, int) and not rel.is_floating_point() and span < 2**23:
        return rel.to(torch.float32).div_(frame_us)
    return rel.to(torch.float64).div_(frame_us)


def _within(values: Tensor, size: int) -> bool:
    """Whether every value lies in ``[0, size)`` (one read-only pass)."""
    low, high = (v.item() for v in torch.aminmax(values))
    return low >= 0 and high < size


def _pixels(col: Tensor, row: Tensor, grid: _Grid, *, look: bool = False) -> Tensor:
    """The pixel table entry of each event (integer coordinates, any shape): int32, the
    output pixel ``row * W' + col``, or -1 off the crop, -2 off the sensor. Coordinates
    are clamped to the table's border; with ``look`` (a per-stream call, which reads values
    anyway) only where one lies past it, on the CPU: a read-only ``aminmax`` is cheaper than
    the clamp's copy of int64 columns. Without it no value is read (the batch kernel stays
    free of host reads)."""
    width = grid.width
    flat = _clamped(row, grid.height, look).to(torch.int32).mul_(width + 2)
    col = _clamped(col, width, look)
    flat.add_(col if col.dtype in (torch.int8, torch.int16, torch.int32) else col.to(torch.int32)).add_(width + 3)
    return _pixel_table(grid, col.device).index_select(0, flat.reshape(-1)).view(flat.shape)


def _clamped(values: Tensor, size: int, look: bool) -> Tensor:
    """``values`` clamped to [-1, size]; unchanged (``look``, on the CPU) when they already lie there."""
    if look and values.device.type == "cpu" and values.numel():
        low, high = (v.item() for v in torch.aminmax(values))
        if low >= -1 and high <= size:
            return values
    return values.clamp(-1, size)


def _tally_outside(tally: _Tally, pixel: Tensor, col: Tensor, row: Tensor, valid: Tensor | None) -> None:
    """Count the (valid) events off the sensor and widen the coordinate ranges the warning names."""
    outside = pixel == _OUTSIDE_SENSOR
    if valid is not None:
        outside &= valid
    n_outside = int(outside.sum())
    if n_outside:
        tally.outside += n_outside
        seen = slice(None) if valid is None else valid
        _merge(tally.x_range, *(int(v) for v in torch.aminmax(col[seen])))
        _merge(tally.y_range, *(int(v) for v in torch.aminmax(row[seen])))


def _event_index(
    col: Tensor, row: Tensor, on: Tensor, rel: Tensor, n_frames: int, grid: _Grid, wide: bool, *, look: bool = False
) -> tuple[Tensor, Tensor, Tensor]:
    """Per event (any shape, integer coordinates): its index inside one stream's
    ``(T, 2, H', W')`` block (int32, int64 if ``wide``; meaningless where not counted), its
    pixel table entry (negative off the crop or sensor) and whether its time is in the window.
    """
    bins, in_time = _bins_of(rel, grid.frame_us, n_frames)
    pixel = _pixels(col, row, grid, look=look)
    index = bins.to(torch.int64) if wide else bins.to(torch.int32)
    index = index.mul_(2).add_(on).mul_(grid.out_h * grid.out_w).add_(pixel)
    return index, pixel, in_time


def _count_chunk(
    counts: Tensor, columns: dict[str, Tensor], valid: Tensor | None, starts: Tensor, n_frames: int, grid: _Grid,
    tally: _Tally, *, in_window: bool = False,
) -> None:
    """Add a (B, n) chunk of columns to ``counts`` (``B * n_frames`` frames, then one spare
    slot where the events not counted go); record the chunk's events in the window and
    off the sensor in ``tally``. ``in_window``: every event's time is known to lie in the
    window (pass 1 read the time ranges).

    The common case, a whole stream on the sensor and in the window with no crop or pool,
    skips the window test, the table and the spare slot: one read-only ``aminmax`` per
    coordinate shows it.
    """
    x, y, p = columns["x"], columns["y"], columns["p"]
    _check_polarity(p, valid, tally)
    col = torch.floor(x) if x.is_floating_point() else x
    row = torch.floor(y) if y.is_floating_point() else y
    rel = _relative(columns["t"], starts.unsqueeze(1))
    spare = counts.numel() - 1
    index_dtype = torch.int64 if spare >= 2**31 else torch.int32
    whole_sensor = (grid.crop_h, grid.crop_w, grid.pool) == (grid.height, grid.width, 1)
    if (
        valid is None and in_window and whole_sensor and x.numel()
        and _within(col, grid.width) and _within(row, grid.height)
    ):
        index = _quotient(rel, grid.frame_us, n_frames).to(index_dtype).mul_(2).add_(p > 0)
        index.mul_(grid.height).add_(row.to(index_dtype)).mul_(grid.width).add_(col.to(index_dtype))
        counted = None
    else:
        index, pixel, in_time = _event_index(
            col, row, p > 0, rel, n_frames, grid, index_dtype == torch.int64, look=True)
        counted = in_time & (pixel >= 0)
        if valid is not None:
            counted &= valid
        if bool(counted.all()):
            counted = None
        else:
            _tally_outside(tally, pixel, col, row, valid)
            if valid is not None:
                in_time &= valid
            tally.in_window += in_time.sum(dim=1).cpu().numpy()
    if x.shape[0] > 1:
        index += torch.arange(x.shape[0], device=x.device, dtype=index.dtype).unsqueeze(1) * (n_frames * grid.frame_size)
    if counted is None:  # every event counts
        tally.in_window += x.shape[1]
    else:
        _to_spare(index, counted, spare)
    _accumulate(counts, index.reshape(-1))


def _to_spare(index: Tensor, counted: Tensor, spare: int) -> Tensor:
    """``index`` where ``counted``, else ``spare``, in place: ``spare + (index - spare) * counted``
    (three vectorised passes; ``torch.where`` and ``masked_fill_`` are 10-20x slower on the CPU)."""
    return index.sub_(spare).mul_(counted).add_(spare)


def _accumulate(counts: Tensor, index: Tensor) -> None:
    """``counts[index] += 1`` for every entry: one ``index_add_`` of an expanded one."""
    if index.numel():
        counts.index_add_(0, index, torch.ones((), dtype=counts.dtype, device=counts.device).expand(index.numel()))


def _as_dtype(counts: Tensor, dtype: torch.dtype) -> Tensor:
    """The counts in ``dtype``; refused by name unless ``dtype`` holds every count exactly."""
    # floats hold every whole number up to 2 / eps exactly (bfloat16: 256, float16: 2048)
    if counts.dtype == dtype:
        return counts
    exact = 2 / torch.finfo(dtype).eps if dtype.is_floating_point else torch.iinfo(dtype).max
    if counts.numel():
        largest = int(counts.max())
        if largest > exact:
            raise ValueError(
                f"a pixel holds {largest:,} events, more than dtype={dtype} holds exactly ({int(exact):,}: "
                f"{largest:,} would become {counts.max().to(dtype).item():,.0f}); use a wider dtype "
                "(torch.float32 or an integer dtype)"
            )
    return counts.to(dtype)


def _check_bytes(
    batch: int, n_frames: int, grid: _Grid, max_bytes: int | None, where: str, n_events: int
) -> None:
    """Refuse, before allocating, a binning that needs more than ``max_bytes``."""
    if max_bytes is None:
        return
    values = batch * n_frames * grid.frame_size
    counting = _accumulator(grid.dtype, n_events)
    needed = values * grid.dtype.itemsize + (values * counting.itemsize if counting != grid.dtype else 0)
    if needed > max_bytes:
        raise ValueError(
            f"events_to_frames: {where} {n_frames:,} frames of {grid.frame_size:,} values"
            f"{f' for {batch} streams' if batch > 1 else ''}, {needed / 1e9:,.1f} GB ({needed:,} bytes)"
            f"{f' with the {counting} counting buffer' if counting != grid.dtype else ''} for the output, more than "
            f"max_bytes={max_bytes:,}. Timestamps must be in microseconds; to bin a long "
            "recording, stream it with iter_frames, pass n_frames for a window, or raise max_bytes"
        )


class _SensorSize(NamedTuple):
    """The two fields of a grid that the sensor warning reads."""

    height: int
    width: int


def _warn_outside(tally: _Tally, total: int, grid: _Grid | _SensorSize, stacklevel: int) -> None:
    if not tally.outside:
        return
    (x_low, x_high), (y_low, y_high) = tally.x_range, tally.y_range
    message = (
        f"{tally.outside:,} of {total:,} events lie outside sensor_size=({grid.height}, {grid.width}) "
        f"(H, W) and were dropped; the events span x = {x_low}..{x_high}, y = {y_low}..{y_high}"
    )
    if x_low >= 0 and y_low >= 0:
        h, w = max(y_high + 1, grid.height), max(x_high + 1, grid.width)
        message += (
            f". If the sensor is ({h}, {w}), pass sensor_size=({h}, {w}) or tonic's "
            f"tonic_sensor_size=({w}, {h}, 2)"
        )
    warnings.warn(EventsOutsideSensorWarning(message), stacklevel=stacklevel)


def _empty_window_error(stream: str, start: Any, t_start: object, frame_ms: object, n_frames: int | None,
                        grid: _Grid, t_min: Any, t_max: Any, count: int) -> ValueError:
    end = "..." if n_frames is None else f"{start + n_frames * grid.frame_us})"
    return ValueError(
        f"no event of {stream} falls in the time window [{start}, {end} µs set by t_start={t_start!r}, "
        f"frame_ms={frame_ms!r}, n_frames={n_frames!r}: its {count:,} events span "
        f"t = {t_min} to {t_max} µs. For absolute timestamps leave t_start='floor' or 'first'; "
        "timestamps must be in microseconds"
    )


def events_to_frames(
    events: Tensor | Mapping[str, Any] | np.ndarray,
    *,
    sensor_size: tuple[int, int] | None = None,
    tonic_sensor_size: tuple[int, int, int] | None = None,
    t_start: str | float | Sequence[float] | Tensor = "floor",
    frame_ms: float = 10.0,
    n_frames: int | None = None,
    crop: tuple[int, int, int, int] | None = None,
    pool: int = 1,
    dtype: torch.dtype = torch.float32,
    lengths: Tensor | Sequence[int] | None = None,
    mask: Tensor | None = None,
    chunk_size: int = CHUNK_EVENTS,
    max_bytes: int | None = MAX_BYTES,
    time_unit: str | None = None,
    columns: str | Sequence[str] | None = None,
) -> Tensor:
    r"""Count events into fixed time bins, one channel per polarity.

    Frame :math:`i` holds the events with
    :math:`t_0 + i\,\Delta \le t < t_0 + (i+1)\,\Delta`, :math:`\Delta` = ``frame_ms``
    milliseconds (timestamps in microseconds), :math:`t_0` set by ``t_start`` (see the
    module docstring for why the default rounds the first event down to the bin grid). Bin
    arithmetic runs in int64 for integer timestamps (exact for uint64 and int64 values up
    to 2**63 - 1 µs), in float64 otherwise. The optional crop keeps the sensor window
    ``(top, left, height, width)``; ``pool = k`` then sums each k×k block (the paper's
    140×150 crop pooled 2×2 gives 70×75). Float coordinates are floored to whole pixels.
    The input is read ``chunk_size`` events at a time and never modified.

    Args:
        events: ``(N, 4)`` rows of ``(x, y, t, p)`` (array or tensor, any integer or float
            dtype; other orders with ``columns``), a ``(B, N, 4)`` batch of padded streams,
            a mapping of columns (an h5py group too), a pandas or polars DataFrame, or a
            numpy structured array (tonic's dtypes, titled fields included). ``p`` is
            bool, {0, 1} or {-1, 1}; anything else raises.
        sensor_size: ``(H, W)`` of the sensor, height first; ``None`` means the paper's
            DAVIS240, (180, 240). Events outside it are dropped with an
            :class:`EventsOutsideSensorWarning`.
        tonic_sensor_size: tonic's ``(W, H, P)`` instead of ``sensor_size``.
        t_start: start of the first bin: ``"floor"`` (the first event rounded down to a
            multiple of the bin width), ``"first"`` (the first event), or a time in
            microseconds; for a batch, one per stream (a (B,) sequence or tensor) or one
            for all. ``"floor"`` and ``"first"`` are taken per stream.
        frame_ms: bin width in milliseconds.
        n_frames: number of bins T; ``None`` makes enough bins to hold the last event (the
            longest stream's, for a batch).
        crop: ``(top, left, height, width)`` window inside the sensor, or ``None`` for the
            whole sensor. Height and width must be multiples of ``pool``.
        pool: side of the square blocks summed into one output pixel.
        dtype: dtype of the counts (float32 by default, as models take float input; any
            integer or float dtype whose range holds the largest count).
        lengths: for a batch, the number of valid events of each stream, shape (B,).
        mask: for a batch, a (B, N) bool tensor marking valid events (instead of lengths).
        chunk_size: events read at a time; the extra memory is a few times this many
            64-bit values plus the output.
        max_bytes: most bytes the binning may allocate (the output,
            ``B·T·2·H'·W'·itemsize``, plus as much again in int32 when more events than
            ``dtype`` counts exactly could meet in one pixel, e.g. float16 past 2,048
            events); more raises ``ValueError`` with the byte count before anything is
            allocated (a 300 s recording in 10 ms bins on a 240×180 sensor needs 10 GB in
            float32). ``None``: no bound. Stream long recordings with
            :func:`iter_frames`.
        time_unit: unit of plain-number timestamps: ``"us"``, ``"ms"``, ``"s"`` or ``"ns"``
            (ns are floored to whole microseconds). ``None`` (default) reads microseconds
            and refuses float timestamps with fractions spanning under 1e6 (they look
            like seconds: pass ``time_unit`` to say what they are), and one stream of at
            least 1,000 integer timestamps spanning under 1e6 with 50 or more events per
            unit (milliseconds, read as microseconds, would fall in one bin). ``timedelta64`` and
            ``datetime64`` columns (pandas, polars ``Duration``/``Datetime``) carry their
            own unit. Float timestamps too coarse to hold microseconds (float32 past
            2**24 µs, about 16.8 s) are refused whatever the unit.
        columns: for ``(N, k)`` or ``(B, N, k)`` rows, what each column holds, e.g.
            ``"txyp"``, with ``"_"`` for a column to skip; ``None`` means ``"xytp"``.

    Shape:
        - events: ``(N, 4)`` (or ``(N, k)`` with ``columns``), ``(B, N, 4)`` or N-long columns.
        - output: ``(T, 2, H', W')``, or ``(B, T, 2, H', W')`` for batched input, with
          ``H' = height // pool``, ``W' = width // pool``.

    Returns:
        The counts, on the events' device (CPU for numpy input).

    Raises:
        ValueError: malformed events, polarity outside bool/{0, 1}/{-1, 1}, a stream with
            events none of which falls in the time window (naming ``t_start``,
            ``frame_ms`` and ``n_frames``), a ``sensor_size`` triple, a crop outside the
            sensor or not divisible by ``pool``, or a count too large for ``dtype``.
        TypeError: events or options of the wrong type.

    Warns:
        EventsOutsideSensorWarning: events lay outside ``sensor_size`` (with counts).

    Example:
        A recording as ``tonic.io.read_aedat4`` returns it, absolute timestamps included:

        >>> import numpy as np
        >>> dvxplorer = [("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")]
        >>> events = np.zeros(4, dtype=dvxplorer)
        >>> events["t"] = 1_700_000_000_004_000 + np.array([0, 6_000, 10_000, 31_000])
        >>> events["x"], events["y"], events["p"] = [1, 1, 2, 319], [0, 0, 1, 239], [1, 0, 1, 1]
        >>> frames = events_to_frames(events, sensor_size=(240, 320))
        >>> frames.shape  # bins from ...000 (floored to 10 ms) to hold the event at +35 ms
        torch.Size([4, 2, 240, 320])
        >>> frames.sum(dim=(2, 3))  # (frame, polarity) totals
        tensor([[0., 1.],
                [1., 1.],
                [0., 0.],
                [0., 1.]])
    """
    source = _source(events, time_unit=time_unit, columns=columns, whole=True)
    grid = _grid(sensor_size, tonic_sensor_size, crop, pool, frame_ms, dtype)
    chunk = max(1, _integer(chunk_size, "chunk_size") // max(source.batch, 1))
    if max_bytes is not None:
        max_bytes = _integer(max_bytes, "max_bytes")
    if n_frames is not None:
        n_frames = _integer(n_frames, "n_frames")
        _check_bytes(source.batch, n_frames, grid, max_bytes, "n_frames asks for", source.batch * source.length)
    if not source.batched and (lengths is not None or mask is not None):
        raise ValueError("lengths and mask apply to a (B, N, 4) batch of events only")
    valid_all = _valid_mask(source.batch, source.length, lengths, mask, source.device)
    batch, length = source.batch, source.length

    def valid_of(i: int, j: int) -> Tensor | None:
        return None if valid_all is None else valid_all[:, i:j]

    if isinstance(t_start, str):
        if t_start not in _T_STARTS:
            raise ValueError(f"t_start must be 'floor', 'first', a number or one per stream, got {t_start!r}")
    else:
        starts = _explicit_starts(t_start, batch)

    # A stream that fits one chunk is read once, for both passes.
    whole = source.read(0, length, _FIELDS) if length <= chunk else None

    def read(i: int, names: Sequence[str]) -> dict[str, Tensor]:
        return whole if whole is not None else source.read(i, i + chunk, names)  # noqa: F821 (deleted after both passes)

    # Pass 1 (only when needed): every stream's time range, for t_start and n_frames.
    ranges = _Tally(batch)
    pass_one = isinstance(t_start, str) or n_frames is None
    if pass_one:
        for i in range(0, length, chunk):
            ranges.add_times(read(i, ("t",))["t"], valid_of(i, i + chunk))
    if isinstance(t_start, str):
        firsts = [0 if v is None else v for v in ranges.t_min]
        starts = torch.tensor(firsts, dtype=torch.float64 if any(isinstance(v, float) for v in firsts) else torch.int64)
        if t_start == "floor":
            starts = _floor_to_grid(starts, grid.frame_us)
    start_values = starts.tolist()
    if n_frames is None:
        n_frames = 0
        for last, start in zip(ranges.t_max, start_values):
            if last is not None and last >= start:
                n_frames = max(n_frames, _bin_of(last, start, grid.frame_us) + 1)
        if n_frames > _MAX_INFERRED_FRAMES:
            raise ValueError(
                f"the events span {n_frames:,} bins of frame_ms={frame_ms!r} (t = {min(v for v in ranges.t_min if v is not None)} "
                f"to {max(v for v in ranges.t_max if v is not None)}); timestamps must be in microseconds. "
                "Pass n_frames to bin a window of that length"
            )
        _check_bytes(batch, n_frames, grid, max_bytes, "the events span", batch * length)

    # Every event's time in the window (pass 1 shows it): the kernel skips the window test.
    in_window = pass_one and all(
        low is None or (low >= start and _bin_of(high, start, grid.frame_us) < n_frames)
        for low, high, start in zip(ranges.t_min, ranges.t_max, start_values)
    )

    # Pass 2: count chunk by chunk straight into the output (and one spare slot).
    tally = _Tally(batch)
    total = batch * n_frames * grid.frame_size
    counts = torch.zeros(total + 1, dtype=_accumulator(grid.dtype, batch * length), device=source.device)

    def bin_chunk(i: int) -> None:  # a function, so that a chunk's temporaries die before the next
        columns = read(i, _FIELDS)
        valid = valid_of(i, i + chunk)
        tally.events += columns["t"].shape[1] if valid is None else valid.sum(dim=1).cpu().numpy()
        _count_chunk(counts, columns, valid, starts, n_frames, grid, tally, in_window=in_window)

    for i in range(0, length, chunk):
        bin_chunk(i)
    del whole

    for b in range(batch):
        if tally.events[b] and not tally.in_window[b]:
            if ranges.t_min[b] is None:  # pass 1 did not run: read the time range for the message
                for i in range(0, length, chunk):
                    ranges.add_times(source.read(i, i + chunk, ("t",))["t"], valid_of(i, i + chunk))
            stream = f"stream {b}" if source.batched else "the stream"
            raise _empty_window_error(
                stream, starts[b].item(), t_start if not isinstance(t_start, (Tensor, np.ndarray)) else "(per stream)",
                frame_ms, n_frames, grid, ranges.t_min[b], ranges.t_max[b], int(tally.events[b])
            )
    _warn_outside(tally, int(tally.events.sum()), grid, stacklevel=3)
    dropped = (tally.events - tally.in_window).tolist()
    if any(dropped):
        streams = [f"{d:,} of {e:,}" for d, e in zip(dropped, tally.events.tolist())]
        where = f"per stream: {', '.join(streams)}" if source.batched else streams[0]
        warnings.warn(
            EventsOutsideWindowWarning(
                f"{sum(dropped):,} events lie outside the window t_start={t_start!r}, n_frames={n_frames} of "
                f"frame_ms={frame_ms!r} and were dropped ({where})"
                + (
                    "; with t_start='floor' the grid starts before the first event, so a window of n_frames "
                    "may need one more frame" if t_start == "floor" else ""
                )
            ),
            stacklevel=2,
        )
    frames = _as_dtype(counts[:total], grid.dtype).view(batch, n_frames, 2, grid.out_h, grid.out_w)
    return frames if source.batched else frames.squeeze(0)


def _valid_mask(
    batch: int, length: int, lengths: Any, mask: Any, device: torch.device
) -> Tensor | None:
    if lengths is not None and mask is not None:
        raise ValueError("give either lengths or mask, not both")
    if mask is not None:
        mask = torch.as_tensor(mask, device=device)
        if mask.dtype != torch.bool or tuple(mask.shape) != (batch, length):
            raise ValueError(
                f"mask must be a bool tensor of shape ({batch}, {length}), "
                f"got shape {tuple(mask.shape)} and dtype {mask.dtype}"
            )
        return mask
    if lengths is not None:
        lengths = torch.as_tensor(lengths, device=device)
        if lengths.dtype.is_floating_point or lengths.dtype == torch.bool:
            raise TypeError(f"lengths must hold integers, got dtype {lengths.dtype}")
        if tuple(lengths.shape) != (batch,):
            raise ValueError(f"lengths must have shape ({batch},), got {tuple(lengths.shape)}")
        if batch and bool(((lengths < 0) | (lengths > length)).any()):
            raise ValueError(f"lengths must lie in [0, {length}], got {lengths.tolist()}")
        return torch.arange(length, device=device) < lengths.unsqueeze(1)
    return None
