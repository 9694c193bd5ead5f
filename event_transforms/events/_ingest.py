"""Events in memory to canonical columns (private to :mod:`event_transforms.events`).

Every input form the binning and :class:`~event_transforms.EventBatch` take — an ``(N, 4)`` or
``(B, N, 4)`` array or tensor (``columns=`` names another order), a mapping of columns, a
numpy structured array (tonic's dtypes included), a pandas or polars DataFrame — becomes the
columns ``x, y, t, p``: names found through one alias table, timestamps in microseconds
(``time_unit=``, ``timedelta64``/``datetime64`` units; seconds-like floats refused by name),
polarity checked. The checks of the binning's settings (sensor size, ``frame_ms``, crop,
dtype) live here too, so the batch, the binning and the streaming share them without
importing each other. File readers are in :mod:`event_transforms.events.io`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, cast

import numpy as np
import torch
from torch import Tensor
from .._validation import FRAME_DTYPES

#: The largest int64, the bound of integer timestamps.
_INT64_MAX = 2**63 - 1


_FIELDS = ("x", "y", "t", "p")


#: Names under which each column is looked up, in order.
_ALIASES = {"x": ("x",), "y": ("y",), "t": ("t", "timestamp"), "p": ("p", "on", "polarity")}


T_START_RULES = ("floor", "first")


#: Microseconds per unit of ``time_unit``.
TIME_UNITS: dict[str, float | int] = {"ns": 1e-3, "us": 1, "ms": 1_000, "s": 1_000_000}


#: Float timestamps with a fractional part spanning less than this (in the unit read, 1 s of
#: microseconds) look like seconds: refused unless ``time_unit`` is given.
SECONDS_SPAN = 1e6


#: Values read to decide whether float timestamps have fractional parts.
_FRACTION_PROBE = 1 << 16


def check_time_unit(time_unit: object) -> str | None:
    if time_unit is None:
        return None
    if not isinstance(time_unit, str) or time_unit not in TIME_UNITS:
        raise ValueError(f"time_unit must be one of {', '.join(map(repr, TIME_UNITS))} or None, got {time_unit!r}")
    return time_unit


def _time_typed(array: np.ndarray, name: str, time_unit: str | None) -> tuple[np.ndarray, str]:
    """A ``timedelta64``/``datetime64`` column as int64 counts of its own unit (checked)."""
    unit, count = np.datetime_data(array.dtype)
    if unit not in TIME_UNITS or count != 1:
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
    scale = TIME_UNITS[unit or "us"]
    magnitude = max(abs(low), abs(high))
    spacing_us = 2.0 ** math.floor(math.log2(magnitude)) * eps * scale if magnitude else 0.0
    if spacing_us > 1:
        raise ValueError(
            f"events['t'] is {dtype_name} with values up to {magnitude:.7g} {unit or 'us'}, where {dtype_name} "
            f"steps {spacing_us:g} us: the timestamps have already lost microseconds. Read them as int64 or "
            "float64 (or subtract the first timestamp before casting)"
        )
    count = int(t.numel()) if isinstance(t, Tensor) else int(np.asarray(t).size)
    span_us = (high - low) * scale
    if unit is not None and fractional and count >= _RATE_EVENTS and 0 < span_us * _MAX_RATE < count:
        raise ValueError(
            f"events['t'] under time_unit={unit!r}: {count:,} events span {high - low:.6g} {unit} "
            f"({count / span_us * 1e6:.3g} events per second, past any sensor), so every event would fall in "
            f"one bin; the timestamps look like {_larger_unit(unit)}: pass time_unit= the unit they are in"
        )
    if unit is None and fractional and high - low < SECONDS_SPAN:
        raise ValueError(
            f"events['t'] holds float timestamps with fractions spanning {high - low:.6g}, which looks like "
            "seconds (timestamps are read as microseconds, so every event would fall in one bin); pass "
            "time_unit='s' (or 'ms', 'ns'), or time_unit='us' if they are microseconds"
        )


#: Whole recordings of at least this many events ...
_RATE_EVENTS = 1000
#: ... at more than this many events per microsecond (1e9 events per second, past any event
#: camera's bandwidth) hold timestamps in a larger unit than the one declared.
_MAX_RATE = 1000

#: Integer timestamps past this (1e17 µs since the epoch is the year 5138) are nanoseconds.
_NANOSECOND_EPOCH = 10**17


def _larger_unit(unit: str) -> str:
    """The units larger than ``unit``, in words."""
    larger = [u for u in TIME_UNITS if TIME_UNITS[u] > TIME_UNITS[unit]]
    return " or ".join(f"{'seconds' if u == 's' else u}" for u in reversed(larger)) or "seconds"


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


def millisecond_advice(count: int, first: float, last: float) -> str | None:
    """Why integer timestamps look like milliseconds read as microseconds, or ``None``."""
    span = last - first
    if count < _MS_EVENTS or not _MS_MIN_SPAN <= span < _MS_SPAN or count < _MS_RATE * (span + 1):
        return None
    rate = count / (span + 1)
    return (f"{count:,} integer timestamps spanning {span:,.0f} look like milliseconds, not microseconds "
            f"({rate:.0f} events per unit: {rate:.3g} million events per second as microseconds, a "
            f"{span / 1000:.3g} s recording as milliseconds)")


def _check_integer_times(t: Any, unit: str | None) -> None:
    """Refuse a 1-D integer timestamp column on the CPU that looks like milliseconds, or like
    nanoseconds since the epoch (``unit`` None; the first and last values and the count only)."""
    if unit is not None or getattr(t, "ndim", 0) != 1 or not len(t):
        return
    if isinstance(t, Tensor):
        if t.is_floating_point() or t.device.type != "cpu" or t.dtype == torch.bool:
            return
    elif np.asarray(t[:1]).dtype.kind not in "iu":
        return
    first = int(t[0])
    if first > _NANOSECOND_EPOCH:
        raise ValueError(
            f"events['t'] starts at {first:,}, which as microseconds since the epoch is the year "
            f"{1970 + first / 3.15576e13:,.0f}: absolute timestamps this large are nanoseconds. Pass time_unit='ns'"
        )
    if len(t) < _MS_EVENTS:
        return
    advice = millisecond_advice(len(t), float(t[0]), float(t[-1]))
    if advice is not None:
        raise ValueError(f"events['t']: {advice}; pass time_unit='ms', or time_unit='us' if they are microseconds")


def to_microseconds(t: Tensor, unit: str) -> Tensor:
    """An int64/float64 timestamp column in ``unit`` as microseconds (ns are floored to whole µs)."""
    if unit == "us":
        return t
    if unit == "ns":
        return t / 1000 if t.is_floating_point() else torch.div(t, 1000, rounding_mode="floor")
    factor = int(TIME_UNITS[unit])
    if t.is_floating_point():
        return t * factor
    if t.numel() and int(t.abs().max()) > _INT64_MAX // factor:
        raise ValueError(f"events['t'] in {unit} holds {int(t.abs().max())}, past what int64 microseconds hold")
    return t * factor


def _field(names: Iterable[str], column: str) -> str | None:
    """The name under which ``column`` is stored, or None."""
    names = set(names)
    return next((alias for alias in _ALIASES[column] if alias in names), None)


def column_order(columns: object) -> list[str]:
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
    names = column_order(columns)
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
    time_unit = check_time_unit(time_unit)
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
            out["t"] = to_microseconds(out["t"], unit)
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


def canonical_columns(
    events: Any, *, time_unit: str | None = None, columns: str | Sequence[str] | None = None
) -> tuple[list[Tensor], bool]:
    """All of x, y, t, p as (B, N) columns at once (t in microseconds), and whether the input was a batch.

    For kernels that need a whole stream in memory (voxel grids, time surfaces); the
    columns are int64 (bool and integer input) or float64, as :func:`_column` makes them.
    """
    source = _source(events, time_unit=time_unit, columns=columns)
    read = source.read(0, source.length, _FIELDS)
    return [read[c] for c in _FIELDS], source.batched


def size_pair(value: object, name: str) -> tuple[Any, Any]:
    """Two entries of a size ``(H, W)``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise ValueError(f"{name} must be a pair (H, W), got {value!r}")
    return value[0], value[1]


def positive_int(value: object, name: str) -> int:
    """An integer >= 1 (Python, numpy or 0-d tensor)."""
    return check_integer(value, name)


def check_integer(value: object, name: str, *, low: int = 1) -> int:
    """A Python, numpy or 0-d tensor integer >= ``low``."""
    if isinstance(value, Tensor) and value.dim() == 0 and not value.is_floating_point():
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Integral) or int(value) < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def _sensor(sensor_size: object, tonic_sensor_size: object, owner: str = "events_to_frames") -> tuple[int, int]:
    """(H, W) from ``sensor_size`` (H, W) or ``tonic_sensor_size`` (W, H, P); one of them is required."""
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
        width, height, polarities = (check_integer(v, "tonic_sensor_size") for v in tonic_sensor_size)
        if polarities != 2:
            raise ValueError(
                f"tonic_sensor_size (W, H, P) must have P = 2 polarities, got {tonic_sensor_size!r}"
            )
        return height, width
    if sensor_size is None:
        raise TypeError(
            f"{owner} needs sensor_size=(H, W) or tonic_sensor_size=(W, H, P): real sensors differ "
            "(DAVIS240 (180, 240), DVXplorer (240, 320)), and a wrong size drops events; "
            "event_transforms.events.stated_sensor_size(path) reads it from a file that states it"
        )
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
    height, width = (check_integer(v, "sensor_size") for v in sensor_size)
    return height, width


def bin_width_us(frame_ms: object) -> float | int:
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
        raise ValueError(f"the cropped size ({crop_h}, {crop_w}) must be divisible by pool={pool} (multiples of pool)")
    return top, left, crop_h, crop_w


#: The one crop check, for the application's readers of recordings too.
check_crop_window = _check_crop


def _check_dtype(dtype: object) -> torch.dtype:
    if not isinstance(dtype, torch.dtype) or dtype == torch.bool or dtype.is_complex:
        raise TypeError(f"dtype must be an integer or float torch.dtype, got {dtype!r}")
    if dtype not in FRAME_DTYPES:
        raise TypeError(
            f"dtype must be one the transforms take, {[str(d) for d in FRAME_DTYPES]}, got {dtype} "
            "(torch's unsigned 16/32/64-bit types lack the arithmetic the kernels need)"
        )
    return dtype


def _check_polarity(p: Tensor, valid: Tensor | None, seen: set[int] | None = None) -> None:
    """Refuse polarities other than bool, {0, 1} or {-1, 1} (and a mix of 0 and -1 for OFF).

    ``seen`` remembers the OFF values found in earlier chunks of the same call (updated here).
    """
    seen = set() if seen is None else seen
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
        seen.add(-1)
    if low == 0 or (low == -1 and 0 not in seen and bool((checked == 0).any())):
        seen.add(0)
    if seen == {-1, 0}:
        raise ValueError(
            "events polarity p mixes the {0, 1} and {-1, 1} conventions (it holds both -1 and 0); "
            "OFF must be either 0 or -1"
        )


def explicit_starts(t_start: object, batch: int) -> Tensor:
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
