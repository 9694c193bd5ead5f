"""Accumulate event streams (x, y, t, p) into event frames (T, 2, H, W).

Events come as a ``(N, 4)`` array or tensor of ``(x, y, t, p)`` rows (any integer or float
dtype, uint64 included), a ``(B, N, 4)`` batch of padded streams with ``lengths`` or
``mask``, a mapping of columns, or a numpy structured array, tonic's own dtypes included:
``tonic.io.read_aedat4`` returns ``[('t', '<u8'), ('x', '<u2'), ('y', '<u2'),
(('p', 'on'), '?')]``, whose polarity field is named ``on`` and titled ``p``. Columns are
found by name: ``x``, ``y``, ``t`` (or ``timestamp``), ``p`` (or ``on``, ``polarity``).
Timestamps are in microseconds; polarity is bool, {0, 1} or {-1, 1}, with ON (``True``,
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
from typing import Any

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


#: Default bound of the memory :func:`events_to_frames` may allocate (its int64 buffer
#: plus the output), in bytes: 4 GiB. A longer recording is refused by name, quickly.
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
        else:
            raise TypeError(f"events[{name!r}] must hold numbers, got numpy dtype {array.dtype}")
        column = torch.from_numpy(np.ascontiguousarray(array))
    if column.is_floating_point() and column.numel() and not bool(torch.isfinite(column).all()):
        raise ValueError(f"events[{name!r}] must be finite, got NaN or Inf")
    return column


def _field(names: Iterable[str], column: str) -> str | None:
    """The name under which ``column`` is stored, or None."""
    names = set(names)
    return next((alias for alias in _ALIASES[column] if alias in names), None)


@dataclass
class _Source:
    """Events of B streams of length N, read ``(start, stop)`` along N as columns (B, n)."""

    batch: int
    length: int
    batched: bool
    read: Callable[[int, int, Sequence[str]], dict[str, Tensor]]
    device: torch.device


def _source(events: Any) -> _Source:
    """Wrap any accepted form of ``events`` without converting it as a whole."""
    cpu = torch.device("cpu")
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

        return _Source(1, len(events), False, read_struct, cpu)
    if isinstance(events, Mapping):
        found = {c: _field(events.keys(), c) for c in _FIELDS}
        missing = [c for c, f in found.items() if f is None]
        if missing:
            raise ValueError(
                f"events mapping needs keys x, y, t (or timestamp) and p (or on, polarity), "
                f"got {sorted(map(str, events))} (missing {', '.join(missing)})"
            )
        columns = {c: events[found[c]] for c in _FIELDS}
        columns = {c: v if isinstance(v, (Tensor, np.ndarray)) else np.asarray(v) for c, v in columns.items()}
        for c, v in columns.items():
            if v.ndim != 1:
                raise ValueError(f"events[{c!r}] must be 1-D, got shape {tuple(v.shape)}")
        lengths = {int(v.shape[0]) for v in columns.values()}
        if len(lengths) != 1:
            raise ValueError(f"events x, y, t, p must have equal lengths, got {sorted(lengths)}")
        tensors = [v for v in columns.values() if isinstance(v, Tensor)]
        device = tensors[0].device if tensors else cpu

        def read_mapping(i: int, j: int, names: Sequence[str]) -> dict[str, Tensor]:
            return {c: _column(columns[c][i:j], c).to(device).unsqueeze(0) for c in names}

        return _Source(1, lengths.pop(), False, read_mapping, device)
    if not isinstance(events, (np.ndarray, Tensor)):
        raise TypeError(
            "events must be a (N, 4) or (B, N, 4) array or tensor, a mapping of x, y, t, p "
            f"columns or a numpy structured array, got {type(events).__name__}"
        )
    if events.ndim not in (2, 3) or events.shape[-1] != 4:
        raise ValueError(
            f"events: expected (N, 4) or (B, N, 4) rows of (x, y, t, p), got {tuple(events.shape)}"
        )
    if isinstance(events, Tensor) and events.is_complex() or (
        isinstance(events, np.ndarray) and events.dtype.kind not in "biuf"
    ):
        raise TypeError(f"events must hold real numbers, got dtype {events.dtype}")
    batched = events.ndim == 3
    rows = events if batched else events[None]

    def read_rows(i: int, j: int, names: Sequence[str]) -> dict[str, Tensor]:
        return {c: _column(rows[:, i:j, _FIELDS.index(c)], c) for c in names}

    device = events.device if isinstance(events, Tensor) else cpu
    return _Source(int(rows.shape[0]), int(rows.shape[1]), batched, read_rows, device)


def _columns(events: Any) -> tuple[list[Tensor], bool]:
    """All of x, y, t, p as (B, N) columns at once, and whether the input was a batch.

    For kernels that need a whole stream in memory (voxel grids, time surfaces); the
    columns are int64 (bool and integer input) or float64, as :func:`_column` makes them.
    """
    source = _source(events)
    columns = source.read(0, source.length, _FIELDS)
    return [columns[c] for c in _FIELDS], source.batched


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
    if isinstance(frame_ms, (bool, np.bool_)) or not isinstance(frame_ms, Real) or not (
        math.isfinite(frame_ms) and frame_ms > 0
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
        if abs(v) > _INT64_MAX:
            raise ValueError(f"t_start must lie within int64 microseconds, got {v!r}")
    if all(float(v).is_integer() for v in values):
        return torch.tensor([int(v) for v in values], dtype=torch.int64)
    return torch.tensor([float(v) for v in values], dtype=torch.float64)


def _floor_to_grid(values: Tensor, frame_us: float | int) -> Tensor:
    if isinstance(frame_us, int) and not values.is_floating_point():
        return torch.div(values, frame_us, rounding_mode="floor") * frame_us
    return torch.floor(values.to(torch.float64) / frame_us) * frame_us


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


def _grid(sensor_size, tonic_sensor_size, crop, pool, frame_ms, dtype) -> _Grid:
    height, width = _sensor(sensor_size, tonic_sensor_size)
    pool = _integer(pool, "pool")
    top, left, crop_h, crop_w = _check_crop(crop, height, width, pool)
    return _Grid(height, width, top, left, crop_h, crop_w, pool, _frame_us(frame_ms), _check_dtype(dtype))


class _Tally:
    """Per-stream counts and ranges gathered while binning, for the errors and the warning."""

    def __init__(self, batch: int) -> None:
        self.events = torch.zeros(batch, dtype=torch.int64)
        self.in_window = torch.zeros(batch, dtype=torch.int64)
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
            low, high = t.amin(dim=1).tolist(), t.amax(dim=1).tolist()
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


def _polarity_channel(p: Tensor, valid: Tensor | None, tally: _Tally | None = None) -> Tensor:
    """Channel per event: 1 for ON (p > 0), 0 for OFF (p in {0, -1}); refuses anything else.

    ``tally`` remembers the OFF values seen in earlier chunks of the same call.
    """
    tally = _Tally(0) if tally is None else tally
    checked = p if valid is None else p[valid]
    if checked.numel():
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
    return (p > 0).to(torch.int64)


def _flat_index(
    columns: dict[str, Tensor], valid: Tensor | None, bins: Tensor, n_frames: int | None, grid: _Grid,
    tally: _Tally, *, within_frame: bool = False,
) -> tuple[Tensor, Tensor | None]:
    """For a (B, n) chunk: the kept events' flat index into (B, T, 2, H', W') (and their bins).

    With ``within_frame`` the index leaves out the sample and frame (it is the index
    within one frame, ``2 * H' * W'`` values) and the kept events' bins come with it;
    ``n_frames=None`` (only then) keeps every bin from 0 on.
    """
    x, y, p = columns["x"], columns["y"], columns["p"]
    channel = _polarity_channel(p, valid, tally)
    col = torch.floor(x).to(torch.int64) if x.is_floating_point() else x
    row = torch.floor(y).to(torch.int64) if y.is_floating_point() else y
    inside = (col >= 0) & (col < grid.width) & (row >= 0) & (row < grid.height)
    outside = ~inside if valid is None else (~inside & valid)
    n_outside = int(outside.sum())
    if n_outside:
        tally.outside += n_outside
        seen = slice(None) if valid is None else valid
        _merge(tally.x_range, int(col[seen].min()), int(col[seen].max()))
        _merge(tally.y_range, int(row[seen].min()), int(row[seen].max()))
    in_time = bins >= 0
    if n_frames is not None:
        in_time &= bins < n_frames
    if valid is not None:
        in_time &= valid
    tally.in_window += in_time.sum(dim=1).cpu()
    if (grid.crop_h, grid.crop_w) == (grid.height, grid.width):
        keep = inside & in_time
    else:
        keep = (col >= grid.left) & (col < grid.left + grid.crop_w) & (row >= grid.top) & (row < grid.top + grid.crop_h)
        keep &= in_time
    if grid.top or grid.left:
        row, col = row - grid.top, col - grid.left
    if grid.pool > 1:
        row, col = row // grid.pool, col // grid.pool
    pixel = (channel * grid.out_h + row) * grid.out_w + col
    if within_frame:
        return pixel[keep], bins[keep]
    if x.shape[0] > 1:
        bins = bins + torch.arange(x.shape[0], device=x.device).unsqueeze(1) * n_frames
    return (bins * grid.frame_size + pixel)[keep], None


def _accumulate(counts: Tensor, index: Tensor) -> None:
    """``counts[index] += 1`` for every entry, with one bincount over the touched range."""
    if index.numel() == 0:
        return
    low, high = int(index.min()), int(index.max())
    counts[low : high + 1] += torch.bincount(index - low, minlength=high - low + 1)


def _as_dtype(counts: Tensor, dtype: torch.dtype) -> Tensor:
    """The int64 counts in ``dtype``; refused by name unless ``dtype`` holds every count exactly."""
    # floats hold every whole number up to 2 / eps exactly (bfloat16: 256, float16: 2048)
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


def _check_bytes(batch: int, n_frames: int, grid: _Grid, max_bytes: int | None, where: str) -> None:
    """Refuse, before allocating, a binning that needs more than ``max_bytes``."""
    if max_bytes is None:
        return
    values = batch * n_frames * grid.frame_size
    needed = values * (8 + (torch.finfo(grid.dtype).bits if grid.dtype.is_floating_point else torch.iinfo(grid.dtype).bits) // 8)
    if needed > max_bytes:
        raise ValueError(
            f"events_to_frames: {where} {n_frames:,} frames of {grid.frame_size:,} values"
            f"{f' for {batch} streams' if batch > 1 else ''}, {needed / 1e9:,.1f} GB ({needed:,} bytes) with the "
            f"int64 buffer, more than max_bytes={max_bytes:,}. Timestamps must be in microseconds; to bin a long "
            "recording, stream it with iter_frames, pass n_frames for a window, or raise max_bytes"
        )


def _warn_outside(tally: _Tally, total: int, grid: _Grid, stacklevel: int) -> None:
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
            dtype), a ``(B, N, 4)`` batch of padded streams, a mapping of columns, or a
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
        max_bytes: most bytes the binning may allocate (an int64 buffer and the output,
            ``B·T·2·H'·W'·(8 + itemsize)``); more raises ``ValueError`` with the byte count
            before anything is allocated (a 300 s recording in 10 ms bins on a 240×180
            sensor needs 31 GB). ``None``: no bound. Stream long recordings with
            :func:`iter_frames`.

    Shape:
        - events: ``(N, 4)``, ``(B, N, 4)`` or N-long columns.
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
    source = _source(events)
    grid = _grid(sensor_size, tonic_sensor_size, crop, pool, frame_ms, dtype)
    chunk = max(1, _integer(chunk_size, "chunk_size") // max(source.batch, 1))
    if max_bytes is not None:
        max_bytes = _integer(max_bytes, "max_bytes")
    if n_frames is not None:
        n_frames = _integer(n_frames, "n_frames")
        _check_bytes(source.batch, n_frames, grid, max_bytes, "n_frames asks for")
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

    # Pass 1 (only when needed): every stream's time range, for t_start and n_frames.
    ranges = _Tally(batch)
    if isinstance(t_start, str) or n_frames is None:
        for i in range(0, length, chunk):
            ranges.add_times(source.read(i, i + chunk, ("t",))["t"], valid_of(i, i + chunk))
    if isinstance(t_start, str):
        firsts = [0 if v is None else v for v in ranges.t_min]
        starts = torch.tensor(firsts, dtype=torch.float64 if any(isinstance(v, float) for v in firsts) else torch.int64)
        if t_start == "floor":
            starts = _floor_to_grid(starts, grid.frame_us)
    if n_frames is None:
        n_frames = 0
        for b, last in enumerate(ranges.t_max):
            if last is not None and last >= starts[b].item():
                last_t = torch.tensor([[last]], dtype=torch.float64 if isinstance(last, float) else torch.int64)
                last_bin = int(_time_bins(last_t, starts[b : b + 1], grid.frame_us))
                n_frames = max(n_frames, last_bin + 1)
        if n_frames > _MAX_INFERRED_FRAMES:
            raise ValueError(
                f"the events span {n_frames:,} bins of frame_ms={frame_ms!r} (t = {min(v for v in ranges.t_min if v is not None)} "
                f"to {max(v for v in ranges.t_max if v is not None)}); timestamps must be in microseconds. "
                "Pass n_frames to bin a window of that length"
            )
        _check_bytes(batch, n_frames, grid, max_bytes, "the events span")

    # Pass 2: bin chunk by chunk into one int64 buffer.
    tally = _Tally(batch)
    counts = torch.zeros(batch * n_frames * grid.frame_size, dtype=torch.int64, device=source.device)

    def bin_chunk(i: int) -> None:  # a function, so that a chunk's temporaries die before the next
        columns = source.read(i, i + chunk, _FIELDS)
        valid = valid_of(i, i + chunk)
        tally.events += (torch.full((batch,), columns["t"].shape[1]) if valid is None else valid.sum(dim=1).cpu())
        bins = _time_bins(columns["t"], starts, grid.frame_us)
        index, _ = _flat_index(columns, valid, bins, n_frames, grid, tally)
        _accumulate(counts, index)

    for i in range(0, length, chunk):
        bin_chunk(i)

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
    frames = _as_dtype(counts, grid.dtype).view(batch, n_frames, 2, grid.out_h, grid.out_w)
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
