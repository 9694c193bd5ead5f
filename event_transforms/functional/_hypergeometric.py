"""Exact, vectorised draws of random subsets of counted events (private; used by TES).

A *pool* is a 1-D int64 tensor of per-pixel event counts, restricted to the pixels that
matter (usually the non-zero ones), and a sorted ``segment`` tensor says which row (frame
and polarity) each entry belongs to; rows are contiguous runs of entries. Memory is a few
vectors of the pool's length whatever the counts are (a pixel holding 10**7 events costs
one entry): events are expanded one by one only up to ``_EXPAND_MAX`` per entry.

Samplers:

* :func:`binomial_counts` - ``Binomial(count, p)`` per entry (each event kept
  independently with probability ``p``).
* :func:`multivariate_hypergeometric` - for each row, the per-entry counts of a uniformly
  random subset of ``size`` of the row's events (without replacement).

Host synchronisations are few and counted: the numbers a sampler needs from the device
(largest count, events to expand, largest draw, widest row) are read together, in one
``tolist``, or handed in by the caller who read them with its own checks.
"""

from __future__ import annotations

import torch
from torch import Tensor

from .._validation import read_host

__all__ = ["segment_sum", "binomial_counts", "multivariate_hypergeometric"]

# Up to this many events of an entry are drawn one by one (one uniform each); larger counts
# go to ``torch.binomial``. Residual subsets of at most _SMALL events per row are drawn
# directly as distinct event positions.
_EXPAND_MAX = 8
_SMALL = 64


def segment_sum(values: Tensor, segment: Tensor, num_segments: int) -> Tensor:
    """Per-row sums of int64 ``values`` (``segment`` gives each entry's row), as int64 (R,)."""
    out = torch.zeros(num_segments, dtype=torch.int64, device=values.device)
    return out.index_add_(0, segment, values)


def expansion_stats(counts: Tensor) -> list[Tensor]:
    """0-d tensors a caller reads (in its own synchronisation) for :func:`binomial_counts`:
    the largest count and the number of events drawn one by one."""
    return [counts.max(), counts.clamp_max(_EXPAND_MAX).sum()]


def binomial_counts(
    counts: Tensor,
    prob: Tensor,
    key: Tensor,
    *,
    generator: torch.Generator | None = None,
    largest: int | None = None,
    events: int | None = None,
    dtype: torch.dtype | None = None,
) -> Tensor:
    """Draw ``Binomial(counts[i], prob[key[i]])`` for every entry.

    The first ``_EXPAND_MAX`` events of each entry (all of them for the small counts of
    event frames) are drawn one by one: one float64 uniform each, kept if below the
    probability, summed back per entry (``index_add_``). Larger counts use
    ``torch.binomial`` in float64 (exact integers up to 2**53) for the whole count.
    Host synchronisations: none when ``largest`` and ``events`` (from
    :func:`expansion_stats`) are given, else one; plus one to gather the counts above
    ``_EXPAND_MAX`` when there are any.

    Args:
        counts: int64 (n,), non-negative.
        prob: float64 (P,), probabilities in [0, 1].
        key: int64 (n,), which probability each entry uses.
        generator: source of randomness, on the counts' device.
        largest: the largest count (an upper bound is not enough: it decides the clamp).
        events: ``counts.clamp_max(_EXPAND_MAX).sum()``.
        dtype: of the result (default int64), e.g. the frames' dtype.

    Returns:
        (n,) ``dtype``, ``0 <= out <= counts``.
    """
    if counts.numel() == 0:
        return counts.to(dtype or counts.dtype, copy=True)
    if largest is None or events is None:
        largest, events = (int(v) for v in read_host(torch.stack(expansion_stats(counts))))
    small = counts if largest <= _EXPAND_MAX else counts.clamp_max(_EXPAND_MAX)
    owner = torch.repeat_interleave(small, output_size=events)  # the entry of each event
    u = torch.rand(events, dtype=torch.float64, device=counts.device, generator=generator)
    prob = prob if prob.dtype == torch.float64 else prob.to(torch.float64)
    hit = u < prob.index_select(0, key).index_select(0, owner)
    dtype = counts.dtype if dtype is None else dtype
    out = torch.zeros(counts.shape, dtype=dtype, device=counts.device).index_add_(0, owner, hit.to(dtype))
    if largest > _EXPAND_MAX:
        large = (counts > _EXPAND_MAX).nonzero().squeeze(1)
        drawn = torch.binomial(
            counts.index_select(0, large).to(torch.float64),
            prob.to(torch.float64).index_select(0, key.index_select(0, large)),
            generator=generator,
        )
        out.index_copy_(0, large, drawn.to(dtype))
    return out


def direct_finish(device: torch.device) -> bool:
    """Whether :func:`multivariate_hypergeometric` finishes by smallest keys at any draw size.

    On an accelerator, yes: one ``topk`` over (rows, widest row) keys replaces a binomial
    level and its correction (about 35 launches and one host synchronisation). On the CPU,
    no: the ``topk`` of a few hundred keys per row costs more arithmetic than the level
    (measured 1.4x slower on the benchmark batch), so a binomial level first shrinks the
    draws to about their square root.
    """
    return torch.device(device).type != "cpu"


def _keys_budget(entries: int) -> int:
    """Most (rows × widest row) keys of the smallest-keys finish: memory O(entries)."""
    return 4 * entries + 2**16


def level_stats(size: Tensor, total: Tensor) -> list[Tensor]:
    """0-d tensors :func:`multivariate_hypergeometric` needs on the host, to be read in one
    synchronisation: the largest draw ``min(size, total - size)`` and the widest row."""
    return [torch.minimum(size, total - size).max(), total.max()]


def multivariate_hypergeometric(
    pool: Tensor,
    segment: Tensor,
    size: Tensor,
    *,
    total: Tensor | None = None,
    generator: torch.Generator | None = None,
    stats: tuple[int, int] | None = None,
    expansion: tuple[int, int] | None = None,
) -> Tensor:
    """Per-entry counts of a uniformly random ``size[r]``-subset of each row's events.

    Row r holds ``total[r] = sum(pool[segment == r])`` events, ``pool[i]`` of them at entry
    i. The result Y has ``0 <= Y <= pool`` and ``segment_sum(Y) == size`` exactly, and is
    distributed as the multivariate hypergeometric law (a uniform subset without
    replacement), independently per row.

    Algorithm (binomial draw, then exact correction, recursively): keep each event
    independently with probability ``q = size / total``, giving Y' ~ Binomial(pool, q)
    with S' = sum(Y'). Conditioned on S', the kept set is a uniform S'-subset. If
    S' > size, remove a uniform (S' - size)-subset of the kept events (a multivariate
    hypergeometric draw of that size from the counts Y'); if S' < size, add a uniform
    (size - S')-subset of the others (from the counts pool - Y'). The result is invariant
    under permutations of the events and always has exactly ``size`` events, so it is a
    uniform size-subset: exact. The correction is of order sqrt(total q (1 - q)), so each
    level shrinks the problem from ~N to ~sqrt(N) events (10**7 -> ~1600 -> ~40). Once
    every row needs at most ``_SMALL`` events (or all but that many; at any size on an
    accelerator, see :func:`direct_finish`), the residual is
    drawn as a set of distinct event *positions* that map to entries by ``searchsorted``
    on the int64 cumsum of the pool: the ``d`` smallest of independent uniform keys, one
    per position of the row (:func:`_smallest_keys`, when rows × widest row is within a
    small multiple of the pool), else by rejection (:func:`_small_subsets`).

    Cost: per level one binomial draw and a few passes over the pool (length n); the
    finish works on (rows, widest row) keys or (rows, <= _SMALL) positions. Memory O(n),
    independent of the counts. Host synchronisations: one per level (:func:`level_stats`,
    none at the top level when ``stats`` is given), one per binomial draw unless
    ``expansion`` gives its numbers (the top level's); the rejection finish adds about one
    per round.

    Args:
        pool: int64 (n,), non-negative counts.
        segment: int64 (n,), sorted row ids in [0, R).
        size: int64 (R,), ``0 <= size <= total``.
        total: int64 (R,) row totals if already known.
        generator: source of randomness, on the pool's device.
        stats: :func:`level_stats` as host ints, if already read.
        expansion: :func:`expansion_stats` of the pool as host ints, if already read.

    Returns:
        int64 (n,).
    """
    if total is None:
        total = segment_sum(pool, segment, size.numel())
    if pool.numel() == 0:
        return pool.clone()
    if stats is None:
        stats = tuple(int(v) for v in read_host(torch.stack(level_stats(size, total))))
    draw, widest = stats
    direct = direct_finish(pool.device)
    if (draw <= _SMALL or direct) and size.numel() * widest <= _keys_budget(pool.numel()):
        return _smallest_keys(pool, segment, size, total, generator, draw, widest)
    if draw <= _SMALL:
        return _small_subsets(pool, segment, size, total, generator, draw)
    # size / total is 0 / 1 = 0 for an empty row.
    prob = size.to(torch.float64) / total.clamp_min(1).to(torch.float64)
    largest, events = (None, None) if expansion is None else expansion
    kept = binomial_counts(pool, prob, segment, generator=generator, largest=largest, events=events)
    kept_total = segment_sum(kept, segment, size.numel())
    excess = kept_total - size
    over = excess > 0
    over_entry = over.index_select(0, segment)
    residual_pool = torch.where(over_entry, kept, pool - kept)
    residual_total = torch.where(over, kept_total, total - kept_total)
    correction = multivariate_hypergeometric(
        residual_pool, segment, excess.abs(), total=residual_total, generator=generator
    )
    return torch.where(over_entry, kept - correction, kept + correction)


def _smallest_keys(
    pool: Tensor, segment: Tensor, size: Tensor, total: Tensor, generator: torch.Generator | None, width: int, widest: int
) -> Tensor:
    """Exact MVHG for draws d = min(size, total - size) <= ``width`` and rows of at most
    ``widest`` events, with no loop.

    Every position of row r (0 .. total - 1; the padding up to ``widest`` sorts last) gets
    an independent float64 uniform key; the d positions with the smallest keys are a
    uniformly random d-subset (exchangeable keys; ties have probability below
    widest**2 * 2**-53 and are broken by position). They are the kept events, or the
    complement when size > total / 2. Positions map to entries through the cumsum of the
    pool. Work (rows, widest) keys and one ``topk``.
    """
    draw = torch.minimum(size, total - size)
    complement = draw != size
    if width == 0:  # every row keeps all or none of its events
        return torch.where(complement.index_select(0, segment), pool, 0)
    position = torch.arange(widest, device=pool.device)
    keys = torch.rand(size.numel(), widest, dtype=torch.float64, device=pool.device, generator=generator)
    keys.masked_fill_(position >= total.unsqueeze(1), 2.0)  # padding after every real position
    chosen = keys.topk(width, dim=1, largest=False, sorted=True).indices  # (rows, width)
    held = position[:width] < draw.unsqueeze(1)
    chosen += (total.cumsum(0) - total).unsqueeze(1)  # first position of each row
    entries = torch.searchsorted(pool.cumsum(0), chosen.view(-1), right=True)
    # Slots past a row's draw may point past the last entry: they add 0 anywhere.
    counted = torch.zeros_like(pool).index_add_(0, entries.clamp_max_(pool.numel() - 1), held.view(-1).to(pool.dtype))
    return torch.where(complement.index_select(0, segment), pool - counted, counted)

def _small_subsets(
    pool: Tensor, segment: Tensor, size: Tensor, total: Tensor, generator: torch.Generator | None, width: int
) -> Tensor:
    """Exact MVHG when every row needs at most ``width`` (<= ``_SMALL``) events or all but that many.

    Row r draws d = min(size, total - size) <= total / 2 distinct event positions in
    [0, total) (the kept events, or the complement when size > total / 2): draw uniform
    positions for the empty slots, keep the ones not already held (one copy of repeated
    values), repeat until all d slots are held. The accepted set is invariant under
    permutations of the positions and has exactly d elements, so it is a uniform
    d-subset; since d <= total / 2 each draw is accepted with probability >= 1/2, so
    about log2(d) rounds. Positions map to entries through the cumsum of the pool.
    Uniform integers use float64 (relative bias below total * 2**-53). Every row takes
    part (rows that draw nothing hold only padding), so no row list is gathered.
    """
    complement = 2 * size > total
    draw = torch.where(complement, total - size, size)
    counted = torch.zeros_like(pool)
    if width > 0:
        rows = size.numel()
        # Bound the (rows, width) work tensors by a small multiple of the pool (matters
        # only for frames of a few pixels, where rows outnumber entries).
        chunk = max(1, (4 * pool.numel() + 2**16) // width)
        cumsum = pool.cumsum(0)
        offset = total.cumsum(0) - total
        for start in range(0, rows, chunk):
            part = slice(start, start + chunk)
            positions = offset[part].unsqueeze(1) + _distinct_positions(
                draw[part].unsqueeze(1), total[part].unsqueeze(1), generator, width
            )
            # Padding slots hold large negative positions: they add 0 at entry 0.
            held = positions >= 0
            entries = torch.searchsorted(cumsum, positions.clamp_min(0), right=True)
            counted.index_add_(0, entries.view(-1), held.view(-1).to(counted.dtype))
    return torch.where(complement.index_select(0, segment), pool - counted, counted)


#: Rounds of :func:`_distinct_positions` run before the first check for empty slots (a
#: round with no empty slot changes nothing, so extra rounds cost time, never exactness).
_UNCHECKED_ROUNDS = 2


def _distinct_positions(want: Tensor, have: Tensor, generator: torch.Generator | None, width: int) -> Tensor:
    """Per row, ``want`` (<= ``width``) distinct uniform positions in [0, have) (see
    :func:`_small_subsets`).

    Returns (rows, width) int64; padding slots hold -2**62, so ``offset + result >= 0``
    selects the drawn positions. Positions are carried doubled, as ``2 v`` for a held value
    and ``2 v + 1`` for a fresh draw, so one sort puts a held value before fresh copies of
    itself.
    """
    device = want.device
    slot = torch.arange(width, device=device).unsqueeze(0)
    # Unused slots hold distinct sentinels >= have, never taken for positions.
    key = torch.where(slot < want, -1, 2 * (have + slot))
    scale = have.to(torch.float64)
    top = have - 1
    rounds = 0
    while True:
        empty = key < 0
        if rounds >= _UNCHECKED_ROUNDS and not bool(empty.any()):
            break
        rounds += 1
        u = torch.rand(key.shape, dtype=torch.float64, device=device, generator=generator)
        fresh = torch.minimum(u.mul_(scale).to(torch.int64), top)
        key, _ = torch.where(empty, 2 * fresh + 1, key).sort(dim=1)
        value = key >> 1
        repeated = torch.nn.functional.pad(value[:, 1:] == value[:, :-1], (1, 0))
        key = (key & ~1).masked_fill_(repeated, -1)
    value = key >> 1
    return value.masked_fill_(value >= have, -(2**62))
