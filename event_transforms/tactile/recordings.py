"""Your own recordings: a folder layout, a data set, the benchmark's data, and the simulator's export.

**The layout.** A folder holding ``recordings.csv`` (a header row, one row per recording):

==============  ==========================================================================
column          meaning
==============  ==========================================================================
``events``      path of the event file, relative to the folder (required)
``force``       path of the force CSV, relative to the folder; empty for an unlabeled
                recording (required column)
``role``        ``train`` (labelled training recordings) or ``deploy`` (recordings of the
                setup the model will meet; labelled ones are scored, unlabeled ones only
                feed :func:`~event_transforms.infer_scene`) (required)
``diameter_mm`` the object's size, for size gaps and the stretch (optional; every row then)
``object``,     free text, kept in each item's metadata (optional)
``session``
``split``       overrides the split rule below for this recording: ``train``/``holdout``
                (training role), ``val``/``test`` (deployment role) (optional)
``crop_top``,   this recording's crop window, all four or none (optional; the simulator's
``crop_left``,  export writes them: the built-in data set's fixed crop)
``crop_height``,
``crop_width``
anything else   kept as text in each item's metadata
==============  ==========================================================================

**Event files** in every form the library ingests: ``.npy`` (a structured array with fields
``x, y, t, p`` — ``timestamp``/``on``/``polarity`` accepted, tonic's dtypes included — or an
``(N, 4)`` array of ``x, y, t, p`` rows; read memory-mapped), ``.npz`` (arrays ``x``, ``y``,
``t``, ``p``), ``.csv`` with a header naming the columns, and through optional extras
``.aedat4`` (the ``aedat`` package) and HDF5 ``.h5``/``.hdf5`` (``h5py``: a structured
``events`` or Prophesee-style ``CD/events`` dataset, or one dataset per column). Timestamps
are microseconds unless ``time_unit`` (``--time-unit``) says ``"ns"``, ``"ms"`` or ``"s"``,
sorted; float timestamps with fractions spanning less than 1e6 look like seconds and are
refused without a ``time_unit``. Polarity bool, {0, 1} or {-1, 1}.

**Force files**: CSV with a header holding ``t_us`` (microseconds on the events' clock, after
the declared offset, whatever ``time_unit`` the event files use) and ``force_n`` (newtons), sorted by time, at any rate. The force clock
runs ``force_offset_ms`` behind the camera's: a sample at ``t_us`` on the force clock is at
``t_us + 1000 · force_offset_ms`` on the events' clock (default 0).

**Frames and labels.** A recording is binned from its first event rounded down to the bin
grid (the ``"floor"`` rule of :func:`~event_transforms.functional.events_to_frames`) to the
bin of its last event, in ``frame_ms`` bins, cropped and sum-pooled. A frame's label is the
mean of the force samples inside its bin ``[start, start + frame_ms)``; a bin holding no
sample (force sampled more slowly than the frames) takes the force linearly interpolated at
its centre. The samples must cover the recording: the first at or before the end of the first
bin, the last at or after the start of the last bin. A recording is then cut into windows of
``frames`` (T) frames every ``stride`` frames (default T); frames after the last whole window
are left out (counted in :attr:`RecordingSet.left_out_frames`).

**Splits** (never a recording on both sides): training-role recordings in the order of
``recordings.csv``: the last third (``n // 3``) are the *hold-out* of the stopping rule, the
rest train. Labelled deployment recordings: the first fifth (``ceil(n / 5)``, at least one)
validate, the rest test; at least two are needed. Unlabeled deployment recordings are used
only as frames for :func:`~event_transforms.infer_scene` (never scored). A ``split`` column
overrides the rule per recording.

**Crop.** ``crop=None`` and no crop columns: the contact area's bounding box over the training
recordings (pixels whose event total stands out from the background, see :func:`contact_crop`),
rounded out to multiples of ``pool``.

**Cache.** Each recording's frames and labels are binned once into the package cache
(:func:`~event_transforms.tactile.datasets.default_cache_dir` ``/recordings``), keyed by a hash
of the event and force files' bytes and of the settings, written to a temporary file and
renamed (nothing half-written stays); a cache file that cannot be read is named, deleted and
rebuilt. Binning reads the event file in chunks (memory-mapped ``.npy``) through
:func:`~event_transforms.functional.iter_frames`, so memory is bounded by a chunk plus the
recording's frames, whatever the file's size.

Example:
    >>> import tempfile, numpy as np
    >>> root = Path(tempfile.mkdtemp())
    >>> rng = np.random.default_rng(0)
    >>> rows = ["events,force,role,diameter_mm"]
    >>> for k, role in enumerate(["train"] * 3 + ["deploy"] * 2):
    ...     events = np.zeros(4000, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
    ...     events["t"] = np.sort(rng.integers(0, 200_000, 4000))
    ...     events["x"], events["y"] = rng.integers(10, 30, 4000), rng.integers(5, 25, 4000)
    ...     events["p"] = rng.integers(0, 2, 4000)
    ...     np.save(root / f"r{k}.npy", events)
    ...     t = np.arange(0, 200_000, 2_000)  # 500 Hz
    ...     np.savetxt(root / f"r{k}.csv", np.c_[t, 5 + np.sin(t / 3e4)], delimiter=",",
    ...                header="t_us,force_n", comments="")
    ...     rows.append(f"r{k}.npy,r{k}.csv,{role},15")
    >>> _ = (root / "recordings.csv").write_text("\\n".join(rows) + "\\n")
    >>> train = RecordingSet(root, split="train", sensor_size=(40, 40), frames=10, pool=2,
    ...                      cache=root / "cache")
    >>> frames, force, meta = train[0]
    >>> len(train), tuple(frames.shape), tuple(force.shape), meta["diameter_mm"], train.crop
    (4, (10, 2, 12, 12), (10,), 15.0, (3, 8, 24, 24))
"""

from __future__ import annotations

__all__ = [
    "SPLITS",
    "Recording",
    "RecordingSet",
    "RecordingSettings",
    "contact_crop",
    "content_hash",
    "export_scene",
    "frame_labels",
    "load_recording_data",
    "read_events",
    "read_force",
    "read_table",
]

import csv
import dataclasses
import hashlib
import json
import math
import os
import tempfile
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import Dataset

from .scenes import BenchmarkScene, Session

#: The splits a recording can belong to.
SPLITS = ("train", "holdout", "val", "test", "unlabeled")
_ROLES = ("train", "deploy")
_REQUIRED = ("events", "force", "role")
_KNOWN = (*_REQUIRED, "diameter_mm", "object", "session", "split", "crop_top", "crop_left", "crop_height", "crop_width")
_CROP_COLUMNS = ("crop_top", "crop_left", "crop_height", "crop_width")
_CACHE_FORMAT = 1
_CHUNK = 2**20
_ALIASES = {"x": ("x",), "y": ("y",), "t": ("t", "timestamp"), "p": ("p", "on", "polarity")}


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class RecordingSettings:
    """How recordings become items (every setting has a command-line option and is recorded).

    Attributes:
        sensor_size: ``(H, W)`` of the sensor; events outside it are refused.
        frame_ms: bin width in milliseconds.
        frames: frames T per window.
        stride: frames between window starts (``None``: T, windows do not overlap).
        crop: ``(top, left, height, width)`` for every recording; ``None``: the crop columns
            of ``recordings.csv`` where given, else the contact area of the training data.
        pool: side of the sum-pooled blocks.
        force_offset_ms: the force clock's lag behind the events' clock.
        time_unit: unit of the event files' timestamps: ``"us"``, ``"ms"``, ``"s"`` or
            ``"ns"`` (``None``: microseconds, float timestamps that look like seconds
            refused). Force files stay in ``t_us``.

    Example:
        >>> RecordingSettings(frames=36).window_stride
        36
        >>> RecordingSettings(time_unit="s").as_dict()["time_unit"]
        's'
    """

    sensor_size: tuple[int, int] = (180, 240)
    frame_ms: float = 10.0
    frames: int = 36
    stride: int | None = None
    crop: tuple[int, int, int, int] | None = None
    pool: int = 2
    force_offset_ms: float = 0.0
    time_unit: str | None = None

    def __post_init__(self) -> None:
        from .._validation import check_positive
        from ..events.ingest import _time_unit

        _time_unit(self.time_unit)  # ValueError naming time_unit and the value

        size = tuple(self.sensor_size)
        if len(size) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1 for v in size):
            raise ValueError(f"sensor_size must be two positive integers (H, W), got {self.sensor_size!r}")
        object.__setattr__(self, "sensor_size", (int(size[0]), int(size[1])))
        check_positive(self.frame_ms, "frame_ms")
        check_positive(self.frames, "frames", integer=True)
        check_positive(self.pool, "pool", integer=True)
        if self.stride is not None:
            check_positive(self.stride, "stride", integer=True)
        if not (isinstance(self.force_offset_ms, (int, float)) and math.isfinite(self.force_offset_ms)):
            raise ValueError(f"force_offset_ms must be a finite number, got {self.force_offset_ms!r}")
        if self.crop is not None:
            object.__setattr__(self, "crop", _check_crop(self.crop, self.sensor_size, self.pool, "crop"))

    @property
    def window_stride(self) -> int:
        """The stride in frames (T when none is given)."""
        return int(self.stride or self.frames)

    @property
    def frame_us(self) -> float | int:
        """The bin width in microseconds (an int when whole)."""
        width = float(self.frame_ms) * 1000.0
        return int(round(width)) if abs(width - round(width)) < 1e-9 * width else width

    def as_dict(self) -> dict[str, Any]:
        """The settings as plain JSON values (``time_unit`` only when given, so that the
        keys of data binned before the setting existed stay valid)."""
        out = dataclasses.asdict(self)
        out["sensor_size"] = list(self.sensor_size)
        out["crop"] = None if self.crop is None else list(self.crop)
        out["stride"] = self.window_stride
        if self.time_unit is None:
            del out["time_unit"]
        return out


def _check_crop(crop: Any, sensor: tuple[int, int], pool: int, where: str) -> tuple[int, int, int, int]:
    try:
        values = tuple(int(v) for v in crop)
        if len(values) != 4 or any(float(v) != int(float(v)) for v in crop):
            raise ValueError
    except (TypeError, ValueError):
        raise ValueError(f"{where} must be four integers (top, left, height, width), got {crop!r}") from None
    top, left, height, width = values
    if top < 0 or left < 0 or height < 1 or width < 1 or top + height > sensor[0] or left + width > sensor[1]:
        raise ValueError(f"{where} {values} must lie inside the sensor {sensor} (H, W)")
    if height % pool or width % pool:
        raise ValueError(f"{where} {values}: height and width must be multiples of pool={pool}")
    return values


# --------------------------------------------------------------------------- the table


@dataclass(frozen=True)
class Recording:
    """One row of ``recordings.csv``.

    Attributes:
        row: the row's line number in ``recordings.csv`` (the header is line 1).
        events: the event file.
        force: the force CSV, ``None`` for an unlabeled recording.
        role: ``"train"`` or ``"deploy"``.
        split: the split the rule (or the ``split`` column) gives it, one of :data:`SPLITS`.
        diameter_mm: the object's size, ``None`` without a ``diameter_mm`` column.
        crop: the row's crop columns, ``None`` without them.
        meta: ``object``, ``session`` and the extra columns, as text.
    """

    row: int
    events: Path
    force: Path | None
    role: str
    split: str
    diameter_mm: float | None = None
    crop: tuple[int, int, int, int] | None = None
    meta: dict[str, str] = field(default_factory=dict)

    def where(self) -> str:
        """``recordings.csv row N (events file)``, for error messages."""
        return f"recordings.csv row {self.row} ({self.events.name})"


def read_table(root: str | os.PathLike[str]) -> list[Recording]:
    """Read and check ``root/recordings.csv``; every recording with its split.

    Raises:
        ValueError: a missing table or column, a missing file, a role other than train or
            deploy, a bad ``diameter_mm``, ``split`` or crop cell (each naming the row), no
            labelled training recording, fewer than two labelled deployment recordings.

    Example:
        >>> import tempfile
        >>> root = Path(tempfile.mkdtemp())
        >>> _ = (root / "a.npy").write_bytes(b"")
        >>> _ = (root / "recordings.csv").write_text("events,force,role\\na.npy,,tain\\n")
        >>> read_table(root)
        Traceback (most recent call last):
        ...
        ValueError: recordings.csv row 2: role must be 'train' or 'deploy', got 'tain'
    """
    root = Path(root)
    table = root / "recordings.csv"
    if not table.is_file():
        raise ValueError(f"{root} holds no recordings.csv (the recording-set layout needs one)")
    with open(table, newline="") as handle:
        reader = csv.DictReader(handle)
        header = [name.strip() for name in (reader.fieldnames or [])]
        missing = [c for c in _REQUIRED if c not in header]
        if missing:
            raise ValueError(f"{table}: missing column(s) {missing}; the header is {header}")
        rows = [{(k or "").strip(): (v or "").strip() for k, v in row.items()} for row in reader]
    has_crop = [c for c in _CROP_COLUMNS if c in header]
    if has_crop and len(has_crop) != 4:
        raise ValueError(f"{table}: give all four crop columns {list(_CROP_COLUMNS)} or none, got {has_crop}")
    recordings = []
    for number, row in enumerate(rows, start=2):
        where = f"recordings.csv row {number}"
        if not row.get("events"):
            raise ValueError(f"{where}: the events cell is empty")
        events = root / row["events"]
        if not events.is_file():
            raise ValueError(f"{where}: events file {str(events)!r} does not exist")
        force = root / row["force"] if row.get("force") else None
        if force is not None and not force.is_file():
            raise ValueError(f"{where}: force file {str(force)!r} does not exist")
        role = row.get("role", "").lower()
        if role not in _ROLES:
            raise ValueError(f"{where}: role must be 'train' or 'deploy', got {row.get('role')!r}")
        diameter = None
        if "diameter_mm" in header:
            try:
                diameter = float(row["diameter_mm"])
                if not (math.isfinite(diameter) and diameter > 0):
                    raise ValueError
            except ValueError:
                raise ValueError(f"{where}: diameter_mm must be a positive number, got {row['diameter_mm']!r}") from None
        crop: tuple[int, int, int, int] | None = None
        if has_crop:
            texts = tuple(row[c] for c in _CROP_COLUMNS)
            try:
                top, left, height, width = (int(v) for v in texts)
            except ValueError:
                raise ValueError(f"{where}: crop columns must be integers, got {texts}") from None
            crop = (top, left, height, width)
        split = row.get("split", "").lower()
        allowed = {"train": ("train", "holdout"), "deploy": ("val", "test")}[role]
        if split and (split not in allowed or force is None):
            raise ValueError(
                f"{where}: split {split!r} is not one of {allowed} for a "
                f"{'labelled' if force is not None else 'unlabeled'} {role} recording"
                + ("" if force is not None else " (an unlabeled recording is never split)")
            )
        if role == "train" and force is None:
            raise ValueError(f"{where}: a training recording needs a force file")
        meta = {k: v for k, v in row.items() if k not in _KNOWN or k in ("object", "session")}
        recordings.append(Recording(number, events, force, role, split or "", diameter, crop, meta))
    return _assign_splits(recordings, table)


def _assign_splits(recordings: list[Recording], table: Path) -> list[Recording]:
    train = [r for r in recordings if r.role == "train"]
    deploy = [r for r in recordings if r.role == "deploy" and r.force is not None]
    if not train:
        raise ValueError(f"{table}: no training recording (role 'train')")
    if not [r for r in recordings if r.role == "deploy"]:
        raise ValueError(f"{table}: no deployment recording (role 'deploy')")
    if len(deploy) < 2:
        raise ValueError(
            f"{table}: {len(deploy)} labelled deployment recording(s); validation and test need at least 2 "
            "(unlabeled ones only feed the scene inference)"
        )
    holdout = len(train) // 3
    val = max(1, math.ceil(len(deploy) / 5))
    splits = {}
    for k, r in enumerate(train):
        splits[r.row] = r.split or ("holdout" if k >= len(train) - holdout else "train")
    for k, r in enumerate(deploy):
        splits[r.row] = r.split or ("val" if k < val else "test")
    out = [dataclasses.replace(r, split=splits.get(r.row, "unlabeled")) for r in recordings]
    for name in ("train", "val", "test"):
        if not any(r.split == name for r in out):
            raise ValueError(f"{table}: the split column leaves no {name!r} recording")
    return out


# --------------------------------------------------------------------------- event files


class _EventFile:
    """An event file read as column chunks ``{"x", "y", "t", "p"}`` of numpy arrays."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._columns: dict[str, Any] | None = None
        self._rows: Any = None
        suffix = path.suffix.lower()
        if suffix == ".npy":
            array = np.load(path, mmap_mode="r", allow_pickle=False)
            if array.dtype.names is not None:
                self._columns = _named_columns(array.dtype.names, lambda name: array[name], path)
            elif array.ndim == 2 and array.shape[1] == 4:
                self._rows = array
            else:
                raise ValueError(f"{path}: expected a structured array or (N, 4) rows of x, y, t, p, got "
                                 f"{array.dtype} of shape {array.shape}")
        elif suffix == ".npz":
            with np.load(path, allow_pickle=False) as archive:
                self._columns = _named_columns(archive.files, lambda name: archive[name], path)
        elif suffix == ".csv":
            self._columns = _read_csv_events(path)
        elif suffix in (".h5", ".hdf5"):
            self._columns = _read_hdf5(path)
        elif suffix == ".aedat4":
            self._columns = _read_aedat4(path)
        else:
            raise ValueError(f"{path}: unknown event file type {suffix!r}; expected .npy, .npz, .csv, .aedat4, .h5 or .hdf5")
        lengths = {len(c) for c in self._columns.values()} if self._columns is not None else {len(self._rows)}
        if len(lengths) != 1:
            raise ValueError(f"{path}: columns x, y, t, p have different lengths {sorted(lengths)}")
        self.length = lengths.pop()

    def chunk(self, start: int, stop: int) -> dict[str, np.ndarray]:
        if self._columns is not None:
            return {c: np.asarray(v[start:stop]) for c, v in self._columns.items()}
        rows = np.asarray(self._rows[start:stop])
        return {c: rows[:, k] for k, c in enumerate("xytp")}

    def chunks(self, size: int = _CHUNK) -> Iterator[dict[str, np.ndarray]]:
        for start in range(0, self.length, size):
            yield self.chunk(start, start + size)


def _named_columns(names: Any, get: Any, path: Path) -> dict[str, Any]:
    names = list(names)
    found = {c: next((a for a in _ALIASES[c] if a in names), None) for c in _ALIASES}
    missing = [c for c, name in found.items() if name is None]
    if missing:
        raise ValueError(f"{path}: needs columns x, y, t (or timestamp), p (or on, polarity); got {names} "
                         f"(missing {', '.join(missing)})")
    return {c: get(name) for c, name in found.items()}


def _read_csv_events(path: Path) -> dict[str, Any]:
    with open(path, newline="") as handle:
        header = [h.strip() for h in next(csv.reader(handle), [])]
    found = _named_columns(header, lambda name: header.index(name), path)
    try:
        data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=list(found.values()), ndmin=2, dtype=np.float64)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    out = {}
    for k, c in enumerate(found):
        column = data[:, k]
        out[c] = column.astype(np.int64) if np.all(column == np.round(column)) else column
    return out


def _read_hdf5(path: Path) -> dict[str, Any]:
    try:
        import h5py
    except ImportError:
        raise ValueError(f"{path}: reading HDF5 needs h5py (pip install h5py)") from None
    handle = h5py.File(path, "r")  # kept open: its datasets are read chunk by chunk
    for name in ("events", "CD/events"):
        if name in handle and getattr(handle[name], "dtype", None) is not None and handle[name].dtype.names:
            dataset = handle[name]
            return _named_columns(dataset.dtype.names, lambda field, data=dataset: _H5Field(data, field), path)
    group = handle["events"] if "events" in handle and not hasattr(handle["events"], "dtype") else handle
    return _named_columns(list(group.keys()), lambda name: group[name], path)


class _H5Field:
    """One field of a structured HDF5 dataset, sliced lazily."""

    def __init__(self, dataset: Any, name: str) -> None:
        self.dataset, self.name = dataset, name

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: slice) -> np.ndarray:
        return self.dataset[index][self.name]


def _read_aedat4(path: Path) -> dict[str, Any]:
    try:
        import aedat
    except ImportError:
        raise ValueError(f"{path}: reading .aedat4 needs the aedat package (pip install aedat)") from None
    parts = [packet["events"] for packet in aedat.Decoder(str(path)) if "events" in packet]
    if not parts:
        raise ValueError(f"{path}: the file holds no event packets")
    events = np.concatenate(parts)
    return _named_columns(events.dtype.names, lambda name: events[name], path)


def read_events(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Every event of one file as columns ``x, y, t, p`` (numpy), in any layout format.

    For large files use :class:`RecordingSet`, which reads them in chunks.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "events.csv"
        >>> _ = path.write_text("timestamp,x,y,polarity\\n10,1,2,1\\n20,3,4,0\\n")
        >>> {k: v.tolist() for k, v in read_events(path).items()}
        {'x': [1, 3], 'y': [2, 4], 't': [10, 20], 'p': [1, 0]}
    """
    source = _EventFile(Path(path))
    return source.chunk(0, source.length)


@dataclass
class _Scan:
    """What one pass over an event file found: size, time span, per-pixel totals."""

    events: int
    t_min: int | float
    t_max: int | float
    totals: np.ndarray  # (H, W) int64


def _scan(source: _EventFile, sensor: tuple[int, int], where: str, time_unit: str | None = None) -> _Scan:
    """Check an event file chunk by chunk (sorted, inside the sensor, polarity, units) and
    count events per pixel; ``t_min``/``t_max`` in microseconds (read in ``time_unit``)."""
    from ..events.ingest import _SECONDS_SPAN, _to_microseconds

    height, width = sensor
    totals = np.zeros(height * width, dtype=np.int64)
    last = None
    t_min: int | float | None = None
    t_max: int | float | None = None
    offset = 0
    fractional = False
    for chunk in source.chunks():
        t = chunk["t"]
        if t.dtype.kind not in "iuf" or chunk["x"].dtype.kind not in "iuf" or chunk["y"].dtype.kind not in "iuf":
            raise ValueError(f"{where}: x, y and t must be numbers, got dtypes {chunk['x'].dtype}, {chunk['y'].dtype}, {t.dtype}")
        if t.size == 0:
            continue
        if t.dtype.kind == "f":
            if not np.isfinite(t).all():
                bad = int(np.flatnonzero(~np.isfinite(t))[0])
                raise ValueError(f"{where}: event {offset + bad} has a NaN or infinite timestamp")
            fractional = fractional or bool(np.any(t != np.floor(t)))
        back = np.flatnonzero(t[1:] < t[:-1])
        if back.size or (last is not None and t[0] < last):
            index = offset + (int(back[0]) + 1 if back.size else 0)
            raise ValueError(f"{where}: events are not sorted by t: event {index} goes back in time")
        x, y = chunk["x"], chunk["y"]
        outside = (x < 0) | (x >= width) | (y < 0) | (y >= height) | (x != np.floor(x)) | (y != np.floor(y))
        if outside.any():
            index = int(np.flatnonzero(outside)[0])
            raise ValueError(
                f"{where}: event {offset + index} at (x, y) = ({x[index]}, {y[index]}) lies outside the sensor "
                f"(H, W) = {sensor} (x spans {x.min()}..{x.max()}, y {y.min()}..{y.max()} in this chunk); "
                "give the sensor size with --sensor-size H W"
            )
        p = chunk["p"]
        if p.dtype.kind != "b":
            values = np.unique(p)
            if not (set(values.tolist()) <= {0, 1} or set(values.tolist()) <= {-1, 1}):
                raise ValueError(f"{where}: polarity must be bool, {{0, 1}} or {{-1, 1}}, got values {values[:6].tolist()}")
        totals += np.bincount(y.astype(np.int64) * width + x.astype(np.int64), minlength=height * width)
        t_min = t[0].item() if t_min is None else t_min
        t_max = last = t[-1].item()
        offset += t.size
    if t_min is None or t_max is None:
        raise ValueError(f"{where}: the event file holds no events")
    span = t_max - t_min
    if time_unit is None and fractional and span < _SECONDS_SPAN:
        raise ValueError(
            f"{where}: timestamps look like seconds, not microseconds (fractional values spanning {span:g}); "
            "give their unit: time_unit='s' (--time-unit s), or 'ms', 'ns', or 'us' if they are microseconds"
        )
    if time_unit is not None:  # to microseconds exactly as the binning converts them
        dtype = torch.float64 if isinstance(t_min, float) else torch.int64
        t_min, t_max = _to_microseconds(torch.tensor([t_min, t_max], dtype=dtype), time_unit).tolist()
    return _Scan(offset, t_min, t_max, totals.reshape(height, width))


# --------------------------------------------------------------------------- force


def read_force(path: str | os.PathLike[str], *, offset_ms: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A force CSV's samples: times on the events' clock (float64 µs) and forces (float64 N).

    Args:
        path: CSV with a header holding ``t_us`` and ``force_n`` (other columns ignored).
        offset_ms: the force clock's lag: ``1000 · offset_ms`` is added to every time.

    Raises:
        ValueError: naming the file and the line: a missing column, a cell that is no
            number, NaN, a negative or decreasing time, no sample.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "force.csv"
        >>> _ = path.write_text("t_us,force_n\\n0,1.5\\n2000,2.5\\n")
        >>> t, f = read_force(path, offset_ms=1.0)
        >>> t.tolist(), f.tolist()
        ([1000.0, 3000.0], [1.5, 2.5])
    """
    path = Path(path)
    with open(path, newline="") as handle:
        header = [h.strip() for h in next(csv.reader(handle), [])]
    missing = [c for c in ("t_us", "force_n") if c not in header]
    if missing:
        raise ValueError(f"{path}: the force CSV needs columns t_us and force_n, missing {missing} (header {header})")
    columns = [header.index("t_us"), header.index("force_n")]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=columns, ndmin=2, dtype=np.float64)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    if data.shape[0] == 0:
        raise ValueError(f"{path}: the force CSV holds no sample")
    t, force = data[:, 0], data[:, 1]
    for name, values in (("t_us", t), ("force_n", force)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ValueError(f"{path} line {int(bad[0]) + 2}: {name} is {values[bad[0]]} (NaN or infinite)")
    negative = np.flatnonzero(t < 0)
    if negative.size:
        raise ValueError(f"{path} line {int(negative[0]) + 2}: t_us is negative ({t[negative[0]]:g})")
    back = np.flatnonzero(t[1:] < t[:-1])
    if back.size:
        raise ValueError(f"{path} line {int(back[0]) + 3}: t_us goes back in time ({t[back[0] + 1]:g} after {t[back[0]]:g})")
    return t + 1000.0 * float(offset_ms), force


def frame_labels(t_us: np.ndarray, force_n: np.ndarray, *, t_start: float, frame_us: float, n_frames: int) -> np.ndarray:
    """The label of each frame: the mean of the samples in its bin, else the force linearly
    interpolated at the bin's centre (float64 ``(n_frames,)``).

    Bin ``i`` is ``[t_start + i · frame_us, t_start + (i + 1) · frame_us)``. The samples must
    cover the bins (the first at or before the end of bin 0, the last at or after the start
    of the last bin), else ``ValueError``.

    Example:
        >>> t = np.array([0.0, 4_000.0, 8_000.0, 22_000.0])  # bin 1 holds no sample: 4.5 at its centre
        >>> frame_labels(t, np.array([1.0, 2.0, 3.0, 6.0]), t_start=0, frame_us=10_000, n_frames=3).tolist()
        [2.0, 4.5, 6.0]
    """
    edges = float(t_start) + np.arange(n_frames + 1, dtype=np.float64) * float(frame_us)
    if t_us[0] >= edges[1] or t_us[-1] < edges[-2]:
        raise ValueError(
            f"force samples span t = {t_us[0]:.0f} to {t_us[-1]:.0f} µs but the frames span {edges[0]:.0f} to "
            f"{edges[-1]:.0f} µs: the force must cover the recording (check --force-offset-ms and the clocks)"
        )
    index = np.searchsorted(t_us, edges, side="left")
    count = np.diff(index)
    filled = count > 0
    means = np.interp((edges[:-1] + edges[1:]) / 2, t_us, force_n)  # bins without a sample
    if filled.any():  # each filled bin's samples summed on their own (exact for one sample)
        means[filled] = np.add.reduceat(force_n[: index[-1]], index[:-1][filled]) / count[filled]
    return means


# --------------------------------------------------------------------------- hashing, cache


def content_hash(path: str | os.PathLike[str], *, chunk: int = 2**22) -> str:
    """SHA-256 of a file's bytes (hex).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "a.txt"
        >>> _ = path.write_bytes(b"abc")
        >>> content_hash(path)[:12]
        'ba7816bf8f01'
    """
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def _key(description: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(description, sort_keys=True, default=str).encode()).hexdigest()[:24]


def _cache_dir(cache: str | os.PathLike[str] | None) -> Path:
    from .datasets import default_cache_dir

    return Path(cache) if cache is not None else default_cache_dir() / "recordings"


def _save_atomic(obj: object, path: Path) -> None:
    from .datasets import _atomic_save

    _atomic_save(obj, path)


def _load_cached(path: Path) -> dict[str, Any] | None:
    """A cache file's contents, or ``None`` (the file named, deleted) when it cannot be read."""
    if not path.exists():
        return None
    try:
        data = torch.load(path, mmap=True, weights_only=True)
        if not isinstance(data, dict) or data.get("format") != _CACHE_FORMAT:
            raise ValueError("not a recording cache file of this version")
        return data
    except Exception as error:  # noqa: BLE001 - any unreadable file is rebuilt, named
        warnings.warn(f"discarded the unreadable cache file {path} ({type(error).__name__}: "
                      f"{str(error).splitlines()[0] if str(error) else ''}); rebuilding it", stacklevel=3)
        path.unlink(missing_ok=True)
        return None


# --------------------------------------------------------------------------- crop


def contact_crop(totals: np.ndarray, pool: int = 2, *, margin: float = 0.1) -> tuple[int, int, int, int]:
    """The contact area's bounding box from per-pixel event totals ``(H, W)``.

    Contact pixels are those above both the background (the median total plus four of its
    Poisson standard deviations plus 4) and a quarter of the busiest pixel's total, pixels
    firing more than 20 times the 99th-percentile total (hot pixels) aside. The box is
    widened by ``margin`` of its size on each side, rounded out to multiples of ``pool`` and
    kept inside the sensor. With no contact pixel, the whole sensor (trimmed to ``pool``).

    Example:
        >>> totals = np.ones((40, 60), dtype=np.int64)
        >>> totals[10:20, 20:40] = 50
        >>> contact_crop(totals, pool=2)
        (9, 18, 12, 24)
    """
    height, width = totals.shape
    values = totals.astype(np.float64)
    background = float(np.median(values))
    hot = values > 20 * max(float(np.percentile(values, 99)), 1.0)
    busy = float(np.where(hot, 0, values).max()) if values.size else 0.0
    threshold = max(background + 4 * math.sqrt(background) + 4, 0.25 * busy)
    rows, cols = np.nonzero((values > threshold) & ~hot)
    if rows.size == 0:
        return 0, 0, height - height % pool, width - width % pool
    top, bottom, left, right = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    pad_h, pad_w = int(math.ceil(margin * (bottom - top))), int(math.ceil(margin * (right - left)))
    top, left = max(0, top - pad_h), max(0, left - pad_w)
    bottom, right = min(height, bottom + pad_h), min(width, right + pad_w)
    crop_h = min(height - height % pool, -(-(bottom - top) // pool) * pool)
    crop_w = min(width - width % pool, -(-(right - left) // pool) * pool)
    top, left = min(top, height - crop_h), min(left, width - crop_w)
    return int(top), int(left), int(crop_h), int(crop_w)


# --------------------------------------------------------------------------- the data set


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
        log: called with one line per recording binned (not per one read from the cache).
        **overrides: fields of :class:`RecordingSettings` (``sensor_size``, ``frame_ms``,
            ``frames``, ``stride``, ``crop``, ``pool``, ``force_offset_ms``, ``time_unit``).

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
        table = read_table(self.root)
        self.all_recordings = table
        self.recordings = [
            r for r in table if (split is None or r.split == split) and (role is None or r.role == role)
        ]
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
                    f"--frames {length}"
                )
            starts = range(0, frames - length + 1, stride)
            self.left_out_frames += frames - (starts[-1] + length)
            self._windows.extend((k, s) for s in starts)
            self._data.append(data)

    # ------------------------------------------------------------------ building
    def _crop_of(self, recording: Recording) -> tuple[int, int, int, int]:
        if self.settings.crop is not None:
            return self.settings.crop
        if recording.crop is not None:
            return _check_crop(recording.crop, self.settings.sensor_size, self.settings.pool,
                               f"{recording.where()}: crop")
        return self.crop

    def _choose_crop(self, table: list[Recording], log: Any) -> tuple[tuple[int, int, int, int], str]:
        settings = self.settings
        if settings.crop is not None:
            return settings.crop, "given"
        if all(r.crop is not None for r in table):
            sizes = {r.crop[2:] for r in table if r.crop is not None}
            if len(sizes) != 1:
                raise ValueError(f"recordings.csv: every row's crop must have one size, got {sorted(sizes)}")
            first = table[0]
            return _check_crop(first.crop, settings.sensor_size, settings.pool, f"{first.where()}: crop"), "recordings.csv"
        if any(r.crop is not None for r in table):
            rows = [r.row for r in table if r.crop is None]
            raise ValueError(f"recordings.csv: crop columns are empty on rows {rows[:5]}; fill every row or none")
        training = [r for r in table if r.split == "train"]
        totals = sum(self._scan(r).totals for r in training)
        crop = contact_crop(totals, settings.pool)  # type: ignore[arg-type]
        return crop, f"contact area of {len(training)} training recordings"

    def _scan(self, recording: Recording) -> _Scan:
        settings = self.settings
        described: dict[str, Any] = {"events": self._hashes[recording.row][0], "sensor": settings.sensor_size}
        if settings.time_unit is not None:  # t_min, t_max are microseconds converted from that unit
            described["time_unit"] = settings.time_unit
        path = self.cache / f"scan-{_key(described)}.pt"
        data = _load_cached(path)
        if data is None:
            try:
                scan = _scan(_EventFile(recording.events), settings.sensor_size, recording.where(), settings.time_unit)
            except ValueError as error:
                raise _named(error, recording) from None
            data = {"format": _CACHE_FORMAT, "events": scan.events, "t_min": scan.t_min, "t_max": scan.t_max,
                    "totals": torch.from_numpy(scan.totals)}
            _save_atomic(data, path)
        return _Scan(int(data["events"]), data["t_min"], data["t_max"], data["totals"].numpy())

    def _binned(self, recording: Recording, log: Any) -> dict[str, Any]:
        settings = self.settings
        crop = self._crop_of(recording)
        events_hash, force_hash = self._hashes[recording.row]
        description = {"format": _CACHE_FORMAT, "events": events_hash, "force": force_hash,
                       "sensor": settings.sensor_size, "frame_ms": settings.frame_ms, "crop": crop,
                       "pool": settings.pool, "force_offset_ms": settings.force_offset_ms}
        if settings.time_unit is not None:
            description["time_unit"] = settings.time_unit
        path = self.cache / f"recording-{_key(description)}.pt"
        data = _load_cached(path)
        if data is not None:
            return data
        tick = time.perf_counter()
        scan = self._scan(recording)
        data = _bin_recording(recording, scan, settings, crop)
        _save_atomic(data, path)
        data = _load_cached(path) or data  # memory-mapped from now on
        if log:
            log(f"binned {recording.where()}: {scan.events:,} events into {data['frames'].shape[0]} frames "
                f"in {time.perf_counter() - tick:.1f} s")
        return data

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
        from .datasets import item_index

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
    def diameters(self) -> tuple[float, ...] | None:
        """The distinct sizes of the chosen recordings (``None`` without ``diameter_mm``)."""
        sizes = [r.diameter_mm for r in self.recordings]
        if not sizes or None in sizes:
            return None
        return tuple(sorted({s for s in sizes if s is not None}))

    def __getstate__(self) -> dict[str, Any]:  # workers reload the memory-mapped cache
        state = dict(self.__dict__)
        state["_data"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self._data is None:
            self._data = [self._binned(r, None) for r in self.recordings]

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(root={str(self.root)!r}, split={self.split!r}, role={self.role!r}, "
                f"recordings={len(self.recordings)}, windows={len(self)})")


def _named(error: Exception, recording: Recording) -> ValueError:
    message = str(error)
    return ValueError(message if "recordings.csv row" in message else f"{recording.where()}: {message}")


def _hashes(root: Path, table: list[Recording], cache: Path) -> dict[int, tuple[str, str | None]]:
    """Content hashes of each row's files (a file's hash is remembered by its size and mtime)."""
    memo_path = cache / "hashes.json"
    try:
        memo = json.loads(memo_path.read_text()) if memo_path.exists() else {}
        if not isinstance(memo, dict):
            memo = {}
    except (OSError, ValueError):
        memo = {}
    changed = False

    def digest(path: Path) -> str:
        nonlocal changed
        stat = path.stat()
        key = f"{path.resolve()}:{stat.st_size}:{stat.st_mtime_ns}"
        if key not in memo:
            memo[key] = content_hash(path)
            changed = True
        return memo[key]

    out = {r.row: (digest(r.events), digest(r.force) if r.force is not None else None) for r in table}
    if changed:
        from .training import write_json_atomic

        try:
            write_json_atomic(memo_path, memo)
        except OSError:
            pass
    return out


def _bin_recording(recording: Recording, scan: _Scan, settings: RecordingSettings,
                   crop: tuple[int, int, int, int]) -> dict[str, Any]:
    """Bin one recording through ``iter_frames`` (chunked) and label its frames."""
    from ..functional import iter_frames

    frame_us = settings.frame_us
    t0 = (scan.t_min // frame_us) * frame_us
    n_frames = int((scan.t_max - t0) // frame_us) + 1
    pool = settings.pool
    shape = (n_frames, 2, crop[2] // pool, crop[3] // pool)
    out = torch.zeros(shape, dtype=torch.int32)
    source = _EventFile(recording.events)
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
            t, values = read_force(recording.force, offset_ms=settings.force_offset_ms)
            force = torch.from_numpy(frame_labels(t, values, t_start=float(t0), frame_us=float(frame_us),
                                                  n_frames=n_frames))
        except ValueError as error:
            raise ValueError(f"{recording.where()}, force file {recording.force.name}: {error}") from None
    storage = torch.int16 if out.numel() == 0 or int(out.max()) <= 32767 else torch.int32
    return {"format": _CACHE_FORMAT, "frames": out.to(storage), "force": force, "t_start_us": t0,
            "events": scan.events}


# --------------------------------------------------------------------------- the benchmark's data


def load_recording_data(
    root: str | os.PathLike[str],
    settings: RecordingSettings | None = None,
    *,
    cache: str | os.PathLike[str] | None = None,
    name: str | None = None,
    log: Any = None,
) -> Any:
    """A folder of recordings as the protocol's :class:`~event_transforms.tactile.copies.SceneData`.

    ``train`` and ``holdout`` come from the training recordings, ``val`` and ``test`` from
    the labelled deployment recordings (see *Splits* in the module docstring). The scene
    (:class:`RecordingScene`) holds :func:`~event_transforms.infer_scene` on the training
    windows and the deployment windows that are not test data (validation and unlabeled
    recordings), as frames only — their forces are never read — with the sizes of
    ``diameter_mm`` where given; its gaps are the inferred ones and its policy (``inferred``,
    ``independent``, ``hybrid``) the inferred scene's. The noise bank (for ``noise``) is the
    deployment windows' quietest frames; the prior's bank (``prior``, ``everything``) the
    training windows' quietest frames (another camera, or the same one, at hand).

    Returns:
        A ``SceneData`` whose ``dataset`` attribute describes the data (folder, files,
        content hash, settings, crop, recordings and windows per split).
    """
    from ..inference import infer_scene, sequence_statistics
    from .copies import SceneData

    start = time.perf_counter()
    settings = settings or RecordingSettings()
    root = Path(root)
    splits = {s: RecordingSet(root, split=s, settings=settings, cache=cache, log=log) for s in SPLITS}
    crop = splits["train"].crop
    for s, data in splits.items():  # every split on the one grid
        if len(data) and tuple(data[0][0].shape) != tuple(splits["train"][0][0].shape):
            raise ValueError(f"split {s!r}: windows of shape {tuple(data[0][0].shape)} differ from the training "
                             f"windows' {tuple(splits['train'][0][0].shape)}; give one crop size")
    train_frames = splits["train"].frames
    deploy_frames = torch.cat([splits["val"].frames, splits["unlabeled"].frames])
    train_sizes = splits["train"].diameters
    deploy_sizes = _sizes(splits["val"], splits["test"], splits["unlabeled"])
    inferred = infer_scene(train_frames, deploy_frames, train_sizes=train_sizes,
                           deploy_sizes=deploy_sizes if deploy_sizes and len(deploy_sizes) == 1 else None,
                           frame_ms=settings.frame_ms)

    def quiet(frames: Tensor) -> Tensor:
        stats = sequence_statistics(frames, frame_ms=settings.frame_ms)
        n, k = stats["quiet"].shape
        return frames.gather(1, stats["quiet"].view(n, k, 1, 1, 1).expand(n, k, *frames.shape[2:])).reshape(
            n * k, *frames.shape[2:])

    table = splits["train"].all_recordings
    dataset = {
        "kind": "recordings",
        "folder": str(root.resolve()),
        "files": len(table) + sum(r.force is not None for r in table) + 1,
        "content_hash": splits["train"].dataset_hash,
        "settings": {**settings.as_dict(), "crop": list(crop)},
        "crop": list(crop),
        "crop_source": splits["train"].crop_source,
        "recordings": {s: len(d.recordings) for s, d in splits.items()},
        "windows": {s: len(d) for s, d in splits.items()},
        "left_out_frames": sum(d.left_out_frames for d in splits.values()),
        "inferred_from": f"{len(train_frames)} training windows and {len(deploy_frames)} deployment windows "
                         "(validation and unlabeled recordings; frames only)",
    }
    scene = RecordingScene.build(name or root.resolve().name, settings, train_sizes, deploy_sizes, inferred,
                                 quiet(train_frames), dataset)
    return SceneData(scene, splits["train"], splits["val"], splits["test"], quiet(deploy_frames),
                     time.perf_counter() - start, holdout=splits["holdout"] if len(splits["holdout"]) else None,
                     dataset=dataset)


def _sizes(*sets: RecordingSet) -> tuple[float, ...] | None:
    sizes: set[float] = set()
    for data in sets:
        if data.recordings:
            found = data.diameters
            if found is None:
                return None
            sizes |= set(found)
    return tuple(sorted(sizes)) or None


@dataclass(frozen=True)
class RecordingScene(BenchmarkScene):
    """A benchmark scene made of a user's recordings: the gaps are those
    :func:`~event_transforms.infer_scene` finds (size from the ``diameter_mm`` column),
    the policy is the inferred scene's, and nothing is simulated.

    The sessions carry only what the protocol reads from them (sizes, frames per window,
    frame length, sensor size); their simulator settings describe no data.
    """

    inferred: Any = field(default=None, compare=False, hash=False, repr=False)
    prior_bank: Any = field(default=None, compare=False, hash=False, repr=False)
    dataset: Any = field(default=None, compare=False, hash=False, repr=False)

    @classmethod
    def build(cls, name: str, settings: RecordingSettings, train_sizes: Any, deploy_sizes: Any, inferred: Any,
              prior_bank: Tensor, dataset: dict[str, Any]) -> RecordingScene:
        from .simulation import SimulatorConfig

        config = SimulatorConfig(sensor_size=settings.sensor_size, n_frames=settings.frames,
                                 frame_ms=float(settings.frame_ms), substep_ms=float(settings.frame_ms))
        # without sizes the sessions hold a placeholder size, never read (no size gap)
        train = Session(tuple(train_sizes or (1.0,)), config)
        deploy = Session(tuple(deploy_sizes or train_sizes or (1.0,)), config)
        gaps = ", ".join(inferred.gaps) or "none"
        description = f"own recordings in {dataset['folder']} (inferred gaps: {gaps})"
        return cls(name, description, train, deploy, (), inferred=inferred, prior_bank=prior_bank, dataset=dataset)

    @property
    def gaps(self) -> tuple[str, ...]:
        return tuple(self.inferred.gaps)

    def gap_sizes(self) -> dict[str, dict[str, tuple[Any, Any]]]:
        """factor -> statistic -> (training mean, deployment mean) of the inferred gaps."""
        evidence = self.inferred.evidence or {}
        out: dict[str, dict[str, tuple[Any, Any]]] = {}
        for factor in self.gaps:
            if factor == "size":
                size = evidence.get("size", {})
                out["size"] = {"diameters_mm": (size.get("train_sizes"), size.get("deploy_sizes"))}
            elif factor in evidence and "statistic" in evidence[factor]:
                e = evidence[factor]
                out[factor] = {e["statistic"]: (round(e["train"]["mean"], 3), round(e["deploy"]["mean"], 3))}
        return out

    @property
    def target_size(self) -> float | None:
        return self.inferred.target_size if "size" in self.gaps else None

    def library_scene(self, noise_bank: Tensor | None = None, **kwargs: Any) -> Any:
        """The inferred :class:`~event_transforms.Scene` (its policy uses its own estimates)."""
        return self.inferred


# --------------------------------------------------------------------------- export


def export_scene(scene: Any, out: str | os.PathLike[str], *, root: str | None = None, log: Any = None) -> Path:
    """Write a built-in scene's grasps in the recording-set layout.

    Every grasp of the scene's splits (training: ``train`` then ``holdout``; deployment:
    ``val`` then ``test``, all labelled) is simulated again from its seed and written as
    ``events/<split>_<k>.npy`` (structured ``x, y, t, p``) and ``force/<split>_<k>.csv`` (one
    sample per frame at its centre, the simulator's F/T reading), with ``diameter_mm``,
    ``split``, the grasp's crop window (the fixed 140 × 150 window centred on the sensor, as
    the built-in data set crops) and the seed in ``recordings.csv``. So
    ``reproduce --data OUT`` reads the same frames and labels as ``reproduce --scenes NAME``.

    Returns:
        The path of ``recordings.csv``.
    """
    from .datasets import _SPLIT_SEED, SPLIT_SIZES
    from .scenes import get_scene
    from .simulation import draw_grasp, simulate_grasps

    scene = get_scene(scene)
    out = Path(out)
    (out / "events").mkdir(parents=True, exist_ok=True)
    (out / "force").mkdir(parents=True, exist_ok=True)
    rows = ["events,force,role,diameter_mm,split,crop_top,crop_left,crop_height,crop_width,seed,scene"]
    for split in ("train", "holdout", "val", "test"):
        session = scene.train if split in ("train", "holdout") else scene.deploy
        role = "train" if split in ("train", "holdout") else "deploy"
        first = _SPLIT_SEED[split]
        tick = time.perf_counter()
        for block in range(0, SPLIT_SIZES[split], 24):
            seeds = range(first + block, first + min(block + 24, SPLIT_SIZES[split]))
            grasps = [draw_grasp(session.diameter(s - first), seed=s, config=session.config) for s in seeds]
            for seed, grasp, recording in zip(seeds, grasps, simulate_grasps(grasps, session.config)):
                k = seed - first
                name = f"{split}_{k:03d}"
                np.save(out / "events" / f"{name}.npy", recording.events)
                force = np.c_[recording.force_t_us.astype(np.float64), recording.force.astype(np.float64)]
                with open(out / "force" / f"{name}.csv", "w") as handle:
                    handle.write("t_us,force_n\n")
                    handle.writelines(f"{int(t)},{float(np.float32(f))!r}\n" for t, f in force)
                top, left, height, width = recording.sensor_crop((140, 150))
                rows.append(f"events/{name}.npy,force/{name}.csv,{role},{grasp.diameter_mm:g},{split},"
                            f"{top},{left},{height},{width},{seed},{scene.name}")
        if log:
            log(f"exported {SPLIT_SIZES[split]} {split} grasps of {scene.name!r} in {time.perf_counter() - tick:.1f} s")
    table = out / "recordings.csv"
    handle_fd, temporary = tempfile.mkstemp(dir=out, prefix=".recordings.", suffix=".tmp")
    with os.fdopen(handle_fd, "w") as handle:
        handle.write("\n".join(rows) + "\n")
    os.replace(temporary, table)
    return table
