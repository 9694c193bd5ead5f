"""``EventsToFrames``: an event stream in, frames ``(T, 2, H, W)`` out, as a module."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from .._validation import FRAME_DTYPES
from ..events.batch import EventBatch
from ..events.binning import bin_events
from ..events.binning import CHUNK_EVENTS, events_to_frames
from ..events._kernel import build_grid
from ..events._ingest import explicit_starts
from ..events._ingest import check_integer, column_order, T_START_RULES, check_time_unit
from .base import EventTransform, Params

__all__ = ["EventsToFrames"]


class EventsToFrames(EventTransform):
    """Count an event stream into frames: :func:`~event_transforms.functional.events_to_frames` as a module.

    Takes what tonic hands a dataset transform (a structured array, tonic's titled
    ``('p', 'on')`` field and absolute uint64 timestamps included), a ``(N, 4)`` array or
    tensor, or a mapping of ``x, y, t, p`` columns, and returns ``(T, 2, H', W')`` counts
    ready for the frame transforms. It holds settings only, draws nothing and is
    picklable, so it runs as a tonic dataset ``transform=`` or in a ``DataLoader`` worker.
    Put it first in a :class:`~event_transforms.Compose` to make the whole pipeline take
    events. An :class:`~event_transforms.EventBatch` is binned on its own device
    (:func:`~event_transforms.functional.bin_events`, bin by bin equal to this module per
    stream; the batch's frame grid, if it has one, fixes the starts), and then this module
    may stand anywhere in a ``Compose``: event transforms before it, frame transforms after. With ``n_frames=None`` the number of frames follows the recording; give
    ``n_frames`` when a ``DataLoader`` must stack samples.

    Args:
        sensor_size: ``(H, W)`` of the sensor, height first (required, or give
            ``tonic_sensor_size``); events outside it are dropped with an
            :class:`~event_transforms.functional.EventsOutsideSensorWarning`.
        tonic_sensor_size: tonic's ``(W, H, P)`` (``dataset.sensor_size``) instead.
        frame_ms: bin width in milliseconds.
        n_frames: number of frames T, or ``None`` for as many as the recording needs.
        t_start: ``"floor"`` (the first event rounded down to a multiple of the bin
            width), ``"first"``, or a time in microseconds.
        crop: ``(top, left, height, width)`` window inside the sensor, or ``None``.
        pool: side of the square blocks summed into one output pixel.
        dtype: dtype of the counts.
        chunk_size: events read at a time (bounds the extra memory).
        time_unit: the timestamps' unit, ``"us"``, ``"ms"``, ``"s"`` or ``"ns"``, as in
            :func:`~event_transforms.functional.events_to_frames` (``None``: microseconds,
            float timestamps that look like seconds refused).
        columns: what each column of ``(N, k)`` rows holds, e.g. ``"txyp"``.

    Shape:
        - input: an event stream of N events (or a ``(B, N, 4)`` batch of equally long
          streams).
        - output: ``(T, 2, H', W')`` (``(B, T, 2, H', W')`` for a batch), then any
          further inputs unchanged.

    Example:
        >>> import numpy as np
        >>> import event_transforms as et
        >>> events = np.zeros(3, dtype=[("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])
        >>> events["t"] = [1_700_000_000_000_000, 1_700_000_000_012_000, 1_700_000_000_025_000]
        >>> events["x"], events["y"], events["p"] = [0, 1, 2], [1, 1, 0], [True, False, True]
        >>> to_frames = et.EventsToFrames(tonic_sensor_size=(3, 2, 2), n_frames=4)
        >>> to_frames
        EventsToFrames(sensor_size=(2, 3), frame_ms=10.0, n_frames=4, t_start='floor')
        >>> to_frames(events).shape
        torch.Size([4, 2, 2, 3])
        >>> pipeline = et.Compose([to_frames, et.HorizontalFlip()])
        >>> pipeline(events)[0, 1].tolist()  # frame 0, ON channel, flipped left-right
        [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """

    def __init__(
        self,
        sensor_size: tuple[int, int] | None = None,
        *,
        tonic_sensor_size: tuple[int, int, int] | None = None,
        frame_ms: float = 10.0,
        n_frames: int | None = None,
        t_start: str | float = "floor",
        crop: tuple[int, int, int, int] | None = None,
        pool: int = 1,
        dtype: torch.dtype = torch.float32,
        chunk_size: int = CHUNK_EVENTS,
        time_unit: str | None = None,
        columns: str | Sequence[str] | None = None,
    ) -> None:
        super().__init__()
        if sensor_size is None and tonic_sensor_size is None:
            raise TypeError(
                "EventsToFrames needs sensor_size=(H, W) or tonic_sensor_size=(W, H, P): real sensors "
                "differ (DAVIS240 (180, 240), DVXplorer (240, 320)), and a wrong size drops events"
            )
        grid = build_grid(sensor_size, tonic_sensor_size, crop, pool, frame_ms, dtype)
        self.sensor_size = (grid.height, grid.width)
        self.frame_ms = float(frame_ms)
        self.n_frames = None if n_frames is None else check_integer(n_frames, "n_frames")
        if isinstance(t_start, str):
            if t_start not in T_START_RULES:
                raise ValueError(f"t_start must be 'floor', 'first' or a number, got {t_start!r}")
        else:
            t_start = explicit_starts(t_start, 1).item()
        self.t_start = t_start
        self.crop = None if crop is None else (grid.top, grid.left, grid.crop_h, grid.crop_w)
        self.pool = grid.pool
        if grid.dtype not in FRAME_DTYPES:
            raise TypeError(f"dtype must be one of the frame dtypes {FRAME_DTYPES}, got {dtype!r}")
        self.dtype = grid.dtype
        self.chunk_size = check_integer(chunk_size, "chunk_size")
        self.time_unit = check_time_unit(time_unit)
        self.columns = None if columns is None else "".join(column_order(columns))

    @property
    def takes_events(self) -> bool:
        return True

    def events_to_frames(self, events: Any) -> Tensor:
        if isinstance(events, EventBatch):
            return self._bin(events)
        if isinstance(events, Tensor) and events.dim() in (4, 5) and events.shape[-3] == 2:
            raise TypeError(
                f"EventsToFrames takes an event stream, got what looks like frames of shape {tuple(events.shape)}"
            )
        return events_to_frames(
            events,
            sensor_size=self.sensor_size,
            t_start=self.t_start,
            frame_ms=self.frame_ms,
            n_frames=self.n_frames,
            crop=self.crop,
            pool=self.pool,
            dtype=self.dtype,
            chunk_size=self.chunk_size,
            time_unit=self.time_unit,
            columns=self.columns,
        )

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor:
        if isinstance(inputs, EventBatch):  # anywhere in a Compose after event transforms
            return self._bin(inputs)
        return inputs  # made from the events in forward, before the parameters were drawn

    def _bin(self, batch: EventBatch) -> Tensor:
        """Bin an :class:`EventBatch` on its device (:func:`~event_transforms.functional.bin_events`):
        ``(B, T, 2, H', W')``. The batch's frame grid, if it has one, fixes the starts."""
        if tuple(batch.sensor_size) != tuple(self.sensor_size):
            raise ValueError(
                f"EventsToFrames(sensor_size={self.sensor_size}) was handed an EventBatch of sensor_size "
                f"{batch.sensor_size}"
            )
        return bin_events(
            batch, frame_ms=self.frame_ms, t_start=self.t_start, n_frames=self.n_frames, crop=self.crop,
            pool=self.pool, dtype=self.dtype,
        )

    def output_shape(self, shape: torch.Size) -> torch.Size:
        height, width = (self.crop[2], self.crop[3]) if self.crop is not None else self.sensor_size
        frames = self.n_frames if self.n_frames is not None else shape[1]
        return torch.Size((shape[0], frames, 2, height // self.pool, width // self.pool))

    def _settings(self) -> str:
        parts = [f"sensor_size={self.sensor_size}", f"frame_ms={self.frame_ms}", f"n_frames={self.n_frames}",
                 f"t_start={self.t_start!r}"]
        if self.crop is not None:
            parts.append(f"crop={self.crop}")
        if self.pool != 1:
            parts.append(f"pool={self.pool}")
        if self.dtype != torch.float32:
            parts.append(f"dtype={self.dtype}")
        return ", ".join(parts)
