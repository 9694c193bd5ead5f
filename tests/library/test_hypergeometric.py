"""The exact samplers behind TES: binomial counts and multivariate hypergeometric subsets."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
import torch

from event_transforms.functional import _hypergeometric as hg


def chi_square_p_value(observed: Counter, pmf: dict, draws: int) -> float:
    """Pearson chi-square goodness of fit; categories merged until each expects >= 5.

    The tail probability is computed with ``torch.special.gammaincc`` (scipy is not a
    dependency): P(chi2_df > x) = Q(df / 2, x / 2).
    """
    cells, obs, exp = [], 0.0, 0.0
    for value in sorted(pmf):
        obs += observed.get(value, 0)
        exp += pmf[value] * draws
        if exp >= 5:
            cells.append((obs, exp))
            obs = exp = 0.0
    if exp > 0:  # fold the remainder into the last cell
        last_obs, last_exp = cells.pop()
        cells.append((last_obs + obs, last_exp + exp))
    assert sum(o for o, _ in cells) == draws, "observed values outside the support"
    statistic = sum((o - e) ** 2 / e for o, e in cells)
    df = len(cells) - 1
    tail = torch.special.gammaincc(torch.tensor(df / 2, dtype=torch.float64),
                                   torch.tensor(statistic / 2, dtype=torch.float64))
    return float(tail)


def hypergeometric_pmf(good: int, total: int, draws: int) -> dict[int, float]:
    """P(k of the ``good`` events among ``draws`` taken without replacement from ``total``)."""
    log_norm = math.lgamma(total + 1) - math.lgamma(draws + 1) - math.lgamma(total - draws + 1)

    def log_comb(n: int, k: int) -> float:
        return math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1)

    low, high = max(0, draws - (total - good)), min(good, draws)
    return {
        k: math.exp(log_comb(good, k) + log_comb(total - good, draws - k) - log_norm)
        for k in range(low, high + 1)
    }


def rows(pool: list[int], repeats: int) -> tuple[torch.Tensor, torch.Tensor]:
    counts = torch.tensor(pool, dtype=torch.int64).repeat(repeats)
    segment = torch.arange(repeats).repeat_interleave(len(pool))
    return counts, segment


class TestSegmentSum:
    def test_against_loop(self):
        values = torch.tensor([1, 2, 3, 4, 5])
        segment = torch.tensor([0, 0, 2, 2, 2])
        assert hg.segment_sum(values, segment, 4).tolist() == [3, 0, 12, 0]


class TestBinomialCounts:
    @pytest.mark.parametrize("count", [0, 1, 3, 8, 9, 40, 10**6, 10**12])
    def test_mean_and_variance(self, count):
        n, p = 20000, 0.3
        counts = torch.full((n,), count, dtype=torch.int64)
        z = hg.binomial_counts(
            counts, torch.tensor([p], dtype=torch.float64), torch.zeros(n, dtype=torch.int64),
            generator=torch.Generator().manual_seed(1),
        ).double()
        assert bool(((z >= 0) & (z <= count)).all())
        assert z.dtype == torch.float64 and bool((z == z.round()).all())
        mean, var = count * p, count * p * (1 - p)
        assert abs(z.mean().item() - mean) <= 5 * math.sqrt(var / n) + 1e-12
        if count:
            assert z.var().item() == pytest.approx(var, rel=0.1)

    def test_small_counts_follow_binomial_law(self):
        n, count, p = 10**4, 6, 0.35
        z = hg.binomial_counts(
            torch.full((n,), count), torch.tensor([p], dtype=torch.float64),
            torch.zeros(n, dtype=torch.int64), generator=torch.Generator().manual_seed(2),
        )
        pmf = {k: math.comb(count, k) * p**k * (1 - p) ** (count - k) for k in range(count + 1)}
        assert chi_square_p_value(Counter(z.tolist()), pmf, n) > 1e-3

    @pytest.mark.parametrize("p, expect", [(0.0, "zero"), (1.0, "all")])
    def test_certain_probabilities(self, p, expect):
        counts = torch.tensor([0, 1, 2, 5, 8, 9, 100, 10**9])
        z = hg.binomial_counts(
            counts, torch.tensor([p], dtype=torch.float64), torch.zeros(8, dtype=torch.int64)
        )
        assert torch.equal(z, torch.zeros_like(counts) if expect == "zero" else counts)

    def test_per_entry_probability_key(self):
        counts = torch.full((4000,), 5)
        key = torch.arange(4000) % 2
        z = hg.binomial_counts(counts, torch.tensor([0.0, 1.0], dtype=torch.float64), key)
        assert torch.equal(z, torch.where(key == 1, 5, 0))

    def test_many_probabilities_on_the_expanded_route(self):
        """A table per probability would outgrow the entries: same law, no big table."""
        n = 3000
        prob = torch.linspace(0, 1, n, dtype=torch.float64)
        counts = torch.full((n,), 8)
        z = hg.binomial_counts(counts, prob, torch.arange(n), generator=torch.Generator().manual_seed(4))
        assert z[0] == 0 and z[-1] == 8 and bool(((z >= 0) & (z <= 8)).all())
        assert abs(z.double().mean().item() - 4.0) < 5 * math.sqrt(8 / 6 / n) + 0.05

    def test_empty(self):
        empty = torch.zeros(0, dtype=torch.int64)
        assert hg.binomial_counts(empty, torch.tensor([0.5], dtype=torch.float64), empty).numel() == 0


@pytest.fixture(params=["levels", "finish-at-once"])
def finish(request, monkeypatch):
    """Run a test with each route a row can take, decided per row: binomial levels then the
    rejection finish, and (with a large ``_SMALL``) the rejection finish at once."""
    if request.param == "finish-at-once":
        monkeypatch.setattr(hg, "_SMALL", 512)
    return request.param


@pytest.mark.usefixtures("finish")
class TestMultivariateHypergeometric:
    def check_invariants(self, pool, segment, size, y):
        assert y.dtype == torch.int64
        assert bool(((y >= 0) & (y <= pool)).all())
        assert torch.equal(hg.segment_sum(y, segment, size.numel()), size)

    @pytest.mark.parametrize(
        "pool, size",
        [
            ([3, 0, 5, 2], 4),  # small path
            ([3, 0, 5, 2], 9),  # complement path (9 > 10 / 2)
            ([3, 0, 5, 2], 0),
            ([3, 0, 5, 2], 10),
            ([300, 500, 200], 600),  # binomial level then correction
            ([10**7], 5 * 10**6),  # one pixel with 10**7 events
            ([1905] * 5250, 5_000_625),  # 10**7 events over many pixels
            ([10**12, 3, 10**11], 7 * 10**11 + 1),
        ],
    )
    def test_invariants(self, pool, size):
        counts, segment = rows(pool, 3)
        sizes = torch.full((3,), size, dtype=torch.int64)
        y = hg.multivariate_hypergeometric(counts, segment, sizes, generator=torch.Generator().manual_seed(0))
        self.check_invariants(counts, segment, sizes, y)

    def test_rows_with_no_events_and_mixed_sizes(self):
        counts = torch.tensor([0, 0, 4, 1, 7, 10**6, 2])
        segment = torch.tensor([0, 0, 1, 1, 3, 3, 4])
        sizes = torch.tensor([0, 3, 0, 500_000, 2])
        y = hg.multivariate_hypergeometric(counts, segment, sizes)
        self.check_invariants(counts, segment, sizes, y)
        assert y[-1] == 2 and y[:2].tolist() == [0, 0]

    @pytest.mark.parametrize("size", [4, 7])  # direct and complement draws
    def test_joint_law_against_numpy(self, size):
        """Chi-square of the joint moved counts vs the exact MVHG law, cross-checked with numpy."""
        pool, draws = [3, 0, 5, 2], 10**4
        counts, segment = rows(pool, draws)
        y = hg.multivariate_hypergeometric(
            counts, segment, torch.full((draws,), size), generator=torch.Generator().manual_seed(5)
        ).view(draws, len(pool))
        total = sum(pool)
        pmf = {}
        for a in range(pool[0] + 1):
            for c in range(pool[2] + 1):
                d = size - a - c
                if 0 <= d <= pool[3]:
                    ways = math.comb(pool[0], a) * math.comb(pool[2], c) * math.comb(pool[3], d)
                    pmf[(a, 0, c, d)] = ways / math.comb(total, size)
        observed = Counter(map(tuple, y.tolist()))
        assert chi_square_p_value(observed, pmf, draws) > 1e-3
        # numpy's sampler of the same law passes the same test (sanity of the test itself)
        ref = np.random.default_rng(0).multivariate_hypergeometric(pool, size, size=draws)
        assert chi_square_p_value(Counter(map(tuple, ref.tolist())), pmf, draws) > 1e-3

    def test_recursive_path_law(self):
        """Sizes above the direct threshold: one pixel's count is hypergeometric."""
        pool, size, draws = [300, 500, 200], 600, 10**4
        counts, segment = rows(pool, draws)
        y = hg.multivariate_hypergeometric(
            counts, segment, torch.full((draws,), size), generator=torch.Generator().manual_seed(6)
        ).view(draws, 3)
        pmf = hypergeometric_pmf(500, 1000, size)
        assert chi_square_p_value(Counter(y[:, 1].tolist()), pmf, draws) > 1e-3

    def test_large_single_pixel_moments(self):
        """10**7 events in one of two pixels: mean and variance of the hypergeometric law."""
        pool, size, draws = [10**7, 10**7], 10**7 // 2, 4000
        counts, segment = rows(pool, draws)
        y = hg.multivariate_hypergeometric(
            counts, segment, torch.full((draws,), size), generator=torch.Generator().manual_seed(7)
        ).view(draws, 2)[:, 0].double()
        n, good = sum(pool), pool[0]
        mean = size * good / n
        var = size * good / n * (1 - good / n) * (n - size) / (n - 1)
        assert abs(y.mean().item() - mean) < 5 * math.sqrt(var / draws)
        assert y.var().item() == pytest.approx(var, rel=0.1)

    def test_many_rows_one_entry_each(self):
        """Rows outnumber entries' budget: the final draw runs in bounded chunks."""
        counts, segment = rows([100], 5000)
        sizes = torch.randint(0, 101, (5000,), generator=torch.Generator().manual_seed(2))
        y = hg.multivariate_hypergeometric(counts, segment, sizes, generator=torch.Generator().manual_seed(2))
        assert torch.equal(y, sizes)  # one pixel per row: everything drawn comes from it
        counts, segment = rows([60, 40], 3000)
        sizes = torch.full((3000,), 30)
        y = hg.multivariate_hypergeometric(counts, segment, sizes, generator=torch.Generator().manual_seed(3))
        self.check_invariants(counts, segment, sizes, y)
        pmf = hypergeometric_pmf(60, 100, 30)
        assert chi_square_p_value(Counter(y[0::2].tolist()), pmf, 3000) > 1e-3

    def test_reproducible(self):
        counts, segment = rows([3, 9, 0, 40, 200], 50)
        sizes = torch.randint(0, 252, (50,), generator=torch.Generator().manual_seed(1))
        a = hg.multivariate_hypergeometric(counts, segment, sizes, generator=torch.Generator().manual_seed(3))
        b = hg.multivariate_hypergeometric(counts, segment, sizes, generator=torch.Generator().manual_seed(3))
        assert torch.equal(a, b)
