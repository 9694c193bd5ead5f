"""``EventBatch``: B event streams as concatenated columns, and their binning on the device.

A batch holds the events of B streams one after another in four columns, ``x``, ``y``
(int16 pixel coordinates, the sensor's column and row), ``t`` (int64 microseconds, or
float64 for float timestamps) and ``p`` (int8, 1 = ON, 0 = OFF: tonic's convention, and
the frames' channel), plus ``offsets`` (B + 1,), an int64 **CPU** tensor: stream ``b``
is ``[offsets[b], offsets[b + 1])``. The offsets stay on the host wherever the columns
live, so slicing, gating and the sizes of every output are known without asking the
device (no host synchronisation); only a transform whose output size depends on the data
(event drop, refractory period, decimation) reads a count back, once per call.

Memory: 2 + 2 + 8 + 1 = **13 bytes per event** (plus 8 bytes per stream of offsets, and
4 bytes per event for the per-event sample index a batched kernel builds once and the
batch keeps). 32 simulated recordings of 36 × 10 ms hold about 1.3 M events: 17 MB, against
48 MB for the float32 frames ``(32, 36, 2, 70, 75)`` they bin to (2.8× smaller; 23×
smaller than the full-sensor float32 ``(32, 36, 2, 180, 240)`` frames). A torch
nested (jagged) tensor was not used: its kernels cover few of the ops needed here (no
``bincount``, no ``index_add_``), so every kernel would work on its ``values()`` and
``offsets()``, which is this layout without the dependency.

**The frame grid.** Transforms that move events between time bins (frame shift, TES,
time reversal, crop in time) need the bins the events will be counted in. A batch may
carry one: ``frame_ms``, per-stream starts ``t_start`` (B,) resolved when the grid is set
(by the :func:`~event_transforms.functional.events_to_frames` rules: ``"floor"``,
``"first"`` or a number) and ``n_frames`` (or ``None``). The starts are fixed before any
transform moves an event, so a shifted event lands exactly in the bin the frame kernel
would put it in; binning an :class:`EventBatch` that has a grid uses it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from .._validation import index_on, read_host
from .dropped import EventsOutsideSensorWarning, EventsOutsideWindowWarning, warn_at_caller
from ._ingest import T_START_RULES, _check_polarity, canonical_columns, explicit_starts, _field, _floor_to_grid, bin_width_us, check_integer, _sensor

__all__ = ["EventBatch", "collate_events"]

_COORD_MAX = 2**15 - 1
_FIELDS = ("x", "y", "t", "p")


def _lengths_of(offsets: Tensor) -> list[int]:
    values = offsets.tolist()
    return [values[i + 1] - values[i] for i in range(len(values) - 1)]


class EventBatch:
    """B event streams in four concatenated columns with per-stream offsets, on any device.

    Build one with :meth:`from_streams` (a list of tonic structured arrays, ``(N, 4)``
    arrays or tensors, or mappings of columns; one call for the whole list) or
    :func:`collate_events` (a ``DataLoader`` ``collate_fn``). See the module docstring for
    the layout, the memory per event and the frame grid.

    Args:
        x, y: (N,) int16 pixel column and row (float coordinates are floored when built
            by :meth:`from_streams`). Events outside the sensor are kept; binning drops
            them.
        t: (N,) int64 (or float64) timestamps in microseconds.
        p: (N,) int8 polarity, 1 = ON, 0 = OFF.
        offsets: (B + 1,) int64 CPU offsets, ``offsets[0] = 0``, non-decreasing, last = N.
        sensor_size: ``(H, W)``, height first.
        frame_ms: bin width of the batch's frame grid, or ``None`` (no grid).
        t_start: (B,) CPU starts of the grid in microseconds (with ``frame_ms``).
        n_frames: number of bins of the grid, or ``None``.

    Shape:
        - x, y, t, p: ``(N,)``, N events of all streams; ``offsets``: ``(B + 1,)``.
        - as a transform's input: ``frame_shape`` = ``(B, T, 2, H, W)`` (T = ``n_frames``, or 1).

    Example:
        >>> import numpy as np
        >>> dtype = [("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")]
        >>> a, b = np.zeros(3, dtype=dtype), np.zeros(1, dtype=dtype)
        >>> a["t"], a["x"], a["p"] = [1_000, 12_000, 25_000], [0, 1, 2], [True, False, True]
        >>> batch = EventBatch.from_streams([a, b], sensor_size=(2, 3), frame_ms=10.0)
        >>> len(batch), batch.lengths, batch.t_start.tolist()
        (2, [3, 1], [0, 0])
        >>> batch[0].t.tolist(), batch.nbytes  # 13 bytes per event
        ([1000, 12000, 25000], 52)
    """

    __slots__ = ("x", "y", "t", "p", "offsets", "sensor_size", "frame_ms", "t_start", "n_frames", "_sample")

    def __init__(
        self,
        x: Tensor,
        y: Tensor,
        t: Tensor,
        p: Tensor,
        offsets: Tensor,
        sensor_size: tuple[int, int],
        *,
        frame_ms: float | None = None,
        t_start: Tensor | None = None,
        n_frames: int | None = None,
        _sample: Tensor | None = None,
    ) -> None:
        for name, column, dtypes in (
            ("x", x, (torch.int16,)), ("y", y, (torch.int16,)), ("t", t, (torch.int64, torch.float64)),
            ("p", p, (torch.int8,)),
        ):
            if not isinstance(column, Tensor) or column.dim() != 1 or column.dtype not in dtypes:
                raise TypeError(
                    f"EventBatch column {name} must be a 1-D tensor of dtype {' or '.join(map(str, dtypes))}, "
                    f"got {column.dtype if isinstance(column, Tensor) else type(column).__name__}"
                )
        if not isinstance(offsets, Tensor) or offsets.dtype != torch.int64 or offsets.dim() != 1 or offsets.numel() < 1:
            raise TypeError(f"offsets must be a 1-D int64 tensor of B + 1 entries, got {offsets!r}")
        if offsets.device.type != "cpu":
            raise ValueError(f"offsets must be a CPU tensor (sizes are read on the host), got device {offsets.device}")
        n = x.shape[0]
        if not (y.shape[0] == t.shape[0] == p.shape[0] == n):
            raise ValueError(f"columns x, y, t, p must have equal lengths, got {[c.shape[0] for c in (x, y, t, p)]}")
        bounds = offsets.tolist()  # host values: no device read, no dispatch
        if bounds[0] != 0 or bounds[-1] != n or any(a > b for a, b in zip(bounds, bounds[1:])):
            raise ValueError(f"offsets must rise from 0 to the number of events {n}, got {bounds}")
        self.x, self.y, self.t, self.p, self.offsets = x, y, t, p, offsets
        self.sensor_size = _sensor(sensor_size, None)
        if frame_ms is None and (t_start is not None or n_frames is not None):
            raise ValueError("t_start and n_frames describe a frame grid: give frame_ms too")
        if frame_ms is not None:
            bin_width_us(frame_ms)
            if t_start is None or not isinstance(t_start, Tensor) or tuple(t_start.shape) != (len(self),):
                raise ValueError(f"a grid needs t_start as a ({len(self)},) CPU tensor of starts, got {t_start!r}")
            t_start = t_start.cpu()
            n_frames = None if n_frames is None else check_integer(n_frames, "n_frames")
        self.frame_ms = None if frame_ms is None else float(frame_ms)
        self.t_start = t_start
        self.n_frames = n_frames
        self._sample = _sample

    # ------------------------------------------------------------------ building

    @classmethod
    def from_streams(
        cls,
        streams: Sequence[Any],
        *,
        sensor_size: tuple[int, int] | None = None,
        tonic_sensor_size: tuple[int, int, int] | None = None,
        frame_ms: float | None = None,
        t_start: str | float | Sequence[float] | Tensor = "floor",
        n_frames: int | None = None,
        device: torch.device | str | None = None,
        time_unit: str | None = None,
        columns: str | Sequence[str] | None = None,
        validate: bool = True,
    ) -> EventBatch:
        """Concatenate event streams (every form :func:`events_to_frames` accepts) into one batch.

        Each stream is parsed by the same column code as ``events_to_frames`` (tonic's
        titled ``('p', 'on')`` field, uint64 timestamps, {0, 1}/{-1, 1}/bool polarity);
        a ``(B, N, 4)`` array counts as B streams of N events.

        Args:
            streams: a sequence of streams.
            sensor_size: ``(H, W)``; or tonic's ``tonic_sensor_size=(W, H, P)``.
            frame_ms: set a frame grid of this bin width (see the module docstring).
            t_start: the grid's start rule: ``"floor"``, ``"first"``, or a number (or one
                per stream), as in ``events_to_frames``; used only with ``frame_ms``.
            n_frames: the grid's number of bins (``None``: enough for the last event).
            device: where the columns go (default: the CPU, or the tensors' device).
            time_unit: the streams' timestamp unit, as in ``events_to_frames`` (the
                batch holds microseconds).
            columns: the order of ``(N, k)`` streams' columns, e.g. ``"txyp"``.
            validate: check every column once (one ``aminmax`` pass each): coordinates
                fit int16 (events outside ``sensor_size`` are kept, and warned about once
                with :class:`~event_transforms.events.EventsOutsideSensorWarning`: the
                binning will drop them), polarity is bool, {0, 1} or {-1, 1}, uint64 timestamps fit
                int64. ``False`` skips these checks for data the caller already trusts
                (the same batch for valid data, about half the time for a list of
                structured arrays); the parsing itself (field names, NaN in float
                columns) still refuses malformed input.

        Shape:
            - streams: B streams, each ``(N_b, 4)`` rows ``(x, y, t, p)``, a structured array or
              a mapping of ``(N_b,)`` columns; or one ``(B, N, 4)`` array.
            - output: a batch of B streams, ``sum(N_b)`` events.

        Raises:
            ValueError: malformed streams, coordinates beyond int16, mixed timestamp kinds.

        Example:
            >>> streams = [torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]), torch.tensor([[1, 1, 50, -1]])]
            >>> batch = EventBatch.from_streams(streams, sensor_size=(2, 3), frame_ms=10.0)
            >>> batch.lengths, batch.t_start.tolist(), batch.p.tolist()  # polarity -1/1 read as 0/1
            ([2, 1], [0, 0], [1, 0, 0])
        """
        if sensor_size is None and tonic_sensor_size is None:
            raise TypeError("EventBatch.from_streams needs sensor_size=(H, W) or tonic_sensor_size=(W, H, P)")
        if isinstance(streams, (np.ndarray, Tensor)) and getattr(streams, "ndim", 0) == 3:
            streams = list(streams)
        if isinstance(streams, (str, bytes, Mapping)) or not isinstance(streams, Sequence):
            raise TypeError(f"streams must be a sequence of event streams, got {type(streams).__name__}")
        height, width = _sensor(sensor_size, tonic_sensor_size)
        # each stream once: a structured array of narrow integer fields is kept as it is
        # (filled straight into the batch), anything else goes through the column parser
        parsed: list[Any] = []
        for i, stream in enumerate(streams):
            if time_unit is None and columns is None and _narrow_struct(stream):
                parsed.append(stream)
                continue
            (x, y, t, p), batched = canonical_columns(stream, time_unit=time_unit, columns=columns)
            if batched:
                raise ValueError(f"streams[{i}] is a batch of shape {tuple(x.shape)}; pass one stream per entry")
            parsed.append((x[0], y[0], t[0], p[0]))
        lengths = [len(s) if isinstance(s, np.ndarray) else s[0].shape[0] for s in parsed]
        # float timestamps only if a non-empty stream has them (an empty float tensor has none)
        time_dtype = torch.float64 if any(
            isinstance(s, tuple) and s[2].is_floating_point() and s[2].numel() for s in parsed
        ) else torch.int64
        devices = {s[0].device for s in parsed if isinstance(s, tuple)}
        target = torch.device(device) if device is not None else (devices.pop() if len(devices) == 1 else torch.device("cpu"))
        total = sum(lengths)
        # structured arrays are filled through numpy views: on the CPU, then moved
        home = torch.device("cpu") if any(isinstance(s, np.ndarray) for s in parsed) else target
        x_all, y_all = (torch.empty(total, dtype=torch.int16, device=home) for _ in range(2))
        t_all, p_all = torch.empty(total, dtype=time_dtype, device=home), torch.empty(total, dtype=torch.int8, device=home)
        start = 0
        for i, (stream, n) in enumerate(zip(parsed, lengths)):
            out = (x_all[start : start + n], y_all[start : start + n], t_all[start : start + n], p_all[start : start + n])
            if isinstance(stream, np.ndarray):
                _fill_from_struct(out, stream, i, validate)
            else:
                _fill_from_columns(out, stream, i, validate)
            start += n
        if validate and total:
            _warn_outside_sensor(x_all, y_all, height, width)
        x, y, t, p = (c.to(target) for c in (x_all, y_all, t_all, p_all))
        offsets = torch.tensor([0, *np.cumsum(lengths, dtype=np.int64).tolist()], dtype=torch.int64)
        batch = cls(x, y, t, p, offsets, (height, width))
        if frame_ms is not None:
            batch = batch.with_grid(frame_ms, t_start=t_start, n_frames=n_frames)
            if validate and total and (n_frames is not None or not isinstance(t_start, str)):
                _warn_outside_window(batch, t_start, n_frames)
        return batch

    def with_grid(
        self, frame_ms: float, *, t_start: str | float | Sequence[float] | Tensor = "floor", n_frames: int | None = None
    ) -> EventBatch:
        """This batch with a frame grid: per-stream starts resolved now, by the ``events_to_frames`` rule.

        ``"floor"``/``"first"`` read each stream's first timestamp: one host read when the
        columns are on an accelerator (build the grid on the CPU, in the ``DataLoader``,
        to keep training steps free of it). An empty stream starts at 0.

        Args:
            frame_ms: bin width in milliseconds (> 0).
            t_start: ``"floor"``, ``"first"``, a time in microseconds or one per stream.
            n_frames: the grid's number of bins (``None``: enough for the last event).

        Shape:
            - t_start: a number, or ``(B,)``.
            - output: the same columns; ``frame_shape`` ``(B, n_frames or 1, 2, H, W)``.

        Example:
            >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
            ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3))
            >>> gridded = batch.with_grid(10.0, n_frames=2)
            >>> gridded.t_start.tolist(), gridded.frame_shape
            ([0, 0], torch.Size([2, 2, 2, 2, 3]))
        """
        frame_us = bin_width_us(frame_ms)
        starts = _resolve_starts(self, t_start, frame_us)
        if n_frames is not None:
            n_frames = check_integer(n_frames, "n_frames")
        return self._replace(frame_ms=float(frame_ms), t_start=starts, n_frames=n_frames)

    # ------------------------------------------------------------------ containers

    def __len__(self) -> int:
        return self.offsets.shape[0] - 1

    @property
    def lengths(self) -> list[int]:
        """Events per stream (read from the CPU offsets: no synchronisation)."""
        return _lengths_of(self.offsets)

    @property
    def num_events(self) -> int:
        return self.offsets.tolist()[-1]

    @property
    def device(self) -> torch.device:
        return self.x.device

    @property
    def nbytes(self) -> int:
        """Bytes held by the columns (the offsets and cached index not counted)."""
        return sum(c.numel() * c.element_size() for c in (self.x, self.y, self.t, self.p))

    @property
    def frame_shape(self) -> torch.Size:
        """``(B, T, 2, H, W)``: the shape transforms draw parameters for (T = 1 without ``n_frames``)."""
        return torch.Size((len(self), self.n_frames or 1, 2, *self.sensor_size))

    def __repr__(self) -> str:
        grid = "" if self.frame_ms is None else f", frame_ms={self.frame_ms}, n_frames={self.n_frames}"
        return (
            f"EventBatch(streams={len(self)}, events={self.num_events}, sensor_size={self.sensor_size}"
            f"{grid}, device={self.device})"
        )

    def _replace(self, **changes: Any) -> EventBatch:
        fields: dict[str, Any] = {
            "x": self.x, "y": self.y, "t": self.t, "p": self.p, "offsets": self.offsets,
            "sensor_size": self.sensor_size, "frame_ms": self.frame_ms, "t_start": self.t_start,
            "n_frames": self.n_frames,
        }
        # the cached per-event sample index survives unless the streams' events change
        sample = changes.pop("_sample") if "_sample" in changes else (None if "offsets" in changes else self._sample)
        fields.update(changes)
        return EventBatch(
            fields["x"], fields["y"], fields["t"], fields["p"], fields["offsets"], fields["sensor_size"],
            frame_ms=fields["frame_ms"], t_start=fields["t_start"], n_frames=fields["n_frames"], _sample=sample,
        )

    def to(self, device: torch.device | str, *, non_blocking: bool = False) -> EventBatch:
        """The batch with its columns on ``device`` (offsets and grid stay on the CPU).

        Args:
            device: the target device.
            non_blocking: copy asynchronously (from pinned memory).

        Shape:
            Columns ``(N,)`` on ``device``; offsets ``(B + 1,)`` on the CPU.

        Example:
            >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
            ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3))
            >>> moved = batch.to("cpu")
            >>> moved.device, moved.offsets.tolist()
            (device(type='cpu'), [0, 2, 3])
        """
        move = lambda c: c.to(device, non_blocking=non_blocking)  # noqa: E731
        sample = None if self._sample is None else move(self._sample)
        return self._replace(x=move(self.x), y=move(self.y), t=move(self.t), p=move(self.p), _sample=sample)

    def pin_memory(self) -> EventBatch:
        """The batch with its (CPU) columns in pinned memory, for fast non-blocking copies.

        Shape:
            The columns' shapes kept.
        """
        return self._replace(x=self.x.pin_memory(), y=self.y.pin_memory(), t=self.t.pin_memory(), p=self.p.pin_memory())

    def __getitem__(self, index: int | slice | Sequence[int] | Tensor) -> EventBatch:
        """Streams by position: an int or a slice (a batch of those streams), or a list/tensor of indices."""
        b = len(self)
        if isinstance(index, (int, np.integer)) and not isinstance(index, bool):
            i = int(index)
            if not -b <= i < b:
                raise IndexError(f"stream index {index} out of range for a batch of {b}")
            index = slice(i % b, i % b + 1)
        if isinstance(index, slice):
            start, stop, step = index.indices(b)
            if step == 1:
                stop = max(stop, start)
                bounds = self.offsets.tolist()
                lo, hi = bounds[start], bounds[stop]
                cols = {k: getattr(self, k)[lo:hi] for k in _FIELDS}
                sample = None if self._sample is None else self._sample[lo:hi] - start
                t_start = None if self.t_start is None else self.t_start[start:stop]
                return self._replace(**cols, offsets=self.offsets[start : stop + 1] - lo, t_start=t_start, _sample=sample)
            index = list(range(start, stop, step))
        return self.index_select(torch.as_tensor(index, dtype=torch.int64).reshape(-1))

    def index_select(self, index: Tensor) -> EventBatch:
        """The streams ``index`` (a CPU int64 tensor), in that order, as a new batch.

        Args:
            index: stream positions, negative ones counted from the end; repeats allowed.

        Shape:
            - index: ``(K,)``.
            - output: a batch of K streams.

        Example:
            >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
            ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3))
            >>> picked = batch.index_select(torch.tensor([1, 0, 1]))
            >>> picked.lengths, picked.x.tolist()
            ([1, 2, 1], [1, 0, 2, 1])
        """
        rows = [int(i) for i in index.tolist()]
        b = len(self)
        for i in rows:
            if not -b <= i < b:
                raise IndexError(f"stream index {i} out of range for a batch of {b}")
        rows = [i % b for i in rows] if b else rows
        bounds = np.asarray(self.offsets.tolist(), dtype=np.int64)
        picked = np.asarray(rows, dtype=np.int64)
        lo, hi = bounds[picked], bounds[picked + 1]
        spans = _Spans(np.zeros(picked.size, dtype=np.int64), lo, hi, [int(bounds[-1])], self.x.device)
        cols = {k: spans.gather([getattr(self, k)]) for k in _FIELDS}
        offsets = torch.from_numpy(np.concatenate(([0], np.cumsum(hi - lo))).astype(np.int64))
        t_start = None if self.t_start is None else self.t_start[torch.tensor(rows, dtype=torch.int64)]
        return self._replace(**cols, offsets=offsets, t_start=t_start)

    def split(self) -> list[EventBatch]:
        """One single-stream batch per stream.

        Shape:
            B batches of one stream each.

        Example:
            >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
            ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3))
            >>> [part.lengths for part in batch.split()]
            [[2], [1]]
        """
        return [self[i] for i in range(len(self))]

    def sample_index(self) -> Tensor:
        """(N,) int32 stream index of every event, on the batch's device (built once, cached).

        Shape:
            ``(N,)`` int32.

        Example:
            >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
            ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3))
            >>> batch.sample_index().tolist()
            [0, 0, 1]
        """
        if self._sample is None:
            n = self.num_events
            if n < 2**31:  # the one-argument form writes each stream's index run by run: no gather
                sample = torch.repeat_interleave(torch.tensor(self.lengths, dtype=torch.int32), output_size=n)
            else:
                ids = torch.arange(len(self), dtype=torch.int32)
                sample = torch.repeat_interleave(ids, torch.tensor(self.lengths, dtype=torch.int64), output_size=n)
            self._sample = sample.to(self.device)
        return self._sample

    def columns(self) -> dict[str, Tensor]:
        """The columns as a dict ``{"x", "y", "t", "p"}``.

        Shape:
            Four ``(N,)`` columns: x, y int16, t int64 (or float64), p int8.

        Example:
            >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
            ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3))
            >>> {name: column.tolist() for name, column in batch.columns().items()}
            {'x': [0, 2, 1], 'y': [1, 0, 1], 't': [100, 15000, 50], 'p': [1, 0, 0]}
        """
        return {k: getattr(self, k) for k in _FIELDS}

    def to_padded(self) -> tuple[Tensor, Tensor]:
        """``(B, N_max, 4)`` int64/float64 rows ``(x, y, t, p)`` padded with zeros, and the (B,) lengths.

        Shape:
            - rows: ``(B, N_max, 4)``, N_max the longest stream; int64 (float64 for float times).
            - lengths: ``(B,)`` int64.

        Example:
            >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
            ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3))
            >>> rows, lengths = batch.to_padded()
            >>> rows[1].tolist(), lengths.tolist()
            ([[1, 1, 50, 0], [0, 0, 0, 0]], [2, 1])
        """
        lengths = self.lengths
        width = max(lengths, default=0)
        dtype = self.t.dtype
        rows = torch.zeros(len(self), width, 4, dtype=dtype, device=self.device)
        if self.num_events:
            sample = self.sample_index().to(torch.int64)
            position = torch.arange(self.num_events, device=self.device) - self.offsets.to(self.device)[sample]
            values = torch.stack([self.x.to(dtype), self.y.to(dtype), self.t, self.p.to(dtype)], 1)
            rows[sample, position] = values
        return rows, torch.tensor(lengths, dtype=torch.int64)


def _narrow_struct(stream: Any) -> bool:
    """Whether ``stream`` is a 1-D structured array whose x and y fit int16 by dtype or
    are uint16, whose t is an integer and whose p is bool or one byte, under the plain
    names ``x``, ``y``, ``t``, ``p``: its fields are copied straight into the batch."""
    if not isinstance(stream, np.ndarray) or stream.dtype.names is None or stream.ndim != 1:
        return False
    fields = stream.dtype.fields or {}
    if not all(name in fields for name in _FIELDS):
        return False
    kinds = {name: fields[name][0] for name in _FIELDS}
    coords = all(kinds[c].kind in "iu" and kinds[c].itemsize <= 2 for c in ("x", "y"))
    return coords and kinds["t"].kind in "iu" and (kinds["p"].kind == "b" or (kinds["p"].kind in "iu" and kinds["p"].itemsize == 1))


def _warn_outside_sensor(x: Tensor, y: Tensor, height: int, width: int) -> None:
    """The caller's streams hold events outside ``sensor_size``: one warning at the caller's line."""
    x_low, x_high = (int(v) for v in torch.aminmax(x))
    y_low, y_high = (int(v) for v in torch.aminmax(y))
    if x_low >= 0 and y_low >= 0 and x_high < width and y_high < height:
        return

    outside = int(((x < 0) | (x >= width) | (y < 0) | (y >= height)).sum())
    warn_at_caller(EventsOutsideSensorWarning(outside, x.numel(), (height, width), (x_low, x_high), (y_low, y_high)))


def _warn_outside_window(batch: EventBatch, t_start: object, n_frames: int | None) -> None:
    """The caller's streams hold events outside the grid they declared (``t_start``,
    ``n_frames``), which the binning will drop: one warning at the caller's line, with counts."""
    assert batch.t_start is not None and batch.frame_ms is not None
    frame_us = bin_width_us(batch.frame_ms)
    rel = batch.t - batch.t_start.to(device=batch.device, dtype=batch.t.dtype).index_select(0, batch.sample_index())
    outside = rel < 0
    if n_frames is not None:
        outside |= rel >= n_frames * frame_us
    per = torch.zeros(len(batch), dtype=torch.int64, device=batch.device).index_add_(
        0, batch.sample_index(), outside.to(torch.int64)).tolist()
    if not any(per):
        return
    window = (f"the grid of EventBatch.from_streams(t_start={t_start!r}, n_frames={n_frames}, "
              f"frame_ms={batch.frame_ms!r})")
    hint = ("the binning of this batch drops them; leave n_frames=None for a grid that holds every stream's last "
            "event, or cut the streams to the window" if n_frames is not None else
            "the binning of this batch drops them; t_start='floor' starts each stream's grid at its first event")
    warn_at_caller(EventsOutsideWindowWarning(sum(per), batch.num_events, list(zip(per, batch.lengths)), window, hint))


def _fill_from_struct(out: tuple[Tensor, ...], stream: np.ndarray, i: int, validate: bool) -> None:
    """Copy a :func:`_narrow_struct` stream's fields into the batch's column slices (one
    casting pass each), then check what the cast may have hidden (one pass each)."""
    x, y, t, p = out
    for name, column in (("x", x), ("y", y)):
        field = stream[name]
        if validate and field.dtype.kind == "u" and field.dtype.itemsize == 2 and field.size and int(field.max()) > _COORD_MAX:
            raise ValueError(f"streams[{i}] {name} must fit int16 pixel coordinates, got {int(field.max())}")
        column.numpy()[...] = field
    t_field = stream["t"]
    t.numpy()[...] = t_field
    if validate and t_field.dtype.kind == "u" and t_field.dtype.itemsize == 8 and t.numel() and bool(t.min() < 0):
        raise ValueError(f"streams[{i}] t holds {int(t_field.max())}, past 2**63 - 1, which int64 cannot hold")
    p.numpy()[...] = stream["p"]
    if stream["p"].dtype.kind != "b":
        if validate:
            _check_polarity(p if stream["p"].dtype.kind == "i" else torch.from_numpy(stream["p"].astype(np.int16)), None)
        p.clamp_(min=0)  # OFF as -1 becomes 0


def _fill_from_columns(out: tuple[Tensor, ...], columns: tuple[Tensor, ...], i: int, validate: bool) -> None:
    """Copy parsed int64/float64 columns into the batch's column slices: coordinates
    floored and checked against int16, polarity checked and mapped to {0, 1}."""
    x, y, t, p = out
    for name, column, target in (("x", columns[0], x), ("y", columns[1], y)):
        column = torch.floor(column) if column.is_floating_point() else column
        if validate and column.numel():
            low, high = (int(v) for v in torch.aminmax(column))
            if low < -_COORD_MAX or high > _COORD_MAX:
                raise ValueError(f"streams[{i}] {name} must fit int16 pixel coordinates, got {max(-low, high)}")
        target.copy_(column)
    t.copy_(columns[2])
    if validate:
        _check_polarity(columns[3], None)
    p.copy_(columns[3] > 0)


#: On the CPU, gathers of whole streams copy runs of adjacent events as slices (a ``memcpy``
#: each, about 5x faster there than an ``index_select`` of every event); on an accelerator
#: they are one ``index_select`` per field, whatever the number of streams. Tests switch it
#: off to count the accelerator path's ops on the CPU.
SLICES_ON_CPU = True


class _Spans:
    """How to gather the spans ``[lo[i], hi[i])`` of sources ``owner[i]``, in order, computed
    once on the host and applied to every field: the spans with adjacent ones of the same
    source joined (slices, on the CPU), or the events' positions in the sources' concatenation
    (one ``index_select``, elsewhere)."""

    def __init__(self, owner: np.ndarray, lo: np.ndarray, hi: np.ndarray, sizes: Sequence[int], device: torch.device) -> None:
        self.index: Tensor | None = None
        if SLICES_ON_CPU and device.type == "cpu":
            keep = hi > lo
            owner, lo, hi = owner[keep], lo[keep], hi[keep]
            if lo.size == 0:
                self.runs: list[tuple[int, int, int]] = []
                return
            new = np.ones(lo.size, dtype=bool)
            new[1:] = (owner[1:] != owner[:-1]) | (lo[1:] != hi[:-1])
            starts = np.flatnonzero(new)
            ends = np.append(starts[1:], lo.size) - 1
            self.runs = list(zip(owner[starts].tolist(), lo[starts].tolist(), hi[ends].tolist()))
            return
        base = np.concatenate(([0], np.cumsum(sizes, dtype=np.int64)[:-1])).astype(np.int64)
        first, last = lo + base[owner], hi + base[owner]
        lengths = last - first
        shift = np.repeat(first - (np.cumsum(lengths) - lengths), lengths)
        self.index = torch.from_numpy(shift + np.arange(int(lengths.sum()), dtype=np.int64))

    def gather(self, pieces: Sequence[Tensor]) -> Tensor:
        """The spans of ``pieces`` (one column per source, in ``owner``'s numbering)."""
        if self.index is None:
            if len(self.runs) == 1:
                k, a, b = self.runs[0]
                return pieces[k][a:b]
            return torch.cat([pieces[k][a:b] for k, a, b in self.runs]) if self.runs else pieces[0][:0]
        column = pieces[0] if len(pieces) == 1 else torch.cat(list(pieces))
        return column.index_select(0, index_on(self.index, column.device))


def merge_streams(parts: Sequence[tuple[Sequence[int], EventBatch]], batch: int, like: EventBatch) -> EventBatch:
    """Reassemble B streams from pieces: ``parts`` gives, for some batches, the stream
    positions their streams go to. Every position must be covered once. One ``cat`` and one
    ``index_select`` per field, whatever B (the offsets are read on the host)."""
    owner = np.full(batch, -1, dtype=np.int64)  # which part, and which stream of it
    row = np.zeros(batch, dtype=np.int64)
    for k, (positions, _) in enumerate(parts):
        owner[np.asarray(positions, dtype=np.int64)] = k
        row[np.asarray(positions, dtype=np.int64)] = np.arange(len(positions))
    if (owner < 0).any():
        raise ValueError("merge_streams: every stream position must be covered")
    return _assemble([part for _, part in parts], owner, row, like)


def replace_streams(batch: EventBatch, positions: np.ndarray, part: EventBatch) -> EventBatch:
    """``batch`` with its streams ``positions`` (host indices, in ``part``'s order) replaced
    by ``part``'s streams: one ``cat`` and one ``index_select`` per field, whatever B."""
    owner = np.zeros(len(batch), dtype=np.int64)
    row = np.arange(len(batch), dtype=np.int64)
    owner[positions] = 1
    row[positions] = np.arange(len(positions))
    return _assemble([batch, part], owner, row, batch)


def _assemble(sources: Sequence[EventBatch], owner: np.ndarray, row: np.ndarray, like: EventBatch) -> EventBatch:
    """Streams ``row[i]`` of ``sources[owner[i]]``, in order, on ``like``'s grid."""
    bounds = [np.asarray(source.offsets.tolist(), dtype=np.int64) for source in sources]
    first = np.concatenate(([0], np.cumsum([b.size - 1 for b in bounds])[:-1])).astype(np.int64)
    which = first[owner] + row
    lo = np.concatenate([b[:-1] for b in bounds])[which]
    hi = np.concatenate([b[1:] for b in bounds])[which]
    spans = _Spans(owner, lo, hi, [int(b[-1]) for b in bounds], like.x.device)
    dtype = like.t.dtype
    for source in sources:
        dtype = torch.promote_types(dtype, source.t.dtype)
    cols = {}
    for k in _FIELDS:
        pieces = [getattr(source, k) for source in sources]
        if k == "t":
            pieces = [piece if piece.dtype == dtype else piece.to(dtype) for piece in pieces]
        cols[k] = spans.gather(pieces)
    offsets = torch.from_numpy(np.concatenate(([0], np.cumsum(hi - lo))).astype(np.int64))
    return like._replace(**cols, offsets=offsets, _sample=None)


def collate_events(
    streams: Sequence[Any],
    *,
    sensor_size: tuple[int, int] | None = None,
    tonic_sensor_size: tuple[int, int, int] | None = None,
    frame_ms: float | None = None,
    t_start: str | float = "floor",
    n_frames: int | None = None,
    time_unit: str | None = None,
    columns: str | Sequence[str] | None = None,
    validate: bool = True,
) -> Any:
    """A ``DataLoader`` ``collate_fn`` body: a list of streams (or of ``(stream, label, ...)``
    tuples) to an :class:`EventBatch` (and the labels collated by torch's default).

    ``validate=False`` skips the column checks for trusted data (see
    :meth:`EventBatch.from_streams`). Bind the sensor and grid with :func:`functools.partial`:
    ``DataLoader(dataset, batch_size=32, collate_fn=partial(collate_events, sensor_size=(180, 240), frame_ms=10.0))``.

    Args:
        streams: event streams (as :meth:`EventBatch.from_streams` takes them), or tuples
            whose first entry is a stream and the rest labels.
        sensor_size: ``(H, W)``; or tonic's ``tonic_sensor_size=(W, H, P)``.
        frame_ms, t_start, n_frames: the frame grid, as in :meth:`EventBatch.from_streams`.

    Shape:
        - streams: B streams of ``N_b`` events each.
        - output: an :class:`EventBatch` of B streams, or ``(batch, *labels)`` with the labels
          stacked ``(B, ...)``.

    Example:
        >>> import numpy as np
        >>> events = np.zeros(2, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
        >>> batch, labels = collate_events([(events, 1.0), (events[:1], 2.0)], sensor_size=(4, 4))
        >>> batch.lengths, labels.tolist()
        ([2, 1], [1.0, 2.0])
    """
    options: dict[str, Any] = dict(sensor_size=sensor_size, tonic_sensor_size=tonic_sensor_size, frame_ms=frame_ms,
                   t_start=t_start, n_frames=n_frames, time_unit=time_unit, columns=columns, validate=validate)
    if streams and isinstance(streams[0], Mapping) and _field(streams[0].keys(), "x") is None:
        keys = sorted(map(str, streams[0]))
        stream_key = next((k for k in keys if k in ("events", "stream")), keys[0] if keys else "events")
        others = ", ".join(f"item[{k!r}]" for k in keys if k != stream_key) or "labels"
        raise TypeError(
            f"collate_events takes streams or (stream, label, ...) tuples; streams[0] is a dict with keys {keys}, "
            f"not event columns x, y, t, p. Return (item[{stream_key!r}], {others}) from the data set's "
            f"__getitem__, or wrap it: collate_fn=lambda items: collate_events([(i[{stream_key!r}], "
            f"{others.replace('item[', 'i[')}) for i in items], sensor_size=...)"
        )
    if streams and isinstance(streams[0], tuple):
        from torch.utils.data import default_collate

        first, *rest = zip(*streams)
        for position, labels in enumerate(rest, start=1):
            _check_label_shapes(labels, position)
        return (EventBatch.from_streams(list(first), **options), *(default_collate(list(r)) for r in rest))
    return EventBatch.from_streams(list(streams), **options)


def _check_label_shapes(labels: Sequence[Any], position: int) -> None:
    """Refuse labels (entry ``position`` of each item) of unequal shapes, naming the items."""
    shapes = [tuple(np.shape(v)) if isinstance(v, (Tensor, np.ndarray, list)) else None for v in labels]
    found = {s for s in shapes if s is not None}
    if len(found) <= 1:
        return
    common = max(found, key=shapes.count)
    odd = [f"item {i}: {s}" for i, s in enumerate(shapes) if s is not None and s != common][:5]
    lengths = sorted({s[0] for s in found if s})
    raise ValueError(
        f"collate_events: entry {position} of the items (a label) has unequal shapes, so they cannot be "
        f"stacked: most are {common}, but {'; '.join(odd)} (lengths {lengths}). Give every item of a batch "
        "labels of one shape: windows of one n_frames (a force label per frame), or pad them in the data set"
    )


# --------------------------------------------------------------------------- grid & binning


def _segment_first(batch: EventBatch, column: Tensor, reduce: str) -> list[Any]:
    """Per-stream min/max of ``column`` read on the host (None for an empty stream)."""
    lengths = batch.lengths
    if not batch.num_events:
        return [None] * len(batch)
    sample = batch.sample_index().to(torch.int64)
    fill = math.inf if column.is_floating_point() else (2**63 - 1)
    init = torch.full((len(batch),), fill if reduce == "amin" else -fill, dtype=column.dtype, device=column.device)
    values = read_host(init.scatter_reduce(0, sample, column, reduce=reduce))
    return [v if n else None for v, n in zip(values, lengths)]


def _resolve_starts(batch: EventBatch, t_start: object, frame_us: float | int) -> Tensor:
    if isinstance(t_start, str):
        if t_start not in T_START_RULES:
            raise ValueError(f"t_start must be 'floor', 'first', a number or one per stream, got {t_start!r}")
        firsts = [0 if v is None else v for v in _segment_first(batch, batch.t, "amin")]
        starts = torch.tensor(firsts, dtype=batch.t.dtype)
        return _floor_to_grid(starts, frame_us) if t_start == "floor" else starts
    return explicit_starts(t_start, len(batch))
