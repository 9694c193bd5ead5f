"""Noise injection (static-scene bank, Poisson)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import event_transforms as et
from event_transforms import functional as F

from tests.support.event_data import FRAME_US, SENSOR, T, frames_of, make_batch, rows
from tests.support.checkers import H, W, check_not_modified, check_sane, sparse_frames


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

# --------------------------------------------------------------------------- on events (EventBatch kernels)


class TestOnEvents:
    """The event kernels of this topic: slow per-event references, and equality with the
    frame kernel after binning where the semantics coincide."""

    def test_bank_noise_matches_frames_and_places_events_at_bin_centres(self):
        batch = make_batch(3)
        bank = torch.poisson(torch.full((9, 2, *SENSOR), 0.2), generator=torch.Generator().manual_seed(1))
        noise = et.AddNoise(bank)
        params = noise.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(2))
        out = noise(batch, params=params)
        assert torch.equal(frames_of(out), noise(frames_of(batch), params=params))
        for b in range(3):  # slow reference: every count of the window is one event at its bin's centre
            first = int(params["offset"][b])
            added = rows(out, b)[batch.lengths[b]:]
            expected = sorted(
                (x, y, int(batch.t_start[b]) + t * FRAME_US + FRAME_US // 2, p)
                for t in range(T) for p in range(2) for y in range(SENSOR[0]) for x in range(SENSOR[1])
                for _ in range(int(bank[first + t, p, y, x]))
            )
            assert sorted(added) == expected and rows(out, b)[: batch.lengths[b]] == rows(batch, b)
        with pytest.raises(ValueError, match="cannot cover frames"):
            et.AddNoise(torch.zeros(9, 2, 5, 5))(batch)

    def test_poisson_noise(self):
        batch = make_batch(3)
        noise = et.AddPoissonNoise(200.0)
        out = noise(batch, generator=torch.Generator().manual_seed(0))
        expected = 200.0 * T * 1e-3 * 2 * SENSOR[0] * SENSOR[1]
        added = [a - b for a, b in zip(out.lengths, batch.lengths)]
        assert all(abs(a - expected) < 6 * math.sqrt(expected) for a in added)
        frames = frames_of(out)
        assert frames.sum() == out.num_events  # every added event lies in the window and sensor
        assert bool((frames >= frames_of(batch)).all())


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).


def _bank(t: int, h: int, w: int) -> torch.Tensor:
    return sparse_frames(t + 5, 2, h, w, seed=9)

BATTERY = {
    "AddNoise": lambda t, h, w: et.AddNoise(_bank(t, h, w)),
    "AddPoissonNoise": lambda t, h, w: et.AddPoissonNoise((0.5, 20.0)),
}

EVENT_BATTERY = {
    "AddPoissonNoise": lambda: et.AddPoissonNoise((1.0, 100.0)),
    "AddNoise p": lambda: et.AddNoise(torch.poisson(torch.full((9, 2, *SENSOR), 0.3),
                                                    generator=torch.Generator().manual_seed(4)), p=0.5),
}


def test_a_replayed_poisson_count_past_any_draw_is_refused_by_name():
    """Fuzzed trees (issue 34, item 8): a ``count`` of 1e9 noise events for a small batch is
    refused by name before anything is allocated (it was a raw RuntimeError, or an OOM kill)."""
    module = et.AddPoissonNoise(5.0)
    frames = torch.zeros(2, 3, 2, 4, 5)
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    params["count"] = torch.full_like(params["count"], 10**9)
    with pytest.raises(ValueError, match=r"AddPoissonNoise: params\['count'\] must lie in \[0, 2944\]"):
        module(frames, params=params)
