"""Transforms on an :class:`~event_transforms.EventBatch`: event kernels of the frame
transforms, and the event-only augmentations.

**One transform, a kernel per input type** (torchvision v2's registry): the kernels below
are registered for the existing transform classes with
:func:`~event_transforms.transforms.base.register_event_kernel`, so ``RandomRotation(30.)``
takes frames or an ``EventBatch`` and draws the same params tree from the same generator
either way (the tree's shape is ``batch.frame_shape``: sensor-sized H, W).

==========================  ===================================================================
transform                   on events
==========================  ===================================================================
Rotate, RandomRotation,     coordinates about the event centroid (or ``center``), each event
Resize, RandomResize,       to the nearest pixel (count-conserving; a bilinear frame warp
Affine, RandomAffine        spreads counts). ``Affine``'s ``translate`` applies; ``shear`` is
                            not supported on events (``ValueError`` if non-zero).
HorizontalFlip, ...Flip     ``x -> W - 1 - x`` / ``y -> H - 1 - y`` (equal to frames after binning)
Translate, RandomTranslate  whole-pixel moves (sensor pixels)
FrameShift, TES             on the batch's frame grid (``frame_ms``, ``n_frames``); exact TES
                            moves exactly round(ζN) events of each bin and polarity
FlipPolarity, TimeReversal  ``p -> 1 - p``; bin i -> T - 1 - i (and polarity swapped)
RandomCrop, CenterCrop      coordinates shifted, the batch's sensor becomes the crop
                            (``resize=False`` only)
CropTime, RandomCropTime    times shifted ``start`` bins; the grid becomes ``length`` bins
RandomEventDrop             random (per event), time (bins of the grid), area (sensor pixels)
AddNoise                    the bank window's counts as events at their bins' centres (the
                            bank is sensor-sized frames of a static scene)
RandomDropPixel, DropPixel  events on masked sensor pixels dropped (the frame kernel's
                            counter-based mask; ``DropPixel(rate_hz=...)`` needs frames)
AddPoissonNoise             uniform events over the grid's window at ``rate_hz`` per pixel
                            and polarity
EventsToFrames              binning on the batch's device (anywhere in a ``Compose``)
==========================  ===================================================================

Event-only augmentations (a frame input raises :class:`TypeError`): :class:`SpatialJitter`,
:class:`TimeJitter`, :class:`TimeSkew`, :class:`RefractoryPeriod`, :class:`Decimation`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from .._validation import check_pair, describe
from ..functional import event_kernels as K
from ..functional.drop import _pixel_mask, random_pixel_mask
from ..events.batch import EventBatch
from .base import _EVENT_NEUTRAL, EventTransform, Params, integers, register_event_kernel, seeds, uniform
from . import affine as _affine
from . import drop as _drop
from . import geometry as _geometry
from . import noise as _noise
from . import polarity as _polarity
from . import temporal as _temporal

__all__ = ["SpatialJitter", "TimeJitter", "TimeSkew", "RefractoryPeriod", "Decimation"]


def _center(module: Any) -> Any:
    center = getattr(module, "center", "mass")
    return center if isinstance(center, str) else tuple(float(c) for c in center)


# --------------------------------------------------------------------------- registrations


@register_event_kernel(_affine._Rotation, neutral={"angle": 0.0})
def _rotate_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    return K.affine_events(batch, angle=params["angle"], center=_center(module))


@register_event_kernel(_affine._Zoom, neutral={"scale": 1.0})
def _resize_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    return K.affine_events(batch, scale=params["scale"], center=_center(module))


@register_event_kernel(_affine._AffineWarp, neutral={"angle": 0.0, "scale": 1.0, "translate": 0.0, "shear": 0.0})
def _affine_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    shear = params.get("shear")
    if shear is not None and any(v != 0 for v in shear.flatten().tolist()):  # CPU params: no sync
        raise ValueError(f"{type(module).__name__}: shear is not supported on events, got {describe(shear)}")
    out = K.affine_events(batch, angle=params["angle"], scale=params["scale"], center=_center(module))
    translate = params.get("translate")
    if translate is not None and any(v != 0 for v in translate.flatten().tolist()):
        out = K.translate_events(out, translate.round().to(torch.int64))
    return out


@register_event_kernel(_geometry.HorizontalFlip)
def _hflip_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    gate = params.get("apply")
    return K.flip_events(batch, torch.ones(len(batch), dtype=torch.bool) if gate is None else gate, axis="x")


@register_event_kernel(_geometry.VerticalFlip)
def _vflip_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    gate = params.get("apply")
    return K.flip_events(batch, torch.ones(len(batch), dtype=torch.bool) if gate is None else gate, axis="y")


@register_event_kernel(_geometry._Roll, neutral={"shift": 0})
def _translate_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    return K.translate_events(batch, params["shift"])


@register_event_kernel(_geometry._Crop)
def _crop_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    if module.resize:
        raise ValueError(f"{type(module).__name__}(resize=True) interpolates frames; on events crop with resize=False")
    module._room(batch.frame_shape)
    return K.crop_events(batch, params["top"], params["left"], module.size)


@register_event_kernel(_temporal._CropTime)
def _crop_time_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    module._room(batch.frame_shape)
    return K.crop_time_events(batch, params["start"], module.length)


@register_event_kernel(_temporal._Shift, neutral={"shift": 0})
def _frame_shift_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    return K.shift_events(batch, params["shift"])


@register_event_kernel(_temporal._EventShift)
def _tes_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    if module.mode == "expected":
        raise ValueError("TES mode='expected' moves fractions of events, which events cannot hold; "
                         "use mode='exact' or 'binomial' on an EventBatch")
    return K.shift_events(batch, params["shift"], params["fraction"], seed=params["seed"], mode=module.mode)


@register_event_kernel(_polarity.FlipPolarity, neutral={})
def _flip_polarity_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    gate = params.get("apply")
    return K.flip_polarity_events(batch, torch.ones(len(batch), dtype=torch.bool) if gate is None else gate.to(torch.bool))


@register_event_kernel(_temporal.TimeReversal, neutral={})
def _time_reversal_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    gate = params.get("apply")
    every = torch.ones(len(batch), dtype=torch.bool) if gate is None else gate.to(torch.bool)
    return K.flip_polarity_events(K.time_reversal_events(batch, every), every)


@register_event_kernel(_noise.AddPoissonNoise, neutral={"rate_hz": 0.0})
def _poisson_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    return K.poisson_noise_events(batch, params["rate_hz"], params["seed"])


@register_event_kernel(_noise.AddNoise)
def _bank_noise_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    return K.bank_noise_events(batch, module.bank, params["offset"])


@register_event_kernel(_drop.RandomDropPixel, neutral={"fraction": 0.0})
def _random_drop_pixel_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    # the same counter-based mask as on frames, over the sensor's pixels
    height, width = batch.sensor_size
    mask = random_pixel_mask(params["seed"], params["fraction"], height, width, batch.device)
    return K.drop_pixels_events(batch, mask)


@register_event_kernel(_drop.DropPixel)
def _drop_pixel_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    if module.pixels is None:
        raise TypeError(
            "DropPixel(rate_hz=...) finds hot pixels from binned frames; on an EventBatch give the "
            "pixels (DropPixel(pixels=...)) or bin first with EventsToFrames"
        )
    height, width = batch.sensor_size
    return K.drop_pixels_events(batch, _pixel_mask(module.pixels, len(batch), height, width, batch.device))


@register_event_kernel(_drop.RandomEventDrop)
def _event_drop_events(module: Any, batch: EventBatch, params: Params) -> EventBatch:
    from .base import apply_by_group, slice_params

    def by_random(sub: EventBatch, index: Tensor) -> EventBatch:
        part = slice_params(params, index)
        return K.drop_events_random(sub, part["fraction"], part["seed"])

    def by_time(sub: EventBatch, index: Tensor) -> EventBatch:
        part = slice_params(params, index)
        return K.drop_window(sub, time=(part["start"], part["length"]))

    def by_area(sub: EventBatch, index: Tensor) -> EventBatch:
        part = slice_params(params, index)
        return K.drop_window(sub, area=(part["top"], part["left"], part["height"], part["width"]))

    branches = {"random": by_random, "time": by_time, "area": by_area}
    functions = [branches[m] if m in module.methods else None for m in ("random", "time", "area")]
    return apply_by_group(batch, params["method"], functions)


# --------------------------------------------------------------------------- event-only


class _EventOnly(EventTransform):
    """An augmentation that exists only for events: frames raise a named ``TypeError``."""

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        raise TypeError(
            f"{type(self).__name__} works on events only: pass an EventBatch "
            f"(EventBatch.from_streams or collate_events), got frames of shape {tuple(frames.shape)}"
        )


def _range(value: float | Sequence[float], name: str, *, low: float = 0.0, high: float = float("inf")) -> tuple[float, float]:
    pair = check_pair(value, name, low=low, high=high, single=True)
    return float(pair[0]), float(pair[1])


class SpatialJitter(_EventOnly):
    """Move every event by Gaussian noise of ``sigma`` pixels in x and y (rounded to whole pixels).

    ``sigma`` is drawn per sample from ``(min, max)`` (a number is fixed); the noise comes
    from the sample's own seed (``params["seed"]``), so a sample alone equals the sample in
    a batch. Events jittered off the sensor are dropped when binned. Sync-free.

    Args:
        sigma: standard deviation in pixels, or a ``(min, max)`` range.
        p: probability that a sample is jittered.

    Shape:
        An :class:`~event_transforms.EventBatch` of B streams in, an ``EventBatch`` out:
        the same streams and events (moved). Frames raise ``TypeError`` (an event-only augmentation).

    Example:
        >>> import event_transforms as et
        >>> batch = et.EventBatch.from_streams([torch.tensor([[5, 5, 0, 1]] * 4)], sensor_size=(10, 10))
        >>> out = et.SpatialJitter(1.0)(batch, generator=torch.Generator().manual_seed(0))
        >>> out.x.tolist(), out.y.tolist()
        ([5, 5, 2, 6], [5, 4, 3, 5])
    """

    def __init__(self, sigma: float | Sequence[float] = 1.0, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.sigma = _range(sigma, "sigma")

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"sigma": uniform(*self.sigma, shape[0], generator), "seed": seeds(shape[0], generator)}

    def apply_events(self, batch: EventBatch, params: Params) -> EventBatch:
        return K.spatial_jitter(batch, params["sigma"], params["seed"])

    def _settings(self) -> str:
        return f"sigma={self.sigma}"


class TimeJitter(_EventOnly):
    """Add Gaussian noise of ``std_us`` microseconds to every timestamp (per-sample std).

    Streams are no longer time-sorted afterwards (binning does not need them sorted).
    Sync-free.

    Args:
        std_us: standard deviation in µs, or a ``(min, max)`` range.
        p: probability that a sample is jittered.

    Shape:
        An :class:`~event_transforms.EventBatch` of B streams in, an ``EventBatch`` out:
        the same streams and events (retimed; no longer time-sorted). Frames raise ``TypeError``
        (an event-only augmentation).

    Example:
        >>> import event_transforms as et
        >>> batch = et.EventBatch.from_streams([torch.tensor([[0, 0, 1000, 1]] * 3)], sensor_size=(2, 2))
        >>> et.TimeJitter(100.0)(batch, generator=torch.Generator().manual_seed(0)).t.tolist()
        [977, 999, 693]
    """

    def __init__(self, std_us: float | Sequence[float] = 100.0, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.std_us = _range(std_us, "std_us")

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"std_us": uniform(*self.std_us, shape[0], generator), "seed": seeds(shape[0], generator)}

    def apply_events(self, batch: EventBatch, params: Params) -> EventBatch:
        return K.time_jitter(batch, params["std_us"], params["seed"])

    def _settings(self) -> str:
        return f"std_us={self.std_us}"


class TimeSkew(_EventOnly):
    """Stretch time: ``t -> t0 + coefficient (t - t0) + offset_us`` per sample.

    ``t0`` is the stream's grid start (the first event without a grid), so absolute
    timestamps (about 1.7e15 µs) are skewed about the recording, not about 0. Sync-free.

    Args:
        coefficient: factor, or a ``(min, max)`` range (must be positive).
        offset_us: shift in µs, or a ``(min, max)`` range.
        p: probability that a sample is skewed.

    Shape:
        An :class:`~event_transforms.EventBatch` of B streams in, an ``EventBatch`` out:
        the same streams and events (retimed). Frames raise ``TypeError`` (an event-only augmentation).

    Example:
        >>> import event_transforms as et
        >>> batch = et.EventBatch.from_streams([torch.tensor([[0, 0, 100, 1], [0, 0, 300, 0]])], sensor_size=(2, 2))
        >>> et.TimeSkew(2.0, offset_us=10.0)(batch).t.tolist()
        [110, 510]
    """

    def __init__(
        self, coefficient: float | Sequence[float] = (0.9, 1.1), offset_us: float | Sequence[float] = 0.0, *, p: float = 1.0
    ) -> None:
        super().__init__(p=p)
        self.coefficient = _range(coefficient, "coefficient", low=1e-12)
        self.offset_us = _range(offset_us, "offset_us", low=-float("inf"))

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {
            "coefficient": uniform(*self.coefficient, shape[0], generator),
            "offset_us": uniform(*self.offset_us, shape[0], generator),
        }

    def apply_events(self, batch: EventBatch, params: Params) -> EventBatch:
        return K.time_skew(batch, params["coefficient"], params["offset_us"])

    def _settings(self) -> str:
        return f"coefficient={self.coefficient}, offset_us={self.offset_us}"


class RefractoryPeriod(_EventOnly):
    """Drop events that follow an event of the same pixel within ``period_us`` (per sample).

    The dead time restarts with every event a pixel saw (kept or not), and either
    polarity counts; the first event of a pixel is kept. Needs the whole stream (one sort
    by pixel and time per call); one host read of the kept counts (the output size
    depends on the data).

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
        self.period_us = _range(period_us, "period_us")

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"period_us": uniform(*self.period_us, shape[0], generator)}

    def apply_events(self, batch: EventBatch, params: Params) -> EventBatch:
        return K.refractory_period(batch, params["period_us"])

    def _settings(self) -> str:
        return f"period_us={self.period_us}"


class Decimation(_EventOnly):
    """Keep every n-th event of each pixel (tonic's ``Decimation``), n per sample.

    Needs the whole stream (one sort by pixel and time); one host read of the kept counts.

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

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        return {"n": integers(self.n[1] - self.n[0] + 1, shape[0], generator) + self.n[0]}

    def apply_events(self, batch: EventBatch, params: Params) -> EventBatch:
        return K.decimation(batch, params["n"])

    def _settings(self) -> str:
        return f"n={self.n}"


# Parameter values that leave a stream unchanged: a gated call (p < 1) runs each kernel once
# on the whole batch with these for the streams its gate skips (no slicing in and out).
_EVENT_NEUTRAL.update({
    _temporal._EventShift: {"fraction": 0.0},
    _drop.RandomEventDrop: {"fraction": 0.0, "length": 0, "height": 0, "width": 0},
    SpatialJitter: {"sigma": 0.0},
    TimeJitter: {"std_us": 0.0},
    TimeSkew: {"coefficient": 1.0, "offset_us": 0.0},
    RefractoryPeriod: {"period_us": 0.0},
    Decimation: {"n": 1},
})
