"""The shared battery of the functional kernels (torchvision's ``check_kernel`` habit).

Every public kernel in :mod:`event_transforms.functional` that maps frames to frames runs
through the same checks: input never modified, device kept, dtype by the documented rule,
one sequence equals a batch of one, B = 0 and T = 1 work, per-sample parameters equal
per-sample calls (deterministic kernels), seeded calls repeat (random kernels), and a
non-tensor or mis-shaped input is refused by name.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from event_transforms import functional as F

from tests.support.checkers import H, W, check_not_modified, sparse_frames


def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _noise(frames) -> torch.Tensor:
    """A fixed (2, H, W) displacement field in [-1, 1] for the frames' size (every sample)."""
    return torch.rand(2, *frames.shape[-2:], generator=gen(1)) * 2 - 1


# name -> (kernel(frames, params, generator), per-sample params for a batch of 3, output dtype rule)
# The params are lists of per-sample values; a kernel gets them as (B,) tensors.
KERNELS = {
    "rotate": (lambda x, p, g: F.rotate(x, p[0]), [[30.0, -45.0, 90.0]], "interpolating"),
    "rotate-nearest": (lambda x, p, g: F.rotate(x, p[0], mode="nearest"), [[30.0, -45.0, 90.0]], "kept"),
    "resize": (lambda x, p, g: F.resize(x, p[0]), [[1.25, 0.8, 1.0]], "interpolating"),
    "perspective": (
        lambda x, p, g: F.perspective(x, p[0] if p[0].numel() else p[0].reshape(0, 4, 2)),
        [[[[1, 1], [0, 10], [16, 9], [15, 0]], [[0, 0], [0, 10], [16, 10], [16, 0]], [[2, 1], [1, 9], [14, 8], [15, 2]]]],
        "interpolating",
    ),
    "elastic": (lambda x, p, g: F.elastic(x, _noise(x), alpha=p[0], sigma=2.0), [[4.0, 0.0, 9.0]], "interpolating"),
    "horizontal_flip": (lambda x, p, g: F.horizontal_flip(x), [], "kept"),
    "vertical_flip": (lambda x, p, g: F.vertical_flip(x), [], "kept"),
    "frame_shift": (lambda x, p, g: F.frame_shift(x, p[0]), [[-1, 2, 0]], "kept"),
    "tes-exact": (lambda x, p, g: F.temporal_event_shift(x, p[0], p[1], generator=g), [[-1, 2, 0], [0.5, 0.25, 1.0]], "kept"),
    "tes-binomial": (
        lambda x, p, g: F.temporal_event_shift(x, p[0], p[1], mode="binomial", generator=g),
        [[-1, 2, 0], [0.5, 0.25, 1.0]], "kept",
    ),
    "tes-expected": (
        lambda x, p, g: F.temporal_event_shift(x, p[0], p[1], mode="expected"),
        [[-1, 2, 0], [0.5, 0.25, 1.0]], "interpolating",
    ),
    "add_noise": (lambda x, p, g: F.add_noise(x, torch.ones(x.shape[-4:], dtype=torch.int16)), [], "kept"),
    "add_poisson_noise": (lambda x, p, g: F.add_poisson_noise(x, p[0], generator=g), [[5.0, 0.0, 200.0]], "kept"),
    "drop_events": (lambda x, p, g: F.drop_random(x, p[0], generator=g), [[0.5, 0.0, 1.0]], "kept"),
    "drop_events-expected": (lambda x, p, g: F.drop_random(x, p[0], mode="expected"), [[0.5, 0.0, 1.0]], "interpolating"),
    "drop_by_time": (lambda x, p, g: F.drop_by_time(x, p[0], p[1]), [[0, 2, 5], [1, 3, 9]], "kept"),
    "drop_by_area": (
        lambda x, p, g: F.drop_by_area(x, p[0], p[1], p[2], p[3]), [[0, 3, 16], [0, 2, 5], [4, 2, 9], [1, 6, 9]], "kept",
    ),
}
RANDOM = {"tes-exact", "tes-binomial", "add_poisson_noise", "drop_events"}
NAMES = sorted(KERNELS)


def call(name: str, frames: torch.Tensor, params: list | None = None, seed: int = 0) -> torch.Tensor:
    kernel, default, _ = KERNELS[name]
    batch = frames.shape[0] if frames.dim() == 5 else 1
    values = default if params is None else params
    tensors = [torch.tensor(v[:batch] if frames.dim() == 5 else v[0]) for v in values]
    return kernel(frames, tensors, gen(seed))


def expected_dtype(name: str, dtype: torch.dtype) -> torch.dtype:
    if KERNELS[name][2] == "interpolating" and not dtype.is_floating_point:
        return torch.float32
    return dtype


@pytest.mark.parametrize("name", NAMES)
class TestKernelBattery:
    @pytest.mark.parametrize("dtype", [torch.float32, torch.float16, torch.bfloat16, torch.float64, torch.uint8, torch.int16, torch.int64])
    def test_dtype_device_and_no_in_place_change(self, name, dtype):
        frames = sparse_frames(3, 6, 2, H, W, density=0.2, dtype=dtype)
        out = check_not_modified(lambda x: call(name, x), frames)
        assert out.shape == frames.shape and out.device == frames.device
        assert out.dtype == expected_dtype(name, dtype)

    def test_single_sequence_equals_batch_of_one(self, name):
        frames = sparse_frames(6, 2, H, W, density=0.2)
        single = call(name, frames, seed=4)
        batch = call(name, frames.unsqueeze(0), seed=4)
        assert single.shape == frames.shape and torch.equal(single, batch[0])

    def test_zero_batch_and_one_frame(self, name):
        empty = torch.zeros(0, 6, 2, H, W, dtype=torch.int16)
        out = call(name, empty, params=[[] for _ in KERNELS[name][1]])
        assert out.shape == empty.shape and out.dtype == expected_dtype(name, torch.int16)
        one = sparse_frames(3, 1, 2, H, W, density=0.3)
        assert call(name, one).shape == one.shape

    def test_per_sample_parameters_equal_per_sample_calls(self, name):
        frames = sparse_frames(3, 6, 2, H, W, density=0.2)
        if name in RANDOM:  # seeded calls repeat; different seeds differ
            assert torch.equal(call(name, frames, seed=7), call(name, frames, seed=7))
            assert not torch.equal(call(name, frames, seed=7), call(name, frames, seed=8))
            return
        batched = call(name, frames)
        values = KERNELS[name][1]
        for b in range(3):
            alone = call(name, frames[b : b + 1], params=[[v[b]] for v in values])
            torch.testing.assert_close(alone[0], batched[b], rtol=1e-5, atol=1e-5)

    def test_bad_frames_are_refused_by_name(self, name):
        kernel, values, _ = KERNELS[name]
        scalars = [torch.tensor(v[0]) for v in values]
        with pytest.raises(TypeError, match="frames must be a torch.Tensor, got ndarray"):
            kernel(np.zeros((6, 2, H, W)), scalars, gen())
        with pytest.raises(ValueError, match=r"frames: expected \(T, 2, H, W\) or \(B, T, 2, H, W\), got \(6, 3, 17, 11\)"):
            kernel(torch.zeros(6, 3, H, W), scalars, gen())

    def test_parameters_of_the_wrong_length_are_refused_by_name(self, name):
        kernel, values, _ = KERNELS[name]
        if not values:
            return
        frames = sparse_frames(2, 6, 2, H, W)
        with pytest.raises(ValueError, match=r"must be a scalar or have shape \(2,\)|must have shape \(4, 2\) or \(2, 4, 2\)"):
            kernel(frames, [torch.tensor(v) for v in values], gen())


def test_center_of_mass_battery():
    frames = sparse_frames(3, 6, 2, H, W, density=0.2, dtype=torch.int16)
    out = check_not_modified(F.center_of_mass, frames)
    assert out.shape == (3, 2) and out.dtype == torch.float64
    torch.testing.assert_close(F.center_of_mass(frames[1]), out[1])
    assert F.center_of_mass(torch.zeros(0, 6, 2, H, W)).shape == (0, 2)
    torch.testing.assert_close(F.center_of_mass(torch.zeros(6, 2, H, W)), torch.tensor([(H - 1) / 2, (W - 1) / 2], dtype=torch.float64))
