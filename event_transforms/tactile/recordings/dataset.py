"""The data set: a folder of recordings as windows of frames and force labels."""

from __future__ import annotations

__all__ = ["RecordingSet"]

import dataclasses
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import Dataset

from ...events.io import EventFile, stated_sensor_size
from .cache import _CACHE_FORMAT, _cache_dir, _hashes, _key, _load_cached, _save_atomic, content_hash
from .labels import force_triggers, frame_labels, read_force, trigger_offset
from .layout import _ROLES, DEFAULT_SENSOR_SIZE, SPLITS, RecordingEntry, RecordingSettings, _check_crop, read_table
from .scan import EventScan, contact_crop, scan_events


class RecordingSet(Dataset):
    """A user's recordings (the layout of this module) as a data set of windows.

    Items are ``(frames, force, meta)`` like the built-in scenes': ``frames`` float32
    ``(T, 2, H', W')`` event counts (channel 0 OFF, 1 ON), ``force`` float32 ``(T,)`` in
    newtons (NaN for unlabeled recordings), ``meta`` a dict of plain values:
    ``diameter_mm`` (with that column), ``recording`` (the events path as written in
    ``recordings.csv``), ``row``, ``start_frame``, ``index`` and the row's text metadata.

    Args:
        root: the folder holding ``recordings.csv``.
        split: one of :data:`SPLITS`, or ``None`` for every recording of ``role``.
        role: ``"train"`` or ``"deploy"`` (with ``split=None``), ``None`` for every recording.
        settings: a :class:`RecordingSettings`; keyword arguments override its fields.
        cache: cache folder (default ``default_cache_dir() / "recordings"``).
        log: called with one line per recording binned (not per one read from the cache) and
            once per conversion made (force units and columns, trigger offsets).
        deployment: whether the folder must hold deployment recordings (``None``: when
            ``split`` or ``role`` asks for them; a folder of training recordings only loads
            with ``split="train"``).
        **overrides: fields of :class:`RecordingSettings` (``sensor_size``, ``frame_ms``,
            ``frames``, ``stride``, ``crop``, ``pool``, ``force_offset_ms``, ``time_unit``,
            ``columns``, ``force_time_unit``, ``force_column``, ``sync``).

    Attributes:
        recordings: the rows of the chosen recordings.
        crop: the crop used (the first recording's, where rows give their own).
        crop_source: ``"given"``, ``"recordings.csv"`` or ``"contact area of N training recordings"``.
        left_out_frames: frames after the last whole window, summed over the recordings.
        dataset_hash: a hash of every file of the folder's table (events, forces, the table).

    Example:
        See the module docstring.
    """

    def __init__(
        self,
        root: str | os.PathLike[str],
        *,
        split: str | None = None,
        role: str | None = None,
        settings: RecordingSettings | None = None,
        cache: str | os.PathLike[str] | None = None,
        log: Any = None,
        deployment: bool | None = None,
        **overrides: Any,
    ) -> None:
        self.root = Path(root)
        self.settings = dataclasses.replace(settings or RecordingSettings(), **overrides)
        if split is not None and split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS} or None, got {split!r}")
        if role is not None and role not in _ROLES:
            raise ValueError(f"role must be 'train', 'deploy' or None, got {role!r}")
        self.split, self.role = split, role
        self.cache = _cache_dir(cache)
        if deployment is None:
            deployment = split in ("val", "test", "unlabeled") or (split is None and role != "train")
        table = read_table(self.root, deployment=deployment)
        self.all_recordings = table
        self.recordings = [
            r for r in table if (split is None or r.split == split) and (role is None or r.role == role)
        ]
        #: where the sensor size came from: "given", "the files" or "the default" (said in the
        #: error for events outside it)
        self.settings, self.sensor_source = self._resolve_sensor(table, self.settings)
        self._log = _once(log)
        self._hashes = _hashes(self.root, table, self.cache)
        self.dataset_hash = _key({"table": content_hash(self.root / "recordings.csv"),
                                  "files": [self._hashes[r.row] for r in table]})
        self.crop, self.crop_source = self._choose_crop(table, log)
        self._windows: list[tuple[int, int]] = []  # (recording k, start frame)
        self._data: list[dict[str, Any]] = []
        self.left_out_frames = 0
        stride, length = self.settings.window_stride, self.settings.frames
        for k, recording in enumerate(self.recordings):
            data = self._binned(recording, log)
            frames = int(data["frames"].shape[0])
            if frames < length:
                raise ValueError(
                    f"{recording.where()}: {frames} frames of {self.settings.frame_ms:g} ms, fewer than one window of "
                    f"frames={length}; lower frames= (or frame_ms=)"
                )
            starts = range(0, frames - length + 1, stride)
            self.left_out_frames += frames - (starts[-1] + length)
            self._windows.extend((k, s) for s in starts)
            self._data.append(data)

    # ------------------------------------------------------------------ building
    @staticmethod
    def _resolve_sensor(table: list[RecordingEntry], settings: RecordingSettings) -> tuple[RecordingSettings, str]:
        """The settings with the sensor size: given, else the one the files state, else the default;
        and which of the three it is."""
        stated: dict[tuple[int, int], RecordingEntry] = {}
        for recording in table:
            try:
                size = stated_sensor_size(recording.events)
            except ValueError as error:
                raise _named(error, recording) from None
            if size is not None:
                stated.setdefault(size, recording)
        if settings.sensor_size is not None:
            for size, recording in stated.items():
                if size != settings.sensor_size:
                    raise ValueError(f"{recording.where()}: the file states a sensor of (H, W) = {size}, but "
                                     f"sensor_size={settings.sensor_size}; leave sensor_size out to use the file's")
            return settings, "given"
        if len(stated) > 1:
            found = "; ".join(f"{size} ({r.where()})" for size, r in stated.items())
            raise ValueError(f"recordings.csv: the event files state different sensor sizes: {found}; one folder "
                             "holds one camera's recordings")
        return (dataclasses.replace(settings, sensor_size=next(iter(stated), DEFAULT_SENSOR_SIZE)),
                "the files" if stated else "the default")

    def _crop_of(self, recording: RecordingEntry) -> tuple[int, int, int, int]:
        if self.settings.crop is not None:
            return self.settings.crop
        if recording.crop is not None:
            return _check_crop(recording.crop, self.sensor_size, self.settings.pool,
                               f"{recording.where()}: crop")
        return self.crop

    def _choose_crop(self, table: list[RecordingEntry], log: Any) -> tuple[tuple[int, int, int, int], str]:
        settings = self.settings
        if settings.crop is not None:
            return settings.crop, "given"
        if all(r.crop is not None for r in table):
            sizes = {r.crop[2:] for r in table if r.crop is not None}
            if len(sizes) != 1:
                raise ValueError(f"recordings.csv: every row's crop must have one size, got {sorted(sizes)}")
            first = table[0]
            return _check_crop(first.crop, self.sensor_size, settings.pool, f"{first.where()}: crop"), "recordings.csv"
        if any(r.crop is not None for r in table):
            rows = [r.row for r in table if r.crop is None]
            raise ValueError(f"recordings.csv: crop columns are empty on rows {rows[:5]}; fill every row or none")
        training = [r for r in table if r.split == "train"]
        totals = sum(self._scan(r).totals for r in training)
        crop = contact_crop(totals, settings.pool)  # type: ignore[arg-type]
        return crop, f"contact area of {len(training)} training recordings"

    def _scan(self, recording: RecordingEntry) -> EventScan:
        settings = self.settings
        described: dict[str, Any] = {"events": self._hashes[recording.row][0], "sensor": settings.sensor_size}
        if settings.time_unit is not None:  # t_min, t_max are microseconds converted from that unit
            described["time_unit"] = settings.time_unit
        if settings.columns is not None:
            described["columns"] = settings.columns
        path = self.cache / f"scan-{_key(described)}.pt"
        data = _load_cached(path)
        if data is None:
            try:
                scan = scan_events(EventFile(recording.events, columns=settings.columns), self.sensor_size,
                                   recording.where(), settings.time_unit)
            except ValueError as error:
                if self.sensor_source == "the default" and "outside the sensor" in str(error):
                    error = ValueError(f"{error}. No event file states its sensor size and none was given, so the "
                                       f"default {DEFAULT_SENSOR_SIZE} (a DAVIS240) was assumed")
                raise _named(error, recording) from None
            data = {"format": _CACHE_FORMAT, "events": scan.events, "t_min": scan.t_min, "t_max": scan.t_max,
                    "totals": torch.from_numpy(scan.totals)}
            _save_atomic(data, path)
        return EventScan(int(data["events"]), data["t_min"], data["t_max"], data["totals"].numpy())

    def _binned(self, recording: RecordingEntry, log: Any) -> dict[str, Any]:
        settings = self.settings
        crop = self._crop_of(recording)
        events_hash, force_hash = self._hashes[recording.row]
        description = {"format": _CACHE_FORMAT, "events": events_hash, "force": force_hash,
                       "sensor": settings.sensor_size, "frame_ms": settings.frame_ms, "crop": crop,
                       "pool": settings.pool, "force_offset_ms": settings.force_offset_ms}
        for name in ("time_unit", "columns", "force_time_unit", "force_column", "sync"):
            if getattr(settings, name) is not None:
                description[name] = getattr(settings, name)
        path = self.cache / f"recording-{_key(description)}.pt"
        data = _load_cached(path)
        if data is not None:
            return data
        tick = time.perf_counter()
        scan = self._scan(recording)
        data = _bin_recording(recording, scan, settings, crop, self._log)
        _save_atomic(data, path)
        data = _load_cached(path) or data  # memory-mapped from now on
        if log:
            log(f"binned {recording.where()}: {scan.events:,} events into {data['frames'].shape[0]} frames "
                f"in {time.perf_counter() - tick:.1f} s")
        return data

    @property
    def sensor_size(self) -> tuple[int, int]:
        """The sensor size used: given, stated by the files, or the default."""
        assert self.settings.sensor_size is not None
        return self.settings.sensor_size

    # ------------------------------------------------------------------ access
    def __len__(self) -> int:
        return len(self._windows)

    def meta(self, index: int) -> dict[str, Any]:
        """The metadata dict of item ``index``."""
        k, start = self._windows[index]
        recording = self.recordings[k]
        meta: dict[str, Any] = {}
        if recording.diameter_mm is not None:
            meta["diameter_mm"] = recording.diameter_mm
        meta.update(recording.meta)
        meta.update({"recording": str(recording.events.relative_to(self.root)), "row": recording.row,
                     "start_frame": start, "index": int(index)})
        return meta

    def __getitem__(self, index: int) -> tuple[Tensor, Tensor, dict[str, Any]]:
        from ..datasets import item_index

        index = item_index(index, len(self), "windows")
        k, start = self._windows[index]
        data = self._data[k]
        stop = start + self.settings.frames
        frames = data["frames"][start:stop].to(torch.float32)
        force = data["force"][start:stop].to(torch.float32) if data["force"] is not None else \
            torch.full((self.settings.frames,), math.nan)
        return frames, force, self.meta(index)

    @property
    def frames(self) -> Tensor:
        """Every window's frames, float32 ``(N, T, 2, H', W')`` (for :func:`infer_scene`)."""
        if not len(self):
            return torch.zeros(0, self.settings.frames, 2, self.crop[2] // self.settings.pool,
                               self.crop[3] // self.settings.pool)
        return torch.stack([self[i][0] for i in range(len(self))])

    @property
    def labelled(self) -> tuple[list[Tensor], list[Tensor]] | None:
        """Each recording with force labels, whole (not windowed): frames float32 ``(T_i, 2, H', W')``
        and forces ``(T_i,)``, for :func:`infer_scene`'s lags (one lag per recording, so
        overlapping windows do not count twice); ``None`` where no recording has labels."""
        if self._data is None:
            self._data = [self._binned(r, None) for r in self.recordings]
        pairs = [(d["frames"].to(torch.float32), d["force"].to(torch.float32)) for d in self._data
                 if d["force"] is not None]
        return ([f for f, _ in pairs], [force for _, force in pairs]) if pairs else None

    @property
    def diameters(self) -> tuple[float, ...] | None:
        """The distinct sizes of the chosen recordings (``None`` without ``diameter_mm``)."""
        sizes = [r.diameter_mm for r in self.recordings]
        if not sizes or None in sizes:
            return None
        return tuple(sorted({s for s in sizes if s is not None}))

    def __getstate__(self) -> dict[str, Any]:  # workers reload the memory-mapped cache
        state = dict(self.__dict__)
        state["_data"] = None
        state["_log"] = None  # a closure over the caller's log: workers say nothing
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self._data is None:
            self._data = [self._binned(r, None) for r in self.recordings]

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(root={str(self.root)!r}, split={self.split!r}, role={self.role!r}, "
                f"recordings={len(self.recordings)}, windows={len(self)})")


def _named(error: Exception, recording: RecordingEntry) -> ValueError:
    message = str(error)
    return ValueError(message if "recordings.csv row" in message else f"{recording.where()}: {message}")


def _once(log: Any) -> Any:
    """``log`` calling through once per distinct line (conversions are said once)."""
    if not log:
        return None
    said: set[str] = set()

    def say(line: str) -> None:
        if line not in said:
            said.add(line)
            log(line)

    return say


def _bin_recording(recording: RecordingEntry, scan: EventScan, settings: RecordingSettings,
                   crop: tuple[int, int, int, int], log: Any = None) -> dict[str, Any]:
    """Bin one recording through ``iter_frames`` (chunked) and label its frames."""
    from ...functional import iter_frames

    frame_us = settings.frame_us
    t0 = (scan.t_min // frame_us) * frame_us
    n_frames = int((scan.t_max - t0) // frame_us) + 1
    pool = settings.pool
    shape = (n_frames, 2, crop[2] // pool, crop[3] // pool)
    out = torch.zeros(shape, dtype=torch.int32)
    source = EventFile(recording.events, columns=settings.columns)
    assert settings.sensor_size is not None  # resolved by RecordingSet
    try:
        # the scan checked the whole file's units (seconds-looking floats refused without a unit),
        # so the chunks are read as that unit, microseconds by default
        stream = iter_frames(source.chunks(), sensor_size=settings.sensor_size, t_start=t0,
                             frame_ms=settings.frame_ms, n_frames=n_frames, crop=crop, pool=pool, dtype=torch.int32,
                             time_unit=settings.time_unit or "us")
        for k, frame in enumerate(stream):
            out[k] = frame
    except ValueError as error:
        raise _named(error, recording) from None
    force = None
    if recording.force is not None:
        try:
            offset_ms = settings.force_offset_ms
            if settings.sync == "triggers":
                offset_ms = _trigger_offset_ms(recording, source, settings, log)
            t, values = read_force(recording.force, offset_ms=offset_ms, time_unit=settings.force_time_unit,
                                   column=settings.force_column, log=log)
            force = torch.from_numpy(frame_labels(t, values, t_start=float(t0), frame_us=float(frame_us),
                                                  n_frames=n_frames))
        except ValueError as error:
            raise ValueError(f"{recording.where()}, force file {recording.force.name}: {error}") from None
    storage = torch.int16 if out.numel() == 0 or int(out.max()) <= 32767 else torch.int32
    return {"format": _CACHE_FORMAT, "frames": out.to(storage), "force": force, "t_start_us": t0,
            "events": scan.events}


#: Trigger sources counted by ``sync="triggers"`` (dv-processing's numbering: 1 the rising edge of
#: the external input, 3 a pulse on it).
_SYNC_SOURCES = (1, 3)


def _trigger_offset_ms(recording: RecordingEntry, source: EventFile, settings: RecordingSettings, log: Any) -> float:
    """The force clock's lag (ms) from the camera's trigger events and the force CSV's trigger column."""
    from ...events._ingest import TIME_UNITS

    assert recording.force is not None
    if source.triggers is None:
        raise ValueError(f"sync='triggers' needs trigger events in the event file (an .aedat4 recording); "
                         f"{recording.events.name} holds none")
    kept = source.triggers[np.isin(source.triggers["source"], _SYNC_SOURCES)]
    if not kept.size:
        found = sorted(set(source.triggers["source"].tolist()))
        raise ValueError(f"sync='triggers': {recording.events.name} holds no external-input trigger (sources "
                         f"{list(_SYNC_SOURCES)}; found {found or 'none'})")
    camera = kept["t"].astype(np.float64) * float(TIME_UNITS[settings.time_unit or "us"])
    force = force_triggers(recording.force, time_unit=settings.force_time_unit)
    offset, spread = trigger_offset(camera, force, f"{recording.where()} (force file {recording.force.name})")
    if log:
        log(f"{recording.where()}: force clock aligned to the camera's by {offset / 1000:+.3f} ms from "
            f"{camera.size} triggers (spread {spread:.1f} µs)")
    return offset / 1000.0
