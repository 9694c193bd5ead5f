"""Drop modules: EventDrop (events by fraction, time window or area), pixel removal, and the
event-only refractory period and decimation.

They only remove counts, so counts can only fall and the dtype is kept. Pixel masks are
computed on the frames' device; nothing is read back to the host.
"""

from __future__ import annotations

from typing import Any

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import check_pair, check_positive
from .. import functional as F
from ..events.batch import EventBatch
from ..functional._dispatch import call_kernel
from .._params import SEED
from ..functional.drop import (
    DECIMATION_SPEC, DROP_BY_AREA_SPEC, DROP_BY_TIME_SPEC, DROP_RANDOM_SPEC, RANDOM_PIXEL_MASK_SPEC, REFRACTORY_PERIOD_SPEC,
    random_pixel_mask,
)
from ..functional._frame_ops import pixel_mask
from .base import EventTransform, Param, Params, apply_by_group, choice, integers, seeds, slice_params, uniform

__all__ = ["RandomEventDrop", "DropPixel", "RandomDropPixel", "RefractoryPeriod", "Decimation"]


_DROPS = ("random", "time", "area")

_HINT = "apply RandomEventDrop before interpolating transforms (bilinear rotate/resize)"


class RandomEventDrop(EventTransform):
    """EventDrop (Gu et al., 2021): each sample loses events by one randomly chosen method.

    * ``"random"``: each event is dropped with probability ρ (binomial thinning);
    * ``"time"``: every event in ``floor(ρ·T)`` consecutive frames at a random start;
    * ``"area"``: every event in a ``floor(ρ·H) × floor(ρ·W)`` rectangle at a random place.

    ρ, the method and the window are drawn per sample in ``make_params``; the random
    thinning draws from a per-sample seed. Counts stay integer and the dtype is kept;
    ``"random"`` needs whole counts (apply it before bilinear rotate/resize).

    Args:
        fraction: ``(min, max)`` range of ρ within [0, 1] (a single number is fixed).
        methods: the methods to choose from, uniformly.
        p: probability that a sample loses events.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (fewer events).

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
        *,
        p: float = 1.0,
    ) -> None:
        super().__init__(p=p)
        self.fraction = check_pair(fraction, "fraction", low=0.0, high=1.0, single=True)
        if isinstance(methods, str) or not isinstance(methods, Sequence) or not methods or any(
            m not in _DROPS for m in methods
        ):
            raise ValueError(f"methods must be a non-empty subset of {_DROPS}, got {methods!r}")
        self.methods = tuple(methods)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b, t, _, h, w = shape
        codes = torch.tensor([_DROPS.index(m) for m in self.methods])
        method = choice(codes, b, generator)
        fraction = uniform(*self.fraction, b, generator)

        def window(size: int) -> tuple[Tensor, Tensor]:
            length = (fraction * size).floor().to(torch.int64)
            return integers(size - length + 1, b, generator), length

        start, length = window(t)
        top, height = window(h)
        left, width = window(w)
        return {
            "method": method, "fraction": fraction, "seed": seeds(b, generator),
            "start": start, "length": length,
            "top": top, "height": height, "left": left, "width": width,
        }

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {
            "method": Param("int", choices=tuple(_DROPS.index(m) for m in self.methods)),
            **DROP_RANDOM_SPEC, "seed": SEED, **DROP_BY_TIME_SPEC, **DROP_BY_AREA_SPEC,
        }

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        def by_random(sub: Tensor | EventBatch, index: Tensor) -> Tensor | EventBatch:
            part = slice_params(params, index)
            return call_kernel(F.drop_random, sub, part["fraction"], "binomial", part["seed"], _HINT)

        def by_time(sub: Tensor | EventBatch, index: Tensor) -> Tensor | EventBatch:
            part = slice_params(params, index)
            return call_kernel(F.drop_by_time, sub, part["start"], part["length"])

        def by_area(sub: Tensor | EventBatch, index: Tensor) -> Tensor | EventBatch:
            part = slice_params(params, index)
            return call_kernel(F.drop_by_area, sub, part["top"], part["left"], part["height"], part["width"])

        branches = {"random": by_random, "time": by_time, "area": by_area}
        functions = [branches[m] if m in self.methods else None for m in _DROPS]
        return apply_by_group(inputs, params["method"], functions)

    def _settings(self) -> str:
        return f"fraction={self.fraction}, methods={self.methods}"


class DropPixel(EventTransform):
    """Remove given pixels, or each sequence's hot pixels, in all frames and polarities.

    Give exactly one of ``pixels`` (the same for every sample: known dead or hot pixels of
    a sensor) or ``rate_hz`` (per sample: pixels whose rate over the sequence, both
    polarities, exceeds ``rate_hz``; see :func:`~event_transforms.functional.hot_pixels`).

    Args:
        pixels: ``(N, 2)`` integer ``(y, x)`` coordinates, or an ``(H, W)`` bool mask.
        rate_hz: hot-pixel threshold in events per second.
        frame_ms: the duration of one frame, for ``rate_hz``.
        p: probability that a sample is cleaned.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` (``pixels=`` only).

    Example:
        >>> frames = torch.zeros(10, 2, 2, 3, dtype=torch.int32)
        >>> frames[:, 1, 0, 2] = 1  # 100 Hz
        >>> frames[3, 0, 1, 1] = 1
        >>> DropPixel(rate_hz=50.0)(frames).nonzero().tolist()
        [[3, 0, 1, 1]]
        >>> DropPixel([[1, 1]])(frames).sum().item()
        10
    """

    def __init__(
        self,
        pixels: Tensor | Sequence[Sequence[int]] | None = None,
        *,
        rate_hz: float | None = None,
        frame_ms: float = 10.0,
        p: float = 1.0,
    ) -> None:
        super().__init__(p=p)
        if (pixels is None) == (rate_hz is None):
            raise ValueError(f"give exactly one of pixels or rate_hz, got pixels={pixels!r}, rate_hz={rate_hz!r}")
        self.pixels = None
        if pixels is not None:
            pixels = pixels if isinstance(pixels, Tensor) else torch.as_tensor(pixels)
            if pixels.dtype == torch.bool and pixels.dim() != 2:
                raise ValueError(f"a pixel mask must have shape (H, W), got {tuple(pixels.shape)}")
            self.pixels = pixels.detach().cpu().clone()
        self.rate_hz = None if rate_hz is None else check_positive(rate_hz, "rate_hz")
        self.frame_ms = check_positive(frame_ms, "frame_ms")

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        if isinstance(inputs, EventBatch):
            if self.pixels is None:
                raise TypeError(
                    "DropPixel(rate_hz=...) finds hot pixels from binned frames; on an EventBatch give the "
                    "pixels (DropPixel(pixels=...)) or bin first with EventsToFrames"
                )
            b, (height, width) = len(inputs), inputs.sensor_size
        else:
            b, _, _, height, width = inputs.shape
        if self.pixels is not None:
            mask = pixel_mask(self.pixels, b, height, width, inputs.device)
        else:
            assert isinstance(inputs, Tensor) and self.rate_hz is not None  # refused above / set without pixels
            mask = F.hot_pixels(inputs, self.rate_hz, frame_ms=self.frame_ms)
        return call_kernel(F.drop_pixel, inputs, mask)

    def _settings(self) -> str:
        if self.pixels is not None:
            shown = f"mask {tuple(self.pixels.shape)}" if self.pixels.dtype == torch.bool else self.pixels.tolist()
            return f"pixels={shown}"
        return f"rate_hz={self.rate_hz}, frame_ms={self.frame_ms}"

class RandomDropPixel(EventTransform):
    """Remove a random set of pixels per sequence (pixel dropout), in all its frames.

    Each pixel of sample b is dropped independently with probability ``fraction[b]``,
    drawn per sample from ``fraction`` (a number or a ``(min, max)`` range). The mask comes
    from the sample's ``params["seed"]`` alone (a counter-based hash), so it replays, a
    batch gives what its samples give alone, and CPU and CUDA drop the same pixels.

    Args:
        fraction: share of pixels dropped, in [0, 1], or a ``(min, max)`` range.
        p: probability that a sample is thinned.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

    Example:
        >>> out = RandomDropPixel(0.5)(torch.ones(2, 3, 2, 20, 20), generator=torch.Generator().manual_seed(0))
        >>> [round(f, 2) for f in (out[:, 0, 0] == 0).float().mean((1, 2)).tolist()]
        [0.49, 0.52]
    """

    def __init__(self, fraction: float | Sequence[float], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.fraction = check_pair(fraction, "fraction", single=True, low=0.0, high=1.0)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b = shape[0]
        return {"fraction": uniform(*self.fraction, b, generator), "seed": seeds(b, generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return RANDOM_PIXEL_MASK_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        # the same counter-based mask over the pixels of the frames or of the sensor
        height, width = inputs.sensor_size if isinstance(inputs, EventBatch) else inputs.shape[-2:]
        mask = random_pixel_mask(params["seed"], params["fraction"], height, width, inputs.device)
        return call_kernel(F.drop_pixel, inputs, mask)

    def _settings(self) -> str:
        return f"fraction={self.fraction}"


# --------------------------------------------------------------------------- events only


class RefractoryPeriod(EventTransform):
    """Drop events that follow an event of the same pixel within ``period_us`` (per sample).

    Events only (frames raise a named ``TypeError``); see
    :func:`~event_transforms.functional.refractory_period`. The dead time restarts with
    every event a pixel saw (kept or not), and either polarity counts; the first event of
    a pixel is kept. Needs the whole stream (one sort by pixel and time per call); one
    host read of the kept counts (the output size depends on the data).

    Args:
        period_us: refractory period in µs, or a ``(min, max)`` range.
        p: probability that a sample is filtered.

    Shape:
        An :class:`~event_transforms.EventBatch` of B streams in, an ``EventBatch`` out:
        the same streams, fewer events. Frames raise ``TypeError`` (an event-only augmentation).

    Example:
        >>> import event_transforms as et
        >>> rows = torch.tensor([[1, 1, 0, 1], [1, 1, 500, 0], [1, 1, 2000, 1], [0, 0, 100, 1]])
        >>> et.RefractoryPeriod(1000.0)(et.EventBatch.from_streams([rows], sensor_size=(2, 2))).t.tolist()
        [0, 2000, 100]
    """

    def __init__(self, period_us: float | Sequence[float] = 1000.0, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        low, high = check_pair(period_us, "period_us", low=0.0, single=True)
        self.period_us = (float(low), float(high))

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"period_us": uniform(*self.period_us, shape[0], generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return REFRACTORY_PERIOD_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.refractory_period, inputs, params["period_us"])

    def _settings(self) -> str:
        return f"period_us={self.period_us}"


class Decimation(EventTransform):
    """Keep every n-th event of each pixel (tonic's ``Decimation``), n per sample.

    Events only; see :func:`~event_transforms.functional.decimation`. Needs the whole
    stream (one sort by pixel and time); one host read of the kept counts.

    Args:
        n: keep one event in n, or a ``(min, max)`` range of whole numbers (inclusive).
        p: probability that a sample is decimated.

    Shape:
        An :class:`~event_transforms.EventBatch` of B streams in, an ``EventBatch`` out:
        the same streams, fewer events. Frames raise ``TypeError`` (an event-only augmentation).

    Example:
        >>> import event_transforms as et
        >>> rows = torch.tensor([[0, 0, t, 1] for t in range(6)])
        >>> et.Decimation(3)(et.EventBatch.from_streams([rows], sensor_size=(1, 1))).t.tolist()
        [2, 5]
    """

    def __init__(self, n: int | Sequence[int] = 2, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        low, high = check_pair(n, "n", low=1, single=True)
        if int(low) != low or int(high) != high:
            raise ValueError(f"n must hold whole numbers >= 1, got {n!r}")
        self.n = (int(low), int(high))

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"n": integers(self.n[1] - self.n[0] + 1, shape[0], generator) + self.n[0]}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return DECIMATION_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.decimation, inputs, params["n"])

    def _settings(self) -> str:
        return f"n={self.n}"
