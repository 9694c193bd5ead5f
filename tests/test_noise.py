"""Noise injection (static-scene bank, Poisson) and EventDrop."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import functional as F

from .checkers import H, W, check_not_modified, check_sane, sparse_frames


def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


class TestAddNoise:
    def test_against_loop(self):
        frames = sparse_frames(2, 3, 2, H, W, dtype=torch.int16)
        noise = sparse_frames(2, 3, 2, H, W, seed=1, dtype=torch.int16)
        out = F.add_noise(frames, noise)
        for index in np.ndindex(*frames.shape):
            assert out[index] == frames[index] + noise[index]
        assert out.dtype == torch.int16

    def test_sequence_noise_broadcasts_over_batch(self):
        frames = sparse_frames(4, 3, 2, H, W)
        noise = sparse_frames(3, 2, H, W, seed=1)
        assert torch.equal(F.add_noise(frames, noise), frames + noise)

    def test_overflow_raises_instead_of_wrapping(self):
        frames = torch.full((1, 2, 1, 1), 250, dtype=torch.uint8)
        with pytest.raises(ValueError, match="overflows torch.uint8"):
            F.add_noise(frames, torch.full((1, 2, 1, 1), 10, dtype=torch.uint8))

    def test_bad_noise(self):
        frames = sparse_frames(3, 2, H, W, dtype=torch.int32)
        with pytest.raises(ValueError, match="noise must have"):
            F.add_noise(frames, torch.zeros(3, 2, H, W + 1, dtype=torch.int32))
        with pytest.raises(ValueError, match="noise must hold whole event counts"):
            F.add_noise(frames, torch.full((3, 2, H, W), 0.5))
        with pytest.raises(ValueError, match="noise must hold non-negative"):
            F.add_noise(frames, -torch.ones(3, 2, H, W, dtype=torch.int32))


class TestAddNoiseModule:
    def test_windows_come_from_the_bank(self):
        n, t = 20, 4
        bank = torch.arange(n, dtype=torch.float32).view(n, 1, 1, 1).expand(n, 2, H, W).contiguous()
        module = et.AddNoise(bank)
        out = module(torch.zeros(50, t, 2, H, W), generator=gen())
        starts = out[:, 0, 0, 0, 0]
        for b in range(50):
            assert out[b, :, 0, 0, 0].tolist() == [starts[b] + k for k in range(t)]
        assert starts.min() >= 0 and starts.max() <= n - t
        assert starts.unique().numel() > 5  # per-sample windows

    def test_every_window_reachable(self):
        bank = torch.arange(6.0).view(6, 1, 1, 1).expand(6, 2, 1, 1)
        starts = et.AddNoise(bank)(torch.zeros(400, 3, 2, 1, 1), generator=gen())[:, 0, 0, 0, 0]
        assert set(starts.tolist()) == {0.0, 1.0, 2.0, 3.0}

    def test_bank_of_the_wrong_size(self):
        module = et.AddNoise(torch.zeros(5, 2, H, W))
        with pytest.raises(ValueError, match="bank of shape"):
            module(torch.zeros(6, 2, H, W))
        with pytest.raises(ValueError, match="bank of shape"):
            module(torch.zeros(3, 2, H + 1, W))
        with pytest.raises(ValueError, match="bank: expected"):
            et.AddNoise(torch.zeros(5, 3, H, W))
        with pytest.raises(ValueError, match="bank must hold non-negative"):
            et.AddNoise(-torch.ones(5, 2, H, W))

    def test_bank_moves_with_module_state(self):
        module = et.AddNoise(torch.ones(5, 2, H, W))
        assert "bank" in module.state_dict()

    @pytest.mark.parametrize("dtype", [torch.float32, torch.int16, torch.int64])
    def test_sparse_bank_equals_dense_sum(self, dtype):
        """A sparse bank adds its non-zero entries only: same sum as the dense windows."""
        bank = sparse_frames(12, 2, H, W, density=0.03, seed=4)
        module = et.AddNoise(bank)
        assert module._entries is not None  # the sparse path
        frames = sparse_frames(6, 5, 2, H, W, density=0.2, dtype=dtype)
        params = module.make_params(frames.shape, generator=gen())
        out = check_not_modified(lambda x: module(x, params=params), frames)
        windows = torch.stack([bank[o : o + 5] for o in params["offset"].tolist()])
        assert out.dtype == dtype
        assert torch.equal(out, frames + windows.to(dtype))

    def test_sparse_bank_overflow_is_refused(self):
        bank = torch.zeros(4, 2, H, W)
        bank[1, 0, 2, 3] = 200.0
        frames = torch.full((1, 3, 2, H, W), 100, dtype=torch.uint8)
        with pytest.raises(ValueError, match="overflows"):
            et.AddNoise(bank)(frames, params={"offset": torch.tensor([0])})

    def test_loaded_bank_is_indexed_again(self):
        module = et.AddNoise(torch.zeros(6, 2, H, W))
        other = torch.zeros(6, 2, H, W)
        other[2, 1, 4, 5] = 3.0
        module.load_state_dict({"bank": other})
        out = module(torch.zeros(1, 3, 2, H, W), params={"offset": torch.tensor([1])})
        assert out.sum() == 3.0 and out[0, 1, 1, 4, 5] == 3.0

    def test_offset_past_the_bank_is_refused(self):
        module = et.AddNoise(torch.zeros(6, 2, H, W))
        with pytest.raises(ValueError, match="params\\['offset'\\]"):
            module(torch.zeros(1, 3, 2, H, W), params={"offset": torch.tensor([4])})


class TestPoissonNoise:
    @pytest.mark.parametrize("rate_hz", [0.5, 5.0, 300.0])  # sparse and dense paths
    def test_mean_and_variance(self, rate_hz):
        frames = torch.zeros(8, 36, 2, H, W)
        out = F.add_poisson_noise(frames, rate_hz, generator=gen())
        lam = rate_hz * 0.01
        n = out.numel()
        assert float(out.mean()) == pytest.approx(lam, abs=5 * math.sqrt(lam / n))
        assert float(out.var()) == pytest.approx(lam, rel=0.1)

    def test_cells_are_poisson(self):
        out = F.add_poisson_noise(torch.zeros(200, 10, 2, 8, 8), 50.0, generator=gen())  # lambda 0.5
        counts = torch.bincount(out.flatten().long(), minlength=4)[:4].double() / out.numel()
        expected = torch.tensor([math.exp(-0.5) * 0.5**k / math.factorial(k) for k in range(4)], dtype=torch.float64)
        torch.testing.assert_close(counts, expected, atol=3e-3, rtol=0)

    def test_per_sample_rates(self):
        out = F.add_poisson_noise(torch.zeros(2, 36, 2, 30, 30), torch.tensor([0.0, 10.0]), generator=gen())
        assert out[0].sum() == 0 and out[1].sum() > 0

    def test_adds_to_frames_in_their_dtype(self):
        frames = sparse_frames(2, 4, 2, H, W, dtype=torch.int16)
        out = check_not_modified(lambda x: F.add_poisson_noise(x, 20.0, generator=gen()), frames)
        check_sane(out, frames)
        assert bool((out >= frames).all())

    def test_reproducible(self):
        frames = torch.zeros(3, 4, 2, H, W)
        a = F.add_poisson_noise(frames, 30.0, generator=gen(7))
        b = F.add_poisson_noise(frames, 30.0, generator=gen(7))
        assert torch.equal(a, b)

    def test_bad_input(self):
        with pytest.raises(ValueError, match="rate_hz"):
            F.add_poisson_noise(torch.zeros(2, 2, H, W), -1.0)
        with pytest.raises(ValueError, match="frame_ms"):
            F.add_poisson_noise(torch.zeros(2, 2, H, W), 1.0, frame_ms=0.0)
        with pytest.raises(TypeError, match="generator"):
            F.add_poisson_noise(torch.zeros(2, 2, H, W), 1.0, generator=0)
        with pytest.raises(ValueError, match="rate_hz"):
            et.AddPoissonNoise((5.0, 1.0))


class TestDropEvents:
    def test_binomial_thinning(self):
        frames = torch.full((4, 36, 2, H, W), 3, dtype=torch.int32)
        out = F.drop_events(frames, 0.25, generator=gen())
        assert out.dtype == torch.int32
        assert bool((out <= frames).all() & (out >= 0).all())
        n = frames.sum().item()
        assert out.sum().item() == pytest.approx(0.75 * n, abs=5 * math.sqrt(n * 0.25 * 0.75))

    def test_extremes_and_per_sample(self):
        frames = sparse_frames(2, 3, 2, H, W, high=9)
        out = F.drop_events(frames, torch.tensor([0.0, 1.0]), generator=gen())
        assert torch.equal(out[0], frames[0])
        assert out[1].sum() == 0

    def test_expected_mode(self):
        frames = sparse_frames(3, 2, H, W, dtype=torch.uint8)
        out = F.drop_events(frames, 0.3, mode="expected")
        assert out.dtype == torch.float32
        torch.testing.assert_close(out, frames.float() * 0.7)

    def test_non_integer_counts_refused(self):
        with pytest.raises(ValueError, match='mode="expected"'):
            F.drop_events(torch.full((2, 2, H, W), 0.5), 0.3)

    def test_fraction_out_of_range(self):
        with pytest.raises(ValueError, match="fraction"):
            F.drop_events(sparse_frames(2, 2, H, W), 1.5)

    def test_by_time_against_loop(self):
        frames = sparse_frames(3, 6, 2, H, W, density=0.5)
        start, length = torch.tensor([0, 2, 5]), torch.tensor([2, 3, 4])
        out = F.drop_by_time(frames, start, length)
        for b in range(3):
            for t in range(6):
                dropped = int(start[b]) <= t < int(start[b]) + int(length[b])
                assert torch.equal(out[b, t], torch.zeros_like(frames[b, t]) if dropped else frames[b, t])

    def test_by_area_against_loop(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.5)
        box = dict(top=torch.tensor([1, 10]), left=torch.tensor([0, 8]), height=torch.tensor([4, 9]), width=torch.tensor([3, 9]))
        out = F.drop_by_area(frames, **box)
        for b in range(2):
            for y in range(H):
                for x in range(W):
                    inside = (box["top"][b] <= y < box["top"][b] + box["height"][b]) and (
                        box["left"][b] <= x < box["left"][b] + box["width"][b]
                    )
                    assert torch.equal(out[b, :, :, y, x], torch.zeros(3, 2) if inside else frames[b, :, :, y, x])

    def test_bad_windows(self):
        with pytest.raises(ValueError, match="start"):
            F.drop_by_time(sparse_frames(3, 2, H, W), -1, 2)
        with pytest.raises(TypeError, match="width must be an integer, got 1.5"):
            F.drop_by_area(sparse_frames(3, 2, H, W), 0, 0, 2, 1.5)


class TestRandomEventDrop:
    @pytest.mark.parametrize("method", ["random", "time", "area"])
    def test_each_method_only_removes(self, method):
        frames = sparse_frames(16, 10, 2, H, W, density=0.5, dtype=torch.int16)
        out = et.RandomEventDrop(fraction=(0.2, 0.6), methods=(method,))(frames, generator=gen())
        check_sane(out, frames)
        assert bool((out <= frames).all())
        assert out.sum() < frames.sum()

    def test_time_method_drops_whole_frames(self):
        frames = torch.ones(8, 10, 2, H, W)
        module = et.RandomEventDrop(fraction=0.3, methods=("time",))
        out = module(frames, generator=gen())
        zero_frames = (out.sum(dim=(2, 3, 4)) == 0).sum(1)
        assert zero_frames.tolist() == [3] * 8

    def test_methods_mix_within_a_batch(self):
        params = et.RandomEventDrop().make_params((60, 6, 2, 9, 11), generator=gen())
        assert set(params["method"].tolist()) == {0, 1, 2}

    def test_bad_settings(self):
        with pytest.raises(ValueError, match="methods"):
            et.RandomEventDrop(methods=("random", "polarity"))
        with pytest.raises(ValueError, match="fraction"):
            et.RandomEventDrop(fraction=(0.2, 1.5))


@settings(max_examples=30, deadline=None)
@given(
    counts=st.lists(st.integers(0, 50), min_size=1, max_size=24),
    fraction=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**31),
)
def test_drop_never_adds_events(counts, fraction, seed):
    frames = torch.tensor(counts + [0] * (-len(counts) % 2), dtype=torch.int64).view(-1, 2, 1, 1)
    out = F.drop_events(frames, fraction, generator=gen(seed))
    assert bool((out >= 0).all() & (out <= frames).all())
