"""Geometry: affine (rotate/resize as special cases), translation, crops, sum-pooling, each
against a slow reference (Python loops over pixels)."""

from __future__ import annotations

import math

import pytest
import torch

import event_transforms as et
from event_transforms import functional as F

from .checkers import H, W, check_not_modified, sparse_frames


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


def _reference_affine_nearest(frames, angle, scale, translate, shear, center):
    """Inverse-map every output pixel through the 2×3 forward map, nearest source pixel."""
    b, t, p, h, w = frames.shape
    out = torch.zeros_like(frames)
    for n in range(b):
        th = math.radians(angle[n])
        shx, shy = math.tan(math.radians(shear[n][0])), math.tan(math.radians(shear[n][1]))
        rot = [[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]]
        sh = [[1 + shx * shy, shx], [shy, 1]]
        a = [[scale[n] * sum(rot[i][k] * sh[k][j] for k in range(2)) for j in range(2)] for i in range(2)]
        det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
        inv = [[a[1][1] / det, -a[0][1] / det], [-a[1][0] / det, a[0][0] / det]]
        cy, cx = center[n]
        for y in range(h):
            for x in range(w):
                u, v = x - cx - translate[n][1], y - cy - translate[n][0]
                sx = inv[0][0] * u + inv[0][1] * v + cx
                sy = inv[1][0] * u + inv[1][1] * v + cy
                ix, iy = round(sx), round(sy)
                if abs(sx - ix) > 0.49 or abs(sy - iy) > 0.49:
                    continue  # ambiguous rounding: checked elsewhere
                if 0 <= ix < w and 0 <= iy < h:
                    out[n, :, :, y, x] = frames[n, :, :, iy, ix]
    return out


class TestAffine:
    def test_special_cases_equal_rotate_and_resize(self):
        frames = sparse_frames(3, 4, 2, H, W, density=0.3)
        angle = torch.tensor([30.0, -75.0, 190.0], dtype=torch.float64)
        scale = torch.tensor([0.83, 1.25, 1.7], dtype=torch.float64)
        for mode in ("bilinear", "nearest"):
            for center in ("mass", "image", (4.0, 6.5)):
                torch.testing.assert_close(
                    F.affine(frames, angle=angle, center=center, mode=mode), F.rotate(frames, angle, center=center, mode=mode)
                )
                torch.testing.assert_close(
                    F.affine(frames, scale=scale, center=center, mode=mode), F.resize(frames, scale, center=center, mode=mode)
                )

    def test_against_reference_nearest(self):
        frames = sparse_frames(3, 2, 2, H, W, density=0.4, dtype=torch.float64)
        angle = [20.0, -40.0, 0.0]
        scale = [1.1, 0.9, 1.0]
        translate = [[1.5, -2.0], [0.0, 3.0], [-2.0, 0.0]]
        shear = [[10.0, 0.0], [-5.0, 8.0], [0.0, 0.0]]
        center = F.center_of_mass(frames).tolist()
        out = F.affine(
            frames, angle=torch.tensor(angle), scale=torch.tensor(scale), translate=torch.tensor(translate),
            shear=torch.tensor(shear), center="mass", mode="nearest",
        )
        ref = _reference_affine_nearest(frames, angle, scale, translate, shear, center)
        known = ref != 0
        assert torch.equal(out[known], ref[known])
        assert int(known.sum()) > 20

    def test_integer_translation_equals_translate(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3, dtype=torch.int32)
        shift = torch.tensor([[2, -3], [-1, 4]])
        out = F.affine(frames, translate=shift.double(), mode="nearest")
        assert torch.equal(out, F.translate(frames, shift))

    def test_module_replays_and_draws_per_sample(self):
        frames = sparse_frames(4, 3, 2, H, W, density=0.3)
        module = et.RandomAffine(30.0, translate=(0.1, 0.2), scale=(0.8, 1.2), shear=(-5, 5, -3, 3))
        params = module.make_params(frames.shape, generator=_g(1))
        assert len(set(params["angle"].tolist())) == 4
        assert bool((params["translate"][:, 0].abs() <= 0.1 * H).all())
        out = module(frames, params=params)
        expected = F.affine(
            frames, angle=params["angle"], translate=params["translate"], scale=params["scale"], shear=params["shear"]
        )
        torch.testing.assert_close(out, expected)

    @pytest.mark.parametrize(
        "kwargs, error, match",
        [
            ({"scale": 0.0}, ValueError, "scale"),
            ({"shear": (95.0, 0.0)}, ValueError, "shear"),
            ({"translate": (1.0,)}, ValueError, "translate"),
            ({"translate": "up"}, TypeError, "translate"),
            ({"mode": "cubic"}, ValueError, "mode"),
            ({"angle": float("inf")}, ValueError, "angle"),
        ],
    )
    def test_named_errors(self, kwargs, error, match):
        with pytest.raises(error, match=match):
            F.affine(torch.zeros(2, 2, 3, 3), **kwargs)

    def test_module_named_errors(self):
        with pytest.raises(ValueError, match="scale"):
            et.RandomAffine(scale=(0.0, 1.0))
        with pytest.raises(ValueError, match="shear"):
            et.RandomAffine(shear=100.0)
        with pytest.raises(ValueError, match="translate"):
            et.RandomAffine(translate=(0.5, 2.0))


def _reference_translate(frames, shift):
    b, t, p, h, w = frames.shape
    out = torch.zeros_like(frames)
    for n in range(b):
        dy, dx = shift[n]
        for y in range(h):
            for x in range(w):
                if 0 <= y - dy < h and 0 <= x - dx < w:
                    out[n, :, :, y, x] = frames[n, :, :, y - dy, x - dx]
    return out


class TestTranslate:
    @pytest.mark.parametrize("dtype", [torch.uint8, torch.int64, torch.float16])
    def test_against_reference(self, dtype):
        frames = sparse_frames(4, 3, 2, H, W, density=0.3, dtype=dtype)
        shift = [[0, 0], [3, -2], [-20, 1], [-1, 11]]
        out = check_not_modified(lambda x: F.translate(x, torch.tensor(shift)), frames)
        assert out.dtype == dtype
        assert torch.equal(out, _reference_translate(frames, shift))

    def test_counts_only_fall(self):
        frames = sparse_frames(5, 3, 2, H, W, density=0.3)
        out = et.RandomTranslate(4)(frames, generator=_g())
        assert bool((out.sum((1, 2, 3, 4)) <= frames.sum((1, 2, 3, 4))).all())

    def test_draws_cover_the_range(self):
        params = et.RandomTranslate((1, 2)).make_params((400, 1, 2, 3, 3), generator=_g())
        assert set(params["shift"][:, 0].tolist()) == {-1, 0, 1}
        assert set(params["shift"][:, 1].tolist()) == {-2, -1, 0, 1, 2}

    def test_named_errors(self):
        with pytest.raises(TypeError, match="shift"):
            F.translate(torch.zeros(1, 2, 3, 3), (0.5, 1))
        with pytest.raises(ValueError, match="max_shift"):
            et.RandomTranslate(-1)


class TestCrop:
    def test_against_reference(self):
        frames = sparse_frames(3, 2, 2, H, W, density=0.4, dtype=torch.int16)
        top, left = [0, 5, 9], [3, 0, 6]
        out = F.crop(frames, torch.tensor(top), torch.tensor(left), (8, 5))
        assert out.shape == (3, 2, 2, 8, 5) and out.dtype == torch.int16
        for n in range(3):
            for y in range(8):
                for x in range(5):
                    assert torch.equal(out[n, :, :, y, x], frames[n, :, :, top[n] + y, left[n] + x])

    def test_resize_back_equals_interpolate(self):
        frames = sparse_frames(2, 2, 2, H, W, density=0.4, dtype=torch.int32)
        out = F.crop(frames, 2, 1, (8, 5), resize=True)
        assert out.shape == frames.shape and out.dtype == torch.float32
        window = frames[:, :, :, 2:10, 1:6].float().reshape(2, 4, 8, 5)
        expected = torch.nn.functional.interpolate(window, size=(H, W), mode="bilinear").reshape(frames.shape)
        torch.testing.assert_close(out, expected)
        assert F.crop(frames, 2, 1, (8, 5), resize=True, mode="nearest").dtype == torch.int32

    def test_center_crop(self):
        frames = sparse_frames(2, 2, 2, H, W, density=0.4)
        assert torch.equal(et.CenterCrop((7, 4))(frames), frames[..., 5:12, 3:7])
        assert torch.equal(F.center_crop(frames, (7, 4)), frames[..., 5:12, 3:7])

    def test_random_crop_is_a_window_per_sample(self):
        frames = torch.arange(4 * H * W, dtype=torch.float32).reshape(4, 1, 1, H, W).expand(4, 3, 2, H, W)
        module = et.RandomCrop((5, 4))
        params = module.make_params(frames.shape, generator=_g(3))
        out = module(frames, params=params)
        for n in range(4):
            t, l = int(params["top"][n]), int(params["left"][n])
            assert torch.equal(out[n], frames[n, :, :, t : t + 5, l : l + 4])
        assert module.output_shape(frames.shape) == out.shape

    def test_named_errors(self):
        with pytest.raises(ValueError, match="size"):
            F.crop(torch.zeros(1, 2, 3, 3), 0, 0, 4)
        with pytest.raises(ValueError, match="top"):
            F.crop(torch.zeros(1, 2, 5, 5), 3, 0, 3)
        with pytest.raises(ValueError, match="resize=True"):
            et.RandomCrop(3, p=0.5)
        with pytest.raises(ValueError, match="does not fit"):
            et.RandomCrop(30)(torch.zeros(1, 2, 5, 5))


class TestDownsample:
    @pytest.mark.parametrize("remainder", ["drop", "keep"])
    @pytest.mark.parametrize("dtype", [torch.int32, torch.float32])
    def test_against_reference(self, remainder, dtype):
        frames = sparse_frames(2, 2, 2, H, W, density=0.4, dtype=dtype)
        out = F.downsample(frames, (3, 2), remainder=remainder)
        ho, wo = (H // 3, W // 2) if remainder == "drop" else (-(-H // 3), -(-W // 2))
        assert out.shape == (2, 2, 2, ho, wo) and out.dtype == dtype
        ref = torch.zeros(2, 2, 2, ho, wo, dtype=torch.float64)
        for y in range(H):
            for x in range(W):
                if y // 3 < ho and x // 2 < wo:
                    ref[..., y // 3, x // 2] += frames[..., y, x].double()
        assert torch.equal(out.double(), ref)
        if remainder == "keep":
            assert float(out.double().sum()) == float(frames.double().sum())

    def test_paper_pooling(self):
        frames = sparse_frames(36, 2, 140, 150, density=0.1, dtype=torch.int16)
        out = et.Downsample(2)(frames)
        assert out.shape == (36, 2, 70, 75) and int(out.sum()) == int(frames.sum())

    def test_narrow_overflow_raises(self):
        frames = torch.full((1, 2, 2, 2), 200, dtype=torch.uint8)
        with pytest.raises(ValueError, match="wider dtype"):
            F.downsample(frames, 2)

    def test_named_errors(self):
        with pytest.raises(ValueError, match="factor"):
            F.downsample(torch.zeros(1, 2, 4, 4), 0)
        with pytest.raises(ValueError, match="remainder"):
            et.Downsample(2, remainder="pad")
