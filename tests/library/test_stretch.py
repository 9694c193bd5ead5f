"""Stretch across the contact axis: against a slow per-pixel reference, invariants, containers."""

from __future__ import annotations

import math

import pytest
import torch

import event_transforms as et
from event_transforms import functional as F

from tests.support.event_data import SENSOR, check_hard_cases, frames_of, make_batch, rows, same_events
from tests.support.checkers import H, W, sparse_frames


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


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
        from event_transforms.functional.stretch import _second_moments

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


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "Stretch": lambda t, h, w: et.Stretch(1.3),
    "StretchAtAngle": lambda t, h, w: et.Stretch(0.8, axis=30.0, center="image"),
    "RandomStretch": lambda t, h, w: et.RandomStretch((0.8, 1.25)),
}


# --------------------------------------------------------------------------- on events (EventBatch kernels)


def reference_stretch_events(events, factor, axis_degrees, center, sensor):
    """Slow per-event reference in plain Python floats: centre and contact axis from the
    events' sums, then ``dst = c + (I + (k - 1) n nᵀ)(src - c)`` rounded half to even."""
    height, width = sensor
    n = len(events)
    if n == 0:
        return []
    if center == "mass":
        cy, cx = sum(e[1] for e in events) / n, sum(e[0] for e in events) / n
    elif center == "image":
        cy, cx = (height - 1) / 2, (width - 1) / 2
    else:
        cy, cx = center
    if axis_degrees == "contact":
        my, mx = sum(e[1] for e in events) / n, sum(e[0] for e in events) / n
        c_yy = sum((e[1] - my) ** 2 for e in events) / n
        c_xx = sum((e[0] - mx) ** 2 for e in events) / n
        c_xy = sum((e[1] - my) * (e[0] - mx) for e in events) / n
        radians = -0.5 * math.atan2(2 * c_xy, c_xx - c_yy)
    else:
        radians = math.radians(axis_degrees)
    nx, ny = math.sin(radians), math.cos(radians)
    out = []
    for x, y, t, p in events:
        along = nx * (x - cx) + ny * (y - cy)
        out.append((round(x + (factor - 1) * nx * along), round(y + (factor - 1) * ny * along), t, p))
    return out


class TestStretchOnEvents:
    @pytest.mark.parametrize("factor, axis, center", [(1.6, "contact", "mass"), (0.7, 30.0, "image"), (2.0, 0.0, (4.0, 6.5)),
                                                      (1.25, -75.0, "mass")])
    def test_against_reference(self, factor, axis, center):
        batch = make_batch(4)
        module = et.Stretch(factor, axis=axis, center=center)
        out = module(batch)
        for b in range(4):
            got = rows(out, b)
            expected = reference_stretch_events(rows(batch, b), factor, axis, center, SENSOR)
            # float64 sums in another order may round an event lying on a half-pixel the other way
            assert sum(g != e for g, e in zip(got, expected)) <= 1 and len(got) == len(expected)

    def test_identity_and_counts(self):
        batch = make_batch()
        assert same_events(F.stretch(batch, 1.0), batch)
        out = F.stretch(batch, torch.tensor([0.5, 1.5, 2.0, 0.8]))
        assert out.lengths == batch.lengths  # counts kept: a moved event is never split

    def test_centre_and_axis_agree_with_frames(self):
        """Where the semantics coincide: the event centroid and contact axis of a batch are those
        of its binned frames (every event on the sensor and in the window)."""
        from event_transforms.functional.stretch import _event_moments

        batch = make_batch()
        centre, covariance = _event_moments(batch)
        frames = frames_of(batch, torch.float64)
        torch.testing.assert_close(centre, F.center_of_mass(frames))
        axis = torch.rad2deg(-0.5 * torch.atan2(2 * covariance[:, 2], covariance[:, 1] - covariance[:, 0]))
        torch.testing.assert_close(axis, F.contact_axis(frames), atol=1e-6, rtol=0)

    def test_random_stretch_and_hard_cases(self):
        batch = make_batch()
        module = et.RandomStretch((0.8, 1.25), p=0.5)
        params = module.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(0))
        out = module(batch, params=params)
        for b, applied in enumerate(params["apply"].tolist()):
            if not applied:
                assert rows(out, b) == rows(batch, b)
        check_hard_cases(lambda: et.RandomStretch((0.5, 2.0)))
        check_hard_cases(lambda: et.Stretch(1.5, axis=20.0, center="image"))


EVENT_BATTERY = {
    "Stretch": lambda: et.Stretch(1.3),
    "StretchAtAngle": lambda: et.Stretch(0.8, axis=30.0, center="image"),
    "RandomStretch": lambda: et.RandomStretch((0.8, 1.25)),
    "RandomStretch p": lambda: et.RandomStretch((0.8, 1.25), p=0.5),
}
