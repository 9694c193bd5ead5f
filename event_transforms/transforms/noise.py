"""Noise modules: static-scene noise injection, Poisson background activity.

EventDrop and pixel removal are in :mod:`event_transforms.transforms.drop`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

import torch
from torch import Tensor

from .._validation import check_counts, check_frames, check_pair, check_positive, describe
from .. import functional as F
from ..events.batch import EventBatch
from ..functional._dispatch import call_kernel
from .._params import SEED
from ..functional._frame_ops import add_entries, poisson_totals
from ..functional.noise import ADD_POISSON_NOISE_SPEC
from .base import EventTransform, Param, Params, integers, seeds, uniform

__all__ = ["AddNoise", "AddPoissonNoise"]


class AddNoise(EventTransform):
    """Add a window of frames recorded (or simulated) in a static scene, drawn per sample.

    The bank is one long static-scene recording ``(N, 2, H, W)``; each sample gets the
    ``T`` consecutive frames starting at its own random offset in ``[0, N - T]``
    (``params["offset"]``). The bank is a buffer, so ``.to(device)`` moves it with the module.

    A sparse bank (at most a quarter of its pixels non-zero, as static scenes are) is also
    kept as its non-zero entries, found once when the bank is set (and again when a state
    dict is loaded): a call then costs one copy of the frames plus one ``index_add_`` of
    the window's entries, with no host synchronisation. Do not modify ``bank`` in place.

    Args:
        bank: non-negative counts ``(N, 2, H, W)`` with ``N >= T`` of the frames it is
            applied to and the frames' ``H, W``.
        p: probability that a sample gets noise.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype of the frames kept.

    Example:
        >>> bank = torch.arange(5.).view(5, 1, 1, 1).expand(5, 2, 3, 4)
        >>> transform = AddNoise(bank)
        >>> out = transform(torch.zeros(2, 3, 2, 3, 4), generator=torch.Generator().manual_seed(4))
        >>> out[:, :, 0, 0, 0].tolist()
        [[1.0, 2.0, 3.0], [2.0, 3.0, 4.0]]
    """

    bank: Tensor  # buffers (nn.Module.__getattr__ types them as Tensor | Module)
    _entry_values: Tensor | None

    def __init__(self, bank: Tensor, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        if not isinstance(bank, Tensor) or bank.dim() != 4 or bank.shape[1] != 2:
            shape = tuple(bank.shape) if isinstance(bank, Tensor) else type(bank).__name__
            raise ValueError(f"bank: expected static-scene frames (N, 2, H, W), got {shape}")
        check_frames(bank.unsqueeze(0), "bank")
        check_counts(bank, "bank")
        if bank.shape[0] == 0:
            raise ValueError("bank must hold at least one frame, got N = 0")
        self.register_buffer("bank", bank.clone())
        self._index_bank()

    def _index_bank(self) -> None:
        """Keep a sparse bank's non-zero entries: flat indices (host), values (buffer), and
        where each bank frame's entries start (host), or ``None`` for a dense bank."""
        flat = self.bank.reshape(-1)
        index = flat.nonzero().squeeze(1)
        frame = self.bank[0].numel()
        if frame == 0 or 4 * index.numel() > flat.numel():
            self._entries = None
            self.register_buffer("_entry_values", None, persistent=False)
            return
        host = np.asarray(index.tolist(), dtype=np.int64)
        self._entries = (host, np.searchsorted(host, np.arange(self.bank.shape[0] + 1) * frame))
        self.register_buffer("_entry_values", flat.index_select(0, index), persistent=False)

    def _load_from_state_dict(self, *args: Any, **kwargs: Any) -> None:
        super()._load_from_state_dict(*args, **kwargs)
        self._index_bank()

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b, t, _, h, w = shape
        n, _, bh, bw = self.bank.shape
        if (bh, bw) != (h, w) or n < t:
            raise ValueError(
                f"bank of shape {tuple(self.bank.shape)} cannot cover frames of shape {tuple(shape)}: "
                f"it needs H, W = {(h, w)} and at least T = {t} frames"
            )
        return {"offset": integers(n - t + 1, b, generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"offset": Param("int", low=0, high=max(self.bank.shape[0] - shape[1], 0))}

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        if isinstance(inputs, EventBatch):
            return call_kernel(F.add_noise, inputs, self.bank, params["offset"])
        frames = inputs
        b, t = frames.shape[:2]
        offset = np.asarray(params["offset"].tolist(), dtype=np.int64).reshape(b)  # CPU: no sync
        if b and (int(offset.max()) + t > self.bank.shape[0] or int(offset.min()) < 0):
            raise ValueError(
                f"params['offset'] must lie in [0, {self.bank.shape[0] - t}] for a bank of "
                f"{self.bank.shape[0]} frames and T = {t}, got {describe(params['offset'])}"
            )
        if self._entries is None or b == 0:
            return call_kernel(F.add_noise, frames, self.bank, params["offset"])
        # Sparse bank: entries of frames [offset, offset + T) of the bank, moved to sample b.
        host, start = self._entries
        frame = self.bank[0].numel()
        low, high = start[offset], start[offset + t]
        counts = high - low
        select = np.repeat(low - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))
        target = host[select] + np.repeat(np.arange(b) * (t * frame) - offset * frame, counts)
        target_t = torch.from_numpy(target).to(frames.device)
        assert self._entry_values is not None  # a sparse bank (self._entries is set)
        values = self._entry_values.index_select(0, torch.from_numpy(select).to(frames.device))
        return add_entries(frames, target_t, values, "noise")

    def _settings(self) -> str:
        return f"bank=({', '.join(map(str, self.bank.shape))})"


class AddPoissonNoise(EventTransform):
    """Add Poisson background activity at ``rate_hz`` per pixel and polarity.

    For sparse noise (under one event per cell) ``make_params`` also draws each sample's
    total ``count``; the kernel places the events from a per-sample ``seed``.

    Args:
        rate_hz: a rate in Hz, or a ``(min, max)`` range drawn uniformly per sample.
        frame_ms: frame length in milliseconds (the paper's 10 ms).
        p: probability that a sample gets noise.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (the noise as events over
        the grid's window).

    Example:
        >>> transform = AddPoissonNoise((0.1, 10.0))
        >>> out = transform(torch.zeros(4, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))
        >>> out.shape, bool((out >= 0).all())
        (torch.Size([4, 36, 2, 70, 75]), True)
    """

    def __init__(self, rate_hz: float | Sequence[float], frame_ms: float = 10.0, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.rate_hz = check_pair(rate_hz, "rate_hz", low=0.0, single=True)
        self.frame_ms = check_positive(frame_ms, "frame_ms")

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        rate = uniform(*self.rate_hz, shape[0], generator)
        params: Params = {"rate_hz": rate}
        totals = poisson_totals(rate * (self.frame_ms / 1000.0), shape, generator)
        if totals is not None:
            params["count"] = totals
        params["seed"] = seeds(shape[0], generator)
        return params

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        # count: the sparse path's event totals, drawn at under one expected event per cell; a
        # replayed tree may not ask for more than 16 events per cell (the kernel places each one)
        cells = math.prod(shape[1:])
        return {**ADD_POISSON_NOISE_SPEC, "count": Param("int", low=0, high=16 * cells + 1024, optional=True), "seed": SEED}

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(
            F.add_poisson_noise, inputs, params["rate_hz"], params["seed"], frame_ms=self.frame_ms, count=params.get("count")
        )

    def _settings(self) -> str:
        return f"rate_hz={self.rate_hz}, frame_ms={self.frame_ms}"


