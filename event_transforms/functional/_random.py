"""Counter-based random streams, one per sample: the randomness of every kernel.

A kernel that draws numbers of its own (temporal event shifting, event drop, Poisson
noise) gets one 63-bit seed per sample (``params["seed"]`` of its module). Each random
number is a hash of that seed and a *counter* that names the number within the sample
(the position of an event in the sample's frames, a slot of a row, ...), plus the
*purpose* (which draw of the kernel it is). So a sample's numbers depend on its own
seed and its own data only, never on which samples share its batch or where it sits in
it: ``module(x[i:i+1], params=slice(tree, i))`` equals ``module(x, params=tree)[i]``
exactly, on any device, with no host synchronisation and no per-sample loop.

The hash works on int32 lanes (wrapping multiplication, logical shifts by masking),
which costs about 1.5x ``torch.rand`` per number on one CPU thread (int64 lanes with
32-bit masks cost 8x). Uniforms have 32 random bits (:func:`uniform`) or 53 (:func:`uniform53`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import torch
from torch import Tensor

if TYPE_CHECKING:  # the batch imports functional; a runtime import here would be a cycle
    from ..events.batch import EventBatch

__all__ = [
    "sample_salts", "uniform", "uniform53", "entry_keys", "sub_uniform", "sub_uniform32", "sub_normal_pair", "draw_seeds", "generator_for",
    "EventStream", "poisson_counts",
]

_MULTIPLIER = 0x45D9F3B  # the 32-bit integer mix of Thomas Mueller's hash
_GOLDEN = 0x9E3779B9 - 2**32  # as a signed int32


def _mix(x: Tensor) -> Tensor:
    """A bijective 32-bit mix of int32 ``x`` (wrapping products, logical shifts)."""
    x = x ^ ((x >> 16) & 0xFFFF)
    x = x * _MULTIPLIER
    x = x ^ ((x >> 16) & 0xFFFF)
    x = x * _MULTIPLIER
    return x ^ ((x >> 16) & 0xFFFF)


def _int32(value: int) -> int:
    value &= 0xFFFFFFFF
    return value - 2**32 if value >= 2**31 else value


def sample_salts(seed: Tensor, device: torch.device | str) -> Tensor:
    """(B,) int32 salts on ``device`` from (B,) int64 seeds: the key of each sample's stream.

    Tensor ops on the device (the seeds are copied without waiting); no host read.
    """
    seed = seed.to(device=device, dtype=torch.int64, non_blocking=True)
    low = (seed & 0xFFFFFFFF).to(torch.int32)
    high = ((seed >> 32) & 0xFFFFFFFF).to(torch.int32)
    return _mix(_mix(low ^ _GOLDEN) ^ high)


def _hash(salt: Tensor, counter: Tensor, purpose: int) -> Tensor:
    low = counter.to(torch.int32) if counter.dtype != torch.int32 else counter
    x = _mix(low ^ salt)
    if counter.dtype == torch.int64:
        high = (counter >> 32).to(torch.int32)
        x = x ^ high
    return _mix(x ^ _int32(purpose * 0x27D4EB2F + 0x165667B1))


def uniform(salt: Tensor, counter: Tensor, purpose: int) -> Tensor:
    """float64 uniforms in (0, 1) with 32 random bits: a hash of (salt, counter, purpose).

    Args:
        salt: int32 salts, broadcast against ``counter`` (a sample's salt per element).
        counter: int32 or int64 counters naming each number within its sample.
        purpose: a small integer naming the draw (different purposes are independent).

    Example:
        >>> salt = sample_salts(torch.tensor([7, 8]), "cpu")
        >>> u = uniform(salt.view(2, 1), torch.arange(3).view(1, 3), purpose=1)
        >>> u.shape, bool(((u > 0) & (u < 1)).all())
        (torch.Size([2, 3]), True)
        >>> torch.equal(u[1], uniform(salt[1:], torch.arange(3), purpose=1))  # a sample alone
        True
    """
    return (_hash(salt, counter, purpose).to(torch.float64) + (2**31 + 0.5)) * 2.0**-32


def uniform53(salt: Tensor, counter: Tensor, purpose: int) -> Tensor:
    """float64 uniforms in [0, 1) with 53 random bits (the hash, then one more mix)."""
    return _to53(_hash(salt, counter, purpose))


def _to53(first: Tensor) -> Tensor:
    second = _mix(first ^ _GOLDEN)
    high = first.to(torch.int64) & 0xFFFFFFFF
    low = second.to(torch.int64) & 0xFFFFFFFF
    return ((high >> 6) * 2**27 + (low >> 5)).to(torch.float64) * 2.0**-53


def entry_keys(salt: Tensor, counter: Tensor) -> Tensor:
    """int32 keys of entries (a hash of salt and counter), for :func:`sub_uniform`: the
    numbers of an entry's sub-items (its events) then cost one gather and one mix each."""
    return _hash(salt, counter, 0)


def sub_uniform(keys: Tensor, within: Tensor, purpose: int, *, bits: int = 32) -> Tensor:
    """Uniforms of sub-item ``within`` (int64) of the entries whose :func:`entry_keys` are
    ``keys`` (gathered per sub-item), for ``purpose``; 32 or 53 random bits."""
    x = _sub_hash(keys, within, purpose)
    if bits == 53:
        return _to53(x)
    return (x.to(torch.float64) + (2**31 + 0.5)) * 2.0**-32


def _sub_hash(keys: Tensor, within: Tensor, purpose: int) -> Tensor:
    return _mix(keys ^ (within.to(torch.int32) * 0x61C88647 + _int32(purpose * 0x27D4EB2F + 0x165667B1)))


def sub_uniform32(keys: Tensor, within: Tensor, purpose: int) -> Tensor:
    """float32 uniforms in (0, 1) with 23 random bits (``(k + 1/2) 2**-23``, exact in
    float32, so never 0 or 1): the keys that event drop and TES compare and rank."""
    x = (_sub_hash(keys, within, purpose) >> 9) & 0x7FFFFF
    return x.to(torch.float32).add_(0.5).mul_(2.0**-23)


def sub_normal_pair(keys: Tensor, within: Tensor, purpose: int) -> tuple[Tensor, Tensor]:
    """Two independent float32 standard normals of sub-item ``within``: Box-Muller (``r cos θ``,
    ``r sin θ``) on the 23-bit uniforms of purposes ``2 purpose + 1`` (radius) and
    ``2 purpose + 2`` (angle): every use of a purpose owns two. float32, as ``torch.normal_``
    draws for float32 (tails to about 5.8 sigma)."""
    radius = sub_uniform32(keys, within, 2 * purpose + 1).log_().mul_(-2.0).sqrt_()
    angle = sub_uniform32(keys, within, 2 * purpose + 2).mul_(2 * math.pi)
    return radius * angle.cos(), radius.mul_(angle.sin_())


class EventStream:
    """The counter-based streams of an event batch: each event named by its sample's seed
    and its position within its sample (0, 1, ... in the sample's stored order).

    Two run fills per event (the sample's key and its first event) and one mix per number,
    whatever B: no per-sample generator, no loop over samples, the same numbers on every
    device (int32 lane arithmetic, wrapping products), and a sample's numbers are the same
    alone as in any batch.

    Args:
        seeds: (B,) int64 per-sample seeds (any device; copied without waiting).
        lengths: (B,) the number of events of each sample (CPU; samples are contiguous runs).
        device: where the events are.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.zeros(3, 4), torch.zeros(2, 4)], sensor_size=(2, 2))
        >>> stream = EventStream.of_batch(batch, torch.tensor([5, 9]))
        >>> alone = EventStream.of_batch(batch[1:], torch.tensor([9]))
        >>> torch.equal(stream.uniform(0)[3:], alone.uniform(0))
        True
    """

    def __init__(self, seeds: Tensor, lengths: Tensor, device: torch.device | str) -> None:
        lengths = lengths.to(torch.int64).cpu()
        total = sum(lengths.tolist())  # CPU lengths: no device read
        index = torch.int32 if total < 2**31 else torch.int64
        first = (lengths.cumsum(0) - lengths).to(device=device, dtype=index, non_blocking=True)
        on_device = lengths.to(device, non_blocking=True)
        keys = entry_keys(sample_salts(seeds, device), torch.zeros(1, dtype=torch.int64, device=device))
        # repeat_interleave fills runs (no per-event gather): each event's sample key and first event
        self.event_keys = torch.repeat_interleave(keys, on_device, output_size=total)
        self.within = torch.arange(total, dtype=index, device=device).sub_(
            torch.repeat_interleave(first, on_device, output_size=total))

    @classmethod
    def of_batch(cls, batch: EventBatch, seeds: Tensor) -> EventStream:
        """The streams of an :class:`~event_transforms.EventBatch`'s events."""
        return cls(seeds, batch.offsets.diff(), batch.device)

    def uniform(self, purpose: int) -> Tensor:
        """(N,) float64 uniforms in (0, 1), 32 random bits, one per event for ``purpose``."""
        return sub_uniform(self.event_keys, self.within, purpose)

    def uniform32(self, purpose: int) -> Tensor:
        """(N,) float32 uniforms in (0, 1), 23 random bits (see :func:`sub_uniform32`)."""
        return sub_uniform32(self.event_keys, self.within, purpose)

    def normal_pair(self, purpose: int) -> tuple[Tensor, Tensor]:
        """Two (N,) float32 standard normals per event for ``purpose`` (:func:`sub_normal_pair`)."""
        return sub_normal_pair(self.event_keys, self.within, purpose)

    def normal(self, purpose: int) -> Tensor:
        """(N,) float32 standard normals, one per event for ``purpose`` (the first of the pair)."""
        return self.normal_pair(purpose)[0]


#: :func:`poisson_counts` searches 64**_POISSON_LEVELS counts above each sample's window start.
_POISSON_LEVELS = 4


def poisson_counts(seeds: Tensor, lam: Tensor, purpose: int) -> Tensor:
    """(B,) int64 Poisson(``lam[b]``) counts, one per sample, by inversion of the CDF at a
    counter-based uniform of the sample's seed (named ``purpose``), on ``lam``'s device.

    Exact inversion of ``P(N <= k) = Q(k + 1, λ)`` (the regularised upper incomplete gamma):
    the smallest k with ``P(N <= k) >= u``, searched above ``λ - 10 sqrt(λ) - 10`` (the mass
    below is under 1e-20, far below the 2**-32 resolution of u) in four rounds of 64 CDF
    evaluations per sample, each narrowing the range 64-fold (64**4 counts: λ up to about
    10**11). A fixed 40-odd ops whatever B and λ; on the CPU (the module path's
    parameters) the sizes they decide need no device read.

    Args:
        seeds: (B,) int64 seeds.
        lam: (B,) float64 means >= 0.

    Example:
        >>> counts = poisson_counts(torch.arange(2000), torch.full((2000,), 3.0), purpose=1)
        >>> round(counts.double().mean().item(), 1), round(counts.double().var().item(), 1)
        (3.0, 3.0)
    """
    device = lam.device
    lam = lam.to(torch.float64)
    if lam.numel() == 0:
        return torch.zeros(0, dtype=torch.int64, device=device)
    u = uniform(sample_salts(seeds, device), torch.zeros_like(lam, dtype=torch.int64), purpose).unsqueeze(1)
    spread = lam.sqrt().mul_(10.0)
    if max(spread.tolist()) * 2 + 50 > 64**_POISSON_LEVELS:
        raise ValueError(f"Poisson means above about 1e11 events are not supported, got {max(lam.tolist()):g}")
    # the answer lies in (low, low + 64**levels]; each round keeps the 64th holding it
    low = (lam - spread - 11.0).floor_().clamp_min_(-1.0).unsqueeze(1)
    lam = lam.unsqueeze(1)
    steps = torch.arange(1, 65, dtype=torch.float64, device=device)
    for level in reversed(range(_POISSON_LEVELS)):
        step = float(64**level)
        below = torch.special.gammaincc(low + steps * step + 1.0, lam) < u  # P(N <= k) < u, first c of 64
        low = low + below.sum(1, keepdim=True) * step
    return low.squeeze(1).to(torch.int64) + 1


def draw_seeds(batch: int, generator: torch.Generator | None) -> Tensor:
    """(B,) int64 seeds for the functional kernels' ``generator=`` argument.

    Drawn on the generator's device (torch's global CPU RNG for ``None``) and left there:
    :func:`sample_salts` reads them with tensor ops, so no host synchronisation.
    """
    device = "cpu" if generator is None else generator.device
    return torch.randint(0, 2**63 - 1, (batch,), generator=generator, device=device, dtype=torch.int64)


def generator_for(seed: int, purpose: int, device: torch.device | str) -> torch.Generator:
    """A ``torch.Generator`` on ``device`` for one sample's draw that has no counter-based
    form (``torch.binomial`` of counts above the expansion limit), from a host seed."""
    value = (int(seed) * 0x9E3779B97F4A7C15 + purpose * 0xBF58476D1CE4E5B9) % 2**64
    value ^= value >> 31
    generator = torch.Generator(device=device)
    generator.manual_seed(value & (2**63 - 1))
    return generator
