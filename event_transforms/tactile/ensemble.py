"""Many force regressors trained in lockstep: one grouped-convolution pass for M members.

:class:`EnsembleForceRegressor` holds ``M`` independent
:class:`~event_transforms.tactile.models.ForceRegressor` networks. Every parameter carries a
leading member dimension (a ConvLSTM input kernel is ``(M, 4 C_hidden, C_in, kH, kW)``) and
each convolution runs once for all members as a grouped convolution (``groups=M`` on an
input of ``(B, M * C, H, W)``), so Python and kernel-launch overhead is paid once per step,
not ``M`` times. Members never mix: a grouped convolution keeps groups apart, the readout is
per member, the loss is the *sum* of the members' MSEs (so each member's gradient is its own
MSE's), Adam is elementwise and gradient clipping is per member.
:meth:`EnsembleForceRegressor.member` gives member ``i`` back as a standalone
``ForceRegressor`` with the same outputs (up to float rounding: the summation order of a
grouped convolution differs from a plain one).

This module is the model: the ensemble, its grouped ConvLSTM cells and
:func:`predict_ensemble` (the one evaluation loop). Its trainer lives in
:mod:`event_transforms.tactile.training` (:func:`~event_transforms.tactile.training.train`,
:func:`~event_transforms.tactile.training.fit_ensemble`, the stopping rule, the batch order
:func:`~event_transforms.tactile.training.shuffled_batches`, per-member clipping
:func:`~event_transforms.tactile.training.clip_grad_norm_per_member_`, ``MemberRecord``,
``EnsembleResult``): import them from there.

Measured cost of one optimiser step, ensemble / loop of M separate models (CPU, one
thread, 2-core machine shared with other jobs; ``hidden_channels=(8,)``, batch 8 per
member, T = 36, 70x75 frames; ``python benchmarks/tactile/ensemble.py --threads 1``, ratios of
thread CPU time, wall-time ratios within 0.05 of them):

=============  ======  ======  ======
input_pool     M = 1   M = 5   M = 15
=============  ======  ======  ======
5              1.01    0.97    0.90
10             1.04    0.50    0.42
=============  ======  ======  ======

At ``input_pool=5`` the step is bound by convolution arithmetic and grouping buys nothing
on the CPU (grouped convolutions with 2-8 channels per group are no faster in oneDNN than
separate ones); at ``input_pool=10`` the per-call overhead dominates and M members cost
about half of M separate steps. In thread CPU time, a single-model step at pool 10 cost
0.52x one at pool 5, and a member-step in an ensemble of 15 at pool 10 cost 0.23x a single
pool-5 step (59, 31 and 206 / 15 ms; absolute times on this loaded machine vary 2-3x
between runs, the ratios far less). On a GPU the ensemble should win at any
pool (on one H100, 10 members took about the time of one with ``vmap``); run
``benchmarks/tactile/ensemble.py --device cuda`` there.

Since issue 17 the trainer pools each member's batch before stacking the members
(:meth:`EnsembleForceRegressor.pool`; ``input_pool²`` times less to stack), and with
``fixed_data=True`` pools every item of a fixed training set once, before the first step:
reading, converting and pooling ``(8, 8, 36, 2, 70, 75)`` frames took 40 % of the earlier
quick step. A 1 x 1 kernel runs as a batched matrix product instead of a grouped
convolution. For the quick model (``hidden_channels=(4,)``, ``input_pool=14``) an 8-member
step at batch 8 costs about a fifth of the earlier quick model's (``(8,)``, pool 10) in
thread CPU time; the numbers are in the CHANGELOG under "Model (issue 17)".

Example:
    >>> from event_transforms.tactile.models import ForceRegressor
    >>> models = []
    >>> for seed in (0, 1):
    ...     _ = torch.manual_seed(seed)
    ...     models.append(ForceRegressor(hidden_channels=(4,), input_pool=2))
    >>> ensemble = EnsembleForceRegressor.from_models(models)
    >>> frames = torch.poisson(torch.full((3, 5, 2, 8, 6), 0.5))
    >>> out = ensemble(frames)  # one shared batch for both members
    >>> tuple(out.shape), torch.allclose(out[1], models[1](frames), atol=1e-5)
    ((2, 3, 5), True)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .models import (
    ConvLSTMCell,
    ForceRegressor,
    _check_positive_int,
    _feature_channels,
    _global_channels,
    _global_features,
    _hard_sigmoid,
    _has_square,
    _input_features,
    _pool_counts,
)

__all__ = ["EnsembleForceRegressor", "predict_ensemble"]


def _grouped_conv(x: Tensor, weight: Tensor, groups: int) -> Tensor:
    """``F.conv2d(x, weight.flatten(0, 1), padding="same", groups=groups)`` for weights
    ``(M, O, C, kH, kW)`` (``groups`` is ``M``, or 1 for an input shared by the members).

    A 1 x 1 kernel runs as one batched matrix product: on the CPU, oneDNN splits a grouped
    1 x 1 convolution into a slow per-group loop (measured: 36 recurrent steps, forward
    and backward, 8 members of 4 channels on 5 x 5 cells, 10.1 ms as convolutions, 6.5 ms
    as products).
    """
    members, out, channels = weight.shape[:3]
    n, _, height, width = x.shape
    if weight.shape[-2:] != (1, 1):
        # im2col and one batched matrix product per member: a member's result does not
        # depend on how many members share the ensemble (oneDNN's grouped convolution picks
        # its algorithm by the group count, so seed 0 alone and seed 0 beside seven others
        # differed in the last bits, and training amplified that; issue 24)
        kh, kw = weight.shape[-2:]
        if kh % 2 == 0 or kw % 2 == 0:
            return F.conv2d(x, weight.flatten(0, 1), padding="same", groups=groups)
        k = channels * kh * kw
        columns = F.unfold(x, (kh, kw), padding=(kh // 2, kw // 2))  # (N, C_total*kh*kw, H*W)
        if groups == 1:  # expanded, not broadcast: the same product as for M separate inputs
            columns = columns.unsqueeze(1).expand(n, members, k, height * width)
        else:
            columns = columns.view(n, members, k, height * width)
        # member-major (M, K, N*H*W): one product per member, the same for any M
        columns = columns.permute(1, 2, 0, 3).reshape(members, k, n * height * width)
        y = torch.bmm(weight.reshape(members, out, k), columns)  # (M, out, N*H*W)
        return y.view(members, out, n, height * width).permute(2, 0, 1, 3).reshape(n, members * out, height, width)
    if groups == 1:  # every member's kernels on the one input
        y = torch.matmul(weight.reshape(members * out, channels), x.reshape(n, channels, height * width))
    else:
        y = torch.matmul(weight.reshape(members, out, channels), x.reshape(n, members, channels, height * width))
    return y.reshape(n, members * out, height, width)


def _gate_bias(cell: ConvLSTMCell) -> Tensor:
    """A cell's gate bias (ForceRegressor builds every cell with one)."""
    bias = cell.input_conv.bias
    if bias is None:
        raise ValueError("an ensemble member's ConvLSTM cells need a gate bias (bias=True); this cell has none")
    return bias


class _GroupedCell(nn.Module):
    """One ConvLSTM layer for ``M`` members, weights ``(M, ...)``, grouped convolutions."""

    def __init__(
        self, members: int, in_channels: int, hidden: int, kernel_size: tuple[int, int], activation: str
    ) -> None:
        super().__init__()
        self.members, self.in_channels, self.hidden = members, in_channels, hidden
        self.kernel_size, self.recurrent_activation = kernel_size, activation
        kh, kw = kernel_size
        self.input_weight = nn.Parameter(torch.empty(members, 4 * hidden, in_channels, kh, kw))
        self.input_bias = nn.Parameter(torch.empty(members, 4 * hidden))
        self.recurrent_weight = nn.Parameter(torch.empty(members, 4 * hidden, hidden, kh, kw))

    def _gate(self, x: Tensor) -> Tensor:
        return _hard_sigmoid(x) if self.recurrent_activation == "hard_sigmoid" else torch.sigmoid(x)

    def input_gates(self, x: Tensor, shared: bool) -> Tensor:
        """``(N, M*C_in, H, W)`` (or ``(N, C_in, H, W)`` when ``shared``) -> ``(N, M*4h, H, W)``."""
        # A shared input needs no copies: one ordinary convolution with every member's kernels.
        gates = _grouped_conv(x, self.input_weight, 1 if shared else self.members)
        return gates + self.input_bias.flatten().view(-1, 1, 1)

    def run(self, input_gates: Tensor) -> Tensor:
        """Loop over time: ``(B, T, M*4h, H, W)`` input gates -> hidden ``(B, T, M*h, H, W)``."""
        batch, steps, _, height, width = input_gates.shape
        members, hidden = self.members, self.hidden
        dtype = torch.promote_types(self.input_weight.dtype, torch.float32)
        c = torch.zeros(batch, members, hidden, height, width, dtype=dtype, device=input_gates.device)
        h = c.flatten(1, 2)
        outputs = []
        for gates in input_gates.unbind(1):
            gates = gates.to(dtype) + _grouped_conv(h, self.recurrent_weight, members).to(dtype)
            i, f, g, o = gates.unflatten(1, (members, 4, hidden)).unbind(2)
            c = self._gate(f) * c + self._gate(i) * torch.tanh(g)
            h = (self._gate(o) * torch.tanh(c)).flatten(1, 2)
            outputs.append(h)
        if not outputs:
            return h.unsqueeze(1)[:, :0]
        return torch.stack(outputs, dim=1)


class EnsembleForceRegressor(nn.Module):
    """``M`` independent :class:`ForceRegressor` networks computed in one pass.

    Parameters have a leading member dimension and every convolution is one grouped
    convolution, so a training step of ``M`` members costs one Python pass. Members are
    initialised as ``M`` ``ForceRegressor(**kwargs)`` built one after another from torch's
    global RNG; for paired seeds build the members yourself after ``torch.manual_seed(seed)``
    and use :meth:`from_models`.

    Args:
        members: number of members ``M``.
        **kwargs: the arguments of :class:`ForceRegressor` (``in_channels``,
            ``hidden_channels``, ``kernel_size``, ``input_pool``, ``recurrent_activation``,
            ``cumulative``, ``features``, ``readout``, ``global_inputs``).

    Shape:
        - frames: ``(M, B, T, 2, H, W)`` (member ``m`` reads batch ``frames[m]``) or
          ``(B, T, 2, H, W)`` (the same batch for every member, e.g. a validation set)
        - output: ``(M, B, T)`` float32 (float64 for a float64 model), newtons

    Example:
        >>> _ = torch.manual_seed(0)
        >>> ensemble = EnsembleForceRegressor(3, hidden_channels=(4,), input_pool=2)
        >>> frames = torch.poisson(torch.full((3, 2, 4, 2, 8, 6), 0.5))
        >>> out = ensemble(frames)
        >>> single = ensemble.member(2)(frames[2])
        >>> tuple(out.shape), torch.allclose(out[2], single, atol=1e-5)
        ((3, 2, 4), True)
    """

    # buffers (register_buffer), declared for the type checker
    force_offset: Tensor
    force_scale: Tensor

    def __init__(self, members: int, **kwargs: Any) -> None:
        super().__init__()
        members = _check_positive_int(members, "members")
        models = [ForceRegressor(**kwargs) for _ in range(members)]
        self._init_structure(members, models[0].config)
        self._load_models(models)

    def _init_structure(self, members: int, config: dict[str, Any]) -> None:
        self.members = members
        self.config = dict(config)
        self.in_channels = int(config["in_channels"])
        self.input_pool = int(config["input_pool"])
        self.cumulative = bool(config["cumulative"])
        self.features, self.readout = str(config["features"]), str(config["readout"])
        self.global_inputs = bool(config["global_inputs"])
        self.square = _has_square(self.in_channels, self.cumulative, self.features)
        hidden = list(config["hidden_channels"])
        inputs = [_feature_channels(self.in_channels, self.cumulative, self.features), *hidden[:-1]]
        self.cells = nn.ModuleList(
            _GroupedCell(members, c_in, c_h, tuple(config["kernel_size"]), config["recurrent_activation"])
            for c_in, c_h in zip(inputs, hidden)
        )
        width = (2 if self.readout == "mean+max" else 1) * hidden[-1]
        if self.global_inputs:
            width += _global_channels(self.in_channels, self.cumulative, self.features)
        self.head_weight = nn.Parameter(torch.empty(members, width))
        self.head_bias = nn.Parameter(torch.empty(members))
        self.register_buffer("force_offset", torch.zeros(members))
        self.register_buffer("force_scale", torch.ones(members))

    @property
    def _layers(self) -> tuple[_GroupedCell, ...]:
        """The layers' grouped cells in order: the items of ``cells``, typed."""
        return tuple(cast(_GroupedCell, cell) for cell in self.cells)

    @torch.no_grad()
    def _load_models(self, models: Sequence[ForceRegressor]) -> None:
        for index, cell in enumerate(self._layers):
            sources = [m.lstm.layers[index] for m in models]
            cell.input_weight.copy_(torch.stack([s.input_conv.weight for s in sources]))
            cell.input_bias.copy_(torch.stack([_gate_bias(s) for s in sources]))
            cell.recurrent_weight.copy_(torch.stack([s.recurrent_conv.weight for s in sources]))
        self.head_weight.copy_(torch.stack([m.head.weight[0] for m in models]))
        self.head_bias.copy_(torch.stack([m.head.bias[0] for m in models]))
        self.force_offset.copy_(torch.stack([m.force_offset for m in models]))
        self.force_scale.copy_(torch.stack([m.force_scale for m in models]))

    @classmethod
    def from_models(cls, models: Sequence[ForceRegressor]) -> EnsembleForceRegressor:
        """An ensemble whose member ``i`` is a copy of ``models[i]`` (weights and force scaling).

        The models must share one configuration (:attr:`ForceRegressor.config`); the
        ensemble takes the first model's dtype and device.
        """
        if isinstance(models, ForceRegressor) or not isinstance(models, Sequence) or not models:
            raise ValueError(f"models must be a non-empty sequence of ForceRegressor, got {models!r}")
        for index, model in enumerate(models):
            if not isinstance(model, ForceRegressor):
                raise TypeError(f"models[{index}] must be a ForceRegressor, got {type(model).__name__}")
            if model.config != models[0].config:
                raise ValueError(
                    f"models[{index}] has configuration {model.config}, models[0] has {models[0].config}"
                )
        ensemble = cls.__new__(cls)
        nn.Module.__init__(ensemble)
        ensemble._init_structure(len(models), models[0].config)
        reference = models[0].head.weight
        ensemble.to(device=reference.device, dtype=reference.dtype)
        ensemble._load_models(models)
        return ensemble

    @torch.no_grad()
    def member(self, index: int) -> ForceRegressor:
        """A standalone :class:`ForceRegressor` holding member ``index``'s weights and scaling."""
        if isinstance(index, bool) or not isinstance(index, int) or not -self.members <= index < self.members:
            raise IndexError(f"index must be an int in [0, {self.members}), got {index!r}")
        model = ForceRegressor(**self.config).to(device=self.head_weight.device, dtype=self.head_weight.dtype)
        for cell, source in zip(model.lstm.layers, self._layers):
            cell.input_conv.weight.copy_(source.input_weight[index])
            _gate_bias(cell).copy_(source.input_bias[index])
            cell.recurrent_conv.weight.copy_(source.recurrent_weight[index])
        model.head.weight.copy_(self.head_weight[index].unsqueeze(0))
        model.head.bias.copy_(self.head_bias[index].unsqueeze(0))
        model.force_offset.copy_(self.force_offset[index])
        model.force_scale.copy_(self.force_scale[index])
        model.train(self.training)
        return model

    @torch.no_grad()
    def set_force_scaling(self, offsets: float | Sequence[float] | Tensor, scales: float | Sequence[float] | Tensor) -> None:
        """Per-member affine map from the heads' outputs to newtons (one value or ``M``)."""
        values = []
        for name, value in (("offsets", offsets), ("scales", scales)):
            tensor = torch.as_tensor(value, dtype=torch.float64).flatten()
            if tensor.numel() == 1:
                tensor = tensor.expand(self.members)
            if tensor.numel() != self.members or not bool(torch.isfinite(tensor).all()):
                raise ValueError(f"{name} must be one finite number or {self.members}, got {value!r}")
            values.append(tensor)
        if not bool((values[1] > 0).all()):
            raise ValueError(f"scales must be positive, got {scales!r}")
        self.force_offset.copy_(values[0])
        self.force_scale.copy_(values[1])

    def _readout(self, h: Tensor, x: Tensor, shared: bool) -> Tensor:
        """``(N, M*h, H, W)`` last hidden state and first-layer input ``(N, [M*]C', h, w)``
        (``shared``: one input for every member) -> force ``(N, M)``."""
        h = h.unflatten(1, (self.members, -1))
        parts = [h.mean(dim=(-2, -1))]
        if self.readout == "mean+max":
            parts.append(h.amax(dim=(-2, -1)))
        if self.global_inputs:
            if shared:
                inputs = _global_features(x, self.square).unsqueeze(1).expand(-1, self.members, -1)
            else:
                inputs = _global_features(x.unflatten(1, (self.members, -1)).flatten(0, 1), self.square)
                inputs = inputs.unflatten(0, (x.shape[0], self.members))
            parts.append(inputs.to(parts[0].dtype))
        features = torch.cat(parts, dim=-1)
        weight = self.head_weight
        out = (features.to(weight.dtype) * weight).sum(-1) + self.head_bias
        out = out.double() if weight.dtype == torch.float64 else out.float()
        return self.force_offset.to(out.dtype) + self.force_scale.to(out.dtype) * out

    def _check_frames(self, frames: object, pooled: bool) -> bool:
        """Validate ``frames``; return whether one batch is shared by every member."""
        if not isinstance(frames, Tensor):
            raise TypeError(f"frames must be a torch.Tensor, got {type(frames).__name__}")
        shared = frames.dim() == 5
        members, channels = self.members, self.in_channels
        if not (shared or (frames.dim() == 6 and frames.shape[0] == members)) or frames.shape[-3] != channels:
            raise ValueError(
                f"frames: expected ({members}, B, T, {channels}, H, W) or (B, T, {channels}, H, W), "
                f"got {tuple(frames.shape)}"
            )
        if not pooled and min(frames.shape[-2:]) < self.input_pool:
            raise ValueError(
                f"frames: (H, W) = {tuple(frames.shape[-2:])} is smaller than input_pool={self.input_pool}"
            )
        return shared

    def pool(self, frames: Tensor) -> Tensor:
        """The members' first stage: ``input_pool`` average pooling of the counts, in the
        model's dtype (float32 or float64), any leading dimensions kept.

        ``model(model.pool(frames), pooled=True)`` equals ``model(frames)``, so a trainer
        can pool each item once (the pooled tensor is ``input_pool²`` times smaller).

        Example:
            >>> ensemble = EnsembleForceRegressor(2, hidden_channels=(2,), input_pool=5)
            >>> frames = torch.ones(3, 4, 2, 10, 15, dtype=torch.int16)
            >>> pooled = ensemble.pool(frames)
            >>> tuple(pooled.shape), torch.equal(ensemble(pooled, pooled=True), ensemble(frames))
            ((3, 4, 2, 2, 3), True)
        """
        self._check_frames(frames, pooled=False)
        return _pool_counts(frames, self.input_pool, self.head_weight.dtype)

    def forward(self, frames: Tensor, *, pooled: bool = False) -> Tensor:
        """Force per frame and member, ``(M, B, T)``; ``pooled``: ``frames`` come from
        :meth:`pool`."""
        shared = self._check_frames(frames, pooled)
        members = self.members
        batch, steps = frames.shape[-5:-3]
        # the input features of ForceRegressor, from the pooled counts
        if not pooled:
            frames = _pool_counts(frames, self.input_pool, self.head_weight.dtype)
        inputs = _input_features(frames.flatten(0, -5), self.cumulative, features=self.features)[0]
        x = inputs.flatten(0, 1)  # ([M*]B*T, C', h, w)
        if not shared:  # (M*B*T, C', h, w) -> (B*T, M*C', h, w), member-major channels
            x = x.unflatten(0, (members, batch * steps)).transpose(0, 1).flatten(1, 2)
        first = x
        for index, cell in enumerate(self._layers):
            if index:
                x = F.avg_pool2d(x, 2)
            gates = cell.input_gates(x, shared and index == 0)
            x = cell.run(gates.unflatten(0, (batch, steps))).flatten(0, 1)
        return self._readout(x, first, shared).unflatten(0, (batch, steps)).permute(2, 0, 1)

    def extra_repr(self) -> str:
        return f"members={self.members}, " + ", ".join(f"{k}={v!r}" for k, v in self.config.items())


@torch.no_grad()
def predict_ensemble(
    model: EnsembleForceRegressor, frames: Tensor, *, batch_size: int = 32, pooled: bool = False
) -> Tensor:
    """Every member's force for frames ``(N, T, 2, H, W)`` shared by all: ``(M, N, T)``, in
    batches of ``batch_size`` on the model's device, in eval mode (the mode is restored).
    ``pooled=True`` takes frames already pooled by :meth:`EnsembleForceRegressor.pool`.

    The one evaluation loop: the trainer's validation passes and the protocol's scores use it.
    """
    was_training = model.training
    model.eval()
    device = model.head_weight.device
    try:
        preds = [
            model(frames[start : start + batch_size].to(device), pooled=pooled)
            for start in range(0, frames.shape[0], batch_size)
        ]
    finally:
        model.train(was_training)
    if not preds:
        raise ValueError("frames must hold at least one sequence, got 0")
    return torch.cat(preds, dim=1)
