"""Rotation, resize and the general affine warp against slow references and torchvision."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torchvision.transforms.v2.functional as TF
from torchvision.transforms import InterpolationMode

import event_transforms as et
from event_transforms import functional as F

from .checkers import H, W, check_not_modified, check_sane, sparse_frames


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


def reference_affine(frames: Tensor, angle: float, scale: float, center: tuple[float, float]) -> np.ndarray:
    """Bilinear inverse warp, one output pixel at a time (zero outside the frame)."""
    x = frames.double().numpy()
    t, p, h, w = x.shape
    cy, cx = center
    theta = math.radians(angle)
    a, b = scale * math.cos(theta), scale * math.sin(theta)
    # OpenCV/kornia convention: dst = M @ src, M = [[a, b, tx], [-b, a, ty]]
    m = np.array([[a, b, (1 - a) * cx - b * cy], [-b, a, b * cx + (1 - a) * cy], [0, 0, 1]])
    inv = np.linalg.inv(m)
    out = np.zeros_like(x)
    for yo in range(h):
        for xo in range(w):
            xs, ys, _ = inv @ np.array([xo, yo, 1.0])
            x0, y0 = math.floor(xs), math.floor(ys)
            for yy, xx in ((y0, x0), (y0, x0 + 1), (y0 + 1, x0), (y0 + 1, x0 + 1)):
                if 0 <= yy < h and 0 <= xx < w:
                    weight = (1 - abs(xs - xx)) * (1 - abs(ys - yy))
                    out[:, :, yo, xo] += weight * x[:, :, yy, xx]
    return out


Tensor = torch.Tensor


class TestCenterOfMass:
    def test_against_loop(self):
        frames = sparse_frames(2, 5, 2, H, W, density=0.2)
        got = F.center_of_mass(frames)
        for b in range(2):
            total = ys = xs = 0.0
            for t in range(5):
                for p in range(2):
                    for y in range(H):
                        for x in range(W):
                            v = float(frames[b, t, p, y, x])
                            total += v
                            ys += v * y
                            xs += v * x
            assert got[b].tolist() == pytest.approx([ys / total, xs / total])

    def test_empty_is_image_centre(self):
        assert F.center_of_mass(torch.zeros(3, 2, H, W)).tolist() == [(H - 1) / 2, (W - 1) / 2]

    def test_huge_counts_in_low_precision(self):
        frames = torch.zeros(2, 2, H, W, dtype=torch.float16)
        frames[0, 0, 3, 4] = 60000
        frames[1, 1, 13, 8] = 60000
        assert F.center_of_mass(frames).tolist() == [8.0, 6.0]


class TestRotate:
    @pytest.mark.parametrize("angle", [0.0, 30.0, -75.0, 90.0, 180.0])
    def test_against_reference(self, angle):
        frames = sparse_frames(2, 2, H, W, density=0.3)
        centre = (7.3, 4.6)
        got = F.rotate(frames, angle, center=centre)
        np.testing.assert_allclose(got.double().numpy(), reference_affine(frames, angle, 1.0, centre), atol=1e-4)

    @pytest.mark.parametrize("angle", [30.0, -75.0, 90.0])
    def test_matches_torchvision_about_image_centre(self, angle):
        frames = sparse_frames(3, 2, H, W, density=0.3)
        expected = TF.rotate(frames, angle, interpolation=InterpolationMode.BILINEAR)
        torch.testing.assert_close(F.rotate(frames, angle, center="image"), expected, atol=1e-4, rtol=0)

    def test_default_centre_is_mass(self):
        frames = sparse_frames(4, 2, H, W, density=0.3)
        centre = tuple(F.center_of_mass(frames).tolist())
        torch.testing.assert_close(F.rotate(frames, 33.0), F.rotate(frames, 33.0, center=centre))

    def test_per_sample_angles_equal_per_sample_calls(self):
        frames = sparse_frames(3, 4, 2, H, W, density=0.2)
        angles = torch.tensor([10.0, -45.0, 120.0])
        batched = F.rotate(frames, angles)
        for b in range(3):
            torch.testing.assert_close(batched[b], F.rotate(frames[b], float(angles[b])))

    def test_same_angle_for_every_frame(self):
        frame = sparse_frames(1, 2, H, W, density=0.3)
        frames = frame.expand(5, 2, H, W)
        out = F.rotate(frames, 40.0, center="image")
        assert all(torch.equal(out[0], out[t]) for t in range(5))

    def test_full_turn_is_identity(self):
        frames = sparse_frames(2, 2, H, W, density=0.3)
        torch.testing.assert_close(F.rotate(frames, 360.0), frames, atol=1e-4, rtol=0)

    @pytest.mark.parametrize("dtype", [torch.uint8, torch.int16, torch.int32, torch.int64])
    def test_integer_input_bilinear_gives_float32_nearest_keeps(self, dtype):
        frames = sparse_frames(2, 2, H, W, density=0.3, dtype=dtype)
        check_sane(F.rotate(frames, 20.0), frames, torch.float32)
        check_sane(F.rotate(frames, 20.0, mode="nearest"), frames)

    @pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float64])
    def test_float_dtypes_kept(self, dtype):
        frames = sparse_frames(2, 2, H, W, density=0.3, dtype=dtype)
        out = F.rotate(frames, 20.0)
        check_sane(out, frames)
        torch.testing.assert_close(out.float(), F.rotate(frames.float(), 20.0), atol=0.05, rtol=0.02)

    def test_nearest_int64_is_exact_for_huge_counts(self):
        frames = torch.zeros(1, 2, H, W, dtype=torch.int64)
        frames[0, 1, 8, 5] = 2**40 + 1
        out = F.rotate(frames, 90.0, center=(8.0, 5.0), mode="nearest")
        assert out[0, 1, 8, 5] == 2**40 + 1

    def test_input_not_modified(self):
        frames = sparse_frames(2, 3, 2, H, W)
        check_not_modified(lambda x: F.rotate(x, 30.0), frames)

    def test_bad_input(self):
        frames = sparse_frames(2, 2, H, W)
        with pytest.raises(ValueError, match="mode"):
            F.rotate(frames, 10.0, mode="bicubic")
        with pytest.raises(ValueError, match="center"):
            F.rotate(frames, 10.0, center="middle")
        with pytest.raises(ValueError, match="angle"):
            F.rotate(frames, float("nan"))
        with pytest.raises(ValueError, match="angle"):
            F.rotate(frames.expand(3, 2, 2, H, W), torch.zeros(2))
        with pytest.raises(ValueError, match=r"\(36, 3, 70, 75\)"):
            F.rotate(torch.zeros(36, 3, 70, 75), 10.0)
        with pytest.raises(TypeError, match="frames"):
            F.rotate(np.zeros((2, 2, H, W)), 10.0)


class TestResize:
    @pytest.mark.parametrize("scale", [1.25, 15 / 18, 2.0, 0.5])
    def test_against_reference(self, scale):
        frames = sparse_frames(2, 2, H, W, density=0.3)
        centre = (9.2, 3.7)
        got = F.resize(frames, scale, center=centre)
        np.testing.assert_allclose(got.double().numpy(), reference_affine(frames, 0.0, scale, centre), atol=1e-4)

    @pytest.mark.parametrize("scale", [1.25, 0.83])
    def test_matches_torchvision_affine(self, scale):
        frames = sparse_frames(3, 2, H, W, density=0.3)
        expected = TF.affine(
            frames, angle=0.0, translate=[0, 0], scale=scale, shear=[0.0, 0.0],
            interpolation=InterpolationMode.BILINEAR,
        )
        torch.testing.assert_close(F.resize(frames, scale, center="image"), expected, atol=1e-4, rtol=0)

    def test_grows_contact_about_its_centre(self):
        frames = torch.zeros(1, 2, 41, 41)
        frames[0, 1, 15:26, 18:23] = 1.0  # an 11 x 5 strip off the image centre
        out = F.resize(frames, 1.25)
        def spread(image):  # weighted standard deviation of the row index
            weight = image.sum(1).double()
            rows = torch.arange(image.shape[0], dtype=torch.float64)
            mean = (weight * rows).sum() / weight.sum()
            return float(((weight * (rows - mean) ** 2).sum() / weight.sum()).sqrt())

        assert spread(out[0, 1]) / spread(frames[0, 1]) == pytest.approx(1.25, rel=0.05)
        torch.testing.assert_close(F.center_of_mass(out), F.center_of_mass(frames), atol=0.05, rtol=0)

    def test_scale_one_is_identity(self):
        frames = sparse_frames(3, 2, H, W)
        torch.testing.assert_close(F.resize(frames, 1.0), frames)

    def test_bad_scale(self):
        for bad in (0.0, -1.0, float("inf")):
            with pytest.raises(ValueError, match="scale"):
                F.resize(sparse_frames(2, 2, H, W), bad)


class TestModules:
    def test_random_rotation_draws_per_sample_and_applies_them(self):
        frames = sparse_frames(5, 3, 2, H, W, density=0.2)
        module = et.RandomRotation((-30.0, 60.0))
        params = module.make_params((5, 6, 2, 9, 11), generator=torch.Generator().manual_seed(1))
        assert params["angle"].unique().numel() == 5
        assert bool((params["angle"] >= -30).all() & (params["angle"] <= 60).all())
        torch.testing.assert_close(module(frames, params=params), F.rotate(frames, params["angle"]))

    def test_random_resize_choices(self):
        module = et.RandomResize(choices=(15 / 18, 15 / 12))
        scales = module.make_params((200, 6, 2, 9, 11), generator=torch.Generator().manual_seed(0))["scale"]
        assert set(scales.tolist()) == {15 / 18, 15 / 12}

    def test_random_resize_needs_one_setting(self):
        with pytest.raises(ValueError, match="exactly one"):
            et.RandomResize()
        with pytest.raises(ValueError, match="exactly one"):
            et.RandomResize((0.8, 1.2), choices=(1.0,))
        with pytest.raises(ValueError, match="scale"):
            et.RandomResize((0.0, 1.2))

    def test_bad_settings(self):
        with pytest.raises(ValueError, match="degrees"):
            et.RandomRotation((30.0, -30.0))
        with pytest.raises(ValueError, match="degrees"):
            et.RandomRotation(-5.0)
        with pytest.raises(TypeError, match="degrees"):
            et.RandomRotation("45")
        with pytest.raises(ValueError, match="p"):
            et.RandomHorizontalFlip(p=1.5)
        with pytest.raises(ValueError, match="mode"):
            et.Rotate(10.0, mode="cubic")

    def test_repr(self):
        assert repr(et.RandomRotation(45.0)) == "RandomRotation(degrees=(-45.0, 45.0), center='mass', mode='bilinear')"
        assert "choices=(1.25,)" in repr(et.RandomResize(choices=[1.25]))


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
