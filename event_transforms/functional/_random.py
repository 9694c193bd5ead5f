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

import numpy as np
import torch
from torch import Tensor

from .._validation import read_host

if TYPE_CHECKING:  # the batch imports functional; a runtime import here would be a cycle
    from ..events.batch import EventBatch

__all__ = [
    "sample_salts", "uniform", "uniform53", "entry_keys", "sub_uniform", "sub_uniform32", "sub_normal_pair", "draw_seeds",
    "sample_keys", "EventStream", "poisson_counts", "binomial_large", "poisson_cells", "search_cumulative",
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
    """``(high >> 6) 2**-26 + (low >> 5) 2**-53`` of the unsigned 32-bit ``first`` and its
    next mix: int32 lanes (logical shifts by masking), then float64, where both terms and
    their sum are exact."""
    second = _mix(first ^ _GOLDEN)
    high = ((first >> 6) & 0x3FFFFFF).to(torch.float64)
    low = ((second >> 5) & 0x7FFFFFF).to(torch.float64)
    return high.mul_(2.0**27).add_(low).mul_(2.0**-53)


def _mix_host(x: np.ndarray) -> np.ndarray:
    """:func:`_mix` on numpy int32 lanes (the same wrapping products and logical shifts)."""
    multiplier = np.int32(_MULTIPLIER)
    x = x ^ ((x >> 16) & 0xFFFF)
    x = x * multiplier
    x = x ^ ((x >> 16) & 0xFFFF)
    x = x * multiplier
    return x ^ ((x >> 16) & 0xFFFF)


def sample_keys(seed: Tensor, device: torch.device | str) -> Tensor:
    """(B,) int32 keys of each sample's stream on ``device``: ``entry_keys(sample_salts(seed),
    0)``, the key :class:`EventStream` gives every event of a sample.

    CPU seeds (the usual case: drawn by a CPU generator) are hashed on the host in numpy
    int32 lanes, the same bits, and copied over once (no device op per step of the hash);
    seeds already on a device are hashed there with tensor ops (no host read).

    Example:
        >>> seeds = torch.tensor([7, 2**62 + 5])
        >>> zero = torch.zeros(1, dtype=torch.int64)
        >>> torch.equal(sample_keys(seeds, "cpu"), entry_keys(sample_salts(seeds, "cpu"), zero))
        True
    """
    if seed.device.type != "cpu" or torch.compiler.is_compiling():
        return entry_keys(sample_salts(seed, device), torch.zeros(1, dtype=torch.int64, device=device))
    values = seed.to(torch.int64).numpy()
    with np.errstate(over="ignore"):
        low = (values & 0xFFFFFFFF).astype(np.int32)
        high = ((values >> 32) & 0xFFFFFFFF).astype(np.int32)
        salt = _mix_host(_mix_host(low ^ np.int32(_GOLDEN)) ^ high)
        # entry_keys at counter 0: _hash(salt, 0, purpose 0)
        keys = _mix_host(_mix_host(salt) ^ np.int32(_int32(0x165667B1)))
    return torch.from_numpy(keys).to(device, non_blocking=True)


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
        self.lengths = on_device  #: (B,) the event counts on ``device``
        keys = sample_keys(seeds, device)
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


#: :func:`binomial_large` inverts the CDF when ``n min(p, 1 - p)`` is below this, else BTRS.
_INVERSION_MEAN = 10.0
#: CDF terms of the inversion (the mass above 63 of a binomial of mean < 10 is below 1e-25).
_INVERSION_TERMS = 64
#: BTRS candidates per entry and round (each accepted with probability above about 0.8, so
#: a second round is needed for about one entry in 10**11).
_BTRS_CANDIDATES = 16


def _stirling_tail(k: Tensor) -> Tensor:
    """``lgamma(k + 1) - ((k + 1/2) log(k + 1) - (k + 1) + log(2 pi) / 2)`` for float64 k >= 0:
    exact (lgamma) below 10, the Stirling series above (error below 1e-16 there)."""
    k1 = k + 1.0
    small = torch.lgamma(k1) - ((k + 0.5) * k1.log() - k1 + 0.5 * math.log(2 * math.pi))
    square = k1 * k1
    series = (1.0 / 12 - (1.0 / 360 - 1.0 / 1260 / square) / square) / k1
    return torch.where(k < 10, small, series)


def binomial_large(keys: Tensor, counts: Tensor, prob: Tensor, purpose: int, largest: int | None = None) -> Tensor:
    """Exact ``Binomial(counts[i], prob[i])`` draws, counter-based: one per entry, vectorised.

    Entry i's numbers are hashes of its key ``keys[i]`` (:func:`entry_keys` of its sample's
    salt and its position in the sample), ``purpose`` and a counter within the entry, so a
    draw depends on its own entry only (a sample alone equals the sample in any batch) and
    is the same on every device up to the last bits of float64 ``log``/``lgamma``. With
    ``p' = min(p, 1 - p)`` (the draw is mirrored, ``n - k``, when ``p > 1/2``):

    * ``n p' < 10``: inversion. The CDF of the first 64 values (the pmf by its ratio
      recurrence, summed in float64) is searched at one 53-bit uniform (purpose
      ``purpose``); the mass above is under 1e-25.
    * otherwise Hörmann's BTRS (transformed rejection with squeeze, 1993): 16 candidates
      per entry and round (uniforms of purposes ``purpose + 1``, ``purpose + 2``, counter
      ``16 round + candidate``), the first accepted one taken. Rounds run until every entry
      has one; a second round is needed about once in 10**11 entries.

    Host synchronisations: one flag read before each round ("does any entry still need
    BTRS?"): one in all when every entry is inverted (small means, as the event counts of
    pooled frames), two when BTRS runs one round. Ops do not depend on the number of entries.

    Args:
        keys: (m,) int32 entry keys.
        counts: (m,) integer counts ``n >= 0`` (exact in float64: below 2**53).
        prob: (m,) float64 probabilities in [0, 1].
        purpose: names the draw; ``purpose``, ``purpose + 1`` and ``purpose + 2`` are used.
        largest: an upper bound of ``counts`` if known on the host: the inversion's CDF then
            stops at ``largest + 1`` terms (its terms above n are 0: the same draws, less work).

    Returns:
        (m,) int64, ``0 <= out <= counts``.

    Example:
        >>> keys = entry_keys(sample_salts(torch.tensor([3]), "cpu"), torch.arange(4000))
        >>> k = binomial_large(keys, torch.full((4000,), 1000), torch.full((4000,), 0.3), 7)
        >>> round(k.double().mean().item()), abs(k.double().var().item() / 210 - 1) < 0.1  # n p, n p (1 - p)
        (300, True)
    """
    n = counts.to(torch.float64)
    prob = prob.to(torch.float64)
    flip = prob > 0.5
    p = torch.where(flip, 1.0 - prob, prob)
    q = 1.0 - p
    r = p / q
    mean = n * p
    # inversion, for every entry (the BTRS ones are overwritten below)
    u = sub_uniform(keys, torch.zeros_like(keys), purpose, bits=53).unsqueeze(1)
    width = _INVERSION_TERMS if largest is None else max(1, min(_INVERSION_TERMS, largest + 1))
    terms = torch.arange(width - 1, dtype=torch.float64, device=n.device)
    ratio = (n.unsqueeze(1) - terms).clamp_min_(0.0).div_(terms + 1.0).mul_(r.unsqueeze(1))
    pmf0 = torch.exp(n * torch.log1p(-p)).unsqueeze(1)
    pmf = torch.cat([pmf0, pmf0 * ratio.cumprod(1)], 1)
    out = (pmf.cumsum(1) < u).sum(1).clamp_max_(_INVERSION_TERMS - 1).to(torch.float64)
    pending = mean >= _INVERSION_MEAN
    if bool(pending.any()):  # one flag, then one per BTRS round (most calls: no entry needs BTRS)
        out = _btrs(out, pending, keys, n, p, q, r, mean, purpose)
    out = out.minimum(n)
    return torch.where(flip, n - out, out).to(torch.int64)


def _btrs(out: Tensor, pending: Tensor, keys: Tensor, n: Tensor, p: Tensor, q: Tensor, r: Tensor, mean: Tensor,
          purpose: int) -> Tensor:
    """The BTRS rounds of :func:`binomial_large` for its ``pending`` entries (``n p' >= 10``)."""
    # BTRS (valid for n p' >= 10), the parameters per entry
    spq = (mean * q).sqrt()
    b = 1.15 + 2.53 * spq
    a = -0.0873 + 0.0248 * b + 0.01 * p
    c = mean + 0.5
    v_r = 0.92 - 4.2 / b
    alpha = (2.83 + 5.1 / b) * spq
    m = ((n + 1.0) * p).floor()
    h = _stirling_tail(m) + _stirling_tail(n - m)
    column = torch.arange(_BTRS_CANDIDATES, device=n.device)
    rounds = 0
    while True:
        within = (column + rounds * _BTRS_CANDIDATES).unsqueeze(0)
        key = keys.unsqueeze(1)
        us_ = sub_uniform(key, within, purpose + 1, bits=53) - 0.5
        v = sub_uniform(key, within, purpose + 2)
        us = 0.5 - us_.abs()
        k = ((2.0 * a.unsqueeze(1) / us + b.unsqueeze(1)) * us_ + c.unsqueeze(1)).floor()
        inside = (k >= 0) & (k <= n.unsqueeze(1))
        squeeze = (us >= 0.07) & (v <= v_r.unsqueeze(1))
        kc = k.clamp(min=0.0).minimum(n.unsqueeze(1))
        log_v = (v * alpha.unsqueeze(1) / (a.unsqueeze(1) / (us * us) + b.unsqueeze(1))).log()
        nm = (n - m).unsqueeze(1)
        bound = (
            (m.unsqueeze(1) + 0.5) * ((m.unsqueeze(1) + 1.0) / (r.unsqueeze(1) * (nm + 1.0))).log()
            + (n.unsqueeze(1) + 1.0) * torch.log1p((kc - m.unsqueeze(1)) / (n.unsqueeze(1) - kc + 1.0))
            + (kc + 0.5) * (r.unsqueeze(1) * (n.unsqueeze(1) - kc + 1.0) / (kc + 1.0)).log()
            + h.unsqueeze(1) - _stirling_tail(kc) - _stirling_tail(n.unsqueeze(1) - kc)
        )
        accept = inside & (squeeze | (log_v <= bound))
        first = torch.where(accept, column, _BTRS_CANDIDATES).amin(1)
        chosen = kc.gather(1, first.clamp_max(_BTRS_CANDIDATES - 1).unsqueeze(1)).squeeze(1)
        found = pending & (first < _BTRS_CANDIDATES)
        out = torch.where(found, chosen, out)
        pending = pending & ~found
        rounds += 1
        if not bool(pending.any()):  # one flag per round
            return out


def poisson_cells(keys: Tensor, lam: Tensor, cells: int, purpose: int) -> Tensor:
    """(B, cells) int64 Poisson(``lam[b]``) counts, one per cell of each sample, counter-based.

    Sample b's cell j inverts the Poisson CDF at the 53-bit uniform named (``keys[b]``, j,
    ``purpose``): the CDF is tabulated once per sample (``P(N <= k) = Q(k + 1, λ)``, the
    regularised upper incomplete gamma, over ``λ ± 10 sqrt(λ) + 11``: the mass outside is
    under 1e-20) and searched per cell (``searchsorted``). Exact up to that mass and to the
    float64 rounding of the table; the same ops whatever B; a sample's counts depend on its
    key only. ``lam`` is a CPU tensor (the table's width is decided on the host).

    Args:
        keys: (B,) int32 sample keys (:func:`entry_keys`).
        lam: (B,) float64 CPU means >= 0.
        cells: cells per sample (below 2**31).
        purpose: names the draw.

    Example:
        >>> keys = entry_keys(sample_salts(torch.tensor([1, 2]), "cpu"), torch.zeros(1, dtype=torch.int64))
        >>> counts = poisson_cells(keys, torch.tensor([2.0, 30.0]), 20000, purpose=1)
        >>> [round(v) for v in counts.double().mean(1).tolist()], [round(v) for v in counts.double().var(1).tolist()]
        ([2, 30], [2, 30])
    """
    device = keys.device
    lam = lam.to(torch.float64).cpu()
    spread = lam.sqrt().mul_(10.0)
    low = (lam - spread - 11.0).floor_().clamp_min_(0.0)
    width = int(math.ceil(max((2.0 * spread + 24.0).tolist(), default=1.0)))
    values = low.unsqueeze(1) + torch.arange(width, dtype=torch.float64)
    cdf = torch.special.gammaincc(values + 1.0, lam.unsqueeze(1)).to(device, non_blocking=True)
    within = torch.arange(cells, dtype=torch.int32, device=device).unsqueeze(0)
    u = sub_uniform(keys.unsqueeze(1), within, purpose, bits=53)
    index = torch.searchsorted(cdf, u).clamp_max_(width - 1)
    return index.add_(low.to(device=device, dtype=torch.int64, non_blocking=True).unsqueeze(1))


#: Buckets of the noise pixels' lookup table per pixel (:func:`search_cumulative`).
_BUCKETS_PER_PIXEL = 4


def search_cumulative(cumulative: Tensor, sample: Tensor, target: Tensor) -> Tensor:
    """``torch.searchsorted(cumulative[sample], target)`` (the first index whose value is >= the
    target) for every target, through a bucket table instead of a binary search of each row.

    With ``step = total / K`` and ``q(v) = clamp(floor(v / step), 0, K)`` (monotone in ``v``,
    rounding included), a target ``x`` in bucket ``g = q(x)`` has its answer between the number
    of values in buckets before ``g`` and the number up to ``g`` inclusive: values with ``q < g``
    are below ``x`` and values with ``q > g`` are not. A short binary search inside that range
    (usually empty: most targets fall in buckets holding no value) gives the same index as
    ``searchsorted``. Rows that are all equal (one camera for the batch) share one table."""
    device = cumulative.device
    rows, pixels = cumulative.shape
    shared = rows > 1 and bool(read_host((cumulative == cumulative[:1]).all()))
    table = cumulative[:1] if shared else cumulative
    buckets = _BUCKETS_PER_PIXEL * pixels
    total = table[:, -1:]
    step = torch.where(total > 0, total / buckets, 1.0)  # a row without rate has no target
    q = torch.div(table, step).floor_().clamp_(0, buckets).to(torch.int64)
    width = buckets + 2
    counts = torch.zeros(table.shape[0], width, dtype=torch.int64, device=device)
    counts.scatter_add_(1, q, torch.ones_like(q))
    guide = torch.cat([torch.zeros_like(counts[:, :1]), counts.cumsum(1)], dim=1).view(-1)  # values in buckets < j
    row = torch.zeros_like(sample) if shared else sample
    g = torch.div(target, step.view(-1)[row]).floor_().clamp_(0, buckets).to(torch.int64)
    at = row * (width + 1) + g
    lo = guide[at]
    hi = guide[at + 1]
    open_ = (lo < hi).nonzero().squeeze(1)
    if open_.numel() == 0:
        return lo
    values = table.reshape(-1)
    base = row[open_] * pixels
    x = target[open_]
    low, high = lo[open_], hi[open_]
    while True:  # binary search in [low, high]; each round halves every range
        mid = (low + high) >> 1
        above = values[base + mid] >= x
        high = torch.where(above, mid, high)
        low = torch.where(above, low, mid + 1)
        if not bool(read_host((low < high).any())):
            break
    return lo.index_copy_(0, open_, low)
