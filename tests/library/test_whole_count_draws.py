"""Counter-based whole-count draws: the exact binomial of counts above the
expansion limit, dense Poisson noise per cell, and the Beta weights of CutMix/MixUp."""

from __future__ import annotations

import math
from collections import Counter

import pytest
import torch

import event_transforms as et
from event_transforms.functional import _hypergeometric as hg
from event_transforms.functional import _random
from event_transforms.transforms.mixing import _beta

from tests.support import random_reference as ref
from tests.support.event_data import OP_COUNTS_CHECKED
from tests.library.test_hypergeometric import chi_square_p_value


def _keys(seed: int, m: int) -> torch.Tensor:
    return _random.entry_keys(_random.sample_salts(torch.tensor([seed]), "cpu"), torch.arange(m))


def binomial_pmf(n: int, p: float, low: int, high: int) -> dict[int, float]:
    """P(K = k) for k in [low, high], in logs (lgamma): exact enough for n = 10**6."""
    if p in (0.0, 1.0):
        return {0 if p == 0.0 else n: 1.0}
    log_norm = math.lgamma(n + 1)
    return {
        k: math.exp(log_norm - math.lgamma(k + 1) - math.lgamma(n - k + 1) + k * math.log(p) + (n - k) * math.log1p(-p))
        for k in range(max(low, 0), min(high, n) + 1)
    }


# (n, p): both routes (inversion when n min(p, 1 - p) < 10, BTRS otherwise), mirrored p > 1/2,
# n just above the expansion limit, and n = 10**6 with p near 0, 1/2 and near 1.
CASES = [
    (9, 0.5), (9, 0.03), (12, 0.9), (19, 0.5), (21, 0.5), (40, 0.3), (100, 0.1), (1000, 0.3),
    (10**6, 1e-6), (10**6, 4e-6), (10**6, 3e-5), (10**6, 0.5), (10**6, 0.99997), (10**6, 1 - 1e-6),
]


@pytest.mark.parametrize("n, p", CASES)
def test_binomial_large_law(n, p):
    draws = 20000
    k = _random.binomial_large(_keys(n % 997, draws), torch.full((draws,), n), torch.full((draws,), p, dtype=torch.float64), 11)
    assert k.dtype == torch.int64 and bool(((k >= 0) & (k <= n)).all())
    mean, var = n * p, n * p * (1 - p)
    z = k.double()
    assert abs(z.mean().item() - mean) <= 5 * math.sqrt(var / draws)
    # the sample variance's standard error is about var sqrt(2 / draws) (plus a kurtosis term)
    assert abs(z.var().item() - var) <= 5 * var * math.sqrt(2 / draws + 1 / (var * draws))
    spread = int(12 * math.sqrt(var)) + 12
    pmf = binomial_pmf(n, p, int(mean) - spread, int(mean) + spread)
    assert chi_square_p_value(Counter(k.tolist()), pmf, draws) > 1e-4


@pytest.mark.parametrize("p", [0.0, 1.0])
def test_binomial_large_certain_probabilities(p):
    n = torch.tensor([0, 9, 10, 10**6, 10**12, 2**52])
    k = _random.binomial_large(_keys(1, 6), n, torch.full((6,), p, dtype=torch.float64), 3)
    assert torch.equal(k, n if p == 1.0 else torch.zeros_like(n))


def test_binomial_large_support_is_exact():
    """Mixed counts and probabilities, both routes in one call: 0 <= k <= n always."""
    g = torch.Generator().manual_seed(5)
    m = 30000
    n = torch.randint(9, 10**6, (m,), generator=g)
    n[::3] = torch.randint(9, 40, (m // 3,), generator=g)
    p = torch.rand(m, generator=g, dtype=torch.float64) ** 3
    p[1::7] = 1 - p[1::7]
    k = _random.binomial_large(_keys(2, m), n, p, 5)
    assert bool(((k >= 0) & (k <= n)).all())


def test_binomial_large_equals_the_python_integer_reference():
    """The same numbers as a plain-Python reference of the key arithmetic and the algorithm
    (tests/support/random_reference.py): the draws are hashes of integers, so they do not depend on
    a device's engine (CPU == CUDA up to the last bits of float64 log/lgamma)."""
    cases = [(n, p) for n in (9, 13, 19, 25, 300, 10**4, 10**6) for p in (0.001, 0.02, 0.3, 0.5, 0.77, 0.999)]
    seed, purpose = 123456789012345, 1_000_004
    counters = torch.arange(len(cases)) * 1_000_003 + 2**33  # 64-bit positions
    keys = _random.entry_keys(_random.sample_salts(torch.tensor([seed]), "cpu"), counters)
    n = torch.tensor([c[0] for c in cases])
    p = torch.tensor([c[1] for c in cases], dtype=torch.float64)
    got = _random.binomial_large(keys, n, p, purpose).tolist()
    expected = [
        ref.binomial_large(ref.entry_key(seed, int(counter)), nn, pp, purpose)
        for counter, (nn, pp) in zip(counters.tolist(), cases)
    ]
    assert [k & 0xFFFFFFFF for k in keys.tolist()] == [ref.entry_key(seed, int(c)) for c in counters.tolist()]
    assert got == expected


def test_binomial_counts_large_entries_are_pure_per_sample():
    """An entry's whole-count draw depends on its sample's seed and its position there only."""
    counts = torch.tensor([3, 50, 10**6, 9, 7, 10**5, 12, 20])
    sample = torch.tensor([0, 0, 0, 0, 1, 1, 1, 1])
    within = torch.tensor([0, 1, 2, 3, 0, 1, 2, 3])
    prob = torch.tensor([0.3, 0.6], dtype=torch.float64)
    seeds = torch.tensor([11, 22])
    stream = hg.Stream.of_samples(seeds, sample, within, 1)
    both = hg.binomial_counts(counts, prob, sample, stream=stream, level=2)
    alone = hg.binomial_counts(
        counts[4:], prob[1:], torch.zeros(4, dtype=torch.int64),
        stream=hg.Stream.of_samples(seeds[1:], torch.zeros(4, dtype=torch.int64), within[4:], 1), level=2,
    )
    assert torch.equal(both[4:], alone)
    other = hg.binomial_counts(
        counts, prob, sample, stream=hg.Stream.of_samples(torch.tensor([99, 22]), sample, within, 1), level=2
    )
    assert torch.equal(other[4:], both[4:]) and not torch.equal(other[:4], both[:4])


def test_exact_tes_conserves_counts_up_to_a_million():
    """Frames whose counts reach 10**6 (both whole-count routes): every row moves exactly
    round(fraction N) events, none is created or lost, each pixel gives at most what it has."""
    g = torch.Generator().manual_seed(8)
    frames = torch.randint(0, 3, (3, 4, 2, 6, 7), generator=g)
    frames[0, 1, 0, :2] = torch.randint(9, 21, (2, 7), generator=g)  # scene-like counts
    frames[1, 2, 1, 3] = torch.randint(10**5, 10**6 + 1, (7,), generator=g)
    frames[2, 0, 0, 0, 0] = 10**6
    frames[2, 3, 1, 5, 6] = 10**6 - 1
    for fraction in (0.2, 0.5, 0.93):
        assert torch.equal(et.functional.temporal_event_shift(frames, 0, fraction), frames)  # shift 0: nothing moves
        out = et.functional.temporal_event_shift(frames, -1, fraction, generator=torch.Generator().manual_seed(3))
        n = frames.sum(dim=(-2, -1)).double()
        kept_first = out[:, 0].sum(dim=(-2, -1)).double()
        # frame 0 loses round(fraction N) of its events off the start; the rest conserve
        assert torch.equal(out.sum(dim=(1, 2, 3, 4)).double(), frames.sum(dim=(1, 2, 3, 4)).double() - torch.round(fraction * n[:, 0]).sum(1))
        assert bool((kept_first <= n[:, 0] + n[:, 1]).all())
        assert bool((out >= 0).all())


# --------------------------------------------------------------------------- dense Poisson noise


def test_poisson_cells_law():
    keys = _random.entry_keys(_random.sample_salts(torch.tensor([4, 5, 6]), "cpu"), torch.zeros(1, dtype=torch.int64))
    lam = torch.tensor([1.0, 3.5, 40.0], dtype=torch.float64)
    counts = _random.poisson_cells(keys, lam, 20000, purpose=1)
    assert counts.shape == (3, 20000) and counts.dtype == torch.int64 and bool((counts >= 0).all())
    for row, rate in zip(counts, lam.tolist()):
        z = row.double()
        assert abs(z.mean().item() - rate) <= 5 * math.sqrt(rate / 20000)
        pmf = {k: math.exp(k * math.log(rate) - rate - math.lgamma(k + 1)) for k in range(int(rate + 15 * math.sqrt(rate) + 15))}
        assert chi_square_p_value(Counter(row.tolist()), pmf, 20000) > 1e-4


def test_dense_poisson_noise_on_frames_is_pure_and_replays():
    module = et.AddPoissonNoise((150.0, 400.0))  # 10 ms frames: 1.5 to 4 events per cell, the dense path
    frames = torch.zeros(5, 3, 2, 8, 9, dtype=torch.int16)
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    out = module(frames, params=params)
    assert out.dtype == torch.int16 and bool((out >= 0).all()) and int(out.sum()) > 0
    assert torch.equal(module(frames, params=params), out)
    for i in range(5):
        alone = module(frames[i : i + 1], params={k: v[i : i + 1] for k, v in params.items()})
        assert torch.equal(alone[0], out[i])


def test_dense_poisson_noise_counts_follow_the_law():
    frames = torch.zeros(2, 10, 2, 40, 50)
    out = et.functional.add_poisson_noise(frames, torch.tensor([120.0, 500.0]), generator=torch.Generator().manual_seed(1))
    for row, rate in zip(out.reshape(2, -1), (1.2, 5.0)):
        assert abs(row.double().mean().item() - rate) <= 5 * math.sqrt(rate / row.numel())
        pmf = {k: math.exp(k * math.log(rate) - rate - math.lgamma(k + 1)) for k in range(40)}
        assert chi_square_p_value(Counter(row.long().tolist()), pmf, row.numel()) > 1e-4


@pytest.mark.skipif(not OP_COUNTS_CHECKED, reason="op counts are budgeted on torch 2.14+")
def test_whole_count_binomial_ops_do_not_grow_with_the_batch():
    """binomial_counts on counts up to 10**6 (inversion and BTRS): the same ops and syncs
    for 4 and 32 samples. Syncs: the expansion stats, the nonzero of the large entries, and
    the two BTRS flags (before the round and after it)."""
    from event_transforms._profiling import count_ops

    def run(b):
        g = torch.Generator().manual_seed(b)
        counts = torch.randint(0, 10**6, (b * 50,), generator=g)
        counts[::2] = torch.randint(0, 20, (b * 25,), generator=g)
        sample = torch.arange(b).repeat_interleave(50)
        stream = hg.Stream.of_samples(torch.arange(b) + 7, sample, torch.arange(50).repeat(b), 1)
        prob = torch.rand(b, generator=g, dtype=torch.float64)
        return count_ops(lambda: hg.binomial_counts(counts, prob, sample, stream=stream))

    small, large = run(4), run(32)
    assert (small.ops, small.syncs) == (large.ops, large.syncs)
    assert small.syncs <= 4


# --------------------------------------------------------------------------- Beta weights of CutMix / MixUp


@pytest.mark.parametrize("alpha", [0.2, 1.0, 4.0])
def test_beta_mean_and_variance(alpha):
    draws = 4000
    x = _beta(alpha, draws, torch.Generator().manual_seed(int(alpha * 10)))
    assert x.dtype == torch.float64 and x.device.type == "cpu" and x.shape == (draws,)
    assert bool(((x >= 0) & (x <= 1)).all())
    var = 1 / (4 * (2 * alpha + 1))
    assert abs(x.mean().item() - 0.5) <= 5 * math.sqrt(var / draws)
    fourth = 3 * (2 * alpha + 1) / (2 * alpha + 3) * var * var  # E(X - 1/2)**4 (excess kurtosis -6 / (2 alpha + 3))
    assert abs(x.var().item() - var) <= 5 * math.sqrt((fourth - var * var) / draws)


def test_beta_is_seeded_and_uses_no_numpy():
    a = _beta(0.4, 64, torch.Generator().manual_seed(3))
    b = _beta(0.4, 64, torch.Generator().manual_seed(3))
    assert torch.equal(a, b) and not torch.equal(a, _beta(0.4, 64, torch.Generator().manual_seed(4)))
    import event_transforms.transforms.mixing as mixing

    assert not hasattr(mixing, "np")
    torch.manual_seed(0)
    c = _beta(0.4, 8, None)
    torch.manual_seed(0)
    assert torch.equal(c, _beta(0.4, 8, None))
