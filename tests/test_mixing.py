"""Mixing: Cutout, CutMix, MixUp and label mixing against slow references, plus the battery
for the cross-sample modules (the shared battery's per-sample checks do not apply to them:
a sample's output depends on its partner)."""

from __future__ import annotations

import pickle

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import event_transforms as et
from event_transforms import functional as F

from .checkers import H, W, check_not_modified, count_shapes, random_counts, sparse_frames

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
            module([[0.0, 1.0]])  # numpy frames are converted (tests/test_ingestion.py), other types refused
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
# This topic's entries of the shared batteries (tests/test_battery.py on frames,
# tests/test_shape_battery.py for size-changing modules, tests/test_event_batch.py on events).

BATTERY = {
    "Cutout": lambda t, h, w: et.Cutout((3, 2)),
    "CutMix": lambda t, h, w: et.CutMix(),
    "MixUp": lambda t, h, w: et.MixUp(0.4),
}
