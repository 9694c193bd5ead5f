"""Temporal transform modules: frame shifting (FS), temporal event shifting (TES), time
reversal and temporal crop.

``shift = j`` moves frames (or events) from t to t + j; j < 0 is earlier. The paper's
best settings are FS-1 = ``FrameShift(-1)`` and TES-2(0.50) =
``TemporalEventShift(-2, 0.5)``. Labels are never touched (the paper keeps ground truth).
:class:`CropTime` and :class:`RandomCropTime` change T for every sample, so they take no
``p``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import TES_MODES, as_number, check_choice, check_pair, check_probability
from .. import functional as F
from ..events.batch import EventBatch
from ..functional._dispatch import call_kernel
from .._params import SEED
from ..functional.temporal import FRAME_SHIFT_SPEC, TEMPORAL_EVENT_SHIFT_SPEC, crop_time_spec
from ..functional._frame_ops import check_length
from ..functional.timestamps import TIME_JITTER_SPEC, TIME_SKEW_SPEC
from .base import EventTransform, Param, Params, choice, integers, seeds, uniform

__all__ = [
    "FrameShift", "RandomFrameShift", "TemporalEventShift", "RandomTemporalEventShift",
    "TimeReversal", "RandomTimeReversal", "CropTime", "RandomCropTime", "TimeJitter", "TimeSkew",
]


#: Shifts beyond any sequence length are the same as T (all events leave); the bound keeps
#: them in int64 with room for index arithmetic.
_MAX_SHIFT = 2**62


def _check_shifts(shifts: object) -> tuple[int, ...]:
    """A non-empty sequence of candidate integer shifts (``range`` objects welcome)."""
    if isinstance(shifts, (str, bytes)) or not isinstance(shifts, (Sequence, range, Tensor)):
        raise TypeError(
            f"shifts must be a sequence of integer shifts such as (-1, 1) or range(-2, 3), "
            f"got {shifts!r}"
        )
    values = tuple(as_number(s, "shifts", integer=True, low=-_MAX_SHIFT, high=_MAX_SHIFT) for s in shifts)
    if not values:
        raise ValueError(f"shifts must hold at least one shift, got {shifts!r}")
    return values


class _Shift(EventTransform):
    """Frame shifting: ``params["shift"]`` (B,) int64."""

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return FRAME_SHIFT_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.frame_shift, inputs, params["shift"])


class _EventShift(EventTransform):
    """Temporal event shifting: ``params`` hold shift, fraction and the kernel's seed."""

    mode: str

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return TEMPORAL_EVENT_SHIFT_SPEC if self.mode == "expected" else {**TEMPORAL_EVENT_SHIFT_SPEC, "seed": SEED}

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        hint = (
            f"{type(self).__name__}(mode={self.mode!r}) moves whole events: apply it before interpolating "
            "transforms (bilinear rotate/resize), or use mode='expected'"
        )
        return call_kernel(
            F.temporal_event_shift, inputs, params["shift"], params["fraction"], self.mode, params.get("seed"), hint
        )

    def _draws(self, shift: Tensor, fraction: Tensor, generator: torch.Generator | None) -> Params:
        params: Params = {"shift": shift, "fraction": fraction}
        if self.mode != "expected":
            params["seed"] = seeds(shift.shape[0], generator)
        return params


class FrameShift(_Shift):
    """Frame shifting FS-j: every frame moves ``shift`` bins; vacated frames are zero.

    Frames moved past either end are dropped (|j| >= T leaves only zeros). Values are
    moved, not changed: dtype and device are kept.

    Args:
        shift: whole frames j; j < 0 moves frames earlier (the paper's FS-1 is -1).
        p: probability that a sample is shifted.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged.

    Example:
        >>> frames = torch.arange(3.0).view(3, 1, 1, 1).expand(3, 2, 1, 1)
        >>> FrameShift(-1)(frames)[:, 0, 0, 0]
        tensor([1., 2., 0.])
    """

    def __init__(self, shift: int, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.shift = as_number(shift, "shift", integer=True, low=-_MAX_SHIFT, high=_MAX_SHIFT)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"shift": torch.full((shape[0],), self.shift, dtype=torch.int64)}

    def _settings(self) -> str:
        return f"shift={self.shift}"


class RandomFrameShift(_Shift):
    """Frame shifting with a shift drawn per sample, uniformly from ``shifts``.

    Args:
        shifts: the candidate shifts, a sequence of integers: choices such as ``(-1, 1)``
            (never 0) or an inclusive range written as ``range(-2, 3)`` (-2 .. 2). One
            draw per sample; every frame of a sample shares it.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.

    Example:
        >>> transform = RandomFrameShift(range(-2, 3))
        >>> frames = torch.ones(4, 5, 2, 3, 3)
        >>> params = transform.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
        >>> out = transform(frames, params=params)  # replays the draw
        >>> bool((out[:, :, 0, 0, 0].sum(dim=1) == 5 - params["shift"].abs()).all())
        True
    """

    def __init__(self, shifts: Sequence[int], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.shifts = _check_shifts(shifts)
        self._choices = torch.tensor(self.shifts, dtype=torch.int64)  # CPU, drawn from in make_params

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"shift": choice(self._choices, shape[0], generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"shift": dataclasses.replace(FRAME_SHIFT_SPEC["shift"], choices=self.shifts)}

    def _settings(self) -> str:
        return f"shifts={self.shifts}"


class TemporalEventShift(_EventShift):
    """Temporal event shifting TES-j(ζ): move a fraction ζ of every frame's events j frames.

    In every frame and polarity a random subset Z_t of the events (ΣZ_t = round(ζ·ΣX_t),
    Z_t <= X_t with ``mode="exact"``) moves to frame t + j; events moved past either end
    are dropped. See :func:`event_transforms.functional.temporal_event_shift` for the
    modes and dtype rules (``"exact"`` and ``"binomial"`` keep the dtype and need
    integer-valued counts; ``"expected"`` returns floats).

    Args:
        shift: whole frames j; j < 0 is earlier (the paper's TES-2(0.50) is ``-2, 0.5``).
        fraction: ζ in [0, 1].
        mode: ``"exact"`` (default), ``"binomial"`` or ``"expected"``.
        p: probability that a sample is shifted.

    The random subset is drawn by the kernel from a per-sample seed in ``params["seed"]``,
    so ``params=`` replays it exactly.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged.

    Example:
        >>> frames = torch.zeros(3, 2, 4, 4, dtype=torch.int64)
        >>> frames[2, 0] = 1  # 16 OFF events in the last frame
        >>> out = TemporalEventShift(-2, 0.25)(frames, generator=torch.Generator().manual_seed(0))
        >>> out[:, 0].sum(dim=(-2, -1))
        tensor([ 4,  0, 12])
    """

    def __init__(self, shift: int, fraction: float, mode: str = "exact", *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.shift = as_number(shift, "shift", integer=True, low=-_MAX_SHIFT, high=_MAX_SHIFT)
        self.fraction = check_probability(fraction, "fraction")
        self.mode = check_choice(mode, "mode", TES_MODES)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        batch = shape[0]
        return self._draws(
            torch.full((batch,), self.shift, dtype=torch.int64),
            torch.full((batch,), self.fraction, dtype=torch.float64),
            generator,
        )

    def _settings(self) -> str:
        return f"shift={self.shift}, fraction={self.fraction}, mode={self.mode!r}"


class RandomTemporalEventShift(_EventShift):
    """Temporal event shifting with shift and fraction drawn per sample.

    Args:
        shifts: candidate shifts, a sequence of integers drawn uniformly: choices such as
            ``(-2, -1)`` or an inclusive range written as ``range(-2, 3)``.
        fractions: ζ drawn uniformly from a ``(min, max)`` range within [0, 1], or a
            single number for a fixed ζ.
        mode: ``"exact"`` (default), ``"binomial"`` or ``"expected"``.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged (dtype rules as in
        :class:`TemporalEventShift`).

    Example:
        >>> transform = RandomTemporalEventShift((-2, -1), (0.25, 0.75))
        >>> frames = torch.randint(0, 3, (4, 6, 2, 5, 5))
        >>> out = transform(frames, generator=torch.Generator().manual_seed(0))
        >>> out.shape, out.dtype, bool((out.sum((1, 2, 3, 4)) <= frames.sum((1, 2, 3, 4))).all())
        (torch.Size([4, 6, 2, 5, 5]), torch.int64, True)
    """

    def __init__(
        self,
        shifts: Sequence[int],
        fractions: float | Sequence[float] = (0.0, 1.0),
        mode: str = "exact",
        *,
        p: float = 1.0,
    ) -> None:
        super().__init__(p=p)
        self.shifts = _check_shifts(shifts)
        self.fractions = check_pair(fractions, "fractions", low=0.0, high=1.0, single=True)
        self.mode = check_choice(mode, "mode", TES_MODES)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        batch = shape[0]
        return self._draws(
            choice(torch.tensor(self.shifts, dtype=torch.int64), batch, generator),
            uniform(*self.fractions, batch, generator),
            generator,
        )

    def _settings(self) -> str:
        return f"shifts={self.shifts}, fractions={self.fractions}, mode={self.mode!r}"


class TimeReversal(EventTransform):
    """Play each sequence backwards: frames reversed and polarities swapped.

    See :func:`~event_transforms.functional.time_reversal`. Per-frame labels (force)
    are *not* reversed (extra inputs pass through); reverse them yourself if a reversed
    sequence should keep its pairing, or do not use it where time has a direction (a contact
    never plays backwards: a scene declares no time reversal).

    Args:
        p: probability that a sample is reversed.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` on the same frame grid.

    Example:
        >>> frames = torch.zeros(3, 2, 1, 1)
        >>> frames[0, 1] = 4.0
        >>> TimeReversal()(frames)[:, :, 0, 0].tolist()
        [[0.0, 0.0], [0.0, 0.0], [4.0, 0.0]]
    """

    gates_in_kernel = True  # the kernel takes the gate as its flags: no gather, no put-back

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.time_reversal, inputs, params.get("apply"))

class RandomTimeReversal(TimeReversal):
    """Reverse each sequence in time (and swap polarities) with probability ``p`` (default 0.5).

    Args:
        p: probability that a sample is reversed (default 0.5).

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` on the same frame grid.

    Example:
        >>> RandomTimeReversal(p=1.0)(torch.arange(4.).view(2, 2, 1, 1))[:, :, 0, 0].tolist()
        [[3.0, 2.0], [1.0, 0.0]]
    """

    def __init__(self, p: float = 0.5) -> None:
        super().__init__(p=p)

    def _settings(self) -> str:
        return "" if self.p < 1 else "p=1.0"

class _CropTime(EventTransform):
    """Keeps frames ``[params["start"], params["start"] + length)``."""

    def __init__(self, length: int) -> None:
        super().__init__()
        self.length = as_number(length, "length", integer=True)
        if self.length < 1:
            raise ValueError(f"length must be >= 1, got {length!r}")

    def _room(self, shape: torch.Size) -> int:
        return shape[1] - check_length(self.length, shape[1])

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        self._room(shape)
        return crop_time_spec(shape, self.length)

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        self._room(inputs.frame_shape if isinstance(inputs, EventBatch) else inputs.shape)
        return call_kernel(F.crop_time, inputs, params["start"], self.length)

    def output_shape(self, shape: torch.Size) -> torch.Size:
        return torch.Size((shape[0], self.length, *shape[2:]))

class CropTime(_CropTime):
    """Keep frames ``[start, start + length)`` of every sequence (tonic's ``CropTime``, in frames).

    Per-frame labels pass through uncut: cut them with the same window.

    Args:
        start: first kept frame (>= 0).
        length: number of kept frames.

    Shape:
        ``(B, T, 2, H, W)`` -> ``(B, length, 2, H, W)``.

    Example:
        >>> CropTime(2, 3)(torch.zeros(36, 2, 70, 75)).shape
        torch.Size([3, 2, 70, 75])
    """

    def __init__(self, start: int, length: int) -> None:
        super().__init__(length)
        self.start = as_number(start, "start", integer=True, low=0)

    def _room(self, shape: torch.Size) -> int:
        room = super()._room(shape)
        if self.start > room:
            raise ValueError(
                f"CropTime: start {self.start} + length {self.length} exceeds the {shape[1]} frames"
            )
        return room

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        self._room(shape)
        return {"start": torch.full((shape[0],), self.start, dtype=torch.int64)}

    def _settings(self) -> str:
        return f"start={self.start}, length={self.length}"

class RandomCropTime(_CropTime):
    """Keep a window of ``length`` frames at a random start per sequence.

    The starts are returned in ``params["start"]``: cut per-frame labels with them,
    ``labels.gather(1, params["start"].view(-1, 1) + torch.arange(length))``.

    Args:
        length: number of kept frames (at most T).

    Shape:
        ``(B, T, 2, H, W)`` -> ``(B, length, 2, H, W)``; dtype and device kept.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch`` whose grid is ``length`` bins.

    Example:
        >>> transform = RandomCropTime(30)
        >>> transform.make_params((3, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))["start"].tolist()
        [6, 4, 3]
    """

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"start": integers(self._room(shape) + 1, shape[0], generator)}

    def _settings(self) -> str:
        return f"length={self.length}"


# --------------------------------------------------------------------------- events only


def _range(value: float | Sequence[float], name: str, *, low: float = 0.0, high: float = float("inf")) -> tuple[float, float]:
    pair = check_pair(value, name, low=low, high=high, single=True)
    return float(pair[0]), float(pair[1])


class TimeJitter(EventTransform):
    """Add Gaussian noise of ``std_us`` microseconds to every timestamp (per-sample std).

    Events only (frames raise a named ``TypeError``); see
    :func:`~event_transforms.functional.time_jitter`. Streams are no longer time-sorted
    afterwards (binning does not need them sorted). Sync-free.

    Args:
        std_us: standard deviation in µs, or a ``(min, max)`` range.
        p: probability that a sample is jittered.

    Shape:
        An :class:`~event_transforms.EventBatch` of B streams in, an ``EventBatch`` out:
        the same streams and events (retimed; no longer time-sorted). Frames raise ``TypeError`` (an event-only augmentation).

    Example:
        >>> import event_transforms as et
        >>> batch = et.EventBatch.from_streams([torch.tensor([[0, 0, 1000, 1]] * 3)], sensor_size=(2, 2))
        >>> et.TimeJitter(100.0)(batch, generator=torch.Generator().manual_seed(0)).t.tolist()
        [951, 868, 1082]
    """

    def __init__(self, std_us: float | Sequence[float] = 100.0, *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.std_us = _range(std_us, "std_us")

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"std_us": uniform(*self.std_us, shape[0], generator), "seed": seeds(shape[0], generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return TIME_JITTER_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.time_jitter, inputs, params["std_us"], params["seed"])

    def _settings(self) -> str:
        return f"std_us={self.std_us}"


class TimeSkew(EventTransform):
    """Stretch time: ``t -> t0 + coefficient (t - t0) + offset_us`` per sample.

    Events only; see :func:`~event_transforms.functional.time_skew`. ``t0`` is the
    stream's grid start (the first event without a grid), so absolute timestamps (about
    1.7e15 µs) are skewed about the recording, not about 0. Sync-free.

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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {
            "coefficient": uniform(*self.coefficient, shape[0], generator),
            "offset_us": uniform(*self.offset_us, shape[0], generator),
        }

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return TIME_SKEW_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.time_skew, inputs, params["coefficient"], params["offset_us"])

    def _settings(self) -> str:
        return f"coefficient={self.coefficient}, offset_us={self.offset_us}"
