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
float timestamps too large for their dtype to hold microseconds (float32 past 2**24 µs).
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

__all__ = ["events_to_frames", "bin_events", "EventsOutsideSensorWarning", "EventsOutsideWindowWarning", "CHUNK_EVENTS", "MAX_BYTES"]

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from .batch import EventBatch, _resolve_starts, _segment_first
from .drops import EventsOutsideSensorWarning, EventsOutsideWindowWarning, counting, record_dropped, warn_at_caller
from .ingest import (
    _FIELDS, _INT64_MAX, _T_STARTS, _check_crop, _check_dtype, _check_polarity, _explicit_starts, _floor_to_grid,
    _frame_us, _integer, _sensor, _source,
)

#: Events read per chunk by default: the extra memory of a call is a few times this many
#: 64-bit values plus the output.
CHUNK_EVENTS = 2**20

#: Largest number of bins ``n_frames=None`` infers before it asks for ``n_frames`` (a
#: recording in nanoseconds read as microseconds spans 1,000 times too many bins).
_MAX_INFERRED_FRAMES = 100_000


#: Default bound of the memory :func:`events_to_frames` may allocate (the output, plus an
#: int32 counting buffer when the dtype may not hold a count exactly), in bytes: 4 GiB. A longer recording is refused by name, quickly.
MAX_BYTES = 2**32


# --------------------------------------------------------------------------- columns


# --------------------------------------------------------------------------- options


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


def _polarity_channel(p: Tensor, valid: Tensor | None, tally: _Tally | None = None) -> Tensor:
    """Channel per event: 1 for ON (p > 0), 0 for OFF (p in {0, -1}); refuses anything else."""
    _check_polarity(p, valid, None if tally is None else tally.polarities)
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
    _check_polarity(p, valid, tally.polarities)
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


def _warn_outside(tally: _Tally, total: int, grid: _Grid | _SensorSize) -> None:
    """The caller's input held events outside the sensor: one warning at the caller's line."""
    if not tally.outside:
        return
    warn_at_caller(EventsOutsideSensorWarning(
        tally.outside, total, (grid.height, grid.width), tuple(tally.x_range), tuple(tally.y_range)))


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
            like seconds: pass ``time_unit`` to say what they are). ``timedelta64`` and
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
    source = _source(events, time_unit=time_unit, columns=columns)
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
    _warn_outside(tally, int(tally.events.sum()), grid)
    dropped = (tally.events - tally.in_window).tolist()
    if any(dropped):
        warn_at_caller(EventsOutsideWindowWarning(
            sum(dropped), int(tally.events.sum()), list(zip(dropped, tally.events.tolist())),
            f"t_start={t_start!r}, n_frames={n_frames} of frame_ms={frame_ms!r}",
            "with t_start='floor' the grid starts before the first event, so a window of n_frames may need one "
            "more frame" if t_start == "floor" else ""))
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


def bin_events(
    batch: EventBatch,
    *,
    frame_ms: float | None = None,
    t_start: str | float | Sequence[float] | Tensor = "floor",
    n_frames: int | None = None,
    crop: tuple[int, int, int, int] | None = None,
    pool: int = 1,
    dtype: torch.dtype = torch.float32,
) -> Tensor:
    """Count an :class:`EventBatch` into frames ``(B, T, 2, H', W')`` on its device.

    Bin by bin equal to :func:`~event_transforms.functional.events_to_frames` of each
    stream with the same ``t_start``, ``frame_ms``, ``n_frames``, ``crop`` and ``pool``
    (and the same bin arithmetic: int64 for integer timestamps). If the batch carries a
    frame grid, its starts are used (``t_start`` is ignored, ``frame_ms`` must match or be
    ``None``, ``n_frames`` defaults to the grid's). Events outside the crop are left out by
    request; events outside the sensor or the time window (a transform may have moved them
    there) are dropped with an :class:`EventsOutsideSensorWarning` or
    :class:`EventsOutsideWindowWarning` that gives their count, as :func:`events_to_frames` does.

    One scatter for the whole batch: int32 linear indices (int64 past 2**31 slots), an
    event outside the window, sensor or crop counted in one spare slot, one ``index_add_``
    of ones straight into the output dtype (when every count fits it exactly; else int32
    and a checked cast), by the kernel of ``events_to_frames``. No ``bincount`` (on accelerators it reads its maximum back). No
    host synchronisation, except the one read of the dropped counts for the warnings, ``n_frames=None`` without a grid (the last bin is read
    back) and ``t_start="floor"``/``"first"`` without a grid (the first events).

    Args:
        batch: the event streams.
        frame_ms: bin width in milliseconds (the grid's, or required without a grid).
        t_start: the start rule without a grid: ``"floor"``, ``"first"``, or a time in
            microseconds (one number or one per stream).
        n_frames: number of bins (default: the grid's, or enough for the last event).
        crop: ``(top, left, height, width)`` window inside the sensor, or ``None``.
        pool: side of the square blocks summed into one output pixel.
        dtype: dtype of the counts.

    Shape:
        - batch: B streams on a ``(H, W)`` sensor.
        - output: ``(B, T, 2, H', W')`` on the batch's device, ``(H', W')`` the crop divided by
          ``pool``.

    Example:
        >>> batch = EventBatch(torch.tensor([0, 2], dtype=torch.int16), torch.tensor([1, 0], dtype=torch.int16),
        ...     torch.tensor([5, 15_000]), torch.tensor([1, 0], dtype=torch.int8), torch.tensor([0, 1, 2]), (2, 3))
        >>> bin_events(batch, frame_ms=10.0, t_start=0, n_frames=2).sum(dim=(2, 3, 4)).tolist()
        [[1.0, 0.0], [0.0, 1.0]]
    """
    if batch.frame_ms is not None:
        if frame_ms is not None and _frame_us(frame_ms) != _frame_us(batch.frame_ms):
            raise ValueError(
                f"frame_ms={frame_ms!r} differs from the batch's grid (frame_ms={batch.frame_ms}); "
                "bin with the grid's width or rebuild the grid with EventBatch.with_grid"
            )
        frame_ms = batch.frame_ms
        starts = batch.t_start
        n_frames = batch.n_frames if n_frames is None else n_frames
    else:
        if frame_ms is None:
            frame_ms = 10.0
        starts = None
    grid = _grid(batch.sensor_size, None, crop, pool, frame_ms, dtype)
    if starts is None:
        starts = _resolve_starts(batch, t_start, grid.frame_us)
    if n_frames is None:
        lasts = _segment_first(batch, batch.t, "amax")
        n_frames = 0
        for b, last in enumerate(lasts):
            if last is not None and last >= starts[b].item():
                last_t = torch.tensor([[last]], dtype=batch.t.dtype)
                n_frames = max(n_frames, int(_time_bins(last_t, starts[b : b + 1], grid.frame_us)) + 1)
        if n_frames > _MAX_INFERRED_FRAMES:
            raise ValueError(f"the events span {n_frames:,} bins of frame_ms={frame_ms!r}; pass n_frames")
    else:
        n_frames = _integer(n_frames, "n_frames", low=0)
    b = len(batch)
    total = b * n_frames * grid.frame_size
    counts, lost = _bin_counts(batch, starts, n_frames, grid, total)
    if lost is not None and counting():  # dropped by design (moved there by a transform): counted, not warned
        record_dropped("off_sensor", lost[0])
        record_dropped("out_of_window", lost[1])
    return counts.view(b, n_frames, 2, grid.out_h, grid.out_w)


def _relative_times(batch: EventBatch, starts: Tensor) -> Tensor:
    """``t - t_start`` of each event's stream: one scalar subtraction when every stream starts
    at the same time (a shared clock, ``t_start`` a number), else a gather of the starts."""
    first = starts.tolist()
    if first and all(v == first[0] for v in first):
        return batch.t - first[0]
    start_of = starts.to(device=batch.device, dtype=batch.t.dtype)
    return batch.t - start_of.index_select(0, batch.sample_index())


def _bin_counts(batch: EventBatch, starts: Tensor, n_frames: int, grid: Any, total: int) -> tuple[Tensor, Tensor | None]:
    """(total,) counts in ``grid.dtype``, by the one binning kernel of :mod:`.binning`: int32
    indices from the pixel table and the float32 bin quotient, every event not counted sent
    to one spare slot, and an ``index_add_`` of ones straight into the output dtype when no
    count can pass what it holds exactly (float32: 2**24), else into int32 and a checked cast.

    On the CPU one sample at a time: its block (``T * 2 * H' * W'`` values) is zeroed, then
    its events are added while the block is still in cache, 2-3x faster than one scatter
    over the whole output. On accelerators, one ``index_add_`` for the batch (sync-free).

    Also returns, on the device, how many events lay off the sensor and how many on it but
    outside the time window (``None`` when there are no events): the caller reads these two
    numbers to decide whether to warn, instead of a second pass over the events.
    """
    device = batch.device
    dtype = grid.dtype
    n = batch.num_events
    if n == 0:
        return torch.zeros(total, dtype=dtype, device=device), None
    index, pixel, in_time = _event_index(
        batch.x, batch.y, batch.p, _relative_times(batch, starts), n_frames, grid, total >= 2**31 - 1
    )
    off_sensor = pixel == _OUTSIDE_SENSOR
    lost = torch.stack([off_sensor.sum(), in_time.logical_not().logical_and_(off_sensor.logical_not_()).sum()])
    if total == 0:
        return torch.zeros(total, dtype=dtype, device=device), lost
    counted = in_time.logical_and_(pixel >= 0)
    block = n_frames * grid.frame_size
    if device.type == "cpu":
        counts = torch.empty(total + 1, dtype=_accumulator(dtype, n))
        counts[total] = 0
        bounds = batch.offsets.tolist()
        for b in range(len(batch)):
            counts[b * block : (b + 1) * block].zero_()
            lo, hi = bounds[b], bounds[b + 1]
            if hi > lo:
                segment = index[lo:hi].add_(b * block - total).mul_(counted[lo:hi]).add_(total)
                _accumulate(counts, segment)
    else:
        index = index.add_(batch.sample_index().to(index.dtype).mul(block))
        counts = torch.zeros(total + 1, dtype=_accumulator(dtype, n), device=device)
        _accumulate(counts, _to_spare(index, counted, total))
    return _as_dtype(counts[:total], dtype), lost
