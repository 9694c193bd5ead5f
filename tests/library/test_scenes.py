"""Tests for ``event_transforms.scenes``: a scene builds transforms for its effects only."""

from __future__ import annotations

import itertools
import pickle

import numpy as np
import pytest
import torch

from event_transforms import (
    AddNoise,
    AddPoissonNoise,
    Compose,
    OneOf,
    RandomHorizontalFlip,
    RandomFrameShift,
    RandomRotation,
    RandomTemporalEventShift,
    RandomTranslate,
)
from event_transforms import functional as F
from event_transforms.data import AugmentedDataset
from event_transforms.scenes import ResizeToTarget, Scene, StretchToTarget, metadata_values

T, H, W = 5, 17, 11

EFFECT_FIELDS = {
    "lag": dict(lag_shifts=(-1,)),
    "size": dict(training_sizes=(12.0, 18.0), target_size=15.0),
    "orientation": dict(orientation_deg=(30.0, 30.0 + 1e-9)),
    "noise": dict(noise=torch.ones(8, 2, H, W)),
    "position": dict(contact_shift_px=(2, 3)),
}
EFFECT_TYPES = {
    "lag": RandomFrameShift,
    "size": StretchToTarget,
    "orientation": RandomRotation,
    "noise": AddNoise,
    "position": RandomTranslate,
}


def frames_batch(batch: int = 4, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    frames = torch.zeros(batch, T, 2, H, W)
    frames[:, :, :, 6:11, 3:8] = torch.randint(0, 4, (batch, T, 2, 5, 5), generator=g).float()
    return frames


def sizes(batch: int = 4) -> dict[str, torch.Tensor]:
    return {"diameter_mm": torch.tensor([12.0, 18.0] * (batch // 2))}


class TestSceneEffects:
    @pytest.mark.parametrize(
        "effects", [c for r in range(5) for c in itertools.combinations(EFFECT_FIELDS, r)]
    )
    def test_builds_a_transform_for_each_declared_effect_only(self, effects):
        fields = {k: v for e in effects for k, v in EFFECT_FIELDS[e].items()}
        scene = Scene(**fields)
        assert set(scene.effects) == set(effects)
        built = scene.transforms()
        assert sorted(type(t).__name__ for t in built) == sorted(EFFECT_TYPES[e].__name__ for e in effects)
        for combination in ("independent", "hybrid"):
            policy = scene.policy(combination)
            kinds = {type(t) for t in policy.transforms}
            for effect, kind in EFFECT_TYPES.items():
                assert (kind in kinds) == (effect in effects)

    @pytest.mark.parametrize(
        "fields",
        [
            dict(training_sizes=(15.0, 15.0), target_size=15.0),  # sizes do not differ
            dict(training_sizes=(12.0,)),  # no target
            dict(orientation_deg=0.0),
            dict(orientation_deg=(10.0, 10.0)),  # fixed, not varying
            dict(lag_shifts=(0,)),
            dict(noise=0.0),
        ],
    )
    def test_effects_that_do_not_vary_build_nothing(self, fields):
        scene = Scene(**fields)
        assert scene.effects == () and scene.transforms() == []
        frames = frames_batch()
        assert torch.equal(scene.policy()(frames), frames)  # the identity

    def test_noise_rate_and_tes(self):
        scene = Scene(lag_shifts=range(-2, 1), lag_fraction=(0.25, 0.75), noise=(0.1, 10.0))
        lag, noise = scene.transforms()
        assert isinstance(lag, RandomTemporalEventShift) and lag.shifts == (-2, -1)
        assert isinstance(noise, AddPoissonNoise) and noise.rate_hz == (0.1, 10.0)

    def test_hybrid_order_is_physical(self):
        scene = Scene(noise=1.0, orientation_deg=10.0, target_size=15.0, lag_shifts=(-1,))
        assert scene.effects == ("lag", "size", "orientation", "noise")
        policy = scene.policy("hybrid")
        assert isinstance(policy, Compose)
        assert [type(t).__name__ for t in policy.transforms] == [
            "RandomFrameShift", "StretchToTarget", "RandomRotation", "AddPoissonNoise"
        ]
        assert isinstance(scene.policy(), OneOf)

    @pytest.mark.parametrize(
        "fields, error",
        [
            (dict(target_size=0.0), ValueError),
            (dict(training_sizes=(12.0, -1.0)), ValueError),
            (dict(size_exponent=0.0), ValueError),
            (dict(noise="loud"), TypeError),
        ],
    )
    def test_bad_scene_raises(self, fields, error):
        with pytest.raises(error):
            Scene(**fields)

    def test_bad_combination_raises(self):
        scene = Scene(lag_shifts=(-1,), noise=1.0)
        with pytest.raises(ValueError, match="combination"):
            scene.policy("stacked")
        with pytest.raises(ValueError, match="weights"):
            scene.policy("hybrid", weights=[1, 1])


class TestResizeToTarget:
    def test_beta_per_sample_from_metadata(self):
        frames = frames_batch()
        out = ResizeToTarget(15.0)(frames, metadata=sizes())
        expected = F.resize(frames, torch.tensor([1.25, 15 / 18, 1.25, 15 / 18], dtype=torch.float64))
        torch.testing.assert_close(out, expected)

    def test_exponent(self):
        transform = ResizeToTarget(15.0, exponent=0.5)
        scales = transform.make_params((2, T, 2, H, W), metadata={"diameter_mm": [12.0, 18.0]})["scale"]
        torch.testing.assert_close(scales, torch.tensor([1.25, 15 / 18], dtype=torch.float64) ** 0.5)

    def test_single_sequence_with_number(self):
        frames = frames_batch(1)[0]
        out = ResizeToTarget(15.0)(frames, metadata={"diameter_mm": 12.0})
        torch.testing.assert_close(out, F.resize(frames, 1.25))

    def test_missing_or_bad_metadata_raises(self):
        transform = ResizeToTarget(15.0)
        with pytest.raises(ValueError, match="metadata"):
            transform(frames_batch())
        with pytest.raises(ValueError, match="diameter_mm"):
            transform(frames_batch(), metadata={"size": 12.0})
        with pytest.raises(ValueError, match="positive"):
            transform(frames_batch(2), metadata={"diameter_mm": [12.0, 0.0]})
        with pytest.raises(ValueError, match="metadata"):
            OneOf([transform])(frames_batch())  # the container passes metadata on: none given

    def test_metadata_forms(self):
        frames = frames_batch(2)
        expected = F.resize(frames, torch.tensor([1.25, 15 / 18], dtype=torch.float64))
        per_item = [{"diameter_mm": 12.0}, {"diameter_mm": 18.0}]  # a list of dicts
        torch.testing.assert_close(ResizeToTarget(15.0)(frames, metadata=per_item), expected)
        collated = {"diameter_mm": np.array([12.0, 18.0])}  # numpy values
        torch.testing.assert_close(ResizeToTarget(15.0)(frames, metadata=collated), expected)
        sample = {"frames": frames, "diameter_mm": torch.tensor([12.0, 18.0])}  # a dict input
        torch.testing.assert_close(ResizeToTarget(15.0)(sample)["frames"], expected)
        with pytest.raises(ValueError, match="each of the 2 samples"):
            metadata_values([{"diameter_mm": 12.0}], "diameter_mm", 2)

    def test_input_unchanged_and_pickles(self):
        frames = frames_batch()
        version = frames._version
        transform = ResizeToTarget(15.0, key="size", exponent=0.5)
        transform(frames, metadata={"size": torch.full((4,), 12.0)})
        assert frames._version == version
        clone = pickle.loads(pickle.dumps(transform))
        assert repr(clone) == repr(transform)


class TestScenePolicies:
    def _candidates(self, frames, meta):
        """Every deterministic effect of EFFECT_FIELDS applied alone, per sample."""
        beta = metadata_values(meta, "diameter_mm", frames.shape[0]).reciprocal() * 15.0
        return {
            "lag": F.frame_shift(frames, -1),
            "size": F.stretch(frames, beta.sqrt()),
            "orientation": F.rotate(frames, 30.0),
        }

    def test_independent_gives_each_sample_exactly_one_effect(self):
        scene = Scene(**EFFECT_FIELDS["lag"], **EFFECT_FIELDS["size"], **EFFECT_FIELDS["orientation"])
        frames, meta = frames_batch(8), sizes(8)
        out = scene.policy()(frames, metadata=meta, generator=torch.Generator().manual_seed(1))
        candidates = self._candidates(frames, meta)
        used = []
        for i in range(8):
            matches = [k for k, c in candidates.items() if torch.allclose(out[i], c[i], atol=1e-4)]
            assert len(matches) == 1
            used.extend(matches)
        assert len(set(used)) > 1

    def test_hybrid_stacks_in_order(self):
        scene = Scene(**EFFECT_FIELDS["lag"], **EFFECT_FIELDS["size"], **EFFECT_FIELDS["orientation"])
        frames, meta = frames_batch(), sizes()
        out = scene.policy("hybrid")(frames, metadata=meta)
        beta = metadata_values(meta, "diameter_mm", 4).reciprocal() * 15.0
        expected = F.rotate(F.stretch(F.frame_shift(frames, -1), beta.sqrt()), 30.0 + 1e-9)
        torch.testing.assert_close(out, expected)

    def test_noise_bank_is_added(self):
        scene = Scene(noise=torch.ones(8, 2, H, W))
        frames = frames_batch()
        assert torch.equal(scene.policy()(frames), frames + 1)

    def test_seeded_and_replayable(self):
        scene = Scene(lag_shifts=range(-2, 3), noise=(1.0, 5.0), **EFFECT_FIELDS["size"])
        policy, frames, meta = scene.policy(), frames_batch(), sizes()
        a = policy(frames, metadata=meta, generator=torch.Generator().manual_seed(3))
        b = policy(frames, metadata=meta, generator=torch.Generator().manual_seed(3))
        assert torch.equal(a, b)

    def test_batch_of_zero_and_single_sequence(self):
        policy = Scene(**EFFECT_FIELDS["size"], **EFFECT_FIELDS["lag"]).policy()
        empty = policy(torch.zeros(0, T, 2, H, W), metadata={"diameter_mm": torch.zeros(0) + 12})
        assert empty.shape == (0, T, 2, H, W)
        one = policy(frames_batch(1)[0], metadata={"diameter_mm": 12.0})
        assert one.shape == (T, 2, H, W)

    def test_pickles_and_repr(self):
        policy = Scene(**EFFECT_FIELDS["size"], **EFFECT_FIELDS["noise"]).policy()
        clone = pickle.loads(pickle.dumps(policy))
        assert isinstance(clone, OneOf) and repr(clone) == repr(policy)
        assert [type(t).__name__ for t in clone.transforms] == ["StretchToTarget", "AddNoise"]

    def test_policy_composes_with_other_transforms(self):
        # a user's pipeline around a scene policy: metadata reaches the policy's resize
        scene = Scene(**EFFECT_FIELDS["size"], **EFFECT_FIELDS["lag"])
        pipeline = Compose([scene.policy(), RandomHorizontalFlip(p=1.0)])
        frames, meta = frames_batch(), sizes()
        params = pipeline.make_params(frames.shape, metadata=meta, generator=torch.Generator().manual_seed(0))
        out = pipeline(frames, params=params)
        index = params["0"]["index"]
        beta = metadata_values(meta, "diameter_mm", 4).reciprocal() * 15.0
        for i in range(4):
            alone = F.frame_shift(frames[i], -1) if index[i] == 0 else F.stretch(frames[i], float(beta[i]) ** 0.5)
            torch.testing.assert_close(out[i], alone.flip(-1))

    def test_augmented_dataset_passes_metadata(self):
        frames = frames_batch(2)
        base = [(frames[i], torch.zeros(T), {"diameter_mm": d, "index": i}) for i, d in enumerate((12.0, 18.0))]
        data = AugmentedDataset(base, Scene(**EFFECT_FIELDS["size"]).policy(), copies=1)
        for i, beta in ((2, 1.25), (3, 15 / 18)):
            torch.testing.assert_close(data[i][0], F.stretch(frames[i - 2], beta**0.5))
            assert data[i][2] == base[i - 2][2]


def test_contact_shift_declares_a_translation():
    scene = Scene(contact_shift_px=(2, 3), orientation_deg=10.0, noise=1.0)
    assert scene.effects == ("orientation", "position", "noise")
    (translate,) = [t for t in scene.transforms() if isinstance(t, RandomTranslate)]
    assert translate.max_shift == (2, 3)
    assert Scene(contact_shift_px=0).effects == ()
    with pytest.raises(ValueError, match="contact_shift_px"):
        Scene(contact_shift_px=-1)


class TestSceneSettingsAtConstruction:
    """Each setting is checked when the Scene is built, under its own name (issue 27)."""

    @pytest.mark.parametrize("kwargs, error, match", [
        ({"lag_shifts": [0.5]}, ValueError, r"lag_shifts must hold whole frames \(integers\), got \[0.5\]"),
        ({"lag_shifts": [True]}, ValueError, "lag_shifts"),
        ({"lag_shifts": 3}, TypeError, "lag_shifts must be a sequence"),
        ({"noise": float("nan")}, ValueError, "noise must be finite"),
        ({"noise": -1.0}, ValueError, r"noise must lie in \[0.0, inf\]"),
        ({"noise": (5.0, 1.0)}, ValueError, "noise must be .min, max. with min <= max"),
        ({"noise": torch.zeros(3, 4, 4)}, ValueError, r"noise frames must be \(N, 2, H, W\)"),
        ({"lag_shifts": [1], "lag_fraction": 1.5}, ValueError, r"lag_fraction must lie in \[0.0, 1.0\]"),
        ({"lag_shifts": [1], "lag_fraction": float("nan")}, ValueError, "lag_fraction must be finite"),
        ({"orientation_deg": float("inf")}, ValueError, "orientation_deg must be finite"),
        ({"orientation_deg": (1.0, 2.0, 3.0)}, TypeError, "orientation_deg must be a number or a"),
    ])
    def test_bad_settings(self, kwargs, error, match):
        with pytest.raises(error, match=match):
            Scene(**kwargs)

    def test_good_settings_still_build(self):
        scene = Scene(lag_shifts=range(-2, 1), lag_fraction=(0.2, 0.8), orientation_deg=10, noise=(0.0, 5.0))
        assert scene.effects == ("lag", "orientation", "noise")
