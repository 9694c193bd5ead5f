"""Event files read without the application: ``.npy``, ``.npz``, ``.csv``, ``.aedat4`` and HDF5.

:func:`read_events` reads a whole file as numpy columns ``x, y, t, p``; :class:`EventFile`
reads one in chunks (memory-mapped ``.npy``, HDF5 datasets sliced lazily), as
:class:`~event_transforms.tactile.recordings.RecordingSet` and ``event-transforms predict`` do.
Formats: ``.npy`` (a structured array with fields ``x, y, t, p`` — ``timestamp``/``on``/
``polarity`` accepted, tonic's dtypes included — or an ``(N, 4)`` array of ``x, y, t, p``
rows), ``.npz`` (arrays ``x``, ``y``, ``t``, ``p``), ``.csv`` with a header naming the columns,
and through optional packages ``.aedat4`` (``aedat``) and HDF5 ``.h5``/``.hdf5`` (``h5py``).
"""

from __future__ import annotations

__all__ = ["EventFile", "read_events"]

import csv
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .binning import _ALIASES

#: Events per chunk of :meth:`EventFile.chunks`.
_CHUNK = 2**20


class EventFile:
    """An event file read as column chunks ``{"x", "y", "t", "p"}`` of numpy arrays.

    Args:
        path: the file (its suffix names the format).

    Attributes:
        path: the file.
        length: its number of events.

    Shape:
        Each chunk holds four numpy columns of equal length (at most ``size`` events).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "events.npy"
        >>> np.save(path, np.array([[1, 2, 10, 1], [3, 4, 20, 0], [5, 6, 30, 1]]))
        >>> source = EventFile(path)
        >>> source.length, [c["t"].tolist() for c in source.chunks(2)]
        (3, [[10, 20], [30]])
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        path = Path(path)
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
        """Events ``start`` to ``stop`` (excluded) as columns."""
        if self._columns is not None:
            return {c: np.asarray(v[start:stop]) for c, v in self._columns.items()}
        rows = np.asarray(self._rows[start:stop])
        return {c: rows[:, k] for k, c in enumerate("xytp")}

    def chunks(self, size: int = _CHUNK) -> Iterator[dict[str, np.ndarray]]:
        """The file's events in order, ``size`` at a time."""
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

    For large files use :class:`EventFile`, which reads them in chunks.

    Args:
        path: the file (its suffix names the format).

    Shape:
        Four numpy columns of length N.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "events.csv"
        >>> _ = path.write_text("timestamp,x,y,polarity\\n10,1,2,1\\n20,3,4,0\\n")
        >>> {k: v.tolist() for k, v in read_events(path).items()}
        {'x': [1, 3], 'y': [2, 4], 't': [10, 20], 'p': [1, 0]}
    """
    source = EventFile(path)
    return source.chunk(0, source.length)
