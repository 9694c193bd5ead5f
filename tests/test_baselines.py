"""Tests for the trivial force baselines."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from event_transforms.tactile.baselines import (
    CumulativeCountRidge,
    GlobalMean,
    PerFrameMean,
    count_features,
    evaluate_baselines,
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


class TestEvaluate:
    def test_scores_and_dataset_input(self):
        frames, force = counts(n=12), torch.rand(12, T) * 20
        items = [(frames[i], force[i], {"i": i}) for i in range(8, 12)]
        scores = evaluate_baselines((frames[:6], force[:6]), (frames[6:8], force[6:8]), items)
        assert set(scores) == {"global-mean", "per-frame-mean", "cumulative-count-ridge"}
        want = float((PerFrameMean().fit(frames[:6], force[:6]).predict(frames[8:]) - force[8:].double()).square().mean())
        assert scores["per-frame-mean"]["test_mse"] == pytest.approx(want)
        assert all(set(s) == {"val_mse", "test_mse"} for s in scores.values())

    def test_stack_items_rejects(self):
        with pytest.raises(TypeError, match="got int"):
            stack_items(3)
        with pytest.raises(ValueError, match="empty dataset"):
            stack_items([])
