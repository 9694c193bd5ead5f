"""Exact, vectorised draws of random subsets of counted events (private; used by TES).

Events are never expanded one by one. A *pool* is a 1-D int64 tensor of per-pixel event
counts, restricted to the pixels that matter (usually the non-zero ones), and a sorted
``segment`` tensor says which row (frame and polarity) each entry belongs to; rows are
contiguous runs of entries. Memory is a few int64/float64 vectors of the pool's length,
whatever the counts are (a pixel holding 10**7 events costs one entry).

Samplers:

* :func:`binomial_counts` - ``Binomial(count, p)`` per entry (each event kept
  independently with probability ``p``).
* :func:`multivariate_hypergeometric` - for each row, the per-entry counts of a uniformly
  random subset of ``size`` of the row's events (without replacement).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["segment_sum", "binomial_counts", "multivariate_hypergeometric"]

# Counts up to this value are drawn by inverse-CDF look-up in a small table (one uniform
# per entry); larger counts go to ``torch.binomial``. Residual subsets of at most _SMALL
# events per row are drawn directly as distinct event positions.
_TABLE_MAX_COUNT = 8
_SMALL = 64


def segment_sum(values: Tensor, segment: Tensor, num_segments: int) -> Tensor:
    """Per-row sums of int64 ``values`` (``segment`` gives each entry's row), as int64 (R,)."""
    out = torch.zeros(num_segments, dtype=torch.int64, device=values.device)
    return out.index_add_(0, segment, values)


def _binomial_cdf_table(prob: Tensor, width: int) -> Tensor:
    """``F[i, n, k] = P(Binomial(n, prob[i]) <= k)`` for n <= width, k < width; +inf for k >= n.

    Shape ``(P, width + 1, width)``, float64, computed in log space so p = 0 and p = 1 are
    exact (``xlogy(0, 0) = 0``).
    """
    dev = prob.device
    n = torch.arange(width + 1, dtype=torch.float64, device=dev).view(1, -1, 1)
    k = torch.arange(width + 1, dtype=torch.float64, device=dev).view(1, 1, -1)
    p = prob.to(torch.float64).view(-1, 1, 1)
    inside = k <= n
    log_pmf = (
        torch.lgamma(n + 1)
        - torch.lgamma(k + 1)
        - torch.lgamma((n - k).clamp_min(0) + 1)
        + torch.xlogy(k, p)
        + torch.xlogy((n - k).clamp_min(0), 1 - p)
    )
    pmf = torch.where(inside, torch.exp(log_pmf), 0.0)
    cdf = pmf.cumsum(dim=-1)[..., :width]
    return torch.where(k[..., :width] < n, cdf, torch.inf)


def binomial_counts(
    counts: Tensor, prob: Tensor, key: Tensor, *, generator: torch.Generator | None = None
) -> Tensor:
    """Draw ``Binomial(counts[i], prob[key[i]])`` for every entry.

    Counts up to ``_TABLE_MAX_COUNT`` (the common case for event frames) use one uniform
    per entry and the exact inverse CDF from a small table of shape (P, w + 1, w), w the
    largest such count; larger counts use ``torch.binomial`` in float64 (exact integers
    up to 2**53). One host synchronisation (the largest count).

    Args:
        counts: int64 (n,), non-negative.
        prob: float64 (P,), probabilities in [0, 1].
        key: int64 (n,), which probability each entry uses.
        generator: source of randomness, on the counts' device.

    Returns:
        int64 (n,), ``0 <= out <= counts``.
    """
    if counts.numel() == 0:
        return counts.clone()
    largest = int(counts.max())
    width = min(largest, _TABLE_MAX_COUNT)
    if width == 0:
        return torch.zeros_like(counts)
    if prob.numel() * (width + 1) * width > 4 * counts.numel() + 2**16:
        # A table per probability would outgrow the entries (many rows, few events).
        drawn = torch.binomial(
            counts.to(torch.float64), prob.to(torch.float64).index_select(0, key), generator=generator
        )
        return drawn.to(torch.int64)
    small = counts if largest <= _TABLE_MAX_COUNT else counts.masked_fill(counts > width, 0)
    table = _binomial_cdf_table(prob, width).view(-1, width)
    rows = table.index_select(0, key * (width + 1) + small)
    u = torch.rand(counts.shape, dtype=torch.float64, device=counts.device, generator=generator)
    out = (u.unsqueeze(1) >= rows).sum(dim=1)
    if largest > _TABLE_MAX_COUNT:
        large = (counts > width).nonzero().squeeze(1)
        drawn = torch.binomial(
            counts.index_select(0, large).to(torch.float64),
            prob.to(torch.float64).index_select(0, key.index_select(0, large)),
            generator=generator,
        )
        out.index_copy_(0, large, drawn.to(torch.int64))
    return out


def multivariate_hypergeometric(
    pool: Tensor,
    segment: Tensor,
    size: Tensor,
    *,
    total: Tensor | None = None,
    generator: torch.Generator | None = None,
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
    every row needs at most ``_SMALL`` events (or all but that many), the residual is
    drawn as a set of distinct event *positions* (see :func:`_small_subsets`) that map to
    entries by ``searchsorted`` on the int64 cumsum of the pool.

    Cost: per level one binomial draw and a few passes over the pool (length n); the
    finish works on (rows, <= _SMALL) tensors for ~log2(_SMALL) rounds. Memory O(n),
    independent of the counts. One host synchronisation per level and per round.

    Args:
        pool: int64 (n,), non-negative counts.
        segment: int64 (n,), sorted row ids in [0, R).
        size: int64 (R,), ``0 <= size <= total``.
        total: int64 (R,) row totals if already known.
        generator: source of randomness, on the pool's device.

    Returns:
        int64 (n,).
    """
    if total is None:
        total = segment_sum(pool, segment, size.numel())
    if pool.numel() == 0:
        return pool.clone()
    if int(torch.minimum(size, total - size).max()) <= _SMALL:
        return _small_subsets(pool, segment, size, total, generator)
    prob = torch.where(total > 0, size.to(torch.float64) / total.clamp_min(1).to(torch.float64), 0.0)
    kept = binomial_counts(pool, prob, segment, generator=generator)
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


def _small_subsets(
    pool: Tensor, segment: Tensor, size: Tensor, total: Tensor, generator: torch.Generator | None
) -> Tensor:
    """Exact MVHG when every row needs at most ``_SMALL`` events or all but ``_SMALL``.

    Row r draws d = min(size, total - size) <= total / 2 distinct event positions in
    [0, total) (the kept events, or the complement when size > total / 2): draw uniform
    positions for the empty slots, keep the ones not already held (one copy of repeated
    values), repeat until all d slots are held. The accepted set is invariant under
    permutations of the positions and has exactly d elements, so it is a uniform
    d-subset; since d <= total / 2 each draw is accepted with probability >= 1/2, so
    about log2(d) rounds. Positions map to entries through the cumsum of the pool.
    Uniform integers use float64 (relative bias below total * 2**-53).
    """
    complement = 2 * size > total
    draw = torch.where(complement, total - size, size)
    rows = (draw > 0).nonzero().squeeze(1)
    counted = torch.zeros_like(pool)
    if rows.numel():
        width = int(draw.max())
        # Bound the (rows, width) work tensors by a small multiple of the pool (matters
        # only for frames of a few pixels, where rows outnumber entries).
        chunk = max(1, (4 * pool.numel() + 2**16) // width)
        cumsum = pool.cumsum(0)
        offset = total.cumsum(0) - total
        for start in range(0, rows.numel(), chunk):
            part = rows[start : start + chunk]
            positions = offset[part].unsqueeze(1) + _distinct_positions(
                draw[part].unsqueeze(1), total[part].unsqueeze(1), generator
            )
            entries = torch.searchsorted(cumsum, positions[positions >= 0], right=True)
            counted.index_add_(0, entries, torch.ones_like(entries))
    return torch.where(complement.index_select(0, segment), pool - counted, counted)


def _distinct_positions(want: Tensor, have: Tensor, generator: torch.Generator | None) -> Tensor:
    """Per row, ``want`` distinct uniform positions in [0, have) (see :func:`_small_subsets`).

    Returns (rows, max want) int64; padding slots hold -2**62, so ``offset + result >= 0``
    selects the drawn positions.
    """
    device = want.device
    slot = torch.arange(int(want.max()), device=device).unsqueeze(0)
    # Unused slots hold distinct sentinels >= have, never taken for positions.
    picks = torch.where(slot < want, -1, have + slot)
    scale = have.to(torch.float64)
    while True:
        empty = picks < 0
        if not bool(empty.any()):
            break
        u = torch.rand(picks.shape, dtype=torch.float64, device=device, generator=generator)
        fresh = torch.minimum((u * scale).to(torch.int64), have - 1)
        # Sort (value, is_fresh): a held value precedes fresh copies of itself.
        key, _ = (torch.where(empty, fresh, picks) * 2 + empty).sort(dim=1)
        values = key // 2
        repeated = torch.zeros_like(empty)
        repeated[:, 1:] = values[:, 1:] == values[:, :-1]
        picks = values.masked_fill(repeated, -1)
    return picks.masked_fill(picks >= have, -(2**62))
