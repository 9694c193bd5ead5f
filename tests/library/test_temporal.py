"""Frame shifting, temporal event shifting (TES), time reversal and temporal crop against
slow references and invariants."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from collections import Counter
from itertools import product

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import functional as F
from event_transforms._validation import as_batch
from event_transforms.functional._random import draw_seeds
from event_transforms._params import check_args
from event_transforms.functional.temporal import TEMPORAL_EVENT_SHIFT_SPEC, _draw_moved, _entries, temporal_event_shift_frames
from event_transforms.transforms import (
    FrameShift,
    RandomFrameShift,
    RandomTemporalEventShift,
    TemporalEventShift,
)

from event_transforms.functional._event_ops import TIME_JITTER

from tests.support import random_reference as reference
from tests.support.event_data import SENSOR, T, frames_of, make_batch, make_streams, rows
from tests.support.checkers import H, W, check_not_modified, check_pickle, check_sane, count_shapes, random_counts, sparse_frames
from tests.library.test_hypergeometric import chi_square_p_value

ALL_DTYPES = [
    torch.float16, torch.bfloat16, torch.float32, torch.float64,
    torch.uint8, torch.int16, torch.int32, torch.int64,
]
MODES = ["exact", "binomial", "expected"]



def _moved_counts(frames, fraction, *, mode="exact", generator=None):
    """The moved counts Z that ``temporal_event_shift`` draws (same generator use), dense.

    With equal generator states, ``temporal_event_shift(frames, j, fraction)`` equals
    ``frames - Z + frame_shift(Z, j)``.
    """
    batch, unbatch = as_batch(frames)
    fractions = check_args("temporal_event_shift", TEMPORAL_EVENT_SHIFT_SPEC, batch.shape[0], fraction=fraction)["fraction"]
    index, sample, values = _entries(batch)
    seeds = draw_seeds(batch.shape[0], generator)  # as temporal_event_shift draws them
    moved, _ = _draw_moved(batch.shape, index, sample, values, fractions, mode, seeds)
    out = torch.zeros(batch.numel(), dtype=frames.dtype, device=frames.device)
    out[index] = moved.to(frames.dtype)
    return unbatch(out.view(batch.shape))

def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)



def reference_frame_shift(frames: torch.Tensor, shifts: list[int]) -> torch.Tensor:
    """Output frame t of sample b is input frame t - shifts[b], or zero."""
    out = torch.zeros_like(frames)
    b, t = frames.shape[:2]
    for i in range(b):
        for k in range(t):
            source = k - shifts[i]
            if 0 <= source < t:
                out[i, k] = frames[i, source]
    return out


def reference_move(frames: torch.Tensor, moved: torch.Tensor, shifts: list[int]) -> torch.Tensor:
    """X - Z + (Z moved by j frames), one frame at a time in float64."""
    x, z = frames.double(), moved.double()
    out = x - z
    b, t = frames.shape[:2]
    for i in range(b):
        for k in range(t):
            if 0 <= k + shifts[i] < t:
                out[i, k + shifts[i]] += z[i, k]
    return out


def dropped(moved: torch.Tensor, shifts: list[int]) -> torch.Tensor:
    """Events per sample moved past either end."""
    t = moved.shape[1]
    out = torch.zeros(len(shifts), dtype=torch.float64)
    for i, s in enumerate(shifts):
        for k in range(t):
            if not 0 <= k + s < t:
                out[i] += moved[i, k].double().sum()
    return out


class TestFrameShift:
    @pytest.mark.parametrize("shift", [-40, -7, -2, -1, 0, 1, 3, 7, 40])
    def test_scalar_against_loop(self, shift):
        frames = sparse_frames(3, 7, 2, H, W)
        out = check_not_modified(lambda x: F.frame_shift(x, shift), frames)
        assert torch.equal(out, reference_frame_shift(frames, [shift] * 3))

    def test_per_sample_against_loop(self):
        frames = sparse_frames(6, 5, 2, H, W, dtype=torch.int16)
        shifts = [-6, -2, 0, 1, 4, 5]
        out = check_not_modified(lambda x: F.frame_shift(x, torch.tensor(shifts)), frames)
        check_sane(out, frames)
        assert torch.equal(out, reference_frame_shift(frames, shifts))
        assert torch.equal(F.frame_shift(frames, shifts), out)  # a list works too

    def test_batched_equals_per_sample(self):
        frames = sparse_frames(4, 6, 2, H, W)
        shifts = torch.tensor([-1, 2, 0, -3])
        out = F.frame_shift(frames, shifts)
        for i in range(4):
            assert torch.equal(out[i], F.frame_shift(frames[i], int(shifts[i])))

    @pytest.mark.parametrize("dtype", ALL_DTYPES)
    def test_dtypes(self, dtype):
        frames = sparse_frames(2, 4, 2, H, W, dtype=dtype)
        out = F.frame_shift(frames, torch.tensor([1, -2]))
        check_sane(out, frames)
        assert torch.equal(out, reference_frame_shift(frames, [1, -2]))

    @pytest.mark.parametrize(
        "shape", [(0, 4, 2, H, W), (2, 1, 2, H, W), (2, 3, 2, 1, W), (2, 3, 2, H, 1), (3, 2, 1, 1)]
    )
    def test_edge_shapes(self, shape):
        frames = sparse_frames(*shape, density=0.5)
        for shift in (-1, 0, 1):
            out = F.frame_shift(frames, shift)
            check_sane(out, frames)
            batch = frames if frames.dim() == 5 else frames.unsqueeze(0)
            expected = reference_frame_shift(batch, [shift] * batch.shape[0])
            assert torch.equal(out, expected if frames.dim() == 5 else expected[0])

    def test_single_sequence_and_non_contiguous(self):
        frames = sparse_frames(5, 2, W, H).transpose(-1, -2)  # (5, 2, H, W), not contiguous
        assert torch.equal(F.frame_shift(frames, 2), reference_frame_shift(frames[None], [2])[0])

    def test_bad_inputs(self):
        frames = sparse_frames(2, 3, 2, H, W)
        with pytest.raises(TypeError, match="shift"):
            F.frame_shift(frames, 1.5)
        with pytest.raises(TypeError, match="shift"):
            F.frame_shift(frames, True)
        with pytest.raises(TypeError, match="shift must hold integers"):
            F.frame_shift(frames, torch.tensor([0.5, 1.0]))
        with pytest.raises(ValueError, match="shift"):
            F.frame_shift(frames, torch.tensor([1, 2, 3]))
        with pytest.raises(ValueError, match=r"\(T, 2, H, W\)"):
            F.frame_shift(torch.zeros(3, 3, H, W), 1)
        assert torch.equal(F.frame_shift(frames, torch.tensor([1.0, -1.0])), F.frame_shift(frames, [1, -1]))


class TestTemporalEventShift:
    # ------------------------------------------------------------ references
    @pytest.mark.parametrize("shift", [-3, -1, 0, 2, 9])
    def test_expected_against_loop(self, shift):
        frames = sparse_frames(3, 6, 2, H, W, dtype=torch.float64)
        fractions = torch.tensor([0.0, 0.3, 1.0], dtype=torch.float64)
        out = check_not_modified(lambda x: F.temporal_event_shift(x, shift, fractions, mode="expected"), frames)
        expected = torch.zeros_like(frames)
        for b in range(3):
            for t in range(6):
                moved = frames[b, t] * fractions[b]
                expected[b, t] += frames[b, t] - moved
                if 0 <= t + shift < 6:
                    expected[b, t + shift] += moved
        torch.testing.assert_close(out, expected, rtol=0, atol=1e-12)

    @pytest.mark.parametrize("mode", ["exact", "binomial"])
    def test_shift_mechanics_given_moved_counts(self, mode):
        frames = sparse_frames(4, 6, 2, H, W, high=9, density=0.3, dtype=torch.int32)
        shifts, fractions = [-2, 1, 0, 7], torch.tensor([0.5, 0.25, 0.9, 0.6], dtype=torch.float64)
        moved = _moved_counts(frames, fractions, mode=mode, generator=gen(4))
        out = check_not_modified(
            lambda x: F.temporal_event_shift(x, torch.tensor(shifts), fractions, mode=mode, generator=gen(4)),
            frames,
        )
        check_sane(out, frames)
        assert torch.equal(out.double(), reference_move(frames, moved, shifts))

    # ------------------------------------------------------------ invariants
    @pytest.mark.parametrize("fraction", [0.1, 0.5, 0.73, 0.999])
    def test_exact_invariants(self, fraction):
        frames = sparse_frames(3, 5, 2, H, W, high=7, density=0.4, dtype=torch.int64)
        frames[0, 2, 1] = 0  # an empty frame and polarity
        frames[1, 3, 0] = 0
        frames[1, 3, 0, 4, 4] = 1  # a single event
        frames[2, 1, 1, 0, 0] = 10**6  # one pixel with 10**6 events
        moved = _moved_counts(frames, fraction, generator=gen(1))
        n = frames.sum(dim=(-2, -1)).double()
        assert torch.equal(moved.sum(dim=(-2, -1)).double(), torch.round(fraction * n))
        assert bool(((moved >= 0) & (moved <= frames)).all())
        shifts = [-1, 2, 4]
        out = F.temporal_event_shift(frames, torch.tensor(shifts), fraction, generator=gen(1))
        conserved = out.double().sum(dim=(1, 2, 3, 4)) + dropped(moved, shifts)
        assert torch.equal(conserved, frames.double().sum(dim=(1, 2, 3, 4)))

    def test_rounding_is_half_to_even(self):
        frames = torch.zeros(1, 2, 2, 1, 4, dtype=torch.int64)
        frames[0, 0, 0, 0, :] = torch.tensor([1, 1, 1, 0])  # N = 3, 0.5 N = 1.5 -> 2
        frames[0, 0, 1, 0, :] = torch.tensor([2, 2, 1, 0])  # N = 5, 0.5 N = 2.5 -> 2
        moved = _moved_counts(frames, 0.5, generator=gen())
        assert moved[0, 0].sum(dim=(-2, -1)).tolist() == [2, 2]

    @pytest.mark.parametrize("size", [3, 8])  # direct draw and complement draw
    def test_exact_law_chi_square(self, size):
        """One pixel's moved count follows the (multivariate) hypergeometric law."""
        draws, pixels = 10**4, [3, 0, 5, 2]  # N = 10
        frames = torch.tensor(pixels, dtype=torch.float32).view(1, 1, 1, 1, 4).repeat(draws, 1, 2, 1, 1)
        moved = _moved_counts(frames, size / 10, generator=gen(11))  # one call, 10**4 samples
        assert torch.equal(moved.sum(dim=(-2, -1)), torch.full((draws, 1, 2), float(size)))
        numpy = pytest.importorskip("numpy")
        support = range(max(0, size - 5), min(5, size) + 1)
        pmf = {k: math.comb(5, k) * math.comb(5, size - k) / math.comb(10, size) for k in support}
        ours = Counter(moved[:, 0, 1, 0, 2].long().tolist())
        assert chi_square_p_value(ours, pmf, draws) > 1e-3
        ref = numpy.random.default_rng(0).multivariate_hypergeometric(pixels, size, size=draws)[:, 2]
        assert chi_square_p_value(Counter(ref.tolist()), pmf, draws) > 1e-3

    def test_binomial_mean(self):
        draws = 4000
        frames = torch.tensor([0, 1, 4, 20], dtype=torch.int64).view(1, 1, 1, 1, 4).repeat(draws, 2, 2, 1, 1)
        moved = _moved_counts(frames, 0.3, mode="binomial", generator=gen(2)).double()
        assert bool(((moved >= 0) & (moved <= frames)).all())
        mean = moved.mean(dim=(0, 1, 2, 3))
        expected = torch.tensor([0, 0.3, 1.2, 6.0], dtype=torch.float64)
        sigma = (torch.tensor([0, 1, 4, 20.0], dtype=torch.float64) * 0.21 / (draws * 4)).sqrt()
        assert bool(((mean - expected).abs() <= 5 * sigma + 1e-12).all())
        sums = moved.sum(dim=(-2, -1))
        assert sums.std() > 0  # totals vary: binomial, not exact

    @pytest.mark.parametrize("mode", MODES)
    @pytest.mark.parametrize("shift", [-2, 0, 3, 10])
    def test_fraction_one_is_frame_shift_and_zero_is_identity(self, mode, shift):
        frames = sparse_frames(2, 5, 2, H, W, high=5, density=0.3)
        shifted = F.temporal_event_shift(frames, shift, 1.0, mode=mode, generator=gen())
        assert torch.equal(shifted, F.frame_shift(frames, shift))
        assert torch.equal(F.temporal_event_shift(frames, shift, 0.0, mode=mode, generator=gen()), frames)

    def test_batched_equals_per_sample_for_deterministic_params(self):
        frames = sparse_frames(3, 6, 2, H, W)
        shifts, fractions = torch.tensor([-1, 2, 0]), torch.tensor([0.25, 1.0, 0.5])
        out = F.temporal_event_shift(frames, shifts, fractions, mode="expected")
        for i in range(3):
            single = F.temporal_event_shift(frames[i], int(shifts[i]), float(fractions[i]), mode="expected")
            assert torch.equal(out[i], single)
        for mode in ("exact", "binomial"):  # fraction 0 or 1 is deterministic
            ones = torch.tensor([1.0, 0.0, 1.0])
            out = F.temporal_event_shift(frames, shifts, ones, mode=mode, generator=gen())
            for i in range(3):
                single = F.temporal_event_shift(frames[i], int(shifts[i]), float(ones[i]), mode=mode)
                assert torch.equal(out[i], single)

    # ------------------------------------------------------------ hard cases
    @pytest.mark.parametrize("mode", MODES)
    @pytest.mark.parametrize("dtype", ALL_DTYPES)
    def test_dtypes(self, mode, dtype):
        frames = sparse_frames(2, 4, 2, H, W, high=6, density=0.3, dtype=dtype)
        out = check_not_modified(lambda x: F.temporal_event_shift(x, -1, 0.5, mode=mode, generator=gen()), frames)
        expected_dtype = dtype if mode != "expected" or dtype.is_floating_point else torch.float32
        check_sane(out, frames, expected_dtype)
        if mode != "expected":
            moved = _moved_counts(frames, 0.5, mode=mode, generator=gen())
            assert torch.equal(out.double(), reference_move(frames, moved, [-1, -1]))

    @pytest.mark.parametrize("mode", MODES)
    @pytest.mark.parametrize(
        "shape", [(0, 4, 2, H, W), (2, 1, 2, H, W), (2, 3, 2, 1, W), (2, 3, 2, H, 1), (3, 2, 1, 1), (3, 2, H, W)]
    )
    def test_edge_shapes(self, mode, shape):
        frames = sparse_frames(*shape, density=0.5)
        for shift in (-1, 1):
            out = F.temporal_event_shift(frames, shift, 0.5, mode=mode, generator=gen())
            check_sane(out, frames)
            assert out.sum() <= frames.sum()

    @pytest.mark.parametrize("mode", MODES)
    def test_empty_and_single_event(self, mode):
        frames = torch.zeros(2, 4, 2, H, W)
        assert torch.equal(F.temporal_event_shift(frames, -1, 0.5, mode=mode), frames)
        frames[1, 2, 0, 3, 5] = 1
        out = F.temporal_event_shift(frames, -1, 1.0, mode=mode)
        assert out[1, 1, 0, 3, 5] == 1 and out.sum() == 1
        out = F.temporal_event_shift(frames, -1, 0.4, mode="exact")  # round(0.4) = 0
        assert torch.equal(out, frames)

    @pytest.mark.parametrize("mode", MODES)
    def test_shift_beyond_sequence_drops_moved_events(self, mode):
        frames = sparse_frames(2, 3, 2, H, W, high=5, density=0.4, dtype=torch.float64)
        for shift in (-3, 3, 100, -(2**40)):
            out = F.temporal_event_shift(frames, shift, 0.5, mode=mode, generator=gen())
            moved = _moved_counts(frames, 0.5, mode=mode, generator=gen()) if mode != "expected" else frames * 0.5
            torch.testing.assert_close(out, frames - moved, rtol=0, atol=1e-12)

    def test_ten_million_events(self):
        """10**7 events in one pixel, and spread over a whole frame: exact and bounded."""
        frames = torch.zeros(1, 4, 2, 70, 75)
        frames[0, 1, 1, 10, 20] = 1e7  # float32 holds it exactly
        frames[0, 2, 0] = 1905.0  # 1905 * 5250 = 10_001_250 events over 5250 pixels
        frames[0, 2, 0, 0, 0] = 1e7
        moved = _moved_counts(frames, 0.37, generator=gen(3))
        n = frames.double().sum(dim=(-2, -1))
        assert torch.equal(moved.double().sum(dim=(-2, -1)), torch.round(0.37 * n))
        assert bool(((moved >= 0) & (moved <= frames)).all())
        out = F.temporal_event_shift(frames, -1, 0.37, generator=gen(3))
        assert out.dtype == torch.float32
        assert torch.equal(out.double(), reference_move(frames, moved, [-1]))
        assert out[0, 0, 1, 10, 20] == 3_700_000 and out[0, 1, 1, 10, 20] == 6_300_000

    def test_counts_far_beyond_memory(self):
        """10**12 events per pixel: impossible if events were ever expanded one by one."""
        frames = torch.zeros(2, 3, 2, 5, 4, dtype=torch.int64)
        frames[:, 1] = 10**12
        frames[1, 2, 1, 0, 0] = 7
        moved = _moved_counts(frames, 0.5, generator=gen())
        n = frames.sum(dim=(-2, -1)).double()
        assert torch.equal(moved.sum(dim=(-2, -1)).double(), torch.round(0.5 * n))
        assert bool(((moved >= 0) & (moved <= frames)).all())

    @pytest.mark.slow
    def test_memory_is_bounded(self):
        """Peak RSS added by TES on 10**7-event frames stays far below 80 MB (one int64 per event)."""
        code = textwrap.dedent(
            """
            import resource, torch
            from event_transforms.functional import temporal_event_shift
            frames = torch.zeros(1, 4, 2, 70, 75)
            frames[0, 1, 1, 10, 20] = 1e7
            frames[0, 2, 0] = 1905.0
            temporal_event_shift(frames, -1, 0.5)  # warm up allocations
            before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            for mode in ("exact", "binomial"):
                temporal_event_shift(frames, -1, 0.5, mode=mode)
            print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before)
            """
        )
        result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        grown_kib = int(result.stdout.strip().splitlines()[-1])
        assert grown_kib < 40_000

    # ------------------------------------------------------------ randomness
    @pytest.mark.parametrize("mode", ["exact", "binomial"])
    def test_generator_reproducible(self, mode):
        frames = sparse_frames(3, 5, 2, H, W, high=20, density=0.5)
        a = F.temporal_event_shift(frames, -1, 0.5, mode=mode, generator=gen(9))
        b = F.temporal_event_shift(frames, -1, 0.5, mode=mode, generator=gen(9))
        c = F.temporal_event_shift(frames, -1, 0.5, mode=mode, generator=gen(10))
        assert torch.equal(a, b) and not torch.equal(a, c)

    @pytest.mark.parametrize("mode", ["exact", "binomial"])
    def test_samples_draw_independently(self, mode):
        frames = sparse_frames(1, 4, 2, H, W, high=6, density=0.5).expand(6, -1, -1, -1, -1)
        out = F.temporal_event_shift(frames, -1, 0.5, mode=mode, generator=gen())
        assert len({tuple(o.flatten().tolist()) for o in out}) == 6

    # ------------------------------------------------------------ errors
    def test_bad_inputs(self):
        frames = sparse_frames(2, 3, 2, H, W)
        with pytest.raises(ValueError, match="fraction"):
            F.temporal_event_shift(frames, -1, 1.5)
        with pytest.raises(ValueError, match="fraction"):
            F.temporal_event_shift(frames, -1, torch.tensor([0.5, -0.1]))
        with pytest.raises(TypeError, match="shift"):
            F.temporal_event_shift(frames, 0.5, 0.5)
        with pytest.raises(TypeError, match="shift must hold integers"):
            F.temporal_event_shift(frames, torch.tensor([0.5, 1.0]), 0.5)
        with pytest.raises(ValueError, match="'poisson'"):
            F.temporal_event_shift(frames, -1, 0.5, mode="poisson")
        with pytest.raises(TypeError, match="generator"):
            F.temporal_event_shift(frames, -1, 0.5, generator=0)
        for mode in ("exact", "binomial"):
            with pytest.raises(ValueError, match="expected"):
                F.temporal_event_shift(frames * 0.5, -1, 0.5, mode=mode)
            with pytest.raises(ValueError, match="non-negative"):
                F.temporal_event_shift(-frames, -1, 0.5, mode=mode)
            bad = frames.clone()
            bad[0, 0, 0, 0, 0] = math.nan
            with pytest.raises(ValueError, match="finite"):
                F.temporal_event_shift(bad, -1, 0.5, mode=mode)
        with pytest.raises(ValueError, match="non-negative"):
            F.temporal_event_shift(-frames, -1, 0.5, mode="expected")
        F.temporal_event_shift(frames * 0.5, -1, 0.5, mode="expected")  # fractional counts fine

    # ------------------------------------------------------------ properties
    @settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(
        seed=st.integers(0, 2**31),
        batch=st.integers(1, 3),
        time=st.integers(1, 5),
        shift=st.integers(-6, 6),
        fraction=st.floats(0.0, 1.0),
        high=st.sampled_from([2, 5, 200]),
        mode=st.sampled_from(["exact", "binomial"]),
    )
    def test_conservation_property(self, seed, batch, time, shift, fraction, high, mode):
        frames = sparse_frames(batch, time, 2, 3, 4, density=0.5, high=high, seed=seed, dtype=torch.int64)
        out = F.temporal_event_shift(frames, shift, fraction, mode=mode, generator=gen(seed))
        moved = _moved_counts(frames, fraction, mode=mode, generator=gen(seed))
        assert bool((out >= 0).all()) and bool(((moved >= 0) & (moved <= frames)).all())
        if mode == "exact":
            n = frames.sum(dim=(-2, -1)).double()
            assert torch.equal(moved.sum(dim=(-2, -1)).double(), torch.round(fraction * n))
        total = out.double().sum(dim=(1, 2, 3, 4)) + dropped(moved, [shift] * batch)
        assert torch.equal(total, frames.double().sum(dim=(1, 2, 3, 4)))


class TestModules:
    def test_frame_shift(self):
        frames = sparse_frames(2, 5, 2, H, W)
        module = FrameShift(-1)
        assert torch.equal(module(frames), F.frame_shift(frames, -1))
        assert torch.equal(module(frames[0]), F.frame_shift(frames[0], -1))
        assert repr(module) == "FrameShift(shift=-1)"
        check_pickle(module, frames)
        with pytest.raises(TypeError, match="shift"):
            FrameShift(0.5)

    @pytest.mark.parametrize(
        "shifts, allowed", [((-1, 1), {-1, 1}), (range(-2, 3), {-2, -1, 0, 1, 2}), ([3], {3})]
    )
    def test_random_frame_shift(self, shifts, allowed):
        module = RandomFrameShift(shifts)
        params = module.make_params((200, 6, 2, 9, 11), generator=gen())
        assert params["shift"].shape == (200,) and params["shift"].dtype == torch.int64
        assert set(params["shift"].tolist()) == allowed  # one draw per sample, all values reached
        frames = sparse_frames(200, 4, 2, 3, 2)
        out = module(frames, params=params)
        assert torch.equal(out, reference_frame_shift(frames, params["shift"].tolist()))
        check_pickle(module, frames[:8])
        assert "shifts=" in repr(module)

    def test_random_frame_shift_bad_arguments(self):
        with pytest.raises(ValueError, match="shifts"):
            RandomFrameShift(())
        with pytest.raises(TypeError, match="shifts"):
            RandomFrameShift((0.5, 1))
        with pytest.raises(TypeError, match="shifts"):
            RandomFrameShift(2)

    @pytest.mark.parametrize("mode", MODES)
    def test_temporal_event_shift(self, mode):
        module = TemporalEventShift(-2, 0.5, mode=mode)
        frames = sparse_frames(3, 5, 2, H, W, high=7, density=0.3)
        params = module.make_params(frames.shape, generator=gen(5))
        out = module(frames, params=params)
        if mode == "expected":  # deterministic: no seed
            assert sorted(params) == ["fraction", "shift"]
        else:  # the kernel draws from per-sample streams keyed by the seeds in params
            assert params["seed"].shape == (3,) and params["seed"].dtype == torch.int64
        shifts, fractions = torch.full((3,), -2), torch.full((3,), 0.5, dtype=torch.float64)
        assert torch.equal(out, temporal_event_shift_frames(frames, shifts, fractions, mode, params.get("seed")))
        assert torch.equal(module(frames, generator=gen(5)), out)
        assert repr(module) == f"TemporalEventShift(shift=-2, fraction=0.5, mode={mode!r})"
        check_pickle(module, frames)
        with pytest.raises(ValueError, match="fraction"):
            TemporalEventShift(-1, 1.5)
        with pytest.raises(ValueError, match="mode"):
            TemporalEventShift(-1, 0.5, mode="nope")

    def test_random_temporal_event_shift(self):
        module = RandomTemporalEventShift((-2, -1), (0.25, 0.75))
        params = module.make_params((300, 6, 2, 9, 11), generator=gen(1))
        assert set(params["shift"].tolist()) == {-2, -1}
        assert params["fraction"].dtype == torch.float64
        assert 0.25 <= params["fraction"].min() and params["fraction"].max() <= 0.75
        assert params["fraction"].std() > 0.1  # per sample, not one per batch
        frames = sparse_frames(300, 4, 2, 3, 5, high=9, density=0.6, dtype=torch.int64)
        out = module(frames, params=params)
        expected = temporal_event_shift_frames(frames, params["shift"], params["fraction"], "exact", params["seed"])
        assert torch.equal(out, expected)
        check_pickle(module, frames[:4])
        fixed = RandomTemporalEventShift(range(-1, 2), 0.5, mode="binomial")
        assert torch.equal(fixed.make_params((5, 6, 2, 9, 11))["fraction"], torch.full((5,), 0.5, dtype=torch.float64))
        assert repr(fixed) == "RandomTemporalEventShift(shifts=(-1, 0, 1), fractions=(0.5, 0.5), mode='binomial')"
        with pytest.raises(ValueError, match="fractions"):
            RandomTemporalEventShift((-1,), (0.5, 1.5))
        with pytest.raises(ValueError, match="fractions"):
            RandomTemporalEventShift((-1,), 2.0)

    def test_module_generator_reproducible(self):
        module = RandomTemporalEventShift(range(-3, 4), (0.0, 1.0))
        frames = sparse_frames(4, 6, 2, H, W, high=5)
        assert torch.equal(module(frames, generator=gen(7)), module(frames, generator=gen(7)))


class TestTimeReversal:
    def test_against_reference(self):
        frames = sparse_frames(2, 5, 2, H, W, density=0.3, dtype=torch.uint8)
        out = check_not_modified(F.time_reversal, frames)
        for t in range(5):
            for p in range(2):
                assert torch.equal(out[:, t, p], frames[:, 4 - t, 1 - p])

    def test_twice_is_identity(self):
        frames = sparse_frames(5, 2, H, W, density=0.3)
        assert torch.equal(et.TimeReversal()(et.TimeReversal()(frames)), frames)

class TestCropTime:
    def test_against_reference(self):
        frames = sparse_frames(3, 8, 2, H, W, density=0.3, dtype=torch.int32)
        start = [0, 2, 5]
        out = F.crop_time(frames, torch.tensor(start), 3)
        assert out.shape == (3, 3, 2, H, W)
        for n in range(3):
            for i in range(3):
                assert torch.equal(out[n, i], frames[n, start[n] + i])

    def test_random_window_and_labels(self):
        frames = sparse_frames(4, 10, 2, H, W, density=0.3)
        force = torch.arange(40.0).view(4, 10)
        module = et.RandomCropTime(6)
        params = module.make_params(frames.shape, generator=gen(1))
        out = module(frames, params=params)
        assert out.shape == (4, 6, 2, H, W) and module.output_shape(frames.shape) == out.shape
        cut = force.gather(1, params["start"].view(-1, 1) + torch.arange(6))  # the documented recipe
        for n in range(4):
            s = int(params["start"][n])
            assert torch.equal(out[n], frames[n, s : s + 6]) and torch.equal(cut[n], force[n, s : s + 6])
        assert set(module.make_params((300, 10, 2, 1, 1), generator=gen())["start"].tolist()) == set(range(5))

    def test_named_errors(self):
        with pytest.raises(ValueError, match="length"):
            F.crop_time(torch.zeros(4, 2, 1, 1), 0, 5)
        with pytest.raises(ValueError, match="start"):
            F.crop_time(torch.zeros(4, 2, 1, 1), 2, 3)
        with pytest.raises(ValueError, match="exceeds"):
            et.CropTime(2, 3)(torch.zeros(4, 2, 1, 1))
        with pytest.raises(ValueError, match="length"):
            et.RandomCropTime(5)(torch.zeros(4, 2, 1, 1))


@settings(max_examples=60, deadline=None)
@given(count_shapes, st.integers(0, 2**31))
def test_time_reversal_is_an_involution_that_swaps_polarity_totals(shape, seed):
    frames = random_counts(shape, seed)
    out = F.time_reversal(frames)
    assert torch.equal(F.time_reversal(out), frames)
    assert torch.equal(out.sum((1, 3, 4)), frames.sum((1, 3, 4)).flip(1))


class TestNarrowDtypes:
    """Issue 19, item 4: TES adds counts in a wide dtype and refuses a result the input dtype
    cannot hold, by name; it never wraps."""

    @pytest.mark.parametrize("mode", ["exact", "binomial"])
    @pytest.mark.parametrize("dtype, value", [(torch.uint8, 250), (torch.int8, 120), (torch.int16, 32_760), (torch.bfloat16, 250)])
    def test_overflow_refused_by_name(self, dtype, value, mode):
        frames = torch.full((1, 4, 2, 8, 8), value, dtype=dtype)
        with pytest.raises(ValueError, match=rf"hold up to \d+ events in a pixel, more than {dtype} holds exactly"):
            F.temporal_event_shift(frames, -1, 0.5, mode=mode, generator=gen(0))

    @pytest.mark.parametrize("dtype", [torch.uint8, torch.int8, torch.int16])
    def test_results_that_fit_are_exact(self, dtype):
        frames = torch.full((1, 4, 2, 8, 8), 60, dtype=dtype)
        out = F.temporal_event_shift(frames, -1, 0.5, generator=gen(0))
        wide = F.temporal_event_shift(frames.to(torch.int64), -1, 0.5, generator=gen(0))
        assert out.dtype == dtype and torch.equal(out.to(torch.int64), wide)
        assert int(out.to(torch.int64).sum()) == 4 * 128 * 60 - 128 * 30  # frame 0's moved half leaves


class TestPerSamplePurity:
    """Issue 19, item 1: a sample's TES draw depends on its own seed and counts only."""

    @pytest.mark.parametrize("mode", ["exact", "binomial"])
    def test_sample_alone_equals_sample_in_any_batch(self, mode):
        frames = sparse_frames(6, 5, 2, H, W, high=9, density=0.5, dtype=torch.int64)
        frames[2, 1, 0, 0, 0] = 10**6  # a count for the whole-count (BTRS) route
        seeds = torch.arange(6, dtype=torch.int64) * 7919 + 3
        shifts, fractions = torch.full((6,), -1), torch.linspace(0.1, 0.9, 6, dtype=torch.float64)
        batched = temporal_event_shift_frames(frames, shifts, fractions, mode, seeds)
        for b in range(6):
            alone = temporal_event_shift_frames(frames[b : b + 1], shifts[b : b + 1], fractions[b : b + 1], mode, seeds[b : b + 1])
            assert torch.equal(alone[0], batched[b])
        other = frames.clone()
        other[0] = 0  # a neighbour's data changes nothing for the others
        changed = temporal_event_shift_frames(other, shifts, fractions, mode, seeds)
        assert torch.equal(changed[1:], batched[1:])

# --------------------------------------------------------------------------- on events (EventBatch kernels)


class TestOnEvents:
    """The event kernels of this topic: slow per-event references, and equality with the
    frame kernel after binning where the semantics coincide."""

    def test_frame_shift_matches_frames(self):
        batch = make_batch()
        for shift in (-2, 1, 0):
            assert torch.equal(frames_of(et.FrameShift(shift)(batch)), F.frame_shift(frames_of(batch), shift))

    @pytest.mark.parametrize("fraction, shift", [(0.5, -2), (0.3, 1), (1.0, -1), (0.0, 2), (0.77, 3)])
    def test_tes_exact_moves_round_zeta_n(self, fraction, shift):
        batch = make_batch(4, n=300)
        tes = et.TemporalEventShift(shift, fraction)
        out = tes(batch, generator=torch.Generator().manual_seed(1))
        n = frames_of(batch).sum(dim=(3, 4))
        k = torch.round(fraction * n.double()).long()
        expected = n - k
        if shift >= 0:
            expected[:, shift:] += k[:, : T - shift]
        else:
            expected[:, :shift] += k[:, -shift:]
        assert torch.equal(frames_of(out).sum(dim=(3, 4)), expected)
        # the same per-(frame, polarity) totals as the frame kernel, whose totals are deterministic too
        frame_out = tes(frames_of(batch), generator=torch.Generator().manual_seed(1))
        assert torch.equal(frames_of(out).sum(dim=(3, 4)), frame_out.sum(dim=(3, 4)))
        assert bool((frames_of(out)[:, :] >= 0).all())

    def test_tes_chi_square(self):
        """Moved counts per pixel of one group: multivariate hypergeometric (a uniform subset of k of N)."""
        pixels = [3, 2, 1]  # N = 6 events in three pixels of frame 1, ON; k = 3
        events = [[i, 0, 1_000 + 10 * j, 1] for i, c in enumerate(pixels) for j in range(c)]
        batch = F.EventBatch.from_streams([torch.tensor(events)], sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)
        runs = 600
        seen = Counter()
        for seed in range(runs):
            out = F.temporal_event_shift_events(batch, torch.tensor([1]), torch.tensor([0.5]), "exact", torch.tensor([seed * 7919 + 11]))
            moved = frames_of(out)[0, 2, 1, 0, :3]
            seen[tuple(moved.tolist())] += 1
        outcomes = [z for z in product(*(range(c + 1) for c in pixels)) if sum(z) == 3]
        total = math.comb(6, 3)
        chi2 = 0.0
        for z in outcomes:
            expected = runs * math.prod(math.comb(c, k) for c, k in zip(pixels, z)) / total
            chi2 += (seen[z] - expected) ** 2 / expected
        assert set(seen) <= set(outcomes)
        assert chi2 < 24.3  # chi-square, 5 degrees of freedom, p = 0.0002

    def test_binomial_tes_and_expected_mode(self):
        batch = make_batch(2, n=400)
        out = et.TemporalEventShift(-1, 0.5, mode="binomial")(batch, generator=torch.Generator().manual_seed(0))
        assert out.num_events <= batch.num_events
        with pytest.raises(ValueError, match="expected"):
            et.TemporalEventShift(-1, 0.5, mode="expected")(batch)

    def test_time_needs_a_grid(self):
        batch = F.EventBatch.from_streams(make_streams(2), sensor_size=SENSOR)
        with pytest.raises(ValueError, match="frame grid"):
            et.FrameShift(1)(batch)

    def test_time_reversal_matches_frames(self):
        batch = make_batch()
        frames = frames_of(batch)
        assert torch.equal(frames_of(et.TimeReversal()(batch)), F.time_reversal(frames))
        flags = torch.tensor([True, False, False, True])
        assert torch.equal(frames_of(F.time_reversal(batch, flags)), F.time_reversal(frames, flags))

    def test_time_jitter_reference(self):
        batch = make_batch(2)
        seed = torch.tensor([3, 4])
        std = torch.tensor([50.0, 200.0])
        out = F.time_jitter_events(batch, std, seed)
        for b in range(2):
            # event i: the Python-integer hashes of (seed b, i, purpose), Box-Muller (float32 in the
            # kernel, float64 here), rounded to whole µs
            noise = [reference.normal(int(seed[b]), i, TIME_JITTER) * std[b].item() for i in range(batch.lengths[b])]
            for (_, _, t, _), (_, _, got, _), v in zip(rows(batch, b), rows(out, b), noise):
                assert abs(got - (t + v)) <= 0.5 + 1e-3

    def test_time_skew_reference(self):
        batch = F.EventBatch.from_streams([torch.tensor([[0, 0, 100, 1], [0, 0, 300, 0]])] * 2, sensor_size=SENSOR)
        out = F.time_skew_events(batch, torch.tensor([2.0, 0.5]), torch.tensor([10.0, 0.0]))
        assert out.t.tolist() == [110, 510, 100, 200]


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "FrameShift": lambda t, h, w: et.FrameShift(-1),
    "RandomFrameShift": lambda t, h, w: et.RandomFrameShift((-2, 2)),
    "TemporalEventShift": lambda t, h, w: et.TemporalEventShift(-2, 0.5),
    "TemporalEventShiftBinomial": lambda t, h, w: et.TemporalEventShift(-2, 0.5, mode="binomial"),
    "RandomTemporalEventShift": lambda t, h, w: et.RandomTemporalEventShift((-2, 2), (0.2, 0.8)),
    "TimeReversal": lambda t, h, w: et.TimeReversal(),
    "RandomTimeReversal": lambda t, h, w: et.RandomTimeReversal(0.5),
}

SHAPE_BATTERY = {
    "CropTime": lambda t, h, w: et.CropTime(min(1, t - 1), max(1, t - 2)),
    "RandomCropTime": lambda t, h, w: et.RandomCropTime(max(1, t - 2)),
}

EVENT_BATTERY = {
    "FrameShift": lambda: et.FrameShift(-1),
    "TemporalEventShift": lambda: et.TemporalEventShift(-2, 0.5),
    "TimeReversal": lambda: et.TimeReversal(),
    "RandomFrameShift": lambda: et.RandomFrameShift((-1, 1, 2)),
    "TES exact": lambda: et.RandomTemporalEventShift((-2, -1), (0.3, 0.7)),
    "TES binomial": lambda: et.RandomTemporalEventShift((-2, -1), (0.3, 0.7), mode="binomial"),
    "RandomTimeReversal": lambda: et.RandomTimeReversal(),
    "TimeJitter": lambda: et.TimeJitter((10.0, 300.0)),
    "TimeSkew": lambda: et.TimeSkew((0.8, 1.2), (-100.0, 100.0)),
    "TES exact p": lambda: et.RandomTemporalEventShift((-1, 1), 0.5, p=0.5),
}
