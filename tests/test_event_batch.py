"""EventBatch, device binning, event kernels and event-only transforms (issue 20)."""

from __future__ import annotations

import math
from collections import Counter
from functools import partial
from itertools import product

import numpy as np
import pytest
import torch

import event_transforms as et
from event_transforms import functional as F
from event_transforms.functional import EventBatch, bin_events, collate_events, events_to_frames
from event_transforms.functional import event_kernels as K
from event_transforms.functional import frame_shift, time_reversal, to_voxel_grid
from event_transforms.events.batch import merge_streams
from event_transforms.transforms.base import slice_params

SENSOR = (11, 17)  # non-square, H first
T = 6
FRAME_US = 1000


def make_streams(batch: int = 4, seed: int = 0, *, n: int | None = None) -> list[torch.Tensor]:
    """Sorted (N, 4) int64 streams of (x, y, t, p) on SENSOR, t in [0, T ms)."""
    g = torch.Generator().manual_seed(seed)
    out = []
    for b in range(batch):
        size = n if n is not None else int(torch.randint(20, 200, (1,), generator=g))
        t = torch.sort(torch.randint(0, T * FRAME_US, (size,), generator=g)).values
        x = torch.randint(0, SENSOR[1], (size,), generator=g)
        y = torch.randint(0, SENSOR[0], (size,), generator=g)
        p = torch.randint(0, 2, (size,), generator=g)
        out.append(torch.stack([x, y, t, p], 1))
    return out


def make_batch(batch: int = 4, seed: int = 0, **kwargs) -> EventBatch:
    return EventBatch.from_streams(make_streams(batch, seed, **kwargs), sensor_size=SENSOR, frame_ms=1.0,
                                   t_start=0, n_frames=T)


def frames_of(batch: EventBatch, dtype=torch.int64) -> torch.Tensor:
    return bin_events(batch, dtype=dtype)


def rows(batch: EventBatch, b: int) -> list[tuple[int, int, int, int]]:
    one = batch[b]
    return list(zip(one.x.tolist(), one.y.tolist(), one.t.tolist(), one.p.tolist()))


# --------------------------------------------------------------------------- EventBatch


class TestEventBatch:
    def test_tonic_dtypes_and_layout(self):
        aedat4 = np.dtype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])
        a = np.zeros(3, dtype=aedat4)
        a["t"] = 1_700_000_000_000_000 + np.array([0, 12_000, 25_000])
        a["x"], a["y"], a["p"] = [0, 16, 3], [10, 0, 2], [True, False, True]
        signed = {"x": np.array([1]), "y": np.array([2]), "t": np.array([7]), "polarity": np.array([-1])}
        batch = EventBatch.from_streams([a, signed, torch.zeros(0, 4)], sensor_size=SENSOR)
        assert len(batch) == 3 and batch.lengths == [3, 1, 0]
        assert (batch.x.dtype, batch.y.dtype, batch.t.dtype, batch.p.dtype) == (torch.int16, torch.int16, torch.int64, torch.int8)
        assert batch.p.tolist() == [1, 0, 1, 0]
        assert batch.nbytes == 13 * 4
        assert batch.offsets.device.type == "cpu"

    def test_indexing(self):
        batch = make_batch(5)
        assert rows(batch[1:3], 0) == rows(batch, 1)
        assert batch[-1].lengths == [batch.lengths[-1]]
        picked = batch[[4, 0]]
        assert picked.lengths == [batch.lengths[4], batch.lengths[0]]
        assert rows(picked, 0) == rows(batch, 4)
        assert picked.t_start.tolist() == [0, 0]
        assert len(batch[2:2]) == 0
        with pytest.raises(IndexError, match="out of range"):
            batch[5]

    def test_errors_name_the_argument(self):
        with pytest.raises(TypeError, match="sensor_size"):
            EventBatch.from_streams(make_streams(1))
        with pytest.raises(ValueError, match="offsets"):
            EventBatch(*(torch.zeros(2, dtype=d) for d in (torch.int16, torch.int16, torch.int64, torch.int8)),
                       torch.tensor([0, 3]), SENSOR)
        with pytest.raises(TypeError, match="column x"):
            EventBatch(torch.zeros(2), torch.zeros(2, dtype=torch.int16), torch.zeros(2, dtype=torch.int64),
                       torch.zeros(2, dtype=torch.int8), torch.tensor([0, 2]), SENSOR)

    def test_to_and_pin_memory(self):
        batch = make_batch(2)
        moved = batch.to("cpu")
        assert torch.equal(moved.t, batch.t) and moved.offsets is batch.offsets
        if torch.cuda.is_available():  # pragma: no cover - needs an accelerator
            assert batch.pin_memory().x.is_pinned()

    def test_collate_in_a_dataloader(self):
        streams = [s.numpy() for s in make_streams(5)]
        data = [(s, float(i)) for i, s in enumerate(streams)]
        loader = torch.utils.data.DataLoader(
            data, batch_size=2, collate_fn=partial(collate_events, sensor_size=SENSOR, frame_ms=1.0, n_frames=T))
        batches = list(loader)
        assert [len(b) for b, _ in batches] == [2, 2, 1]
        assert batches[1][1].tolist() == [2.0, 3.0]
        assert batches[0][0].n_frames == T

    def test_merge_streams_restores_order(self):
        batch = make_batch(4)
        parts = [([1, 3], batch[[1, 3]]), ([0, 2], batch[[0, 2]])]
        merged = merge_streams(parts, 4, batch)
        assert merged.lengths == batch.lengths and torch.equal(merged.t, batch.t)


# --------------------------------------------------------------------------- binning


class TestBinning:
    @pytest.mark.parametrize("t_start, crop, pool, n_frames", [
        ("floor", None, 1, None), ("first", None, 1, 8), (-300, (1, 2, 8, 12), 2, 7), ("floor", (0, 0, 10, 16), 2, None),
    ])
    def test_equals_events_to_frames_per_stream(self, t_start, crop, pool, n_frames):
        streams = make_streams(4, seed=1)
        if isinstance(t_start, str):
            streams[1][:, 2] += 1_700_000_000_000_000  # absolute timestamps in one stream
        batch = EventBatch.from_streams(streams, sensor_size=SENSOR)
        out = bin_events(batch, frame_ms=1.0, t_start=t_start, n_frames=n_frames, crop=crop, pool=pool)
        singles = [events_to_frames(s, sensor_size=SENSOR, frame_ms=1.0, t_start=t_start, n_frames=n_frames,
                                    crop=crop, pool=pool) for s in streams]
        for b, single in enumerate(singles):
            t = single.shape[0]
            assert torch.equal(out[b, :t], single)
            assert out[b, t:].sum() == 0

    def test_grid_is_used_and_module_matches(self):
        batch = make_batch(3)
        to_frames = et.EventsToFrames(SENSOR, frame_ms=1.0, n_frames=T, dtype=torch.int16)
        out = to_frames(batch)
        assert out.dtype == torch.int16 and out.shape == (3, T, 2, *SENSOR)
        assert torch.equal(out.long(), frames_of(batch))
        with pytest.raises(ValueError, match="frame_ms"):
            bin_events(batch, frame_ms=2.0)

    def test_outside_sensor_dropped_and_empty(self):
        batch = EventBatch.from_streams([torch.tensor([[-1, 0, 0, 1], [17, 0, 0, 1], [3, 4, 0, 0]]), torch.zeros(0, 4)],
                                        sensor_size=SENSOR)
        out = bin_events(batch, frame_ms=1.0, n_frames=2)
        assert out.sum().item() == 1 and out[0, 0, 0, 4, 3] == 1
        assert bin_events(batch[1:], frame_ms=1.0, n_frames=2).sum() == 0
        assert bin_events(batch[:0], frame_ms=1.0, n_frames=2).shape == (0, 2, 2, *SENSOR)

    def test_voxel_grid(self):
        batch = make_batch(3)
        padded, lengths = batch.to_padded()
        assert torch.equal(to_voxel_grid(batch, n_bins=4), to_voxel_grid(padded, n_bins=4, sensor_size=SENSOR, lengths=lengths))


# --------------------------------------------------------------------------- kernels vs references


class TestKernels:
    def test_flips_and_polarity_match_frames(self):
        batch = make_batch()
        frames = frames_of(batch)
        assert torch.equal(frames_of(et.HorizontalFlip()(batch)), frames.flip(-1))
        assert torch.equal(frames_of(et.VerticalFlip()(batch)), frames.flip(-2))
        assert torch.equal(frames_of(et.FlipPolarity()(batch)), frames.flip(2))
        assert torch.equal(frames_of(et.TimeReversal()(batch)), time_reversal(frames))

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
        out = K.translate_events(batch, shift)
        for b in range(2):
            assert rows(out, b) == [(x + int(shift[b, 1]), y + int(shift[b, 0]), t, p) for x, y, t, p in rows(batch, b)]
        frames = frames_of(batch)
        assert torch.equal(frames_of(et.Translate((1, -2))(batch)), et.Translate((1, -2))(frames))

    def test_rotation_reference(self):
        batch = make_batch(3)
        angle, scale = torch.tensor([30.0, -75.0, 180.0]), torch.tensor([1.0, 1.25, 0.8])
        out = K.affine_events(batch, angle=angle, scale=scale)
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
        square = EventBatch.from_streams(streams, sensor_size=(11, 11), frame_ms=1.0, t_start=0, n_frames=T)
        frames = bin_events(square, dtype=torch.int64).float()
        for angle in (90.0, 180.0, -90.0):
            rotate = et.Rotate(angle, center="image", mode="nearest")
            assert torch.equal(bin_events(rotate(square)), rotate(frames))
        assert et.RandomRotation(40.0)(square).lengths == square.lengths  # every event kept (some off the sensor)

    def test_frame_shift_matches_frames(self):
        batch = make_batch()
        for shift in (-2, 1, 0):
            assert torch.equal(frames_of(et.FrameShift(shift)(batch)), frame_shift(frames_of(batch), shift))

    @pytest.mark.parametrize("fraction, shift", [(0.5, -2), (0.3, 1), (1.0, -1), (0.0, 2), (0.77, 3)])
    def test_tes_exact_moves_round_zeta_n(self, fraction, shift):
        batch = make_batch(4, n=300)
        tes = et.TemporalEventShift(shift, fraction)
        out = tes(batch, generator=torch.Generator().manual_seed(1))
        n = frames_of(batch).sum(dim=(3, 4))
        k = torch.round(fraction * n.double()).long()
        expected = n - k
        if shift >= 0:
            expected[:, shift:] += k[:, : T - shift]
        else:
            expected[:, :shift] += k[:, -shift:]
        assert torch.equal(frames_of(out).sum(dim=(3, 4)), expected)
        # the same per-(frame, polarity) totals as the frame kernel, whose totals are deterministic too
        frame_out = tes(frames_of(batch), generator=torch.Generator().manual_seed(1))
        assert torch.equal(frames_of(out).sum(dim=(3, 4)), frame_out.sum(dim=(3, 4)))
        assert bool((frames_of(out)[:, :] >= 0).all())

    def test_tes_chi_square(self):
        """Moved counts per pixel of one group: multivariate hypergeometric (a uniform subset of k of N)."""
        pixels = [3, 2, 1]  # N = 6 events in three pixels of frame 1, ON; k = 3
        events = [[i, 0, 1_000 + 10 * j, 1] for i, c in enumerate(pixels) for j in range(c)]
        batch = EventBatch.from_streams([torch.tensor(events)], sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)
        runs = 600
        seen = Counter()
        for seed in range(runs):
            out = K.shift_events(batch, torch.tensor([1]), torch.tensor([0.5]), seed=torch.tensor([seed * 7919 + 11]))
            moved = frames_of(out)[0, 2, 1, 0, :3]
            seen[tuple(moved.tolist())] += 1
        outcomes = [z for z in product(*(range(c + 1) for c in pixels)) if sum(z) == 3]
        total = math.comb(6, 3)
        chi2 = 0.0
        for z in outcomes:
            expected = runs * math.prod(math.comb(c, k) for c, k in zip(pixels, z)) / total
            chi2 += (seen[z] - expected) ** 2 / expected
        assert set(seen) <= set(outcomes)
        assert chi2 < 24.3  # chi-square, 5 degrees of freedom, p = 0.0002

    def test_binomial_tes_and_expected_mode(self):
        batch = make_batch(2, n=400)
        out = et.TemporalEventShift(-1, 0.5, mode="binomial")(batch, generator=torch.Generator().manual_seed(0))
        assert out.num_events <= batch.num_events
        with pytest.raises(ValueError, match="expected"):
            et.TemporalEventShift(-1, 0.5, mode="expected")(batch)

    def test_time_needs_a_grid(self):
        batch = EventBatch.from_streams(make_streams(2), sensor_size=SENSOR)
        with pytest.raises(ValueError, match="frame grid"):
            et.FrameShift(1)(batch)

    def test_random_drop_reference(self):
        batch = make_batch(3)
        fraction, seed = torch.tensor([0.2, 0.5, 0.9]), torch.tensor([5, 6, 7])
        out = K.drop_events_random(batch, fraction, seed)
        for b in range(3):
            u = torch.empty(batch.lengths[b]).uniform_(generator=torch.Generator().manual_seed(int(seed[b])))
            expected = [e for e, ui in zip(rows(batch, b), u.tolist()) if not ui < fraction[b].item()]
            assert rows(out, b) == expected

    def test_bank_noise_matches_frames_and_places_events_at_bin_centres(self):
        batch = make_batch(3)
        bank = torch.poisson(torch.full((9, 2, *SENSOR), 0.2), generator=torch.Generator().manual_seed(1))
        noise = et.AddNoise(bank)
        params = noise.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(2))
        out = noise(batch, params=params)
        assert torch.equal(frames_of(out), noise(frames_of(batch), params=params))
        for b in range(3):  # slow reference: every count of the window is one event at its bin's centre
            first = int(params["offset"][b])
            added = rows(out, b)[batch.lengths[b]:]
            expected = sorted(
                (x, y, int(batch.t_start[b]) + t * FRAME_US + FRAME_US // 2, p)
                for t in range(T) for p in range(2) for y in range(SENSOR[0]) for x in range(SENSOR[1])
                for _ in range(int(bank[first + t, p, y, x]))
            )
            assert sorted(added) == expected and rows(out, b)[: batch.lengths[b]] == rows(batch, b)
        with pytest.raises(ValueError, match="cannot cover frames"):
            et.AddNoise(torch.zeros(9, 2, 5, 5))(batch)

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

    def test_jitters_reference(self):
        batch = make_batch(2)
        sigma, seed = torch.tensor([1.5, 0.0]), torch.tensor([3, 4])
        out = K.spatial_jitter(batch, sigma, seed)
        for b in range(2):
            n = batch.lengths[b]
            g = torch.Generator().manual_seed(int(seed[b]))
            noise_x, noise_y = torch.empty(n).normal_(generator=g), torch.empty(n).normal_(generator=g)
            for i, ((x, y, t, p), (ox, oy, ot, op)) in enumerate(zip(rows(batch, b), rows(out, b))):
                assert ox == round(x + noise_x[i].item() * sigma[b].item())
                assert oy == round(y + noise_y[i].item() * sigma[b].item())
                assert (ot, op) == (t, p)
        std = torch.tensor([50.0, 200.0])
        out = K.time_jitter(batch, std, seed)
        for b in range(2):
            noise = torch.empty(batch.lengths[b], dtype=torch.float64).normal_(generator=torch.Generator().manual_seed(int(seed[b])))
            noise = torch.round(noise * std[b].item()).long().tolist()
            assert [e[2] for e in rows(out, b)] == [t + v for (_, _, t, _), v in zip(rows(batch, b), noise)]

    def test_time_skew_reference(self):
        batch = EventBatch.from_streams([torch.tensor([[0, 0, 100, 1], [0, 0, 300, 0]])] * 2, sensor_size=SENSOR)
        out = K.time_skew(batch, torch.tensor([2.0, 0.5]), torch.tensor([10.0, 0.0]))
        assert out.t.tolist() == [110, 510, 100, 200]

    def test_refractory_and_decimation_reference(self):
        streams = [torch.stack([s[:, 0] % 3, s[:, 1] % 3, s[:, 2], s[:, 3]], 1) for s in make_streams(3, seed=4, n=150)]
        batch = EventBatch.from_streams(streams, sensor_size=(3, 3))  # crowded pixels
        period = torch.tensor([300.0, 0.0, 2000.0])
        out = K.refractory_period(batch, period)
        n = torch.tensor([2, 1, 3])
        dec = K.decimation(batch, n)
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

    def test_poisson_noise(self):
        batch = make_batch(3)
        noise = et.AddPoissonNoise(200.0)
        out = noise(batch, generator=torch.Generator().manual_seed(0))
        expected = 200.0 * T * 1e-3 * 2 * SENSOR[0] * SENSOR[1]
        added = [a - b for a, b in zip(out.lengths, batch.lengths)]
        assert all(abs(a - expected) < 6 * math.sqrt(expected) for a in added)
        frames = frames_of(out)
        assert frames.sum() == out.num_events  # every added event lies in the window and sensor
        assert bool((frames >= frames_of(batch)).all())


# --------------------------------------------------------------------------- shared invariants

FACTORIES = {
    "RandomRotation": lambda: et.RandomRotation(30.0),
    "RandomResize": lambda: et.RandomResize((0.8, 1.25)),
    "RandomAffine": lambda: et.RandomAffine(20.0, translate=(0.1, 0.1)),
    "RandomHorizontalFlip": lambda: et.RandomHorizontalFlip(),
    "RandomVerticalFlip": lambda: et.RandomVerticalFlip(),
    "RandomTranslate": lambda: et.RandomTranslate((2, 3)),
    "RandomFrameShift": lambda: et.RandomFrameShift((-1, 1, 2)),
    "TES exact": lambda: et.RandomTemporalEventShift((-2, -1), (0.3, 0.7)),
    "TES binomial": lambda: et.RandomTemporalEventShift((-2, -1), (0.3, 0.7), mode="binomial"),
    "RandomFlipPolarity": lambda: et.RandomFlipPolarity(),
    "RandomTimeReversal": lambda: et.RandomTimeReversal(),
    "RandomEventDrop": lambda: et.RandomEventDrop((0.1, 0.5)),
    "AddPoissonNoise": lambda: et.AddPoissonNoise((1.0, 100.0)),
    "SpatialJitter": lambda: et.SpatialJitter((0.5, 2.0)),
    "TimeJitter": lambda: et.TimeJitter((10.0, 300.0)),
    "TimeSkew": lambda: et.TimeSkew((0.8, 1.2), (-100.0, 100.0)),
    "RefractoryPeriod": lambda: et.RefractoryPeriod((100.0, 2000.0)),
    "Decimation": lambda: et.Decimation((1, 3)),
    # gated (p < 1): one pass with neutral parameters for the skipped streams
    "RandomRotation p": lambda: et.RandomRotation(30.0, p=0.5),
    "TES exact p": lambda: et.RandomTemporalEventShift((-1, 1), 0.5, p=0.5),
    "RandomEventDrop p": lambda: et.RandomEventDrop((0.2, 0.6), p=0.5),
    "RandomDropPixel p": lambda: et.RandomDropPixel((0.1, 0.4), p=0.5),
    "AddNoise p": lambda: et.AddNoise(torch.poisson(torch.full((9, 2, *SENSOR), 0.3),
                                                    generator=torch.Generator().manual_seed(4)), p=0.5),
    "DropPixel": lambda: et.DropPixel([[1, 1], [3, 5]]),
    "SpatialJitter p": lambda: et.SpatialJitter(1.5, p=0.5),
    "Decimation p": lambda: et.Decimation(2, p=0.5),
}
EVENT_ONLY = ("SpatialJitter", "TimeJitter", "TimeSkew", "RefractoryPeriod", "Decimation")


def same(a: EventBatch, b: EventBatch) -> bool:
    return a.lengths == b.lengths and all(torch.equal(getattr(a, k), getattr(b, k)) for k in ("x", "y", "t", "p"))


@pytest.mark.parametrize("name", list(FACTORIES))
class TestBattery:
    def test_dtype_device_no_in_place(self, name):
        batch = make_batch()
        versions = [getattr(batch, k)._version for k in ("x", "y", "t", "p")]
        copy = [getattr(batch, k).clone() for k in ("x", "y", "t", "p")]
        out = FACTORIES[name]()(batch, generator=torch.Generator().manual_seed(0))
        assert isinstance(out, EventBatch) and len(out) == len(batch)
        assert (out.x.dtype, out.y.dtype, out.t.dtype, out.p.dtype) == (torch.int16, torch.int16, torch.int64, torch.int8)
        assert out.device == batch.device and out.sensor_size == batch.sensor_size
        assert [getattr(batch, k)._version for k in ("x", "y", "t", "p")] == versions
        assert all(torch.equal(c, getattr(batch, k)) for c, k in zip(copy, ("x", "y", "t", "p")))

    def test_sample_alone_equals_sample_in_batch(self, name):
        batch = make_batch(5)
        transform = FACTORIES[name]()
        params = transform.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(2))
        whole = transform(batch, params=params)
        for i in range(5):
            alone = transform(batch[i : i + 1], params=slice_params(params, torch.tensor([i])))
            assert same(alone, whole[i])

    def test_seeded_and_replay(self, name):
        batch = make_batch()
        transform = FACTORIES[name]()
        a = transform(batch, generator=torch.Generator().manual_seed(7))
        b = transform(batch, generator=torch.Generator().manual_seed(7))
        params = transform.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(7))
        torch.manual_seed(123)
        assert same(a, b) and same(a, transform(batch, params=params))

    def test_edge_sizes(self, name):
        transform = FACTORIES[name]()
        empty = make_batch(0)
        assert len(transform(empty)) == 0
        one = EventBatch.from_streams([torch.tensor([[3, 4, 1500, 1]]), torch.zeros(0, 4)], sensor_size=SENSOR,
                                      frame_ms=1.0, t_start=0, n_frames=T)
        out = transform(one, generator=torch.Generator().manual_seed(0))
        assert len(out) == 2 and out.lengths[0] <= 1 + (10**6 if name in ("AddPoissonNoise", "AddNoise p") else 0)

    def test_in_containers(self, name):
        batch = make_batch()
        g = lambda: torch.Generator().manual_seed(1)  # noqa: E731
        to_frames = et.EventsToFrames(SENSOR, frame_ms=1.0, n_frames=T)
        pipeline = et.Compose([FACTORIES[name](), to_frames, et.RandomFrameShift((-1, 1))])
        assert pipeline(batch, generator=g()).shape == (4, T, 2, *SENSOR)
        for container in (et.OneOf([FACTORIES[name](), et.HorizontalFlip()]), et.RandomApply(FACTORIES[name](), p=0.5)):
            params = container.make_params(batch.frame_shape, generator=g())
            out = container(batch, params=params)
            assert isinstance(out, EventBatch) and same(out, container(batch, params=params))

    def test_frames_refused_by_event_only(self, name):
        if name not in EVENT_ONLY:
            pytest.skip("has a frame kernel")
        with pytest.raises(TypeError, match=name.split()[0]):
            FACTORIES[name]()(torch.zeros(2, T, 2, *SENSOR))


@pytest.mark.parametrize("name", ["RandomRotation p", "TES exact p", "RandomEventDrop p", "SpatialJitter p", "Decimation p",
                                  "RandomDropPixel p"])
def test_gate_leaves_skipped_streams_unchanged(name):
    batch = make_batch(6)
    transform = FACTORIES[name]()
    params = transform.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(4))
    out = transform(batch, params=params)
    gate = params["apply"].tolist()
    assert any(gate) and not all(gate)
    for i, applied in enumerate(gate):
        if not applied:
            assert same(out[i], batch[i])


def test_frame_only_transform_refuses_events():
    with pytest.raises(TypeError, match="Denoise has no kernel for an EventBatch"):
        et.Denoise()(make_batch())


def test_order_stops_mattering():
    """On events, TES and event drop can follow a rotation (on frames they raise once it fired)."""
    batch = make_batch()
    pipeline = et.Compose([et.RandomRotation(30.0, p=0.5), et.RandomTemporalEventShift((-1,), 0.5),
                           et.RandomEventDrop(0.2), et.EventsToFrames(SENSOR, frame_ms=1.0, n_frames=T)])
    for seed in range(5):
        assert pipeline(batch, generator=torch.Generator().manual_seed(seed)).shape == (4, T, 2, *SENSOR)


def test_events_to_frames_first_takes_an_event_batch():
    batch = make_batch()
    pipeline = et.Compose([et.EventsToFrames(SENSOR, frame_ms=1.0, n_frames=T), et.HorizontalFlip()])
    assert torch.equal(pipeline(batch), bin_events(batch).flip(-1))


def test_modules_still_move_with_to():
    """The input-type dispatch must not shadow ``nn.Module._apply`` (used by ``.to``)."""
    rotation = et.RandomRotation(10.0).to("cpu", torch.float64)
    noise = et.AddNoise(torch.zeros(8, 2, *SENSOR)).to(torch.float64)
    assert noise.bank.dtype == torch.float64 and isinstance(rotation, et.RandomRotation)
