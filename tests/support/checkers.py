"""Shared checkers and inputs for transform tests (torchvision v2's habit)."""

from __future__ import annotations

import pickle

import torch
from hypothesis import strategies as st
from torch import Tensor

H, W = 17, 11  # deliberately non-square, H != W
#: (B, T, H, W) for :func:`random_counts` in property tests, B = 0 included.
count_shapes = st.tuples(st.integers(0, 3), st.integers(1, 4), st.integers(1, 9), st.integers(1, 9))


def sparse_frames(
    *shape: int, density: float = 0.05, high: int = 4, seed: int = 0, dtype: torch.dtype = torch.float32
) -> Tensor:
    """Realistic sparse event counts: ``density`` of pixels hold 1..high-1 events."""
    g = torch.Generator().manual_seed(seed)
    mask = torch.rand(shape, generator=g) < density
    counts = torch.randint(1, high, shape, generator=g)
    return (mask * counts).to(dtype)


def check_not_modified(function, frames: Tensor) -> Tensor:
    """Call ``function(frames)`` and assert the input was neither written nor changed."""
    version = frames._version
    before = frames.clone()
    out = function(frames)
    assert frames._version == version, "input tensor was modified in place"
    assert torch.equal(frames, before)
    return out


def check_sane(out: Tensor, frames: Tensor, dtype: torch.dtype | None = None) -> None:
    """Shape and device kept, dtype as expected, finite, non-negative."""
    assert out.shape == frames.shape
    assert out.device == frames.device
    assert out.dtype == (frames.dtype if dtype is None else dtype)
    if out.numel():
        wide = out.double()
        assert bool(torch.isfinite(wide).all())
        assert bool((wide >= 0).all())


def check_pickle(module: torch.nn.Module, frames: Tensor) -> None:
    """A pickled round trip gives the same output for the same generator seed."""
    clone = pickle.loads(pickle.dumps(module))
    a = module(frames, generator=torch.Generator().manual_seed(3))
    b = clone(frames, generator=torch.Generator().manual_seed(3))
    assert torch.equal(a, b)
    assert repr(clone) == repr(module)


def random_counts(shape: tuple[int, int, int, int], seed: int) -> Tensor:
    """Dense counts 0..4 of shape ``(B, T, 2, H, W)`` for ``shape = (B, T, H, W)`` (property tests)."""
    b, t, h, w = shape
    g = torch.Generator().manual_seed(seed)
    return torch.randint(0, 5, (b, t, 2, h, w), generator=g, dtype=torch.int64)
