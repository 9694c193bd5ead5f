"""Force labels: a force CSV read and checked, each frame's label from its samples."""

from __future__ import annotations

__all__ = ["read_force", "frame_labels"]

import csv
import os
import warnings
from pathlib import Path

import numpy as np


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
