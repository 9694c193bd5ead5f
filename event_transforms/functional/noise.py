"""Event-level noise kernels: adding static-scene or Poisson background events.

Adding keeps the frames' dtype (integer counts stay integer; an integer result that would
not fit the dtype raises instead of wrapping). Dropping events (EventDrop) is in
:mod:`event_transforms.functional.drop`.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from ._random import EventStream, draw_seeds, poisson_cells, poisson_counts, sample_keys, sub_uniform
from .._validation import (
    check_counts,
    check_frames,
    check_generator,
    check_positive,
    read_host,
)

from ..events.batch import EventBatch
from ._frame_ops import SMALL_INTEGERS
from ._dispatch import batch_of, call_kernel, register_kernel
from .._params import Param, check_args
from ._event_ops import POISSON_COUNT, POISSON_P, POISSON_T, POISSON_X, POISSON_Y, _append, _require_grid

__all__ = [
    "add_noise", "add_noise_frames", "add_noise_events",
    "add_poisson_noise", "add_poisson_noise_frames", "add_poisson_noise_events",
]

Scalars = float | Sequence[float] | Tensor


#: Purpose of the dense per-cell Poisson draws (the sparse path's positions use purpose 0).
_POISSON_CELLS = 1


def _add_counts(frames: Tensor, counts: Tensor, name: str) -> Tensor:
    """``frames + counts`` in the frames' dtype; raises if an integer dtype would overflow."""
    if frames.dtype in SMALL_INTEGERS and frames.numel():
        limit = torch.iinfo(frames.dtype).max
        high = (frames.to(torch.int64) + counts.to(torch.int64)).max()
        if bool(high > limit):
            raise ValueError(
                f"adding {name} overflows {frames.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    return frames + counts.to(frames.dtype)


def _add_events(batch: Tensor, flat_index: Tensor) -> Tensor:
    """Add one event at each flat position (repeats accumulate): O(events) beyond a clone.

    No host synchronisation for float and int64 frames; narrower integer dtypes are
    checked for overflow (``unique`` and one read).
    """
    out = batch.clone(memory_format=torch.contiguous_format)
    flat = out.view(-1)
    if batch.dtype in SMALL_INTEGERS and flat_index.numel():
        cell, added = torch.unique(flat_index, return_counts=True)
        high = (flat.index_select(0, cell).to(torch.int64) + added).max()
        limit = torch.iinfo(batch.dtype).max
        if bool(high > limit):
            raise ValueError(
                f"adding Poisson noise overflows {batch.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    ones = torch.ones((), dtype=out.dtype, device=out.device).expand(flat_index.shape)
    return flat.index_add_(0, flat_index, ones).view(batch.shape)


def add_noise(inputs: Tensor | EventBatch, noise: Tensor) -> Tensor | EventBatch:
    """Add noise frames (e.g. recorded from a static scene) to event frames.

    On an EventBatch (:func:`add_noise_events`) the noise counts are added as events at
    the centres of their bins on the batch's grid, so binning gives the frames plus the noise.

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch with a
            frame grid.
        noise: non-negative counts of the same shape (for an EventBatch: ``(B, T, 2, H, W)``
            on its grid and sensor), or ``(T, 2, H, W)`` added to every sample of a batch.
            For integer ``frames`` (and for events) the noise must be integer-valued.

    Returns:
        ``frames + noise`` in the frames' dtype, on the frames' device.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - noise: the frames' shape, or ``(T, 2, H, W)`` for a batch.
        - output: the frames' shape, dtype and device.

    Example:
        >>> frames = torch.zeros(2, 2, 3, 4, dtype=torch.int16)
        >>> noise = torch.ones(2, 2, 3, 4, dtype=torch.int16)
        >>> out = add_noise(frames, noise)
        >>> out.dtype, int(out.sum())
        (torch.int16, 48)
    """
    batch, b, restore = batch_of(inputs)
    shape = batch.frame_shape if isinstance(batch, EventBatch) else check_frames(inputs).shape
    check_frames(noise, "noise")
    if noise.shape != shape and noise.shape != shape[-4:]:
        raise ValueError(
            f"noise must have the frames' shape {tuple(shape)} or {tuple(shape[-4:])}, got {tuple(noise.shape)}"
        )
    whole = isinstance(batch, EventBatch) or not batch.is_floating_point()
    check_counts(noise, "noise", whole="integer frames need whole noise counts" if whole else None)
    # the noise frames as a bank: sample i takes frames [i T, i T + T) (all samples [0, T) for one sequence)
    single = noise.dim() == 4 and len(shape) == 5
    bank = noise if noise.dim() == 4 else noise.reshape(-1, *noise.shape[-3:])
    offset = torch.arange(b, dtype=torch.int64) * (0 if single else shape[-4])
    return restore(call_kernel(add_noise, batch, bank, offset))


@register_kernel(add_noise, Tensor)
def add_noise_frames(batch: Tensor, bank: Tensor, offset: Tensor) -> Tensor:
    """Kernel of :func:`add_noise` for frames ``(B, T, 2, H, W)``: sample b gets frames
    ``offset[b] .. offset[b] + T`` of ``bank`` ``(N, 2, H, W)`` added (dense).

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        bank: ``(N, 2, H, W)`` noise frames.
        offset: ``(B,)`` the first bank frame of each sample's window.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`add_noise` gives for a batch.
    """
    b, t = batch.shape[:2]
    index = (offset.to(torch.int64).view(b, 1) + torch.arange(t)).reshape(-1)
    bank = bank.to(batch.device)
    noise = bank.index_select(0, index.to(batch.device)).view(b, t, *bank.shape[1:])
    return _add_counts(batch, noise, "noise")


@register_kernel(add_noise, EventBatch)
def add_noise_events(batch: EventBatch, bank: Tensor, offset: Tensor) -> EventBatch:
    """Kernel of :func:`add_noise` for an EventBatch: stream b gets frames ``offset[b] .. offset[b] + T``
    of ``bank`` ``(N, 2, H, W)`` (sensor-sized whole counts) as events, each at the centre of
    its bin on the batch's grid (a frame bank has no finer timing), so binning gives the
    stream's frames plus that window, as :class:`~event_transforms.AddNoise` does on frames.
    Deterministic; one ``nonzero`` over the streams' windows and one host read of the
    per-stream counts, the same ops whatever B.


    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        bank: ``(N, 2, H, W)`` whole counts of a static scene, the sensor's size.
        offset: ``(B,)`` the first bank frame of each stream's window.

    Shape:
        - batch: B streams, N events.
        - bank: ``(N, 2, H, W)``; offset: ``(B,)``.
        - output: B streams, N events plus the window's counts.
    Example:
        >>> batch = EventBatch.from_streams([torch.zeros(0, 4)], sensor_size=(1, 2), frame_ms=1.0,
        ...                                 t_start=0, n_frames=2)
        >>> bank = torch.zeros(3, 2, 1, 2)
        >>> bank[2, 1, 0, 1] = 2  # two ON events at x = 1 in the bank's third frame
        >>> out = add_noise_events(batch, bank, torch.tensor([1]))
        >>> out.x.tolist(), out.t.tolist(), out.p.tolist()
        ([1, 1], [1500, 1500], [1, 1])
    """
    starts, frame_us, n_frames = _require_grid(batch, "AddNoise")
    height, width = batch.sensor_size
    if tuple(bank.shape[-2:]) != (height, width):
        raise ValueError(
            f"bank: AddNoise on events needs a bank of the sensor's size (H, W) = ({height}, {width}), "
            f"got {tuple(bank.shape)}"
        )
    device = batch.device
    b, plane = len(batch), height * width
    if b == 0:
        return batch
    # every stream's window of the bank at once: one nonzero, one read of the per-stream counts
    rows = (offset.to(torch.int64).view(b, 1) + torch.arange(n_frames)).reshape(-1).to(device)
    counts = bank.to(device).index_select(0, rows).reshape(-1).to(torch.int64)
    entries = counts.nonzero().squeeze(1)  # the output size depends on the bank
    repeats = counts.index_select(0, entries)
    per_stream = n_frames * 2 * plane
    added = torch.zeros(b, dtype=torch.int64, device=device).index_add_(
        0, entries.div(per_stream, rounding_mode="floor"), repeats)
    added = torch.tensor(read_host(added), dtype=torch.int64)
    index = torch.repeat_interleave(entries, repeats, output_size=sum(added.tolist()))
    sample, rest = index.div(per_stream, rounding_mode="floor"), index.remainder(per_stream)
    frame, rest = rest.div(2 * plane, rounding_mode="floor"), rest.remainder(2 * plane)
    p, pixel = rest.div(plane, rounding_mode="floor"), rest.remainder(plane)
    t = starts.to(device).index_select(0, sample) + frame * frame_us + frame_us // 2
    columns = (pixel.remainder(width), pixel.div(width, rounding_mode="floor"), t, p)
    return _append(batch, columns, added)


#: :func:`add_poisson_noise`: the per-sample rate in Hz per pixel and polarity (finite, >= 0);
#: :class:`~event_transforms.AddPoissonNoise` adds its per-sample seed and sparse totals.
ADD_POISSON_NOISE_SPEC = {"rate_hz": Param("float", low=0.0)}


def add_poisson_noise(
    inputs: Tensor | EventBatch,
    rate_hz: Scalars,
    *,
    frame_ms: float = 10.0,
    generator: torch.Generator | None = None,
) -> Tensor | EventBatch:
    """Add background activity: independent Poisson counts per pixel, polarity and frame.

    Each pixel and polarity fires at ``rate_hz`` (per sample), so a frame of
    ``frame_ms`` milliseconds receives Poisson(λ) events with λ = rate_hz · frame_ms / 1000.
    For sparse noise (λ < 1, the usual 0.1–10 Hz) the total per sample is drawn from
    Poisson(λ·n) and its events placed uniformly at random among the n cells; this is
    exactly independent Poisson(λ) per cell (Poissonisation) and costs O(events), not
    O(n). Denser noise draws every cell by inverting the Poisson CDF at a counter-based
    uniform of the sample's seed and the cell. On an EventBatch
    (:func:`add_poisson_noise_events`) uniform events are added over the window of the
    batch's grid (whose bin width replaces ``frame_ms``).

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch with a grid.
        rate_hz: events per second per pixel and polarity (>= 0), a number or ``(B,)``.
        frame_ms: frame length in milliseconds (> 0).
        generator: a ``torch.Generator`` on the frames' device, or ``None``.

    Returns:
        Frames plus noise counts, in the frames' dtype.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - rate_hz: a number or ``(B,)``.

    Example:
        >>> frames = torch.zeros(36, 2, 70, 75)
        >>> out = add_poisson_noise(frames, 5.0, generator=torch.Generator().manual_seed(0))
        >>> int(out.sum())  # expected 5 Hz * 0.36 s * 2 * 70 * 75 = 18900
        18884
    """
    batch, b, restore = batch_of(inputs)
    frame_ms = check_positive(frame_ms, "frame_ms")
    check_generator(generator, batch.device)
    rate = check_args("add_poisson_noise", ADD_POISSON_NOISE_SPEC, b, rate_hz=rate_hz)["rate_hz"]
    lam = rate * (frame_ms / 1000.0)
    totals = None
    if isinstance(batch, Tensor) and lam.numel() and max(lam.tolist()) < 1.0:
        # sparse: totals first (an accelerator generator draws there)
        device = "cpu" if generator is None else generator.device
        totals = torch.poisson((lam * batch[0].numel()).to(device), generator=generator).long().cpu()
    seeds = draw_seeds(b, generator)
    return restore(call_kernel(add_poisson_noise, batch, rate, seeds, frame_ms=frame_ms, count=totals))


@register_kernel(add_poisson_noise, Tensor)
def add_poisson_noise_frames(
    batch: Tensor, rate_hz: Tensor, seeds: Tensor, *, frame_ms: float = 10.0, count: Tensor | None = None
) -> Tensor:
    """Kernel of :func:`add_poisson_noise` for frames ``(B, T, 2, H, W)``: ``rate_hz`` (B,)
    CPU float64, per-sample ``seeds``, and for sparse noise the totals ``count`` (B,).

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        rate_hz: events per second per pixel and polarity (>= 0), a number or ``(B,)``.
        seeds: ``(B,)`` int64 per-sample seeds of the counter-based streams.
        frame_ms: frame length in milliseconds (> 0).
        count: ``(B,)`` event totals drawn by the module, or ``None`` to draw them here.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`add_poisson_noise` gives for a batch.
    """
    return _add_poisson_noise(batch, rate_hz * (frame_ms / 1000.0), totals=count, seeds=seeds)


@register_kernel(add_poisson_noise, EventBatch)
def add_poisson_noise_events(
    batch: EventBatch, rate_hz: Tensor, seeds: Tensor, *, frame_ms: float = 10.0, count: Tensor | None = None
) -> EventBatch:
    """Kernel of :func:`add_poisson_noise` for an EventBatch: per pixel and polarity a Poisson
    process of ``rate_hz[b]`` over the grid's window (the grid's bin width replaces
    ``frame_ms``; ``count`` does not apply). Added events follow the sample's own events.

    Args:
        batch: the event streams, with a frame grid (``frame_ms``, ``n_frames``).
        rate_hz: ``(B,)`` events per second per pixel and polarity (>= 0).
        seeds: ``(B,)`` int64 per-sample seeds.
        frame_ms: ignored: the grid's bin width applies.
        count: ignored on events.

    Shape:
        - batch: B streams, N events.
        - rate_hz, seeds: ``(B,)``.
        - output: B streams, N events plus the noise.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> noisy = add_poisson_noise_events(batch, torch.tensor([0.0, 1000.0]), torch.tensor([1, 2]))
        >>> noisy.lengths[0], noisy.lengths[1] > 1  # 1000 Hz x 20 ms x 12 pixel-polarities: about 240
        (2, True)
    """
    return _poisson_events(batch, rate_hz, seeds)


def _add_poisson_noise(batch: Tensor, lam: Tensor, *, totals: Tensor | None = None, seeds: Tensor) -> Tensor:
    """Add Poisson(λ_b) counts per cell to a (B, T, 2, H, W) batch; ``lam`` (B,) CPU float64,
    ``seeds`` (B,) int64 per-sample seeds.

    With ``totals`` (B,) (CPU int64, from :func:`poisson_totals`) the events are placed
    uniformly among the cells: exactly independent Poisson(λ) per cell (Poissonisation), in
    O(events) work and with no host synchronisation; event k of sample b lands in the cell
    named by a counter-based uniform of (seed b, k). Without, every cell is drawn by
    inversion of the Poisson(λ_b) CDF at a counter-based uniform of (seed b, cell)
    (:func:`~._random.poisson_cells`), all samples in one vectorised call. Either way a sample's noise depends on its own seed only, never on its batch.
    """
    if batch.numel() == 0:
        return batch.clone()
    device = batch.device
    cells = batch[0].numel()
    if totals is not None:
        # event k of sample b: its sample's key and k by run fills (EventStream), no gather
        stream = EventStream(seeds, totals, device)
        count = stream.within.shape[0]
        position = (sub_uniform(stream.event_keys, stream.within, 0, bits=53) * cells).to(torch.int64)
        position = position.clamp_max_(cells - 1)
        first_cell = torch.arange(0, batch.shape[0] * cells, cells, device=device)
        return _add_events(batch, position.add_(torch.repeat_interleave(first_cell, stream.lengths, output_size=count)))
    keys = sample_keys(seeds, device)
    noise = poisson_cells(keys, lam, cells, _POISSON_CELLS).view(batch.shape)
    return _add_counts(batch, noise, "Poisson noise")


def _poisson_events(batch: EventBatch, rate_hz: Tensor, seed: Tensor) -> EventBatch:
    """Add background events: per pixel and polarity a Poisson process of ``rate_hz[b]``
    over the grid's window, i.e. Poisson(rate · T · frame · 2HW) events of uniform pixel,
    polarity and time. The counts are drawn on the host from the seeds
    (:func:`~._random.poisson_counts`: CPU parameters, so the sizes need no device read);
    the positions come from the sample's counter-based stream (the added event's position
    among the sample's added events). Added events follow the sample's own events (the
    stream is no longer time-sorted). Sync-free; the same ops whatever B."""
    starts, frame_us, n_frames = _require_grid(batch, "AddPoissonNoise")
    height, width = batch.sensor_size
    span = n_frames * frame_us
    counts = poisson_counts(seed.cpu(), rate_hz.to(torch.float64).cpu() * (span * 1e-6 * 2 * height * width), POISSON_COUNT)
    device = batch.device
    total = sum(counts.tolist())
    sample = torch.repeat_interleave(torch.arange(len(batch), device=device), counts.to(device), output_size=total)
    stream = EventStream(seed, counts, device)
    x = (stream.uniform(POISSON_X) * width).to(torch.int16)
    y = (stream.uniform(POISSON_Y) * height).to(torch.int16)
    t = (starts.to(device=device, dtype=torch.float64).index_select(0, sample) + stream.uniform(POISSON_T) * span).floor_()
    p = (stream.uniform(POISSON_P) < 0.5).to(torch.int8)
    return _append(batch, (x, y, t.to(batch.t.dtype), p), counts)
