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

__all__ = ["events_to_frames", "bin_events", "EventsOutsideSensorWarning", "EventsOutsideWindowWarning", "CHUNK_EVENTS", "MAX_BYTES"]

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from .batch import EventBatch, _resolve_starts, _segment_first
from .dropped import EventsOutsideSensorWarning, EventsOutsideWindowWarning, counting, record_dropped, warn_at_caller
from ._ingest import (
    _FIELDS, T_START_RULES, explicit_starts, _floor_to_grid,
    bin_width_us, check_integer, _source,
)
from .._compile import compiled_kernels_enabled
from ._kernel import (
    valid_mask,
    _OUTSIDE_SENSOR, _Tally, _accumulate, _count_blocks, _accumulator, _as_dtype, _batch_kernel, _bin_of, _check_bytes, _count_chunk,
    _empty_window_error, event_index, frame_hint, build_grid, _pixel_table, relative_times, _time_bins, _to_spare, _warn_outside, _zeroed,
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


# --------------------------------------------------------------------------- binning


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



def events_to_frames(
    events: Tensor | Mapping[str, Any] | np.ndarray | EventBatch,
    *,
    sensor_size: tuple[int, int] | None = None,
    tonic_sensor_size: tuple[int, int, int] | None = None,
    t_start: str | float | Sequence[float] | Tensor = "floor",
    frame_ms: float | None = None,
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
            bool, {0, 1} or {-1, 1}; anything else raises. An
            :class:`~event_transforms.EventBatch` is binned by :func:`bin_events` (its own
            sensor and grid; ``sensor_size`` and the reading options must then be left out).
        sensor_size: ``(H, W)`` of the sensor, height first; required unless
            ``tonic_sensor_size`` is given (there is no default sensor). Events outside it
            are dropped with an :class:`EventsOutsideSensorWarning` that gives their count
            and the size they fit (naming the swap when x and y look exchanged).
        tonic_sensor_size: tonic's ``(W, H, P)`` instead of ``sensor_size``.
        t_start: start of the first bin: ``"floor"`` (the first event rounded down to a
            multiple of the bin width), ``"first"`` (the first event), or a time in
            microseconds; for a batch, one per stream (a (B,) sequence or tensor) or one
            for all. ``"floor"`` and ``"first"`` are taken per stream.
        frame_ms: bin width in milliseconds; ``None`` means 10 ms (an EventBatch's own grid,
            if it has one).
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
        TypeError: events or options of the wrong type, or no sensor size.

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
    if isinstance(events, EventBatch):
        given = {name: value for name, value in (
            ("sensor_size", sensor_size), ("tonic_sensor_size", tonic_sensor_size), ("lengths", lengths),
            ("mask", mask), ("time_unit", time_unit), ("columns", columns)) if value is not None}
        if given:
            raise TypeError(f"events_to_frames of an EventBatch takes no {', '.join(given)}: the batch holds its "
                            "sensor size and columns in microseconds")
        return bin_events(events, frame_ms=frame_ms, t_start=t_start, n_frames=n_frames, crop=crop, pool=pool,
                          dtype=dtype)
    frame_ms = 10.0 if frame_ms is None else frame_ms
    source = _source(events, time_unit=time_unit, columns=columns, whole=True)
    grid = build_grid(sensor_size, tonic_sensor_size, crop, pool, frame_ms, dtype)
    chunk = max(1, check_integer(chunk_size, "chunk_size") // max(source.batch, 1))
    if max_bytes is not None:
        max_bytes = check_integer(max_bytes, "max_bytes")
    if n_frames is not None:
        n_frames = check_integer(n_frames, "n_frames")
        _check_bytes(source.batch, n_frames, grid, max_bytes, "n_frames asks for", source.batch * source.length)
    if not source.batched and (lengths is not None or mask is not None):
        raise ValueError("lengths and mask apply to a (B, N, 4) batch of events only")
    valid_all = valid_mask(source.batch, source.length, lengths, mask, source.device)
    batch, length = source.batch, source.length

    def valid_of(i: int, j: int) -> Tensor | None:
        return None if valid_all is None else valid_all[:, i:j]

    if isinstance(t_start, str):
        if t_start not in T_START_RULES:
            raise ValueError(f"t_start must be 'floor', 'first', a number or one per stream, got {t_start!r}")
    else:
        starts = explicit_starts(t_start, batch)

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
                f"to {max(v for v in ranges.t_max if v is not None)}); {frame_hint(grid.frame_us)}timestamps must be "
                "in microseconds (or say their unit with time_unit). Pass n_frames to bin a window of that length"
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
    counts = _zeroed(torch.empty(total + 1, dtype=_accumulator(grid.dtype, batch * length), device=source.device))

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
            _window_hint(t_start, n_frames, grid.frame_us, ranges)))
    frames = _as_dtype(counts[:total], grid.dtype).view(batch, n_frames, 2, grid.out_h, grid.out_w)
    return frames if source.batched else frames.squeeze(0)


def _window_hint(t_start: object, n_frames: int, frame_us: float | int, ranges: _Tally) -> str:
    """What may explain events outside an explicit window: a unit other than microseconds (the
    window a tiny share of the events' span), or the floored grid's first bin."""
    lows = [v for v in ranges.t_min if v is not None]
    highs = [v for v in ranges.t_max if v is not None]
    window = n_frames * frame_us
    if lows and highs and max(highs) - min(lows) > 100 * window:
        span = max(highs) - min(lows)
        return (f"the window of {window / 1000:g} ms is {100 * window / span:.2g} % of the events' span "
                f"({span / 1000:,.0f} ms read as microseconds): if the timestamps are in another unit, pass "
                "time_unit (e.g. time_unit='ns')")
    if t_start == "floor":
        return ("with t_start='floor' the grid starts before the first event, so a window of n_frames may need one "
                "more frame")
    return ""


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

    One scatter for the whole batch on an accelerator (on the CPU one per sample, into a
    block that stays in cache): int32 linear indices (int64 past 2**31 slots), an
    event outside the window, sensor or crop counted in a spare slot, one ``index_add_``
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
        if frame_ms is not None and bin_width_us(frame_ms) != bin_width_us(batch.frame_ms):
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
    grid = build_grid(batch.sensor_size, None, crop, pool, frame_ms, dtype)
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
        n_frames = check_integer(n_frames, "n_frames", low=0)
    b = len(batch)
    total = b * n_frames * grid.frame_size
    counts, lost = _bin_counts(batch, starts, n_frames, grid, total)
    if lost is not None and counting():  # dropped by design (moved there by a transform): counted, not warned
        record_dropped("off_sensor", lost[0])
        record_dropped("out_of_window", lost[1])
    return counts.view(b, n_frames, 2, grid.out_h, grid.out_w)


def _bin_counts(batch: EventBatch, starts: Tensor, n_frames: int, grid: Any, total: int) -> tuple[Tensor, Tensor | None]:
    """(total,) counts in ``grid.dtype``, by the one binning kernel of :mod:`.binning`: int32
    indices from the pixel table and the float32 bin quotient, every event not counted sent
    to one spare slot, and an ``index_add_`` of ones straight into the output dtype when no
    count can pass what it holds exactly (float32: 2**24), else into int32 and a checked cast.

    On the CPU one sample at a time (:func:`~._kernel._count_blocks`): its events are added
    into one scratch block (``T * 2 * H' * W'`` values plus two spare slots) while it is in
    cache, and the block is copied out, so the output is written once and never zeroed
    (the masking path below remains for float times and blocks past 2**29 values). On
    accelerators, one ``index_add_`` for the batch (sync-free).

    Also returns, on the device, how many events lay off the sensor and how many on it but
    outside the time window (``None`` when there are no events): the caller reads these two
    numbers to decide whether to warn, instead of a second pass over the events.
    """
    device = batch.device
    dtype = grid.dtype
    n = batch.num_events
    if n == 0:
        return torch.zeros(total, dtype=dtype, device=device), None
    if compiled_kernels_enabled():  # one compiled scatter for the batch, on any device
        kernel = _batch_kernel(grid, n_frames, total, _accumulator(dtype, n))
        counts, lost = kernel(batch.x, batch.y, batch.p, relative_times(batch, starts), batch.sample_index(),
                              _pixel_table(grid, device))
        return _as_dtype(counts, dtype), lost
    rel = relative_times(batch, starts)
    if device.type == "cpu" and total:
        blocks = _count_blocks(batch.x, batch.y, batch.p, rel, batch.offsets.tolist(), n_frames, grid,
                               _accumulator(dtype, n), counting())
        if blocks is not None:
            return _as_dtype(blocks[0], dtype), blocks[1]
    index, pixel, in_time = event_index(batch.x, batch.y, batch.p, rel, n_frames, grid, total >= 2**31 - 1)
    off_sensor = pixel == _OUTSIDE_SENSOR
    # off the sensor, and on it outside the window (= every event neither in time nor off it)
    lost = torch.stack([off_sensor.count_nonzero(), (in_time | off_sensor).count_nonzero().neg_().add_(n)])
    if total == 0:
        return torch.zeros(total, dtype=dtype, device=device), lost
    counted = in_time.logical_and_(pixel >= 0)
    block = n_frames * grid.frame_size
    if device.type == "cpu":
        counts = torch.empty(total + 1, dtype=_accumulator(dtype, n))
        counts[total] = 0
        bounds = batch.offsets.tolist()
        for b in range(len(batch)):
            _zeroed(counts[b * block : (b + 1) * block])
            lo, hi = bounds[b], bounds[b + 1]
            if hi > lo:
                segment = index[lo:hi].add_(b * block - total).mul_(counted[lo:hi]).add_(total)
                _accumulate(counts, segment)
    else:
        index = index.add_(batch.sample_index().to(index.dtype).mul(block))
        counts = torch.zeros(total + 1, dtype=_accumulator(dtype, n), device=device)
        _accumulate(counts, _to_spare(index, counted, total))
    return _as_dtype(counts[:total], dtype), lost
