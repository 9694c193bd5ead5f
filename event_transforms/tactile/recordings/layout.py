"""The layout's table and settings: ``recordings.csv`` read and checked, each recording's split.

See :mod:`event_transforms.tactile.recordings` for the layout.
"""

from __future__ import annotations

__all__ = ["SPLITS", "DEFAULT_SENSOR_SIZE", "RecordingSettings", "RecordingEntry", "read_table"]

import csv
import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from ...events._ingest import check_crop_window

#: The splits a recording can belong to.
SPLITS = ("train", "holdout", "val", "test", "unlabeled")
_ROLES = ("train", "deploy")
_REQUIRED = ("events", "force", "role")
_KNOWN = (*_REQUIRED, "diameter_mm", "object", "session", "split", "crop_top", "crop_left", "crop_height", "crop_width")
_CROP_COLUMNS = ("crop_top", "crop_left", "crop_height", "crop_width")
#: The sensor size where neither the settings nor the files say one (the DAVIS240's).
DEFAULT_SENSOR_SIZE = (180, 240)
#: Settings recorded only when given.
_OPTIONAL = ("time_unit", "columns", "force_time_unit", "force_column", "sync")


@dataclass(frozen=True)
class RecordingSettings:
    """How recordings become items (every setting has a command-line option and is recorded).

    Attributes:
        sensor_size: ``(H, W)`` of the sensor; events outside it are refused. ``None``: the
            size the event files state (``.aedat4``, HDF5 attributes), else
            :data:`DEFAULT_SENSOR_SIZE`; a given size that differs from a file's is refused.
        frame_ms: bin width in milliseconds.
        frames: frames T per window.
        stride: frames between window starts (``None``: T, windows do not overlap).
        crop: ``(top, left, height, width)`` for every recording; ``None``: the crop columns
            of ``recordings.csv`` where given, else the contact area of the training data.
        pool: side of the sum-pooled blocks.
        force_offset_ms: the force clock's lag behind the events' clock.
        time_unit: unit of the event files' timestamps: ``"us"``, ``"ms"``, ``"s"`` or
            ``"ns"`` (``None``: microseconds, float timestamps that look like seconds
            refused; integer timestamps whose span and count look like milliseconds refused).
        columns: the column order of ``(N, k)`` event arrays (``.npy``, plain HDF5), e.g.
            ``"txyp"`` (``None``: ``x, y, t, p``).
        force_time_unit: the unit of a force time column whose name does not say it (the
            names ``t_ns``, ``t_us``, ``t_ms``, ``t_s`` say it).
        force_column: the force CSV's label column (``None``: ``force_n``), or
            ``"magnitude"``: the norm of ``fx, fy, fz``.
        sync: ``"triggers"``: each recording's force clock aligned to the camera's from the
            trigger events of its ``.aedat4`` file and the force CSV's ``trigger`` column
            (``force_offset_ms`` then unused, must be 0); ``None``: ``force_offset_ms``.

    Example:
        >>> RecordingSettings(frames=36).window_stride
        36
        >>> RecordingSettings(time_unit="s").as_dict()["time_unit"]
        's'
    """

    sensor_size: tuple[int, int] | None = None
    frame_ms: float = 10.0
    frames: int = 36
    stride: int | None = None
    crop: tuple[int, int, int, int] | None = None
    pool: int = 2
    force_offset_ms: float = 0.0
    time_unit: str | None = None
    columns: str | None = None
    force_time_unit: str | None = None
    force_column: str | None = None
    sync: str | None = None

    def __post_init__(self) -> None:
        from ..._validation import check_positive
        from ...events._ingest import check_time_unit

        check_time_unit(self.time_unit)  # ValueError naming time_unit and the value
        if self.force_time_unit is not None and self.force_time_unit not in ("ns", "us", "ms", "s"):
            raise ValueError(f"force_time_unit must be one of 'ns', 'us', 'ms', 's' or None, got {self.force_time_unit!r}")
        for name in ("columns", "force_column"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, str) or not value):
                raise ValueError(f"{name} must be a non-empty string or None, got {value!r}")
        if self.sync not in (None, "triggers"):
            raise ValueError(f"sync must be 'triggers' or None, got {self.sync!r}")
        if self.sync is not None and self.force_offset_ms:
            raise ValueError(f"sync={self.sync!r} measures the force clock's offset; leave force_offset_ms at 0, "
                             f"got {self.force_offset_ms!r}")
        if self.sensor_size is not None:
            size = tuple(self.sensor_size)
            if len(size) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1
                                     for v in size):
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
            object.__setattr__(self, "crop", _check_crop(self.crop, self.sensor_size or (2**31, 2**31), self.pool,
                                                         "crop"))

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
        """The settings as plain JSON values (``time_unit``, ``columns``, the force options and
        ``sync`` only when given, so that the keys of data binned before they existed stay valid)."""
        out = dataclasses.asdict(self)
        out["sensor_size"] = None if self.sensor_size is None else list(self.sensor_size)
        out["crop"] = None if self.crop is None else list(self.crop)
        out["stride"] = self.window_stride
        for name in _OPTIONAL:
            if out[name] is None:
                del out[name]
        return out


def _check_crop(crop: Any, sensor: tuple[int, int], pool: int, where: str) -> tuple[int, int, int, int]:
    """A crop read from a table or a setting (numbers or their text) as four ints, checked by the
    binning's one crop check (:mod:`event_transforms.events._ingest`), errors prefixed with ``where``."""
    try:
        values = tuple(int(v) for v in crop)
        if len(values) != 4 or any(float(v) != int(float(v)) for v in crop):
            raise ValueError
    except (TypeError, ValueError):
        raise ValueError(f"{where} must be four integers (top, left, height, width), got {crop!r}") from None
    try:
        return check_crop_window(values, sensor[0], sensor[1], pool)
    except ValueError as error:
        raise ValueError(f"{where}: {error}") from None


@dataclass(frozen=True)
class RecordingEntry:
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


def read_table(root: str | os.PathLike[str], *, deployment: bool = True) -> list[RecordingEntry]:
    """Read and check ``root/recordings.csv``; every recording with its split.

    Args:
        root: the folder holding ``recordings.csv``.
        deployment: whether deployment recordings are needed (at least two labelled); a
            folder of training recordings only reads with ``deployment=False``.

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
        recordings.append(RecordingEntry(number, events, force, role, split or "", diameter, crop, meta))
    _refuse_repeated_files(recordings)
    return _assign_splits(recordings, table, deployment)


def _refuse_repeated_files(recordings: list[RecordingEntry]) -> None:
    """Refuse an event file listed in two rows (in two roles it would be trained on and scored,
    in one role counted twice), naming both rows."""
    seen: dict[Path, RecordingEntry] = {}
    for r in recordings:
        key = r.events.resolve()
        first = seen.setdefault(key, r)
        if first is not r:
            roles = (f"as {first.role!r} and as {r.role!r}: a recording is either trained on or deployed, "
                     "never both" if first.role != r.role else f"twice as {r.role!r}: it would count twice")
            raise ValueError(f"recordings.csv rows {first.row} and {r.row} list the same events file "
                             f"{str(r.events)!r} {roles}; list each recording once")


def _assign_splits(recordings: list[RecordingEntry], table: Path, deployment: bool = True) -> list[RecordingEntry]:
    train = [r for r in recordings if r.role == "train"]
    deploy = [r for r in recordings if r.role == "deploy" and r.force is not None]
    if not train:
        raise ValueError(f"{table}: no training recording (role 'train')")
    if deployment and not [r for r in recordings if r.role == "deploy"]:
        raise ValueError(f"{table}: no deployment recording (role 'deploy'); a folder of training recordings "
                         "only loads with split='train' (or 'holdout', or role='train') and trains with "
                         "`event-transforms train`")
    if deployment and len(deploy) < 2:
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
    for name in ("train", "val", "test") if deployment else ("train",):
        if not any(r.split == name for r in out):
            raise ValueError(f"{table}: the split column leaves no {name!r} recording")
    return out
