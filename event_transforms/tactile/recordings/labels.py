"""Force labels: a force CSV read and checked, each frame's label from its samples."""

from __future__ import annotations

__all__ = ["read_force", "frame_labels", "force_triggers", "trigger_offset", "TIME_COLUMNS", "WRENCH"]

import csv
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np


#: Force time columns recognised by name, and their unit in microseconds.
TIME_COLUMNS = {"t_ns": 1e-3, "t_us": 1.0, "t_ms": 1e3, "t_s": 1e6}
#: Time columns that need ``force_time_unit``.
_GENERIC_TIME = ("t", "time", "timestamp")
_UNIT_WORDS = {"ns": "nanoseconds", "us": "microseconds", "ms": "milliseconds", "s": "seconds"}
#: Wrench columns reduced by ``force_column="magnitude"``.
WRENCH = ("fx", "fy", "fz")


def _header(path: Path) -> list[str]:
    try:
        with open(path, newline="") as handle:
            return [h.strip() for h in next(csv.reader(handle), [])]
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text CSV file (a force file is a CSV with a header)") from None


def _time_column(header: list[str], time_unit: str | None, path: Path) -> tuple[str, float]:
    """The force file's time column and its microseconds per unit."""
    named = [c for c in TIME_COLUMNS if c in header]
    if len(named) > 1:
        raise ValueError(f"{path}: several time columns {named}; keep one")
    if time_unit is not None:
        if time_unit not in _UNIT_WORDS:
            raise ValueError(f"force_time_unit must be one of {', '.join(map(repr, _UNIT_WORDS))} or None, got "
                             f"{time_unit!r}")
        if named and named[0] != f"t_{time_unit}":
            raise ValueError(f"{path}: force_time_unit={time_unit!r} but the column {named[0]} names its unit; "
                             "leave force_time_unit out")
        generic = named or [c for c in _GENERIC_TIME if c in header]
        if not generic:
            raise ValueError(f"{path}: no time column: expected one of {[*TIME_COLUMNS, *_GENERIC_TIME]} "
                             f"(header {header})")
        return generic[0], TIME_COLUMNS[f"t_{time_unit}"]
    if named:
        return named[0], TIME_COLUMNS[named[0]]
    generic = [c for c in _GENERIC_TIME if c in header]
    if generic:
        raise ValueError(f"{path}: the time column {generic[0]!r} does not say its unit; name it t_ns, t_us, t_ms or "
                         "t_s, or pass force_time_unit='ns' (or 'us', 'ms', 's')")
    raise ValueError(f"{path}: the force CSV needs a time column t_us (or t_ns, t_ms, t_s) and force_n, missing the "
                     f"time (header {header})")


def _force_columns(header: list[str], column: str | None, path: Path) -> list[str]:
    """The columns whose values (or whose magnitude) make the label."""
    if column is None:
        if "force_n" in header:
            return ["force_n"]
        wrench = [c for c in WRENCH if c in header]
        hint = (f"; the file holds a wrench ({', '.join(wrench)}): pass force_column='magnitude' or an axis, e.g. "
                f"force_column={wrench[-1]!r}") if wrench else "; pass force_column='NAME' to read another column"
        raise ValueError(f"{path}: the force CSV needs a column force_n (header {header}){hint}")
    if column == "magnitude":
        missing = [c for c in WRENCH if c not in header]
        if missing:
            raise ValueError(f"{path}: force_column='magnitude' needs columns fx, fy, fz, missing {missing} "
                             f"(header {header})")
        return list(WRENCH)
    if column not in header:
        raise ValueError(f"{path}: force_column={column!r} is not a column of the file (header {header})")
    return [column]


def read_force(
    path: str | os.PathLike[str],
    *,
    offset_ms: float = 0.0,
    time_unit: str | None = None,
    column: str | None = None,
    log: Any = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A force CSV's samples: times on the events' clock (float64 µs) and forces (float64 N).

    Args:
        path: CSV with a header holding a time column and a force column (other columns ignored).
            The time column is ``t_us``, ``t_ns``, ``t_ms`` or ``t_s`` (the unit read from the
            name), or ``t``/``time``/``timestamp`` with ``time_unit``. The force is ``force_n``,
            the column ``column`` names, or with ``column="magnitude"`` the norm of ``fx, fy, fz``.
        offset_ms: the force clock's lag: ``1000 · offset_ms`` is added to every time.
        time_unit: the unit of a time column whose name does not say it: ``"ns"``, ``"us"``,
            ``"ms"`` or ``"s"``.
        column: the force column (``None``: ``force_n``), or ``"magnitude"``.
        log: called with one line saying each conversion made (a unit other than
            microseconds, a column other than ``force_n``).

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
        >>> _ = path.write_text("t_ns,fx,fy,fz\\n0,3,0,4\\n2000000,0,0,2\\n")  # a wrench in ns
        >>> t, f = read_force(path, column="magnitude", log=print)
        force.csv: time column t_ns (nanoseconds) read as microseconds; force = |(fx, fy, fz)|
        >>> t.tolist(), f.tolist()
        ([0.0, 2000.0], [5.0, 2.0])
    """
    path = Path(path)
    header = _header(path)
    time_name, scale = _time_column(header, time_unit, path)
    force_names = _force_columns(header, column, path)
    names = [time_name, *force_names]
    columns = [header.index(c) for c in names]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=columns, ndmin=2, dtype=np.float64)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    if data.shape[0] == 0:
        raise ValueError(f"{path}: the force CSV holds no sample")
    for k, name in enumerate(names):
        values = data[:, k]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            fix = " (drop the row or fill it)" if name in WRENCH or name == column else ""
            raise ValueError(f"{path} line {int(bad[0]) + 2}: {name} is {values[bad[0]]} (NaN or infinite){fix}")
    t = data[:, 0]
    force = np.sqrt(np.square(data[:, 1:]).sum(axis=1)) if column == "magnitude" else data[:, 1]
    negative = np.flatnonzero(t < 0)
    if negative.size:
        raise ValueError(f"{path} line {int(negative[0]) + 2}: {time_name} is negative ({t[negative[0]]:g})")
    back = np.flatnonzero(t[1:] < t[:-1])
    if back.size:
        raise ValueError(f"{path} line {int(back[0]) + 3}: {time_name} goes back in time ({t[back[0] + 1]:g} after "
                         f"{t[back[0]]:g})")
    notes = []
    if time_name != "t_us" or scale != 1.0:
        unit = next(u for u, v in TIME_COLUMNS.items() if v == scale)[2:]
        notes.append(f"time column {time_name} ({_UNIT_WORDS[unit]}) read as microseconds")
    if column == "magnitude":
        notes.append("force = |(fx, fy, fz)|")
    elif column not in (None, "force_n"):
        notes.append(f"force = column {column}")
    if log and notes:
        log(f"{path.name}: {'; '.join(notes)}")
    return (t * scale if scale != 1.0 else t) + 1000.0 * float(offset_ms), force


def force_triggers(path: str | os.PathLike[str], *, time_unit: str | None = None) -> np.ndarray:
    """The times (float64 µs on the force clock) of the force CSV's rows marked in its
    ``trigger`` column (non-zero: the sample at which the logger raised the sync line).

    Args:
        path: the force CSV (time column as in :func:`read_force`).
        time_unit: the unit of a time column whose name does not say it.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "force.csv"
        >>> _ = path.write_text("t_ms,force_n,trigger\\n0,1,0\\n1,1,1\\n2,1,0\\n3,1,1\\n")
        >>> force_triggers(path).tolist()
        [1000.0, 3000.0]
    """
    path = Path(path)
    header = _header(path)
    if "trigger" not in header:
        raise ValueError(f"{path}: sync='triggers' needs a trigger column in the force CSV (non-zero on the samples "
                         f"at which the sync line was raised); header {header}")
    time_name, scale = _time_column(header, time_unit, path)
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=[header.index(time_name), header.index("trigger")],
                      ndmin=2, dtype=np.float64)
    return data[data[:, 1] != 0, 0] * scale


def trigger_offset(camera_us: np.ndarray, force_us: np.ndarray, where: str) -> tuple[float, float]:
    """The force clock's lag behind the camera's from matching trigger times: the median of
    ``camera - force`` and the largest deviation from it (both µs).

    Args:
        camera_us: the camera's trigger times (the events' clock).
        force_us: the same triggers on the force clock, as many, in order.
        where: how errors name the recording.

    Raises:
        ValueError: no trigger, or counts that differ (naming both).

    Example:
        >>> trigger_offset(np.array([1500.0, 2500.0, 3502.0]), np.array([0.0, 1000.0, 2000.0]), "r0")
        (1500.0, 2.0)
    """
    camera, force = np.asarray(camera_us, dtype=np.float64), np.asarray(force_us, dtype=np.float64)
    if camera.size != force.size or camera.size == 0:
        raise ValueError(f"{where}: {camera.size} camera trigger(s) but {force.size} on the force clock; they must "
                         "match one to one (cut the recordings to the same pulses, or give a constant "
                         "force_offset_ms)")
    lag = camera - force
    offset = float(np.median(lag))
    return offset, float(np.abs(lag - offset).max())


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
