"""Cleaning kernels: hot pixels by rate and a frame-level denoising filter.

Both only find or zero entries, so counts can only fall and the dtype is kept. Neither
reads values back to the host. Removing pixels (given, hot or random) is in
:mod:`event_transforms.functional.drop`.
"""

from __future__ import annotations

import torch
from torch import Tensor

from .._validation import as_batch, as_number, check_frames, check_positive
from ..events.batch import EventBatch
from ..events._kernel import relative_times
from ..events._kernel import event_index, build_grid
from ._dispatch import kernel_for, register_kernel
from ._event_ops import _compact, _require_grid

__all__ = ["hot_pixels", "denoise", "denoise_frames", "denoise_events"]


def hot_pixels(frames: Tensor, rate_hz: float, *, frame_ms: float = 10.0) -> Tensor:
    """Pixels whose event rate over the sequence exceeds ``rate_hz`` (hot pixels), per sample.

    The rate of a pixel is its event count over all frames and both polarities divided by
    the sequence's duration ``T · frame_ms`` (tonic's ``identify_hot_pixel`` on frames).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        rate_hz: events per second above which a pixel is hot (> 0).
        frame_ms: the duration of one frame in milliseconds.

    Returns:
        bool ``(H, W)`` or ``(B, H, W)`` on the frames' device.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: bool ``(H, W)`` or ``(B, H, W)`` on the frames' device.

    Example:
        >>> frames = torch.zeros(10, 2, 2, 3)
        >>> frames[:, 1, 0, 2] = 1.0  # one event per 10 ms frame: 100 Hz
        >>> hot_pixels(frames, 50.0).nonzero().tolist()
        [[0, 2]]
    """
    batch, unbatch = as_batch(check_frames(frames))
    rate = check_positive(rate_hz, "rate_hz")
    duration = check_positive(frame_ms, "frame_ms") / 1000.0
    return unbatch(_hot_pixels(batch, rate * duration))


def _hot_pixels(batch: Tensor, events_per_frame: float) -> Tensor:
    """(B, H, W): total count over T and P > ``events_per_frame`` · T."""
    acc = torch.float64 if batch.dtype in (torch.float64, torch.int32, torch.int64) else torch.float32
    total = batch.to(acc).sum(dim=(1, 2))
    return total > events_per_frame * batch.shape[1]


def denoise(frames: Tensor | EventBatch, *, radius: int = 1, temporal_radius: int = 1) -> Tensor | EventBatch:
    """Remove events with no other event nearby (background-activity filter on frames).

    An entry (t, p, y, x) with events is kept when some *other* entry within
    ``|y' - y| <= radius``, ``|x' - x| <= radius`` and ``|t' - t| <= temporal_radius``, of
    either polarity, holds events; otherwise its events are removed. This is tonic's
    ``Denoise`` (a neighbour within ``filter_time``) on frames, with a symmetric window in
    time (a frame cannot tell earlier from later events inside it). Values > 0 count as
    events. Counts kept are unchanged; the dtype is kept.

    On an EventBatch (:func:`denoise_events`, which needs the batch's frame grid) an event
    survives when another event lies within ``radius`` pixels and ``temporal_radius`` *bins
    of the grid*, not in the event's own entry (its pixel, bin and polarity): the frame
    rule, event by event, so binned the result equals the frame kernel's exactly. It is not
    tonic's continuous-time filter (``|t' - t| <= filter_time``): two events are neighbours
    by the bins they fall in, so their time difference may reach almost
    ``(temporal_radius + 1) · frame_ms``, and a second event in the same entry does not
    count (on frames the two are one entry).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        radius: spatial half-width of the window in pixels (>= 0).
        temporal_radius: temporal half-width in frames (>= 0).

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> frames = torch.zeros(3, 2, 5, 5, dtype=torch.int16)
        >>> frames[1, 1, 0, 0] = 2  # alone
        >>> frames[0, 0, 3, 3] = frames[1, 1, 4, 4] = 1  # neighbours in space and time
        >>> denoise(frames).nonzero().tolist()
        [[0, 0, 3, 3], [1, 1, 4, 4]]
    """
    kernel = kernel_for(denoise, frames)
    spatial = as_number(radius, "radius", integer=True, low=0)
    temporal = as_number(temporal_radius, "temporal_radius", integer=True, low=0)
    if isinstance(frames, EventBatch):
        return kernel(frames, spatial, temporal)
    batch, unbatch = as_batch(check_frames(frames))
    return unbatch(kernel(batch, spatial, temporal))


def _box_sum(values: Tensor, dim: int, radius: int) -> Tensor:
    """Sum over ``[i - radius, i + radius]`` along ``dim`` (zeros outside), by a cumulative sum."""
    if radius == 0:
        return values
    size = values.shape[dim]
    radius = min(radius, size)  # a wider window adds only zeros
    pad = [0, 0] * (values.dim() - 1 - dim % values.dim()) + [radius + 1, radius]
    total = torch.nn.functional.pad(values, pad).cumsum(dim)
    return total.narrow(dim, 2 * radius + 1, size) - total.narrow(dim, 0, size)


@register_kernel(denoise, Tensor)
def denoise_frames(batch: Tensor, radius: int, temporal_radius: int) -> Tensor:
    """Kernel of :func:`denoise` for frames: keep the counts of a pixel only if another
    pixel within ``radius`` (space) and ``temporal_radius`` frames (time) holds an event.

    Args:
        batch: frames ``(B, T, 2, H, W)``.
        radius: the spatial neighbourhood in pixels.
        temporal_radius: the temporal neighbourhood in frames.

    Shape:
        - batch: ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> frames = torch.zeros(1, 1, 2, 3, 3)
        >>> frames[0, 0, 0, 0, 0] = 1  # alone: removed
        >>> int(denoise_frames(frames, 1, 0).sum())
        0
    """
    if batch.numel() == 0:
        return batch.clone()
    occupied = batch > 0  # (B, T, 2, H, W)
    return batch.masked_fill(occupied & (_occupied_others(occupied, radius, temporal_radius) < 0.5), 0)


def _occupied_others(occupied: Tensor, radius: int, temporal_radius: int) -> Tensor:
    """(B, T, 2, H, W) float32: occupied entries in each entry's window, the entry itself excluded."""
    # occupied entries per (t, y, x), both polarities: whole numbers, exact in float32
    window = occupied.sum(dim=2, dtype=torch.float32)
    window = _box_sum(_box_sum(_box_sum(window, 1, temporal_radius), 2, radius), 3, radius)
    return window.unsqueeze(2) - occupied.to(torch.float32)


@register_kernel(denoise, EventBatch)
def denoise_events(batch: EventBatch, radius: int, temporal_radius: int) -> EventBatch:
    """Kernel of :func:`denoise` for an EventBatch with a frame grid: an event is removed when
    no other entry (pixel, bin, polarity) within its window holds an event (see :func:`denoise`).

    The occupancy of the grid's ``(B, T, 2, H, W)`` entries is built by one scatter (memory
    as the binned frames, in float32), the frame kernel's box sums count each entry's
    occupied neighbours, and each event reads its entry's count by one gather. Events outside
    the grid's window or the sensor have no entry: they are kept, and the binning drops them
    with its warning. One host read (of the kept counts).

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        radius: spatial half-width of the window in pixels (>= 0).
        temporal_radius: temporal half-width in bins of the grid (>= 0).

    Shape:
        - batch: B streams, N events.
        - output: B streams, at most N events (in their order).

    Example:
        >>> from event_transforms import EventBatch
        >>> events = torch.tensor([[0, 0, 1500, 1], [3, 3, 500, 0], [4, 4, 1200, 1]])  # (x, y, t, p)
        >>> batch = EventBatch.from_streams([events], sensor_size=(5, 5), frame_ms=1.0, t_start=0, n_frames=3)
        >>> denoise_events(batch, 1, 1).x.tolist()  # the event at (0, 0) has no neighbour
        [3, 4]
    """
    starts, _, n_frames = _require_grid(batch, "denoise")
    if batch.num_events == 0:
        return batch
    b = len(batch)
    height, width = batch.sensor_size
    grid = build_grid(batch.sensor_size, None, None, 1, batch.frame_ms, torch.float32)
    block = n_frames * grid.frame_size
    index, pixel, inside = event_index(batch.x, batch.y, batch.p, relative_times(batch, starts), n_frames, grid,
                                        b * block >= 2**31)
    inside &= pixel >= 0
    index = index.masked_fill(~inside, 0)
    entry = index.to(torch.int64).add_(batch.sample_index().to(torch.int64) * block)
    occupied = torch.zeros(b * block, dtype=torch.float32, device=batch.device)
    occupied.index_put_((entry,), inside.to(torch.float32), accumulate=True)
    occupied = occupied.view(b, n_frames, 2, height, width) > 0
    others = _occupied_others(occupied, radius, temporal_radius).view(-1).index_select(0, entry)
    return _compact(batch, ~inside | (others > 0.5))
