"""The eager CPU fast paths pinned bit for bit.

Each fast path is held equal to a slow, obvious reference or to the formulation it replaced,
on seeded inputs and the hard cases: the batch binning (memset-zeroed blocks, dropped counts
by ``count_nonzero``, no copy of the times for a zero start) against a loop over events;
the centre of mass without ``nan_to_num`` against the copy it skips, NaN and ±Inf included;
the host-hashed sample keys and the int32-lane 53-bit uniforms against the tensor hash;
Poisson noise's sparse path against its former gather formulation; the CPU compaction
against a mask loop.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

import event_transforms as et
from event_transforms import EventBatch
from event_transforms.events._kernel import _zeroed
from event_transforms.events.binning import bin_events
from event_transforms.functional._event_ops import _kept
from event_transforms.functional._random import (
    _GOLDEN, _hash, _mix, entry_keys, sample_keys, sample_salts, uniform53,
)
from event_transforms.functional._warp import _mass_weight
from event_transforms.functional.noise import _add_poisson_noise

SENSOR = (6, 7)


def _streams(seed: int, sizes: list[int], sensor: tuple[int, int] = SENSOR, span: int = 40_000,
             margin: int = 0) -> list[torch.Tensor]:
    """(N, 4) int64 streams (x, y, t, p); ``margin`` pixels and 10 ms of time past each edge."""
    g = torch.Generator().manual_seed(seed)
    out = []
    for n in sizes:
        x = torch.randint(-margin, sensor[1] + margin, (n,), generator=g)
        y = torch.randint(-margin, sensor[0] + margin, (n,), generator=g)
        t = torch.randint(-10_000 if margin else 0, span + (10_000 if margin else 0), (n,), generator=g)
        p = torch.randint(0, 2, (n,), generator=g)
        out.append(torch.stack([x, y, t, p], 1))
    return out


def _reference(streams: list[torch.Tensor], n_frames: int, frame_us: int, sensor: tuple[int, int],
               crop: tuple[int, int, int, int] | None = None, pool: int = 1) -> tuple[np.ndarray, int, int]:
    """(B, T, 2, H', W') int64 counts by a loop over events, and the events off the sensor
    and on it outside the window (start 0)."""
    height, width = sensor
    top, left, ch, cw = crop or (0, 0, height, width)
    out = np.zeros((len(streams), n_frames, 2, ch // pool, cw // pool), dtype=np.int64)
    off = late = 0
    for b, s in enumerate(streams):
        for x, y, t, p in s.tolist():
            if not (0 <= x < width and 0 <= y < height):
                off += 1
                continue
            k = t // frame_us
            if not 0 <= k < n_frames:
                late += 1
                continue
            r, c = y - top, x - left
            if 0 <= r < ch - ch % pool and 0 <= c < cw - cw % pool:
                out[b, k, int(p > 0), r // pool, c // pool] += 1
    return out, off, late


def _batch(streams: list[torch.Tensor], n_frames: int, sensor: tuple[int, int] = SENSOR) -> EventBatch:
    """The streams as a batch on a 10 ms grid from 0, events off the sensor kept (as a
    transform leaves them: the constructor, not from_streams, which drops them)."""
    columns = torch.cat([torch.zeros(0, 4, dtype=torch.int64), *streams])
    offsets = torch.tensor([0, *np.cumsum([len(s) for s in streams], dtype=np.int64).tolist()])
    batch = EventBatch(columns[:, 0].to(torch.int16), columns[:, 1].to(torch.int16), columns[:, 2],
                       columns[:, 3].to(torch.int8), offsets, sensor)
    return batch.with_grid(10.0, t_start=0, n_frames=n_frames)


@pytest.fixture(params=["scratch", "masks"])
def binning_path(request, monkeypatch):
    """Both CPU batch paths: the scratch blocks, and the masks (blocks past the scratch size)."""
    if request.param == "masks":
        monkeypatch.setattr("event_transforms.events._kernel._SCRATCH_BYTES", 0)
    return request.param


@pytest.mark.parametrize("sizes", [[300, 0, 1, 257], [1], [0, 0], []])
@pytest.mark.parametrize("crop,pool", [(None, 1), ((1, 2, 4, 4), 2)])
def test_batch_binning_equals_a_loop_and_counts_what_it_drops(sizes, crop, pool, binning_path):
    streams = _streams(len(sizes) + 7 * pool, sizes, margin=2)
    batch = _batch(streams, 4)
    t_before = batch.t.clone()
    with et.count_dropped() as dropped:
        frames = bin_events(batch, crop=crop, pool=pool, dtype=torch.int64)
    expected, off, late = _reference(streams, 4, 10_000, SENSOR, crop, pool)
    assert sum(sizes) < 300 or (off and late)  # the big cases drop both kinds
    assert torch.equal(frames, torch.from_numpy(expected))
    assert dropped.counts().get("off_sensor", 0) == off
    assert dropped.counts().get("out_of_window", 0) == late
    assert torch.equal(batch.t, t_before)  # the zero-start path reads t in place, never writes it
    assert torch.equal(bin_events(batch, crop=crop, pool=pool, dtype=torch.int64), frames)  # not counting
    late_start = batch.with_grid(10.0, t_start=-10_000, n_frames=5)  # a start other than 0: t - start
    assert torch.equal(bin_events(late_start, crop=crop, pool=pool, dtype=torch.int64)[:, 1:], frames)


@pytest.mark.parametrize("dtype", [torch.uint8, torch.int16, torch.float16, torch.bfloat16, torch.float32])
def test_batch_binning_dtypes_at_their_limits_and_one_frame(dtype, binning_path):
    exact = {torch.uint8: 255, torch.int16: 32767, torch.float16: 2048, torch.bfloat16: 256, torch.float32: 2**24}
    limit = min(exact[dtype], 40_000)
    pile = torch.tensor([[3, 2, 5, 1]]).repeat(limit, 1)  # every event in one pixel of the one frame
    streams = [pile, *_streams(3, [50])]
    frames = bin_events(_batch(streams, 1), dtype=dtype)
    expected, _, _ = _reference(streams, 1, 10_000, SENSOR)
    assert frames.dtype == dtype and frames.shape == (2, 1, 2, *SENSOR)
    assert torch.equal(frames.to(torch.float64), torch.from_numpy(expected).to(torch.float64))
    if exact[dtype] < 40_000:  # one more event than the dtype counts exactly: refused by name
        with pytest.raises(ValueError, match="dtype"):
            bin_events(_batch([torch.cat([pile, pile[:1]])], 1), dtype=dtype)


def test_batch_binning_a_million_events_in_one_pixel(binning_path):
    pile = torch.tensor([[0, 0, 9_999, 0]]).repeat(10**6, 1)
    frames = bin_events(_batch([pile, torch.tensor([[1, 1, 0, 1]])], 2, (2, 2)))
    assert frames[0, 0, 0, 0, 0].item() == 10**6 and frames[1, 0, 1, 1, 1].item() == 1
    assert frames.sum().item() == 10**6 + 1


def test_zeroed_writes_positive_zeros_in_place():
    for dtype in (torch.float32, torch.bfloat16, torch.int16, torch.uint8, torch.int64):
        values = torch.full((37,), -3).to(dtype)
        assert _zeroed(values) is values
        assert torch.equal(values, torch.zeros(37, dtype=dtype))
        if dtype.is_floating_point:
            assert not torch.signbit(values).any()
    strided = torch.full((4, 6), 5.0)[:, ::2]
    assert torch.equal(_zeroed(strided), torch.zeros(4, 3)) and _zeroed(torch.empty(0)).numel() == 0


def _mass_weight_reference(batch: torch.Tensor) -> torch.Tensor:
    b, t, p, h, w = batch.shape
    flat = batch.reshape(b, t * p, h * w).to(torch.float32)
    flat = torch.nan_to_num(flat, nan=0.0, posinf=0.0, neginf=0.0)
    return torch.matmul(torch.ones(1, t * p), flat).view(b, h, w)


@pytest.mark.parametrize("poison", [None, float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float16, torch.bfloat16])
def test_mass_weight_equals_the_nan_to_num_copy(poison, dtype):
    batch = torch.poisson(torch.full((3, 5, 2, 4, 6), 2.0), generator=torch.Generator().manual_seed(1)).to(dtype)
    if poison is not None:
        batch[1, 2, 0, 3, 4] = poison
    assert torch.equal(_mass_weight(batch), _mass_weight_reference(batch))
    huge = torch.full((1, 2, 2, 2, 2), 3e38)  # finite entries whose sum overflows: inf either way
    assert torch.equal(_mass_weight(huge), _mass_weight_reference(huge))


def test_centre_of_mass_ignores_non_finite_pixels_as_before():
    frames = torch.poisson(torch.full((2, 3, 2, 9, 11), 1.0), generator=torch.Generator().manual_seed(2))
    frames[0, 1, 0, 4, 4] = float("nan")
    frames[1, 0, 1, 2, 7] = float("inf")
    assert torch.equal(et.functional.center_of_mass(frames), et.functional.center_of_mass(frames.nan_to_num(0.0, 0.0, 0.0)))


SEEDS = [0, 1, 7, 2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**62 + 5, 2**63 - 1]


def test_sample_keys_equal_the_tensor_hash():
    seeds = torch.tensor(SEEDS)
    seeds = torch.cat([seeds, torch.randint(0, 2**63 - 1, (200,), generator=torch.Generator().manual_seed(3))])
    zero = torch.zeros(1, dtype=torch.int64)
    expected = entry_keys(sample_salts(seeds, "cpu"), zero)
    assert torch.equal(sample_keys(seeds, "cpu"), expected)
    assert sample_keys(seeds, "cpu").dtype == torch.int32
    assert sample_keys(seeds[:0], "cpu").shape == (0,)


def _to53_int64(first: torch.Tensor) -> torch.Tensor:
    """The former 53-bit formula on int64 lanes."""
    second = _mix(first ^ _GOLDEN)
    high = first.to(torch.int64) & 0xFFFFFFFF
    low = second.to(torch.int64) & 0xFFFFFFFF
    return ((high >> 6) * 2**27 + (low >> 5)).to(torch.float64) * 2.0**-53


def test_53_bit_uniforms_equal_the_int64_formula():
    salt = sample_salts(torch.tensor(SEEDS), "cpu").view(-1, 1)
    counter = torch.arange(5000).view(1, -1)
    for purpose in (0, 3, 11):
        expected = _to53_int64(_hash(salt, counter, purpose))
        got = uniform53(salt, counter, purpose)
        assert torch.equal(got, expected)
        assert float(got.min()) >= 0.0 and float(got.max()) < 1.0
    edge = torch.tensor([0, -1, 2**31 - 1, -(2**31), 1, -2], dtype=torch.int32)
    from event_transforms.functional._random import _to53

    assert torch.equal(_to53(edge), _to53_int64(edge))


def _poisson_reference(batch: torch.Tensor, totals: torch.Tensor, seeds: torch.Tensor) -> torch.Tensor:
    """The sparse Poisson path as it was: a gather of each event's sample and key."""
    cells = batch[0].numel()
    count = sum(totals.tolist())
    sample = torch.repeat_interleave(torch.arange(batch.shape[0]), totals, output_size=count)
    within = torch.arange(count) - (totals.cumsum(0) - totals).index_select(0, sample)
    keys = entry_keys(sample_salts(seeds, "cpu"), torch.zeros(1, dtype=torch.int64))
    position = (_to53_int64(_hash_sub(keys.index_select(0, sample), within)) * cells).to(torch.int64)
    flat = batch.clone().view(-1)
    flat.index_add_(0, sample * cells + position.clamp_max_(cells - 1), torch.ones(count, dtype=batch.dtype))
    return flat.view(batch.shape)


def _hash_sub(keys: torch.Tensor, within: torch.Tensor) -> torch.Tensor:
    from event_transforms.functional._random import _sub_hash

    return _sub_hash(keys, within, 0)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float16, torch.int16, torch.int64])
@pytest.mark.parametrize("totals", [[5, 0, 3000, 1], [0], [7], [0, 0]])
def test_sparse_poisson_noise_equals_the_gather_formulation(dtype, totals):
    batch = torch.poisson(torch.full((len(totals), 3, 2, 5, 7), 1.0), generator=torch.Generator().manual_seed(4))
    batch = batch.to(dtype)
    totals = torch.tensor(totals)
    seeds = torch.randint(0, 2**63 - 1, (len(totals),), generator=torch.Generator().manual_seed(5))
    got = _add_poisson_noise(batch, torch.full((len(totals),), 0.05, dtype=torch.float64), totals=totals, seeds=seeds)
    assert got.dtype == dtype
    assert torch.equal(got, _poisson_reference(batch, totals, seeds))
    if len(totals) > 1:  # a sample's noise depends on its own seed only
        alone = _add_poisson_noise(batch[1:2], torch.full((1,), 0.05, dtype=torch.float64), totals=totals[1:2],
                                   seeds=seeds[1:2])
        assert torch.equal(alone[0], got[1])


def test_sparse_poisson_noise_refuses_overflow_of_a_narrow_dtype():
    batch = torch.full((1, 1, 2, 1, 1), 255, dtype=torch.uint8)
    with pytest.raises(ValueError, match="overflows"):
        _add_poisson_noise(batch, torch.tensor([1.0], dtype=torch.float64), totals=torch.tensor([3]),
                           seeds=torch.tensor([1]))


@pytest.mark.parametrize("sizes", [[5, 0, 9, 1], [0], [3], []])
@pytest.mark.parametrize("share", [0.0, 0.4, 1.0])
def test_cpu_compaction_equals_a_mask_loop(sizes, share):
    batch = _batch(_streams(8, sizes), 4)
    keep = torch.rand(batch.num_events, generator=torch.Generator().manual_seed(6)) < share
    index, offsets = _kept(batch, keep)
    assert torch.equal(index, torch.arange(batch.num_events)[keep])
    bounds = batch.offsets.tolist()
    lengths = [int(keep[a:b].sum()) for a, b in zip(bounds[:-1], bounds[1:])]
    assert offsets.tolist() == np.concatenate([[0], np.cumsum(lengths, dtype=np.int64)]).tolist()
    assert offsets.device.type == "cpu" and offsets.dtype == torch.int64


@pytest.mark.parametrize("sizes", [[5, 0, 9, 1], [0], [3], [], [0, 0, 4]])
def test_sample_index_equals_a_loop(sizes):
    batch = _batch(_streams(9, sizes), 4)
    expected = [b for b, n in enumerate(sizes) for _ in range(n)]
    got = batch.sample_index()
    assert got.dtype == torch.int32 and got.tolist() == expected
