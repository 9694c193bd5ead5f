"""Rotation, resize and the general affine warp against slow references and torchvision."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch
import torchvision.transforms.v2.functional as TF
from torchvision.transforms import InterpolationMode

import event_transforms as et
from event_transforms import EventBatch
from event_transforms.events import EventsOutsideSensorWarning
from event_transforms import functional as F

from tests.support.event_data import SENSOR, T, check_hard_cases, frames_of, make_batch, make_streams, rows, same_events
from tests.support.checkers import H, W, check_not_modified, check_sane, sparse_frames


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


# --------------------------------------------------------------------------- perspective and elastic


def _bilinear(x: np.ndarray, ys: float, xs: float) -> np.ndarray:
    """Bilinear sample of (T, P, H, W) ``x`` at one (y, x) point, zero outside."""
    h, w = x.shape[-2:]
    out = np.zeros(x.shape[:2])
    y0, x0 = math.floor(ys), math.floor(xs)
    for yy, xx in ((y0, x0), (y0, x0 + 1), (y0 + 1, x0), (y0 + 1, x0 + 1)):
        if 0 <= yy < h and 0 <= xx < w:
            out += (1 - abs(xs - xx)) * (1 - abs(ys - yy)) * x[:, :, yy, xx]
    return out


def reference_perspective(frames: Tensor, corners: list[list[float]]) -> np.ndarray:
    """Solve the forward homography (frame corners -> ``corners``) from its eight equations,
    invert it, and sample every output pixel bilinearly (zero outside)."""
    x = frames.double().numpy()
    t, p, h, w = x.shape
    source = [(0.0, 0.0), (w - 1.0, 0.0), (w - 1.0, h - 1.0), (0.0, h - 1.0)]  # (x, y)
    rows, rhs = [], []
    for (sx, sy), (dy, dx) in zip(source, corners):
        rows.append([sx, sy, 1, 0, 0, 0, -sx * dx, -sy * dx])
        rhs.append(dx)
        rows.append([0, 0, 0, sx, sy, 1, -sx * dy, -sy * dy])
        rhs.append(dy)
    forward = np.append(np.linalg.solve(np.array(rows), np.array(rhs)), 1.0).reshape(3, 3)
    inverse = np.linalg.inv(forward)
    out = np.zeros_like(x)
    for yo in range(h):
        for xo in range(w):
            sx, sy, sw = inverse @ np.array([xo, yo, 1.0])
            out[:, :, yo, xo] = _bilinear(x, sy / sw, sx / sw)
    return out


def reference_elastic(frames: Tensor, noise: Tensor, alpha: float, sigma: float) -> np.ndarray:
    """Smooth the noise with a Gaussian over ±3 sigma (zero outside), one pixel at a time, and
    sample every output pixel at its displaced position bilinearly (zero outside)."""
    x, n = frames.double().numpy(), noise.double().numpy()
    t, p, h, w = x.shape
    radius = math.ceil(3 * sigma)
    weights = [math.exp(-0.5 * (k / sigma) ** 2) for k in range(-radius, radius + 1)]
    weights = [v / sum(weights) for v in weights]
    out = np.zeros_like(x)
    for yo in range(h):
        for xo in range(w):
            field = [0.0, 0.0]
            for i, wy in enumerate(weights):
                for j, wx in enumerate(weights):
                    yy, xx = yo + i - radius, xo + j - radius
                    if 0 <= yy < h and 0 <= xx < w:
                        field[0] += wy * wx * n[0, yy, xx]
                        field[1] += wy * wx * n[1, yy, xx]
            out[:, :, yo, xo] = _bilinear(x, yo + alpha * field[0], xo + alpha * field[1])
    return out


CORNERS = [[1.0, 0.5], [0.0, 9.0], [15.5, 10.0], [16.0, 1.5]]  # a convex quadrilateral in a 17×11 frame


class TestPerspective:
    def test_matches_slow_reference(self):
        frames = sparse_frames(3, 2, H, W, density=0.3)
        out = check_not_modified(lambda x: F.perspective(x, CORNERS), frames)
        np.testing.assert_allclose(out.double().numpy(), reference_perspective(frames, CORNERS), atol=1e-4)

    def test_frame_corners_are_the_identity_and_nearest_keeps_the_dtype(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3, dtype=torch.int16)
        corners = [[0, 0], [0, W - 1], [H - 1, W - 1], [H - 1, 0]]
        out = F.perspective(frames, corners, mode="nearest")
        assert out.dtype == torch.int16 and torch.equal(out, frames)
        assert F.perspective(frames, corners).dtype == torch.float32

    def test_per_sample_corners_equal_per_sample_calls(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3)
        corners = torch.tensor([CORNERS, [[0.0, 0.0], [1.0, 10.0], [16.0, 9.0], [15.0, 0.0]]])
        out = F.perspective(frames, corners)
        for b in range(2):
            torch.testing.assert_close(out[b], F.perspective(frames[b], corners[b]))

    def test_matches_kornia(self):
        kornia = pytest.importorskip("kornia")
        frames = sparse_frames(3, 2, H, W, density=0.3)
        corners = torch.tensor(CORNERS, dtype=torch.float64)
        source = torch.tensor([[0.0, 0.0], [W - 1.0, 0.0], [W - 1.0, H - 1.0], [0.0, H - 1.0]], dtype=torch.float64)
        matrix = kornia.geometry.transform.get_perspective_transform(source[None], corners.flip(-1)[None])
        folded = frames.reshape(1, -1, H, W).double()
        expected = kornia.geometry.transform.warp_perspective(folded, matrix, (H, W), align_corners=True)
        torch.testing.assert_close(F.perspective(frames.double().unsqueeze(0), corners), expected.view(1, *frames.shape))

    @pytest.mark.parametrize(
        "corners, error, message",
        [
            ([[0, 0], [0, 10], [16, 10]], ValueError, r"perspective: corners must have shape \(4, 2\) or \(1, 4, 2\)"),
            ([[0, 0], [16, 10], [0, 10], [16, 0]], ValueError, "convex quadrilateral"),  # crossed
            ([[0, 0], [0, 10], [16, 10], [16, float("nan")]], ValueError, "finite"),
            ("corners", TypeError, "corners must be"),
            ([[True, False]] * 4, TypeError, "real numbers"),
        ],
    )
    def test_bad_corners_are_refused_by_name(self, corners, error, message):
        with pytest.raises(error, match=message):
            F.perspective(torch.zeros(3, 2, H, W), corners)


class TestElastic:
    def test_matches_slow_reference(self):
        frames = sparse_frames(3, 2, H, W, density=0.3)
        noise = torch.rand(2, H, W, generator=_g(1)) * 2 - 1
        out = check_not_modified(lambda x: F.elastic(x, noise, alpha=6.0, sigma=1.5), frames)
        np.testing.assert_allclose(out.double().numpy(), reference_elastic(frames, noise, 6.0, 1.5), atol=1e-4)

    def test_no_strength_is_the_identity(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3, dtype=torch.int32)
        noise = torch.rand(2, 2, H, W, generator=_g(2)) * 2 - 1
        out = F.elastic(frames, noise, alpha=torch.tensor([0.0, 0.0]), mode="nearest")
        assert out.dtype == torch.int32 and torch.equal(out, frames)

    def test_per_sample_strength_equals_per_sample_calls(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3)
        noise = torch.rand(2, 2, H, W, generator=_g(3)) * 2 - 1
        out = F.elastic(frames, noise, alpha=torch.tensor([3.0, 8.0]), sigma=2.0)
        for b, alpha in enumerate((3.0, 8.0)):
            torch.testing.assert_close(out[b], F.elastic(frames[b], noise[b], alpha=alpha, sigma=2.0))

    def test_matches_kornia(self):
        kornia = pytest.importorskip("kornia")
        frames = sparse_frames(3, 2, H, W, density=0.3).double()
        noise = torch.rand(1, 2, H, W, generator=_g(4), dtype=torch.float64) * 2 - 1
        size = 2 * math.ceil(3 * 2.0) + 1
        alpha = (5.0 * 2 / (W - 1), 5.0 * 2 / (H - 1))  # pixels to kornia's normalised units, (x, y)
        expected = kornia.geometry.transform.elastic_transform2d(
            frames.reshape(1, -1, H, W), noise.flip(1), (size, size), (2.0, 2.0), alpha, align_corners=True
        )
        torch.testing.assert_close(F.elastic(frames, noise[0], alpha=5.0, sigma=2.0), expected.view(frames.shape))

    @pytest.mark.parametrize(
        "kwargs, error, message",
        [
            ({"noise": np.zeros((2, H, W))}, TypeError, "noise must be a tensor"),
            ({"noise": torch.zeros(2, W, H)}, ValueError, r"noise must be a float tensor \(2, 17, 11\)"),
            ({"noise": torch.zeros(2, H, W, dtype=torch.int64)}, ValueError, "noise must be a float tensor"),
            ({"alpha": -1.0}, ValueError, r"elastic: alpha must lie in \[0.0, inf\], got -1.0"),
            ({"sigma": 0.0}, ValueError, "sigma must be finite and > 0"),
            ({"mode": "bicubic"}, ValueError, "mode"),
        ],
    )
    def test_bad_arguments_are_refused_by_name(self, kwargs, error, message):
        arguments = {"noise": torch.zeros(2, H, W), **kwargs}
        with pytest.raises(error, match=message):
            F.elastic(torch.zeros(3, 2, H, W), arguments.pop("noise"), **arguments)


class TestSequenceWarpModules:
    def test_random_perspective_draws_corners_inside_the_reach(self):
        module = et.RandomPerspective(0.4)
        params = module.make_params((50, 3, 2, H, W), generator=_g(5))
        moves = (params["corners"] - torch.tensor([[0, 0], [0, W - 1], [H - 1, W - 1], [H - 1, 0]])).abs()
        reach = torch.tensor([0.4 * (H - 1) / 2, 0.4 * (W - 1) / 2], dtype=torch.float64)
        assert bool((moves <= reach).all()) and bool((moves > 0).any())
        frames = sparse_frames(50, 3, 2, H, W, density=0.2)
        out = module(frames, params=params)
        for b in (0, 17):
            torch.testing.assert_close(out[b], F.perspective(frames[b], params["corners"][b]))

    def test_no_distortion_or_strength_is_the_identity(self):
        frames = sparse_frames(3, 4, 2, H, W, density=0.2)
        torch.testing.assert_close(et.RandomPerspective(0.0)(frames, generator=_g()), frames)
        torch.testing.assert_close(et.RandomElastic(alpha=0.0)(frames, generator=_g()), frames)

    def test_random_elastic_replays_its_field(self):
        module = et.RandomElastic(alpha=(5.0, 10.0), sigma=2.0)
        frames = sparse_frames(3, 4, 2, H, W, density=0.2)
        params = module.make_params(frames.shape, generator=_g(6))
        assert params["noise"].abs().max() <= 1 and bool(((params["alpha"] >= 5) & (params["alpha"] <= 10)).all())
        expected = F.elastic(frames, params["noise"], alpha=params["alpha"], sigma=2.0)
        torch.testing.assert_close(module(frames, params=params), expected)

    def test_bad_settings_are_refused_by_name(self):
        with pytest.raises(ValueError, match=r"distortion_scale must lie in \[0, 1\), got 1.0"):
            et.RandomPerspective(1.0)
        with pytest.raises(ValueError, match="alpha"):
            et.RandomElastic(alpha=-2.0)
        with pytest.raises(ValueError, match="sigma"):
            et.RandomElastic(sigma=0.0)
        with pytest.raises(ValueError, match="mode"):
            et.RandomElastic(mode="bicubic")

# --------------------------------------------------------------------------- on events (EventBatch kernels)


class TestOnEvents:
    """The event kernels of this topic: slow per-event references, and equality with the
    frame kernel after binning where the semantics coincide."""

    def test_rotation_reference(self):
        batch = make_batch(3)
        angle, scale = torch.tensor([30.0, -75.0, 180.0]), torch.tensor([1.0, 1.25, 0.8])
        out = F.affine_events(batch, angle, scale)
        for b in range(3):
            events = rows(batch, b)
            cy = sum(e[1] for e in events) / len(events)
            cx = sum(e[0] for e in events) / len(events)
            c, s = math.cos(math.radians(angle[b])) * scale[b].item(), math.sin(math.radians(angle[b])) * scale[b].item()
            expected = []
            for x, y, t, p in events:
                nx = cx + c * (x - cx) + s * (y - cy)
                ny = cy - s * (x - cx) + c * (y - cy)
                expected.append((nx, ny, t, p))
            for (x, y, t, p), (nx, ny, et_, ep) in zip(rows(out, b), expected):
                assert abs(x - nx) <= 0.5 + 1e-4 and abs(y - ny) <= 0.5 + 1e-4 and (t, p) == (et_, ep)

    def test_rotation_matches_frame_nearest_at_right_angles(self):
        streams = [torch.stack([s[:, 0] % 11, s[:, 1], s[:, 2], s[:, 3]], 1) for s in make_streams(2)]
        square = F.EventBatch.from_streams(streams, sensor_size=(11, 11), frame_ms=1.0, t_start=0, n_frames=T)
        frames = F.bin_events(square, dtype=torch.int64).float()
        for angle in (90.0, 180.0, -90.0):
            rotate = et.Rotate(angle, center="image", mode="nearest")
            assert torch.equal(F.bin_events(rotate(square)), rotate(frames))
        assert et.RandomRotation(40.0)(square).lengths == square.lengths  # every event kept (some off the sensor)

    def test_dispatcher_takes_events(self):
        """``F.rotate(batch, angle)`` is the module's event path with the same angles."""
        batch = make_batch(3)
        rotation = et.RandomRotation(40.0)
        params = rotation.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(3))
        out = F.rotate(batch, params["angle"])
        expected = rotation(batch, params=params)
        assert all(torch.equal(getattr(out, k), getattr(expected, k)) for k in ("x", "y", "t", "p"))
        resized = F.resize(batch, 1.5, center="image")
        assert resized.lengths == batch.lengths
        with pytest.raises(ValueError, match="shear is not supported on events"):
            F.affine(batch, shear=(10.0, 0.0))
        corners = [[0, 0], [0, 16], [10, 16], [10, 0]]  # the sensor's own corners: the identity
        assert same_events(F.perspective(batch, corners), batch)


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "Rotate": lambda t, h, w: et.Rotate(30.0),
    "RandomRotation": lambda t, h, w: et.RandomRotation(45.0),
    "Resize": lambda t, h, w: et.Resize(1.25),
    "RandomResize": lambda t, h, w: et.RandomResize(choices=(15 / 18, 15 / 12)),
    "Affine": lambda t, h, w: et.Affine(angle=15.0, translate=(1.5, -1.0), scale=1.1, shear=(5.0, 0.0)),
    "RandomAffine": lambda t, h, w: et.RandomAffine(20.0, translate=(0.1, 0.1), scale=(0.9, 1.1), shear=5.0),
    "RandomPerspective": lambda t, h, w: et.RandomPerspective(0.3),
    "RandomElastic": lambda t, h, w: et.RandomElastic(alpha=(2.0, 6.0), sigma=2.0, p=0.5),
}

EVENT_BATTERY = {
    "Rotate": lambda: et.Rotate(30.0),
    "Resize": lambda: et.Resize(1.25, center="image"),
    "Affine": lambda: et.Affine(angle=15.0, translate=(1.5, -1.0), scale=1.1),
    "RandomRotation": lambda: et.RandomRotation(30.0),
    "RandomResize": lambda: et.RandomResize((0.8, 1.25)),
    "RandomAffine": lambda: et.RandomAffine(20.0, translate=(0.1, 0.1)),
    "RandomRotation p": lambda: et.RandomRotation(30.0, p=0.5),
    "RandomPerspective": lambda: et.RandomPerspective(0.3),
    "RandomPerspective p": lambda: et.RandomPerspective(0.5, p=0.5),
    "RandomElastic": lambda: et.RandomElastic(alpha=(2.0, 6.0), sigma=2.0),
    "RandomElastic p": lambda: et.RandomElastic(alpha=(2.0, 6.0), sigma=2.0, p=0.5),
}


# --------------------------------------------------------------------------- perspective and elastic on events


def _homography(corners, height, width):
    """3×3 map of pixel (x, y, 1) from the frame's corners to ``corners`` ((4, 2) (y, x)):
    the direct linear system of four point pairs, solved in NumPy (an independent reference)."""
    source = [(0.0, 0.0), (width - 1.0, 0.0), (width - 1.0, height - 1.0), (0.0, height - 1.0)]  # (x, y)
    rows_, rhs = [], []
    for (x, y), (v, u) in zip(source, corners):  # target (y, x) -> (u, v) = (x', y')
        rows_.append([x, y, 1, 0, 0, 0, -u * x, -u * y])
        rows_.append([0, 0, 0, x, y, 1, -v * x, -v * y])
        rhs += [u, v]
    h = np.linalg.solve(np.array(rows_, dtype=np.float64), np.array(rhs, dtype=np.float64))
    return np.append(h, 1.0).reshape(3, 3)


def reference_perspective_events(events, corners, sensor):
    height, width = sensor
    h = _homography(corners, height, width)
    out = []
    for x, y, t, p in events:
        u, v, w = h @ np.array([x, y, 1.0])
        if w <= 0:
            continue
        nx, ny = round(u / w), round(v / w)
        if 0 <= nx < width and 0 <= ny < height:
            out.append((nx, ny, t, p))
    return out


def _smooth_reference(noise, sigma):
    """(2, H, W) noise smoothed by a separable Gaussian of ±3σ, zero outside: plain loops."""
    radius = math.ceil(3 * sigma)
    weights = [math.exp(-0.5 * (k / sigma) ** 2) for k in range(-radius, radius + 1)]
    total = sum(weights)
    weights = [w / total for w in weights]
    _, height, width = noise.shape
    out = np.zeros(noise.shape)
    for c in range(2):
        for y in range(height):
            for x in range(width):
                acc = 0.0
                for i, wy in enumerate(weights):
                    for j, wx in enumerate(weights):
                        yy, xx = y + i - radius, x + j - radius
                        if 0 <= yy < height and 0 <= xx < width:
                            acc += wy * wx * float(noise[c, yy, xx])
                out[c, y, x] = acc
    return out


def reference_elastic_events(events, noise, alpha, sigma, sensor, steps=4):
    """Per event: q <- p - field(q) from q = p, the field read bilinearly (clamped), rounded;
    events off the sensor dropped."""
    height, width = sensor
    field = alpha * _smooth_reference(noise, sigma)

    def read(c, y, x):
        y, x = min(max(y, 0.0), height - 1.0), min(max(x, 0.0), width - 1.0)
        y0, x0 = math.floor(y), math.floor(x)
        y1, x1 = min(y0 + 1, height - 1), min(x0 + 1, width - 1)
        wy, wx = y - y0, x - x0
        top = field[c, y0, x0] + wx * (field[c, y0, x1] - field[c, y0, x0])
        bottom = field[c, y1, x0] + wx * (field[c, y1, x1] - field[c, y1, x0])
        return top + wy * (bottom - top)

    out = []
    for x, y, t, p in events:
        qx, qy = float(x), float(y)
        for _ in range(steps):
            qx, qy = x - read(1, qy, qx), y - read(0, qy, qx)
        nx, ny = round(qx), round(qy)
        if 0 <= nx < width and 0 <= ny < height:
            out.append((nx, ny, t, p))
    return out


class TestPerspectiveOnEvents:
    def test_against_reference(self):
        batch = make_batch(3)
        module = et.RandomPerspective(0.6)
        params = module.make_params(batch.frame_shape, generator=_g(4))
        corners = params["corners"]
        corners[1] = torch.tensor([[-2.0, 1.0], [0.5, 18.0], [12.0, 15.0], [9.0, -1.5]])  # reaching out: events leave
        with et.count_dropped() as dropped:  # dropped by design: counted, not warned
            out = module(batch, params=params)
        assert dropped.counts()["off_sensor"] == int(batch.lengths[1] - out.lengths[1]) > 0
        for b in range(3):
            got = rows(out, b)
            expected = reference_perspective_events(rows(batch, b), corners[b].tolist(), SENSOR)
            assert got == expected
        assert out.lengths[1] < batch.lengths[1]

    def test_translation_equals_frames(self):
        """Where the semantics coincide: corners moved by whole pixels are a translation, and
        the frames' nearest warp then moves whole pixels too."""
        batch = make_batch(2)
        height, width = SENSOR
        corners = torch.tensor([[0.0, 0.0], [0.0, width - 1.0], [height - 1.0, width - 1.0], [height - 1.0, 0.0]])
        corners = corners + torch.tensor([2.0, -3.0])
        out = F.perspective(batch, corners)
        frames = frames_of(batch)
        assert torch.equal(frames_of(out), F.perspective(frames, corners, mode="nearest"))
        assert torch.equal(frames_of(out), F.translate(frames, (2, -3)))

    def test_hard_cases(self):
        check_hard_cases(lambda: et.RandomPerspective(0.5))


class TestElasticOnEvents:
    def test_against_reference(self):
        batch = make_batch(2)
        module = et.RandomElastic(alpha=(4.0, 8.0), sigma=1.5)
        params = module.make_params(batch.frame_shape, generator=_g(6))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EventsOutsideSensorWarning)
            out = module(batch, params=params)
        for b in range(2):
            expected = reference_elastic_events(rows(batch, b), params["noise"][b], float(params["alpha"][b]), 1.5, SENSOR)
            assert rows(out, b) == expected

    def test_shift_equals_frames_and_drops_by_design(self):
        """Where the semantics coincide: a field that is one whole-pixel shift over the events
        moves them as the frames' nearest warp moves pixels; events pushed off are dropped
        and counted (never warned)."""
        height, width = SENSOR
        events = torch.tensor([[x, y, 100 * (x + y), (x + y) % 2] for x in range(8) for y in range(4, 7)])
        batch = EventBatch.from_streams([events], sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)
        noise = torch.zeros(1, 2, height, width)
        noise[0, 1] = 1.0  # the frames sample from the right: content moves left
        with warnings.catch_warnings(), et.count_dropped() as dropped:
            warnings.simplefilter("error")
            out = F.elastic(batch, noise, alpha=3.0, sigma=0.3)  # 0.3 px: the field is 3 px everywhere
        assert dropped.counts() == {"off_sensor": 9}
        assert rows(out, 0) == [(x - 3, y, t, p) for x, y, t, p in rows(batch, 0) if x >= 3]
        assert torch.equal(frames_of(out), F.elastic(frames_of(batch), noise, alpha=3.0, sigma=0.3, mode="nearest"))

    def test_zero_strength_is_identity(self):
        batch = make_batch()
        noise = torch.rand(4, 2, *SENSOR, generator=_g(1)) * 2 - 1
        assert same_events(F.elastic(batch, noise, alpha=0.0), batch)

    def test_hard_cases(self):
        check_hard_cases(lambda: et.RandomElastic(alpha=(2.0, 6.0), sigma=2.0))
