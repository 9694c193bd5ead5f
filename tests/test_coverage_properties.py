"""Property tests (hypothesis) for the issue-13 transforms: invariants that hold for any
shape, parameter and count."""

from __future__ import annotations

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from event_transforms import functional as F

shapes = st.tuples(st.integers(0, 3), st.integers(1, 4), st.integers(1, 9), st.integers(1, 9))


def _frames(shape, seed):
    b, t, h, w = shape
    g = torch.Generator().manual_seed(seed)
    return torch.randint(0, 5, (b, t, 2, h, w), generator=g, dtype=torch.int64)


@settings(max_examples=60, deadline=None)
@given(shapes, st.integers(0, 2**31), st.integers(1, 4), st.integers(1, 4))
def test_downsample_keep_conserves_every_event(shape, seed, fy, fx):
    frames = _frames(shape, seed)
    out = F.downsample(frames, (fy, fx), remainder="keep")
    assert torch.equal(out.sum((1, 2, 3, 4)), frames.sum((1, 2, 3, 4)))


@settings(max_examples=60, deadline=None)
@given(shapes, st.integers(0, 2**31), st.integers(-10, 10), st.integers(-10, 10))
def test_translate_there_and_back_keeps_what_stayed_inside(shape, seed, dy, dx):
    frames = _frames(shape, seed)
    b = frames.shape[0]
    there = F.translate(frames, torch.tensor([[dy, dx]] * b, dtype=torch.int64).reshape(b, 2))
    back = F.translate(there, torch.tensor([[-dy, -dx]] * b, dtype=torch.int64).reshape(b, 2))
    assert bool((there.sum() <= frames.sum()).all())
    assert bool((back == frames)[back > 0].all())  # whatever came back is where it was
    assert int(back.sum()) == int(there.sum())


@settings(max_examples=60, deadline=None)
@given(shapes, st.integers(0, 2**31))
def test_time_reversal_is_an_involution_that_swaps_polarity_totals(shape, seed):
    frames = _frames(shape, seed)
    out = F.time_reversal(frames)
    assert torch.equal(F.time_reversal(out), frames)
    assert torch.equal(out.sum((1, 3, 4)), frames.sum((1, 3, 4)).flip(1))


@settings(max_examples=60, deadline=None)
@given(shapes, st.integers(0, 2**31), st.data())
def test_cutmix_counts_are_outside_own_plus_inside_partner(shape, seed, data):
    frames = _frames(shape, seed)
    b, _, _, h, w = frames.shape
    partner = torch.randperm(b, generator=torch.Generator().manual_seed(seed))
    top = torch.tensor([data.draw(st.integers(0, h)) for _ in range(b)], dtype=torch.int64)
    left = torch.tensor([data.draw(st.integers(0, w)) for _ in range(b)], dtype=torch.int64)
    height = torch.tensor([data.draw(st.integers(0, h)) for _ in range(b)], dtype=torch.int64)
    width = torch.tensor([data.draw(st.integers(0, w)) for _ in range(b)], dtype=torch.int64)
    out = F.cutmix(frames, partner, top, left, height, width)
    inside = F.cutout(torch.ones_like(frames), top, left, height, width) == 0
    expected = (frames * ~inside).sum((1, 2, 3, 4)) + (frames[partner] * inside).sum((1, 2, 3, 4))
    assert torch.equal(out.sum((1, 2, 3, 4)), expected)


@settings(max_examples=40, deadline=None)
@given(shapes, st.integers(0, 2**31), st.integers(0, 3), st.integers(0, 3))
def test_denoise_only_removes_whole_entries(shape, seed, radius, temporal_radius):
    frames = _frames(shape, seed) * (torch.rand(shape[0], shape[1], 2, shape[2], shape[3], generator=torch.Generator().manual_seed(seed)) < 0.2)
    out = F.denoise(frames, radius=radius, temporal_radius=temporal_radius)
    kept = out > 0
    assert torch.equal(out[kept], frames[kept]) and bool((out <= frames).all())
