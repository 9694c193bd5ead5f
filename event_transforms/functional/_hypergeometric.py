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
(largest count, events to expand, largest draw, widest finished draw) are read together, in
one ``tolist``, or handed in by the caller who read them with its own checks.

Randomness comes from a :class:`Stream`: per-sample counter-based streams in which every
entry and row is named by its place within its sample, and every route is decided per row,
so a sample's draw is the same alone as in any batch (per-sample purity).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from .._validation import read_host
from ._random import (
    _int32, _mix, _sub_hash, _to53, binomial_large, draw_seeds, entry_keys, sample_salts,
)

__all__ = ["segment_sum", "Stream", "binomial_counts", "multivariate_hypergeometric"]

# Up to this many events of an entry are drawn one by one (one uniform each); larger counts
# are drawn whole (``_random.binomial_large``: inversion or BTRS, counter-based). Residual subsets of at most _SMALL events per row are drawn
# directly as distinct event positions.
_EXPAND_MAX = 8
_SMALL = 64


def segment_sum(values: Tensor, segment: Tensor, num_segments: int) -> Tensor:
    """Per-row sums of int64 ``values`` (``segment`` gives each entry's row), as int64 (R,)."""
    out = torch.zeros(num_segments, dtype=torch.int64, device=values.device)
    return out.index_add_(0, segment, values)


@dataclass
class Stream:
    """Where the samplers' random numbers come from: per-sample counter-based streams.

    Every entry (a non-zero pixel) and every row (a frame and polarity of a sample) is
    named by its sample's salt and its position *within the sample*, so its numbers do
    not depend on the rest of the batch (see :mod:`._random`).

    Attributes:
        seeds: (B,) int64 per-sample seeds (CPU for the module path).
        entry_sample: (n,) int64 sample of each entry.
        entry_salt: (n,) int32 salt of each entry's sample.
        entry_counter: (n,) int64 position of each entry within its sample.
        row_salt: (R,) int32 salt of each row's sample.
        row_counter: (R,) int64 position of each row within its sample.
    """

    seeds: Tensor
    entry_sample: Tensor
    entry_salt: Tensor
    entry_counter: Tensor
    row_salt: Tensor
    row_counter: Tensor

    @classmethod
    def of_samples(cls, seeds: Tensor, entry_sample: Tensor, entry_counter: Tensor, rows_per_sample: int) -> Stream:
        """Streams for a batch: entries named by (sample, position), rows by (sample, row)."""
        device = entry_sample.device
        salts = sample_salts(seeds, device)
        rows = torch.arange(salts.numel() * rows_per_sample, device=device)
        return cls(
            seeds, entry_sample, salts.index_select(0, entry_sample), entry_counter,
            salts.repeat_interleave(rows_per_sample), rows.remainder(max(rows_per_sample, 1)),
        )

    @classmethod
    def single(cls, entries: int, rows: int, generator: torch.Generator | None, device: torch.device) -> Stream:
        """One stream for a whole problem (the samplers' own ``generator=`` form)."""
        seeds = draw_seeds(1, generator).to(device)
        zeros = torch.zeros(entries, dtype=torch.int64, device=device)
        return cls.of_samples(seeds, zeros, torch.arange(entries, device=device), rows)


def _stream(
    stream: Stream | None, entries: int, rows: int, generator: torch.Generator | None, device: torch.device
) -> Stream:
    return stream if stream is not None else Stream.single(entries, rows, generator, device)


def expansion_stats(counts: Tensor) -> list[Tensor]:
    """0-d tensors a caller reads (in its own synchronisation) for :func:`binomial_counts`:
    the largest count and the number of events drawn one by one."""
    return [counts.max(), counts.clamp_max(_EXPAND_MAX).sum()]


def binomial_counts(
    counts: Tensor,
    prob: Tensor,
    key: Tensor,
    *,
    stream: Stream | None = None,
    level: int = 0,
    generator: torch.Generator | None = None,
    largest: int | None = None,
    events: int | None = None,
    dtype: torch.dtype | None = None,
) -> Tensor:
    """Draw ``Binomial(counts[i], prob[key[i]])`` for every entry.

    The first ``_EXPAND_MAX`` events of each entry (all of them for the small counts of
    event frames) are drawn one by one: one uniform each, a hash of the entry's sample
    salt and the event's position in the sample (``stream``; ``level`` names the draw),
    kept if below the probability, summed back per entry (``index_add_``). Larger counts
    are drawn whole by :func:`~._random.binomial_large` (exact inversion for
    ``n min(p, 1 - p) < 10``, Hörmann's BTRS otherwise), from the same per-entry key and
    the purposes ``_LARGE_PURPOSE + 4 level`` (+1, +2), all such entries of the batch in one
    vectorised call. Host synchronisations: none when ``largest`` and ``events`` (from
    :func:`expansion_stats`) are given, else one; plus, when there are counts above
    ``_EXPAND_MAX``, one to gather them (``nonzero``) and one flag per BTRS round plus one
    (one in all when no such entry has ``n min(p, 1 - p) >= 10``, two almost always otherwise).

    Args:
        counts: int64 (n,), non-negative.
        prob: float64 (P,), probabilities in [0, 1].
        key: int64 (n,), which probability each entry uses.
        stream: the per-sample streams (default: one stream from ``generator``).
        level: names this draw among the draws of one stream.
        generator: source of the stream's seed when ``stream`` is not given.
        largest: the largest count (an upper bound is not enough: it decides the clamp).
        events: ``counts.clamp_max(_EXPAND_MAX).sum()``.
        dtype: of the result (default int64), e.g. the frames' dtype.

    Returns:
        (n,) ``dtype``, ``0 <= out <= counts``.
    """
    if counts.numel() == 0:
        return counts.to(dtype or counts.dtype, copy=True)
    stream = _stream(stream, counts.numel(), 0, generator, counts.device)
    if largest is None or events is None:
        largest, events = (int(v) for v in read_host(torch.stack(expansion_stats(counts))))
    small = counts if largest <= _EXPAND_MAX else counts.clamp_max(_EXPAND_MAX)
    owner = torch.repeat_interleave(small, output_size=events)  # the entry of each event
    first = small.cumsum(0).sub_(small)  # the first event of each entry
    index = torch.int32 if events < 2**31 else torch.int64  # _sub_hash takes the low 32 bits either way
    within = torch.arange(events, dtype=index, device=counts.device).sub_(first.to(index).index_select(0, owner))
    keys = entry_keys(stream.entry_salt, stream.entry_counter)  # per entry, then one mix per event
    prob = prob if prob.dtype == torch.float64 else prob.to(torch.float64)
    below = _hash_thresholds(prob)  # the sub_uniform comparison on the int32 hashes
    hit = _sub_hash(keys.index_select(0, owner), within, level) < below.index_select(0, key).index_select(0, owner)
    dtype = counts.dtype if dtype is None else dtype
    out = torch.zeros(counts.shape, dtype=dtype, device=counts.device).index_add_(0, owner, hit.to(dtype))
    if largest > _EXPAND_MAX:
        _large_counts(out, counts, prob, key, keys, level, largest)
    return out


def _hash_thresholds(prob: Tensor) -> Tensor:
    """int64 T with ``sub_uniform(keys, within, purpose) < prob`` exactly when the int32 hash
    ``_sub_hash(keys, within, purpose) < T``, for float64 ``prob`` in [0, 1].

    The uniform is u = (x + 2**31 + 1/2) 2**-32, exact in float64, so u < p <=> x + 2**31 <
    p 2**32 - 1/2 <=> x < ceil(p 2**32 - 1/2) - 2**31 for an integer x; p 2**32 - 1/2 is exact
    in float64 (or, below 1/4, rounds within (-1/2, -1/4], whose ceiling is 0 all the same)."""
    return (prob * 2.0**32 - 0.5).ceil_().to(torch.int64).sub_(2**31)


#: Purposes of the whole-count draws (:func:`~._random.binomial_large`), four per level.
_LARGE_PURPOSE = 1_000_000


def _large_counts(
    out: Tensor, counts: Tensor, prob: Tensor, key: Tensor, keys: Tensor, level: int, largest: int
) -> None:
    """Overwrite the entries above ``_EXPAND_MAX`` with whole-count binomial draws
    (:func:`~._random.binomial_large`), keyed by each entry's sample salt and position in
    its sample and by ``level`` (``keys``: every entry's :func:`~._random.entry_keys`): one
    vectorised call for the batch, pure per sample."""
    large = (counts > _EXPAND_MAX).nonzero().squeeze(1)
    drawn = binomial_large(
        keys.index_select(0, large), counts.index_select(0, large), prob.index_select(0, key.index_select(0, large)),
        _LARGE_PURPOSE + 4 * level, largest,
    )
    out.index_copy_(0, large, drawn.to(out.dtype))


def level_stats(size: Tensor, total: Tensor) -> list[Tensor]:
    """0-d tensors :func:`multivariate_hypergeometric` needs on the host, to be read in one
    synchronisation: the largest draw ``d = min(size, total - size)`` of any row."""
    return [torch.minimum(size, total - size).max()]


def multivariate_hypergeometric(
    pool: Tensor,
    segment: Tensor,
    size: Tensor,
    *,
    total: Tensor | None = None,
    stream: Stream | None = None,
    generator: torch.Generator | None = None,
    stats: int | None = None,
    expansion: tuple[int, int] | None = None,
    level: int = 0,
) -> Tensor:
    """Per-entry counts of a uniformly random ``size[r]``-subset of each row's events.

    Row r holds ``total[r] = sum(pool[segment == r])`` events, ``pool[i]`` of them at entry
    i. The result Y has ``0 <= Y <= pool`` and ``segment_sum(Y) == size`` exactly, and is
    distributed as the multivariate hypergeometric law (a uniform subset without
    replacement), independently per row.

    Algorithm (binomial draw, then exact correction, recursively), decided **per row** from
    that row's own draw d = min(size, total - size), so a row's result never depends on
    the other rows of the batch: a row with d <= ``_SMALL`` is finished at once by drawing
    d distinct event *positions* (:func:`_small_subsets`). Any other row keeps each event
    independently with probability ``q = size / total``, giving Y' ~ Binomial(pool, q)
    with S' = sum(Y'). Conditioned on S', the kept set is a uniform S'-subset. If
    S' > size, remove a uniform (S' - size)-subset of the kept events (a multivariate
    hypergeometric draw of that size from the counts Y'); if S' < size, add a uniform
    (size - S')-subset of the others (from the counts pool - Y'). The result is invariant
    under permutations of the events and always has exactly ``size`` events, so it is a
    uniform size-subset: exact. The correction is of order sqrt(total q (1 - q)) events
    (10**7 -> ~1600), and it is finished at once by drawing distinct positions, whatever
    its width: always two levels, so the ops do not depend on the data or the batch size.

    Randomness: counter-based, from ``stream`` (entries and rows named within their
    sample; ``level`` names the recursion level), so a sample's rows give the same result
    alone as in any batch. Cost: per level one binomial draw and a few passes over the
    pool (length n); the finishes work on (rows, widest draw) positions. Memory O(n),
    independent of the counts. Host synchronisations: one per level
    (:func:`level_stats`, none at the top level when ``stats`` is given), one per
    binomial draw unless ``expansion`` gives its numbers (the top level's), and one per
    round of the finish after the first ``_UNCHECKED_ROUNDS`` (rarely any).

    Args:
        pool: int64 (n,), non-negative counts.
        segment: int64 (n,), sorted row ids in [0, R).
        size: int64 (R,), ``0 <= size <= total``.
        total: int64 (R,) row totals if already known.
        stream: the per-sample streams (default: one stream from ``generator``).
        generator: source of the stream's seed when ``stream`` is not given.
        stats: :func:`level_stats` as a host int, if already read.
        expansion: :func:`expansion_stats` of the pool as host ints, if already read.
        level: the recursion level (names the draws).

    Returns:
        int64 (n,).
    """
    if total is None:
        total = segment_sum(pool, segment, size.numel())
    if pool.numel() == 0:
        return pool.clone()
    stream = _stream(stream, pool.numel(), size.numel(), generator, pool.device)
    draw = int(read_host(level_stats(size, total)[0])) if stats is None else stats
    if level > 0:
        # the correction of a binomial level (about sqrt(N) events): finished at once, every
        # row, whatever its width, so the number of levels (and ops) never depends on the data
        return _small_subsets(pool, segment, size, total, stream, draw, level)
    if draw <= _SMALL:
        return _small_subsets(pool, segment, size, total, stream, draw, level)
    finish = torch.minimum(size, total - size) <= _SMALL
    drawn = torch.where(finish, 0, size)  # the rows that take a binomial level
    # drawn / total is 0 / 1 = 0 for an empty row (and for every finished row).
    prob = drawn.to(torch.float64) / total.clamp_min(1).to(torch.float64)
    largest: int | None
    events: int | None
    largest, events = (None, None) if expansion is None else expansion
    kept = binomial_counts(pool, prob, segment, stream=stream, level=level, largest=largest, events=events)
    kept_total = segment_sum(kept, segment, size.numel())
    excess = kept_total - drawn
    over = excess > 0
    over_entry = over.index_select(0, segment)
    # One finish for every row: the rows finished at this level draw their own subset
    # (``level``), the others the correction of their binomial draw (``level + 1``, from the
    # kept events or the others); each row's numbers are named by its own level, so this is
    # the draw of a finish per level, in one call. A finished row drew with probability 0:
    # it kept nothing and is not over, so its pool, total and result need no case of their own.
    sub_pool = torch.where(over_entry, kept, pool - kept)
    sub_size = torch.where(finish, size, excess.abs())
    sub_total = torch.where(over, kept_total, total - kept_total)
    widest = int(read_host(torch.minimum(sub_size, sub_total - sub_size).max()))
    counted = _small_subsets(pool=sub_pool, segment=segment, size=sub_size, total=sub_total, stream=stream,
                             width=widest, level=level, deeper=~finish)
    return torch.where(over_entry, kept - counted, kept + counted)


def _small_subsets(
    pool: Tensor, segment: Tensor, size: Tensor, total: Tensor, stream: Stream, width: int, level: int,
    deeper: Tensor | None = None,
) -> Tensor:
    """Exact MVHG when every row needs at most ``width`` (<= ``_SMALL``) events or all but that many.

    Row r draws d = min(size, total - size) <= total / 2 distinct event positions in
    [0, total) (the kept events, or the complement when size > total / 2): draw uniform
    positions for the empty slots, keep the ones not already held (one copy of repeated
    values), repeat until all d slots are held. The accepted set is invariant under
    permutations of the positions and has exactly d elements, so it is a uniform
    d-subset; since d <= total / 2 each draw is accepted with probability >= 1/2, so
    about log2(d) rounds. Positions map to entries through the cumsum of the pool.
    Uniform integers use 53-bit uniforms (relative bias below total * 2**-53), named by
    the row's position in its sample, the slot, the level and the round, so a row's
    draw does not depend on the other rows. Every row takes part (rows that draw nothing
    hold only padding), so no row list is gathered. ``deeper`` (bool (R,), optional) names
    the draws of its rows by ``level + 1`` instead of ``level``: the finishes of two levels
    in one call, each row's numbers exactly those of its own level's call.
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
            names = (stream.row_salt[part].unsqueeze(1), stream.row_counter[part].unsqueeze(1) * _ROW_STRIDE)
            positions = offset[part].unsqueeze(1) + _distinct_positions(
                draw[part].unsqueeze(1), total[part].unsqueeze(1), names, width, level,
                None if deeper is None else deeper[part],
            )
            # Padding slots hold large negative positions: they add 0 at entry 0.
            held = positions >= 0
            entries = torch.searchsorted(cumsum, positions.clamp_min(0), right=True)
            counted.index_add_(0, entries.view(-1), held.view(-1).to(counted.dtype))
    return torch.where(complement.index_select(0, segment), pool - counted, counted)


#: Rounds of :func:`_distinct_positions` run before the first check for empty slots (a
#: round with no empty slot changes nothing, so extra rounds cost time, never exactness).
_UNCHECKED_ROUNDS = 4

#: Slot k of row r draws the uniform named by counter ``r * _ROW_STRIDE + k`` (rows of any width).
_ROW_STRIDE = 2**32


def _round_tags(level: int, rounds: range, deeper: Tensor | None, device: torch.device) -> Tensor:
    """The hash tags of purposes ``1_000 + 64 level + r`` (r in ``rounds``) as int32
    (rounds, 1, 1), or per row (rounds, rows, 1) with the rows of ``deeper`` at ``level + 1``."""
    def tag(lvl: int, r: int) -> int:
        return _int32((1_000 + 64 * lvl + r) * 0x27D4EB2F + 0x165667B1)

    if deeper is None:
        return torch.tensor([tag(level, r) for r in rounds], dtype=torch.int32, device=device).view(-1, 1, 1)
    table = torch.tensor([[tag(level, r), tag(level + 1, r)] for r in rounds], dtype=torch.int32, device=device)
    return table.index_select(1, deeper.to(torch.int64)).unsqueeze(2)


def _uniform53_rounds(salt: Tensor, counter: Tensor, tags: Tensor) -> Tensor:
    """``torch.stack([uniform53(salt, counter, p) for p in purposes])``, bit for bit, in fewer
    ops, for the (rounds, ...) int32 hash ``tags`` of the purposes (:func:`_round_tags`): the
    purpose-free first mix of the hash once, then one mix per purpose over the stack."""
    low = counter.to(torch.int32) if counter.dtype != torch.int32 else counter
    x = _mix(low ^ salt)
    if counter.dtype == torch.int64:
        x = x ^ (counter >> 32).to(torch.int32)
    return _to53(_mix(x.unsqueeze(0) ^ tags))


def _fresh(u: Tensor, scale: Tensor, top: Tensor) -> Tensor:
    """Uniform positions ``min(floor(u have), have - 1)`` carried as fresh draws, ``2 v + 1``."""
    return torch.minimum(u.mul_(scale).to(torch.int64), top).mul_(2).add_(1)


def _distinct_positions(
    want: Tensor, have: Tensor, names: tuple[Tensor, Tensor], width: int, level: int, deeper: Tensor | None = None
) -> Tensor:
    """Per row, ``want`` (<= ``width``) distinct uniform positions in [0, have) (see
    :func:`_small_subsets`). ``names`` are each row's salt and first counter: slot k of
    round r draws the uniform named (salt, counter + k) for purpose (level, r), or
    (level + 1, r) for the rows of ``deeper``.

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
    salt, first = names
    counter = first + slot
    top = have - 1
    # the unchecked rounds' fresh draws (doubled, + 1) at once: one hash of (salt, counter), then
    # one mix per round's purpose over a (rounds, rows, width) stack, the numbers uniform53 gives
    tags = _round_tags(level, range(1, _UNCHECKED_ROUNDS + 1), deeper, device)
    drawn = _fresh(_uniform53_rounds(salt, counter, tags), scale, top)
    rounds = 0
    while True:
        empty = key < 0
        if rounds >= _UNCHECKED_ROUNDS and not bool(empty.any()):
            break
        rounds += 1
        if rounds <= _UNCHECKED_ROUNDS:
            fresh = drawn[rounds - 1]
        else:
            tags = _round_tags(level, range(rounds, rounds + 1), deeper, device)
            fresh = _fresh(_uniform53_rounds(salt, counter, tags)[0], scale, top)  # (rows, width), small
        key, _ = torch.where(empty, fresh, key).sort(dim=1)
        value = key >> 1
        repeated = torch.nn.functional.pad(value[:, 1:] == value[:, :-1], (1, 0))
        key = (key & ~1).masked_fill_(repeated, -1)
    value = key >> 1
    return value.masked_fill_(value >= have, -(2**62))
