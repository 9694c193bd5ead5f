"""The DVS emulator (``functional.emulate_events``, ``EmulateEvents``): hand-computed crossings, a slow
per-pixel reference, noise and leak at their stated rates, per-sample purity, replay, hard cases."""

from __future__ import annotations

import math

import pytest
import torch

import event_transforms as et
from event_transforms import functional as F
from event_transforms.functional import emulate as E
from event_transforms.authoring import slice_params
from tests.support.event_data import same_events

FPS = 30.0
DT = 1e6 / FPS


def ramp(levels: list[float], shape: tuple[int, int] = (2, 3)) -> torch.Tensor:
    """Float frames whose lin-log level (log of 255 x) takes ``levels`` (all above the knee)."""
    values = torch.tensor([math.exp(v) / 255.0 for v in levels], dtype=torch.float64)
    return values.view(-1, 1, 1).expand(-1, *shape).clone()


def per_pixel(events: et.EventBatch) -> dict[tuple[int, int], list[tuple[int, int]]]:
    out: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for x, y, t, p in zip(events.x.tolist(), events.y.tolist(), events.t.tolist(), events.p.tolist()):
        out.setdefault((y, x), []).append((t, p))
    return out


class TestCrossings:
    def test_linear_ramp_gives_floor_of_change_over_threshold(self):
        # log rises 1.1 over 4 intervals: floor(1.1 / 0.25) = 4 ON events per pixel, at the crossings
        start = math.log(60.0)
        events = F.emulate_events(ramp([start + 1.1 * k / 4 for k in range(5)]), fps=FPS, threshold_on=0.25, seed=0)
        rows = per_pixel(events)
        assert len(rows) == 6
        slope = 1.1 / (4 * DT)  # log units per µs
        for got in rows.values():
            assert [p for _, p in got] == [1] * 4
            expected = [math.floor(0.25 * j / slope) for j in range(1, 5)]
            assert [t for t, _ in got] == pytest.approx(expected, abs=1)

    def test_falling_ramp_gives_off_events_at_the_off_threshold(self):
        start = math.log(200.0)
        events = F.emulate_events(ramp([start - 0.95 * k / 2 for k in range(3)]), fps=FPS, threshold_on=0.1,
                                  threshold_off=0.3, seed=0)
        assert events.lengths == [6 * 3] and set(events.p.tolist()) == {0}  # floor(0.95 / 0.3) = 3

    def test_timestamps_lie_inside_their_frame_interval(self):
        # a jump in interval 2 only: every event between frame 2 and frame 3
        levels = [4.0, 4.0, 4.0, 5.0, 5.0]
        events = F.emulate_events(ramp(levels), fps=FPS, threshold_on=0.3, seed=0)
        assert events.lengths == [6 * 3]
        assert bool((events.t >= math.floor(2 * DT)).all()) and bool((events.t <= math.ceil(3 * DT)).all())

    def test_refractory_period_spaces_events_by_threshold_time_plus_refractory(self):
        levels = [4.0 + 0.5 * k for k in range(5)]  # slope 0.5 per frame, threshold 0.05
        refractory = 10_000.0
        events = F.emulate_events(ramp(levels, (1, 1)), fps=FPS, threshold_on=0.05, refractory_us=refractory, seed=0)
        times = events.t.tolist()
        slope = 0.5 / DT
        spacing = 0.05 / slope + refractory
        assert len(times) == math.floor((4 * DT - 0.05 / slope) / spacing) + 1
        assert all(b - a >= refractory for a, b in zip(times, times[1:]))
        assert [b - a for a, b in zip(times, times[1:])] == pytest.approx([spacing] * (len(times) - 1), abs=1.5)

    def test_huge_jump_is_bounded_by_the_refractory_period(self):
        video = torch.zeros(3, 4, 5, dtype=torch.uint8)
        video[1:] = 255  # from the linear part to log(255): about 5.5 log units in one interval
        free = F.emulate_events(video, fps=FPS, threshold_on=0.01, seed=0)
        bounded = F.emulate_events(video, fps=FPS, threshold_on=0.01, refractory_us=5_000.0, seed=0)
        per_free = free.lengths[0] // 20
        assert per_free == math.floor(math.log(255.0) / 0.01)
        assert bounded.lengths[0] // 20 <= math.floor(DT / 5_000.0) + 1

    @pytest.mark.parametrize("refractory", [0.0, 3_000.0])
    def test_matches_a_slow_per_pixel_reference(self, refractory):
        generator = torch.Generator().manual_seed(5)
        video = (torch.rand(6, 4, 5, generator=generator) * 200 + 30).to(torch.uint8)
        kwargs = dict(threshold_on=0.12, threshold_off=0.17, mismatch=0.1, refractory_us=refractory, seed=9)
        events = F.emulate_events(video, fps=FPS, **kwargs)
        args = {"threshold_on": torch.tensor([0.12]), "threshold_off": torch.tensor([0.17]), "mismatch": torch.tensor([0.1]),
                "noise_hz": torch.zeros(1), "hot_pixel_fraction": torch.zeros(1), "hot_pixel_hz": torch.zeros(1)}
        keys = E.sample_keys(torch.tensor([9]), "cpu")
        on, off, _ = E._camera(keys, 20, args, 10.0, 2.0, torch.device("cpu"))
        levels = E._levels(video, 20.0, True).reshape(6, 20).double()
        expected = []
        for i in range(20):
            expected += [(t, i, p) for t, p in _reference(levels[:, i].tolist(), float(on[0, i]), float(off[0, i]), refractory)]
        got = sorted(zip(events.t.tolist(), (events.y * 5 + events.x).tolist(), events.p.tolist()))
        expected.sort()
        assert len(got) == len(expected) > 20
        assert sorted((i, p) for _, i, p in got) == sorted((i, p) for _, i, p in expected)
        assert [t for t, _, _ in got] == pytest.approx([t for t, _, _ in expected], abs=2)


def _reference(levels: list[float], on: float, off: float, refractory: float) -> list[tuple[int, int]]:
    """One pixel, event by event: the next crossing of the linearly interpolated level."""
    out = []
    d, blind_until = 0.0, -math.inf
    for k in range(len(levels) - 1):
        t0, t1 = k * DT, (k + 1) * DT
        rate = (levels[k + 1] - levels[k]) / DT
        t = t0
        if blind_until > t0:
            d, t = 0.0, min(blind_until, t1)
        while rate != 0 and t < t1:
            distance = on - d if rate > 0 else off + d
            crossing = t + distance / abs(rate)
            if crossing > t1:
                d += rate * (t1 - t)
                break
            out.append((math.floor(crossing), int(rate > 0)))
            d, blind_until = 0.0, crossing + refractory
            t = min(blind_until, t1)
    return out


class TestNoiseAndLeak:
    def test_constant_video_gives_shot_noise_at_its_rate(self):
        video = torch.full((31, 40, 50), 0.5)
        events = F.emulate_events(video, fps=FPS, noise_hz=5.0, noise_spread=1.0, seed=3)
        expected = 5.0 * 2000 * 1.0  # rate x pixels x duration (s)
        assert abs(events.lengths[0] - expected) < 4 * math.sqrt(expected)
        on = events.p.double().mean().item()
        assert abs(on - 0.5) < 4 * math.sqrt(0.25 / events.lengths[0])
        assert int(events.t.min()) >= 0 and int(events.t.max()) < 1_000_000

    def test_constant_video_gives_leak_events_at_their_rate(self):
        video = torch.full((61, 10, 20), 0.5)
        events = F.emulate_events(video, fps=FPS, leak_hz=3.0, seed=4)
        per_pixel_count = torch.bincount((events.y * 20 + events.x).long(), minlength=200)
        assert set(events.p.tolist()) == {1}
        assert set(per_pixel_count.tolist()) <= {6, 7}  # 2 s at 3 Hz from a random phase: 6 or 7

    def test_hot_pixels_fire_at_their_rate(self):
        video = torch.full((31, 50, 50), 0.5)
        events = F.emulate_events(video, fps=FPS, hot_pixel_fraction=0.01, hot_pixel_hz=200.0, hot_pixel_spread=1.0,
                                  seed=1)
        hot = torch.bincount((events.y * 50 + events.x).long(), minlength=2500)
        assert 10 <= int((hot > 0).sum()) <= 45  # 25 expected
        assert abs(hot[hot > 0].double().mean().item() - 200.0) < 20


class TestPurity:
    KW = dict(mismatch=0.05, refractory_us=1_000.0, noise_hz=1.0, leak_hz=0.5, hot_pixel_fraction=0.01)

    def test_a_sample_alone_equals_the_sample_in_a_batch(self):
        video = torch.rand(3, 8, 9, 11, generator=torch.Generator().manual_seed(0))
        batch = F.emulate_events(video, fps=FPS, threshold_on=torch.tensor([0.1, 0.2, 0.3]),
                                 seed=torch.tensor([1, 2, 3]), **self.KW)
        alone = F.emulate_events(video[1], fps=FPS, threshold_on=0.2, seed=2, **self.KW)
        for column in ("x", "y", "t", "p"):
            assert torch.equal(getattr(batch[1], column), getattr(alone, column))

    def test_seeded_reproducibility_and_chunking(self):
        video = torch.rand(10, 7, 6, generator=torch.Generator().manual_seed(1))
        a = F.emulate_events(video, fps=FPS, seed=7, **self.KW)
        b = F.emulate_events(video, fps=FPS, seed=7, chunk_frames=1, **self.KW)
        c = F.emulate_events(video, fps=FPS, seed=8, **self.KW)
        assert torch.equal(a.t, b.t) and torch.equal(a.x, b.x) and torch.equal(a.p, b.p)
        assert not (a.lengths == c.lengths and torch.equal(a.t, c.t))

    def test_generator_draws_the_seeds(self):
        video = torch.rand(5, 4, 4)
        one = F.emulate_events(video, fps=FPS, noise_hz=50.0, generator=torch.Generator().manual_seed(3))
        two = F.emulate_events(video, fps=FPS, noise_hz=50.0, generator=torch.Generator().manual_seed(3))
        assert torch.equal(one.t, two.t)

    def test_input_is_not_modified(self):
        video = torch.rand(4, 3, 3)
        version, copy = video._version, video.clone()
        F.emulate_events(video, fps=FPS, seed=0)
        assert video._version == version and torch.equal(video, copy)

    @pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
    def test_cuda_equals_cpu(self):
        video = torch.rand(2, 6, 9, 11, generator=torch.Generator().manual_seed(2))
        cpu = F.emulate_events(video, fps=FPS, seed=torch.tensor([4, 5]), **self.KW)
        cuda = F.emulate_events(video.cuda(), fps=FPS, seed=torch.tensor([4, 5]), **self.KW)
        assert cuda.device.type == "cuda" and cuda.lengths == cpu.lengths
        assert torch.equal(cuda.x.cpu(), cpu.x) and (cuda.t.cpu() - cpu.t).abs().max() <= 1


class TestHardCases:
    def test_one_frame_and_empty_batch(self):
        assert F.emulate_events(torch.rand(1, 3, 4), fps=FPS, noise_hz=100.0, seed=0).lengths == [0]
        assert F.emulate_events(torch.rand(2, 0, 3, 4), fps=FPS, noise_hz=100.0, seed=0).lengths == [0, 0]
        empty = F.emulate_events(torch.rand(0, 5, 3, 4), fps=FPS)
        assert len(empty) == 0 and empty.sensor_size == (3, 4)
        with pytest.raises(ValueError, match="H and W"):
            F.emulate_events(torch.rand(2, 5, 0, 4), fps=FPS, seed=0)

    def test_constant_video_without_noise_is_silent(self):
        assert F.emulate_events(torch.full((9, 5, 6), 0.3), fps=FPS, seed=0, mismatch=0.1).lengths == [0]

    @pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float64])
    def test_float_dtypes_agree_with_float32_on_a_coarse_ramp(self, dtype):
        video = torch.tensor([0.1, 0.3, 0.9]).view(3, 1, 1).expand(3, 4, 5)
        reference = F.emulate_events(video, fps=FPS, threshold_on=0.3, seed=0)
        assert F.emulate_events(video.to(dtype), fps=FPS, threshold_on=0.3, seed=0).lengths == reference.lengths

    def test_uint8_is_read_in_digital_numbers(self):
        digital = torch.tensor([25, 76, 230], dtype=torch.uint8).view(3, 1, 1).expand(3, 2, 2)
        unit = digital.double() / 255.0
        assert F.emulate_events(digital, fps=FPS, seed=0).lengths == F.emulate_events(unit, fps=FPS, seed=0).lengths

    def test_rgb_needs_a_stated_channel(self):
        rgb = torch.rand(4, 3, 5, 6)
        red = F.emulate_events(rgb, fps=FPS, channel=0, seed=0)
        assert red.lengths == F.emulate_events(rgb[:, 0], fps=FPS, seed=0).lengths
        assert F.emulate_events(rgb, fps=FPS, channel="luma", seed=0).sensor_size == (5, 6)
        with pytest.raises(ValueError, match="channel"):
            F.emulate_events(rgb, fps=FPS, channel="green")

    def test_frame_times_give_the_event_clock(self):
        video = ramp([4.0, 4.5, 5.0])
        events = F.emulate_events(video, frame_times_us=[1_000_000, 1_010_000, 1_050_000], threshold_on=0.2, seed=0)
        assert int(events.t.min()) >= 1_000_000 and int(events.t.max()) <= 1_050_000

    def test_meta_device_is_refused_by_name(self):
        with pytest.raises(ValueError, match="meta"):
            F.emulate_events(torch.zeros(3, 4, 5, device="meta"), fps=FPS, seed=0)

    @pytest.mark.parametrize(("kwargs", "error", "match"), [
        (dict(frames=torch.zeros(3, 4)), ValueError, "frames"),
        (dict(frames=torch.zeros(3, 4, 5, dtype=torch.int32)), TypeError, "frames"),
        (dict(frames=[[0.0]]), TypeError, "frames"),
        (dict(fps=None), TypeError, "fps"),
        (dict(fps=30.0, frame_times_us=[0, 1, 2]), TypeError, "frame_times_us"),
        (dict(fps=None, frame_times_us=[0, 2, 1]), ValueError, "frame_times_us"),
        (dict(fps=None, frame_times_us=[0, 1]), ValueError, "frame_times_us"),
        (dict(threshold_on=0.0), ValueError, "threshold_on"),
        (dict(mismatch=-0.1), ValueError, "mismatch"),
        (dict(refractory_us=float("nan")), ValueError, "refractory_us"),
        (dict(seed=-1), ValueError, "seed"),
        (dict(knee_dn=0.0), ValueError, "knee_dn"),
        (dict(noise_spread=0.5), ValueError, "noise_spread"),
        (dict(frames=torch.zeros(3, 3, 4, 5), channel=None, threshold_on=torch.tensor([0.1, 0.2])), ValueError,
         "threshold_on"),
    ])
    def test_bad_input_names_the_argument(self, kwargs, error, match):
        call = dict(frames=torch.rand(3, 4, 5), fps=FPS, seed=0)
        call.update(kwargs)
        with pytest.raises(error, match=match):
            F.emulate_events(call.pop("frames"), **call)


class TestModule:
    def test_params_replay_and_ranges(self):
        emulate = et.EmulateEvents(fps=FPS, threshold=(0.1, 0.4), noise_hz=(1.0, 5.0), refractory_us=100.0)
        video = torch.rand(4, 6, 5, 7, generator=torch.Generator().manual_seed(0))
        params = emulate.make_params(video.shape, generator=torch.Generator().manual_seed(1))
        assert params["threshold_on"].shape == (4,) and torch.equal(params["threshold_on"], params["threshold_off"])
        assert bool(((params["threshold_on"] >= 0.1) & (params["threshold_on"] <= 0.4)).all())
        assert bool((params["refractory_us"] == 100.0).all())
        first = emulate(video, params=params)
        again = emulate(video, params=params)
        assert torch.equal(first.t, again.t) and first.lengths == again.lengths
        alone = emulate(video[2], params={k: v[2:3] for k, v in params.items()})
        assert torch.equal(first[2].t, alone.t) and torch.equal(first[2].x, alone.x)

    def test_one_camera_for_every_sample(self):
        emulate = et.EmulateEvents(fps=FPS, threshold=0.2, mismatch=0.2, camera_seed=11)
        params = emulate.make_params((3, 5, 4, 4), generator=torch.Generator().manual_seed(0))
        assert params["camera_seed"].tolist() == [11, 11, 11]

    def test_bad_params_and_settings_are_refused_by_name(self):
        emulate = et.EmulateEvents(fps=FPS)
        video = torch.rand(2, 4, 3, 3)
        params = emulate.make_params(video.shape)
        params["threshold_on"] = torch.tensor([0.2, -1.0], dtype=torch.float64)
        with pytest.raises(ValueError, match="threshold_on"):
            emulate(video, params=params)
        with pytest.raises(ValueError, match="threshold"):
            et.EmulateEvents(fps=FPS, threshold=(0.0, 0.2))
        with pytest.raises(ValueError, match="channel"):
            et.EmulateEvents(fps=FPS, channel="blue")
        with pytest.raises(TypeError, match="frame_times_us"):
            et.EmulateEvents()(video)
        assert "threshold=(0.15, 0.3)" in repr(et.EmulateEvents(fps=FPS))

    def test_rgb_module_and_frame_times(self):
        emulate = et.EmulateEvents(channel="mean", threshold=0.2)
        rgb = torch.rand(2, 5, 3, 4, 6)
        events = emulate(rgb, frame_times_us=torch.arange(5) * 20_000, generator=torch.Generator().manual_seed(0))
        assert len(events) == 2 and events.sensor_size == (4, 6)


class TestInContainers:
    """EmulateEvents in each container: first in a Compose (event transforms and the binning after it),
    in a OneOf of cameras, refused by RandomApply and anywhere it would be handed events."""

    VIDEO = torch.rand(4, 6, 5, 7, generator=torch.Generator().manual_seed(3))

    def _camera(self, threshold: float = 0.2) -> et.EmulateEvents:
        return et.EmulateEvents(fps=FPS, threshold=threshold, mismatch=0.05, noise_hz=2.0)

    def test_compose_replays_and_equals_its_members_chained(self):
        emulate, flip = self._camera(), et.HorizontalFlip(p=0.5)
        binning = et.EventsToFrames(sensor_size=(5, 7), frame_ms=1000.0 / FPS, n_frames=6, t_start=0)
        pipeline = et.Compose([emulate, flip, binning])
        assert pipeline.takes_video and not pipeline.takes_events
        params = pipeline.make_params(self.VIDEO.shape, generator=torch.Generator().manual_seed(0))
        assert params["1"]["apply"].shape == (4,)
        frames = pipeline(self.VIDEO, params=params)
        assert frames.shape == (4, 6, 2, 5, 7)
        chained = binning(flip(emulate(self.VIDEO, params=params["0"]), params=params["1"]), params=params["2"])
        assert torch.equal(frames, chained)
        assert torch.equal(pipeline(self.VIDEO, generator=torch.Generator().manual_seed(0)), frames)
        # a sample alone equals the sample in the batch, labels pass through
        alone, label = pipeline(self.VIDEO[1], torch.tensor(7.0), params=slice_params(params, torch.tensor([1])))
        assert torch.equal(alone[0], frames[1]) and label.item() == 7.0
        # the counts are the events': the binning loses none inside the window
        events = flip(emulate(self.VIDEO, params=params["0"]), params=params["1"])
        assert frames.sum().item() == sum(int(((events[b].t >= 0) & (events[b].t < 6e6 / FPS)).sum()) for b in range(4))

    def test_one_of_cameras_gives_each_sample_its_branch(self):
        low, high = self._camera(0.1), self._camera(0.4)
        either = et.OneOf([low, high])
        assert either.takes_video
        params = either.make_params(self.VIDEO.shape, generator=torch.Generator().manual_seed(5))
        index = params["index"].tolist()
        assert set(index) == {0, 1}, index  # the seed draws both branches
        events = either(self.VIDEO, params=params)
        assert len(events) == 4
        for b, branch in enumerate(index):
            member = (low, high)[branch]
            own = member(self.VIDEO[b], params=slice_params(params[str(branch)], torch.tensor([b])))
            assert same_events(events[b : b + 1], own), b
        empty = either(self.VIDEO[:0], params=slice_params(params, torch.zeros(0, dtype=torch.int64)))
        assert len(empty) == 0 and empty.num_events == 0
        # one branch for the whole batch is not gathered
        whole = et.OneOf([low, high], weights=[1.0, 0.0])
        one = whole(self.VIDEO, generator=torch.Generator().manual_seed(1))
        assert len(one) == 4

    def test_refused_where_it_would_be_handed_events_or_leave_a_video(self):
        with pytest.raises(TypeError, match=r"transform \(EmulateEvents\) turns a video into events, so RandomApply"):
            et.RandomApply(self._camera(), p=0.5)
        with pytest.raises(TypeError, match=r"transforms\[1\] \(EmulateEvents\) turns a video into events"):
            et.Compose([et.HorizontalFlip(), self._camera()])
        with pytest.raises(TypeError, match=r"members \[0\] turn a video into events and members \[1\] do not"):
            et.OneOf([self._camera(), et.HorizontalFlip()])
        with pytest.raises(TypeError, match="give the module fps="):
            et.Compose([et.EmulateEvents(threshold=0.2)])(self.VIDEO)
        with pytest.raises(TypeError, match="takes a video as a torch.Tensor"):
            et.Compose([self._camera()])(self.VIDEO.numpy())
        with pytest.raises(ValueError, match=r"expected a video shape \(B, T, H, W\)"):
            et.Compose([self._camera()]).make_params((2, 3, 2, 5, 7, 1))
