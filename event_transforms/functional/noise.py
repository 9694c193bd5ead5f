"""Event-level noise kernels: adding static-scene or Poisson background events.

Adding keeps the frames' dtype (integer counts stay integer; an integer result that would
not fit the dtype raises instead of wrapping). Dropping events (EventDrop) is in
:mod:`event_transforms.functional.drop`.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from ._random import draw_seeds, entry_keys, generator_for, sample_salts, sub_uniform
from .._validation import (
    as_batch,
    check_counts,
    check_frames,
    check_generator,
    check_positive,
    describe,
    per_sample,
    read_host,
)

__all__ = ["add_noise", "add_poisson_noise"]

_SMALL_INTEGERS = (torch.uint8, torch.int8, torch.int16, torch.int32)
Scalars = float | Sequence[float] | Tensor


def _add_counts(frames: Tensor, counts: Tensor, name: str) -> Tensor:
    """``frames + counts`` in the frames' dtype; raises if an integer dtype would overflow."""
    if frames.dtype in _SMALL_INTEGERS and frames.numel():
        limit = torch.iinfo(frames.dtype).max
        high = (frames.to(torch.int64) + counts.to(torch.int64)).max()
        if bool(high > limit):
            raise ValueError(
                f"adding {name} overflows {frames.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    return frames + counts.to(frames.dtype)


def _add_entries(frames: Tensor, target: Tensor, values: Tensor, name: str) -> Tensor:
    """A copy of ``frames`` with ``values`` added at the distinct flat positions ``target``.

    Integer dtypes narrower than int64 are checked for overflow first (one host
    synchronisation, for those dtypes only); float dtypes need none.
    """
    out = frames.clone(memory_format=torch.contiguous_format)
    flat = out.view(-1)
    if frames.dtype in _SMALL_INTEGERS and target.numel():
        limit = torch.iinfo(frames.dtype).max
        high = (flat.index_select(0, target).to(torch.int64) + values.to(torch.int64)).max()
        if bool(high > limit):
            raise ValueError(
                f"adding {name} overflows {frames.dtype}: a pixel would hold {int(high)} > {limit}; "
                "use a wider dtype"
            )
    return flat.index_add_(0, target, values.to(out.dtype)).view(frames.shape)


def _add_events(batch: Tensor, flat_index: Tensor) -> Tensor:
    """Add one event at each flat position (repeats accumulate): O(events) beyond a clone.

    No host synchronisation for float and int64 frames; narrower integer dtypes are
    checked for overflow (``unique`` and one read).
    """
    out = batch.clone(memory_format=torch.contiguous_format)
    flat = out.view(-1)
    if batch.dtype in _SMALL_INTEGERS and flat_index.numel():
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


def add_noise(frames: Tensor, noise: Tensor) -> Tensor:
    """Add noise frames (e.g. recorded from a static scene) to event frames.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        noise: non-negative counts of the same shape, or ``(T, 2, H, W)`` added to every
            sample of a batch. For integer ``frames`` the noise must be integer-valued.

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
    check_frames(frames)
    check_frames(noise, "noise")
    if noise.shape != frames.shape and noise.shape != frames.shape[-4:]:
        raise ValueError(
            f"noise must have the frames' shape {tuple(frames.shape)} or {tuple(frames.shape[-4:])}, "
            f"got {tuple(noise.shape)}"
        )
    hint = None if frames.is_floating_point() else "integer frames need whole noise counts"
    check_counts(noise, "noise", whole=hint)
    return _add_counts(frames, noise.to(frames.device), "noise")


def add_poisson_noise(
    frames: Tensor,
    rate_hz: Scalars,
    *,
    frame_ms: float = 10.0,
    generator: torch.Generator | None = None,
) -> Tensor:
    """Add background activity: independent Poisson counts per pixel, polarity and frame.

    Each pixel and polarity fires at ``rate_hz`` (per sample), so a frame of
    ``frame_ms`` milliseconds receives Poisson(λ) events with λ = rate_hz · frame_ms / 1000.
    For sparse noise (λ < 1, the usual 0.1–10 Hz) the total per sample is drawn from
    Poisson(λ·n) and its events placed uniformly at random among the n cells; this is
    exactly independent Poisson(λ) per cell (Poissonisation) and costs O(events), not
    O(n). Denser noise draws every cell with ``torch.poisson``.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
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
    batch, unbatch = as_batch(check_frames(frames))
    frame_ms = check_positive(frame_ms, "frame_ms")
    check_generator(generator, frames.device)
    rate = per_sample(rate_hz, batch.shape[0], "rate_hz")
    if rate.numel() and not bool((rate.isfinite() & (rate >= 0)).all()):
        raise ValueError(f"rate_hz must be finite and >= 0, got {describe(rate_hz)}")
    lam = rate * (frame_ms / 1000.0)
    totals = None
    if lam.numel() and max(lam.tolist()) < 1.0:  # sparse: totals first (an accelerator generator draws there)
        device = "cpu" if generator is None else generator.device
        totals = torch.poisson((lam * batch[0].numel()).to(device), generator=generator).long().cpu()
    return unbatch(_add_poisson_noise(batch, lam, totals=totals, seeds=draw_seeds(batch.shape[0], generator)))


def _poisson_totals(lam: Tensor, shape: torch.Size, generator: torch.Generator | None) -> Tensor | None:
    """Per-sample totals Poisson(λ·cells) (int64 CPU) for sparse noise, or ``None`` if dense.

    ``lam`` is the (B,) mean count per cell (CPU float64). Below one event per cell the noise
    is placed event by event (the totals, then uniform positions); otherwise cell by cell.
    """
    if lam.numel() == 0 or max(lam.tolist()) >= 1.0:
        return None
    cells = float(torch.Size(shape[1:]).numel())
    return torch.poisson(lam * cells, generator=generator).to(torch.int64)


def _add_poisson_noise(batch: Tensor, lam: Tensor, *, totals: Tensor | None = None, seeds: Tensor) -> Tensor:
    """Add Poisson(λ_b) counts per cell to a (B, T, 2, H, W) batch; ``lam`` (B,) CPU float64,
    ``seeds`` (B,) int64 per-sample seeds.

    With ``totals`` (B,) (CPU int64, from :func:`_poisson_totals`) the events are placed
    uniformly among the cells: exactly independent Poisson(λ) per cell (Poissonisation), in
    O(events) work and with no host synchronisation; event k of sample b lands in the cell
    named by a counter-based uniform of (seed b, k). Without, every cell is drawn with
    ``torch.poisson``, one call per sample with a generator seeded by that sample's seed.
    Either way a sample's noise depends on its own seed only, never on its batch.
    """
    if batch.numel() == 0:
        return batch.clone()
    device = batch.device
    cells = batch[0].numel()
    if totals is not None:
        count = sum(totals.tolist())  # a CPU tensor: read on the host
        sample = torch.repeat_interleave(
            torch.arange(batch.shape[0], device=device), totals.to(device), output_size=count
        )
        first = (totals.cumsum(0) - totals).to(device)
        within = torch.arange(count, device=device) - first.index_select(0, sample)
        keys = entry_keys(sample_salts(seeds, device), torch.zeros(1, dtype=torch.int64, device=device))
        position = (sub_uniform(keys.index_select(0, sample), within, 0, bits=53) * cells).to(torch.int64)
        position = position.clamp_max_(cells - 1)
        return _add_events(batch, sample * cells + position)
    rates = lam.to(dtype=torch.float64).tolist()
    host_seeds = seeds.tolist() if seeds.device.type == "cpu" else read_host(seeds)
    noise = torch.empty(batch.shape, dtype=torch.float64, device=device)
    for b, rate in enumerate(rates):
        generator = generator_for(host_seeds[b], 0, device)
        noise[b] = torch.poisson(torch.full(batch.shape[1:], rate, dtype=torch.float64, device=device), generator=generator)
    return _add_counts(batch, noise, "Poisson noise")


