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


def _reference_stretch(frames, factor, axis_deg, center):
    """Per output pixel: inverse-map through ``c + (I + (1/k - 1) n nᵀ)(d - c)``, bilinear
    sample with zero padding; ``axis_deg`` None means the contact axis from a Python loop
    over the events' second moments."""
    b, t, p, h, w = frames.shape
    out = torch.zeros(frames.shape, dtype=torch.float64)
    for s in range(b):
        weight = frames[s].double().sum((0, 1))
        mass = float(weight.sum())
        if center[s] is None:
            if mass == 0:
                cy, cx = (h - 1) / 2, (w - 1) / 2
            else:
                cy = sum(y * float(weight[y, x]) for y in range(h) for x in range(w)) / mass
                cx = sum(x * float(weight[y, x]) for y in range(h) for x in range(w)) / mass
        else:
            cy, cx = center[s]
        if axis_deg[s] is None:
            cyy = cxx = cxy = 0.0
            for y in range(h):
                for x in range(w):
                    m = float(weight[y, x])
                    cyy += m * (y - cy) ** 2
                    cxx += m * (x - cx) ** 2
                    cxy += m * (x - cx) * (y - cy)
            pixel = 0.5 * math.atan2(2 * cxy, cxx - cyy)  # major axis, y down
            nx, ny = -math.sin(pixel), math.cos(pixel)
        else:
            a = math.radians(axis_deg[s])
            nx, ny = math.sin(a), math.cos(a)
        inv = 1 / factor[s] - 1
        for y in range(h):
            for x in range(w):
                u, v = x - cx, y - cy
                along = nx * u + ny * v
                sx, sy = cx + u + inv * along * nx, cy + v + inv * along * ny
                x0, y0 = math.floor(sx), math.floor(sy)
                for yy, wy in ((y0, 1 - (sy - y0)), (y0 + 1, sy - y0)):
                    for xx, wx in ((x0, 1 - (sx - x0)), (x0 + 1, sx - x0)):
                        if 0 <= xx < w and 0 <= yy < h and wx * wy > 0:
                            out[s, :, :, y, x] += wx * wy * frames[s, :, :, yy, xx].double()
    return out


class TestStretch:
    def test_matches_slow_reference(self):
        frames = sparse_frames(3, 3, 2, H, W, density=0.3)
        frames[2] = 0  # empty: stays empty
        factor = [1.3, 0.7, 1.5]
        out = F.stretch(frames, torch.tensor(factor))
        expected = _reference_stretch(frames, factor, [None] * 3, [None] * 3)
        torch.testing.assert_close(out.double(), expected, atol=1e-5, rtol=1e-5)
        out = F.stretch(frames, torch.tensor(factor), axis=torch.tensor([20.0, -70.0, 0.0]), center=(8.0, 5.0))
        expected = _reference_stretch(frames, factor, [20.0, -70.0, 0.0], [(8.0, 5.0)] * 3)
        torch.testing.assert_close(out.double(), expected, atol=1e-5, rtol=1e-5)

    @pytest.mark.parametrize("angle", [0.0, 30.0, 60.0, 90.0, -45.0])
    def test_contact_axis_of_a_strip(self, angle):
        frames = torch.zeros(2, 2, 41, 41, dtype=torch.int16)
        a = math.radians(angle)
        for k in range(-30, 31):
            x, y = 20 + 0.5 * k * math.cos(a), 20 - 0.5 * k * math.sin(a)
            frames[0, 1, round(y), round(x)] += 1
        found = float(F.contact_axis(frames))
        assert abs((found - angle + 90) % 180 - 90) < 3.0
        assert float(F.contact_axis(torch.zeros(1, 2, 5, 5))) == 0.0
        assert F.contact_axis(torch.zeros(0, 1, 2, 5, 5)).shape == (0,)

    def test_stretches_across_the_strip_only(self):
        """The second moment across the contact axis grows by k², along it not at all."""
        frames = torch.zeros(1, 2, 61, 61)
        a = math.radians(35.0)
        for k in range(-40, 41):
            for j in (-1, 0, 1):
                x = 30 + 0.5 * k * math.cos(a) + j * math.sin(a)
                y = 30 - 0.5 * k * math.sin(a) + j * math.cos(a)
                frames[0, 0, round(y), round(x)] += 1.0
        from event_transforms.functional.geometry import _second_moments

        def spreads(x):
            _, cov = _second_moments(x.unsqueeze(0))
            c_yy, c_xx, c_xy = cov[0].tolist()
            ux, uy = math.cos(a), -math.sin(a)
            nx, ny = math.sin(a), math.cos(a)
            along = ux * ux * c_xx + uy * uy * c_yy + 2 * ux * uy * c_xy
            across = nx * nx * c_xx + ny * ny * c_yy + 2 * nx * ny * c_xy
            return along, across
        before, after = spreads(frames), spreads(F.stretch(frames, 2.0))
        assert after[0] == pytest.approx(before[0], rel=0.05)
        assert after[1] / before[1] == pytest.approx(4.0, rel=0.25)
        assert float(F.stretch(frames, 2.0).sum()) == pytest.approx(2 * float(frames.sum()), rel=0.05)

    def test_factor_one_is_identity_and_axis_angle_is_periodic(self):
        frames = sparse_frames(2, 4, 2, H, W, density=0.3)
        torch.testing.assert_close(F.stretch(frames, 1.0), frames)
        torch.testing.assert_close(F.stretch(frames, 1.4, axis=10.0), F.stretch(frames, 1.4, axis=190.0))

    @pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.uint8, torch.int64])
    def test_dtypes(self, dtype):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3, dtype=dtype)
        assert F.stretch(frames, 1.2).dtype == (dtype if dtype.is_floating_point else torch.float32)
        assert F.stretch(frames, 1.2, mode="nearest").dtype == dtype

    @pytest.mark.parametrize(
        "kwargs, error, text",
        [
            (dict(factor=0.0), ValueError, "factor"),
            (dict(factor=float("nan")), ValueError, "factor"),
            (dict(factor=1.0, axis="major"), ValueError, "axis"),
            (dict(factor=1.0, axis=float("inf")), ValueError, "axis"),
            (dict(factor=1.0, mode="cubic"), ValueError, "mode"),
            (dict(factor="big"), TypeError, "factor"),
        ],
    )
    def test_bad_arguments(self, kwargs, error, text):
        with pytest.raises(error, match=text):
            F.stretch(torch.zeros(2, 2, H, W), **kwargs)

    def test_modules(self):
        frames = sparse_frames(4, 3, 2, H, W, density=0.3)
        g = lambda: torch.Generator().manual_seed(0)  # noqa: E731
        transform = et.RandomStretch((0.8, 1.25))
        params = transform.make_params(frames.shape, generator=g())
        torch.testing.assert_close(transform(frames, params=params), F.stretch(frames, params["factor"]))
        for i in range(4):  # a sample alone equals the sample in the batch
            alone = transform(frames[i : i + 1], params={"factor": params["factor"][i : i + 1]})
            torch.testing.assert_close(alone[0], F.stretch(frames[i], float(params["factor"][i])))
        choices = et.RandomStretch(choices=(0.9, 1.1)).make_params(frames.shape, generator=g())["factor"]
        assert set(choices.tolist()) <= {0.9, 1.1}
        torch.testing.assert_close(et.Stretch(1.3, axis=20.0)(frames), F.stretch(frames, 1.3, axis=20.0))
        assert torch.equal(et.Stretch(1.3, p=0.0)(frames), frames)
        with pytest.raises(ValueError, match="exactly one"):
            et.RandomStretch()
        with pytest.raises(ValueError, match="factor"):
            et.Stretch(-1.0)
        for container in (et.Compose([et.Stretch(1.3)]), et.OneOf([et.Stretch(1.3)]), et.RandomApply(et.Stretch(1.3), p=1.0)):
            torch.testing.assert_close(container(frames, generator=g()), F.stretch(frames, 1.3))

    def test_stretch_to_target(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3)
        out = et.StretchToTarget(15.0)(frames, metadata={"diameter_mm": torch.tensor([12.0, 18.0])})
        torch.testing.assert_close(out, F.stretch(frames, torch.tensor([1.25, 15 / 18]).sqrt()))
        with pytest.raises(ValueError, match="diameter_mm"):
            et.StretchToTarget(15.0)(frames)
