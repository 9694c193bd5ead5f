"""Bin an event stream that arrives in chunks, one frame at a time.

:func:`iter_frames` bins an iterable of time-sorted chunks (a file read piece by piece, a
live sensor) and yields one ``(2, H, W)`` frame per bin as soon as the bin is complete,
by the rules of :func:`~event_transforms.functional.events_to_frames` (input forms,
``t_start``, sensor and crop, dtype), so the frames equal those of binning the whole
stream at once; memory stays a few times one chunk plus one frame.
"""

from __future__ import annotations

__all__ = ["iter_frames"]

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from ._kernel import _accumulate, _as_dtype, _empty_window_error, _exact_count, _Grid, build_grid, _pixels, _Tally, _tally_outside, _time_bins, _to_spare, _warn_outside
from ._ingest import explicit_starts, _floor_to_grid
from ._ingest import _FIELDS, T_START_RULES, _check_polarity, check_integer, column_order, _Source, _source, check_time_unit


def iter_frames(
    chunks: Iterable[Tensor | Mapping[str, Any] | np.ndarray],
    *,
    sensor_size: tuple[int, int] | None = None,
    tonic_sensor_size: tuple[int, int, int] | None = None,
    t_start: str | float = "floor",
    frame_ms: float = 10.0,
    n_frames: int | None = None,
    crop: tuple[int, int, int, int] | None = None,
    pool: int = 1,
    dtype: torch.dtype = torch.float32,
    frames_per_step: int = 32,
    time_unit: str | None = None,
    columns: str | Sequence[str] | None = None,
) -> Iterator[Tensor]:
    r"""Bin a stream of event chunks and yield one frame ``(2, H', W')`` per bin, in order.

    For recordings too large to hold and for online use: each chunk is any single-stream
    input :func:`events_to_frames` takes (a slice of a memory-mapped file, a packet from
    a sensor), the chunks together sorted by ``t`` (as tonic's readers and cameras deliver
    them). A frame is yielded as soon as a later event shows its bin is complete (the
    last one when the chunks run out); empty bins between events are yielded as zeros. The
    frames equal :func:`events_to_frames` on the whole stream with the same options, and
    feed a recurrent model's per-frame step directly (after ``frame.unsqueeze(0)``). Memory: one chunk plus ``frames_per_step`` frames.

    Args:
        chunks: an iterable of event chunks, sorted by time across and within chunks.
        sensor_size: ``(H, W)`` (or give ``tonic_sensor_size``; one is required). Events outside it are dropped
            with an :class:`EventsOutsideSensorWarning` (once, on the first chunk that has
            any).
        tonic_sensor_size: tonic's ``(W, H, P)`` instead of ``sensor_size``.
        t_start: ``"floor"``, ``"first"`` (both from the first event of the stream) or a
            time in microseconds.
        frame_ms: bin width in milliseconds.
        n_frames: stop after this many frames (reading no further chunk); ``None`` runs
            until the chunks end.
        crop: ``(top, left, height, width)`` window inside the sensor, or ``None``.
        pool: side of the square blocks summed into one output pixel.
        dtype: dtype of the yielded counts.
        frames_per_step: bins counted at once within a chunk (bounds the buffer).
        time_unit: unit of the chunks' timestamps, as in :func:`events_to_frames`
            (``"us"``, ``"ms"``, ``"s"``, ``"ns"``; ``None``: microseconds, float
            timestamps that look like seconds refused).
        columns: the order of ``(N, k)`` chunks' columns, e.g. ``"txyp"``.

    Shape:
        - chunks: each ``(N_k, 4)`` rows ``(x, y, t, p)``, a structured array or a mapping of
          ``(N_k,)`` columns.
        - yields: ``(2, H', W')``, ``(H', W')`` the crop divided by ``pool``.

    Yields:
        ``(2, H', W')`` counts, one per bin from ``t_start`` on.

    Raises:
        ValueError: chunks not sorted by time; events none of which falls in the time
            window; the errors of :func:`events_to_frames`.

    Example:
        >>> import numpy as np
        >>> events = np.zeros(6, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "?")])
        >>> events["t"] = [1_000, 2_000, 15_000, 41_000, 42_000, 43_000]
        >>> events["p"] = [True, True, False, True, True, True]
        >>> chunks = (events[i : i + 4] for i in range(0, len(events), 4))
        >>> [frame.sum(dim=(1, 2)).tolist() for frame in iter_frames(chunks, sensor_size=(1, 1))]
        [[0.0, 2.0], [1.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 3.0]]
    """
    _check_chunks(chunks)
    grid = build_grid(sensor_size, tonic_sensor_size, crop, pool, frame_ms, dtype, "iter_frames")
    if n_frames is not None:
        n_frames = check_integer(n_frames, "n_frames")
    step = check_integer(frames_per_step, "frames_per_step")
    if isinstance(t_start, str):
        if t_start not in T_START_RULES:
            raise ValueError(f"t_start must be 'floor', 'first' or a number, got {t_start!r}")
        starts: Tensor | None = None
    else:
        starts = explicit_starts(t_start, 1)
    time_unit = check_time_unit(time_unit)  # checked now, not at the first chunk
    if columns is not None:
        column_order(columns)

    def source_of(events: Any) -> _Source:
        return _source(events, time_unit=time_unit, columns=columns)

    return _iter_frames(chunks, grid, t_start, starts, frame_ms, n_frames, step, source_of)


def _check_chunks(chunks: object) -> None:
    """Refuse one whole stream where an iterable of chunks belongs (iterating it would yield
    single rows or records: numpy's ``void``), naming the fix."""
    whole = None
    if isinstance(chunks, np.ndarray) and chunks.dtype.names is not None:
        whole = "a numpy structured array"
    elif isinstance(chunks, Mapping):
        whole = "a mapping of columns"
    elif isinstance(chunks, (np.ndarray, Tensor)) and chunks.ndim == 2:
        whole = f"an array of shape {tuple(chunks.shape)}"
    elif type(chunks).__module__.split(".")[0] in ("pandas", "polars") and hasattr(chunks, "columns"):
        whole = "a data frame"
    if whole is not None:
        raise TypeError(
            f"iter_frames takes an iterable of event chunks, got {whole} (one whole stream): pass [events] "
            "for one chunk, slices such as (events[i : i + n] for i in range(0, len(events), n)), or bin it "
            "at once with events_to_frames(events, ...)"
        )


def _iter_frames(
    chunks: Iterable[Any], grid: _Grid, t_start: object, starts: Tensor | None, frame_ms: object,
    n_frames: int | None, step: int, source_of: Callable[[Any], _Source],
) -> Iterator[Tensor]:
    size = grid.frame_size
    shape = (2, grid.out_h, grid.out_w)
    exact = _exact_count(grid.dtype)
    tally = _Tally(1)
    warned = False
    pending = 0  # the next bin to yield
    base = 0  # the bin of the window's first frame: counts holds bins base .. base + step - 1
    in_window = 0  # events counted in the window (the cast is checked only past what dtype holds exactly)
    counts: Tensor | None = None  # the window's frames in int32 and one spare slot
    last_t: Any = None
    end = 0  # one past the last bin that holds an event

    def emit(k: int) -> Tensor:
        assert counts is not None
        if not base <= k < base + step:
            return torch.zeros(shape, dtype=grid.dtype, device=counts.device)
        frame = counts[(k - base) * size : (k - base + 1) * size]
        if frame.dtype == grid.dtype:
            return frame.clone().view(shape)
        return (frame.to(grid.dtype) if in_window <= exact else _as_dtype(frame, grid.dtype)).view(shape)

    for number, events in enumerate(chunks):
        source = source_of(events)
        if source.batched:
            raise ValueError(f"chunks[{number}] must be one stream, got a batch of shape {tuple(events.shape)}")
        chunk = _stream_chunk(source, number, last_t, starts, t_start, n_frames, grid, tally)
        if chunk is None:
            continue
        starts, last_t, bins, within, kept, (lo, hi), past_window = chunk
        del chunk
        if tally.outside and not warned:
            _warn_outside(tally, int(tally.events.item()), grid)
            warned = True
        if counts is None:
            counts = torch.zeros(step * size + 1, dtype=torch.int32, device=source.device)
        # the events in the window, lo .. hi, are sorted by bin: count them a window of bins at a time
        while lo < hi:
            first = int(bins[lo])
            while pending < first:
                yield emit(pending)
                pending += 1
            if first >= base + step:  # every frame of the window is out: the window moves on
                base, in_window = first, 0
                counts.zero_()
            stop = min(hi, int(torch.searchsorted(bins, base + step)))
            if in_window + stop - lo >= 2**31 and counts.dtype == torch.int32:
                counts = counts.to(torch.int64)
            index = (bins[lo:stop] - base).mul_(size).add_(within[lo:stop])
            _accumulate(counts, _to_spare(index, kept[lo:stop], counts.numel() - 1))
            in_window += stop - lo
            end = int(bins[stop - 1]) + 1
            lo = stop
        del bins, within, kept  # before the next chunk is read
        if past_window:
            break  # every later event is past the window: the remaining bins are complete
    if tally.events.item() and not tally.in_window.item():
        assert starts is not None  # set by the first chunk that held events
        raise _empty_window_error(
            "the stream", starts.item(), t_start, frame_ms, n_frames, grid, tally.t_min[0], tally.t_max[0],
            int(tally.events.item()),
        )
    if counts is None:
        if n_frames is None:
            return
        counts = torch.zeros(step * size + 1, dtype=torch.int32)
    for k in range(pending, end if n_frames is None else n_frames):
        yield emit(k)


def _stream_chunk(
    source: _Source, number: int, last_t: Any, starts: Tensor | None, t_start: object, n_frames: int | None,
    grid: _Grid, tally: _Tally,
) -> tuple[Tensor, Any, Tensor, Tensor, Tensor, tuple[int, int], bool] | None:
    """One chunk of a stream, checked: (starts, its last t, every event's bin (int64, sorted),
    index within a frame and whether it is on the crop, the span of events in the window, and
    whether the chunk reaches past the window)."""
    if source.length == 0:
        return None
    columns = source.read(0, source.length, _FIELDS)
    t = columns["t"]
    first_t, chunk_last = t[0, 0].item(), t[0, -1].item()
    if (last_t is not None and first_t < last_t) or bool((t[0, 1:] < t[0, :-1]).any()):
        raise ValueError(
            f"iter_frames needs events sorted by t across chunks; chunks[{number}] goes back in time "
            f"(to t={t.min().item()} after t={last_t if last_t is not None else first_t})"
        )
    if starts is None:
        starts = torch.tensor([first_t], dtype=torch.float64 if isinstance(first_t, float) else torch.int64)
        if t_start == "floor":
            starts = _floor_to_grid(starts, grid.frame_us)
    tally.add_times(t, None)
    tally.events += t.shape[1]
    x, y, p = columns["x"][0], columns["y"][0], columns["p"][0]
    _check_polarity(p, None, tally.polarities)
    col = torch.floor(x) if x.is_floating_point() else x
    row = torch.floor(y) if y.is_floating_point() else y
    pixel = _pixels(col, row, grid, look=True)
    _tally_outside(tally, pixel, col, row, None)
    bins = _time_bins(t, starts, grid.frame_us)[0]
    stop = bins[-1].item() + 1 if n_frames is None else n_frames
    lo, hi = torch.searchsorted(bins, torch.tensor([0, stop], dtype=bins.dtype, device=bins.device)).tolist()
    tally.in_window += hi - lo
    within = (p > 0).to(torch.int32).mul_(grid.out_h * grid.out_w).add_(pixel)
    past_window = n_frames is not None and int(bins[-1]) >= n_frames
    return starts, chunk_last, bins, within, pixel >= 0, (lo, hi), past_window
