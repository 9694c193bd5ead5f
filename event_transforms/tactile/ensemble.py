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

:func:`fit_ensemble` trains every member for the same number of optimiser steps, each on its
own data set, shuffled with its own seed, with a one-cycle (or cosine) learning rate,
per-member gradient clipping, periodic validation and optional per-member early stopping.

Measured cost of one optimiser step, ensemble / loop of M separate models (CPU, one
thread, 2-core machine shared with other jobs; ``hidden_channels=(8,)``, batch 8 per
member, T = 36, 70x75 frames; ``python benchmarks/ensemble.py --threads 1``, ratios of
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
pool (DESIGN.md measured 10 members in about the time of one with ``vmap``); run
``benchmarks/ensemble.py --device cuda`` there.

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

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
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

__all__ = [
    "EnsembleForceRegressor",
    "MemberRecord",
    "EnsembleResult",
    "clip_grad_norm_per_member_",
    "shuffled_batches",
    "fit_ensemble",
    "predict_ensemble",
]


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


# ----------------------------------------------------------------------------- training


def shuffled_batches(length: int, batch_size: int, steps: int, *, seed: int) -> Tensor:
    """Indices ``(steps, batch_size)`` of ``steps`` batches drawn from ``length`` items.

    The items are visited in passes; each pass is a fresh ``torch.randperm`` from one
    ``torch.Generator`` seeded with ``seed``, and batches run on across the end of a pass
    (no item is dropped, no batch is short), so a data set with copies gives more distinct
    data to the same number of steps.

    Example:
        >>> batches = shuffled_batches(5, 2, 4, seed=0)
        >>> tuple(batches.shape), sorted(batches.flatten()[:5].tolist())
        ((4, 2), [0, 1, 2, 3, 4])
    """
    for name, value in (("length", length), ("batch_size", batch_size), ("steps", steps)):
        _check_positive_int(value, name)
    generator = torch.Generator().manual_seed(seed)
    needed = steps * batch_size
    passes = [torch.randperm(length, generator=generator) for _ in range(-(-needed // length))]
    return torch.cat(passes)[:needed].view(steps, batch_size)


def clip_grad_norm_per_member_(parameters: Sequence[Tensor], max_norm: float) -> Tensor:
    """Clip each member's gradient to norm ``max_norm``; return the norms before clipping.

    Every parameter's first dimension is the member. Member ``m``'s norm is the 2-norm over
    its slices of every gradient, and its slices are scaled by
    ``min(1, max_norm / (norm + 1e-6))``, as :func:`torch.nn.utils.clip_grad_norm_` does for
    one model. No host synchronisation.

    Example:
        >>> w = torch.zeros(2, 3, requires_grad=True)
        >>> w.grad = torch.tensor([[3.0, 4.0, 0.0], [0.3, 0.4, 0.0]])
        >>> clip_grad_norm_per_member_([w], 1.0).tolist()
        [5.0, 0.5]
        >>> [[round(v, 4) for v in row] for row in w.grad.tolist()]
        [[0.6, 0.8, 0.0], [0.3, 0.4, 0.0]]
    """
    grads = [p.grad for p in parameters if p.grad is not None]
    if not grads:
        return torch.zeros(0)
    # member by member: a row reduction of (M, K) sums in another order than the same row
    # alone, and a last-bit change in the clip scale made a seed's training depend on how
    # many members shared its ensemble (issue 24)
    squares = torch.stack(
        [torch.stack([g.detach()[m].square().sum() for g in grads]).sum() for m in range(grads[0].shape[0])]
    )
    norms = squares.sqrt()
    coef = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.detach().mul_(coef.view(-1, *([1] * (g.dim() - 1))).to(g.dtype))
    return norms


@dataclass
class MemberRecord:
    """What one member of :func:`fit_ensemble` did (losses in N², steps counted from 1)."""

    member: int
    seed: int
    steps: int
    train_loss: list[float] = field(default_factory=list)
    val_steps: list[int] = field(default_factory=list)
    val_loss: list[float] = field(default_factory=list)
    best_val_loss: float = math.inf
    best_step: int = 0
    stopped_step: int | None = None
    selected_val_loss: float = math.inf


@dataclass
class EnsembleResult:
    """Outcome of :func:`fit_ensemble`; the model holds the selected weights afterwards.

    ``train_s`` is the wall time of the optimiser steps (data loading and augmentation
    included), ``augmentation_s`` the part of it spent inside a timed augmentation
    (:class:`~event_transforms.tactile.training.Stopwatch`), ``val_s`` the validation time.
    """

    members: list[MemberRecord]
    steps: int
    select: str
    schedule: str
    train_s: float
    val_s: float
    augmentation_s: float
    total_s: float

    @property
    def seconds_per_step(self) -> float:
        """Training wall time per optimiser step (all members together)."""
        return self.train_s / max(self.steps, 1)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        out = asdict(self)
        out["seconds_per_step"] = self.seconds_per_step
        return out


def _stack_member_batch(
    data: Any, indices: Tensor, collate: Callable[[Sequence[Any]], tuple]
) -> tuple[Tensor, Tensor, list]:
    frames, force, metas = collate([data[int(i)] for i in indices])
    return frames, force, metas


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


def _validation_mse(model: EnsembleForceRegressor, frames: Tensor, force: Tensor, batch_size: int) -> Tensor:
    """Per-member MSE over every frame of the shared, pooled validation set, ``(M,)`` float64."""
    pred = predict_ensemble(model, frames, batch_size=batch_size, pooled=True)
    return (pred.double() - force.double()).square().mean(dim=(1, 2))


def fit_ensemble(
    model: EnsembleForceRegressor,
    train_sets: Sequence[Any],
    val_data: Any,
    *,
    steps: int,
    batch_size: int = 8,
    seeds: Sequence[int],
    lr_max: float = 1e-2,
    clip: float | None = 1.0,
    schedule: str = "one-cycle",
    eval_every: int | None = None,
    patience: int | None = None,
    select: str = "final",
    val_batch_size: int = 32,
    device: str | torch.device | None = None,
    progress: bool | None = None,
    stopwatch: Any | None = None,
    description: str = "ensemble",
    augment: Sequence[Callable[[Tensor, list], Tensor] | None] | None = None,
    batches: Sequence[Tensor] | None = None,
    on_validation: Callable[[dict[str, Any]], None] | None = None,
    fixed_data: bool = False,
) -> EnsembleResult:
    """Train every member of ``model`` for exactly ``steps`` optimiser steps, in lockstep.

    Member ``m`` reads ``train_sets[m]`` (items ``(frames, force, meta)``; sizes may differ:
    copies add data, not steps), in batches of ``batch_size`` from :func:`shuffled_batches`
    with ``seeds[m]``. The loss is the sum over members of each member's MSE, so every
    member gets its own gradient; Adam (elementwise) over all parameters, the learning rate
    following ``schedule``, gradients clipped per member (:func:`clip_grad_norm_per_member_`).

    Every ``eval_every`` steps and after the last step, each member's validation MSE on
    ``val_data`` (shared by all members) is computed. With ``patience``, a member whose
    validation MSE has not improved for ``patience`` evaluations is frozen: its slices are
    restored after every later optimiser step, so Adam's momentum cannot move it; training
    ends early when every member is frozen. At the end, ``select="best"`` loads each
    member's best-validation weights, ``"final"`` keeps the final ones (a frozen member's are
    those it had when frozen).

    Augmentation inside the data sets that draws from torch's global RNG is not seeded
    here; seed it before calling for reproducible runs. The force scaling of the members is
    not changed (set it first with :meth:`EnsembleForceRegressor.set_force_scaling`).

    Args:
        model: the ensemble; trained in place on ``device``.
        train_sets: one Dataset per member, items ``(frames, force, meta)``.
        val_data: a Dataset of such items, or a ``(frames, force)`` pair.
        steps: optimiser steps per member.
        batch_size: sequences per member per step.
        seeds: one shuffling seed per member.
        lr_max: peak (one-cycle) or initial (cosine, constant) learning rate.
        clip: per-member gradient-norm limit; ``None`` for no clipping.
        schedule: ``"one-cycle"`` (:class:`torch.optim.lr_scheduler.OneCycleLR` with its
            defaults: 30 % warm-up from ``lr_max / 25``, cosine annealing to
            ``lr_max / 25e4``), ``"cosine"`` (to zero) or ``"constant"``.
        eval_every: steps between validations; default ``max(1, steps // 20)``.
        patience: evaluations without improvement before a member is frozen; ``None`` never.
        select: ``"final"`` or ``"best"``.
        val_batch_size: sequences per validation forward pass.
        device: where to train; default the model's device.
        progress: a tqdm bar; ``None`` shows it only when stderr is a terminal.
        stopwatch: the :class:`~event_transforms.tactile.training.Stopwatch` of a
            ``TimedTransform`` inside the data sets; reported as ``augmentation_s``.
        description: label of the progress bar.
        augment: per member, ``None`` or a callable ``(frames, metas) -> frames`` applied to
            the member's batch ``(B, T, 2, H, W)`` after it is moved to ``device``: on-the-fly
            augmentation on the training device (its time is counted in ``train_s``).
        batches: per member, the item indices ``(steps, batch_size)`` of every step, instead
            of :func:`shuffled_batches` (e.g. a schedule that gives paired members the same
            items at the same steps).
        on_validation: called after every validation pass with a dict ``step``, ``steps``,
            ``train_loss`` (mean over members of the last step's MSE), ``val_mse`` (one per
            member), ``elapsed_s``.
        fixed_data: the training sets return the same item for an index every time (no
            randomness in ``__getitem__``, e.g. fixed copies): every item of a set is read
            and pooled (:meth:`EnsembleForceRegressor.pool`) once, before the first step,
            instead of at every step. Members with an ``augment`` callable still read and
            pool their batches at every step.

    With ``progress=None`` and stderr not a terminal, one plain line per validation pass
    (step, training loss, validation MSE range, elapsed time and ETA) replaces the bar.

    Example:
        >>> from torch.utils.data import TensorDataset
        >>> g = torch.Generator().manual_seed(0)
        >>> x = torch.poisson(torch.full((6, 5, 2, 8, 8), 0.5), generator=g)
        >>> data = TensorDataset(x, x.sum((2, 3, 4)) / 20)
        >>> _ = torch.manual_seed(0)
        >>> ensemble = EnsembleForceRegressor(2, hidden_channels=(2,), input_pool=2)
        >>> result = fit_ensemble(ensemble, [data, data], data, steps=6, batch_size=2,
        ...                       seeds=[0, 1], eval_every=3, select="best", progress=False)
        >>> [m.val_steps for m in result.members], len(result.members[0].train_loss)
        ([[3, 6], [3, 6]], 6)
    """
    try:
        from tqdm.auto import tqdm
    except ImportError as error:
        raise ImportError(
            "the training loop needs tqdm, which is not installed: pip install 'event-transforms[app]'",
            name="tqdm",
        ) from error

    from .baselines import stack_items
    from .training import Stopwatch, collate

    if not isinstance(model, EnsembleForceRegressor):
        raise TypeError(f"model must be an EnsembleForceRegressor, got {type(model).__name__}")
    members = model.members
    steps = _check_positive_int(steps, "steps")
    batch_size = _check_positive_int(batch_size, "batch_size")
    val_batch_size = _check_positive_int(val_batch_size, "val_batch_size")
    eval_every = max(1, steps // 20) if eval_every is None else _check_positive_int(eval_every, "eval_every")
    if patience is not None:
        _check_positive_int(patience, "patience")
    if augment is not None and len(augment) != members:
        raise ValueError(f"augment must hold one callable or None per member ({members}), got {len(augment)}")
    if isinstance(train_sets, (str, bytes)) or not isinstance(train_sets, Sequence) or len(train_sets) != members:
        raise ValueError(f"train_sets must hold one Dataset per member ({members}), got {train_sets!r:.80}")
    seeds = list(seeds)
    if len(seeds) != members or not all(isinstance(s, int) and not isinstance(s, bool) for s in seeds):
        raise ValueError(f"seeds must be {members} ints, one per member, got {seeds!r}")
    if select not in ("final", "best"):
        raise ValueError(f"select must be 'final' or 'best', got {select!r}")
    if schedule not in ("one-cycle", "cosine", "constant"):
        raise ValueError(f"schedule must be 'one-cycle', 'cosine' or 'constant', got {schedule!r}")
    if not (isinstance(lr_max, (int, float)) and math.isfinite(lr_max) and lr_max > 0):
        raise ValueError(f"lr_max must be a positive number, got {lr_max!r}")
    if clip is not None and not (isinstance(clip, (int, float)) and math.isfinite(clip) and clip > 0):
        raise ValueError(f"clip must be a positive number or None, got {clip!r}")
    for index, data in enumerate(train_sets):
        if len(data) == 0:
            raise ValueError(f"train_sets[{index}] is empty")

    if not isinstance(fixed_data, bool):
        raise TypeError(f"fixed_data must be a bool, got {fixed_data!r}")
    device = model.head_weight.device if device is None else torch.device(device)
    model.to(device)
    val_frames, val_force = stack_items(val_data)
    val_frames, val_force = model.pool(val_frames.to(device)), val_force.to(device)
    # fixed data: each set's items pooled once, (N, T, C, h, w) and (N, T), shared by members
    pooled_sets: dict[int, tuple[Tensor, Tensor]] = {}
    if fixed_data:
        for m, data in enumerate(train_sets):
            if (augment is None or augment[m] is None) and id(data) not in pooled_sets:
                chunks, forces = [], []
                for first in range(0, len(data), 16):  # 16 raw items in memory at a time
                    frames, force, _ = collate([data[i] for i in range(first, min(first + 16, len(data)))])
                    chunks.append(model.pool(frames.to(device)))
                    forces.append(force.to(device))
                pooled_sets[id(data)] = (torch.cat(chunks), torch.cat(forces))
    if batches is None:
        batches = [shuffled_batches(len(data), batch_size, steps, seed=seed) for data, seed in zip(train_sets, seeds)]
    else:
        batches = [torch.as_tensor(b, dtype=torch.int64) for b in batches]
        if len(batches) != members:
            raise ValueError(f"batches must hold one index tensor per member ({members}), got {len(batches)}")
        for index, (b, data) in enumerate(zip(batches, train_sets)):
            if tuple(b.shape) != (steps, batch_size) or (b.numel() and not 0 <= int(b.min()) <= int(b.max()) < len(data)):
                raise ValueError(
                    f"batches[{index}] must be ({steps}, {batch_size}) indices into train_sets[{index}] "
                    f"({len(data)} items), got shape {tuple(b.shape)}"
                )
    watch = stopwatch if stopwatch is not None else Stopwatch()
    params = list(model.parameters())
    optimiser = torch.optim.Adam(params, lr=lr_max)
    scheduler: torch.optim.lr_scheduler.LRScheduler | None
    if schedule == "one-cycle":
        scheduler = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=lr_max, total_steps=steps)
    elif schedule == "cosine":
        scheduler = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=steps)
    else:
        scheduler = None

    records = [MemberRecord(member=m, seed=seeds[m], steps=0) for m in range(members)]
    losses = torch.zeros(steps, members, dtype=torch.float64, device=device)
    best = [p.detach().clone() for p in params]
    frozen = torch.zeros(members, dtype=torch.bool, device=device)
    frozen_host = [False] * members
    frozen_state: list[Tensor] | None = None
    waited = [0] * members
    logged = 0
    train_s = val_s = 0.0
    aug_start, start = watch.seconds, time.perf_counter()
    bar = tqdm(range(steps), desc=description, disable=None if progress is None else not progress,
               leave=False, dynamic_ncols=True)
    plain = progress is None and bool(bar.disable)  # not a terminal: plain progress lines
    model.train()
    step = 0
    for step in bar:
        tick = time.perf_counter()
        inputs, targets = [], []
        for m in range(members):
            indices = batches[m][step]
            if id(train_sets[m]) in pooled_sets and (augment is None or augment[m] is None):
                pooled, force = pooled_sets[id(train_sets[m])]
                rows = indices.to(device)
                inputs.append(pooled.index_select(0, rows))
                targets.append(force.index_select(0, rows))
                continue
            frames, force, metas = _stack_member_batch(train_sets[m], indices, collate)
            frames = frames.to(device, non_blocking=True)
            member_augment = None if augment is None else augment[m]
            if member_augment is not None:
                frames = member_augment(frames, metas)
            inputs.append(model.pool(frames))  # pooled per member: M small tensors stacked
            targets.append(force.to(device, non_blocking=True))
        frames, force = torch.stack(inputs), torch.stack(targets)
        pred = model(frames, pooled=True)
        per_member = (pred - force.to(pred.dtype)).square().mean(dim=(1, 2))
        optimiser.zero_grad(set_to_none=True)
        per_member.sum().backward()
        if clip is not None:
            clip_grad_norm_per_member_(params, clip)
        optimiser.step()
        if frozen_state is not None:
            with torch.no_grad():
                for p, saved in zip(params, frozen_state):
                    p.copy_(torch.where(frozen.view(-1, *([1] * (p.dim() - 1))), saved, p))
        if scheduler is not None:
            scheduler.step()
        losses[step] = per_member.detach().double()
        train_s += time.perf_counter() - tick
        if (step + 1) % eval_every and step + 1 != steps:
            continue
        tick = time.perf_counter()
        val = _validation_mse(model, val_frames, val_force, val_batch_size).tolist()
        history = losses[logged : step + 1].tolist()
        logged = step + 1
        newly_frozen = []
        for m, record in enumerate(records):
            if frozen_host[m]:
                continue
            record.train_loss.extend(row[m] for row in history)
            record.steps = step + 1
            record.val_steps.append(step + 1)
            record.val_loss.append(val[m])
            if val[m] < record.best_val_loss:
                record.best_val_loss, record.best_step, waited[m] = val[m], step + 1, 0
                with torch.no_grad():
                    for p, saved in zip(params, best):
                        saved[m].copy_(p[m])
            else:
                waited[m] += 1
                if patience is not None and waited[m] >= patience and step + 1 != steps:
                    newly_frozen.append(m)
        if newly_frozen:
            with torch.no_grad():
                if frozen_state is None:
                    frozen_state = [p.detach().clone() for p in params]
                for m in newly_frozen:
                    frozen_host[m] = True
                    records[m].stopped_step = step + 1
                    for p, saved in zip(params, frozen_state):
                        saved[m].copy_(p[m])
                frozen[newly_frozen] = True
        val_s += time.perf_counter() - tick
        active = [val[m] for m in range(members) if not frozen_host[m]]
        train_now = sum(history[-1]) / max(len(history[-1]), 1) if history else math.nan
        bar.set_postfix(loss=f"{train_now:.3g}", val=f"{min(val):.3g}-{max(val):.3g}", active=len(active))
        if on_validation is not None:
            on_validation({"step": step + 1, "steps": steps, "train_loss": train_now, "val_mse": val,
                           "elapsed_s": time.perf_counter() - start})
        if plain:
            elapsed = time.perf_counter() - start
            eta = elapsed / (step + 1) * (steps - step - 1)
            print(f"{description}: step {step + 1}/{steps}, train loss {train_now:.3g}, "
                  f"val MSE {min(val):.3g}-{max(val):.3g}, {elapsed:.0f} s elapsed, ETA {eta:.0f} s",
                  file=sys.stderr, flush=True)
        if all(frozen_host):
            break
    bar.close()

    with torch.no_grad():
        for m, record in enumerate(records):
            if select == "best":
                for p, saved in zip(params, best):
                    p[m].copy_(saved[m])
                record.selected_val_loss = record.best_val_loss
            else:
                record.selected_val_loss = record.val_loss[-1]
    return EnsembleResult(
        members=records,
        steps=step + 1,
        select=select,
        schedule=schedule,
        train_s=train_s,
        val_s=val_s,
        augmentation_s=watch.seconds - aug_start,
        total_s=time.perf_counter() - start,
    )
