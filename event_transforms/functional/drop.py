"""Drop operations: events (EventDrop: a random fraction, a time window, an area), pixels
(given pixels, random pixel dropout), and the event-only refractory period and decimation.

Dropping follows EventDrop (Gu et al., 2021) for events. Each operation is a dispatcher
(:func:`drop_random`, :func:`drop_by_time`, :func:`drop_by_area`, :func:`drop_pixel`,
:func:`refractory_period`, :func:`decimation`) with a kernel per input type beside it
(``<op>_frames``, ``<op>_events``). On frames these only remove counts: the dtype is kept
(``drop_random(mode="expected")`` scales instead and returns floats).
Pixel masks are computed on the frames' device; :func:`random_pixel_mask` is a
counter-based draw, so a sample's mask depends on its own seed only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from .._params import SEED, Param, check_args
from .._validation import DROP_MODES, check_choice, check_generator, count_stats
from ..events.batch import EventBatch
from ._frame_ops import pixel_mask
from ._dispatch import batch_of, call_kernel, kernel_for, register_kernel
from ._event_ops import DROP_KEYS, _compact, _keys, _per_event, _require_grid
from ._hypergeometric import _EXPAND_MAX, Stream, binomial_counts
from ._random import draw_seeds, sample_salts, uniform

__all__ = [
    "drop_random", "drop_random_frames", "drop_random_events",
    "drop_by_time", "drop_by_time_frames", "drop_by_time_events",
    "drop_by_area", "drop_by_area_frames", "drop_by_area_events",
    "drop_pixel", "drop_pixel_frames", "drop_pixel_events", "random_pixel_mask",
    "refractory_period", "refractory_period_events", "decimation", "decimation_events",
]

Scalars = float | Sequence[float] | Tensor


# --------------------------------------------------------------------------- declarations
# Each operation's per-sample arguments, declared once: the dispatcher checks its arguments
# against it (check_args), the module's params_spec returns it (check_tree).

#: :func:`drop_random`: the probability of dropping an event.
DROP_RANDOM_SPEC = {"fraction": Param("float", low=0.0, high=1.0)}
#: :func:`random_pixel_mask`: the share of pixels dropped and the seed of the draw.
RANDOM_PIXEL_MASK_SPEC = {"fraction": Param("float", low=0.0, high=1.0), "seed": SEED}
#: :func:`refractory_period`: the dead time in µs.
REFRACTORY_PERIOD_SPEC = {"period_us": Param("float", low=0.0)}
#: :func:`decimation`: keep one event in n.
DECIMATION_SPEC = {"n": Param("int", low=1)}


#: :func:`drop_by_time`'s window: first frame and number of frames, non-negative (a window past
#: the end stops at the end).
DROP_BY_TIME_SPEC = {"start": Param("int", low=0), "length": Param("int", low=0)}
#: :func:`drop_by_area`'s rectangle: first row and column, height and width, non-negative (a
#: rectangle past the border stops there).
DROP_BY_AREA_SPEC = {
    "top": Param("int", low=0), "left": Param("int", low=0),
    "height": Param("int", low=0), "width": Param("int", low=0),
}


# --------------------------------------------------------------------------- events


def drop_random(
    inputs: Tensor | EventBatch,
    fraction: Scalars,
    *,
    mode: str = "binomial",
    generator: torch.Generator | None = None,
) -> Tensor | EventBatch:
    """Drop a random fraction of the events (EventDrop's *random drop*), per sample.

    ``mode="binomial"`` drops each event independently with probability ``fraction``
    (counts stay integer, dtype kept; needs integer-valued counts). ``mode="expected"``
    scales the counts by ``1 - fraction`` (float output: input dtype for floats, float32
    for integers) and accepts any counts, e.g. after an interpolating transform (frames
    only: an EventBatch takes ``"binomial"``).

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        fraction: probability of dropping an event, in [0, 1], a number or ``(B,)``.
        mode: ``"binomial"`` or ``"expected"``.
        generator: a ``torch.Generator`` on the frames' device, or ``None``.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - fraction: a number or ``(B,)``.

    Example:
        >>> frames = torch.full((4, 2, 8, 8), 10, dtype=torch.int32)
        >>> out = drop_random(frames, 0.5, generator=torch.Generator().manual_seed(0))
        >>> out.dtype, int(out.sum()), bool((out <= frames).all())
        (torch.int32, 2550, True)
    """
    batch, b, restore = batch_of(inputs)
    check_choice(mode, "mode", DROP_MODES)
    check_generator(generator, batch.device)
    fraction_t = check_args("drop_random", DROP_RANDOM_SPEC, b, fraction=fraction)["fraction"]
    seeds = draw_seeds(b, generator) if mode == "binomial" else None
    return restore(call_kernel(drop_random, batch, fraction_t, mode, seeds))


_DROP_HINT = 'drop events before interpolating transforms (bilinear rotate/resize), or use mode="expected"'


@register_kernel(drop_random, Tensor)
def drop_random_frames(batch: Tensor, fraction: Tensor, mode: str, seeds: Tensor | None, hint: str = _DROP_HINT) -> Tensor:
    """Kernel of :func:`drop_random` on a (B, T, 2, H, W) batch with (B,) CPU fractions and (B,) int64
    per-sample ``seeds``; ``hint`` ends the error raised for fractional counts.

    Each event's fate is a counter-based uniform named by its sample's seed and its
    position in the sample (:class:`~._hypergeometric.Stream`), so a sample's result does
    not depend on its batch. One ``nonzero`` and one host read (the check and the numbers
    the sampler needs).

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        fraction: probability of dropping an event, in [0, 1], a number or ``(B,)``.
        mode: ``"binomial"`` or ``"expected"``.
        seeds: ``(B,)`` int64 per-sample seeds of the counter-based streams.
        hint: the advice in the error message when the counts are not whole.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`drop_random` gives for a batch.
    """
    keep = (1.0 - fraction).view(-1, 1, 1, 1, 1)
    if mode == "expected":
        dtype = batch.dtype if batch.is_floating_point() else torch.float32
        return (batch.to(torch.float64) * keep.to(batch.device)).to(dtype)
    if batch.numel() == 0:
        return batch.clone()
    # Binomial thinning on the non-zero pixels only: frames are sparse.
    flat = batch.reshape(-1)
    index = flat.nonzero().squeeze(1)
    values = flat.index_select(0, index)
    if index.numel() == 0:
        return batch.clone()
    if seeds is None:
        raise ValueError(f"drop_random with mode={mode!r} needs seeds (one int64 seed per sample)")
    counts = values.to(torch.int64)
    high, events = count_stats(values, counts, hint=hint, extra=[counts.clamp_max(_EXPAND_MAX).sum()])
    volume = batch[0].numel()
    sample = torch.div(index, volume, rounding_mode="floor")
    stream = Stream.of_samples(seeds, sample, index - sample * volume, 0)
    prob = keep.view(-1).to(batch.device, torch.float64)
    kept = binomial_counts(counts, prob, sample, stream=stream, largest=int(high), events=events, dtype=batch.dtype)
    out = torch.zeros_like(flat).index_copy_(0, index, kept)
    return out.reshape(batch.shape)


@register_kernel(drop_random, EventBatch)
def drop_random_events(
    batch: EventBatch, fraction: Tensor, mode: str = "binomial", seeds: Tensor | None = None, hint: str = _DROP_HINT
) -> EventBatch:
    """Kernel of :func:`drop_random` for an EventBatch: each event of sample b dropped with
    probability ``fraction[b]`` (its own uniform, from the sample's counter-based stream:
    a hash of ``seeds[b]`` and the event's position in its sample). One host read of the
    kept counts.

    Args:
        batch: the event streams.
        fraction: ``(B,)`` drop probabilities in [0, 1].
        mode: ``"binomial"`` (events are whole; other modes are refused).
        seeds: ``(B,)`` int64 per-sample seeds.
        hint: the advice in the error for another mode.

    Shape:
        - batch: B streams, N events.
        - fraction, seeds: ``(B,)``.
        - output: B streams, at most N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> drop_random_events(batch, torch.tensor([1.0, 0.0]), seeds=torch.tensor([3, 4])).lengths
        [0, 1]
    """
    if mode != "binomial":
        raise ValueError(f"drop_random on events drops whole events: mode must be 'binomial', got {mode!r}")
    if seeds is None:
        raise ValueError("drop_random on events needs seeds (one int64 seed per sample)")
    _, dropped = _keys(batch, seeds, fraction, DROP_KEYS)  # u < fraction
    return _compact(batch, ~dropped)

def _window_mask(start: Tensor, length: Tensor, size: int, device: torch.device) -> Tensor:
    """(B, size) bool: True inside [start, start + length) per sample."""
    position = torch.arange(size, device=device)
    start = start.to(device).unsqueeze(1)
    return (position >= start) & (position < start + length.to(device).unsqueeze(1))

def drop_by_time(inputs: Tensor | EventBatch, start: Scalars, length: Scalars) -> Tensor | EventBatch:
    """Remove every event in frames ``[start, start + length)`` of each sample (EventDrop's *drop by time*).

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch with a
            frame grid (the bins of its grid).
        start: first dropped frame, a non-negative integer or ``(B,)``.
        length: number of dropped frames (a window past the end stops at the end).

    Returns:
        Frames with the window zeroed; dtype kept.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - start, length: integers or ``(B,)``.

    Example:
        >>> frames = torch.ones(5, 2, 1, 1, dtype=torch.uint8)
        >>> drop_by_time(frames, 1, 2)[:, 0, 0, 0].tolist()
        [1, 0, 0, 1, 1]
    """
    batch, b, restore = batch_of(inputs)
    window = check_args("drop_by_time", DROP_BY_TIME_SPEC, b, start=start, length=length)
    return restore(call_kernel(drop_by_time, batch, window["start"], window["length"]))


@register_kernel(drop_by_time, Tensor)
def drop_by_time_frames(batch: Tensor, start: Tensor, length: Tensor) -> Tensor:
    """Kernel of :func:`drop_by_time` for frames ``(B, T, 2, H, W)`` with (B,) int64 CPU windows.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        start: first dropped frame, a non-negative integer or ``(B,)``.
        length: number of dropped frames (a window past the end stops at the end).

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`drop_by_time` gives for a batch.
    """
    b, t = batch.shape[:2]
    mask = _window_mask(start, length, t, batch.device)
    return batch.masked_fill(mask.view(b, t, 1, 1, 1), 0)


@register_kernel(drop_by_time, EventBatch)
def drop_by_time_events(batch: EventBatch, start: Tensor, length: Tensor) -> EventBatch:
    """Kernel of :func:`drop_by_time` for an EventBatch: sample b's events in bins
    ``[start[b], start[b] + length[b])`` of the grid dropped. One host read of the kept counts.

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        start: ``(B,)`` first dropped bin.
        length: ``(B,)`` number of dropped bins.

    Shape:
        - batch: B streams, N events.
        - start, length: ``(B,)``.
        - output: B streams, at most N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> drop_by_time_events(batch, torch.tensor([1, 0]), torch.tensor([1, 1])).t.tolist()
        [100]
    """
    from ..events._kernel import relative_times
    from ..events._kernel import bins_of

    starts, frame_us, n_frames = _require_grid(batch, "RandomEventDrop (time)")
    bins, inside = bins_of(relative_times(batch, starts), frame_us, n_frames)
    first, size = (_per_event(v.to(torch.int32), batch) for v in (start, length))
    hit = inside & (bins >= first) & (bins < first + size)
    return _compact(batch, ~hit)

def drop_by_area(
    inputs: Tensor | EventBatch, top: Scalars, left: Scalars, height: Scalars, width: Scalars
) -> Tensor | EventBatch:
    """Remove every event in a rectangle of each sample, in all frames (EventDrop's *drop by area*).

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        top, left: the rectangle's first row and column, non-negative integers or ``(B,)``.
        height, width: its size in pixels (a rectangle past the border stops there).

    Returns:
        Frames with the rectangle zeroed; dtype kept.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - top, left, height, width: integers or ``(B,)``.

    Example:
        >>> frames = torch.ones(1, 2, 3, 4)
        >>> drop_by_area(frames, 1, 1, 2, 2)[0, 0].tolist()
        [[1.0, 1.0, 1.0, 1.0], [1.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0]]
    """
    batch, b, restore = batch_of(inputs)
    box = check_args("drop_by_area", DROP_BY_AREA_SPEC, b, top=top, left=left, height=height, width=width)
    return restore(call_kernel(drop_by_area, batch, box["top"], box["left"], box["height"], box["width"]))


@register_kernel(drop_by_area, Tensor)
def drop_by_area_frames(batch: Tensor, top: Tensor, left: Tensor, height: Tensor, width: Tensor) -> Tensor:
    """Kernel of :func:`drop_by_area` for frames ``(B, T, 2, H, W)`` with (B,) int64 CPU rectangles.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        top: the rectangle's first row and column, non-negative integers or ``(B,)``.
        left: the rectangle's first row and column, non-negative integers or ``(B,)``.
        height: its size in pixels (a rectangle past the border stops there).
        width: its size in pixels (a rectangle past the border stops there).

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`drop_by_area` gives for a batch.
    """
    b, _, _, h, w = batch.shape
    rows = _window_mask(top, height, h, batch.device)
    cols = _window_mask(left, width, w, batch.device)
    mask = (rows.unsqueeze(2) & cols.unsqueeze(1)).view(b, 1, 1, h, w)
    return batch.masked_fill(mask, 0)


@register_kernel(drop_by_area, EventBatch)
def drop_by_area_events(batch: EventBatch, top: Tensor, left: Tensor, height: Tensor, width: Tensor) -> EventBatch:
    """Kernel of :func:`drop_by_area` for an EventBatch: sample b's events in the sensor
    rectangle dropped. One host read of the kept counts.

    Args:
        batch: the event streams.
        top, left: ``(B,)`` the rectangle's first row and column.
        height, width: ``(B,)`` its size in pixels.

    Shape:
        - batch: B streams, N events.
        - top, left, height, width: ``(B,)``.
        - output: B streams, at most N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> one = torch.tensor([1, 1])
        >>> drop_by_area_events(batch, one * 0, one * 0, one, one * 3).y.tolist()  # row 0 emptied
        [1, 1]
    """
    top, left, height, width = (_per_event(v.to(torch.int64), batch) for v in (top, left, height, width))
    y, x = batch.y.to(torch.int64), batch.x.to(torch.int64)
    hit = (y >= top) & (y < top + height) & (x >= left) & (x < left + width)
    return _compact(batch, ~hit)


# --------------------------------------------------------------------------- pixels

_PIXEL_MASK = 1  # the purpose of the pixel draw


def drop_pixel(inputs: Tensor | EventBatch, pixels: Tensor | Sequence[Sequence[int]]) -> Tensor | EventBatch:
    """Remove every event of the given pixels, in all frames and both polarities.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch
            (pixels of its sensor).
        pixels: ``(N, 2)`` integer ``(y, x)`` coordinates (every sample), or a bool mask
            ``(H, W)`` (every sample) or ``(B, H, W)`` (per sample), e.g. from
            :func:`hot_pixels`.

    Returns:
        The frames with those pixels zeroed; dtype and device kept.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - pixels: ``(N, 2)`` integers, or a bool ``(H, W)`` or ``(B, H, W)`` mask.

    Example:
        >>> drop_pixel(torch.ones(1, 2, 2, 3, dtype=torch.uint8), [[0, 1], [1, 2]])[0, 0].tolist()
        [[1, 0, 1], [1, 1, 0]]
    """
    batch, b, restore = batch_of(inputs)
    height, width = batch.sensor_size if isinstance(batch, EventBatch) else batch.shape[-2:]
    return restore(call_kernel(drop_pixel, batch, pixel_mask(pixels, b, height, width, batch.device)))


@register_kernel(drop_pixel, Tensor)
def drop_pixel_frames(batch: Tensor, mask: Tensor) -> Tensor:
    """Kernel of :func:`drop_pixel`: zero the (B or 1, H, W) bool ``mask`` pixels in every frame.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        mask: bool ``(B, H, W)`` or ``(1, H, W)``: the pixels whose events go.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`drop_pixel` gives for a batch.
    """
    return batch.masked_fill(mask.unsqueeze(1).unsqueeze(1), 0)


@register_kernel(drop_pixel, EventBatch)
def drop_pixel_events(batch: EventBatch, mask: Tensor) -> EventBatch:
    """Kernel of :func:`drop_pixel`: drop the events of stream b on a pixel where ``mask[b]`` holds.

    ``mask`` is ``(B, H, W)`` or ``(1, H, W)`` bool in sensor pixels (``batch.sensor_size``).
    Events outside the sensor (moved off it by an earlier transform) are kept: binning drops
    them. One host read of the kept counts.


    Args:
        batch: the event streams.
        mask: bool, ``True`` on the pixels whose events go: ``(B, H, W)`` per stream or
            ``(1, H, W)`` for all.

    Shape:
        - batch: B streams, N events.
        - mask: ``(B, H, W)`` or ``(1, H, W)``, the sensor's size.
        - output: B streams, at most N events.
    Example:
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 5, 1], [1, 0, 6, 0]])], sensor_size=(2, 2))
        >>> mask = torch.tensor([[[False, True], [False, False]]])  # pixel (y=0, x=1)
        >>> drop_pixel_events(batch, mask).x.tolist()
        [0]
    """
    height, width = batch.sensor_size
    if batch.num_events == 0:
        return batch
    x, y = batch.x.to(torch.int64), batch.y.to(torch.int64)
    inside = (x >= 0) & (x < width) & (y >= 0) & (y < height)
    pixel = y.clamp(0, height - 1) * width + x.clamp(0, width - 1)
    mask = mask.to(batch.device).reshape(-1, height * width)
    if mask.shape[0] == 1:
        dropped = mask[0].index_select(0, pixel)
    else:
        dropped = mask.reshape(-1).index_select(0, batch.sample_index().to(torch.int64) * (height * width) + pixel)
    return _compact(batch, ~(dropped & inside))


def random_pixel_mask(seed: Tensor, fraction: Tensor, height: int, width: int, device: torch.device) -> Tensor:
    """(B, H, W) bool: each pixel dropped with probability ``fraction[b]``, from ``seed[b]`` alone.

    A counter-based draw (:mod:`._random`): a pixel's uniform number is a hash of the
    sample's 63-bit seed and the pixel's index, so a sample's mask depends on its own seed only (a batch gives
    what its samples give alone) and is the same on the CPU and on CUDA.

    Args:
        seed: ``(B,)`` int64 seeds (CPU).
        fraction: ``(B,)`` drop probabilities in [0, 1] (CPU).
        height, width: the frame size.
        device: where the mask is built.

    Shape:
        - seed, fraction: ``(B,)``.
        - output: bool ``(B, height, width)`` on ``device``.

    Example:
        >>> mask = random_pixel_mask(torch.tensor([1, 2]), torch.tensor([0.5, 0.0]), 3, 4, torch.device("cpu"))
        >>> mask.shape, mask[1].any().item()  # nothing dropped at fraction 0
        (torch.Size([2, 3, 4]), False)
        >>> alone = random_pixel_mask(torch.tensor([1]), torch.tensor([0.5]), 3, 4, torch.device("cpu"))
        >>> torch.equal(mask[:1], alone)  # a sample's mask depends on its own seed only
        True
    """
    pixel = torch.arange(height * width, dtype=torch.int32, device=device)
    u = uniform(sample_salts(seed, device).unsqueeze(1), pixel, _PIXEL_MASK)  # (B, H*W) in (0, 1)
    return (u < fraction.to(device, torch.float64, non_blocking=True).unsqueeze(1)).view(-1, height, width)


# --------------------------------------------------------------------------- refractory period and decimation (events only)


def refractory_period(batch: EventBatch, period_us: Scalars) -> EventBatch:
    """Drop events that follow an event of the same pixel within ``period_us`` (events only).

    The dead time restarts with every event a pixel saw (kept or not), and either
    polarity counts; the first event of a pixel is kept. One host read of the kept counts.

    Args:
        batch: an EventBatch.
        period_us: the refractory period in µs (>= 0), a number or ``(B,)``.

    Shape:
        - batch: an EventBatch of B streams with N events.
        - output: an EventBatch of the same B streams, sensor and grid, at most N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> rows = torch.tensor([[1, 1, 0, 1], [1, 1, 500, 0], [1, 1, 2000, 1], [0, 0, 100, 1]])
        >>> refractory_period(EventBatch.from_streams([rows], sensor_size=(2, 2)), 1000.0).t.tolist()
        [0, 2000, 100]
    """
    kernel = kernel_for(refractory_period, batch)
    return kernel(batch, check_args("refractory_period", REFRACTORY_PERIOD_SPEC, len(batch), period_us=period_us)["period_us"])


def decimation(batch: EventBatch, n: int | Sequence[int] | Tensor) -> EventBatch:
    """Keep every ``n``-th event of each pixel (the n-th, 2n-th, ... in time), as tonic's ``Decimation``.

    Events only. One host read of the kept counts.

    Args:
        batch: an EventBatch.
        n: keep one event in n (>= 1), an integer or ``(B,)``.

    Shape:
        - batch: an EventBatch of B streams with N events.
        - output: an EventBatch of the same B streams, sensor and grid, at most N events.

    Example:
        >>> from event_transforms import EventBatch
        >>> rows = torch.tensor([[0, 0, t, 1] for t in range(6)])
        >>> decimation(EventBatch.from_streams([rows], sensor_size=(1, 1)), 3).t.tolist()
        [2, 5]
    """
    kernel = kernel_for(decimation, batch)
    return kernel(batch, check_args("decimation", DECIMATION_SPEC, len(batch), n=n)["n"])


def _pixel_runs(batch: EventBatch) -> tuple[Tensor, Tensor, Tensor]:
    """Events ordered by (sample, pixel, time): the order, each ordered event's pixel key,
    and its rank inside its pixel's run (two stable sorts)."""
    sample = batch.sample_index().to(torch.int64)
    key = ((sample << 16) + batch.y.to(torch.int64) + 2**15 << 16) + batch.x.to(torch.int64) + 2**15  # any int16 pixel
    order = torch.argsort(batch.t, stable=True)
    order = order.index_select(0, torch.argsort(key.index_select(0, order), stable=True))
    sorted_key = key.index_select(0, order)
    start = torch.ones_like(sorted_key, dtype=torch.bool)
    start[1:] = sorted_key[1:] != sorted_key[:-1]
    position = torch.arange(order.shape[0], device=order.device)
    run_start = torch.cummax(torch.where(start, position, 0), 0).values
    return order, start, position - run_start


@register_kernel(refractory_period, EventBatch)
def refractory_period_events(batch: EventBatch, period_us: Tensor) -> EventBatch:
    """Drop an event when its pixel (either polarity) had an event less than ``period_us[b]``
    before it (the previous event, kept or not: a pixel's dead time restarts with every
    event it saw). The first event of each pixel is kept. Output in (time) order of the
    input. One host read of the kept counts.

    Args:
        batch: the event streams.
        period_us: ``(B,)`` dead time of a pixel in microseconds.

    Shape:
        - batch: B streams, N events.
        - period_us: ``(B,)``.
        - output: B streams, at most N events, in input order.

    Example:
        >>> from event_transforms import EventBatch
        >>> events = torch.tensor([[0, 0, 0, 1], [0, 0, 400, 0], [0, 0, 1_000, 1], [1, 0, 10, 1]])
        >>> batch = EventBatch.from_streams([events], sensor_size=(1, 2))
        >>> refractory_period_events(batch, torch.tensor([500.0])).t.tolist()  # 400 follows 0 too soon
        [0, 1000, 10]
    """
    if batch.num_events == 0:
        return batch
    order, start, _ = _pixel_runs(batch)
    t = batch.t.index_select(0, order).to(torch.float64)
    gap = torch.empty_like(t)
    gap[0] = math.inf
    gap[1:] = t[1:] - t[:-1]
    period = _per_event(period_us.to(torch.float64), batch).index_select(0, order)
    keep_sorted = start | (gap >= period)
    keep = torch.empty_like(keep_sorted).index_put_((order,), keep_sorted)
    return _compact(batch, keep)


@register_kernel(decimation, EventBatch)
def decimation_events(batch: EventBatch, n: Tensor) -> EventBatch:
    """Keep every ``n[b]``-th event of each pixel (the n-th, 2n-th, ... in time), as tonic's
    ``Decimation``. One host read of the kept counts.

    Args:
        batch: the event streams.
        n: ``(B,)`` positive integers: keep each pixel's n-th, 2n-th, ... event.

    Shape:
        - batch: B streams, N events.
        - n: ``(B,)``.
        - output: B streams, at most N events, in input order.

    Example:
        >>> from event_transforms import EventBatch
        >>> events = torch.tensor([[0, 0, 0, 1], [0, 0, 400, 0], [0, 0, 1_000, 1], [1, 0, 10, 1]])
        >>> batch = EventBatch.from_streams([events], sensor_size=(1, 2))
        >>> decimation_events(batch, torch.tensor([2])).t.tolist()  # pixel x = 0: its 2nd event
        [400]
    """
    if batch.num_events == 0:
        return batch
    order, _, rank = _pixel_runs(batch)
    every = _per_event(n.to(torch.int64), batch).index_select(0, order)
    keep_sorted = (rank + 1) % every == 0
    keep = torch.empty_like(keep_sorted).index_put_((order,), keep_sorted)
    return _compact(batch, keep)
