"""Reference ConvLSTM force regressor (the paper's best architecture, from its reference [17]).

The paper's best regressor (its ref. [17]) is a ConvLSTM whose exact layer sizes are not
public; this module gives a small, documented stand-in that trains in minutes on a CPU:

``counts --avg-pool--> log1p --ConvLSTM--> (avg-pool --ConvLSTM)... --> mean+max over
(H, W) --> linear --> force per frame``.

Gate arithmetic: for input ``x_t`` and state ``(h_{t-1}, c_{t-1})``

.. math::

    [i, f, g, o] = W_x * x_t + W_h * h_{t-1} + b \\qquad (* = \\text{2-D convolution})

    c_t = \\sigma(f) \\odot c_{t-1} + \\sigma(i) \\odot \\tanh(g), \\qquad
    h_t = \\sigma(o) \\odot \\tanh(c_t)

with the gate order **i, f, g, o** along the channel axis (PyTorch's ``nn.LSTM`` order,
and Keras's ``i, f, c, o``). ``σ`` is the logistic sigmoid or, with
``recurrent_activation="hard_sigmoid"``, Keras 2's ``clip(0.2 x + 0.5, 0, 1)``.
The gates and the cell state are computed in float32 even under ``torch.autocast``, so a
1,000-frame sequence in bfloat16 stays finite.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import torch
import torch.nn.functional as F
from torch import Tensor, nn

__all__ = ["ConvLSTMCell", "ConvLSTM", "ForceRegressor", "State"]

#: Recurrent state of a stack of ConvLSTM layers: one ``(h, c)`` pair per layer (and, for a
#: ``ForceRegressor(cumulative=True)``, a last entry ``(running_sum,)``).
State = list[tuple[Tensor, ...]]

_ACTIVATIONS = ("sigmoid", "hard_sigmoid")
_CHECKPOINT_FORMAT = 1


def _hard_sigmoid(x: Tensor) -> Tensor:
    return torch.clamp(0.2 * x + 0.5, 0.0, 1.0)


def _as_pair(value: int | Sequence[int], name: str) -> tuple[int, int]:
    if isinstance(value, bool):
        raise TypeError(f"{name} must be a positive int or a pair of them, got {value!r}")
    if isinstance(value, int):
        pair = (value, value)
    elif isinstance(value, Sequence) and len(value) == 2 and all(
        isinstance(v, int) and not isinstance(v, bool) for v in value
    ):
        pair = (int(value[0]), int(value[1]))
    else:
        raise TypeError(f"{name} must be a positive int or a pair of them, got {value!r}")
    if min(pair) < 1:
        raise ValueError(f"{name} must be positive, got {value!r}")
    return pair


def _check_positive_int(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{name} must be a positive int, got {value!r}")
    if value < 1:
        raise ValueError(f"{name} must be a positive int, got {value!r}")
    return value


def _pair(entry: tuple[Tensor, ...], name: str) -> tuple[Tensor, Tensor]:
    """A layer's ``(h, c)`` state entry, checked to be a pair."""
    if len(entry) != 2:
        raise ValueError(f"{name} must be an (h, c) pair, got {len(entry)} entries")
    return entry[0], entry[1]


_FEATURES = ("linear", "log1p", "signed")
_READOUTS = ("mean", "mean+max")


def _feature_channels(in_channels: int, cumulative: bool, features: str = "log1p") -> int:
    """Channels the first ConvLSTM layer reads (see :func:`_input_features`)."""
    signed = features == "signed" and in_channels == 2
    if not cumulative:
        return 1 if signed else in_channels
    if features == "log1p":
        return 2 * in_channels + (1 if in_channels == 2 else 0)
    if signed:
        return 2
    return in_channels + (1 if in_channels == 2 else in_channels)


def _global_channels(in_channels: int, cumulative: bool, features: str) -> int:
    """Entries of :func:`_global_features`: one per input channel, plus the squared signed total."""
    channels = _feature_channels(in_channels, cumulative, features)
    return channels + (1 if _has_square(in_channels, cumulative, features) else 0)


def _has_square(in_channels: int, cumulative: bool, features: str) -> bool:
    return cumulative and features in ("linear", "signed") and in_channels == 2


def _global_features(x: Tensor, square: bool) -> Tensor:
    """First-layer input ``(N, C', h, w)`` -> its spatial means ``(N, C')`` (``+ 1``: the
    square of the last, the signed running total, when ``square``)."""
    means = x.mean(dim=(-2, -1))
    return torch.cat([means, means[:, -1:].square()], dim=-1) if square else means


def _pool_counts(frames: Tensor, pool: int, dtype: torch.dtype) -> Tensor:
    """``(..., C, H, W)`` counts -> ``(..., C, H // pool, W // pool)`` averages in ``dtype``."""
    x = frames.to(dtype)
    if pool > 1:
        x = F.avg_pool2d(x.flatten(0, -4), pool).unflatten(0, x.shape[:-3])
    return x


def _input_features(
    pooled: Tensor, cumulative: bool, running: Tensor | None = None, features: str = "log1p"
) -> tuple[Tensor, Tensor | None]:
    """Pooled counts ``(B, T, C, h, w)`` -> network input ``(B, T, C', h, w)``.

    ``features="signed"``: for two polarities the frame's ``OFF - ON`` pooled count and, with
    ``cumulative``, the signed running sum ``d = Σ OFF - Σ ON``; ``features="linear"``: the
    pooled counts of each channel as they are and, with ``cumulative``, ``d`` (for other
    channel counts than two, both read each channel's count and running sum): every feature
    adds up linearly over pixels and frames.
    ``features="log1p"``: ``log1p`` of the pooled counts; with ``cumulative``, also
    ``log1p`` of each channel's running sum over time and, for two polarities,
    ``sign(d) log1p(|d|)``. Sums run in float64 from ``running`` (``(B, C, h, w)``, the sum
    before the first frame; ``None`` = zero). Returns the features and the running sum
    after the last frame (``None`` without ``cumulative``).
    """
    linear = features in ("linear", "signed")
    values = pooled if linear else torch.log1p(pooled)
    if features == "signed" and pooled.shape[2] == 2:
        values = pooled[:, :, :1] - pooled[:, :, 1:]
    if not cumulative:
        return values, None
    sums = pooled.double().cumsum(dim=1)
    if running is not None:
        sums = sums + running.to(sums.dtype).unsqueeze(1)
    signed = sums[:, :, :1] - sums[:, :, 1:] if pooled.shape[2] == 2 else None
    if linear:
        extra = [sums if signed is None else signed]
    else:
        extra = [torch.log1p(sums)]
        if signed is not None:
            extra.append(torch.sign(signed) * torch.log1p(signed.abs()))
    values = torch.cat([values, *(e.to(values.dtype) for e in extra)], dim=2)
    if pooled.shape[1]:
        last = sums[:, -1]
    else:
        last = running if running is not None else sums.new_zeros(pooled.shape[:1] + pooled.shape[2:])
    return values, last


class ConvLSTMCell(nn.Module):
    """One ConvLSTM step: ``(x_t, (h, c)) -> (h', c')``.

    The input and recurrent convolutions are separate (``input_conv`` with the bias,
    ``recurrent_conv`` without), so a layer can convolve a whole sequence's inputs in one
    call and only loop over the recurrent part. Padding is ``"same"``: ``h`` has the
    input's (H, W).

    Initialisation (:meth:`reset_parameters`, as Keras ``ConvLSTM2D``): input kernels
    Glorot-uniform per gate, recurrent kernel orthogonal, bias zero except the forget
    gate's, which is 1 (``unit_forget_bias``).

    Args:
        in_channels: channels of ``x``.
        hidden_channels: channels of ``h`` and ``c``.
        kernel_size: convolution kernel, int or (kH, kW); used for both convolutions.
        bias: add a learnable bias to the gates.
        recurrent_activation: ``"sigmoid"`` or ``"hard_sigmoid"`` (Keras 2's
            ``clip(0.2 x + 0.5, 0, 1)``) for the gates i, f, o.

    Shape:
        - x: ``(B, C_in, H, W)``
        - hx: ``None`` (zero state) or a pair ``(h, c)`` of ``(B, C_hidden, H, W)``
        - output: ``(h', c')``, each ``(B, C_hidden, H, W)``, float32 (or float64 for a
          float64 model)

    Example:
        >>> _ = torch.manual_seed(0)
        >>> cell = ConvLSTMCell(2, 4, 3)
        >>> h, c = cell(torch.rand(1, 2, 5, 6))
        >>> h, c = cell(torch.rand(1, 2, 5, 6), (h, c))
        >>> tuple(h.shape), bool(h.abs().max() < 1)
        ((1, 4, 5, 6), True)
    """

    def __init__(
        self,
        in_channels: int,
        hidden_channels: int,
        kernel_size: int | Sequence[int] = 3,
        bias: bool = True,
        recurrent_activation: str = "sigmoid",
    ) -> None:
        super().__init__()
        self.in_channels = _check_positive_int(in_channels, "in_channels")
        self.hidden_channels = _check_positive_int(hidden_channels, "hidden_channels")
        self.kernel_size = _as_pair(kernel_size, "kernel_size")
        if recurrent_activation not in _ACTIVATIONS:
            raise ValueError(
                f"recurrent_activation must be one of {_ACTIVATIONS}, got {recurrent_activation!r}"
            )
        self.recurrent_activation = recurrent_activation
        self.input_conv = nn.Conv2d(
            in_channels, 4 * hidden_channels, self.kernel_size, padding="same", bias=bias
        )
        self.recurrent_conv = nn.Conv2d(
            hidden_channels, 4 * hidden_channels, self.kernel_size, padding="same", bias=False
        )
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """Glorot-uniform input kernels per gate, orthogonal recurrent kernel, forget bias 1."""
        hidden = self.hidden_channels
        kh, kw = self.kernel_size
        with torch.no_grad():
            for gate in range(4):
                block = self.input_conv.weight[gate * hidden : (gate + 1) * hidden]
                fan_in, fan_out = self.in_channels * kh * kw, hidden * kh * kw
                bound = math.sqrt(6.0 / (fan_in + fan_out))
                block.uniform_(-bound, bound)
            recurrent = torch.empty(4 * hidden, hidden * kh * kw)
            nn.init.orthogonal_(recurrent)
            self.recurrent_conv.weight.copy_(recurrent.view_as(self.recurrent_conv.weight))
            if self.input_conv.bias is not None:
                self.input_conv.bias.zero_()
                self.input_conv.bias[hidden : 2 * hidden].fill_(1.0)

    def _gate(self, x: Tensor) -> Tensor:
        return _hard_sigmoid(x) if self.recurrent_activation == "hard_sigmoid" else torch.sigmoid(x)

    def zero_state(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """A zero ``(h, c)`` matching ``x`` ``(B, C_in, H, W)`` in batch, size and device."""
        dtype = torch.promote_types(self.input_conv.weight.dtype, torch.float32)
        shape = (x.shape[0], self.hidden_channels, x.shape[-2], x.shape[-1])
        zeros = torch.zeros(shape, dtype=dtype, device=x.device)
        return zeros, zeros

    def step_gates(
        self, input_gates: Tensor, hx: tuple[Tensor, Tensor]
    ) -> tuple[Tensor, Tensor]:
        """Advance one step from precomputed ``input_conv(x)`` (``(B, 4 C_hidden, H, W)``)."""
        h, c = hx
        gates = input_gates.to(c.dtype) + self.recurrent_conv(h).to(c.dtype)
        i, f, g, o = gates.chunk(4, dim=1)
        c = self._gate(f) * c + self._gate(i) * torch.tanh(g)
        h = self._gate(o) * torch.tanh(c)
        return h, c

    def forward(
        self, x: Tensor, hx: tuple[Tensor, Tensor] | None = None
    ) -> tuple[Tensor, Tensor]:
        """One step; ``hx=None`` starts from the zero state."""
        if x.dim() != 4 or x.shape[1] != self.in_channels:
            raise ValueError(
                f"x: expected (B, {self.in_channels}, H, W), got {tuple(x.shape)}"
            )
        if hx is None:
            hx = self.zero_state(x)
        return self.step_gates(self.input_conv(x), hx)

    def extra_repr(self) -> str:
        return (
            f"{self.in_channels}, {self.hidden_channels}, kernel_size={self.kernel_size}, "
            f"recurrent_activation={self.recurrent_activation!r}"
        )


class ConvLSTM(nn.Module):
    """Stacked ConvLSTM layers over a batch-first sequence ``(B, T, C, H, W)``.

    Layer ``l`` reads the hidden sequence of layer ``l - 1``. Each layer convolves all
    ``T`` inputs in one call and loops over time only for the recurrent convolution.

    Args:
        in_channels: channels of the input frames.
        hidden_channels: channels per layer; an int means one layer.
        kernel_size: kernel of every layer.
        bias: gate bias in every layer.
        recurrent_activation: ``"sigmoid"`` or ``"hard_sigmoid"``.

    Shape:
        - x: ``(B, T, C_in, H, W)``
        - hx: ``None`` or a list of ``(h, c)`` per layer
        - output: ``(sequence, state)``; ``sequence`` is the last layer's hidden states
          ``(B, T, C_last, H, W)`` and ``state`` the list of final ``(h, c)`` per layer.

    Example:
        >>> _ = torch.manual_seed(0)
        >>> lstm = ConvLSTM(2, [4, 3])
        >>> out, state = lstm(torch.rand(2, 5, 2, 6, 7))
        >>> tuple(out.shape), len(state), tuple(state[1][0].shape)
        ((2, 5, 3, 6, 7), 2, (2, 3, 6, 7))
    """

    def __init__(
        self,
        in_channels: int,
        hidden_channels: int | Sequence[int],
        kernel_size: int | Sequence[int] = 3,
        bias: bool = True,
        recurrent_activation: str = "sigmoid",
    ) -> None:
        super().__init__()
        hidden = [hidden_channels] if isinstance(hidden_channels, int) else list(hidden_channels)
        if not hidden:
            raise ValueError(f"hidden_channels must name at least one layer, got {hidden_channels!r}")
        inputs = [in_channels, *hidden[:-1]]
        self.cells = nn.ModuleList(
            ConvLSTMCell(c_in, c_h, kernel_size, bias, recurrent_activation)
            for c_in, c_h in zip(inputs, hidden)
        )

    @property
    def layers(self) -> tuple[ConvLSTMCell, ...]:
        """The layers' cells in order: the items of :attr:`cells` (an ``nn.ModuleList``), typed."""
        return tuple(cast(ConvLSTMCell, cell) for cell in self.cells)

    @staticmethod
    def run_layer(
        cell: ConvLSTMCell, x: Tensor, hx: tuple[Tensor, Tensor] | None
    ) -> tuple[Tensor, tuple[Tensor, Tensor]]:
        """Run one cell over ``x`` ``(B, T, C, H, W)``; return hidden sequence and last state."""
        batch, steps = x.shape[:2]
        if hx is None:
            hx = cell.zero_state(x[:, 0] if steps else x.new_zeros(batch, *x.shape[2:]))
        input_gates = cell.input_conv(x.flatten(0, 1)).unflatten(0, (batch, steps))
        outputs = []
        # unbind, not input_gates[:, t]: indexing makes autograd build a full-size zero
        # gradient per step (O(T^2) memory traffic); unbind's backward stacks once.
        for gates in input_gates.unbind(1):
            hx = cell.step_gates(gates, hx)
            outputs.append(hx[0])
        if not outputs:
            return hx[0].unsqueeze(1)[:, :0], hx
        return torch.stack(outputs, dim=1), hx

    def forward(self, x: Tensor, hx: State | None = None) -> tuple[Tensor, State]:
        """Run every layer over the sequence."""
        if x.dim() != 5:
            raise ValueError(f"x: expected (B, T, C, H, W), got {tuple(x.shape)}")
        if hx is not None and len(hx) != len(self.cells):
            raise ValueError(f"hx must hold one (h, c) per layer ({len(self.cells)}), got {len(hx)}")
        state: State = []
        for index, cell in enumerate(self.layers):
            x, last = self.run_layer(cell, x, None if hx is None else _pair(hx[index], f"hx[{index}]"))
            state.append(last)
        return x, state


class ForceRegressor(nn.Module):
    """Event frames ``(B, T, 2, H, W)`` to contact force per frame ``(B, T)`` in newtons.

    Per frame: an ``input_pool`` x ``input_pool`` average pool of the counts (events per
    pixel), the input features, then one ConvLSTM layer per entry of ``hidden_channels``
    with a 2x2 average pool between layers, then a spatial pooling of the last hidden state
    and a linear head. The output is ``force_offset + force_scale * head(...)``; the two
    buffers (default 0 and 1) let a trainer standardise the targets while the model keeps
    answering in newtons (:meth:`set_force_scaling`).

    **Why these defaults** (issue 17). Force is an integral of the events (the membrane's
    indentation): a 40-parameter least-squares model on the running signed event total
    beat the earlier network, whose per-cell ``log1p`` features and max over space let a
    hot pixel or a rotated contact own its input. So by default:

    - ``features="signed"``, ``cumulative=True``: per cell, the frame's ``OFF - ON``
      pooled count and the signed running sum ``d = Σ OFF - Σ ON`` (float64 sums), as they
      are, so a sum over pixels of the input is a sum of events, and background activity
      and hot pixels, which fire both polarities, cancel. ``features="linear"`` reads the
      OFF and ON counts separately (and ``d``); on the ``noise`` scene it scored 9.5 N² on
      validation data against 0.39 for ``"signed"``. ``features="log1p"`` is the earlier
      input (``log1p`` of counts, of each running sum and ``sign(d) log1p(|d|)``; with
      ``cumulative=False`` only ``log1p`` counts).
    - ``readout="mean"``: the spatial mean of the last hidden state, which no single pixel
      can own; ``"mean+max"`` is the earlier readout.
    - ``global_inputs=True``: the head also reads the spatial mean of every input channel
      (by default the frame's ``OFF - ON`` total and the running signed total, per pixel)
      and the square of the running signed total, a linear path that holds the physics
      least-squares model
      (:class:`~event_transforms.tactile.baselines.PhysicsLeastSquares`; with
      ``features="linear"`` all of it but its per-frame intercepts, which the ConvLSTM's
      state supplies).

    :meth:`step` runs the same network one 10 ms frame at a time, for online use, and gives
    the same numbers as :meth:`forward` on the whole sequence (the running sum is carried
    in the state).

    Args:
        in_channels: polarity channels of the frames (2).
        hidden_channels: ConvLSTM channels per layer.
        kernel_size: ConvLSTM kernel.
        input_pool: average-pool factor applied to every frame first (1 = none).
        recurrent_activation: ``"sigmoid"`` or ``"hard_sigmoid"`` (Keras 2 parity).
        cumulative: add the running sums of the pooled counts as input channels.
        features: ``"signed"``, ``"linear"`` or ``"log1p"`` input features (see above).
        readout: ``"mean"`` or ``"mean+max"`` spatial pooling of the last hidden state.
        global_inputs: the head also reads the spatial means of the input features.

    Shape:
        - frames: ``(B, T, 2, H, W)``, any real dtype, non-negative counts
        - output: ``(B, T)`` float32 (float64 for a float64 model)

    Example:
        >>> _ = torch.manual_seed(0)
        >>> model = ForceRegressor(hidden_channels=(4,), input_pool=10)
        >>> frames = torch.poisson(torch.full((1, 4, 2, 70, 75), 0.5))
        >>> force = model(frames)
        >>> state = None
        >>> steps = []
        >>> for t in range(4):
        ...     f, state = model.step(frames[:, t], state)
        ...     steps.append(f)
        >>> tuple(force.shape), torch.allclose(torch.stack(steps, 1), force, atol=1e-5)
        ((1, 4), True)
        >>> # inputs: the OFF - ON count + the signed running sum; state: 1 layer + the sum
        >>> model.lstm.cells[0].in_channels, len(state)
        (2, 2)
        >>> # head: 4 hidden means + 2 input means + the squared signed total
        >>> model.head.in_features
        7
    """

    # buffers (register_buffer) and the attributes :meth:`load` sets, declared for the type checker
    force_offset: Tensor
    force_scale: Tensor
    preprocessing: dict[str, Any]
    package_version: str

    def __init__(
        self,
        in_channels: int = 2,
        hidden_channels: int | Sequence[int] = (8, 16),
        kernel_size: int | Sequence[int] = 3,
        input_pool: int = 4,
        recurrent_activation: str = "sigmoid",
        cumulative: bool = True,
        features: str = "signed",
        readout: str = "mean",
        global_inputs: bool = True,
    ) -> None:
        super().__init__()
        self.in_channels = _check_positive_int(in_channels, "in_channels")
        self.input_pool = _check_positive_int(input_pool, "input_pool")
        for name, value in (("cumulative", cumulative), ("global_inputs", global_inputs)):
            if not isinstance(value, bool):
                raise TypeError(f"{name} must be a bool, got {value!r}")
        if features not in _FEATURES:
            raise ValueError(f"features must be one of {_FEATURES}, got {features!r}")
        if readout not in _READOUTS:
            raise ValueError(f"readout must be one of {_READOUTS}, got {readout!r}")
        self.cumulative, self.features, self.readout = cumulative, features, readout
        self.global_inputs = global_inputs
        channels = _feature_channels(in_channels, cumulative, features)
        self.lstm = ConvLSTM(channels, hidden_channels, kernel_size, True, recurrent_activation)
        last = self.lstm.layers[-1].hidden_channels
        width = (2 if readout == "mean+max" else 1) * last
        if global_inputs:
            width += _global_channels(in_channels, cumulative, features)
        self.head = nn.Linear(width, 1)
        self.register_buffer("force_offset", torch.zeros(()))
        self.register_buffer("force_scale", torch.ones(()))

    @property
    def config(self) -> dict[str, object]:
        """The constructor's keyword arguments: ``ForceRegressor(**model.config)`` rebuilds it."""
        first = self.lstm.layers[0]
        return {
            "in_channels": self.in_channels,
            "hidden_channels": tuple(cell.hidden_channels for cell in self.lstm.layers),
            "kernel_size": first.kernel_size,
            "input_pool": self.input_pool,
            "recurrent_activation": first.recurrent_activation,
            "cumulative": self.cumulative,
            "features": self.features,
            "readout": self.readout,
            "global_inputs": self.global_inputs,
        }

    def set_force_scaling(self, offset: float, scale: float) -> None:
        """Set the affine map from the head's output to newtons (e.g. target mean and std)."""
        if not (math.isfinite(offset) and math.isfinite(scale) and scale > 0):
            raise ValueError(
                f"offset must be finite and scale finite and positive, got {offset!r}, {scale!r}"
            )
        self.force_offset.fill_(offset)
        self.force_scale.fill_(scale)

    def save(self, path: str | os.PathLike[str], *, preprocessing: dict[str, Any] | None = None) -> None:
        """Write a checkpoint: weights, :attr:`config`, force scaling, the package version and
        ``preprocessing`` (how frames were made: ``frame_ms``, ``crop``, ``pool``, ...), to a
        temporary file renamed into place (nothing half-written stays).

        Example:
            >>> import tempfile
            >>> path = os.path.join(tempfile.mkdtemp(), "model.pt")
            >>> model = ForceRegressor(hidden_channels=(4,), input_pool=10)
            >>> model.set_force_scaling(5.0, 2.0)
            >>> model.save(path, preprocessing={"frame_ms": 10.0, "crop": [0, 0, 140, 150], "pool": 2})
            >>> restored = ForceRegressor.load(path)
            >>> restored.config == model.config, restored.preprocessing["pool"], float(restored.force_scale)
            (True, 2, 2.0)
        """
        from .. import __version__
        from .datasets import _atomic_save

        config = {k: list(v) if isinstance(v, tuple) else v for k, v in self.config.items()}
        _atomic_save({"format": _CHECKPOINT_FORMAT, "package_version": __version__, "config": config,
                      "state_dict": {k: v.detach().cpu() for k, v in self.state_dict().items()},
                      "preprocessing": dict(preprocessing or {})}, Path(path))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ForceRegressor:
        """A model from a checkpoint of :meth:`save` (on the CPU, in eval mode); its
        ``preprocessing`` dict and ``package_version`` become attributes.

        Raises:
            ValueError: naming ``path`` when it is missing, unreadable or not a checkpoint.
        """
        try:
            checkpoint = torch.load(path, map_location="cpu", weights_only=True)
            if not isinstance(checkpoint, dict) or checkpoint.get("format") != _CHECKPOINT_FORMAT:
                raise ValueError("not a ForceRegressor checkpoint of this version")
            config: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in checkpoint["config"].items()}
            model = cls(**config)
            model.load_state_dict(checkpoint["state_dict"])
        except Exception as error:  # noqa: BLE001 - one line naming the file, never a raw traceback
            first = str(error).splitlines()[0] if str(error) else ""
            raise ValueError(f"cannot load a model from {str(path)!r} ({type(error).__name__}: {first})") from None
        model.preprocessing = dict(checkpoint.get("preprocessing") or {})
        model.package_version = str(checkpoint.get("package_version"))
        return model.eval()

    def _check(self, frames: Tensor, rank: int, layout: str) -> None:
        if not isinstance(frames, Tensor):
            raise TypeError(f"frames must be a torch.Tensor, got {type(frames).__name__}")
        if frames.dim() != rank or frames.shape[-3] != self.in_channels:
            raise ValueError(f"frames: expected {layout}, got {tuple(frames.shape)}")
        if min(frames.shape[-2:]) < self.input_pool:
            raise ValueError(
                f"frames: (H, W) = {tuple(frames.shape[-2:])} is smaller than "
                f"input_pool={self.input_pool}"
            )

    def _readout(self, h: Tensor, x: Tensor) -> Tensor:
        """Last hidden state ``(N, C, h, w)`` and first-layer input ``(N, C', h', w')`` ->
        force ``(N,)``."""
        parts = [h.mean(dim=(-2, -1))]
        if self.readout == "mean+max":
            parts.append(h.amax(dim=(-2, -1)))
        if self.global_inputs:
            square = _has_square(self.in_channels, self.cumulative, self.features)
            parts.append(_global_features(x, square).to(parts[0].dtype))
        features = torch.cat(parts, dim=-1)
        out = self.head(features.to(self.head.weight.dtype)).squeeze(-1)
        # float32 (under autocast too), but a float64 model's output stays float64 throughout
        out = out.double() if self.head.weight.dtype == torch.float64 else out.float()
        return self.force_offset.to(out.dtype) + self.force_scale.to(out.dtype) * out

    def forward(self, frames: Tensor) -> Tensor:
        """Force per frame for a batch of sequences."""
        self._check(frames, 5, f"(B, T, {self.in_channels}, H, W)")
        batch, steps = frames.shape[:2]
        pooled = _pool_counts(frames, self.input_pool, self.head.weight.dtype)
        inputs, _ = _input_features(pooled, self.cumulative, features=self.features)
        x = inputs
        for index, cell in enumerate(self.lstm.layers):
            if index:
                x = F.avg_pool2d(x.flatten(0, 1), 2).unflatten(0, (batch, steps))
            x, _ = ConvLSTM.run_layer(cell, x, None)
        force = self._readout(x.flatten(0, 1), inputs.flatten(0, 1))
        return force.unflatten(0, (batch, steps))

    def step(self, frame: Tensor, state: State | None = None) -> tuple[Tensor, State]:
        """One frame ``(B, 2, H, W)`` -> force ``(B,)`` and the new state.

        ``state=None`` starts a new sequence. Feeding the frames of a sequence one by one
        gives the numbers :meth:`forward` gives for the whole sequence. The state holds one
        ``(h, c)`` per layer and, with ``cumulative=True``, a last entry ``(running_sum,)``:
        the pooled counts summed over the frames so far, float64 ``(B, C, h, w)``.
        """
        self._check(frame, 4, f"(B, {self.in_channels}, H, W)")
        layers = len(self.lstm.cells)
        if state is not None and len(state) != layers + self.cumulative:
            extra = " and the running sum" if self.cumulative else ""
            raise ValueError(
                f"state must hold one (h, c) per layer ({layers}){extra}, got {len(state)} entries"
            )
        pooled = _pool_counts(frame, self.input_pool, self.head.weight.dtype)
        running = state[-1][0] if state is not None and self.cumulative else None
        inputs, running = _input_features(pooled.unsqueeze(1), self.cumulative, running, self.features)
        x = inputs = inputs[:, 0]
        new_state: State = []
        for index, cell in enumerate(self.lstm.layers):
            if index:
                x = F.avg_pool2d(x, 2)
            hx = cell.zero_state(x) if state is None else _pair(state[index], f"state[{index}]")
            hx = cell.step_gates(cell.input_conv(x), hx)
            new_state.append(hx)
            x = hx[0]
        if running is not None:
            new_state.append((running,))
        return self._readout(x, inputs), new_state

    def extra_repr(self) -> str:
        inputs = f"{self.features} input" + (" + cumulative sums" if self.cumulative else "")
        head = f"{self.readout} readout" + (" + global inputs" if self.global_inputs else "")
        return f"input_pool={self.input_pool}, {inputs}, {head}"
