"""Representations beside frames, from events (x, y, t, p): voxel grids and time surfaces.

Events are given as :func:`~event_transforms.functional.events_to_frames` takes them (a
``(N, 4)`` tensor, a ``(B, N, 4)`` padded batch with ``lengths`` or ``mask``, a mapping of
arrays, or tonic's structured array; timestamps in microseconds; polarity 1/True ON,
0/False/-1 OFF). Coordinates are floored to whole pixels and events outside the sensor
are dropped, never clamped. Each is computed with one scatter for the whole batch.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from .._params import Param, check_args
from .._validation import check_choice
from ..events.batch import EventBatch
from ..events._kernel import polarity_channel, valid_mask
from ..events._ingest import canonical_columns, size_pair, positive_int

__all__ = ["to_voxel_grid", "to_time_surface"]

VOXEL_POLARITIES = ("signed", "split")


def _parse(events: Any, sensor_size: tuple[int, int], lengths: Any, mask: Any) -> tuple[Any, ...]:
    """Columns (B, N), batched flag, (H, W), validity (B, N) and in-sensor pixel indices."""
    (x, y, t, p), batched = canonical_columns(events)
    batch, length = x.shape
    height, width = (positive_int(s, "sensor_size") for s in size_pair(sensor_size, "sensor_size"))
    if not batched and (lengths is not None or mask is not None):
        raise ValueError("lengths and mask apply to a (B, N, 4) batch of events only")
    valid = valid_mask(batch, length, lengths, mask, x.device)
    channel = polarity_channel(p, valid)
    col = torch.floor(x.to(torch.float64)).to(torch.int64) if x.is_floating_point() else x.to(torch.int64)
    row = torch.floor(y.to(torch.float64)).to(torch.int64) if y.is_floating_point() else y.to(torch.int64)
    keep = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    if valid is not None:
        keep &= valid
    return batched, (batch, height, width), t.to(torch.float64), channel, row, col, keep


def to_voxel_grid(
    events: Tensor | Mapping[str, Any] | np.ndarray,
    *,
    n_bins: int,
    sensor_size: tuple[int, int] = (180, 240),
    polarity: str = "signed",
    lengths: Tensor | Sequence[int] | None = None,
    mask: Tensor | None = None,
) -> Tensor:
    r"""Spread events over ``n_bins`` time bins with bilinear weights in time (Zhu et al. 2019).

    Each stream's timestamps are normalised to :math:`t^* = (n - 1)(t - t_0)/(t_1 - t_0)`,
    :math:`t_0, t_1` its first and last (valid, in-sensor) event, and an event adds
    :math:`\max(0, 1 - |t^* - k|)` to bins :math:`k = \lfloor t^*\rfloor` and :math:`k + 1`:
    the total weight of every event is 1. With ``polarity="signed"`` (tonic's
    ``ToVoxelGrid``) ON events add +1 and OFF events -1 in one channel, ``(n, 1, H, W)``;
    with ``"split"`` each polarity has its channel, ``(n, 2, H, W)``, non-negative, in the
    frames' layout so every transform applies. A stream whose events share one timestamp
    puts them all in bin 0.

    Args:
        events: events as :func:`~event_transforms.functional.events_to_frames` takes them,
            or an :class:`~event_transforms.EventBatch` (its own sensor size is used; the
            output is batched, ``(B, n_bins, C, H, W)``, on its device).
        n_bins: number of time bins (>= 1).
        sensor_size: (H, W).
        polarity: ``"signed"`` or ``"split"``.
        lengths, mask: for a ``(B, N, 4)`` batch, its valid events.

    Returns:
        float32 ``(n_bins, C, H, W)`` or ``(B, n_bins, C, H, W)`` on the events' device,
        ``C`` = 1 (signed) or 2 (split).

    Shape:
        - events: ``(N, 4)`` (or columns) for one stream, ``(B, N, 4)`` with ``lengths`` or
          ``mask``, or an :class:`~event_transforms.EventBatch`.
        - output: float32 ``(n_bins, C, H, W)`` or ``(B, n_bins, C, H, W)``, ``C`` = 1 (signed) or 2
          (split).

    Example:
        >>> events = torch.tensor([[0, 0, 0, 1], [1, 0, 500, 0], [1, 0, 1000, 1]])
        >>> grid = to_voxel_grid(events, n_bins=3, sensor_size=(1, 2))
        >>> grid[:, 0, 0].tolist()
        [[1.0, 0.0], [0.0, -1.0], [0.0, 1.0]]
    """
    n_bins = positive_int(n_bins, "n_bins")
    check_choice(polarity, "polarity", VOXEL_POLARITIES)
    if isinstance(events, EventBatch):  # padded once on its device; the batch's sensor size
        if lengths is not None or mask is not None:
            raise ValueError("lengths and mask come from the EventBatch itself; do not pass them")
        sensor_size = events.sensor_size
        events, lengths = events.to_padded()
    batched, (b, height, width), t, channel, row, col, keep = _parse(events, sensor_size, lengths, mask)
    device = t.device
    inf = torch.tensor(math.inf, dtype=torch.float64, device=device)
    first = torch.where(keep, t, inf).amin(dim=1, keepdim=True) if t.shape[1] else t.new_zeros(b, 1)
    last = torch.where(keep, t, -inf).amax(dim=1, keepdim=True) if t.shape[1] else t.new_zeros(b, 1)
    span = last - first
    scaled = torch.where(span > 0, (n_bins - 1) * (t - first) / torch.where(span > 0, span, 1.0), 0.0)
    scaled = torch.where(keep, scaled, 0.0)  # masked events: no NaN/inf in the index
    lower = scaled.floor().clamp(0, n_bins - 1)
    upper_weight = scaled - lower
    channels = 1 if polarity == "signed" else 2
    sign = (2.0 * channel - 1.0) if polarity == "signed" else torch.ones_like(scaled)
    c = torch.zeros_like(channel) if polarity == "signed" else channel
    sample = torch.arange(b, device=device).unsqueeze(1).expand_as(row)
    size = b * n_bins * channels * height * width

    def flat(k: Tensor) -> Tensor:
        return (((sample * n_bins + k) * channels + c) * height + row.clamp(0, height - 1)) * width + col.clamp(0, width - 1)

    low_index = flat(lower.to(torch.int64))
    high_bin = lower.to(torch.int64) + 1
    high_ok = keep & (high_bin < n_bins) & (upper_weight > 0)
    high_index = flat(high_bin.clamp(max=n_bins - 1))
    index = torch.cat([low_index[keep], high_index[high_ok]])
    weight = torch.cat([(sign * (1 - upper_weight))[keep], (sign * upper_weight)[high_ok]])
    grid = torch.bincount(index, weights=weight, minlength=size) if size else weight.new_zeros(0)
    grid = grid.to(torch.float32).view(b, n_bins, channels, height, width)
    return grid if batched else grid.squeeze(0)


def to_time_surface(
    events: Tensor | Mapping[str, Any] | np.ndarray,
    *,
    tau_ms: float,
    t_start: str | float | Sequence[float] | Tensor = "floor",
    frame_ms: float = 10.0,
    n_frames: int = 36,
    sensor_size: tuple[int, int] = (180, 240),
    lengths: Tensor | Sequence[int] | None = None,
    mask: Tensor | None = None,
) -> Tensor:
    r"""Exponentially decaying time surfaces, sampled at the end of each frame.

    Frame :math:`i` ends at :math:`s_i = t_\mathrm{start} + (i + 1)\Delta`; its surface at
    pixel (y, x) and polarity p is :math:`\exp(-(s_i - t_\mathrm{last})/\tau)` with
    :math:`t_\mathrm{last}` the time of the latest event there in
    :math:`[t_\mathrm{start}, s_i)`, and 0 where there has been none (Lagorce et al.'s
    time surface with exponential decay, on the frames' clock of
    :func:`~event_transforms.functional.events_to_frames`). Events outside
    :math:`[t_\mathrm{start}, t_\mathrm{start} + T\Delta)` or the sensor are dropped.

    Args:
        events: events as :func:`~event_transforms.functional.events_to_frames` takes them.
        tau_ms: decay time constant in milliseconds (> 0).
        t_start: ``"floor"`` (default: each stream's first event rounded down to a multiple
            of the frame length), ``"first"`` (its first event), or a number or one per
            stream, in the events' microseconds — the rule of
            :func:`~event_transforms.functional.events_to_frames`, so absolute timestamps
            (1.7e15 µs) work without an offset.
        frame_ms, n_frames, sensor_size, lengths, mask: as in
            :func:`~event_transforms.functional.events_to_frames`.

    Returns:
        float32 ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` in (0, 1], zero before a pixel's
        first event, on the events' device.

    Raises:
        ValueError: a stream holds events on the sensor but none in its window (naming
            ``t_start``, ``frame_ms`` and ``n_frames``), rather than returning zeros.

    Shape:
        - events: ``(N, 4)`` (or columns) for one stream, or ``(B, N, 4)`` with ``lengths`` or
          ``mask``.
        - output: float32 ``(n_frames, 2, H, W)`` or ``(B, n_frames, 2, H, W)``.

    Example:
        >>> events = torch.tensor([[0, 0, 5_000, 1]])  # ON at 5 ms
        >>> surface = to_time_surface(events, tau_ms=10.0, n_frames=2, sensor_size=(1, 1))
        >>> [round(v, 4) for v in surface[:, 1, 0, 0].tolist()]  # exp(-0.5), exp(-1.5)
        [0.6065, 0.2231]
    """
    for value, name in ((tau_ms, "tau_ms"), (frame_ms, "frame_ms")):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    n_frames = positive_int(n_frames, "n_frames")
    batched, (b, height, width), t, channel, row, col, keep = _parse(events, sensor_size, lengths, mask)
    device = t.device
    frame_us = float(frame_ms) * 1000.0
    if isinstance(t_start, str):
        if t_start not in ("floor", "first"):
            raise ValueError(f"t_start must be 'floor', 'first', a number or one per stream, got {t_start!r}")
        first = torch.where(keep, t, math.inf).amin(dim=1) if t.shape[1] else t.new_zeros(b)
        starts = torch.where(torch.isfinite(first), first, 0.0)
        if t_start == "floor":
            starts = torch.floor(starts / frame_us) * frame_us
    else:
        starts = check_args("t_start", {"t_start": Param("float")}, b, t_start=t_start)["t_start"].to(device)
    since = t - starts.unsqueeze(1)
    time_bin = torch.floor(since / frame_us)
    in_window = keep & (time_bin >= 0) & (time_bin < n_frames)
    lost = keep.any(dim=1) & ~in_window.any(dim=1)
    if b and bool(lost.any()):  # one host read: never silent zeros for a stream with events
        stream = int(lost.nonzero()[0, 0])
        span = t[stream][keep[stream]]
        raise ValueError(
            f"no event of stream {stream} falls in the window t_start={float(starts[stream]):.0f} µs, "
            f"frame_ms={frame_ms!r}, n_frames={n_frames} (its events span t = {float(span.min()):.0f} "
            f"to {float(span.max()):.0f} µs)"
        )
    keep = in_window
    sample = torch.arange(b, device=device).unsqueeze(1).expand_as(row)
    index = (((sample * n_frames + time_bin.clamp(0, n_frames - 1).to(torch.int64)) * 2 + channel) * height + row.clamp(0, height - 1)) * width + col.clamp(0, width - 1)
    size = b * n_frames * 2 * height * width
    latest = torch.full((size,), -math.inf, dtype=torch.float64, device=device)
    latest = latest.scatter_reduce(0, index[keep], since[keep], reduce="amax")
    latest = latest.view(b, n_frames, 2, height, width)
    if n_frames and latest.numel():
        latest = latest.cummax(dim=1).values  # the latest event up to the end of each frame
    ends = (torch.arange(n_frames, device=device, dtype=torch.float64) + 1) * frame_us
    age = ends.view(1, n_frames, 1, 1, 1) - latest
    surface = torch.exp(-age / (float(tau_ms) * 1000.0)).to(torch.float32)  # exp(-inf) = 0 where none
    return surface if batched else surface.squeeze(0)
