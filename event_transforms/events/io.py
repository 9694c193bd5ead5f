"""Event files read without the application: ``.npy``, ``.npz``, ``.csv``, ``.aedat4`` and HDF5.

:func:`read_events` reads a whole file as numpy columns ``x, y, t, p``; :class:`EventFile`
reads one in chunks (memory-mapped ``.npy``, HDF5 datasets sliced lazily), as
a data set over a folder of recordings does.

Formats:

- ``.npy``: a structured array with fields ``x, y, t, p`` (``timestamp``/``on``/``polarity``
  accepted, tonic's dtypes included), or an ``(N, 4)`` array of rows in ``x, y, t, p`` order
  (another order named with ``columns="txyp"``, ``"_"`` skipping a column);
- ``.npz``: arrays ``x``, ``y``, ``t``, ``p`` (and the sensor size where an array
  ``sensor_size`` holds ``[H, W]``, as ``event-transforms convert`` writes it);
- ``.csv``: a header naming the columns;
- ``.aedat4`` (the ``aedat`` package): every event packet; the sensor size from the file's
  stream description; trigger packets kept for :attr:`EventFile.triggers`;
- ROS bags: :mod:`event_transforms.events.bags` (re-exported here: ``read_bag_events``, ``read_bag_values``, ``read_bag_stamps``);
- Prophesee ``.dat`` (CD events; read here, no package needed): the sensor size from its
  ``% Width``/``% Height`` (or ``% geometry WxH``) header lines;
- Prophesee ``.raw`` in EVT 3.0 (the ``evt3`` package, MIT: the ``prophesee`` extra), its
  sensor size and trigger events kept (rising edges as source 1, falling as 2);
- HDF5 ``.h5``/``.hdf5`` (``h5py``): a structured ``events`` or Prophesee-style ``CD/events``
  dataset, a plain ``(N, 4)`` ``events`` dataset (rows as in ``.npy``, ``columns=`` naming
  another order), or one dataset per column (at the root or in an ``events`` group). The
  sensor size from attributes ``width``/``height`` or ``geometry`` (``"WxH"``) of the root,
  the events dataset or its group, where the file states them.

The readers convert nothing: timestamps come back in the file's own unit (see ``time_unit``
of :func:`~event_transforms.functional.events_to_frames`).
"""

from __future__ import annotations

__all__ = ["EventFile", "read_events", "stated_sensor_size", "read_bag_events", "read_bag_values",
           "read_bag_stamps", "EVENT_MESSAGES"]

import csv
import os
import zipfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .bags import EVENT_MESSAGES, read_bag_events, read_bag_stamps, read_bag_values
from ._ingest import _ALIASES

#: Events per chunk of :meth:`EventFile.chunks`.
_CHUNK = 2**20
#: Rows probed to tell an (N, 4) array's time column.
_PROBE = 4096
_SUFFIXES = (".npy", ".npz", ".csv", ".aedat4", ".h5", ".hdf5", ".dat", ".raw")


class EventFile:
    """An event file read as column chunks ``{"x", "y", "t", "p"}`` of numpy arrays.

    Args:
        path: the file (its suffix names the format).
        columns: the order of the columns of an ``(N, k)`` array (``.npy`` or a plain HDF5
            dataset), e.g. ``"txyp"``, ``"_"`` for a column to skip (default ``"xytp"``);
            files with named columns are read by name (so one setting serves a folder of both).

    Attributes:
        path: the file.
        length: its number of events.
        sensor_size: ``(H, W)`` where the file states it (``.aedat4``, HDF5 attributes, an
            ``.npz``'s ``sensor_size``), else ``None``.
        triggers: the file's trigger events (``.aedat4``) as a structured array with fields
            ``t`` (the events' clock) and ``source``, ``None`` for formats without them.

    Shape:
        Each chunk holds four numpy columns of equal length (at most ``size`` events).

    Raises:
        ValueError: naming the file and what it is not: a missing file, an unknown suffix, a
            file that is not of its suffix's format, missing columns, an ``(N, 4)`` array whose
            rows look like another order (with the ``columns=`` that reads it).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "events.npy"
        >>> np.save(path, np.array([[1, 2, 10, 1], [3, 4, 20, 0], [5, 6, 30, 1]]))
        >>> source = EventFile(path)
        >>> source.length, [c["t"].tolist() for c in source.chunks(2)]
        (3, [[10, 20], [30]])
        >>> np.save(path, np.array([[10, 1, 2, 1], [20, 3, 4, 0], [30, 5, 6, 1]]))  # t first
        >>> EventFile(path, columns="txyp").chunk(0, 3)["t"].tolist()
        [10, 20, 30]
    """

    def __init__(self, path: str | os.PathLike[str], *, columns: str | Sequence[str] | None = None) -> None:
        path = Path(path)
        self.path = path
        self.sensor_size: tuple[int, int] | None = None
        self.triggers: np.ndarray | None = None
        self._columns: dict[str, Any] | None = None
        self._rows: Any = None
        self._order: dict[str, int] = {}
        suffix = path.suffix.lower()
        if not path.is_file():
            raise ValueError(f"events file {str(path)!r} does not exist")
        if suffix == ".npy":
            array = _load_npy(path)
            if array.dtype.names is not None:
                self._columns = _named_columns(array.dtype.names, lambda name: array[name], path)
            elif array.ndim == 2:
                self._rows = array
            else:
                raise ValueError(f"{path}: expected a structured array or (N, 4) rows of x, y, t, p, got "
                                 f"{array.dtype} of shape {array.shape}")
        elif suffix == ".npz":
            if not zipfile.is_zipfile(path):
                raise ValueError(f"{path}: not a NumPy .npz archive (no zip file); save one with numpy.savez")
            with np.load(path, allow_pickle=False) as archive:
                self._columns = _named_columns(archive.files, lambda name: archive[name], path)
                self.sensor_size = _npz_sensor(archive, path)
        elif suffix == ".csv":
            self._columns = _read_csv_events(path)
        elif suffix in (".h5", ".hdf5"):
            self._columns, self._rows, self.sensor_size = _read_hdf5(path)
        elif suffix == ".aedat4":
            self._columns, self.sensor_size, self.triggers = _read_aedat4(path)
        elif suffix == ".dat":
            self._columns, self.sensor_size = _read_dat(path)
        elif suffix == ".raw":
            self._columns, self.sensor_size, self.triggers = _read_raw(path)
        else:
            raise ValueError(f"{path}: unknown event file type {suffix!r}; expected one of {', '.join(_SUFFIXES)}")
        if self._rows is not None:
            self._order = _row_order(self._rows, columns, path)
        lengths = {len(c) for c in self._columns.values()} if self._columns is not None else {len(self._rows)}
        if len(lengths) != 1:
            raise ValueError(f"{path}: columns x, y, t, p have different lengths {sorted(lengths)}")
        self.length = lengths.pop()

    def chunk(self, start: int, stop: int) -> dict[str, np.ndarray]:
        """Events ``start`` to ``stop`` (excluded) as columns."""
        if self._columns is not None:
            return {c: np.asarray(v[start:stop]) for c, v in self._columns.items()}
        rows = np.asarray(self._rows[start:stop])
        return {c: rows[:, self._order[c]] for c in "xytp"}

    def chunks(self, size: int = _CHUNK) -> Iterator[dict[str, np.ndarray]]:
        """The file's events in order, ``size`` at a time."""
        for start in range(0, self.length, size):
            yield self.chunk(start, start + size)


def _load_npy(path: Path) -> np.ndarray:
    with open(path, "rb") as handle:
        magic = handle.read(6)
    if magic != b"\x93NUMPY":
        kind = _what_it_is(path)
        raise ValueError(f"{path}: not a NumPy file (.npy files start with \\x93NUMPY; this one starts with "
                         f"{magic!r}{kind}); write it with numpy.save")
    try:
        return np.load(path, mmap_mode="r", allow_pickle=False)
    except (ValueError, OSError) as error:
        raise ValueError(f"{path}: a damaged NumPy file ({error}); write it again with numpy.save") from None


def _npz_sensor(archive: Any, path: Path) -> tuple[int, int] | None:
    """(H, W) from an .npz's ``sensor_size`` array (as ``event-transforms convert`` writes it)."""
    if "sensor_size" not in archive.files:
        return None
    size = np.asarray(archive["sensor_size"]).reshape(-1)
    if size.size != 2 or size.dtype.kind not in "iu" or (size < 1).any():
        raise ValueError(f"{path}: sensor_size must hold two positive integers (H, W), got {size.tolist()}")
    return int(size[0]), int(size[1])


def _what_it_is(path: Path) -> str:
    """`` (it looks like a CSV)`` and the like, for errors naming a wrong file."""
    head = path.read_bytes()[:512]
    if head.startswith(b"PK"):
        return ", a zip archive: a .npz or a torch checkpoint?"
    if head.startswith(b"\x89HDF"):
        return ", an HDF5 file: name it .h5"
    if head.startswith(b"#!AER-DAT4"):
        return ", an AEDAT4 file: name it .aedat4"
    try:
        text = head.decode()
    except UnicodeDecodeError:
        return ""
    return ", text: a CSV? name it .csv" if "," in text else ""


def _order_names(columns: str | Sequence[str], width: int, path: Path) -> list[str]:
    names = list(columns) if isinstance(columns, (str, Sequence)) else None
    if names is None or sorted(n for n in names if n != "_") != ["p", "t", "x", "y"] or any(
            n not in "xytp_" or len(n) != 1 for n in names):
        raise ValueError(f"{path}: columns must name each of x, y, t, p once and '_' for a column to skip "
                         f"(e.g. 'txyp'), got {columns!r}")
    if len(names) != width:
        raise ValueError(f"{path}: columns={columns!r} names {len(names)} columns, but the rows have {width}")
    return names


def _row_order(rows: Any, columns: str | Sequence[str] | None, path: Path) -> dict[str, int]:
    """Where x, y, t, p are among the rows' columns; rows that look like another order are refused."""
    width = int(rows.shape[1]) if len(rows.shape) == 2 else -1
    if columns is not None:
        names = _order_names(columns, width, path)
        return {c: names.index(c) for c in "xytp"}
    if width != 4:
        raise ValueError(f"{path}: expected (N, 4) rows of x, y, t, p, got shape {tuple(rows.shape)}; name the "
                         "columns with columns= (e.g. 'txyp', '_' for a column to skip)")
    probe = np.asarray(rows[:_PROBE])
    if len(probe) > 2 and np.any(np.diff(probe[:, 2]) < 0):  # the t column goes back: is another one the time?
        steady = [k for k in (0, 1, 3) if np.all(np.diff(probe[:, k]) >= 0) and probe[-1, k] > probe[0, k]]
        if len(steady) == 1:
            names = ["x", "y", "p"]
            names.insert(steady[0], "t")
            order = "".join(names)
            raise ValueError(
                f"{path}: the rows' third column (t in the default x, y, t, p order) goes back in time, while column "
                f"{steady[0] + 1} rises steadily: the rows look like {', '.join(order)} order; pass columns={order!r}")
    return {c: k for k, c in enumerate("xytp")}


def _named_columns(names: Any, get: Any, path: Path) -> dict[str, Any]:
    names = list(names)
    found = {c: next((a for a in _ALIASES[c] if a in names), None) for c in _ALIASES}
    missing = [c for c, name in found.items() if name is None]
    if missing:
        hint = ""
        if "force_n" in names or any(str(n).startswith("f") and len(str(n)) == 2 for n in names):
            hint = "; this looks like a force file, not an event file"
        raise ValueError(f"{path}: needs columns x, y, t (or timestamp), p (or on, polarity); got {names} "
                         f"(missing {', '.join(missing)}){hint}")
    return {c: get(name) for c, name in found.items()}


def _read_csv_events(path: Path) -> dict[str, Any]:
    try:
        with open(path, newline="") as handle:
            header = [h.strip() for h in next(csv.reader(handle), [])]
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text CSV file{_what_it_is(path)}") from None
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


def _read_hdf5(path: Path) -> tuple[dict[str, Any] | None, Any, tuple[int, int] | None]:
    try:
        import h5py
    except ImportError:
        raise ValueError(f"{path}: reading HDF5 needs h5py: pip install 'event-transforms[hdf5]'") from None
    try:
        handle = h5py.File(path, "r")  # kept open: its datasets are read chunk by chunk
    except OSError as error:
        raise ValueError(f"{path}: not an HDF5 file ({error}){_what_it_is(path)}") from None
    for name in ("events", "CD/events"):
        if name in handle and isinstance(handle[name], h5py.Dataset):
            dataset = handle[name]
            sensor = _h5_sensor([handle, dataset, dataset.parent], path)
            if dataset.dtype.names:
                return _named_columns(dataset.dtype.names, lambda field, data=dataset: _H5Field(data, field),
                                      path), None, sensor
            if dataset.ndim == 2:
                return None, _H5Rows(dataset), sensor
            raise ValueError(f"{path}: dataset {name!r} of shape {dataset.shape} is neither structured nor (N, k) rows")
    group = handle["events"] if "events" in handle and isinstance(handle["events"], h5py.Group) else handle
    return (_named_columns(list(group.keys()), lambda name: _H5Rows(group[name]), path), None,
            _h5_sensor([handle, group], path))


def _h5_sensor(nodes: list[Any], path: Path) -> tuple[int, int] | None:
    """(H, W) from ``width``/``height`` or ``geometry`` ("WxH") attributes, where given."""
    for node in nodes:
        attrs = node.attrs
        if "width" in attrs and "height" in attrs:
            return int(attrs["height"]), int(attrs["width"])
        if "geometry" in attrs:
            text = attrs["geometry"]
            text = text.decode() if isinstance(text, bytes) else str(text)
            try:
                width, height = (int(v) for v in text.lower().split("x"))
            except ValueError:
                raise ValueError(f"{path}: attribute geometry={text!r} is not 'WIDTHxHEIGHT'") from None
            return height, width
    return None


def _h5_slice(dataset: Any, index: Any) -> np.ndarray:
    """``dataset[index]``, a filter HDF5 cannot load named (Prophesee's ECF codec)."""
    try:
        return np.asarray(dataset[index])
    except OSError as error:
        raise ValueError(
            f"{dataset.file.filename}: dataset {dataset.name} cannot be read ({str(error).splitlines()[0]}); if it "
            "is compressed with a filter this HDF5 lacks (Prophesee's files use their ECF codec), install the "
            "filter's HDF5 plugin (HDF5_PLUGIN_PATH) or convert the file") from None


class _H5Rows:
    """An (N, k) HDF5 dataset, sliced lazily, its read errors named."""

    def __init__(self, dataset: Any) -> None:
        self.dataset, self.shape = dataset, dataset.shape

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: slice) -> np.ndarray:
        return _h5_slice(self.dataset, index)


class _H5Field:
    """One field of a structured HDF5 dataset, sliced lazily."""

    def __init__(self, dataset: Any, name: str) -> None:
        self.dataset, self.name = dataset, name

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: slice) -> np.ndarray:
        return _h5_slice(self.dataset, index)[self.name]


def _dat_header(path: Path) -> tuple[int, tuple[int, int] | None]:
    """The byte offset of a Prophesee .dat file's events and the sensor size its header states."""
    width = height = None
    with open(path, "rb") as handle:
        offset = 0
        while True:
            line = handle.readline()
            if not line.startswith(b"%"):
                break
            offset += len(line)
            words = line[1:].decode(errors="replace").split()
            if len(words) >= 2 and words[0].lower() == "width":
                width = int(words[1])
            elif len(words) >= 2 and words[0].lower() == "height":
                height = int(words[1])
            elif len(words) >= 2 and words[0].lower() == "geometry":
                width, height = (int(v) for v in words[1].lower().split("x"))
    if offset == 0:
        raise ValueError(f"{path}: not a Prophesee .dat file (no '%' header lines){_what_it_is(path)}")
    return offset, (height, width) if width and height else None


class _Bits:
    """Bits ``shift``..``shift + width`` of a uint32 column, sliced lazily."""

    def __init__(self, data: np.ndarray, shift: int, width: int) -> None:
        self.data, self.shift, self.mask = data, shift, (1 << width) - 1

    def __len__(self) -> int:
        return len(self.data)

    def __getitem__(self, index: slice) -> np.ndarray:
        return ((np.asarray(self.data[index]) >> self.shift) & self.mask).astype(np.int32)


def _read_dat(path: Path) -> tuple[dict[str, Any], tuple[int, int] | None]:
    """A Prophesee .dat file of CD events (8-byte records: uint32 t in µs, uint32 with x in bits
    0-13, y in 14-27, polarity in 28-31), memory-mapped."""
    offset, sensor = _dat_header(path)
    kind, size = np.fromfile(path, dtype=np.uint8, count=2, offset=offset)
    if size != 8:
        raise ValueError(f"{path}: .dat events of {size} bytes (type {kind}); only 8-byte CD events are read")
    dtype = np.dtype([("t", "<u4"), ("data", "<u4")])
    if path.stat().st_size <= offset + 2:
        records = np.zeros(0, dtype=dtype)
    else:
        records = np.memmap(path, dtype=dtype, mode="r", offset=offset + 2)
    columns = {"x": _Bits(records["data"], 0, 14), "y": _Bits(records["data"], 14, 14), "t": records["t"],
               "p": _Bits(records["data"], 28, 4)}
    return columns, sensor


def _raw_header(path: Path) -> tuple[str, tuple[int, int] | None]:
    """A Prophesee .raw file's encoding (``evt 3.0``) and the sensor size its header states."""
    encoding, sensor = "", None
    with open(path, "rb") as handle:
        while (line := handle.readline()).startswith(b"%"):
            words = line[1:].decode(errors="replace").strip()
            if words.lower().startswith("evt "):
                encoding = words.lower()
            elif words.lower().startswith("geometry "):
                width, height = (int(v) for v in words.split()[1].lower().split("x"))
                sensor = (height, width)
            elif words.lower().startswith("format ") and sensor is None:  # "format EVT3;height=720;width=1280"
                fields = dict(f.split("=", 1) for f in words.split(None, 1)[1].split(";") if "=" in f)
                if "width" in fields and "height" in fields:
                    sensor = (int(fields["height"]), int(fields["width"]))
    return encoding, sensor


def _read_raw(path: Path) -> tuple[dict[str, Any], tuple[int, int] | None, np.ndarray]:
    encoding, _ = _raw_header(path)
    if encoding != "evt 3.0":
        raise ValueError(f"{path}: only Prophesee .raw files in EVT 3.0 are read, this one says "
                         f"{encoding or 'no encoding (no % evt header)'}; convert it with Metavision's tools")
    try:
        import evt3
    except ImportError:
        raise ValueError(f"{path}: reading Prophesee .raw needs evt3: pip install 'event-transforms[prophesee]'") from None
    events, found = evt3.decode_file_with_triggers(str(path))
    columns = {"x": np.asarray(events.x), "y": np.asarray(events.y), "t": np.asarray(events.t).astype(np.int64),
               "p": np.asarray(events.p)}
    triggers = np.zeros(len(found), dtype=[("t", "<u8"), ("source", "u1")])
    if len(found):
        triggers["t"] = np.asarray(found.timestamp)
        triggers["source"] = np.where(np.asarray(found.value) > 0, 1, 2)
    return columns, (int(events.sensor_height), int(events.sensor_width)), triggers


def _read_aedat4(path: Path) -> tuple[dict[str, Any], tuple[int, int] | None, np.ndarray | None]:
    try:
        import aedat
    except ImportError:
        raise ValueError(f"{path}: reading .aedat4 needs the aedat package: pip install 'event-transforms[aedat]'") from None
    try:
        decoder = aedat.Decoder(str(path))
        streams = decoder.id_to_stream()
        packets = list(decoder)
    except Exception as error:  # noqa: BLE001 - the decoder's own errors (RuntimeError, OSError) named once
        raise ValueError(f"{path}: not a readable AEDAT4 file ({type(error).__name__}: {error})") from None
    sizes = {(int(s["height"]), int(s["width"])) for s in streams.values() if s.get("type") == "events"
             and "width" in s and "height" in s}
    parts = [packet["events"] for packet in packets if "events" in packet]
    if not parts:
        raise ValueError(f"{path}: the file holds no event packets")
    events = np.concatenate(parts)
    triggers = [packet["triggers"] for packet in packets if "triggers" in packet]
    trigger_array = np.concatenate(triggers) if triggers else np.zeros(0, dtype=[("t", "<u8"), ("source", "u1")])
    sensor = sizes.pop() if len(sizes) == 1 else None
    return _named_columns(events.dtype.names, lambda name: events[name], path), sensor, trigger_array


def read_events(path: str | os.PathLike[str], *, columns: str | Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Every event of one file as columns ``x, y, t, p`` (numpy), in any of the module's formats.

    For large files use :class:`EventFile`, which reads them in chunks.

    Args:
        path: the file (its suffix names the format).
        columns: the order of an ``(N, k)`` array's columns (``.npy``, plain HDF5), e.g. ``"txyp"``.

    Shape:
        Four numpy columns of length N, timestamps in the file's own unit.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "events.csv"
        >>> _ = path.write_text("timestamp,x,y,polarity\\n10,1,2,1\\n20,3,4,0\\n")
        >>> {k: v.tolist() for k, v in read_events(path).items()}
        {'x': [1, 3], 'y': [2, 4], 't': [10, 20], 'p': [1, 0]}
    """
    source = EventFile(path, columns=columns)
    return source.chunk(0, source.length)


def stated_sensor_size(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """The sensor size ``(H, W)`` an event file states (``.aedat4`` stream description, HDF5
    attributes, an ``.npz``'s ``sensor_size``), read from its header only; ``None`` for
    formats and files that state none.

    Args:
        path: the event file.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "events.npy"
        >>> np.save(path, np.array([[1, 2, 10, 1]]))
        >>> stated_sensor_size(path) is None
        True
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz" and zipfile.is_zipfile(path):
        with np.load(path, allow_pickle=False) as archive:
            return _npz_sensor(archive, path)
    if suffix == ".dat":
        return _dat_header(path)[1]
    if suffix == ".raw":
        return _raw_header(path)[1]
    if suffix == ".aedat4":
        try:
            import aedat

            streams = aedat.Decoder(str(path)).id_to_stream()
        except ImportError:
            raise ValueError(f"{path}: reading .aedat4 needs the aedat package: pip install 'event-transforms[aedat]'") from None
        except Exception as error:  # noqa: BLE001 - the decoder's own errors named once
            raise ValueError(f"{path}: not a readable AEDAT4 file ({type(error).__name__}: {error})") from None
        sizes = {(int(s["height"]), int(s["width"])) for s in streams.values() if s.get("type") == "events"
                 and "width" in s and "height" in s}
        return sizes.pop() if len(sizes) == 1 else None
    if suffix in (".h5", ".hdf5"):
        try:
            import h5py
        except ImportError:
            raise ValueError(f"{path}: reading HDF5 needs h5py: pip install 'event-transforms[hdf5]'") from None
        try:
            with h5py.File(path, "r") as handle:
                nodes = [handle]
                for name in ("events", "CD/events"):
                    if name in handle:
                        nodes += [handle[name], handle[name].parent]
                        break
                return _h5_sensor(nodes, path)
        except OSError as error:
            raise ValueError(f"{path}: not an HDF5 file ({error}){_what_it_is(path)}") from None
    return None
