"""Accumulate event streams (x, y, t, p) into event frames (T, 2, H, W).

Events come as a ``(N, 4)`` tensor of ``(x, y, t, p)`` rows, a ``(B, N, 4)`` batch of
padded streams with ``lengths`` or ``mask``, a mapping of arrays ``{"x", "y", "t", "p"}``,
or a numpy structured array with fields ``x, y, t, p`` (tonic's format). Timestamps are
in microseconds. Polarity ``1``/``True`` is ON (channel 1); ``0``, ``False`` and ``-1`` are
OFF (channel 0), tonic's convention.

Frame ``i`` collects the events with ``t_start + i*frame <= t < t_start + (i+1)*frame``.
The bins are anchored at ``t_start``, not at the first event, so frames stay in step with
force samples taken on the same clock. Events outside the time window, the sensor or the
crop are dropped, never wrapped or clamped.
"""

from __future__ import annotations

__all__ = ["events_to_frames"]

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from .._validation import per_sample

_FIELDS = ("x", "y", "t", "p")


def _column(values: Any, name: str) -> Tensor:
    """One field as a 1-D tensor (int64 for integer input, float64 for float input)."""
    if isinstance(values, Tensor):
        column = values
    else:
        array = np.asarray(values)
        if array.dtype == np.bool_:
            array = array.astype(np.int8)
        elif array.dtype.kind in "iu":
            array = array.astype(np.int64)
        elif array.dtype.kind == "f":
            array = array.astype(np.float64)
        else:
            raise TypeError(f"events[{name!r}] must hold numbers, got numpy dtype {array.dtype}")
        column = torch.from_numpy(np.ascontiguousarray(array))
    if column.dim() != 1:
        raise ValueError(f"events[{name!r}] must be 1-D, got shape {tuple(column.shape)}")
    return column


def _columns(events: Any) -> tuple[list[Tensor], bool]:
    """Split ``events`` into x, y, t, p columns of shape (B, N); also say if it was batched."""
    if isinstance(events, np.ndarray) and events.dtype.names is not None:
        missing = [f for f in _FIELDS if f not in events.dtype.names]
        if missing:
            raise ValueError(
                f"events structured array needs fields x, y, t, p, got {events.dtype.names}"
            )
        if events.ndim != 1:
            raise ValueError(f"events structured array must be 1-D, got shape {events.shape}")
        return [_column(events[f], f).unsqueeze(0) for f in _FIELDS], False
    if isinstance(events, Mapping):
        missing = [f for f in _FIELDS if f not in events]
        if missing:
            raise ValueError(f"events mapping needs keys x, y, t, p, got {sorted(events)}")
        columns = [_column(events[f], f) for f in _FIELDS]
        lengths = {c.shape[0] for c in columns}
        if len(lengths) != 1:
            raise ValueError(f"events x, y, t, p must have equal lengths, got {sorted(lengths)}")
        device = columns[0].device
        return [c.to(device).unsqueeze(0) for c in columns], False
    if isinstance(events, np.ndarray):
        events = torch.from_numpy(np.ascontiguousarray(events))
    if not isinstance(events, Tensor):
        raise TypeError(
            "events must be a (N, 4) or (B, N, 4) tensor, a mapping of x, y, t, p arrays or a "
            f"numpy structured array, got {type(events).__name__}"
        )
    if events.dim() not in (2, 3) or events.shape[-1] != 4:
        raise ValueError(
            f"events: expected (N, 4) or (B, N, 4) rows of (x, y, t, p), got {tuple(events.shape)}"
        )
    if events.dtype == torch.bool or events.is_complex():
        raise TypeError(f"events must hold real numbers, got dtype {events.dtype}")
    batched = events.dim() == 3
    if not batched:
        events = events.unsqueeze(0)
    return [events[..., i] for i in range(4)], batched


def _positive_int(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _valid_mask(
    batch: int, length: int, lengths: Any, mask: Any, device: torch.device
) -> Tensor | None:
    if lengths is not None and mask is not None:
        raise ValueError("give either lengths or mask, not both")
    if mask is not None:
        mask = torch.as_tensor(mask, device=device)
        if mask.dtype != torch.bool or tuple(mask.shape) != (batch, length):
            raise ValueError(
                f"mask must be a bool tensor of shape ({batch}, {length}), "
                f"got shape {tuple(mask.shape)} and dtype {mask.dtype}"
            )
        return mask
    if lengths is not None:
        lengths = torch.as_tensor(lengths, device=device)
        if lengths.dtype.is_floating_point or lengths.dtype == torch.bool:
            raise TypeError(f"lengths must hold integers, got dtype {lengths.dtype}")
        if tuple(lengths.shape) != (batch,):
            raise ValueError(f"lengths must have shape ({batch},), got {tuple(lengths.shape)}")
        if batch and bool(((lengths < 0) | (lengths > length)).any()):
            raise ValueError(f"lengths must lie in [0, {length}], got {lengths.tolist()}")
        return torch.arange(length, device=device) < lengths.unsqueeze(1)
    return None


def events_to_frames(
    events: Tensor | Mapping[str, Any] | np.ndarray,
    *,
    t_start: float | Sequence[float] | Tensor = 0,
    frame_ms: float = 10.0,
    n_frames: int = 36,
    sensor_size: tuple[int, int] = (180, 240),
    crop: tuple[int, int, int, int] | None = None,
    pool: int = 1,
    dtype: torch.dtype = torch.float32,
    lengths: Tensor | Sequence[int] | None = None,
    mask: Tensor | None = None,
) -> Tensor:
    r"""Count events into fixed time bins, one channel per polarity.

    Frame :math:`i` holds the events with
    :math:`t_\mathrm{start} + i\,\Delta \le t < t_\mathrm{start} + (i+1)\,\Delta`,
    :math:`\Delta` = ``frame_ms`` milliseconds (timestamps are in microseconds). The
    optional crop keeps the sensor window ``(top, left, height, width)``; ``pool = k`` then
    sums each k×k block (the paper's "adding the closest neighbourhoods": its 140×150 crop
    pooled 2×2 gives 70×75). Coordinates are floored to whole pixels; events outside the
    time window, the sensor or the crop are dropped. Computed with one ``bincount`` for
    the whole batch.

    Args:
        events: a ``(N, 4)`` tensor of ``(x, y, t, p)`` rows, a ``(B, N, 4)`` batch of
            padded streams, a mapping with keys ``x, y, t, p``, or a numpy structured
            array with those fields (tonic's format). ``p`` is 1/True for ON (channel 1)
            and 0/False/-1 for OFF (channel 0). Integer or float64 timestamps are exact;
            float32 timestamps lose microseconds past 2**24 µs (16.8 s).
        t_start: start of the first bin in microseconds; for a batch, a number or a (B,)
            sequence/tensor (one start per stream).
        frame_ms: bin width in milliseconds.
        n_frames: number of bins T.
        sensor_size: (H, W) of the sensor; events with ``x >= W`` or ``y >= H`` are dropped.
        crop: ``(top, left, height, width)`` window inside the sensor, or ``None`` for the
            whole sensor. Height and width must be multiples of ``pool``.
        pool: side of the square blocks summed into one output pixel.
        dtype: dtype of the counts (float32 by default, as models take float input; any
            integer or float dtype whose range holds the largest count).
        lengths: for a batch, the number of valid events of each stream, shape (B,).
        mask: for a batch, a (B, N) bool tensor marking valid events (instead of lengths).

    Returns:
        Counts of shape ``(T, 2, H', W')``, or ``(B, T, 2, H', W')`` for batched input,
        with ``H' = height // pool`` and ``W' = width // pool``, on the events' device
        (CPU for numpy input).

    Raises:
        ValueError: malformed events, polarity outside {-1, 0, 1}, a crop outside the
            sensor or not divisible by ``pool``, or a count too large for ``dtype``.

    Example:
        >>> import numpy as np
        >>> events = np.zeros(3, dtype=[("x", int), ("y", int), ("t", int), ("p", int)])
        >>> events["x"], events["y"] = [1, 1, 2], [0, 0, 1]
        >>> events["t"], events["p"] = [1_000, 10_000, 35_000], [1, 0, 1]
        >>> frames = events_to_frames(events, n_frames=3, sensor_size=(2, 3))
        >>> frames.shape
        torch.Size([3, 2, 2, 3])
        >>> frames.sum(dim=(2, 3))  # (frame, polarity) totals; t=35 ms is past the window
        tensor([[0., 1.],
                [1., 0.],
                [0., 0.]])
    """
    (x, y, t, p), batched = _columns(events)
    batch, length = x.shape
    device = x.device

    height, width = (_positive_int(s, "sensor_size") for s in _pair(sensor_size, "sensor_size"))
    n_frames = _positive_int(n_frames, "n_frames")
    pool = _positive_int(pool, "pool")
    if isinstance(frame_ms, bool) or not isinstance(frame_ms, (int, float)) or not (
        math.isfinite(frame_ms) and frame_ms > 0
    ):
        raise ValueError(f"frame_ms must be a positive finite number, got {frame_ms!r}")
    if not isinstance(dtype, torch.dtype) or dtype == torch.bool or dtype.is_complex:
        raise TypeError(f"dtype must be an integer or float torch.dtype, got {dtype!r}")
    top, left, crop_h, crop_w = _check_crop(crop, height, width, pool)
    if not batched and (lengths is not None or mask is not None):
        raise ValueError("lengths and mask apply to a (B, N, 4) batch of events only")
    valid = _valid_mask(batch, length, lengths, mask, device)
    starts = per_sample(t_start, batch, "t_start", dtype=torch.float64)
    if batch and not bool(torch.isfinite(starts).all()):
        raise ValueError(f"t_start must be finite, got {starts.tolist()}")

    channel = _polarity_channel(p, valid)

    # Bins in float64: exact for integer timestamps below 2**53 µs.
    frame_us = float(frame_ms) * 1000.0
    time_bin = torch.floor((t.to(torch.float64) - starts.to(device).unsqueeze(1)) / frame_us)
    col = torch.floor(x.to(torch.float64)) if x.is_floating_point() else x.to(torch.int64)
    row = torch.floor(y.to(torch.float64)) if y.is_floating_point() else y.to(torch.int64)
    keep = (time_bin >= 0) & (time_bin < n_frames)
    keep &= (col >= left) & (col < left + crop_w) & (row >= top) & (row < top + crop_h)
    if valid is not None:
        keep &= valid

    out_h, out_w = crop_h // pool, crop_w // pool
    sample = torch.arange(batch, device=device).unsqueeze(1).expand(batch, length)
    index = (sample * n_frames + time_bin.to(torch.int64)) * 2 + channel
    index = (index * out_h + (row.to(torch.int64) - top) // pool) * out_w
    index = index + (col.to(torch.int64) - left) // pool
    size = batch * n_frames * 2 * out_h * out_w
    counts = torch.bincount(index[keep], minlength=size)
    info = torch.finfo(dtype) if dtype.is_floating_point else torch.iinfo(dtype)
    if counts.numel() and batch * length > info.max:  # else no count can overflow
        largest = int(counts.max())
        if largest > info.max:
            raise ValueError(f"a count of {largest} does not fit dtype {dtype}; use a wider dtype")
    frames = counts.to(dtype).view(batch, n_frames, 2, out_h, out_w)
    return frames if batched else frames.squeeze(0)


def _pair(value: object, name: str) -> tuple[Any, Any]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise ValueError(f"{name} must be a pair (H, W), got {value!r}")
    return value[0], value[1]


def _check_crop(
    crop: object, height: int, width: int, pool: int
) -> tuple[int, int, int, int]:
    if crop is None:
        top, left, crop_h, crop_w = 0, 0, height, width
    else:
        if (
            isinstance(crop, (str, bytes))
            or not isinstance(crop, Sequence)
            or len(crop) != 4
            or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in crop)
        ):
            raise ValueError(f"crop must be four integers (top, left, height, width), got {crop!r}")
        top, left, crop_h, crop_w = (int(v) for v in crop)
        if top < 0 or left < 0 or crop_h < 1 or crop_w < 1 or top + crop_h > height or (
            left + crop_w > width
        ):
            raise ValueError(
                f"crop (top, left, height, width) must lie inside the sensor ({height}, {width}), "
                f"got {crop!r}"
            )
    if crop_h % pool or crop_w % pool:
        raise ValueError(
            f"the cropped size ({crop_h}, {crop_w}) must be divisible by pool={pool}"
        )
    return top, left, crop_h, crop_w


def _polarity_channel(p: Tensor, valid: Tensor | None) -> Tensor:
    """Channel index per event: 1 for ON (p > 0), 0 for OFF (p in {0, -1, False})."""
    if p.dtype == torch.bool:
        return p.to(torch.int64)
    checked = p if valid is None else p[valid]
    bad = (checked != 0) & (checked != 1) & (checked != -1)
    if checked.numel() and bool(bad.any()):
        raise ValueError(
            f"events polarity p must be 0/1, -1/1 or bool, got {checked[bad].flatten()[0].item()!r}"
        )
    return (p > 0).to(torch.int64)
