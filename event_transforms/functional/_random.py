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
which costs about 1.5x ``torch.rand`` per number on one CPU thread; int64 lanes with
32-bit masks, as :func:`~event_transforms.functional.drop.random_pixel_mask` used, cost
8x. Uniforms have 32 random bits (:func:`uniform`) or 53 (:func:`uniform53`).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["sample_salts", "uniform", "uniform53", "entry_keys", "sub_uniform", "draw_seeds", "generator_for"]

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
    x = _mix(keys ^ (within.to(torch.int32) * 0x61C88647 + _int32(purpose * 0x27D4EB2F + 0x165667B1)))
    if bits == 53:
        return _to53(x)
    return (x.to(torch.float64) + (2**31 + 0.5)) * 2.0**-32


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
