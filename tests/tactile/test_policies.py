"""The policy rows: stretch, inferred, prior, everything build and run on a batch."""

from __future__ import annotations

import pytest
import torch

import event_transforms as et
from event_transforms.tactile.policies import POLICY_METHODS, other_camera_bank, policy_rows, prior_scene
from event_transforms.tactile.methods import parse_method
from event_transforms.tactile.benchmark_scenes import get_scene


def _batch():
    g = torch.Generator().manual_seed(0)
    frames = torch.poisson(torch.full((4, 36, 2, 70, 75), 0.05), generator=g)
    frames[:, 5:25, 0, 30:40, 10:65] += 2.0
    return frames, {"diameter_mm": torch.tensor([12.0, 18.0, 12.0, 18.0])}


@pytest.mark.parametrize("scene", ["paper", "timing", "paper-offset"])
@pytest.mark.parametrize("name", POLICY_METHODS)
def test_every_policy_method_builds_and_runs(scene, name):
    if name == "stretch" and get_scene(scene).target_size is None:
        with pytest.raises(ValueError, match="stretch"):
            parse_method(name, scene=scene)
        return
    method = parse_method(name, scene=scene)
    transform = method.build()
    frames, meta = _batch()
    before = frames.clone()
    out = transform(frames, metadata=meta, generator=torch.Generator().manual_seed(1))
    assert out.shape == frames.shape and torch.equal(frames, before)
    assert bool(out.isfinite().all()) and float(out.min()) >= 0
    assert method.copies == 1 and parse_method(f"{name}x3", scene=scene).copies == 3


def test_policy_contents():
    bank = torch.zeros(6, 2, 70, 75)
    prior = prior_scene("paper", bank)
    assert prior.effects == ("lag", "size", "orientation", "position", "noise")
    assert tuple(prior.lag_shifts) == (-3, -2, -1, 1, 2, 3) and prior.orientation_deg == 45.0
    assert prior_scene("timing", bank).effects == ("lag", "orientation", "position", "noise")  # no size gap
    everything = parse_method("everything", scene="paper").build()
    prior_policy = parse_method("prior", scene="paper").build()
    assert isinstance(everything, et.Compose) and len(everything.transforms) == 5
    assert isinstance(prior_policy, et.OneOf)
    # one thing differs, the combination: the same effects with the same settings
    assert [repr(t) for t in prior_policy.transforms] == [repr(t) for t in everything.transforms]
    assert isinstance(parse_method("stretch", scene="size-extrapolation").build(), et.StretchToTarget)
    assert policy_rows("control") == () and policy_rows("noise") == ("inferred", "prior", "everything")


def test_other_camera_is_not_the_deployment_camera():
    """The prior's bank comes from another camera: its hot pixels sit elsewhere."""
    from event_transforms.tactile.datasets import noise_bank

    scene = get_scene("noise")
    other = other_camera_bank(scene, 200).sum((0, 1))
    deployment = noise_bank(200, seed=1, config=scene.deploy.config).sum((0, 1))
    hot_other = set((other > other.mean() + 8 * other.std()).nonzero().flatten().tolist())
    hot_deploy = set((deployment > deployment.mean() + 8 * deployment.std()).nonzero().flatten().tolist())
    assert hot_other != hot_deploy


def test_inferred_uses_the_deployment_validation_frames():
    policy = parse_method("inferred", scene="timing").build()
    assert isinstance(policy, et.OneOf)
    (shift,) = policy.transforms
    assert isinstance(shift, et.RandomFrameShift) and shift.shifts == (2,)


def test_matched_is_every_gap_s_matched_augmentation():
    """``matched`` (issue 33): the scene's declared gaps, each with its matched augmentation and
    the physics' stretch for size, one per copy; refused where there is nothing to combine."""
    matched = parse_method("matched", scene="paper-offset").build()
    assert isinstance(matched, et.OneOf)
    lag, size = matched.transforms
    assert isinstance(lag, et.RandomFrameShift) and tuple(lag.shifts) == (-1,)
    assert isinstance(size, et.StretchToTarget) and size.target_size == 15.0
    membrane = parse_method("matched", scene="paper-membrane").build()
    assert tuple(membrane.transforms[0].shifts) == (1,)
    # a single gap: the one matched augmentation (the protocol runs it only where it combines)
    assert [type(t).__name__ for t in parse_method("matched", scene="timing").build().transforms] == [
        "RandomFrameShift"]
    assert parse_method("matched", scene="noise").needs_noise_bank
    with pytest.raises(ValueError, match="scene 'control' has none"):
        parse_method("matched", scene="control")
    frames, meta = _batch()
    before = frames.clone()
    out = matched(frames, metadata=meta, generator=torch.Generator().manual_seed(1))
    assert out.shape == frames.shape and torch.equal(frames, before)
