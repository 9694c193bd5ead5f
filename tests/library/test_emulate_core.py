"""The DVS emulator's public parts (``threshold_crossings``, ``camera_pixels``, ``noise_events``): each
equals ``emulate_events`` on the same pixels, hand-computed crossings, pieces, refused arguments."""

from __future__ import annotations

import math

import pytest
import torch

from event_transforms import functional as F


def lin_log_levels(video: torch.Tensor) -> torch.Tensor:
    """The emulator's levels of uint8 frames above the knee (log, rounded to LOG_QUANTUM), (B, T, P)."""
    x = video.to(torch.float32).clamp_min(20.0).log()
    return x.mul_(1.0 / F.LOG_QUANTUM).round_().mul_(F.LOG_QUANTUM).flatten(2)


def as_rows(sample, pixel, t, p) -> list[tuple[int, int, int, int]]:
    return sorted(zip(sample.tolist(), torch.floor(t).to(torch.int64).tolist(), pixel.tolist(), p.tolist()))


def batch_rows(events, width: int) -> list[tuple[int, int, int, int]]:
    sample = torch.repeat_interleave(torch.arange(len(events)), torch.tensor(events.lengths))
    pixel = events.y.to(torch.int64) * width + events.x.to(torch.int64)
    return sorted(zip(sample.tolist(), events.t.tolist(), pixel.tolist(), events.p.tolist()))


def video(seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    wave = torch.sin(torch.linspace(0, 5.0, 9)).view(1, 9, 1, 1)
    base = 60 + 150 * torch.rand(2, 1, 5, 6, generator=g)
    return (base * (1 + 0.4 * wave * torch.rand(2, 1, 5, 6, generator=g))).clamp(21, 255).round().to(torch.uint8)


class TestEqualsTheDenseEmulator:
    @pytest.mark.parametrize("camera", [
        dict(threshold_on=0.1),
        dict(threshold_on=0.1, threshold_off=0.15, mismatch=0.1, refractory_us=4000.0),
        dict(threshold_on=0.1, refractory_us=torch.tensor([0.0, 9000.0]), leak_hz=torch.tensor([3.0, 0.5])),
    ])
    def test_crossings_of_every_pixel_are_the_dense_events(self, camera):
        frames = video()
        dense = F.emulate_events(frames, fps=30.0, seed=torch.tensor([1, 2]), camera_seed=5, random_reference=False,
                                 **camera)
        on, off, _ = F.camera_pixels(30, camera_seed=torch.tensor([5, 5]), threshold_on=camera["threshold_on"],
                                     threshold_off=camera.get("threshold_off"), mismatch=camera.get("mismatch", 0.0))
        times = torch.arange(9, dtype=torch.float64) * (1e6 / 30.0)
        events, _ = F.threshold_crossings(lin_log_levels(frames), times, on, off,
                                          refractory_us=camera.get("refractory_us", 0.0),
                                          leak_hz=camera.get("leak_hz", 0.0))
        assert dense.num_events > 50
        assert as_rows(*events) == batch_rows(dense, 6)

    def test_a_subset_of_pixels_gives_their_events_only(self):
        frames = video(1)
        dense = F.emulate_events(frames[:1], fps=30.0, threshold_on=0.1, refractory_us=3000.0, seed=0)
        keep = torch.tensor([3, 7, 8, 20, 29])
        on, off, _ = F.camera_pixels(30, camera_seed=0, threshold_on=0.1)
        times = torch.arange(9, dtype=torch.float64) * (1e6 / 30.0)
        (sample, column, t, p), _ = F.threshold_crossings(lin_log_levels(frames[:1])[0][:, keep], times, on[0, keep],
                                                          refractory_us=3000.0)
        rows = [r for r in batch_rows(dense, 6) if r[2] in keep.tolist()]
        assert rows and as_rows(sample, keep[column], t, p) == rows

    def test_pieces_with_the_state_equal_one_call(self):
        frames = video(2)
        levels = lin_log_levels(frames)
        times = torch.arange(9, dtype=torch.float64) * 1000.0
        whole, state = F.threshold_crossings(levels, times, 0.1, refractory_us=1500.0, leak_hz=2.0)
        first, middle = F.threshold_crossings(levels[:, :4], times[:4], 0.1, refractory_us=1500.0, leak_hz=2.0)
        second, end = F.threshold_crossings(levels[:, 3:], times[3:], 0.1, refractory_us=1500.0, leak_hz=2.0,
                                            state=middle)
        assert as_rows(*whole) == sorted(as_rows(*first) + as_rows(*second))
        assert all(torch.equal(a, b) for a, b in zip(state, end))

    def test_noise_events_are_the_dense_noise(self):
        constant = torch.full((2, 3, 4, 5), 100, dtype=torch.uint8)
        dense = F.emulate_events(constant, fps=10.0, noise_hz=40.0, hot_pixel_fraction=0.2, hot_pixel_hz=300.0,
                                 seed=torch.tensor([3, 4]), camera_seed=1)
        _, _, rate = F.camera_pixels(20, camera_seed=torch.tensor([1, 1]), noise_hz=40.0, hot_pixel_fraction=0.2,
                                     hot_pixel_hz=300.0)
        events = F.noise_events(rate, 2e5, seed=torch.tensor([3, 4]))
        assert dense.num_events > 100
        assert as_rows(*events) == batch_rows(dense, 5)
        alone = F.noise_events(rate[1], 2e5, seed=4)
        assert as_rows(*alone) == [(0, *r[1:]) for r in as_rows(*events) if r[0] == 1]


class TestHandComputed:
    @pytest.mark.parametrize("rise", [0.3, 1.0, -0.7])
    def test_a_ramp_gives_floor_of_the_change_over_the_threshold(self, rise):
        levels = torch.linspace(0.0, rise, 6).mul(2**20).round().div(2**20).view(6, 1)
        times = torch.arange(6, dtype=torch.float64) * 1000.0
        (_, _, t, p), _ = F.threshold_crossings(levels, times, 0.125)
        assert len(t) == math.floor(abs(float(levels[-1])) / 0.125)
        assert set(p.tolist()) == {int(rise > 0)}
        assert bool((t > 0).all() and (t.floor() <= 5000.0).all() and (t.diff() >= 0).all())  # float32 slopes: within 1 µs

    def test_empty_and_refused(self):
        (sample, *_), state = F.threshold_crossings(torch.zeros(1, 4), [0.0], 0.2)
        assert len(sample) == 0 and state[0].shape == (1, 4)
        with pytest.raises(ValueError, match="times_us"):
            F.threshold_crossings(torch.zeros(3, 2), [0.0, 2.0, 1.0], 0.2)
        with pytest.raises(ValueError, match="threshold_on"):
            F.threshold_crossings(torch.zeros(3, 2), [0.0, 1.0, 2.0], torch.tensor([0.2, 0.0]))
        with pytest.raises(ValueError, match="refractory_us"):
            F.threshold_crossings(torch.zeros(3, 2), [0.0, 1.0, 2.0], 0.2, refractory_us=-1.0)
        with pytest.raises(TypeError, match="levels"):
            F.threshold_crossings(torch.zeros(3, 2, dtype=torch.int64), [0.0, 1.0, 2.0], 0.2)
        with pytest.raises(ValueError, match="rate_hz"):
            F.noise_events(torch.tensor([-1.0]), 10.0, seed=0)


    def test_hard_cases(self):
        """B = 0, no pixels, T = 1 (above), a pixel with a million crossings, half-precision levels, silent rates."""
        times = [0.0, 1.0, 2.0]
        for levels in (torch.zeros(0, 3, 4), torch.zeros(2, 3, 0)):
            (sample, pixel, t, p), (d, blind) = F.threshold_crossings(levels, times, 0.2)
            assert len(sample) == len(pixel) == len(t) == len(p) == 0 and d.shape == levels[:, 0].shape
        jump, theta = torch.tensor([[0.0], [1e4]]), 0.01
        (_, pixel, t, p), _ = F.threshold_crossings(jump, [0.0, 1e6], theta)
        assert len(t) == int(torch.tensor(1e4) / torch.tensor(theta)) and bool((p == 1).all())
        assert bool((t > 0).all() and (t <= 1e6).all() and (t.diff() >= 0).all())
        ramp = torch.linspace(0.0, 1.0, 7).view(7, 1).expand(7, 3).contiguous()
        exact = F.threshold_crossings(ramp, torch.arange(7.0) * 100, 0.1, refractory_us=5.0)[0]
        for dtype in (torch.float16, torch.bfloat16):  # computed in float32 from the given levels
            low = F.threshold_crossings(ramp.to(dtype), torch.arange(7.0) * 100, 0.1, refractory_us=5.0)[0]
            again = F.threshold_crossings(ramp.to(dtype).float(), torch.arange(7.0) * 100, 0.1, refractory_us=5.0)[0]
            assert all(torch.equal(a, b) for a, b in zip(low, again)) and abs(len(low[0]) - len(exact[0])) <= 3
        assert all(len(v) == 0 for v in F.noise_events(torch.zeros(0, 5), 10.0, seed=torch.zeros(0, dtype=torch.int64)))
        assert all(len(v) == 0 for v in F.noise_events(torch.zeros(2, 5), 1e6, seed=torch.tensor([1, 2])))
        assert F.camera_pixels(4, camera_seed=torch.zeros(0, dtype=torch.int64))[0].shape == (0, 4)


class TestNoisePixelSearch:
    @pytest.mark.parametrize("case", ["log-uniform", "hot-only", "zeros-and-ties", "different-rows"])
    def test_the_bucket_table_equals_searchsorted(self, case):
        from event_transforms.functional import _random as R

        g = torch.Generator().manual_seed(0)
        rows, pixels = 3, 500
        rates = torch.exp(torch.rand(1, pixels, generator=g, dtype=torch.float64) * 4.6 - 2.3).expand(rows, -1)
        if case == "hot-only":
            rates = torch.zeros(rows, pixels, dtype=torch.float64)
            rates[:, [7, 300, 499]] = 100.0
        elif case == "zeros-and-ties":
            rates = rates.clone()
            rates[:, 100:400] = 0.0
            rates[:, 50:60] = 0.25
        elif case == "different-rows":
            rates = torch.rand(rows, pixels, generator=g, dtype=torch.float64)
            rates[1, :250] = 0.0
        cumulative = rates.cumsum(1)
        sample = torch.randint(0, rows, (20_000,), generator=g)
        target = torch.rand(20_000, generator=g, dtype=torch.float64) * cumulative[sample, -1]
        target[:200] = cumulative[sample[:200], torch.randint(0, pixels, (200,), generator=g)]  # exactly on values
        expected = torch.stack([torch.searchsorted(cumulative[s], x) for s, x in zip(sample[:2000], target[:2000])])
        assert torch.equal(R.search_cumulative(cumulative, sample[:2000], target[:2000]), expected)
        padded = torch.searchsorted(cumulative, target.expand(rows, -1).contiguous())[sample, torch.arange(20_000)]
        assert torch.equal(R.search_cumulative(cumulative, sample, target), padded)
