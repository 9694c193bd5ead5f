"""One source of randomness: the counter-based streams of ``functional/_random.py``.

(a) The numbers are integer arithmetic only: the library's tensors equal a plain-Python
    integer implementation (``tests/support/random_reference.py``) bit for bit, and no event
    kernel dispatches a torch RNG op (whose engine differs between the CPU and CUDA), so
    the same params tree gives the same events on every device.
(b) Ops per call independent of B: ``tests/library/test_host_syncs.py``.
(c) The distributions the kernels promise, on fixed seeds (deterministic: cannot flake).
"""

from __future__ import annotations

import math

import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

import event_transforms as et
from event_transforms import functional as F
from event_transforms.functional._event_ops import DROP_KEYS, JITTER, TIME_JITTER
from event_transforms.functional._random import EventStream, poisson_counts, sample_salts, uniform

from tests.support.op_cases import EVENT_CASES, event_batch

from tests.support import random_reference as reference

SEEDS = [0, 1, 7, 2**31 - 1, 2**31, 2**32 + 5, 2**62 + 12345, 2**63 - 1]


# --------------------------------------------------------------------------- (a) the same numbers anywhere


def test_event_streams_equal_the_python_integer_hash():
    lengths = torch.tensor([3, 0, 5, 1, 4, 2, 6, 3])
    stream = EventStream(torch.tensor(SEEDS), lengths, "cpu")
    expected_u, expected_u32, expected_n = [], [], []
    for seed, n in zip(SEEDS, lengths.tolist()):
        expected_u += [reference.uniform(seed, i, 4) for i in range(n)]
        expected_u32 += [reference.uniform32(seed, i, DROP_KEYS) for i in range(n)]
        expected_n += [reference.normal_pair(seed, i, JITTER) for i in range(n)]
    assert stream.uniform(4).tolist() == expected_u  # bit for bit
    assert stream.uniform32(DROP_KEYS).tolist() == expected_u32
    # float32 Box-Muller against float64: the same numbers to float32 precision
    torch.testing.assert_close(torch.stack(stream.normal_pair(JITTER), 1).double(),
                               torch.tensor(expected_n, dtype=torch.float64), rtol=2e-6, atol=2e-6)


def test_counter_uniforms_equal_the_python_integer_hash_with_64_bit_counters():
    counters = torch.tensor([0, 1, 2**31 - 1, 2**31, 2**32 + 7, 2**40 + 3], dtype=torch.int64)
    for seed in SEEDS:
        got = uniform(sample_salts(torch.tensor([seed]), "cpu"), counters, 9).tolist()
        assert got == [reference.stream_uniform(seed, c, 9) for c in counters.tolist()]


def test_streams_build_on_the_meta_device():
    """Tensor ops only: the draw of a sample runs where no value can be read."""
    stream = EventStream(torch.tensor([3, 4], device="meta"), torch.tensor([5, 2]), "meta")
    assert stream.uniform32(1).device.type == "meta" and stream.normal(2).shape == (7,)


_RNG_OPS = ("uniform", "normal", "rand", "bernoulli", "poisson", "binomial", "multinomial", "random_",
            "exponential", "geometric", "cauchy", "log_normal", "randperm")


class _Ops(TorchDispatchMode):
    def __init__(self):
        super().__init__()
        self.names: list[str] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.names.append(func.__name__)
        return func(*args, **(kwargs or {}))


@pytest.mark.parametrize("name", sorted(EVENT_CASES))
def test_event_kernels_use_no_engine(name):
    """Given a params tree, no event kernel calls a torch RNG op (Mersenne Twister on the
    CPU, Philox on CUDA: different numbers): its randomness is the integer hash above."""
    module, batch = EVENT_CASES[name](), event_batch(4)
    params = module.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(0))
    with _Ops() as ops:
        module(batch, params=params)
    assert ops.names  # the mode saw the kernel
    assert not [n for n in ops.names if any(r in n for r in _RNG_OPS)], ops.names


def test_a_params_tree_gives_the_same_events_in_any_batch_order():
    """A sample's numbers are named by its own seed and its events' positions: reordering
    the batch reorders the output and changes nothing else."""
    batch = event_batch(5, seed=3)
    module = et.SpatialJitter(1.5)
    params = module.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(2))
    out = module(batch, params=params)
    order = [4, 2, 0, 3, 1]
    swapped = module(F.EventBatch.from_streams(
        [torch.stack([batch[i].x, batch[i].y, batch[i].t, batch[i].p], 1).long() for i in order],
        sensor_size=batch.sensor_size, frame_ms=1.0, t_start=0, n_frames=6), params={
            k: v[order] for k, v in params.items()})
    for j, i in enumerate(order):
        assert torch.equal(swapped[j].x, out[i].x) and torch.equal(swapped[j].y, out[i].y)


# --------------------------------------------------------------------------- (c) distributions, fixed seeds


def _big_batch(n: int = 20_000, b: int = 4) -> F.EventBatch:
    x = torch.arange(n) % 17
    streams = [torch.stack([x, (x * 3) % 11, (torch.arange(n) * 6000) // n, x % 2], 1) for _ in range(b)]
    return F.EventBatch.from_streams(streams, sensor_size=(11, 17), frame_ms=1.0, t_start=0, n_frames=6)


def test_uniforms_are_uniform_and_purposes_independent():
    stream = EventStream(torch.tensor([11, 12, 13, 14]), torch.full((4,), 25_000), "cpu")
    u, v = stream.uniform(1), stream.uniform(2)
    n = u.numel()
    assert abs(u.mean().item() - 0.5) < 5 * math.sqrt(1 / 12 / n)
    # Kolmogorov-Smirnov: the largest gap to the uniform CDF, against its 0.1 % critical value
    for w in (u, stream.uniform32(3).double()):
        ks = (w.sort().values - (torch.arange(n, dtype=torch.float64) + 0.5) / n).abs().max().item()
        assert ks < 1.95 / math.sqrt(n)
    assert abs(torch.corrcoef(torch.stack([u, v]))[0, 1].item()) < 5 / math.sqrt(n)
    # consecutive events of a sample are uncorrelated
    assert abs(torch.corrcoef(torch.stack([u[:-1], u[1:]]))[0, 1].item()) < 5 / math.sqrt(n)


def test_event_drop_rate():
    batch = _big_batch()
    fraction = torch.tensor([0.1, 0.3, 0.5, 0.9])
    out = F.drop_random_events(batch, fraction, "binomial", torch.tensor([1, 2, 3, 4]))
    for b, (rho, n) in enumerate(zip(fraction.tolist(), batch.lengths)):
        kept = out.lengths[b]
        assert abs(kept - (1 - rho) * n) < 5 * math.sqrt(n * rho * (1 - rho))
    assert F.drop_random_events(batch, torch.tensor([0.0, 1.0, 0.0, 1.0]), "binomial",
                                torch.tensor([5, 6, 7, 8])).lengths == [batch.lengths[0], 0, batch.lengths[2], 0]


def test_jitter_std_and_shape():
    batch = _big_batch()
    sigma = torch.tensor([0.5, 1.0, 2.0, 4.0])
    out = F.spatial_jitter_events(batch, sigma, torch.tensor([9, 8, 7, 6]))
    for b, s in enumerate(sigma.tolist()):
        dx = (out[b].x.double() - batch[b].x.double())
        dy = (out[b].y.double() - batch[b].y.double())
        n = dx.numel()
        want = math.sqrt(s * s + 1 / 12)  # the rounding to whole pixels adds a uniform's variance
        for d in (dx, dy):
            assert abs(d.mean().item()) < 5 * want / math.sqrt(n)
            assert abs(d.std().item() / want - 1) < 5 / math.sqrt(2 * n)
        assert abs(torch.corrcoef(torch.stack([dx, dy]))[0, 1].item()) < 5 / math.sqrt(n)


def test_time_jitter_is_gaussian():
    batch = _big_batch()
    batch = batch._replace(t=batch.t.double())  # float timestamps: no rounding
    std = torch.tensor([10.0, 50.0, 200.0, 1000.0])
    out = F.time_jitter_events(batch, std, torch.tensor([1, 2, 3, 4]))
    for b, s in enumerate(std.tolist()):
        z = ((out[b].t - batch[b].t) / s).sort().values
        n = z.numel()
        assert abs(z.mean().item()) < 5 / math.sqrt(n)
        assert abs(z.std().item() - 1) < 5 / math.sqrt(2 * n)
        cdf = 0.5 * (1 + torch.erf(z / math.sqrt(2)))
        ks = (cdf - (torch.arange(n, dtype=torch.float64) + 0.5) / n).abs().max().item()
        assert ks < 1.95 / math.sqrt(n)  # Kolmogorov-Smirnov at 0.1 %


@pytest.mark.parametrize("lam", [0.0, 0.05, 3.0, 40.0, 2_500.0, 1e6, 3e9])
def test_poisson_counts_mean_and_variance(lam):
    n = 4000
    counts = poisson_counts(torch.arange(n), torch.full((n,), lam), purpose=3).double()
    if lam == 0:
        assert counts.sum() == 0
        return
    assert abs(counts.mean().item() - lam) < 5 * math.sqrt(lam / n)
    # the variance of the sample variance of a Poisson is about (2 lam^2 + lam) / n
    assert abs(counts.var().item() - lam) < 5 * math.sqrt((2 * lam * lam + lam) / n)


def test_poisson_counts_refuse_means_past_the_search():
    with pytest.raises(ValueError, match="Poisson means"):
        poisson_counts(torch.tensor([1]), torch.tensor([1e13]), purpose=3)


def test_poisson_counts_probabilities():
    lam = 3.0
    counts = poisson_counts(torch.arange(20_000), torch.full((20_000,), lam), purpose=3)
    n = counts.numel()
    chi2 = 0.0
    for k in range(9):
        p = math.exp(-lam) * lam**k / math.factorial(k)
        chi2 += ((counts == k).sum().item() - n * p) ** 2 / (n * p)
    assert chi2 < 27.9  # chi-square, 8 degrees of freedom, 0.05 %


def test_poisson_noise_events_rate_and_uniform_placement():
    batch = _big_batch(n=10, b=4)
    rate = torch.tensor([500.0, 1000.0, 2000.0, 4000.0])
    out = F.add_poisson_noise_events(batch, rate, torch.tensor([1, 2, 3, 4]))
    cells = 2 * 11 * 17
    for b, r in enumerate(rate.tolist()):
        expected = r * 6e-3 * cells
        stream = out[b]
        n = stream.num_events - 10  # the added events follow the stream's own 10
        assert stream.x[:10].tolist() == batch[b].x.tolist()
        assert abs(n - expected) < 5 * math.sqrt(expected)
        for column, size in ((stream.x, 17), (stream.y, 11), (stream.p, 2)):
            values = column[10:].double()
            assert abs(values.mean().item() - (size - 1) / 2) < 5 * size / math.sqrt(12 * n)
            assert values.min() >= 0 and values.max() <= size - 1
        t = stream.t[10:].double()
        assert abs(t.mean().item() - 3000) < 5 * 6000 / math.sqrt(12 * n) and t.min() >= 0 and t.max() < 6000


def test_tes_binomial_rate_on_events():
    batch = _big_batch()
    out = F.temporal_event_shift_events(batch, torch.tensor([1, 1, 1, 1]), torch.tensor([0.2, 0.4, 0.6, 0.8]),
                                        "binomial", torch.tensor([4, 3, 2, 1]))
    for b, zeta in enumerate((0.2, 0.4, 0.6, 0.8)):
        inside = batch[b].t < 5000  # events of the last bin leave the window when moved
        n = int(inside.sum())
        moved = int((out[b].t[: batch.lengths[b]] != batch[b].t).sum()) if out.lengths[b] == batch.lengths[b] else None
        # the stream keeps its order: an event moved out of the window is gone
        gone = batch.lengths[b] - out.lengths[b]
        last = batch.lengths[b] - n
        assert abs(gone - zeta * last) < 5 * math.sqrt(last * zeta * (1 - zeta))
        assert moved is None or abs(moved - zeta * n) < 5 * math.sqrt(n * zeta * (1 - zeta))


def test_time_jitter_reference_purpose_is_its_own():
    """Two kernels with the same seed draw different numbers (their purposes differ)."""
    batch = _big_batch(n=1000, b=1)
    a = EventStream.of_batch(batch, torch.tensor([5])).normal(TIME_JITTER)
    b = EventStream.of_batch(batch, torch.tensor([5])).normal(JITTER)
    assert abs(torch.corrcoef(torch.stack([a, b]))[0, 1].item()) < 5 / math.sqrt(1000)
