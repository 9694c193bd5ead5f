"""Tests for the lockstep ensemble of force regressors and its trainer."""

from __future__ import annotations

import pickle

import pytest
import torch
from torch.utils.data import Dataset, TensorDataset

from event_transforms.tactile.ensemble import EnsembleForceRegressor
from event_transforms.tactile.models import ForceRegressor
from event_transforms.tactile.stopwatch import Stopwatch
from event_transforms.tactile.training import clip_grad_norm_per_member_, fit_ensemble, shuffled_batches

pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest.py

T, H, W = 5, 9, 7


def counts(*shape, rate=0.7, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.poisson(torch.full(shape, rate), generator=g)


def seeded_models(seeds, dtype=torch.float32, **kwargs):
    kwargs.setdefault("hidden_channels", (3, 2))
    kwargs.setdefault("input_pool", 2)
    models = []
    for seed in seeds:
        torch.manual_seed(seed)
        models.append(ForceRegressor(**kwargs).to(dtype))
    return models


def dataset(n, seed):
    x = counts(n, T, 2, H, W, seed=seed)
    force = x[:, :, 0].sum((-2, -1)).cumsum(1) / 30 - x[:, :, 1].sum((-2, -1)) / 20
    return TensorDataset(x, force)


#: ForceRegressor options the ensemble must mirror (the defaults, each switch, the earlier model).
OPTIONS = [
    {},
    {"recurrent_activation": "hard_sigmoid"},
    {"kernel_size": 1},  # a batched matrix product, not a convolution
    {"kernel_size": (1, 3)},
    {"readout": "mean+max"},
    {"global_inputs": False},
    {"features": "log1p"},
    {"features": "linear"},
    {"features": "signed"},
    {"cumulative": False},
    {"cumulative": False, "features": "log1p", "readout": "mean+max", "global_inputs": False},
]


class TestForward:
    @pytest.mark.parametrize("options", OPTIONS)
    def test_members_match_single_models(self, options):
        models = seeded_models([0, 1, 2], torch.float64, **options)
        ensemble = EnsembleForceRegressor.from_models(models)
        frames = counts(3, 2, T, 2, H, W)
        out = ensemble(frames)
        assert out.shape == (3, 2, T) and out.dtype == torch.float64
        for m, model in enumerate(models):
            torch.testing.assert_close(out[m], model(frames[m]), rtol=1e-10, atol=1e-10)
        torch.testing.assert_close(ensemble(ensemble.pool(frames), pooled=True), out, rtol=0, atol=0)

    def test_one_frame_and_empty_batch(self):
        models = seeded_models([0, 1], torch.float64)
        ensemble = EnsembleForceRegressor.from_models(models)
        frames = counts(2, 3, 1, 2, H, W)
        for m, model in enumerate(models):
            torch.testing.assert_close(ensemble(frames)[m], model(frames[m]), rtol=1e-10, atol=1e-10)
        assert ensemble(counts(2, 0, T, 2, H, W)).shape == (2, 0, T)
        assert ensemble(counts(0, T, 2, H, W)).shape == (2, 0, T)

    def test_pool_checks_and_keeps_input(self):
        ensemble = EnsembleForceRegressor(2, hidden_channels=(2,), input_pool=2)
        frames = counts(2, 3, T, 2, H, W).to(torch.int16)
        before, version = frames.clone(), frames._version
        pooled = ensemble.pool(frames)
        assert pooled.shape == (2, 3, T, 2, H // 2, W // 2) and pooled.dtype == torch.float32
        assert torch.equal(frames, before) and frames._version == version
        with pytest.raises(ValueError, match=r"expected \(2, B, T, 2, H, W\) or \(B, T, 2, H, W\), got \(3, 2, 9, 7\)"):
            ensemble.pool(counts(3, 2, H, W))

    @pytest.mark.parametrize("options", [{}, {"kernel_size": 1}, {"features": "log1p", "readout": "mean+max"}])
    def test_shared_batch_broadcasts(self, options):
        models = seeded_models([3, 4], **options)
        ensemble = EnsembleForceRegressor.from_models(models)
        frames = counts(4, T, 2, H, W).to(torch.uint8)
        out = ensemble(frames)
        assert out.shape == (2, 4, T) and out.dtype == torch.float32
        per_member = ensemble(frames.expand(2, *frames.shape))
        torch.testing.assert_close(out, per_member, rtol=1e-5, atol=1e-5)
        for m, model in enumerate(models):
            torch.testing.assert_close(out[m], model(frames), rtol=1e-5, atol=1e-5)

    def test_member_round_trip(self):
        models = seeded_models([0, 1])
        models[1].set_force_scaling(3.0, 2.5)
        ensemble = EnsembleForceRegressor.from_models(models)
        for m, model in enumerate(models):
            copy = ensemble.member(m)
            assert copy.config == model.config
            for (name, a), (_, b) in zip(copy.state_dict().items(), model.state_dict().items()):
                assert torch.equal(a, b), name
        assert ensemble.member(-1).force_scale == 2.5

    def test_members_are_independent(self):
        ensemble = EnsembleForceRegressor(3, hidden_channels=(2,), input_pool=2)
        frames = counts(3, 1, T, 2, H, W).requires_grad_()
        ensemble(frames)[1].sum().backward()
        assert frames.grad[0].abs().sum() == 0 and frames.grad[2].abs().sum() == 0
        assert frames.grad[1].abs().sum() > 0
        for p in ensemble.parameters():
            assert p.grad[0].abs().sum() == 0 and p.grad[2].abs().sum() == 0

    def test_init_draws_like_consecutive_models(self):
        torch.manual_seed(7)
        ensemble = EnsembleForceRegressor(2, hidden_channels=(3,), input_pool=2)
        torch.manual_seed(7)
        first, second = ForceRegressor(hidden_channels=(3,), input_pool=2), ForceRegressor(hidden_channels=(3,), input_pool=2)
        assert torch.equal(ensemble.member(0).head.weight, first.head.weight)
        assert torch.equal(ensemble.member(1).lstm.cells[0].input_conv.weight, second.lstm.cells[0].input_conv.weight)

    def test_set_force_scaling(self):
        ensemble = EnsembleForceRegressor(2, hidden_channels=(2,), input_pool=2)
        frames = counts(1, T, 2, H, W)
        raw = ensemble(frames)
        ensemble.set_force_scaling([1.0, -2.0], [2.0, 3.0])
        scaled = ensemble(frames)
        torch.testing.assert_close(scaled[0], 1.0 + 2.0 * raw[0])
        torch.testing.assert_close(scaled[1], -2.0 + 3.0 * raw[1])
        ensemble.set_force_scaling(5.0, 1.0)
        assert ensemble.force_offset.tolist() == [5.0, 5.0]
        with pytest.raises(ValueError, match="scales must be positive"):
            ensemble.set_force_scaling(0.0, [1.0, 0.0])
        with pytest.raises(ValueError, match=r"offsets must be one finite number or 2, got \[1.0, 2.0, 3.0\]"):
            ensemble.set_force_scaling([1.0, 2.0, 3.0], 1.0)

    def test_errors_name_argument_and_value(self):
        ensemble = EnsembleForceRegressor(2, hidden_channels=(2,), input_pool=2)
        with pytest.raises(ValueError, match=r"frames: expected \(2, B, T, 2, H, W\) or \(B, T, 2, H, W\), got \(3, 1, 5, 2, 9, 7\)"):
            ensemble(counts(3, 1, T, 2, H, W))
        with pytest.raises(ValueError, match="smaller than input_pool=2"):
            ensemble(counts(1, T, 2, 1, W))
        with pytest.raises(ValueError, match="models\\[1\\] has configuration"):
            EnsembleForceRegressor.from_models(seeded_models([0]) + seeded_models([1], input_pool=3))
        with pytest.raises(IndexError, match=r"index must be an int in \[0, 2\), got 2"):
            ensemble.member(2)
        with pytest.raises(ValueError, match="members must be a positive int, got 0"):
            EnsembleForceRegressor(0)

    def test_pickle_and_state_dict(self):
        ensemble = EnsembleForceRegressor(2, hidden_channels=(2, 2), input_pool=2)
        clone = pickle.loads(pickle.dumps(ensemble))
        frames = counts(1, T, 2, H, W)
        torch.testing.assert_close(clone(frames), ensemble(frames))
        other = EnsembleForceRegressor(2, hidden_channels=(2, 2), input_pool=2)
        other.load_state_dict(ensemble.state_dict())
        torch.testing.assert_close(other(frames), ensemble(frames))


class TestHelpers:
    def test_clip_matches_torch_per_member(self):
        models = seeded_models([0, 1, 2])
        ensemble = EnsembleForceRegressor.from_models(models)
        frames = counts(3, 2, T, 2, H, W, rate=3.0)
        ensemble(frames).square().sum().backward()
        norms = clip_grad_norm_per_member_(list(ensemble.parameters()), 0.05)
        for m, model in enumerate(models):
            model(frames[m]).square().sum().backward()
            want = torch.nn.utils.clip_grad_norm_(model.parameters(), 0.05)
            torch.testing.assert_close(norms[m], want, rtol=1e-4, atol=1e-6)
        copy_grads = {name: p.grad for name, p in ensemble.named_parameters()}
        for m, model in enumerate(models):
            torch.testing.assert_close(copy_grads["cells.0.input_weight"][m], model.lstm.cells[0].input_conv.weight.grad, rtol=1e-4, atol=1e-7)
            torch.testing.assert_close(copy_grads["head_bias"][m], model.head.bias.grad[0], rtol=1e-4, atol=1e-7)

    def test_shuffled_batches_are_passes(self):
        batches = shuffled_batches(7, 3, 10, seed=4)
        flat = batches.flatten().tolist()
        for p in range(4):
            assert sorted(flat[7 * p : 7 * p + 7]) == list(range(7))
        assert torch.equal(batches, shuffled_batches(7, 3, 10, seed=4))
        assert not torch.equal(batches, shuffled_batches(7, 3, 10, seed=5))
        # the first pass is the permutation a generator seeded alike draws
        assert flat[:7] == torch.randperm(7, generator=torch.Generator().manual_seed(4)).tolist()


def reference_run(model, data, *, steps, batch_size, seed, lr_max, clip, val):
    """A plain single-model loop: the same batches, Adam, one-cycle, clip_grad_norm_."""
    optimiser = torch.optim.Adam(model.parameters(), lr=lr_max)
    scheduler = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=lr_max, total_steps=steps)
    losses = []
    for indices in shuffled_batches(len(data), batch_size, steps, seed=seed):
        frames, force = data[indices]
        loss = torch.nn.functional.mse_loss(model(frames), force.to(model.head.weight.dtype))
        optimiser.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), clip)
        optimiser.step()
        scheduler.step()
        losses.append(float(loss.detach()))
    with torch.no_grad():
        val_loss = float((model(val[0]).double() - val[1].double()).square().mean())
    return losses, val_loss


class TestFitEnsemble:
    def test_member_matches_single_model_run(self):
        seeds = [0, 1, 2]
        sets = [dataset(6, 10), dataset(11, 11), dataset(6, 12)]  # sizes differ: same steps
        val = dataset(4, 13)
        options = dict(steps=5, batch_size=3, lr_max=5e-2, clip=0.5)
        ensemble = EnsembleForceRegressor.from_models(seeded_models(seeds, torch.float64))
        result = fit_ensemble(ensemble, sets, val, seeds=seeds, eval_every=5, progress=False, **options)
        val_pair = val.tensors
        for m, seed in enumerate(seeds):
            model = seeded_models([seed], torch.float64)[0]
            sets_m = TensorDataset(sets[m].tensors[0], sets[m].tensors[1].double())
            losses, val_loss = reference_run(model, sets_m, seed=seed, val=val_pair, **options)
            record = result.members[m]
            assert record.steps == 5 and len(record.train_loss) == 5
            assert record.train_loss == pytest.approx(losses, rel=1e-8)
            assert record.val_loss[-1] == pytest.approx(val_loss, rel=1e-8)
            member = ensemble.member(m)
            for (name, a), (_, b) in zip(member.state_dict().items(), model.state_dict().items()):
                torch.testing.assert_close(a, b, rtol=1e-8, atol=1e-10, msg=name)

    def test_given_batches_replace_the_shuffle_and_validation_is_reported(self):
        sets = [dataset(6, 1), dataset(6, 1)]  # the same items: with the same batches, the same run
        batches = shuffled_batches(6, 2, 4, seed=7)
        seen = []
        ensemble = EnsembleForceRegressor.from_models(seeded_models([0, 0]))
        result = fit_ensemble(ensemble, sets, sets[0], steps=4, batch_size=2, seeds=[0, 1], eval_every=2,
                              batches=[batches, batches], on_validation=seen.append, progress=False)
        assert result.members[0].train_loss == pytest.approx(result.members[1].train_loss)
        assert [r["step"] for r in seen] == [2, 4] and len(seen[0]["val_mse"]) == 2
        with pytest.raises(ValueError, match=r"batches\[1\] must be \(4, 2\) indices"):
            fit_ensemble(ensemble, sets, sets[0], steps=4, batch_size=2, seeds=[0, 1], progress=False,
                         batches=[batches, batches + 6])
    @pytest.mark.parametrize("options", [{}, {"cumulative": False, "features": "log1p", "readout": "mean+max",
                                             "global_inputs": False}])
    def test_fixed_data_is_the_same_run(self, options):
        """Pooling each item once (fixed_data) changes the cost, not the numbers."""
        seeds = [0, 1, 2]
        sets = [dataset(6, 10), dataset(7, 11), dataset(6, 10)]
        sets[2] = sets[0]  # two members share one set, as seeds of `none` do
        kwargs = dict(steps=6, batch_size=3, seeds=seeds, eval_every=3, progress=False)
        runs = []
        for fixed in (False, True):
            ensemble = EnsembleForceRegressor.from_models(seeded_models(seeds, torch.float64, **options))
            result = fit_ensemble(ensemble, sets, dataset(4, 13), fixed_data=fixed, **kwargs)
            runs.append((ensemble, result))
        (a, ra), (b, rb) = runs
        for m in range(3):
            assert ra.members[m].train_loss == pytest.approx(rb.members[m].train_loss, rel=1e-12)
        for (name, x), (_, y) in zip(a.state_dict().items(), b.state_dict().items()):
            torch.testing.assert_close(x, y, rtol=1e-12, atol=1e-12, msg=name)

    def test_fixed_data_still_augments(self):
        """A member with an augment callable reads and transforms its batch at every step."""
        seen = []

        def augment(frames, metas):
            seen.append(frames.shape[0])
            return frames * 2

        ensemble = EnsembleForceRegressor.from_models(seeded_models([0, 1]))
        data = TensorDataset(counts(4, T, 2, H, W), torch.rand(4, T))
        fit_ensemble(ensemble, [data, data], data, steps=3, batch_size=2, seeds=[0, 1], progress=False,
                     augment=[None, augment], fixed_data=True)
        assert seen == [2, 2, 2]
        with pytest.raises(TypeError, match="fixed_data must be a bool, got 1"):
            fit_ensemble(ensemble, [data, data], data, steps=1, seeds=[0, 1], fixed_data=1)

    def test_float32_member_close_to_single_model(self):
        seeds = [5, 6]
        sets = [dataset(6, 1), dataset(6, 2)]
        options = dict(steps=4, batch_size=2, lr_max=1e-2, clip=1.0)
        ensemble = EnsembleForceRegressor.from_models(seeded_models(seeds))
        fit_ensemble(ensemble, sets, sets[0], seeds=seeds, progress=False, **options)
        frames = counts(3, T, 2, H, W, seed=9)
        for m, seed in enumerate(seeds):
            model = seeded_models([seed])[0]
            reference_run(model, sets[m], seed=seed, val=sets[0].tensors, **options)
            torch.testing.assert_close(ensemble.member(m)(frames), model(frames), rtol=1e-4, atol=1e-4)

    def test_select_best_and_final(self):
        sets = [dataset(8, 1), dataset(8, 2)]
        val = dataset(4, 3)
        for select in ("best", "final"):
            ensemble = EnsembleForceRegressor.from_models(seeded_models([0, 1]))
            result = fit_ensemble(ensemble, sets, val, steps=8, batch_size=2, seeds=[0, 1], lr_max=0.3,
                                  eval_every=2, select=select, progress=False)
            with torch.no_grad():
                now = (ensemble(val.tensors[0]).double() - val.tensors[1].double()).square().mean((1, 2))
            for m, record in enumerate(result.members):
                assert record.val_steps == [2, 4, 6, 8]
                assert record.best_val_loss == min(record.val_loss)
                assert record.val_loss[record.val_steps.index(record.best_step)] == record.best_val_loss
                want = record.best_val_loss if select == "best" else record.val_loss[-1]
                assert record.selected_val_loss == want
                assert float(now[m]) == pytest.approx(want, rel=1e-5)

    def test_patience_freezes_members(self):
        sets = [dataset(8, 1), dataset(8, 2), dataset(8, 3)]
        val = dataset(4, 4)
        ensemble = EnsembleForceRegressor.from_models(seeded_models([0, 1, 2]))
        result = fit_ensemble(ensemble, sets, val, steps=12, batch_size=2, seeds=[0, 1, 2], lr_max=0.5,
                              schedule="constant", eval_every=1, patience=1, progress=False)
        stopped = [r.stopped_step for r in result.members]
        assert any(s is not None for s in stopped), stopped
        with torch.no_grad():
            now = (ensemble(val.tensors[0]).double() - val.tensors[1].double()).square().mean((1, 2))
        for m, record in enumerate(result.members):
            assert float(now[m]) == pytest.approx(record.val_loss[-1], rel=1e-5)
            if record.stopped_step is not None:
                assert record.steps == record.stopped_step == len(record.train_loss) == record.val_steps[-1]
                assert record.stopped_step < 12

    def test_all_frozen_stops_early(self):
        sets = [dataset(4, 1), dataset(4, 2)]
        ensemble = EnsembleForceRegressor.from_models(seeded_models([0, 1]))
        before = [p.detach().clone() for p in ensemble.parameters()]
        result = fit_ensemble(ensemble, sets, sets[0], steps=20, batch_size=2, seeds=[0, 1], lr_max=1e-30,
                              schedule="constant", eval_every=1, patience=2, progress=False)
        assert result.steps == 3
        assert [r.stopped_step for r in result.members] == [3, 3]
        for a, b in zip(before, ensemble.parameters()):
            torch.testing.assert_close(a, b, rtol=0, atol=1e-25)

    def test_timing_and_stopwatch(self):
        watch = Stopwatch()

        class Timed(Dataset):
            def __init__(self, data):
                self.data = data

            def __len__(self):
                return len(self.data)

            def __getitem__(self, index):
                with watch:
                    return self.data[index]

        sets = [Timed(dataset(4, 1)), Timed(dataset(5, 2))]
        ensemble = EnsembleForceRegressor.from_models(seeded_models([0, 1]))
        result = fit_ensemble(ensemble, sets, dataset(3, 3).tensors, steps=3, batch_size=2, seeds=[0, 1],
                              stopwatch=watch, progress=False)
        assert watch.calls == 2 * 3 * 2
        assert 0 < result.augmentation_s <= result.train_s <= result.total_s
        assert result.seconds_per_step == pytest.approx(result.train_s / 3)
        assert set(result.to_dict()) >= {"members", "train_s", "val_s", "augmentation_s", "seconds_per_step"}

    def test_rejects_bad_arguments(self):
        ensemble = EnsembleForceRegressor(2, hidden_channels=(2,), input_pool=2)
        data = dataset(4, 0)
        base = dict(steps=2, seeds=[0, 1], progress=False)
        with pytest.raises(ValueError, match="train_sets must hold one Dataset per member \\(2\\)"):
            fit_ensemble(ensemble, [data], data, **base)
        with pytest.raises(ValueError, match=r"seeds must be 2 ints, one per member, got \[0\]"):
            fit_ensemble(ensemble, [data, data], data, steps=2, seeds=[0], progress=False)
        with pytest.raises(ValueError, match="select must be 'final' or 'best', got 'last'"):
            fit_ensemble(ensemble, [data, data], data, select="last", **base)
        with pytest.raises(ValueError, match="schedule must be"):
            fit_ensemble(ensemble, [data, data], data, schedule="step", **base)
        with pytest.raises(ValueError, match="clip must be a positive number or None, got 0"):
            fit_ensemble(ensemble, [data, data], data, clip=0, **base)
        with pytest.raises(ValueError, match="steps must be > 0, got 0"):
            fit_ensemble(ensemble, [data, data], data, steps=0, seeds=[0, 1])
        with pytest.raises(ValueError, match=r"train_sets\[1\] is empty"):
            fit_ensemble(ensemble, [data, TensorDataset(torch.zeros(0))], data, **base)
