"""Noise modules: static-scene noise injection, Poisson background activity, EventDrop."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .. import functional as F
from .._validation import check_frames, check_number
from .base import EventTransform, Params, apply_by_group, check_range, choice, uniform

__all__ = ["AddNoise", "AddPoissonNoise", "RandomEventDrop"]


class AddNoise(EventTransform):
    """Add a window of frames recorded (or simulated) in a static scene, drawn per sample.

    The bank is one long static-scene recording ``(N, 2, H, W)``; each sample gets the
    ``T`` consecutive frames starting at its own random offset in ``[0, N - T]``. The bank
    is a buffer, so ``.to(device)`` moves it with the module.

    Args:
        bank: non-negative counts ``(N, 2, H, W)`` with ``N >= T`` of the frames it is
            applied to and the frames' ``H, W``.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype of the frames kept.

    Example:
        >>> bank = torch.arange(5.).view(5, 1, 1, 1).expand(5, 2, 3, 4)
        >>> transform = AddNoise(bank)
        >>> out = transform(torch.zeros(2, 3, 2, 3, 4), generator=torch.Generator().manual_seed(4))
        >>> out[:, :, 0, 0, 0].tolist()
        [[1.0, 2.0, 3.0], [2.0, 3.0, 4.0]]
    """

    def __init__(self, bank: Tensor) -> None:
        super().__init__()
        if not isinstance(bank, Tensor) or bank.dim() != 4 or bank.shape[1] != 2:
            shape = tuple(bank.shape) if isinstance(bank, Tensor) else type(bank).__name__
            raise ValueError(f"bank: expected static-scene frames (N, 2, H, W), got {shape}")
        check_frames(bank, "bank")
        if bank.shape[0] == 0:
            raise ValueError("bank must hold at least one frame, got N = 0")
        self.register_buffer("bank", bank.clone())

    def _check_size(self, frames: Tensor) -> None:
        t, _, h, w = frames.shape[-4:]
        n, _, bh, bw = self.bank.shape
        if (bh, bw) != (h, w) or n < t:
            raise ValueError(
                f"bank of shape {tuple(self.bank.shape)} cannot cover frames of shape "
                f"{tuple(frames.shape)}: it needs H, W = {(h, w)} and at least T = {t} frames"
            )

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        # The window length is only known with the frames: draw a uniform position in
        # [0, 1) now and scale it to [0, N - T] in apply.
        return {"offset": uniform(0.0, 1.0, batch_size, generator)}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        self._check_size(frames)
        t = frames.shape[1]
        span = self.bank.shape[0] - t + 1
        start = (params["offset"] * span).floor().long().clamp_(max=span - 1)
        index = start.unsqueeze(1) + torch.arange(t)  # (B, T), CPU
        bank = self.bank.to(frames.device)
        noise = bank.index_select(0, index.reshape(-1).to(frames.device)).view(frames.shape[0], t, *bank.shape[1:])
        return F.add_noise(frames, noise)

    def extra_repr(self) -> str:
        return f"bank=({', '.join(map(str, self.bank.shape))})"


class AddPoissonNoise(EventTransform):
    """Add Poisson background activity at ``rate_hz`` per pixel and polarity.

    Args:
        rate_hz: a rate in Hz, or a ``(min, max)`` range drawn uniformly per sample.
        frame_ms: frame length in milliseconds (the paper's 10 ms).

    Example:
        >>> transform = AddPoissonNoise((0.1, 10.0))
        >>> out = transform(torch.zeros(4, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))
        >>> out.shape, bool((out >= 0).all())
        (torch.Size([4, 36, 2, 70, 75]), True)
    """

    def __init__(self, rate_hz: float | Sequence[float], frame_ms: float = 10.0) -> None:
        super().__init__()
        if isinstance(rate_hz, (int, float)) and not isinstance(rate_hz, bool):
            rate_hz = (float(rate_hz), float(rate_hz))
        self.rate_hz = check_range(rate_hz, "rate_hz", low=0.0)
        self.frame_ms = check_number(frame_ms, "frame_ms", low=0.0)
        if self.frame_ms == 0:
            raise ValueError(f"frame_ms must be > 0, got {frame_ms!r}")

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return {"rate_hz": uniform(*self.rate_hz, batch_size, generator)}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.add_poisson_noise(frames, params["rate_hz"], frame_ms=self.frame_ms, generator=generator)

    def extra_repr(self) -> str:
        return f"rate_hz={self.rate_hz}, frame_ms={self.frame_ms}"


_DROPS = ("random", "time", "area")


class RandomEventDrop(EventTransform):
    """EventDrop (Gu et al., 2021): each sample loses events by one randomly chosen method.

    * ``"random"``: each event is dropped with probability ρ (binomial thinning);
    * ``"time"``: every event in ``floor(ρ·T)`` consecutive frames at a random start;
    * ``"area"``: every event in a ``floor(ρ·H) × floor(ρ·W)`` rectangle at a random place.

    ρ is drawn per sample from ``fraction``. Counts stay integer and the dtype is kept;
    ``"random"`` needs integer-valued counts (apply it before rotate/resize).

    Args:
        fraction: ``(min, max)`` range of ρ within [0, 1] (a single number is fixed).
        methods: the methods to choose from, uniformly.

    Example:
        >>> drop = RandomEventDrop(fraction=(0.1, 0.5))
        >>> frames = torch.ones(3, 36, 2, 70, 75)
        >>> out = drop(frames, generator=torch.Generator().manual_seed(0))
        >>> bool((out <= frames).all()), out.dtype
        (True, torch.float32)
    """

    def __init__(
        self,
        fraction: float | Sequence[float] = (0.0, 0.5),
        methods: Sequence[str] = _DROPS,
    ) -> None:
        super().__init__()
        if isinstance(fraction, (int, float)) and not isinstance(fraction, bool):
            fraction = (float(fraction), float(fraction))
        self.fraction = check_range(fraction, "fraction", low=0.0)
        if self.fraction[1] > 1:
            raise ValueError(f"fraction must lie in [0, 1], got {fraction!r}")
        if isinstance(methods, str) or not methods or any(m not in _DROPS for m in methods):
            raise ValueError(f"methods must be a non-empty subset of {_DROPS}, got {methods!r}")
        self.methods = tuple(methods)

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        codes = torch.tensor([_DROPS.index(m) for m in self.methods])
        return {
            "method": choice(codes, batch_size, generator),
            "fraction": uniform(*self.fraction, batch_size, generator),
            # positions in [0, 1): scaled to the frames' size in apply
            "start": uniform(0.0, 1.0, batch_size, generator),
            "top": uniform(0.0, 1.0, batch_size, generator),
            "left": uniform(0.0, 1.0, batch_size, generator),
        }

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        _, t, _, h, w = frames.shape
        fraction = params["fraction"]

        def window(size: int, position: Tensor) -> tuple[Tensor, Tensor]:
            length = (fraction * size).floor().long()
            start = (position * (size - length + 1)).floor().long().clamp(max=size - length)
            return start, length

        def by_random(sub: Tensor, index: Tensor) -> Tensor:
            return F.drop_events(sub, fraction[index], generator=generator)

        def by_time(sub: Tensor, index: Tensor) -> Tensor:
            start, length = window(t, params["start"])
            return F.drop_by_time(sub, start[index], length[index])

        def by_area(sub: Tensor, index: Tensor) -> Tensor:
            top, height = window(h, params["top"])
            left, width = window(w, params["left"])
            return F.drop_by_area(sub, top[index], left[index], height[index], width[index])

        branches = {"random": by_random, "time": by_time, "area": by_area}
        functions = [branches[m] if m in self.methods else None for m in _DROPS]
        return apply_by_group(frames, params["method"], functions)

    def extra_repr(self) -> str:
        return f"fraction={self.fraction}, methods={self.methods}"
