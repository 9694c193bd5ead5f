"""One pass over an event file: checked (sorted, inside the sensor, polarity, units) and
counted per pixel; the contact area from those counts."""

from __future__ import annotations

__all__ = ["EventScan", "scan_events", "contact_crop"]

import math
from dataclasses import dataclass

import numpy as np
import torch

from ...events.io import EventFile


@dataclass
class EventScan:
    """What one pass over an event file found: size, time span, per-pixel totals.

    Attributes:
        events: the number of events.
        t_min, t_max: the first and last timestamps in microseconds.
        totals: events per pixel, int64 ``(H, W)``.
    """

    events: int
    t_min: int | float
    t_max: int | float
    totals: np.ndarray  # (H, W) int64


def scan_events(source: EventFile, sensor: tuple[int, int], where: str, time_unit: str | None = None) -> EventScan:
    """Check an event file chunk by chunk (sorted, inside the sensor, polarity, units) and
    count events per pixel; ``t_min``/``t_max`` in microseconds (read in ``time_unit``).

    Args:
        source: the event file.
        sensor: ``(H, W)``; an event outside is refused.
        where: how errors name the file.
        time_unit: the timestamps' unit (``None``: microseconds, seconds-looking floats refused).

    Raises:
        ValueError: naming ``where`` and the first bad event.

    Example:
        >>> import tempfile
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "e.npy"
        >>> np.save(path, np.array([[1, 2, 10, 1], [3, 4, 20, 0]]))
        >>> found = scan_events(EventFile(path), (8, 8), "e.npy")
        >>> found.events, found.t_min, found.t_max, int(found.totals.sum())
        (2, 10, 20, 2)
    """
    from ...events._ingest import SECONDS_SPAN, millisecond_advice, to_microseconds

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
                f"pass sensor_size=(H, W) of the camera (at least ({int(y.max()) + 1}, {int(x.max()) + 1}) here)"
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
    if time_unit is None and fractional and span < SECONDS_SPAN:
        raise ValueError(
            f"{where}: timestamps look like seconds, not microseconds (fractional values spanning {span:g}); "
            "give their unit: time_unit='s', or 'ms', 'ns', or 'us' if they are microseconds"
        )
    if time_unit is None and not isinstance(t_min, float):
        advice = millisecond_advice(offset, t_min, t_max)
        if advice is not None:
            raise ValueError(f"{where}: {advice}; give their unit: time_unit='ms', or time_unit='us' if they are "
                             "microseconds")
    if time_unit is not None:  # to microseconds exactly as the binning converts them
        dtype = torch.float64 if isinstance(t_min, float) else torch.int64
        t_min, t_max = to_microseconds(torch.tensor([t_min, t_max], dtype=dtype), time_unit).tolist()
    return EventScan(offset, t_min, t_max, totals.reshape(height, width))


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
