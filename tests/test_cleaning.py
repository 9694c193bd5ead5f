"""Cleaning: hot/given pixel removal, random pixel dropout and the frame-level denoising
filter against slow references (Python loops over entries and windows)."""

from __future__ import annotations

import pytest
import torch

import event_transforms as et
from event_transforms import functional as F
from event_transforms.transforms.base import slice_params

from .checkers import H, W, check_not_modified, sparse_frames


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


class TestDropPixel:
    def test_coordinates_against_reference(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.5, dtype=torch.int16)
        pixels = [[0, 0], [16, 10], [5, 3]]
        out = check_not_modified(et.DropPixel(pixels), frames)
        ref = frames.clone()
        for y, x in pixels:
            ref[..., y, x] = 0
        assert out.dtype == torch.int16 and torch.equal(out, ref)
        assert torch.equal(F.drop_pixel(frames, torch.tensor(pixels)), ref)

    def test_hot_pixels_against_reference(self):
        frames = sparse_frames(3, 8, 2, H, W, density=0.1)
        frames[0, :, 1, 2, 3] = 3.0  # 300 Hz at 10 ms frames
        frames[2, ::2, 0, 7, 7] = 2.0  # 100 Hz
        out = et.DropPixel(rate_hz=90.0)(frames)
        ref = frames.clone()
        for n in range(3):
            for y in range(H):
                for x in range(W):
                    if float(frames[n, :, :, y, x].sum()) / (8 * 0.010) > 90.0:
                        ref[n, :, :, y, x] = 0
        assert torch.equal(out, ref)
        assert not out[0, :, 1, 2, 3].any() and not out[2, :, 0, 7, 7].any()

    def test_named_errors(self):
        with pytest.raises(ValueError, match="exactly one"):
            et.DropPixel()
        with pytest.raises(ValueError, match="inside"):
            F.drop_pixel(torch.zeros(1, 2, 3, 3), [[3, 0]])
        with pytest.raises(TypeError, match="integers"):
            F.drop_pixel(torch.zeros(1, 2, 3, 3), [[0.5, 0.0]])
        with pytest.raises(ValueError, match="rate_hz"):
            F.hot_pixels(torch.zeros(1, 2, 3, 3), 0.0)


class TestRandomDropPixel:
    def test_mask_is_per_pixel_and_shared_by_frames(self):
        frames = torch.ones(4, 3, 2, 40, 30)
        module = et.RandomDropPixel((0.2, 0.6))
        params = module.make_params(frames.shape, generator=_g(1))
        out = module(frames, params=params)
        dropped = out == 0
        assert torch.equal(dropped, dropped[:, :1, :1].expand_as(dropped))  # all frames, both polarities
        share = dropped[:, 0, 0].float().mean((1, 2))
        torch.testing.assert_close(share, params["fraction"].float(), atol=0.06, rtol=0)

    def test_batched_equals_alone_and_replays(self):
        frames = sparse_frames(3, 4, 2, H, W, density=0.5)
        module = et.RandomDropPixel(0.5)
        params = module.make_params(frames.shape, generator=_g(2))
        out = module(frames, params=params)
        for n in range(3):
            assert torch.equal(module(frames[n : n + 1], params=slice_params(params, torch.tensor([n])))[0], out[n])
        other = module.make_params(frames.shape, generator=_g(3))
        assert not torch.equal(module(frames, params=other), out)


def _reference_denoise(frames, radius, temporal_radius):
    b, t, p, h, w = frames.shape
    out = frames.clone()
    for n in range(b):
        for i in range(t):
            for c in range(p):
                for y in range(h):
                    for x in range(w):
                        if frames[n, i, c, y, x] <= 0:
                            continue
                        found = False
                        for j in range(max(0, i - temporal_radius), min(t, i + temporal_radius + 1)):
                            for d in range(p):
                                for yy in range(max(0, y - radius), min(h, y + radius + 1)):
                                    for xx in range(max(0, x - radius), min(w, x + radius + 1)):
                                        if (j, d, yy, xx) != (i, c, y, x) and frames[n, j, d, yy, xx] > 0:
                                            found = True
                        if not found:
                            out[n, i, c, y, x] = 0
    return out


class TestDenoise:
    @pytest.mark.parametrize("radius, temporal_radius", [(1, 1), (0, 0), (2, 0), (1, 5)])
    def test_against_reference(self, radius, temporal_radius):
        frames = sparse_frames(2, 4, 2, 9, 7, density=0.04, dtype=torch.int32)
        out = F.denoise(frames, radius=radius, temporal_radius=temporal_radius)
        assert torch.equal(out, _reference_denoise(frames, radius, temporal_radius))

    def test_module_and_counts(self):
        frames = sparse_frames(2, 6, 2, H, W, density=0.05, dtype=torch.uint8)
        out = check_not_modified(et.Denoise(), frames)
        assert out.dtype == torch.uint8
        kept = out > 0
        assert torch.equal(out[kept], frames[kept]) and int(out.sum()) < int(frames.sum())

    def test_named_errors(self):
        with pytest.raises(ValueError, match="radius"):
            et.Denoise(-1)
        with pytest.raises(TypeError, match="temporal_radius"):
            F.denoise(torch.zeros(1, 2, 3, 3), temporal_radius=0.5)
