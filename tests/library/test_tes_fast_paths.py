"""The faster exact-TES paths against the slower forms they replace,
bit for bit: the integer threshold of the binomial level, the inversion table cut at the
largest count, the two finishes in one call, and numpy's nonzero on the CPU."""

from __future__ import annotations

import pytest
import torch

import event_transforms as et
from event_transforms.functional import _hypergeometric as hg
from event_transforms.functional import _random
from event_transforms.functional import temporal


def _probabilities() -> torch.Tensor:
    edges = [0.0, 1.0, 0.5, 2.0**-33, 2.0**-32, 1.5 * 2.0**-32, 2.0**-31, 0.25, 0.75, 1 - 2.0**-33, 1 - 2.0**-32,
             1 - 2.0**-53, 0.1, 0.3, 1 / 3]
    # p at, and one float64 step either side of, the uniforms' grid (k + 1/2) 2**-32
    grid = (torch.tensor([0, 1, 2, 2**31 - 1, 2**31, 2**32 - 2, 2**32 - 1], dtype=torch.float64) + 0.5) * 2.0**-32
    steps = torch.cat([grid, grid.nextafter(torch.tensor(2.0, dtype=torch.float64)),
                       grid.nextafter(torch.tensor(-1.0, dtype=torch.float64))])
    random = torch.rand(200, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    return torch.cat([torch.tensor(edges, dtype=torch.float64), steps.clamp(0, 1), random])


def test_integer_threshold_equals_the_float64_uniform_comparison():
    """u = (x + 2**31 + 1/2) 2**-32 < p  <=>  x < ceil(p 2**32 - 1/2) - 2**31, for every int32 x
    near each threshold and at both ends of the range."""
    prob = _probabilities()
    below = hg._hash_thresholds(prob)
    offsets = torch.arange(-3, 4)
    near = (below.unsqueeze(1) + offsets).clamp(-(2**31), 2**31 - 1)
    ends = torch.tensor([-(2**31), -(2**31) + 1, 0, 2**31 - 2, 2**31 - 1]).expand(prob.numel(), 5)
    x = torch.cat([near, ends], 1).to(torch.int32)
    u = (x.to(torch.float64) + (2**31 + 0.5)) * 2.0**-32
    assert torch.equal(u < prob.unsqueeze(1), x < below.unsqueeze(1))


def test_binomial_counts_equal_the_float64_uniforms():
    """binomial_counts (integer thresholds) keeps exactly the events whose sub_uniform is below p."""
    g = torch.Generator().manual_seed(3)
    counts = torch.randint(0, 9, (500,), generator=g)
    key = torch.randint(0, 4, (500,), generator=g)
    prob = torch.tensor([0.0, 1.0, 0.37, 2.0**-32], dtype=torch.float64)
    sample = torch.arange(500) // 100
    stream = hg.Stream.of_samples(torch.arange(5) + 11, sample, torch.arange(500) % 100, 1)
    got = hg.binomial_counts(counts, prob, key, stream=stream, level=1)
    keys = _random.entry_keys(stream.entry_salt, stream.entry_counter)
    owner = torch.repeat_interleave(counts)
    within = torch.arange(owner.numel()) - (counts.cumsum(0) - counts)[owner]
    hit = _random.sub_uniform(keys[owner], within, 1) < prob[key][owner]
    want = torch.zeros(500, dtype=torch.int64).index_add_(0, owner, hit.long())
    assert torch.equal(got, want)
    assert got[prob[key] == 0].sum() == 0 and torch.equal(got[prob[key] == 1], counts[prob[key] == 1])


@pytest.mark.parametrize("high", [9, 20, 40, 62, 63, 100])
def test_inversion_table_cut_at_the_largest_count_gives_the_same_draws(high):
    g = torch.Generator().manual_seed(high)
    n = torch.randint(0, high + 1, (400,), generator=g)
    n[0] = high
    prob = torch.rand(400, generator=g, dtype=torch.float64)
    prob[:5] = torch.tensor([0.0, 1.0, 0.5, 1e-9, 1 - 1e-9], dtype=torch.float64)
    keys = _random.entry_keys(_random.sample_salts(torch.tensor([5]), "cpu"), torch.arange(400))
    assert torch.equal(_random.binomial_large(keys, n, prob, 9, high), _random.binomial_large(keys, n, prob, 9))


def test_two_finishes_in_one_call_equal_a_call_per_level():
    """_small_subsets with ``deeper`` rows (named by level + 1) equals one call per level."""
    g = torch.Generator().manual_seed(4)
    rows, per_row = 12, 30
    pool = torch.randint(0, 6, (rows * per_row,), generator=g)
    segment = torch.arange(rows).repeat_interleave(per_row)
    total = hg.segment_sum(pool, segment, rows)
    size = (torch.rand(rows, generator=g) * total).round().long()
    size[0], size[1] = 0, total[1]  # nothing and everything
    deeper = torch.rand(rows, generator=g) < 0.5
    stream = hg.Stream.of_samples(torch.tensor([21, 22]), segment // (rows // 2) // per_row,
                                  torch.arange(rows * per_row), rows // 2)
    width = int(torch.minimum(size, total - size).max())
    both = hg._small_subsets(pool, segment, size, total, stream, width, 0, deeper)
    zero = torch.zeros_like(size)
    first = hg._small_subsets(pool, segment, torch.where(deeper, zero, size), total, stream, width, 0)
    second = hg._small_subsets(pool, segment, torch.where(deeper, size, zero), total, stream, width, 1)
    # each row is taken from its own level's call (a row of size 0 draws nothing in the other)
    want = torch.where(deeper.index_select(0, segment), second, first)
    assert torch.equal(both, want)
    assert torch.equal(hg.segment_sum(both, segment, rows), size)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float16, torch.bfloat16, torch.float64, torch.uint8,
                                   torch.int16, torch.int32, torch.int64])
def test_numpy_nonzero_equals_torch_nonzero(dtype, monkeypatch):
    frames = torch.poisson(torch.full((3, 5, 2, 7, 9), 0.4), generator=torch.Generator().manual_seed(6)).to(dtype)
    if dtype.is_floating_point:
        frames[0, 1, 0, 2, 3] = -0.0  # an entry holding 0 in both paths
    fast = temporal._entries(frames)
    monkeypatch.setattr(temporal, "_NUMPY_NONZERO", ())
    slow = temporal._entries(frames)
    for a, b in zip(fast, slow):
        assert a.dtype == b.dtype and torch.equal(a, b)
    out = et.functional.temporal_event_shift(frames, -1, 0.5, generator=torch.Generator().manual_seed(1))
    monkeypatch.undo()
    again = et.functional.temporal_event_shift(frames, -1, 0.5, generator=torch.Generator().manual_seed(1))
    assert torch.equal(out.view(torch.uint8) if dtype.is_floating_point else out,
                       again.view(torch.uint8) if dtype.is_floating_point else again)
