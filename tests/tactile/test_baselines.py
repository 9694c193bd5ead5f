"""Tests for the trivial force baselines."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from event_transforms.tactile.baselines import (
    CumulativeCountRidge,
    GlobalMean,
    PerFrameMean,
    PhysicsLeastSquares,
    count_features,
    evaluate_baselines,
    physics_features,
    stack_items,
)

N, T, H, W = 7, 6, 5, 3


def counts(n=N, steps=T, rate=1.5, seed=0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    return torch.poisson(torch.full((n, steps, 2, H, W), rate), generator=g).to(dtype)


def reference_features(frames):
    """Loops over sequences, frames and polarities."""
    out = np.zeros((frames.shape[0], frames.shape[1], 4))
    for n in range(frames.shape[0]):
        running = [0.0, 0.0]
        for t in range(frames.shape[1]):
            for p in range(2):
                total = float(frames[n, t, p].double().sum())
                running[p] += total
                out[n, t, p] = running[p]
                out[n, t, 2 + p] = total
    return out


def reference_ridge(frames, force, alpha):
    """Augmented least squares: rows sqrt(alpha) * e_k append the penalty on features only."""
    feats = reference_features(frames).reshape(-1, 4)
    mean, std = feats.mean(0), feats.std(0)
    std[std == 0] = 1
    z = (feats - mean) / std
    steps = frames.shape[1]
    onehot = np.tile(np.eye(steps), (frames.shape[0], 1))
    design = np.hstack([z, onehot])
    penalty = np.hstack([np.sqrt(alpha) * np.eye(4), np.zeros((4, steps))])
    a = np.vstack([design, penalty])
    b = np.concatenate([force.double().numpy().reshape(-1), np.zeros(4)])
    coef, *_ = np.linalg.lstsq(a, b, rcond=None)
    return coef, (mean, std)


class TestCountFeatures:
    @pytest.mark.parametrize("dtype", [torch.uint8, torch.int32, torch.float16, torch.float64])
    def test_matches_loop(self, dtype):
        frames = counts(dtype=dtype)
        got = count_features(frames)
        assert got.dtype == torch.float64
        np.testing.assert_allclose(got.numpy(), reference_features(frames))

    def test_rejects_shape(self):
        with pytest.raises(ValueError, match=r"frames: expected \(N, T, 2, H, W\), got \(2, 3, 3, 4, 4\)"):
            count_features(torch.zeros(2, 3, 3, 4, 4))


class TestMeans:
    def test_global_mean(self):
        frames, force = counts(), torch.rand(N, T)
        pred = GlobalMean().fit(frames, force).predict(counts(3))
        assert pred.shape == (3, T) and pred.dtype == torch.float64
        torch.testing.assert_close(pred, torch.full((3, T), float(force.double().mean()), dtype=torch.float64))

    def test_per_frame_mean(self):
        frames, force = counts(), torch.rand(N, T)
        pred = PerFrameMean().fit(frames, force).predict(counts(2))
        for t in range(T):
            assert pred[0, t] == pytest.approx(sum(float(force[n, t]) for n in range(N)) / N)
        torch.testing.assert_close(pred[0], pred[1])

    def test_per_frame_mean_rejects_other_length(self):
        model = PerFrameMean().fit(counts(), torch.rand(N, T))
        with pytest.raises(ValueError, match=f"fitted on T = {T} frames per sequence, got T = 4"):
            model.predict(counts(steps=4))

    def test_predict_before_fit(self):
        with pytest.raises(RuntimeError, match="before fit"):
            GlobalMean().predict(counts())

    def test_force_shape_named(self):
        with pytest.raises(ValueError, match=r"force: expected \(N, T\) = \(7, 6\).*got \(7, 5\)"):
            GlobalMean().fit(counts(), torch.rand(N, 5))
        with pytest.raises(TypeError, match="force must be a torch.Tensor, got list"):
            GlobalMean().fit(counts(), [1.0])


class TestCumulativeCountRidge:
    @pytest.mark.parametrize("alpha", [0.0, 0.3, 5.0])
    def test_matches_lstsq_reference(self, alpha):
        frames = counts(n=9)
        force = torch.randn(9, T, generator=torch.Generator().manual_seed(1)) * 3 + 10
        model = CumulativeCountRidge(alpha=alpha).fit(frames, force)
        coef, (mean, std) = reference_ridge(frames, force, alpha)
        np.testing.assert_allclose(model.coef_.numpy(), coef, rtol=1e-7, atol=1e-8)
        np.testing.assert_allclose(model.feature_mean_.numpy(), mean)
        np.testing.assert_allclose(model.feature_std_.numpy(), std)
        test = counts(n=4, seed=5)
        want = ((reference_features(test).reshape(-1, 4) - mean) / std) @ coef[:4] + np.tile(coef[4:], 4)
        np.testing.assert_allclose(model.predict(test).numpy().reshape(-1), want, rtol=1e-9, atol=1e-9)

    def test_recovers_exactly_linear_force(self):
        frames = counts(n=12, rate=3.0)
        feats = count_features(frames)
        intercepts = torch.linspace(-2, 5, T, dtype=torch.float64)
        force = 0.05 * feats[..., 0] - 0.02 * feats[..., 1] + 0.1 * feats[..., 3] + intercepts
        model = CumulativeCountRidge(alpha=0.0).fit(frames, force)
        test = counts(n=5, rate=3.0, seed=9)
        tf = count_features(test)
        want = 0.05 * tf[..., 0] - 0.02 * tf[..., 1] + 0.1 * tf[..., 3] + intercepts
        torch.testing.assert_close(model.predict(test), want, atol=1e-6, rtol=0)
        # unstandardised weights = w / std
        raw = model.coef_[:4] / model.feature_std_
        torch.testing.assert_close(raw, torch.tensor([0.05, -0.02, 0.0, 0.1], dtype=torch.float64), atol=1e-9, rtol=0)

    def test_default_alpha_is_one(self):
        model = CumulativeCountRidge().fit(counts(), torch.rand(N, T))
        assert model.alpha_ == 1.0

    def test_alpha_from_validation_grid(self):
        frames = counts(n=10)
        feats = count_features(frames)
        noise = torch.randn(10, T, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
        force = 0.1 * feats[..., 0] + noise
        val_frames = counts(n=10, seed=4)
        val_force = 0.1 * count_features(val_frames)[..., 0]
        grid = (0.001, 1.0, 1e6)
        model = CumulativeCountRidge(alphas=grid).fit(frames, force, val=(val_frames, val_force))
        assert set(model.validation_mse_) == set(grid)
        assert model.alpha_ == min(grid, key=model.validation_mse_.__getitem__)
        assert model.alpha_ != 1e6  # shrinking the real signal away must lose
        explicit = CumulativeCountRidge(alpha=1e6).fit(frames, force, val=(val_frames, val_force))
        assert explicit.alpha_ == 1e6

    def test_rejects_bad_alpha(self):
        with pytest.raises(ValueError, match="alpha must be a finite number >= 0, got -1"):
            CumulativeCountRidge(alpha=-1)
        with pytest.raises(ValueError, match="alphas must be a non-empty"):
            CumulativeCountRidge(alphas=())

    def test_input_dtype_does_not_matter(self):
        frames, force = counts(), torch.rand(N, T)
        a = CumulativeCountRidge().fit(frames, force).predict(frames)
        b = CumulativeCountRidge().fit(frames.to(torch.int16), force.double()).predict(frames.to(torch.uint8))
        torch.testing.assert_close(a, b)


def reference_physics_features(frames, diameters=None):
    """Loops over sequences and frames: d, d², OFF, ON (and d / D, d² / D)."""
    width = 4 if diameters is None else 6
    out = np.zeros((frames.shape[0], frames.shape[1], width))
    for n in range(frames.shape[0]):
        signed = 0.0
        for t in range(frames.shape[1]):
            off, on = (float(frames[n, t, p].double().sum()) for p in range(2))
            signed += off - on
            row = [signed, signed**2, off, on]
            if diameters is not None:
                row += [signed / float(diameters[n]), signed**2 / float(diameters[n])]
            out[n, t] = row
    return out


def reference_physics_fit(frames, force, diameters=None):
    """numpy least squares on raw features and one-hot frame indices; returns predict(frames, diameters)."""
    feats = reference_physics_features(frames, diameters)
    k, steps = feats.shape[-1], frames.shape[1]

    def design(f):
        return np.hstack([f.reshape(-1, k), np.tile(np.eye(steps), (f.shape[0], 1))])

    coef, *_ = np.linalg.lstsq(design(feats), force.double().numpy().reshape(-1), rcond=None)
    return lambda x, d=None: (design(reference_physics_features(x, d)) @ coef).reshape(x.shape[0], steps)


class TestPhysicsLeastSquares:
    @pytest.mark.parametrize("dtype", [torch.float32, torch.int16])
    def test_features_match_loop(self, dtype):
        frames = counts(dtype=dtype)
        frames[0, :, 1] *= 3  # more ON than OFF: a negative running total
        np.testing.assert_allclose(physics_features(frames).numpy(), reference_physics_features(frames))
        sizes = torch.linspace(10, 20, N)
        np.testing.assert_allclose(physics_features(frames, sizes).numpy(), reference_physics_features(frames, sizes))
        assert bool((physics_features(frames)[0, -1, 0] < 0))

    @pytest.mark.parametrize("size_aware", [False, True])
    def test_matches_numpy_lstsq(self, size_aware):
        frames = counts(n=20, rate=2.0)
        sizes = torch.linspace(12, 18, 20) if size_aware else None
        force = torch.rand(20, T, generator=torch.Generator().manual_seed(1), dtype=torch.float64) * 20
        model = PhysicsLeastSquares(size_aware=size_aware).fit(frames, force, diameters=sizes)
        reference = reference_physics_fit(frames, force, sizes)
        test = counts(n=4, rate=2.0, seed=5)
        test_sizes = torch.tensor([12.0, 15.0, 18.0, 13.0]) if size_aware else None
        np.testing.assert_allclose(model.predict(test, diameters=test_sizes).numpy(), reference(test, test_sizes),
                                   rtol=1e-7, atol=1e-7)
        assert model.coef_.numel() == T + (6 if size_aware else 4)
        assert model.name == ("physics least-squares + size" if size_aware else "physics least-squares")

    def test_recovers_exact_physics_and_beats_the_ridge_on_it(self):
        frames = counts(n=12, rate=3.0)
        frames[:, :, 0] += counts(n=12, rate=1.0, seed=3)[:, :, 0]  # net OFF: a growing indentation
        d = physics_features(frames)[..., 0]
        profile = torch.linspace(0, 2, T, dtype=torch.float64)
        force = profile + 0.02 * d + 1e-4 * d**2
        model = PhysicsLeastSquares().fit(frames, force)
        torch.testing.assert_close(model.predict(frames), force, atol=1e-8, rtol=0)
        ridge = CumulativeCountRidge(alpha=0.0).fit(frames, force)
        assert float((ridge.predict(frames) - force).square().mean()) > 1e-6  # no square term

    def test_invariants(self):
        """Permuting sequences, scaling the force, or shifting it per frame index move the fit along."""
        frames = counts(n=10, rate=2.0)
        force = torch.rand(10, T, generator=torch.Generator().manual_seed(2), dtype=torch.float64) * 10
        base = PhysicsLeastSquares().fit(frames, force).predict(frames)
        order = torch.randperm(10, generator=torch.Generator().manual_seed(0))
        torch.testing.assert_close(PhysicsLeastSquares().fit(frames[order], force[order]).predict(frames), base)
        torch.testing.assert_close(PhysicsLeastSquares().fit(frames, 3 * force).predict(frames), 3 * base)
        shift = torch.linspace(-1, 1, T, dtype=torch.float64)
        torch.testing.assert_close(PhysicsLeastSquares().fit(frames, force + shift).predict(frames), base + shift)
        # the fit never worsens when the force is what the features explain plus zero
        assert float((base - force).square().mean()) <= float((force - force.mean(0)).square().mean()) + 1e-12

    def test_one_frame_and_empty_input(self):
        frames, force = counts(n=5, steps=1), torch.rand(5, 1)
        model = PhysicsLeastSquares().fit(frames, force)
        assert model.predict(frames).shape == (5, 1)
        assert model.predict(frames[:0]).shape == (0, 1)
        with pytest.raises(ValueError, match="need at least one sequence, got N = 0"):
            PhysicsLeastSquares().fit(frames[:0], force[:0])

    def test_errors_name_argument(self):
        frames, force = counts(), torch.rand(N, T)
        with pytest.raises(TypeError, match="size_aware must be a bool, got 1"):
            PhysicsLeastSquares(size_aware=1)
        with pytest.raises(ValueError, match="needs the bolt diameters, got None"):
            PhysicsLeastSquares(size_aware=True).fit(frames, force)
        with pytest.raises(ValueError, match=r"diameters: expected \(N,\) = \(7,\), got \(3,\)"):
            PhysicsLeastSquares(size_aware=True).fit(frames, force, diameters=[1.0, 2.0, 3.0])
        with pytest.raises(ValueError, match="diameters must be finite and positive"):
            PhysicsLeastSquares(size_aware=True).fit(frames, force, diameters=[0.0] * N)
        with pytest.raises(ValueError, match="pass size_aware=True"):
            PhysicsLeastSquares().fit(frames, force, diameters=[1.0] * N)
        with pytest.raises(RuntimeError, match="before fit"):
            PhysicsLeastSquares().predict(frames)
        model = PhysicsLeastSquares().fit(frames, force)
        with pytest.raises(ValueError, match="fitted on T = 6 frames per sequence, got T = 3"):
            model.predict(frames[:, :3])
        with pytest.raises(ValueError, match="needs bolt diameters"):
            evaluate_baselines((frames, force), (frames, force), (frames, force),
                               baselines=[PhysicsLeastSquares(size_aware=True)])

    def test_inputs_unchanged(self):
        frames, force = counts(), torch.rand(N, T)
        before = (frames.clone(), force.clone(), frames._version, force._version)
        PhysicsLeastSquares().fit(frames, force).predict(frames)
        assert torch.equal(frames, before[0]) and torch.equal(force, before[1])
        assert (frames._version, force._version) == before[2:]


class TestEvaluate:
    def test_scores_and_dataset_input(self):
        frames, force = counts(n=12), torch.rand(12, T) * 20
        items = [(frames[i], force[i], {"i": i}) for i in range(8, 12)]
        scores = evaluate_baselines((frames[:6], force[:6]), (frames[6:8], force[6:8]), items)
        assert set(scores) == {"global-mean", "per-frame-mean", "cumulative-count-ridge", "physics least-squares"}
        want = float((PerFrameMean().fit(frames[:6], force[:6]).predict(frames[8:]) - force[8:].double()).square().mean())
        assert scores["per-frame-mean"]["test_mse"] == pytest.approx(want)
        assert all(set(s) == {"val_mse", "test_mse"} for s in scores.values())

    def test_stack_items_rejects(self):
        with pytest.raises(TypeError, match="got int"):
            stack_items(3)
        with pytest.raises(ValueError, match="empty dataset"):
            stack_items([])
