"""Compose (hybrid), OneOf (independent), RandomApply."""

from __future__ import annotations

import pytest
import torch
from torch import nn

import event_transforms as et

from tests.support.checkers import H, W, sparse_frames


def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


class TestCompose:
    def test_applies_in_order(self):
        frames = sparse_frames(3, 6, 2, H, W, density=0.3)
        out = et.Compose([et.FrameShift(-1), et.HorizontalFlip(), et.Rotate(20.0)])(frames)
        torch.testing.assert_close(out, et.Rotate(20.0)(et.FrameShift(-1)(frames).flip(-1)))

    def test_one_generator_for_all(self):
        frames = sparse_frames(3, 6, 2, H, W, density=0.3)
        pipeline = et.Compose([et.RandomTemporalEventShift((-2, 2), (0.2, 0.8)), et.RandomRotation(30.0)])
        assert torch.equal(pipeline(frames, generator=gen(4)), pipeline(frames, generator=gen(4)))
        assert not torch.equal(pipeline(frames, generator=gen(4)), pipeline(frames, generator=gen(5)))

    def test_accepts_plain_modules(self):
        frames = sparse_frames(2, 6, 2, H, W)
        assert torch.equal(et.Compose([nn.Identity(), et.FrameShift(0)])(frames), frames)

    def test_accepts_plain_callables(self):
        frames = sparse_frames(2, 6, 2, H, W)
        pipeline = et.Compose([lambda x: 2 * x, et.FrameShift(-1)])
        assert isinstance(pipeline.transforms[0], et.Lambda)
        assert torch.equal(pipeline(frames), et.FrameShift(-1)(2 * frames))
        assert pipeline.make_params(frames.shape)["0"] == {}

    def test_rejects_non_callables(self):
        with pytest.raises(TypeError, match=r"transforms\[1\] must be an EventTransform or a callable, got int"):
            et.Compose([et.FrameShift(1), 3])
        with pytest.raises(TypeError, match="transforms must be a sequence"):
            et.Compose(et.FrameShift(1))


class TestOneOf:
    def test_each_sample_gets_exactly_its_branch(self):
        frames = sparse_frames(40, 5, 2, H, W, density=0.3)
        one_of = et.OneOf([et.FrameShift(1), et.HorizontalFlip(), et.VerticalFlip()])
        params = one_of.make_params((40, 6, 2, 9, 11), generator=gen())
        out = one_of(frames, params=params)
        branches = [et.FrameShift(1)(frames), frames.flip(-1), frames.flip(-2)]
        for b in range(40):
            assert torch.equal(out[b], branches[int(params["index"][b])][b])
        assert set(params["index"].tolist()) == {0, 1, 2}

    def test_weights(self):
        one_of = et.OneOf([et.FrameShift(1), et.HorizontalFlip()], weights=[3.0, 1.0])
        index = one_of.make_params((4000, 6, 2, 9, 11), generator=gen())["index"]
        assert float(index.eq(0).double().mean()) == pytest.approx(0.75, abs=0.03)
        never = et.OneOf([et.FrameShift(1), et.HorizontalFlip()], weights=[0.0, 1.0])
        assert never.make_params((100, 6, 2, 9, 11), generator=gen())["index"].eq(1).all()

    def test_dtype_does_not_depend_on_the_draw(self):
        frames = sparse_frames(1, 5, 2, H, W, dtype=torch.int16)
        one_of = et.OneOf([et.Rotate(10.0), et.FrameShift(1)], weights=[1e-9, 1.0])
        for seed in range(5):
            assert one_of(frames, generator=gen(seed)).dtype == torch.float32

    def test_unused_branch_is_not_run(self):
        calls = []

        class Spy(nn.Module):
            def forward(self, x):
                calls.append(x.shape[0])
                return x

        frames = sparse_frames(8, 5, 2, H, W)
        et.OneOf([Spy(), et.FrameShift(1)], weights=[0.0, 1.0])(frames, generator=gen())
        assert calls == [0]  # called once, on an empty sub-batch (for the dtype), never on samples

    def test_bad_weights(self):
        with pytest.raises(ValueError, match="weights"):
            et.OneOf([et.FrameShift(1)], weights=[1.0, 2.0])
        with pytest.raises(ValueError, match="weights"):
            et.OneOf([et.FrameShift(1), et.HorizontalFlip()], weights=[0.0, 0.0])
        with pytest.raises(ValueError, match="weights"):
            et.OneOf([et.FrameShift(1), et.HorizontalFlip()], weights=[-1.0, 2.0])
        with pytest.raises(ValueError, match="at least one"):
            et.OneOf([])


class TestRandomApply:
    def test_probability_extremes(self):
        frames = sparse_frames(6, 5, 2, H, W, density=0.3)
        assert torch.equal(et.RandomApply(et.HorizontalFlip(), p=0.0)(frames), frames)
        assert torch.equal(et.RandomApply(et.HorizontalFlip(), p=1.0)(frames), frames.flip(-1))

    def test_per_sample_gate(self):
        frames = sparse_frames(50, 5, 2, H, W, density=0.3)
        gate = et.RandomApply(et.HorizontalFlip(), p=0.3)
        params = gate.make_params((50, 6, 2, 9, 11), generator=gen())
        out = gate(frames, params=params)
        for b in range(50):
            assert torch.equal(out[b], frames[b].flip(-1) if params["apply"][b] else frames[b])
        assert 5 < int(params["apply"].sum()) < 25

    def test_output_is_not_the_input_object(self):
        frames = sparse_frames(3, 5, 2, H, W)
        out = et.RandomApply(et.HorizontalFlip(), p=0.0)(frames)
        assert out.data_ptr() != frames.data_ptr()

    def test_bad_settings(self):
        with pytest.raises(ValueError, match="p must lie"):
            et.RandomApply(et.HorizontalFlip(), p=-0.1)
        with pytest.raises(TypeError, match="transform must be an EventTransform or a callable, got str"):
            et.RandomApply("flip")


def test_paper_independent_and_hybrid():
    """Independent: each copy one method; hybrid: both stacked (the paper's two combinations)."""
    frames = sparse_frames(16, 36, 2, 70, 75)
    resize = et.RandomResize(choices=(15 / 18, 15 / 12))
    shift = et.FrameShift(-1)
    independent = et.OneOf([resize, shift])(frames, generator=gen())
    hybrid = et.Compose([resize, shift])(frames, generator=gen())
    assert independent.shape == hybrid.shape == frames.shape
    # hybrid: the last frame is always vacated by the shift; independent only for shifted samples
    assert hybrid[:, -1].sum() == 0
    assert independent[:, -1].sum() > 0


# ----------------------------------------------------------------------------- coupled members


class TestCoupledMembers:
    """CutMix and MixUp in containers (issue 19, item 2): mixed labels, or a named refusal."""

    @pytest.fixture
    def batch(self):
        g = torch.Generator().manual_seed(0)
        return torch.poisson(torch.full((6, 5, 2, 9, 11), 0.5), generator=g), torch.rand(6, 5, generator=g)

    @pytest.mark.parametrize("make", [lambda: et.CutMix(), lambda: et.MixUp(0.4), lambda: et.CutMix(p=0.5)])
    def test_compose_mixes_the_labels_like_the_transform_alone(self, batch, make):
        frames, labels = batch
        mixing = make()
        pipeline = et.Compose([et.FrameShift(-1), mixing, et.RandomHorizontalFlip(0.5)])
        assert pipeline.couples_samples
        params = pipeline.make_params(frames.shape, generator=torch.Generator().manual_seed(3))
        out, mixed = pipeline(frames, labels, params=params)
        _, alone = mixing(et.FrameShift(-1)(frames), labels, params=params["1"])
        assert torch.equal(mixed, alone)
        assert not torch.equal(mixed, labels)  # never unmixed labels

    def test_compose_with_a_dict_uses_the_members_label_key(self, batch):
        frames, labels = batch
        pipeline = et.Compose([et.MixUp(0.4, label_key="force")])
        out = pipeline({"frames": frames, "force": labels}, generator=torch.Generator().manual_seed(0))
        assert not torch.equal(out["force"], labels)
        with pytest.raises(ValueError, match=r"coupled members must agree on label_key, got \['a', 'b'\]"):
            et.Compose([et.MixUp(label_key="a"), et.CutMix(label_key="b")])

    def test_integer_classes_come_back_soft_through_compose(self, batch):
        frames, _ = batch
        classes = torch.tensor([0, 1, 2, 1, 0, 2])
        _, soft = et.Compose([et.CutMix(num_classes=3)])(frames, classes, generator=torch.Generator().manual_seed(1))
        assert soft.shape == (6, 3)
        torch.testing.assert_close(soft.sum(1), torch.ones(6, dtype=soft.dtype))

    @pytest.mark.parametrize("mixing", [et.CutMix(), et.MixUp()], ids=["CutMix", "MixUp"])
    def test_one_of_and_random_apply_refuse_by_name(self, mixing):
        with pytest.raises(TypeError, match=rf"transforms\[0\] \({type(mixing).__name__}\) mixes samples of the batch"):
            et.OneOf([mixing, et.FrameShift(1)])
        with pytest.raises(TypeError, match=rf"transforms\[1\] \({type(mixing).__name__}\) mixes samples"):
            et.OneOf([et.RandomRotation(10.0), mixing])
        with pytest.raises(TypeError, match=rf"transform \({type(mixing).__name__}\) mixes samples of the batch"):
            et.RandomApply(mixing, p=0.5)
        with pytest.raises(TypeError, match=r"transform \(Compose\) mixes samples"):
            et.RandomApply(et.Compose([et.FrameShift(1), mixing]), p=0.5)
        with pytest.raises(TypeError, match=r"transforms\[0\] \(Compose\) mixes samples"):
            et.OneOf([et.Compose([mixing]), et.FrameShift(1)])

    def test_forward_is_never_overridden(self):
        from event_transforms.transforms.base import EventTransform

        for cls in (et.CutMix, et.MixUp, et.Compose, et.OneOf, et.RandomApply):
            assert cls.forward is EventTransform.forward

    def test_apply_labels_is_the_identity_by_default(self, batch):
        frames, labels = batch
        assert et.FrameShift(1).apply_labels(labels, {}) is labels
        assert not et.Compose([et.FrameShift(1)]).couples_samples
        out, same = et.Compose([et.FrameShift(1)])(frames, labels)
        assert same is labels


# --------------------------------------------------------------------------- batteries
# This topic's entries of the shared batteries (tests/library/test_battery.py on frames,
# tests/library/test_shape_battery.py for size-changing modules, tests/library/test_event_batch.py on events).

BATTERY = {
    "Compose": lambda t, h, w: et.Compose([et.FrameShift(-1), et.RandomRotation(10.0)]),
    "OneOf": lambda t, h, w: et.OneOf([et.RandomResize(choices=(0.83, 1.25)), et.FrameShift(-1)]),
    "RandomApply": lambda t, h, w: et.RandomApply(et.RandomFrameShift((-1, 1)), p=0.5),
}


def test_torch_module_apply_reaches_every_submodule():
    """``nn.Module.apply(fn)`` on a tree that holds transforms calls ``fn`` on each submodule:
    the transform hook is ``apply_transform``, so no transform class defines ``apply``."""
    seen: list[str] = []
    tree = nn.Sequential(
        et.Compose([et.RandomRotation(10.0), et.OneOf([et.RandomFrameShift([1]), et.AddPoissonNoise(5.0)])]),
        nn.Conv2d(2, 2, 3),
    )
    assert tree.apply(lambda m: seen.append(type(m).__name__)) is tree
    assert seen.count("RandomRotation") == 1 and seen.count("RandomFrameShift") == 1
    assert {"Compose", "OneOf", "AddPoissonNoise", "Conv2d", "Sequential"} <= set(seen)
    frames = torch.poisson(torch.full((2, 3, 2, 6, 6), 0.5))
    params = et.RandomRotation(10.0).make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    rotation = et.RandomRotation(10.0)
    assert torch.equal(rotation(frames, params=params), rotation(frames, params=params))  # the transform path is untouched


def test_no_library_transform_shadows_module_apply():
    """``apply`` is ``torch.nn.Module.apply`` on every public transform class."""
    classes = [getattr(et, name) for name in et.__all__]
    transforms = [c for c in classes if isinstance(c, type) and issubclass(c, et.EventTransform)]
    assert len(transforms) > 30
    for cls in transforms:
        assert cls.apply is nn.Module.apply, cls.__name__


def test_a_subclass_with_the_old_hook_name_is_refused_by_name():
    """A subclass that defines ``apply(inputs, params)`` (the hook's name up to 0.1) is refused
    when the class is defined, naming the hook to use; ``module.apply(fn)`` is torch's."""
    with pytest.raises(TypeError, match=r"Double defines apply: the hook is apply_transform\(inputs, params\)"):

        class Double(et.EventTransform):
            def apply(self, inputs, params):
                return 2 * inputs

    class Triple(et.EventTransform):
        def apply_transform(self, inputs, params):
            return 3 * inputs

    seen: list[str] = []
    module = Triple()
    assert module.apply(lambda m: seen.append(type(m).__name__)) is module and seen == ["Triple"]


def test_a_gated_coupled_transform_must_name_its_partners():
    """The gate gathers a coupled transform's kept samples with their partners, so a coupled
    subclass with p < 1 and no partner_key is refused by name (not run ungated)."""

    class Swap(et.EventTransform):
        couples_samples = True

        def apply_transform(self, inputs, params):
            return inputs.flip(0)

    frames = torch.ones(4, 2, 2, 3, 3)
    gate = {"apply": torch.tensor([True, False, True, False])}
    with pytest.raises(TypeError, match=r"Swap couples samples and has p=0.5 < 1, so it must name .* partner_key"):
        Swap(p=0.5)(frames, params=gate)
    assert torch.equal(Swap()(frames), frames.flip(0))

