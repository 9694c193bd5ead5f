"""Geometry: flips, translation, crops, sum-pooling, each against a slow reference (Python
loops over pixels), and their invariants (hypothesis)."""

from __future__ import annotations


import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import EventBatch
from event_transforms import functional as F

from event_transforms.functional._event_ops import JITTER

from tests.support import random_reference as reference
from tests.support.event_data import SENSOR, check_hard_cases, frames_of, make_batch, make_streams, rows
from tests.support.checkers import H, W, check_not_modified, count_shapes, random_counts, sparse_frames


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


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
            top, left = int(params["top"][n]), int(params["left"][n])
            assert torch.equal(out[n], frames[n, :, :, top : top + 5, left : left + 4])
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


class TestFlips:
    def test_against_loop(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.3, dtype=torch.int16)
        h, v = F.horizontal_flip(frames), F.vertical_flip(frames)
        for y in range(H):
            for x in range(W):
                assert torch.equal(h[..., y, x], frames[..., y, W - 1 - x])
                assert torch.equal(v[..., y, x], frames[..., H - 1 - y, x])
        assert h.dtype == torch.int16

    def test_random_flip_per_sample(self):
        frames = sparse_frames(64, 2, 2, H, W, density=0.3)
        flip = et.RandomHorizontalFlip(p=0.5)
        params = flip.make_params((64, 6, 2, 9, 11), generator=torch.Generator().manual_seed(0))
        out = flip(frames, params=params)
        for b in range(64):
            expected = frames[b].flip(-1) if params["apply"][b] else frames[b]
            assert torch.equal(out[b], expected)
        assert 10 < int(params["apply"].sum()) < 54


@settings(max_examples=60, deadline=None)
@given(count_shapes, st.integers(0, 2**31), st.integers(1, 4), st.integers(1, 4))
def test_downsample_keep_conserves_every_event(shape, seed, fy, fx):
    frames = random_counts(shape, seed)
    out = F.downsample(frames, (fy, fx), remainder="keep")
    assert torch.equal(out.sum((1, 2, 3, 4)), frames.sum((1, 2, 3, 4)))

@settings(max_examples=60, deadline=None)
@given(count_shapes, st.integers(0, 2**31), st.integers(-10, 10), st.integers(-10, 10))
def test_translate_there_and_back_keeps_what_stayed_inside(shape, seed, dy, dx):
    frames = random_counts(shape, seed)
    b = frames.shape[0]
    there = F.translate(frames, torch.tensor([[dy, dx]] * b, dtype=torch.int64).reshape(b, 2))
    back = F.translate(there, torch.tensor([[-dy, -dx]] * b, dtype=torch.int64).reshape(b, 2))
    assert bool((there.sum() <= frames.sum()).all())
    assert bool((back == frames)[back > 0].all())  # whatever came back is where it was
    assert int(back.sum()) == int(there.sum())

# --------------------------------------------------------------------------- on events (EventBatch kernels)


class TestOnEvents:
    """The event kernels of this topic: slow per-event references, and equality with the
    frame kernel after binning where the semantics coincide."""

    def test_flips_match_frames(self):
        batch = make_batch()
        frames = frames_of(batch)
        assert torch.equal(frames_of(et.HorizontalFlip()(batch)), frames.flip(-1))
        assert torch.equal(frames_of(et.VerticalFlip()(batch)), frames.flip(-2))
        assert torch.equal(frames_of(F.horizontal_flip(batch)), F.horizontal_flip(frames))
        flags = torch.tensor([True, False, True, False])
        assert torch.equal(frames_of(F.vertical_flip(batch, flags)), F.vertical_flip(frames, flags))

    def test_crops_match_frames(self):
        batch = make_batch(3)
        frames = frames_of(batch)
        for crop in (et.RandomCrop((7, 9)), et.CenterCrop((5, 12))):
            params = crop.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(1))
            out = crop(batch, params=params)
            assert out.sensor_size == crop.size
            assert torch.equal(frames_of(out), crop(frames, params=params))
        crop_time = et.RandomCropTime(4)
        params = crop_time.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(2))
        out = crop_time(batch, params=params)
        assert out.n_frames == 4 and torch.equal(frames_of(out), crop_time(frames, params=params))
        with pytest.raises(ValueError, match="resize=False"):
            et.RandomCrop((7, 9), resize=True)(batch)

    def test_translate_reference(self):
        batch = make_batch(2)
        shift = torch.tensor([[1, -2], [0, 3]])
        out = F.translate_events(batch, shift)
        for b in range(2):
            assert rows(out, b) == [(x + int(shift[b, 1]), y + int(shift[b, 0]), t, p) for x, y, t, p in rows(batch, b)]
        frames = frames_of(batch)
        assert torch.equal(frames_of(et.Translate((1, -2))(batch)), et.Translate((1, -2))(frames))

    def test_spatial_jitter_reference(self):
        batch = make_batch(2)
        sigma, seed = torch.tensor([1.5, 0.0]), torch.tensor([3, 4])
        out = F.spatial_jitter_events(batch, sigma, seed)
        for b in range(2):
            s = int(seed[b])  # event i: Python-integer hashes of (seed, i, purpose), Box-Muller
            for i, ((x, y, t, p), (ox, oy, ot, op)) in enumerate(zip(rows(batch, b), rows(out, b))):
                nx, ny = reference.normal_pair(s, i, JITTER)  # float64; the kernel rounds a float32 sum
                assert abs(ox - (x + nx * sigma[b].item())) <= 0.5 + 1e-5
                assert abs(oy - (y + ny * sigma[b].item())) <= 0.5 + 1e-5
                assert (ot, op) == (t, p)

    def test_jitter_sigma_is_checked(self):
        batch = make_batch(1)
        with pytest.raises(ValueError, match="sigma"):
            et.SpatialJitter(-1.0)
        with pytest.raises(ValueError, match=r"SpatialJitter: params\['sigma'\] must lie in \[0.0, inf\]"):
            et.SpatialJitter(1.0)(batch, params={"sigma": torch.tensor([-1.0]), "seed": torch.tensor([1])})
        with pytest.raises(ValueError, match=r"spatial_jitter: sigma must lie in \[0.0, inf\], got -1.0"):
            F.spatial_jitter(batch, -1.0, 1)

    def test_dispatchers_take_events(self):
        batch = make_batch(3)
        frames = frames_of(batch)
        assert torch.equal(frames_of(F.translate(batch, (1, -2))), F.translate(frames, (1, -2)))
        out = F.crop(batch, 1, 2, (5, 6))
        assert out.sensor_size == (5, 6) and torch.equal(frames_of(out), F.crop(frames, 1, 2, (5, 6)))
        assert torch.equal(frames_of(F.downsample(batch, 2, remainder="keep")), F.downsample(frames, 2, remainder="keep"))


class TestDownsampleOnEvents:
    @staticmethod
    def reference(c: int, factor: int, size: int, new_size: int) -> int:
        """Per event: its block; a coordinate outside the sensor stays outside."""
        if c >= size:
            return new_size + (c - size) // factor
        return c // factor  # Python floors: c < 0 stays < 0

    @pytest.mark.parametrize("factor, remainder", [((2, 2), "drop"), ((3, 2), "keep"), ((2, 5), "drop"), ((4, 3), "keep")])
    def test_against_reference_and_frames(self, factor, remainder):
        import warnings

        from event_transforms.functional.geometry import downsampled_size

        streams = [torch.cat([s, torch.tensor([[-3, 2, 10, 1], [SENSOR[1] + 1, 0, 20, 0], [0, SENSOR[0], 30, 1]])])
                   for s in make_streams(3, seed=11)]
        batch = EventBatch.from_streams(streams, sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=6)
        out = F.downsample(batch, factor, remainder=remainder)
        new_h, new_w = downsampled_size(*SENSOR, factor, remainder)
        assert out.sensor_size == (new_h, new_w) and out.lengths == batch.lengths
        for b in range(len(batch)):
            expected = [(self.reference(x, factor[1], SENSOR[1], new_w), self.reference(y, factor[0], SENSOR[0], new_h), t, p)
                        for x, y, t, p in rows(batch, b)]
            assert rows(out, b) == expected
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the events outside the sensor (and under "drop" the remainder's)
            assert torch.equal(frames_of(out), F.downsample(frames_of(batch), factor, remainder=remainder))

    def test_module_and_hard_cases(self):
        batch = make_batch()
        assert torch.equal(frames_of(et.Downsample(2, remainder="keep")(batch)), et.Downsample(2, remainder="keep")(frames_of(batch)))
        check_hard_cases(lambda: et.Downsample((2, 3), remainder="keep"))


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "HorizontalFlip": lambda t, h, w: et.HorizontalFlip(),
    "VerticalFlip": lambda t, h, w: et.VerticalFlip(),
    "RandomHorizontalFlip": lambda t, h, w: et.RandomHorizontalFlip(0.5),
    "RandomVerticalFlip": lambda t, h, w: et.RandomVerticalFlip(0.5),
    "Translate": lambda t, h, w: et.Translate((1, -2)),
    "RandomTranslate": lambda t, h, w: et.RandomTranslate(2),
    "RandomCropResize": lambda t, h, w: et.RandomCrop((max(1, h - 3), max(1, w - 2)), resize=True),
    "CenterCropResize": lambda t, h, w: et.CenterCrop((max(1, h - 4), max(1, w - 1)), resize=True),
}

SHAPE_BATTERY = {
    "RandomCrop": lambda t, h, w: et.RandomCrop((max(1, h - 3), max(1, w - 2))),
    "CenterCrop": lambda t, h, w: et.CenterCrop((max(1, h - 4), max(1, w - 1))),
    "Downsample": lambda t, h, w: et.Downsample(2),
    "DownsampleKeep": lambda t, h, w: et.Downsample((3, 2), remainder="keep"),
}

EVENT_BATTERY = {
    "HorizontalFlip": lambda: et.HorizontalFlip(),
    "VerticalFlip": lambda: et.VerticalFlip(),
    "Translate": lambda: et.Translate((1, -2)),
    "RandomHorizontalFlip": lambda: et.RandomHorizontalFlip(),
    "RandomVerticalFlip": lambda: et.RandomVerticalFlip(),
    "RandomTranslate": lambda: et.RandomTranslate((2, 3)),
    "SpatialJitter": lambda: et.SpatialJitter((0.5, 2.0)),
    "SpatialJitter p": lambda: et.SpatialJitter(1.5, p=0.5),
    "Downsample": lambda: et.Downsample(2),
    "Downsample keep": lambda: et.Downsample((3, 2), remainder="keep"),
}
