"""Tests for the reference ConvLSTM force regressor."""

from __future__ import annotations

import pickle

import pytest
import torch
import torch.nn.functional as F

from event_transforms.tactile.models import ConvLSTM, ConvLSTMCell, ForceRegressor

H, W = 17, 11


pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest.py


def reference_cell_step(cell: ConvLSTMCell, x, h, c):
    """The textbook ConvLSTM step, from one convolution over cat([x, h])."""
    weight = torch.cat([cell.input_conv.weight, cell.recurrent_conv.weight], dim=1)
    gates = F.conv2d(torch.cat([x, h], 1), weight, cell.input_conv.bias, padding="same")
    hidden = cell.hidden_channels
    act = (
        (lambda v: torch.clamp(0.2 * v + 0.5, 0, 1))
        if cell.recurrent_activation == "hard_sigmoid"
        else torch.sigmoid
    )
    i, f, g, o = (gates[:, k * hidden : (k + 1) * hidden] for k in range(4))
    c = act(f) * c + act(i) * torch.tanh(g)
    return act(o) * torch.tanh(c), c


def small_model(**kwargs) -> ForceRegressor:
    torch.manual_seed(0)
    kwargs.setdefault("hidden_channels", (4, 4))
    kwargs.setdefault("input_pool", 2)
    return ForceRegressor(**kwargs)


def counts(*shape, rate=0.5, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.poisson(torch.full(shape, rate), generator=g)


class TestConvLSTMCell:
    @pytest.mark.parametrize("activation", ["sigmoid", "hard_sigmoid"])
    def test_matches_reference(self, activation):
        torch.manual_seed(0)
        cell = ConvLSTMCell(3, 5, 3, recurrent_activation=activation).double()
        x = torch.randn(2, 3, H, W, dtype=torch.float64)
        h = torch.randn(2, 5, H, W, dtype=torch.float64)
        c = torch.randn(2, 5, H, W, dtype=torch.float64)
        got = cell(x, (h, c))
        want = reference_cell_step(cell, x, h, c)
        torch.testing.assert_close(got, want)

    def test_zero_state_default(self):
        torch.manual_seed(0)
        cell = ConvLSTMCell(2, 4, (3, 5))
        x = torch.rand(3, 2, H, W)
        zeros = torch.zeros(3, 4, H, W)
        torch.testing.assert_close(cell(x), cell(x, (zeros, zeros)))
        assert cell(x)[0].shape == (3, 4, H, W)

    def test_init(self):
        torch.manual_seed(0)
        cell = ConvLSTMCell(2, 4, 3)
        bias = cell.input_conv.bias
        assert torch.equal(bias[4:8], torch.ones(4))
        assert torch.equal(bias[:4], torch.zeros(4)) and torch.equal(bias[8:], torch.zeros(8))
        w = cell.recurrent_conv.weight.reshape(16, -1)  # (4 hidden, hidden k k)
        torch.testing.assert_close(w @ w.T, torch.eye(16), atol=1e-5, rtol=0)
        bound = (6 / (2 * 9 + 4 * 9)) ** 0.5
        assert cell.input_conv.weight.abs().max() <= bound
        assert cell.recurrent_conv.bias is None

    def test_reset_parameters_reproducible(self):
        a, b = ConvLSTMCell(2, 4), ConvLSTMCell(2, 4)
        torch.manual_seed(3)
        a.reset_parameters()
        torch.manual_seed(3)
        b.reset_parameters()
        for p, q in zip(a.parameters(), b.parameters()):
            assert torch.equal(p, q)

    def test_hard_sigmoid_is_keras2(self):
        cell = ConvLSTMCell(1, 1, recurrent_activation="hard_sigmoid")
        v = torch.tensor([-10.0, -2.5, 0.0, 1.0, 2.5, 10.0])
        torch.testing.assert_close(cell._gate(v), torch.tensor([0.0, 0.0, 0.5, 0.7, 1.0, 1.0]))

    def test_bad_arguments(self):
        with pytest.raises(ValueError, match="recurrent_activation"):
            ConvLSTMCell(2, 4, recurrent_activation="relu")
        with pytest.raises(ValueError, match="hidden_channels"):
            ConvLSTMCell(2, 0)
        with pytest.raises(TypeError, match="kernel_size"):
            ConvLSTMCell(2, 4, kernel_size=(3, 3, 3))
        with pytest.raises(ValueError, match=r"\(B, 2, H, W\)"):
            ConvLSTMCell(2, 4)(torch.rand(1, 3, 5, 5))

    def test_repr(self):
        assert "hard_sigmoid" in repr(ConvLSTMCell(2, 4, recurrent_activation="hard_sigmoid"))


class TestConvLSTM:
    def test_shapes_and_state(self):
        torch.manual_seed(0)
        lstm = ConvLSTM(2, [4, 3], kernel_size=3)
        out, state = lstm(torch.rand(2, 5, 2, H, W))
        assert out.shape == (2, 5, 3, H, W)
        assert [s[0].shape for s in state] == [(2, 4, H, W), (2, 3, H, W)]
        torch.testing.assert_close(out[:, -1], state[-1][0])

    def test_matches_loop_over_cells(self):
        torch.manual_seed(0)
        lstm = ConvLSTM(2, [4, 3]).double()
        x = torch.rand(2, 6, 2, H, W, dtype=torch.float64)
        out, _ = lstm(x)
        seq = x
        for cell in lstm.cells:
            h = c = torch.zeros(2, cell.hidden_channels, H, W, dtype=torch.float64)
            hs = []
            for t in range(seq.shape[1]):
                h, c = reference_cell_step(cell, seq[:, t], h, c)
                hs.append(h)
            seq = torch.stack(hs, 1)
        torch.testing.assert_close(out, seq)

    def test_state_continues_sequence(self):
        torch.manual_seed(0)
        lstm = ConvLSTM(2, [4, 3]).double()
        x = torch.rand(1, 8, 2, H, W, dtype=torch.float64)
        whole, _ = lstm(x)
        first, state = lstm(x[:, :5])
        second, _ = lstm(x[:, 5:], state)
        torch.testing.assert_close(torch.cat([first, second], 1), whole)

    def test_bad_input(self):
        lstm = ConvLSTM(2, 4)
        with pytest.raises(ValueError, match=r"\(B, T, C, H, W\)"):
            lstm(torch.rand(5, 2, H, W))
        with pytest.raises(ValueError, match="hidden_channels"):
            ConvLSTM(2, [])


class TestForceRegressor:
    def test_shapes(self):
        model = small_model()
        assert model(counts(3, 7, 2, H, W)).shape == (3, 7)
        assert model(counts(1, 1, 2, H, W)).shape == (1, 1)
        default = ForceRegressor()
        assert default(counts(2, 3, 2, 70, 75)).shape == (2, 3)

    def test_default_model_is_small(self):
        assert sum(p.numel() for p in ForceRegressor().parameters()) < 50_000

    @pytest.mark.parametrize("dtype", [torch.uint8, torch.int16, torch.int64, torch.float16])
    def test_accepts_count_dtypes(self, dtype):
        model = small_model()
        x = counts(2, 4, 2, H, W)
        torch.testing.assert_close(model(x.to(dtype)), model(x))

    def test_input_unchanged(self):
        model = small_model()
        x = counts(2, 4, 2, H, W)
        before, version = x.clone(), x._version
        model(x)
        assert x._version == version and torch.equal(x, before)

    @pytest.mark.parametrize("activation", ["sigmoid", "hard_sigmoid"])
    def test_streaming_equals_full_forward(self, activation):
        model = small_model(recurrent_activation=activation, hidden_channels=(4, 5, 3))
        model.eval()
        x = counts(2, 9, 2, H, W, rate=2.0)
        full = model(x)
        state, outs = None, []
        for t in range(x.shape[1]):
            force, state = model.step(x[:, t], state)
            outs.append(force)
        torch.testing.assert_close(torch.stack(outs, 1), full, atol=1e-5, rtol=1e-5)
        assert len(state) == 3 + 1  # one (h, c) per layer and the running sum

    def test_streaming_equals_full_forward_float64(self):
        model = small_model().double()
        x = counts(1, 6, 2, H, W, rate=2.0)
        full = model(x)
        assert full.dtype == torch.float64
        state, outs = None, []
        for t in range(6):
            force, state = model.step(x[:, t], state)
            outs.append(force)
        torch.testing.assert_close(torch.stack(outs, 1), full, atol=1e-12, rtol=1e-12)

    def test_gradients_reach_every_parameter(self):
        model = small_model(hidden_channels=(4, 4, 4))
        x = counts(2, 5, 2, H, W, rate=1.0)
        loss = (model(x) - 3.0).square().mean()
        loss.backward()
        for name, p in model.named_parameters():
            assert p.grad is not None, name
            assert torch.isfinite(p.grad).all(), name
            assert p.grad.abs().sum() > 0, name

    def test_force_scaling(self):
        model = small_model()
        x = counts(2, 4, 2, H, W)
        base = model(x)
        model.set_force_scaling(10.0, 4.0)
        torch.testing.assert_close(model(x), 10.0 + 4.0 * base)
        state = model.state_dict()
        assert float(state["force_offset"]) == 10.0 and float(state["force_scale"]) == 4.0
        with pytest.raises(ValueError, match="scale"):
            model.set_force_scaling(0.0, 0.0)

    def test_overfits_tiny_batch(self):
        model = small_model(hidden_channels=(6,))
        x = counts(4, 6, 2, H, W, rate=0.3, seed=1)
        x[:, :, :, 4:8, 3:7] += torch.arange(4).view(4, 1, 1, 1, 1) * 3.0
        target = torch.linspace(0, 1, 6).expand(4, 6) * torch.tensor([2.0, 5.0, 9.0, 14.0])[:, None]
        opt = torch.optim.Adam(model.parameters(), lr=2e-2)
        first = None
        for _ in range(250):
            loss = F.mse_loss(model(x), target)
            first = loss.item() if first is None else first
            opt.zero_grad()
            loss.backward()
            opt.step()
        assert loss.item() < 0.05 * first

    def test_pickle_and_state_dict(self):
        model = small_model()
        x = counts(1, 3, 2, H, W)
        clone = pickle.loads(pickle.dumps(model))
        torch.testing.assert_close(clone(x), model(x))
        other = small_model(hidden_channels=(4, 4))
        torch.manual_seed(123)
        other.lstm.cells[0].reset_parameters()
        other.load_state_dict(model.state_dict())
        torch.testing.assert_close(other(x), model(x))

    def test_bad_input(self):
        model = small_model()
        with pytest.raises(ValueError, match=r"\(B, T, 2, H, W\)"):
            model(counts(4, 2, H, W))
        with pytest.raises(ValueError, match=r"\(B, T, 2, H, W\)"):
            model(counts(1, 4, 3, H, W))
        with pytest.raises(ValueError, match=r"\(B, 2, H, W\)"):
            model.step(counts(1, 1, 2, H, W))
        with pytest.raises(ValueError, match="input_pool"):
            model(counts(1, 2, 2, 1, W))
        with pytest.raises(TypeError, match="frames"):
            model([[1.0]])
        with pytest.raises(ValueError, match="state"):
            model.step(counts(1, 2, H, W), [])


class TestStability:
    """Finite outputs and gradients in the regimes a trainer meets."""

    @staticmethod
    def check_finite(model, x):
        out = model(x)
        assert torch.isfinite(out).all()
        out.float().square().mean().backward()
        for name, p in model.named_parameters():
            assert p.grad is not None and torch.isfinite(p.grad).all(), name
        return out

    def test_thousand_frames(self):
        model = small_model(hidden_channels=(3,), input_pool=4)
        x = counts(1, 1000, 2, 16, 12, rate=1.0)
        self.check_finite(model, x)

    @pytest.mark.parametrize("features", ["log1p", "linear", "signed"])
    def test_huge_counts(self, features):
        model = small_model(features=features)
        x = torch.full((2, 6, 2, H, W), 1e4)
        x[0, :, :, :3] = 0
        out = self.check_finite(model, x)
        if features == "log1p":  # linear input answers linearly (and its square) by design
            assert out.abs().max() < 1e3

    def test_all_zero_input(self):
        model = small_model()
        out = self.check_finite(model, torch.zeros(2, 5, 2, H, W))
        torch.testing.assert_close(out[0], out[1])

    def test_autocast_bfloat16(self):
        model = small_model(hidden_channels=(3, 3), input_pool=4)
        x = counts(1, 1000, 2, 16, 12, rate=1.0)
        x[..., 2:5, 2:5] = 1e4
        with torch.autocast("cpu", dtype=torch.bfloat16):
            out = model(x)
        assert out.dtype == torch.float32 and torch.isfinite(out).all()
        out.square().mean().backward()
        for name, p in model.named_parameters():
            assert torch.isfinite(p.grad).all(), name
        with torch.no_grad():
            ref = model(x)
        assert (out - ref).abs().max() < 0.2 * ref.abs().max() + 0.1

    def test_autocast_gates_stay_float32(self):
        torch.manual_seed(0)
        cell = ConvLSTMCell(2, 3)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            h, c = cell(torch.rand(1, 2, H, W))
            h, c = cell(torch.rand(1, 2, H, W), (h, c))
        assert h.dtype == torch.float32 and c.dtype == torch.float32


def reference_cumulative_features(model: ForceRegressor, frames):
    """A loop over sequences and frames: log1p pooled counts, log1p running sums, signed sum
    (``features="log1p"``) or pooled counts and the signed running sum (``"linear"``)."""
    out = []
    for seq in frames:
        running = None
        rows = []
        for frame in seq:
            pooled = F.avg_pool2d(frame.double().unsqueeze(0), model.input_pool)[0]
            running = pooled.clone() if running is None else running + pooled
            if model.features in ("linear", "signed"):
                d = (running[0] - running[1]).unsqueeze(0) if frame.shape[0] == 2 else running
                values = pooled
                if model.features == "signed" and frame.shape[0] == 2:
                    values = (pooled[0] - pooled[1]).unsqueeze(0)
                rows.append(torch.cat([values, d]))
                continue
            parts = [torch.log1p(pooled), torch.log1p(running)]
            if frame.shape[0] == 2:
                d = running[0] - running[1]
                parts.append((torch.sign(d) * torch.log1p(d.abs())).unsqueeze(0))
            rows.append(torch.cat(parts))
        out.append(torch.stack(rows))
    return torch.stack(out)


class TestCumulative:
    def test_input_features_match_loop(self):
        from event_transforms.tactile.models import _input_features, _pool_counts

        x = counts(2, 7, 2, H, W, rate=1.5)
        x[0, :, 1] *= 3  # more ON than OFF in one sequence: a negative signed sum
        for features, channels in (("log1p", 5), ("linear", 3), ("signed", 2)):
            model = small_model(cumulative=True, features=features)
            pooled = _pool_counts(x, model.input_pool, torch.float64)
            got, last = _input_features(pooled, True, features=features)
            want = reference_cumulative_features(model, x)
            torch.testing.assert_close(got, want)
            assert bool((got[0, -1, -1] < 0).all()) and got.shape[2] == channels
            torch.testing.assert_close(last, pooled.sum(1))

    @pytest.mark.parametrize("features,channels,single", [("log1p", 5, 2), ("linear", 3, 2), ("signed", 2, 2)])
    def test_channels_and_config(self, features, channels, single):
        model = small_model(cumulative=True, features=features)
        assert model.lstm.cells[0].in_channels == channels and model.config["cumulative"] is True
        one = small_model(cumulative=True, in_channels=1, features=features)
        assert one.lstm.cells[0].in_channels == single
        assert one(counts(1, 3, 1, H, W)).shape == (1, 3)
        assert ForceRegressor(**model.config).config == model.config
        assert "cumulative" in repr(model) and features in repr(model)

    def test_earlier_model_is_one_option_set_away(self):
        """The model before issue 17: per-frame log1p input and a mean + max readout."""
        earlier = small_model(cumulative=False, features="log1p", readout="mean+max", global_inputs=False)
        assert earlier.lstm.cells[0].in_channels == 2 and earlier.head.in_features == 2 * 4
        assert set(earlier.state_dict()) == set(small_model().state_dict())
        _, state = earlier.step(counts(1, 2, H, W))
        assert len(state) == 2  # one (h, c) per layer, nothing else

    @pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
    def test_streaming_equals_full_forward(self, dtype):
        model = small_model(cumulative=True, hidden_channels=(4, 3)).to(dtype)
        x = counts(2, 40, 2, H, W, rate=2.0)
        full = model(x)
        state, outs = None, []
        for t in range(x.shape[1]):
            force, state = model.step(x[:, t], state)
            outs.append(force)
        tol = 1e-12 if dtype == torch.float64 else 1e-5
        torch.testing.assert_close(torch.stack(outs, 1), full, atol=tol, rtol=tol)
        assert len(state) == 3 and state[-1][0].dtype == torch.float64
        torch.testing.assert_close(state[-1][0], F.avg_pool2d(x.double().flatten(0, 1), 2).unflatten(0, (2, 40)).sum(1))

    def test_running_sum_makes_history_matter(self):
        model = small_model(cumulative=True, hidden_channels=(3,))
        quiet, busy = counts(1, 4, 2, H, W, rate=0.1), counts(1, 4, 2, H, W, rate=5.0)
        frame = counts(1, 2, H, W, rate=1.0, seed=3)
        _, s_quiet = model.step(frame, model.step(quiet[:, 0])[1])
        _, s_busy = model.step(frame, model.step(busy[:, 0])[1])
        assert not torch.equal(s_quiet[-1][0], s_busy[-1][0])

    def test_thousand_frames_finite(self):
        model = small_model(cumulative=True, hidden_channels=(3,), input_pool=4)
        x = counts(1, 1000, 2, 16, 12, rate=1.0)
        x[..., 2:5, 2:5] = 1e4
        TestStability.check_finite(model, x)

    def test_bad_arguments(self):
        with pytest.raises(TypeError, match="cumulative must be a bool, got 1"):
            ForceRegressor(cumulative=1)
        model = small_model(cumulative=True)
        _, state = model.step(counts(1, 2, H, W))
        with pytest.raises(ValueError, match=r"one \(h, c\) per layer \(2\) and the running sum, got 2 entries"):
            model.step(counts(1, 2, H, W), state[:2])


def reference_forward(model: ForceRegressor, frames):
    """The model's forward pass from its parts, one sequence and one frame at a time."""
    out = []
    for seq in frames:
        if model.cumulative:
            inputs = reference_cumulative_features(model, seq.unsqueeze(0))[0]
        else:
            inputs = F.avg_pool2d(seq.double(), model.input_pool)
            if model.features == "log1p":
                inputs = torch.log1p(inputs)
            elif model.features == "signed":
                inputs = inputs[:, :1] - inputs[:, 1:]
        states = [None] * len(model.lstm.cells)
        forces = []
        for x in inputs.to(model.head.weight.dtype):
            first, h = x, x.unsqueeze(0)
            for index, cell in enumerate(model.lstm.cells):
                if index:
                    h = F.avg_pool2d(h, 2)
                states[index] = cell(h, states[index])
                h = states[index][0]
            parts = [h.mean((-2, -1))[0]]
            if model.readout == "mean+max":
                parts.append(h.amax((-2, -1))[0])
            if model.global_inputs:
                means = first.mean((-2, -1))
                parts.append(means)
                if model.cumulative and model.features in ("linear", "signed") and seq.shape[1] == 2:
                    parts.append(means[-1:] ** 2)
            forces.append(model.force_offset + model.force_scale * model.head(torch.cat(parts))[0])
        out.append(torch.stack(forces))
    return torch.stack(out)


OPTIONS = [
    {},
    {"readout": "mean+max"},
    {"global_inputs": False},
    {"features": "log1p"},
    {"features": "linear"},
    {"features": "signed"},
    {"cumulative": False},
    {"cumulative": False, "features": "signed"},
    {"cumulative": False, "features": "log1p", "readout": "mean+max", "global_inputs": False},
]


class TestOptions:
    """Input features, readout and global inputs (issue 17): every combination the same model."""

    def test_defaults(self):
        model = ForceRegressor()
        assert model.config["features"] == "signed" and model.config["readout"] == "mean"
        assert model.config["cumulative"] is True and model.config["global_inputs"] is True
        # head: 16 hidden means + OFF - ON and signed running total means + its square
        assert model.head.in_features == 16 + 3 and model.lstm.cells[0].in_channels == 2

    @pytest.mark.parametrize("options", OPTIONS)
    def test_forward_matches_reference(self, options):
        model = small_model(hidden_channels=(3, 2), **options).double()
        model.set_force_scaling(2.0, 3.0)
        x = counts(2, 5, 2, H, W, rate=1.5)
        x[1, :, 1] *= 2
        torch.testing.assert_close(model(x), reference_forward(model, x), atol=1e-12, rtol=1e-12)

    @pytest.mark.parametrize("options", OPTIONS)
    def test_streaming_equals_forward(self, options):
        model = small_model(hidden_channels=(3,), **options)
        x = counts(3, 8, 2, H, W, rate=1.0)
        state, outs = None, []
        for t in range(x.shape[1]):
            force, state = model.step(x[:, t], state)
            outs.append(force)
        torch.testing.assert_close(torch.stack(outs, 1), model(x), atol=1e-5, rtol=1e-5)
        assert len(state) == 1 + model.cumulative

    @pytest.mark.parametrize("options", OPTIONS)
    def test_one_frame_and_empty_batch(self, options):
        model = small_model(**options)
        x = counts(2, 1, 2, H, W)
        torch.testing.assert_close(model(x)[:, 0], model.step(x[:, 0])[0], atol=1e-6, rtol=1e-6)
        assert model(counts(0, 4, 2, H, W)).shape == (0, 4)
        assert model(counts(2, 0, 2, H, W)).shape == (2, 0)

    def test_global_inputs_hold_the_physics_features(self):
        """With the hidden state's head weights at zero, the model is a linear function of
        the frame's OFF and ON totals, the running signed total and its square."""
        from event_transforms.tactile.baselines import physics_features

        model = small_model(hidden_channels=(3,), input_pool=4, features="linear").double()
        height, width = 16, 12  # divisible by the pool: every pixel counts
        weights = torch.tensor([0.0, 0.0, 0.0, 0.5, -0.25, 0.75, 2.0], dtype=torch.float64)
        with torch.no_grad():
            model.head.weight.copy_(weights.unsqueeze(0))
            model.head.bias.fill_(1.5)
        x = counts(2, 6, 2, height, width, rate=1.0)
        x[0, :, 0] += 1.0
        physics = physics_features(x) / (height * width)  # d, d², OFF, ON per pixel
        d, off, on = physics[..., 0], physics[..., 2], physics[..., 3]
        want = 1.5 + 0.5 * off - 0.25 * on + 0.75 * d + 2.0 * d.square()
        torch.testing.assert_close(model(x), want, atol=1e-12, rtol=1e-12)

    def test_mean_readout_limits_one_hot_pixel(self):
        """A hot pixel moves one cell of the last hidden state: the mean readout sees it
        divided by the cells, the max readout whole."""
        torch.manual_seed(0)
        x = counts(1, 6, 2, 16, 16, rate=0.2)
        hot = x.clone()
        hot[..., 5, 5] += 50.0
        moved = {}
        for readout in ("mean", "mean+max"):
            model = small_model(hidden_channels=(4,), input_pool=2, readout=readout, global_inputs=False,
                                features="log1p", cumulative=False)
            with torch.no_grad():
                model.head.weight.fill_(1.0)
            with torch.no_grad():
                moved[readout] = float((model(hot) - model(x)).abs().max())
        assert moved["mean"] < moved["mean+max"]

    def test_bad_arguments(self):
        with pytest.raises(ValueError, match="features must be one of .*, got 'log'"):
            ForceRegressor(features="log")
        with pytest.raises(ValueError, match="readout must be one of .*, got 'max'"):
            ForceRegressor(readout="max")
        with pytest.raises(TypeError, match="global_inputs must be a bool, got 1"):
            ForceRegressor(global_inputs=1)


def test_signed_input_ignores_balanced_noise():
    """Events that come in OFF/ON pairs (background activity, hot pixels) leave the
    ``features="signed"`` input, and so the default model, unchanged."""
    model = small_model(hidden_channels=(3,))
    x = counts(2, 6, 2, H, W, rate=0.5)
    noise = counts(2, 6, 1, H, W, rate=3.0, seed=7)
    noisy = x + noise  # the same number of extra OFF and ON events at every pixel
    with torch.no_grad():
        torch.testing.assert_close(model(noisy), model(x), atol=1e-6, rtol=1e-6)
        linear = small_model(hidden_channels=(3,), features="linear")
        assert not torch.allclose(linear(noisy), linear(x), atol=1e-3)
