"""Mixing: Cutout, CutMix, MixUp and label mixing against slow references, plus the battery
for the cross-sample modules (the shared battery's per-sample checks do not apply to them:
a sample's output depends on its partner)."""

from __future__ import annotations

import pickle
import warnings

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import EventBatch
from event_transforms import functional as F

from tests.support.event_data import SENSOR, T, check_hard_cases, frames_of, make_streams, rows
from tests.support.event_data import make_batch as make_event_batch
from tests.support.checkers import H, W, check_not_modified, count_shapes, random_counts, sparse_frames

DTYPES = [torch.float32, torch.float16, torch.bfloat16, torch.float64, torch.uint8, torch.int16, torch.int32, torch.int64]


def _g(seed=0):
    return torch.Generator().manual_seed(seed)


def _reference_box(frames, fill_from, top, left, height, width):
    out = frames.clone()
    for n in range(frames.shape[0]):
        for y in range(top[n], min(top[n] + height[n], frames.shape[-2])):
            for x in range(left[n], min(left[n] + width[n], frames.shape[-1])):
                out[n, :, :, y, x] = 0 if fill_from is None else frames[fill_from[n], :, :, y, x]
    return out


class TestCutout:
    def test_against_reference(self):
        frames = sparse_frames(3, 2, 2, H, W, density=0.4, dtype=torch.int16)
        box = ([0, 5, 15], [3, 0, 9], [4, 17, 5], [2, 3, 5])
        out = check_not_modified(lambda x: F.cutout(x, *[torch.tensor(v) for v in box]), frames)
        assert out.dtype == torch.int16 and torch.equal(out, _reference_box(frames, None, *box))

    def test_boxes_are_clipped_and_centred(self):
        module = et.Cutout((5, 3))
        params = module.make_params((500, 1, 2, H, W), generator=_g())
        assert bool((params["height"] <= 5).all()) and bool((params["width"] <= 3).all())
        assert bool((params["top"] + params["height"] <= H).all()) and bool((params["left"] + params["width"] <= W).all())
        assert int((params["height"] == 5).sum()) > 300  # most boxes are whole
        out = module(torch.ones(500, 1, 2, H, W), params=params)
        removed = (out == 0).sum((1, 2, 3, 4)) // 2
        assert torch.equal(removed, params["height"] * params["width"])


class TestCutMix:
    def test_against_reference(self):
        frames = sparse_frames(3, 2, 2, H, W, density=0.4, dtype=torch.uint8)
        partner = [2, 0, 1]
        box = ([0, 5, 10], [3, 0, 9], [4, 12, 7], [2, 3, 2])
        out = F.cutmix(frames, torch.tensor(partner), *[torch.tensor(v) for v in box])
        assert out.dtype == torch.uint8 and torch.equal(out, _reference_box(frames, partner, *box))

    def test_module_mixes_frames_and_labels_with_params(self):
        frames = sparse_frames(6, 3, 2, H, W, density=0.4)
        force = torch.rand(6, 3)
        module = et.CutMix()
        params = module.make_params(frames.shape, generator=_g(1))
        out, mixed = module(frames, force, params=params)
        p = params["partner"].tolist()
        box = [params[k].tolist() for k in ("top", "left", "height", "width")]
        assert torch.equal(out, _reference_box(frames, p, *box))
        for n in range(6):
            w = 1 - box[2][n] * box[3][n] / (H * W)
            assert abs(float(params["weight"][n]) - w) < 1e-12
            torch.testing.assert_close(mixed[n], w * force[n] + (1 - w) * force[p[n]])

    def test_class_indices_become_soft_targets(self):
        frames = sparse_frames(4, 3, 2, H, W, density=0.4)
        labels = torch.tensor([0, 2, 1, 2])
        params = et.CutMix(num_classes=3).make_params(frames.shape, generator=_g(2))
        _, soft = et.CutMix(num_classes=3)(frames, labels, params=params)
        assert soft.shape == (4, 3) and soft.dtype == torch.float32
        torch.testing.assert_close(soft.sum(1), torch.ones(4))
        for n in range(4):
            w, q = float(params["weight"][n]), int(params["partner"][n])
            expected = torch.zeros(3)
            expected[labels[n]] += w
            expected[labels[q]] += 1 - w
            torch.testing.assert_close(soft[n], expected)
        with pytest.raises(TypeError, match="num_classes"):
            et.CutMix()(frames, labels)


class TestMixUp:
    def test_against_reference(self):
        frames = sparse_frames(3, 2, 2, H, W, density=0.4, dtype=torch.int32)
        out = F.mixup(frames, torch.tensor([1, 2, 0]), torch.tensor([0.3, 1.0, 0.5]))
        assert out.dtype == torch.float32
        for n, (q, w) in enumerate(zip([1, 2, 0], [0.3, 1.0, 0.5])):
            torch.testing.assert_close(out[n], w * frames[n].float() + (1 - w) * frames[q].float())

    def test_module_replays_and_gates(self):
        frames = sparse_frames(8, 3, 2, H, W, density=0.4)
        force = torch.rand(8, 3)
        module = et.MixUp(0.4, p=0.5)
        params = module.make_params(frames.shape, generator=_g(3))
        gate = params["apply"]
        assert 0 < int(gate.sum()) < 8
        torch.manual_seed(0)
        out, mixed = module(frames, force, params=params)
        torch.manual_seed(99)
        again, mixed_again = module(frames, force, params=params)
        assert torch.equal(out, again) and torch.equal(mixed, mixed_again)
        assert torch.equal(out[~gate], frames[~gate]) and torch.equal(mixed[~gate], force[~gate])
        for n in gate.nonzero().squeeze(1).tolist():
            w, q = float(params["weight"][n]), int(params["partner"][n])
            torch.testing.assert_close(out[n], (frames[q] + w * (frames[n] - frames[q])))
            torch.testing.assert_close(mixed[n], force[q] + w * (force[n] - force[q]))


@pytest.mark.parametrize("name", ["CutMix", "MixUp"])
@pytest.mark.parametrize("labels", ["force", "classes"])
def test_gated_labels_follow_the_one_gating_rule(name, labels, monkeypatch):
    """The gate gathers the chosen samples with their partners: chosen labels are the ungated
    call's, the others their own (one-hot for class indices), on frames, on events and in
    the select evaluation (traced calls, accelerator gates)."""
    frames = sparse_frames(8, 3, 2, H, W, density=0.4)
    target = torch.rand(8, 3) if labels == "force" else torch.tensor([0, 2, 1, 1, 0, 2, 2, 1])
    module = getattr(et, name)(num_classes=3 if labels == "classes" else None, p=0.5)
    params = module.make_params(frames.shape, generator=_g(11))
    gate = params["apply"]
    assert 0 < int(gate.sum()) < 8
    ungated_module = getattr(et, name)(num_classes=3 if labels == "classes" else None)
    ungated, ungated_labels = ungated_module(frames, target, params={k: v for k, v in params.items() if k != "apply"})
    own = target if labels == "force" else torch.nn.functional.one_hot(target, 3).to(ungated_labels.dtype)
    out, mixed = module(frames, target, params=params)
    assert torch.equal(mixed[gate], ungated_labels[gate]) and torch.equal(mixed[~gate], own[~gate])
    assert torch.equal(out[gate], ungated[gate].to(out.dtype))
    batch = make_event_batch(8)
    event_params = module.make_params(batch.frame_shape, generator=_g(11))
    _, from_events = module(batch, target, params=event_params)
    assert torch.equal(from_events, module(frames_of(batch), target, params=event_params)[1])
    monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    selected, selected_labels = module(frames, target, params=params)
    assert torch.equal(selected, out) and torch.equal(selected_labels, mixed)


@pytest.mark.parametrize("name", ["CutMix", "MixUp"])
class TestMixingBattery:
    @staticmethod
    def build(name):
        return et.CutMix() if name == "CutMix" else et.MixUp(0.4)

    @pytest.mark.parametrize("dtype", DTYPES)
    def test_dtypes(self, name, dtype):
        frames = sparse_frames(4, 3, 2, H, W, density=0.3, dtype=dtype)
        force = torch.rand(4, 3)
        out, mixed = check_not_modified(lambda x: self.build(name)(x, force, generator=_g()), frames)
        expected = dtype if name == "CutMix" or dtype.is_floating_point else torch.float32
        assert out.dtype == expected and out.shape == frames.shape and mixed.shape == force.shape
        assert bool((out.double() >= 0).all())

    def test_hard_cases(self, name):
        module = self.build(name)
        empty = torch.zeros(3, 5, 2, H, W)
        assert module(empty, generator=_g()).sum() == 0
        zero = module(torch.zeros(0, 5, 2, H, W, dtype=torch.int16), torch.zeros(0, 5), generator=_g())
        assert zero[0].shape == (0, 5, 2, H, W) and zero[1].shape == (0, 5)
        one = torch.zeros(1, 5, 2, H, W, dtype=torch.int32)
        one[0, 2, 1, 8, 5] = 1
        assert torch.equal(module(one, generator=_g()).double(), one.double())  # its own partner
        seq, force = module(sparse_frames(1, 2, H, W, density=0.3), torch.ones(1), generator=_g())
        assert seq.shape == (1, 2, H, W) and force.shape == (1,)

    def test_replay_params_tree(self, name):
        frames = sparse_frames(5, 3, 2, H, W, density=0.3)
        module = self.build(name)
        params = module.make_params(frames.shape, generator=_g(1))
        assert all(v.shape[0] == 5 and v.device.type == "cpu" for v in params.values())
        assert sorted(params["partner"].tolist()) == list(range(5))
        torch.manual_seed(0)
        first = module(frames, params=params)
        torch.manual_seed(1)
        assert torch.equal(module(frames, params=params), first)
        assert torch.equal(module(frames, generator=_g(1)), first)

    def test_pickle(self, name):
        frames = sparse_frames(4, 3, 2, H, W, density=0.3)
        module = self.build(name)
        clone = pickle.loads(pickle.dumps(module))
        assert torch.equal(module(frames, generator=_g(3)), clone(frames, generator=_g(3)))
        assert repr(clone) == repr(module)

    def test_dict_video_and_rest(self, name):
        from torchvision import tv_tensors

        frames = sparse_frames(4, 3, 2, H, W, density=0.3)
        force, extra = torch.rand(4, 3), object()
        module = et.CutMix(label_key="force") if name == "CutMix" else et.MixUp(0.4, label_key="force")
        sample = {"frames": frames, "force": force, "id": extra}
        out = module(sample, generator=_g(4))
        expected, expected_force = module(frames, force, generator=_g(4))
        assert torch.equal(out["frames"], expected) and torch.equal(out["force"], expected_force) and out["id"] is extra
        video, mixed, same = module(tv_tensors.Video(frames), force, extra, generator=_g(4))
        assert isinstance(video, tv_tensors.Video) and same is extra and torch.equal(mixed, expected_force)

    def test_named_errors(self, name):
        module = self.build(name)
        frames = sparse_frames(4, 3, 2, H, W, density=0.3)
        with pytest.raises(ValueError, match="batch size 4"):
            module(frames, torch.zeros(3))
        with pytest.raises(TypeError, match="labels"):
            module(frames, [1, 2, 3, 4])
        with pytest.raises(ValueError, match=r"got \(6, 3, 17, 11\)"):
            module(torch.zeros(6, 3, H, W))
        with pytest.raises(TypeError, match="frames"):
            module([[0.0, 1.0]])  # numpy frames are converted (tests/library/test_ingestion.py), other types refused
        with pytest.raises(ValueError, match="alpha"):
            et.MixUp(0.0)
        with pytest.raises(ValueError, match="partner"):
            F.mixup(frames, [0, 1, 2, 4], 0.5)
        with pytest.raises(ValueError, match="weight"):
            F.mixup(frames, [0, 1, 2, 3], 1.5)


@settings(max_examples=60, deadline=None)
@given(count_shapes, st.integers(0, 2**31), st.data())
def test_cutmix_counts_are_outside_own_plus_inside_partner(shape, seed, data):
    frames = random_counts(shape, seed)
    b, _, _, h, w = frames.shape
    partner = torch.randperm(b, generator=torch.Generator().manual_seed(seed))
    top = torch.tensor([data.draw(st.integers(0, h)) for _ in range(b)], dtype=torch.int64)
    left = torch.tensor([data.draw(st.integers(0, w)) for _ in range(b)], dtype=torch.int64)
    height = torch.tensor([data.draw(st.integers(0, h)) for _ in range(b)], dtype=torch.int64)
    width = torch.tensor([data.draw(st.integers(0, w)) for _ in range(b)], dtype=torch.int64)
    out = F.cutmix(frames, partner, top, left, height, width)
    inside = F.cutout(torch.ones_like(frames), top, left, height, width) == 0
    expected = (frames * ~inside).sum((1, 2, 3, 4)) + (frames[partner] * inside).sum((1, 2, 3, 4))
    assert torch.equal(out.sum((1, 2, 3, 4)), expected)


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "Cutout": lambda t, h, w: et.Cutout((3, 2)),
    "CutMix": lambda t, h, w: et.CutMix(),
    "MixUp": lambda t, h, w: et.MixUp(0.4),
}


# --------------------------------------------------------------------------- on events (EventBatch kernels)


def _grid_batch(streams, t_start=0):
    return EventBatch.from_streams(streams, sensor_size=SENSOR, frame_ms=1.0, t_start=t_start, n_frames=T)


def _inside(event, box):
    x, y = event[0], event[1]
    top, left, height, width = box
    return top <= y < top + height and left <= x < left + width


def _boxes(values):
    return [torch.tensor(v) for v in values]


class TestCutoutOnEvents:
    def test_against_reference_and_frames(self):
        batch = make_event_batch(3)
        box = ([0, 5, 8], [3, 0, 9], [4, 17, 5], [2, 3, 20])
        out = F.cutout(batch, *_boxes(box))
        for b in range(3):
            mine = [v[b] for v in box]
            assert rows(out, b) == [e for e in rows(batch, b) if not _inside(e, mine)]
        assert out.num_events < batch.num_events
        assert torch.equal(frames_of(out), F.cutout(frames_of(batch), *_boxes(box)))

    def test_module_and_hard_cases(self):
        batch = make_event_batch(4)
        module = et.Cutout((5, 4))
        params = module.make_params(batch.frame_shape, generator=_g(3))
        assert torch.equal(frames_of(module(batch, params=params)), module(frames_of(batch), params=params))
        check_hard_cases(lambda: et.Cutout(3))


def reference_cutmix_events(batch, b, partner, box):
    """Slow per-event reference: the stream's own events outside its box, then its partner's
    inside it, moved onto the stream's grid."""
    q = partner[b]
    if q == b:
        return rows(batch, b)
    mine = [v[b] for v in box]
    shift = int(batch.t_start[b]) - int(batch.t_start[q])
    own = [e for e in rows(batch, b) if not _inside(e, mine)]
    return own + [(x, y, t + shift, p) for x, y, t, p in rows(batch, q) if _inside((x, y), mine)]


def reference_mixup_events(batch, b, partner, weight, seed):
    """Slow per-event reference of the draws: own event k kept when its uniform (counter 2k)
    is below w, partner event k taken when its uniform (counter 2k + 1) is below 1 - w."""
    from event_transforms.functional._random import sample_salts, uniform

    q = partner[b]
    if q == b:
        return rows(batch, b)
    salt = sample_salts(torch.tensor([seed[b]]), "cpu")
    u = lambda counter: float(uniform(salt, torch.tensor([counter]), 1)[0])  # noqa: E731
    shift = int(batch.t_start[b]) - int(batch.t_start[q])
    own = [e for k, e in enumerate(rows(batch, b)) if u(2 * k) < weight[b]]
    return own + [(x, y, t + shift, p) for k, (x, y, t, p) in enumerate(rows(batch, q)) if u(2 * k + 1) < 1 - weight[b]]


class TestCutMixOnEvents:
    @pytest.mark.parametrize("t_start", [0, [0, 2000, 1000, 0]])
    def test_against_reference_and_frames(self, t_start):
        batch = _grid_batch(make_streams(4, seed=8), t_start)
        partner = [2, 0, 2, 1]  # sample 2 is its own partner
        box = ([0, 5, 8, 3], [3, 0, 9, 4], [4, 17, 5, 6], [2, 3, 20, 7])
        out = F.cutmix(batch, partner, *_boxes(box))
        for b in range(4):
            assert rows(out, b) == reference_cutmix_events(batch, b, partner, box)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # shifted partner events past the window
            assert torch.equal(frames_of(out), F.cutmix(frames_of(batch), partner, *_boxes(box)))

    def test_module_mixes_labels_as_on_frames(self):
        batch = make_event_batch(6)
        frames = frames_of(batch)
        force = torch.rand(6, T)
        module = et.CutMix()
        params = module.make_params(batch.frame_shape, generator=_g(1))
        out, mixed = module(batch, force, params=params)
        expected, expected_force = module(frames, force, params=params)
        assert torch.equal(frames_of(out), expected) and torch.equal(mixed, expected_force)

    def test_gate_leaves_skipped_streams(self):
        batch = make_event_batch(8)
        module = et.CutMix(p=0.5)
        params = module.make_params(batch.frame_shape, generator=_g(5))
        out, _ = module(batch, torch.rand(8), params=params)
        gate = params["apply"].tolist()
        assert any(gate) and not all(gate)
        for b, applied in enumerate(gate):
            if not applied:
                assert rows(out, b) == rows(batch, b)

    def test_a_sample_depends_only_on_itself_and_its_partner(self):
        batch = make_event_batch(5)
        partner, box = [3, 4, 0, 1, 2], ([1, 2, 3, 0, 4], [2, 5, 0, 6, 1], [5, 4, 6, 8, 3], [7, 6, 5, 9, 8])
        whole = F.cutmix(batch, partner, *_boxes(box))
        for b in range(5):
            pair = batch.index_select(torch.tensor([b, partner[b]]))
            alone = F.cutmix(pair, [1, 0], *_boxes([[v[b], v[b]] for v in box]))
            assert rows(alone, 0) == rows(whole, b)

    def test_hard_cases(self):
        check_hard_cases(lambda: et.CutMix(), coupled=True)


class TestMixUpOnEvents:
    @pytest.mark.parametrize("t_start", [0, [0, 2000, 1000, 0]])
    def test_against_reference(self, t_start):
        batch = _grid_batch(make_streams(4, seed=9), t_start)
        partner, weight, seed = [1, 3, 2, 0], [0.3, 0.8, 0.5, 0.0], [11, 2**62 + 5, 7, 123]
        out = F.mixup(batch, partner, weight, seed=seed)
        for b in range(4):
            assert rows(out, b) == reference_mixup_events(batch, b, partner, weight, seed)
        ends = F.mixup(batch, partner, [1.0, 0.0, 1.0, 0.0], seed=seed)  # itself, or its partner's events
        assert rows(ends, 0) == rows(batch, 0)
        assert rows(ends, 1) == reference_cutmix_events(batch, 1, partner, ([0] * 4, [0] * 4, [99] * 4, [99] * 4))

    def test_equals_frames_in_expectation(self):
        """Binned, the mean over many draws is the frame MixUp (each entry a sum of Bernoulli
        draws with mean w·x + (1 - w)·x'); checked with 5-sigma bounds per entry."""
        pair = make_streams(2, seed=10)
        copies = 400
        batch = _grid_batch([pair[0], pair[1]] * copies)
        partner = torch.arange(2 * copies) ^ 1  # 0 <-> 1, 2 <-> 3, ...
        weight = torch.tensor([0.3, 0.6]).repeat(copies)
        out = F.mixup(batch, partner, weight, seed=torch.arange(2 * copies) * 7919)
        mean = frames_of(out, torch.float64).view(copies, 2, T, 2, *SENSOR).mean(0)
        frames = frames_of(batch[:2], torch.float64)
        expected = F.mixup(frames, [1, 0], [0.3, 0.6]).to(torch.float64)
        w = torch.tensor([0.3, 0.6], dtype=torch.float64).view(2, 1, 1, 1, 1)
        variance = w * (1 - w) * (frames + frames.flip(0)) / copies
        assert bool(((mean - expected).abs() <= 5 * variance.sqrt() + 1e-12).all())
        assert float((mean - expected).abs().max()) > 0  # draws, not the blend itself

    def test_module_labels_replay_and_seed(self):
        batch = make_event_batch(6)
        force = torch.rand(6, T)
        module = et.MixUp(0.4)
        params = module.make_params(batch.frame_shape, generator=_g(3))
        assert params["seed"].dtype == torch.int64 and params["seed"].shape == (6,)
        out, mixed = module(batch, force, params=params)
        again, _ = module(batch, force, params=params)
        assert rows(out, 0) == rows(again, 0) and out.lengths == again.lengths
        assert torch.equal(mixed, module(frames_of(batch).float(), force, params=params)[1])
        with pytest.raises(ValueError, match="seed"):
            F.mixup(batch, torch.arange(6), 0.5, seed=-1)

    def test_a_sample_depends_only_on_itself_and_its_partner(self):
        batch = make_event_batch(5)
        partner, weight, seed = [3, 4, 0, 1, 2], [0.2, 0.4, 0.6, 0.8, 0.5], [1, 2, 3, 4, 5]
        whole = F.mixup(batch, partner, weight, seed=seed)
        for b in range(5):
            pair = batch.index_select(torch.tensor([b, partner[b]]))
            alone = F.mixup(pair, [1, 0], [weight[b], 0.5], seed=[seed[b], 0])
            assert rows(alone, 0) == rows(whole, b)

    def test_hard_cases(self):
        check_hard_cases(lambda: et.MixUp(0.4), coupled=True)


EVENT_BATTERY = {
    "Cutout": lambda: et.Cutout((3, 2)),
    "Cutout p": lambda: et.Cutout(4, p=0.5),
    "CutMix": lambda: et.CutMix(),
    "MixUp": lambda: et.MixUp(0.4),
    "MixUp p": lambda: et.MixUp(1.0, p=0.5),
}
