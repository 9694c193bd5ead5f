"""The one binning kernel (private to :mod:`event_transforms.events`): the frame grid and its
pixel table, the bin arithmetic (int64 for integer timestamps), the per-chunk count, the
accumulation in a dtype that holds every count exactly, and the tallies behind the errors
and warnings. :func:`~event_transforms.functional.events_to_frames`,
:func:`~event_transforms.functional.bin_events` and
:func:`~event_transforms.functional.iter_frames` are its three entry points."""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from .._compile import compilable
from .batch import EventBatch
from .dropped import EventsOutsideSensorWarning, warn_at_caller
from ._ingest import (
    _INT64_MAX, _check_crop, _check_dtype, _check_polarity, bin_width_us, check_integer, _sensor,
)

#: Pixel table entries: an output pixel ``row * W' + col``, or one of these.
_OUTSIDE_CROP, _OUTSIDE_SENSOR = -1, -2
_TABLES: dict[tuple, Tensor] = {}


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


def build_grid(
    sensor_size: object, tonic_sensor_size: object, crop: object, pool: object, frame_ms: object, dtype: object,
    owner: str = "events_to_frames",
) -> _Grid:
    height, width = _sensor(sensor_size, tonic_sensor_size, owner)
    pool = check_integer(pool, "pool")
    top, left, crop_h, crop_w = _check_crop(crop, height, width, pool)
    return _Grid(height, width, top, left, crop_h, crop_w, pool, bin_width_us(frame_ms), _check_dtype(dtype))


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


def polarity_channel(p: Tensor, valid: Tensor | None, tally: _Tally | None = None) -> Tensor:
    """Channel per event: 1 for ON (p > 0), 0 for OFF (p in {0, -1}); refuses anything else."""
    _check_polarity(p, valid, None if tally is None else tally.polarities)
    return (p > 0).to(torch.int64)


#: Largest whole number each float dtype counts to exactly.
_EXACT_FLOAT = {torch.float16: 2**11, torch.bfloat16: 2**8, torch.float32: 2**24, torch.float64: 2**53}


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


def bins_of(rel: Tensor, frame_us: float | int, n_frames: int) -> tuple[Tensor, Tensor]:
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
    :func:`bins_of`), else the int64 floor quotient."""
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


def event_index(
    col: Tensor, row: Tensor, on: Tensor, rel: Tensor, n_frames: int, grid: _Grid, wide: bool, *, look: bool = False
) -> tuple[Tensor, Tensor, Tensor]:
    """Per event (any shape, integer coordinates): its index inside one stream's
    ``(T, 2, H', W')`` block (int32, int64 if ``wide``; meaningless where not counted), its
    pixel table entry (negative off the crop or sensor) and whether its time is in the window.
    """
    bins, in_time = bins_of(rel, grid.frame_us, n_frames)
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
        index, pixel, in_time = event_index(
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


def _zeroed(values: Tensor) -> Tensor:
    """``values.zero_()``; a contiguous CPU tensor by one libc ``memset`` (all-zero bytes are
    +0 in every dtype), 2-4x faster than ``fill_`` on buffers past the cache."""
    if values.device.type == "cpu" and values.is_contiguous() and values.numel() and not torch.compiler.is_compiling():
        ctypes.memset(values.data_ptr(), 0, values.numel() * values.element_size())
        return values
    return values.zero_()


#: Pixel-table entries of :func:`_count_blocks` for a pixel off the crop (and, one less, off
#: the sensor): far enough below zero that an event's block index stays negative.
_FAR = -(2**30)
#: Largest scratch block of :func:`_count_blocks` (a sample's frames): about a CPU's L2 cache
#: (measured: 1.5 MB blocks 0.6x the masking path's time, 12 MB blocks 1.15x).
_SCRATCH_BYTES = 2**22
_FAR_TABLES: dict[tuple, Tensor] = {}


def _far_table(grid: _Grid, device: torch.device) -> Tensor:
    """:func:`_pixel_table` with every output pixel plus one, ``_FAR`` off the crop and
    ``_FAR - 1`` off the sensor (int32): the table of :func:`_count_blocks`."""
    key = (grid.height, grid.width, grid.top, grid.left, grid.crop_h, grid.crop_w, grid.pool, str(device))
    table = _FAR_TABLES.get(key)
    if table is None:
        base = _pixel_table(grid, device)
        table = torch.where(base >= 0, base + 1, torch.where(base == _OUTSIDE_SENSOR, _FAR - 1, _FAR)).to(torch.int32)
        if len(_FAR_TABLES) > 32:
            _FAR_TABLES.clear()
        _FAR_TABLES[key] = table
    return table


def _count_blocks(
    x: Tensor, y: Tensor, p: Tensor, rel: Tensor, bounds: list[int], n_frames: int, grid: _Grid,
    accumulator: torch.dtype, lost: bool,
) -> tuple[Tensor, Tensor | None] | None:
    """The CPU batch binning, sample by sample through one cache-resident scratch block;
    ``None`` where it does not apply (float times, an int64 bin quotient, a block past
    ``_SCRATCH_BYTES``, where a scratch out of cache costs a third pass over the output), and
    the caller takes the general path.

    Per event: the bin ``floor(clamp(rel / frame, -1, T))`` (the quotient of :func:`_quotient`,
    exact where it matters), its index ``(2 bin + ON) * H'W' + pixel + 1`` inside its sample's
    block, 0 or ``T 2 H'W' + 1`` for every event not counted (before or after the window, or
    off the crop or sensor: the table's far entries keep the index negative), by one clamp, with
    no mask. Per sample: the scratch zeroed (in cache), one ``index_add_`` of ones, and the
    block copied out, so the output is written once and never zeroed; 4-5 fewer passes over
    the events than masking, and the same counts (whole numbers, exact in ``accumulator``).
    With ``lost``, also the (2,) events off the sensor and on it outside the window."""
    block = n_frames * grid.frame_size
    frame = grid.out_h * grid.out_w
    if rel.is_floating_point() or block + 2 * frame >= 2**29 or (block + 2) * accumulator.itemsize > _SCRATCH_BYTES:
        return None
    quotient = _quotient(rel, grid.frame_us, n_frames)
    if not quotient.is_floating_point():
        return None
    bins = quotient.clamp_(-1.0, float(n_frames)).floor_().to(torch.int32)
    del quotient
    flat = _clamped(y, grid.height, False).to(torch.int32).mul_(grid.width + 2)
    col = _clamped(x, grid.width, False)
    flat.add_(col if col.dtype == torch.int32 else col.to(torch.int32)).add_(grid.width + 3)
    pixel = _far_table(grid, x.device).index_select(0, flat)
    del flat
    dropped = None
    if lost:
        off_sensor = pixel == _FAR - 1
        in_time = (bins >= 0).logical_and_(bins < n_frames)
        dropped = torch.stack([off_sensor.count_nonzero(), (in_time | off_sensor).count_nonzero().neg_().add_(x.shape[0])])
        del off_sensor, in_time
    on = p.to(torch.int32)  # 1 = ON, 0 = OFF (the batch's contract; the masking path adds p as is)
    index = bins.mul_(2).add_(on).mul_(frame).add_(pixel).clamp_(0, block + 1)
    del pixel, on
    counts = torch.empty(len(bounds) - 1, block, dtype=accumulator)
    scratch = torch.empty(block + 2, dtype=accumulator)
    one = torch.ones((), dtype=accumulator)
    inner = scratch[1 : block + 1]
    for b in range(len(bounds) - 1):
        lo, hi = bounds[b], bounds[b + 1]
        if hi == lo:
            _zeroed(counts[b])
            continue
        _zeroed(scratch)
        scratch.index_add_(0, index[lo:hi], one.expand(hi - lo))
        counts[b].copy_(inner)
    return counts.view(-1), dropped


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
            f"max_bytes={max_bytes:,}. {frame_hint(grid.frame_us)}Timestamps must be in microseconds (or "
            "say their unit with time_unit); to bin a long recording, stream it with iter_frames, pass n_frames "
            "for a window, or raise max_bytes"
        )


def frame_hint(frame_us: float | int) -> str:
    """A sentence for errors about too many bins when ``frame_ms`` is under a millisecond, else ``""``."""
    if frame_us >= 1000:
        return ""
    return (f"frame_ms is in milliseconds: frame_ms={frame_us / 1000:g} makes bins of {frame_us:g} µs "
            f"(if {frame_us / 1000:g} s was meant, pass frame_ms={frame_us:g}). ")


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


def relative_times(batch: EventBatch, starts: Tensor) -> Tensor:
    """``t - t_start`` of each event's stream: one scalar subtraction when every stream starts
    at the same time (a shared clock, ``t_start`` a number), else a gather of the starts."""
    first = starts.tolist()
    if first and all(v == first[0] for v in first):
        if first[0] == 0 and not batch.t.is_floating_point():
            return batch.t  # read only by every caller: no copy of the int64 column
        return batch.t - first[0]
    start_of = starts.to(device=batch.device, dtype=batch.t.dtype)
    return batch.t - start_of.index_select(0, batch.sample_index())


_BATCH_KERNELS: dict[tuple, Any] = {}


def _batch_kernel(grid: _Grid, n_frames: int, total: int, accumulator: torch.dtype) -> Any:
    """The binning of a whole batch as one pure function of its columns, for the compiled path
    (:mod:`event_transforms._compile`): the grid's numbers are closure constants, so only the
    event count varies between calls and one compiled graph serves every batch on this grid.

    Returns ``f(x, y, p, rel, sample, table) -> (counts, lost)``: ``(total,)`` counts in
    ``accumulator`` and the (2,) events off the sensor and on it outside the time window, by
    the arithmetic of :func:`event_index` (every count equal to the eager path's)."""
    key = (grid.height, grid.width, grid.out_h, grid.out_w, grid.frame_us, type(grid.frame_us), n_frames, total,
           accumulator)
    fn = _BATCH_KERNELS.get(key)
    if fn is not None:
        return fn
    height, width, frame = grid.height, grid.width, grid.out_h * grid.out_w
    block, wide = n_frames * grid.frame_size, total >= 2**31 - 1
    frame_us = grid.frame_us

    @compilable
    def bin_batch(x: Tensor, y: Tensor, p: Tensor, rel: Tensor, sample: Tensor, table: Tensor) -> tuple[Tensor, Tensor]:
        quotient = _quotient(rel, frame_us, n_frames)
        in_time = (quotient >= 0) & (quotient < n_frames)
        index_dtype = torch.int64 if wide or quotient.dtype == torch.int64 else torch.int32
        flat = y.clamp(-1, height).to(torch.int32) * (width + 2) + x.clamp(-1, width).to(torch.int32) + (width + 3)
        pixel = table[flat]
        index = (quotient.to(index_dtype) * 2 + (p > 0).to(index_dtype)) * frame + pixel + sample.to(index_dtype) * block
        counted = in_time & (pixel >= 0)
        index = torch.where(counted, index, total)
        counts = torch.zeros(total + 1, dtype=accumulator, device=x.device)
        counts.index_add_(0, index, torch.ones((), dtype=accumulator, device=x.device).expand(index.shape[0]))
        off_sensor = pixel == _OUTSIDE_SENSOR
        lost = torch.stack([off_sensor.sum(), (~in_time & ~off_sensor).sum()])
        return counts[:total], lost

    if len(_BATCH_KERNELS) > 32:
        _BATCH_KERNELS.clear()
    _BATCH_KERNELS[key] = bin_batch
    return bin_batch


def valid_mask(
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
