"""Drop transforms: EventDrop (random fraction, time window, area) and pixel removal."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import functional as F
from event_transforms.transforms.base import slice_params

from event_transforms.functional._event_ops import DROP_KEYS

from tests.support import random_reference as reference
from tests.support.event_data import SENSOR, frames_of, make_batch, make_streams, rows
from tests.support.checkers import H, W, check_not_modified, check_sane, sparse_frames


def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)



class TestDropEvents:
    def test_binomial_thinning(self):
        frames = torch.full((4, 36, 2, H, W), 3, dtype=torch.int32)
        out = F.drop_random(frames, 0.25, generator=gen())
        assert out.dtype == torch.int32
        assert bool((out <= frames).all() & (out >= 0).all())
        n = frames.sum().item()
        assert out.sum().item() == pytest.approx(0.75 * n, abs=5 * math.sqrt(n * 0.25 * 0.75))

    def test_extremes_and_per_sample(self):
        frames = sparse_frames(2, 3, 2, H, W, high=9)
        out = F.drop_random(frames, torch.tensor([0.0, 1.0]), generator=gen())
        assert torch.equal(out[0], frames[0])
        assert out[1].sum() == 0

    def test_expected_mode(self):
        frames = sparse_frames(3, 2, H, W, dtype=torch.uint8)
        out = F.drop_random(frames, 0.3, mode="expected")
        assert out.dtype == torch.float32
        torch.testing.assert_close(out, frames.float() * 0.7)

    def test_non_integer_counts_refused(self):
        with pytest.raises(ValueError, match='mode="expected"'):
            F.drop_random(torch.full((2, 2, H, W), 0.5), 0.3)

    def test_fraction_out_of_range(self):
        with pytest.raises(ValueError, match="fraction"):
            F.drop_random(sparse_frames(2, 2, H, W), 1.5)

    def test_by_time_against_loop(self):
        frames = sparse_frames(3, 6, 2, H, W, density=0.5)
        start, length = torch.tensor([0, 2, 5]), torch.tensor([2, 3, 4])
        out = F.drop_by_time(frames, start, length)
        for b in range(3):
            for t in range(6):
                dropped = int(start[b]) <= t < int(start[b]) + int(length[b])
                assert torch.equal(out[b, t], torch.zeros_like(frames[b, t]) if dropped else frames[b, t])

    def test_by_area_against_loop(self):
        frames = sparse_frames(2, 3, 2, H, W, density=0.5)
        box = dict(top=torch.tensor([1, 10]), left=torch.tensor([0, 8]), height=torch.tensor([4, 9]), width=torch.tensor([3, 9]))
        out = F.drop_by_area(frames, **box)
        for b in range(2):
            for y in range(H):
                for x in range(W):
                    inside = (box["top"][b] <= y < box["top"][b] + box["height"][b]) and (
                        box["left"][b] <= x < box["left"][b] + box["width"][b]
                    )
                    assert torch.equal(out[b, :, :, y, x], torch.zeros(3, 2) if inside else frames[b, :, :, y, x])

    def test_bad_windows(self):
        with pytest.raises(ValueError, match="start"):
            F.drop_by_time(sparse_frames(3, 2, H, W), -1, 2)
        with pytest.raises(TypeError, match="width must be an integer, got 1.5"):
            F.drop_by_area(sparse_frames(3, 2, H, W), 0, 0, 2, 1.5)

class TestRandomEventDrop:
    @pytest.mark.parametrize("method", ["random", "time", "area"])
    def test_each_method_only_removes(self, method):
        frames = sparse_frames(16, 10, 2, H, W, density=0.5, dtype=torch.int16)
        out = et.RandomEventDrop(fraction=(0.2, 0.6), methods=(method,))(frames, generator=gen())
        check_sane(out, frames)
        assert bool((out <= frames).all())
        assert out.sum() < frames.sum()

    def test_time_method_drops_whole_frames(self):
        frames = torch.ones(8, 10, 2, H, W)
        module = et.RandomEventDrop(fraction=0.3, methods=("time",))
        out = module(frames, generator=gen())
        zero_frames = (out.sum(dim=(2, 3, 4)) == 0).sum(1)
        assert zero_frames.tolist() == [3] * 8

    def test_methods_mix_within_a_batch(self):
        params = et.RandomEventDrop().make_params((60, 6, 2, 9, 11), generator=gen())
        assert set(params["method"].tolist()) == {0, 1, 2}

    def test_bad_settings(self):
        with pytest.raises(ValueError, match="methods"):
            et.RandomEventDrop(methods=("random", "polarity"))
        with pytest.raises(ValueError, match="fraction"):
            et.RandomEventDrop(fraction=(0.2, 1.5))

@settings(max_examples=30, deadline=None)
@given(
    counts=st.lists(st.integers(0, 50), min_size=1, max_size=24),
    fraction=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**31),
)
def test_drop_never_adds_events(counts, fraction, seed):
    frames = torch.tensor(counts + [0] * (-len(counts) % 2), dtype=torch.int64).view(-1, 2, 1, 1)
    out = F.drop_random(frames, fraction, generator=gen(seed))
    assert bool((out >= 0).all() & (out <= frames).all())


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
        params = module.make_params(frames.shape, generator=gen(1))
        out = module(frames, params=params)
        dropped = out == 0
        assert torch.equal(dropped, dropped[:, :1, :1].expand_as(dropped))  # all frames, both polarities
        share = dropped[:, 0, 0].float().mean((1, 2))
        torch.testing.assert_close(share, params["fraction"].float(), atol=0.06, rtol=0)

    def test_batched_equals_alone_and_replays(self):
        frames = sparse_frames(3, 4, 2, H, W, density=0.5)
        module = et.RandomDropPixel(0.5)
        params = module.make_params(frames.shape, generator=gen(2))
        out = module(frames, params=params)
        for n in range(3):
            assert torch.equal(module(frames[n : n + 1], params=slice_params(params, torch.tensor([n])))[0], out[n])
        other = module.make_params(frames.shape, generator=gen(3))
        assert not torch.equal(module(frames, params=other), out)

# --------------------------------------------------------------------------- on events (EventBatch kernels)


class TestOnEvents:
    """The event kernels of this topic: slow per-event references, and equality with the
    frame kernel after binning where the semantics coincide."""

    def test_random_drop_reference(self):
        batch = make_batch(3)
        fraction, seed = torch.tensor([0.2, 0.5, 0.9]), torch.tensor([5, 6, 7])
        out = F.drop_random_events(batch, fraction, "binomial", seed)
        for b in range(3):  # event i of sample b: the Python-integer hash of (seed b, i, DROP_KEYS)
            u = [reference.uniform32(int(seed[b]), i, DROP_KEYS) for i in range(batch.lengths[b])]
            zeta = torch.tensor(fraction[b].item(), dtype=torch.float32).item()
            expected = [e for e, ui in zip(rows(batch, b), u) if not ui < zeta]
            assert rows(out, b) == expected

    def test_pixel_drop_reference_and_frames(self):
        batch = make_batch(3)
        drop = et.RandomDropPixel((0.2, 0.6))
        params = drop.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(5))
        out = drop(batch, params=params)
        mask = F.random_pixel_mask(params["seed"], params["fraction"], *SENSOR, torch.device("cpu"))
        for b in range(3):  # slow reference: an event goes when its pixel is masked for its stream
            assert rows(out, b) == [e for e in rows(batch, b) if not mask[b, e[1], e[0]]]
        assert torch.equal(frames_of(out), drop(frames_of(batch), params=params))
        fixed = et.DropPixel([[1, 2], [4, 0]])
        assert torch.equal(frames_of(fixed(batch)), fixed(frames_of(batch)))
        with pytest.raises(TypeError, match="rate_hz"):
            et.DropPixel(rate_hz=100.0)(batch)

    def test_event_drop_time_and_area_match_frames(self):
        batch = make_batch(4)
        drop = et.RandomEventDrop((0.2, 0.6), methods=("time", "area"))
        params = drop.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(3))
        assert torch.equal(frames_of(drop(batch, params=params)), drop(frames_of(batch), params=params))

    def test_refractory_and_decimation_reference(self):
        streams = [torch.stack([s[:, 0] % 3, s[:, 1] % 3, s[:, 2], s[:, 3]], 1) for s in make_streams(3, seed=4, n=150)]
        batch = F.EventBatch.from_streams(streams, sensor_size=(3, 3))  # crowded pixels
        period = torch.tensor([300.0, 0.0, 2000.0])
        out = F.refractory_period_events(batch, period)
        n = torch.tensor([2, 1, 3])
        dec = F.decimation_events(batch, n)
        for b in range(3):
            last: dict = {}
            counts: dict = {}
            kept, decimated = [], []
            for event in rows(batch, b):
                x, y, t, _ = event
                if (x, y) not in last or t - last[(x, y)] >= period[b]:
                    kept.append(event)
                last[(x, y)] = t
                counts[(x, y)] = counts.get((x, y), 0) + 1
                if counts[(x, y)] % int(n[b]) == 0:
                    decimated.append(event)
            assert rows(out, b) == kept
            assert rows(dec, b) == decimated

    def test_decimation_params_are_checked_by_the_spec(self):
        batch = make_batch(1)
        with pytest.raises(ValueError, match=r"Decimation: params\['n'\] must lie in \[1, inf\]"):
            et.Decimation(2)(batch, params={"n": torch.tensor([0])})
        with pytest.raises(ValueError, match=r"decimation: n must lie in \[1, inf\], got 0"):
            F.decimation(batch, 0)
        with pytest.raises(ValueError, match=r"RefractoryPeriod: params\['period_us'\] must lie in \[0.0, inf\]"):
            et.RefractoryPeriod(10.0)(batch, params={"period_us": torch.tensor([-1.0])})

    def test_dispatchers_take_events(self):
        batch = make_batch(3)
        frames = frames_of(batch)
        assert torch.equal(frames_of(F.drop_by_time(batch, 1, 2)), F.drop_by_time(frames, 1, 2))
        assert torch.equal(frames_of(F.drop_by_area(batch, 2, 3, 4, 5)), F.drop_by_area(frames, 2, 3, 4, 5))
        assert torch.equal(frames_of(F.drop_pixel(batch, [[1, 2]])), F.drop_pixel(frames, [[1, 2]]))
        out = F.drop_random(batch, 0.5, generator=torch.Generator().manual_seed(0))
        assert out.num_events < batch.num_events
        assert not hasattr(F, "drop_events")  # the former name of drop_random, removed
        with pytest.raises(TypeError, match="refractory_period works on events only"):
            F.refractory_period(frames, 10.0)


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "RandomEventDrop": lambda t, h, w: et.RandomEventDrop((0.1, 0.5)),
    "DropPixel": lambda t, h, w: et.DropPixel([[0, 0], [h - 1, w - 1]]),
    "DropHotPixels": lambda t, h, w: et.DropPixel(rate_hz=150.0),
    "RandomDropPixel": lambda t, h, w: et.RandomDropPixel((0.1, 0.3)),
}

EVENT_BATTERY = {
    "RandomEventDrop": lambda: et.RandomEventDrop((0.1, 0.5)),
    "RefractoryPeriod": lambda: et.RefractoryPeriod((100.0, 2000.0)),
    "Decimation": lambda: et.Decimation((1, 3)),
    "RandomEventDrop p": lambda: et.RandomEventDrop((0.2, 0.6), p=0.5),
    "RandomDropPixel p": lambda: et.RandomDropPixel((0.1, 0.4), p=0.5),
    "DropPixel": lambda: et.DropPixel([[1, 1], [3, 5]]),
    "Decimation p": lambda: et.Decimation(2, p=0.5),
}
