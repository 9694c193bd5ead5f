"""Scenes: say which physical effects vary in your setup; get the transform that simulates them.

An augmentation simulates a physical effect. A :class:`Scene` declares which
effects really vary between the training data and the data the model will meet, and
:meth:`Scene.policy` builds a transform that simulates exactly those and nothing else:

========================================  ===============================================
effect declared in the scene              transform built
========================================  ===============================================
object size differs from training sizes   :class:`StretchToTarget`: across the contact
                                          axis by (target / source)^½, per sample, from
                                          its metadata (``size_transform="resize"``: the
                                          paper's zoom, :class:`ResizeToTarget`)
contact orientation varies                :class:`~event_transforms.RandomRotation`
contact centre moves between recordings   :class:`~event_transforms.RandomTranslate`
                                          (whole pixels, zero fill)
lag between force and events varies       :class:`~event_transforms.RandomFrameShift`, or
                                          :class:`~event_transforms.RandomTemporalEventShift`
                                          when only a fraction of the events lags
background activity                       :class:`~event_transforms.AddNoise` (static-scene
                                          frames) or :class:`~event_transforms.AddPoissonNoise`
========================================  ===============================================

The policy combines them independently by default (one effect per synthetic sample, the
paper's better combination: 5.71 N against 7.20 N for the hybrid) or stacks them
(``combination="hybrid"``) in physical order: lag first (event shifting needs whole
counts, so it runs before interpolation), then size, orientation, position, and noise last.

Effects a contact does *not* call for, so no scene declares them: time reversal (a
contact never plays backwards: loading and release differ), polarity flip (ON and OFF events
mark pressing and releasing), mixing of two recordings (CutMix/MixUp are regularisers, not
physical effects), and crops that change the frame size.
"""

from __future__ import annotations

__all__ = ["Scene", "ResizeToTarget", "StretchToTarget", "metadata_values", "SIZE_TRANSFORMS"]

import math

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import Tensor

from ._params import Param, check_args
from ._validation import check_positive, describe
from .functional._warp import Center
from .transforms.base import EventTransform, Params
from .transforms.containers import Compose, OneOf
from .transforms.noise import AddNoise, AddPoissonNoise
from .transforms.geometry import RandomTranslate
from .transforms.affine import RandomRotation, _Zoom
from .functional.stretch import CONTACT
from .transforms.stretch import _StretchWarp
from .transforms.temporal import RandomFrameShift, RandomTemporalEventShift

_COMBINATIONS = ("independent", "hybrid")
#: How a scene simulates a size gap: ``"stretch"`` across the contact strip (physics) or
#: ``"resize"``, the paper's isotropic zoom.
SIZE_TRANSFORMS = ("stretch", "resize")
#: The width exponent γ of each size transform's default: the contact strip's half-width
#: grows as √D under line contact (γ = ½); the paper's zoom uses β = D₂/D₁ (γ = 1).
_DEFAULT_EXPONENT = {"stretch": 0.5, "resize": 1.0}

Metadata = Mapping[str, Any] | Sequence[Mapping[str, Any]] | None


def metadata_values(metadata: Metadata, key: str, batch: int, *, owner: str = "transform") -> Tensor:
    """Each sample's ``metadata[key]`` as a (B,) float64 CPU tensor.

    ``metadata`` is a dict holding a number (one sequence, or one value for the whole
    batch) or a (B,) sequence/array/tensor (as ``default_collate`` makes it), or a list of
    B dicts (one per sample).

    Example:
        >>> metadata_values([{"d": 12.0}, {"d": 18.0}], "d", 2)
        tensor([12., 18.], dtype=torch.float64)
        >>> metadata_values({"d": torch.tensor([12.0, 18.0])}, "d", 2)
        tensor([12., 18.], dtype=torch.float64)
    """
    if isinstance(metadata, Sequence) and not isinstance(metadata, (str, bytes)) and all(
        isinstance(m, Mapping) for m in metadata
    ):
        if len(metadata) != batch or any(key not in m for m in metadata):
            raise ValueError(
                f"{owner} needs metadata[{key!r}] for each of the {batch} samples, got "
                f"{len(metadata)} dicts"
            )
        values: Any = [m[key] for m in metadata]
    elif isinstance(metadata, Mapping) and key in metadata:
        values = metadata[key]
    else:
        raise ValueError(
            f"{owner} needs each sample's {key!r}: call it (or the container holding it) with "
            f"metadata={{{key!r}: ...}}, got metadata={metadata!r}"
        )
    if isinstance(values, list) and values and isinstance(values[0], Tensor):
        values = torch.stack([torch.as_tensor(v) for v in values])
    return check_args(owner, {f"metadata[{key!r}]": Param("float")}, batch, **{f"metadata[{key!r}]": values})[
        f"metadata[{key!r}]"]


class _ToTarget:
    """Mixin of the ``*ToTarget`` modules: per-sample factors ``(target / source)^exponent``,
    the source size read from each sample's metadata under ``key``."""

    def _set_target(self, target_size: float, key: str, exponent: float) -> None:
        self.target_size = check_positive(target_size, "target_size")
        self.exponent = check_positive(exponent, "exponent")
        if not isinstance(key, str):
            raise TypeError(f"key must be a string, got {key!r}")
        self.key = key

    def _factors(self, shape: Sequence[int], metadata: Any) -> Tensor:
        return _target_factors(metadata, self.key, shape[0], self.target_size, self.exponent, type(self).__name__)

    def _settings(self) -> str:
        return f"target_size={self.target_size}, key={self.key!r}, exponent={self.exponent}, {self._common()}"  # type: ignore[attr-defined]


class ResizeToTarget(_ToTarget, _Zoom):
    """Resize each sample so its object looks ``target_size`` large: β = (target / source)^e.

    ``make_params`` reads each sample's source size from its metadata (see
    :func:`metadata_values`: a dict of numbers or (B,) values, or a list of dicts) and
    stores β in ``params["scale"]``; containers hand the batch's metadata to it. The
    exponent ``e`` is 1 for the paper's β = target / source; a contact whose width grows as
    √D (line contact) calls for ``e = 1/2``.

    Args:
        target_size: the size to imitate (e.g. 15.0 mm).
        key: the metadata entry holding each sample's size.
        exponent: e above (> 0).
        center, mode: as in :func:`event_transforms.functional.resize`.
        p: probability that a sample is resized.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtypes as in
    :class:`~event_transforms.Resize`.
        An :class:`~event_transforms.EventBatch` gives an ``EventBatch``.

    Example:
        >>> transform = ResizeToTarget(15.0, center="image")
        >>> frames = torch.zeros(2, 1, 2, 5, 5)
        >>> frames[:, 0, 0, 2, 3] = 1.0
        >>> out = transform(frames, metadata={"diameter_mm": torch.tensor([7.5, 15.0])})
        >>> out[0, 0, 0, 2].tolist(), out[1, 0, 0, 2].tolist()  # doubled, unchanged
        ([0.0, 0.0, 0.0, 0.5, 1.0], [0.0, 0.0, 0.0, 1.0, 0.0])
    """

    def __init__(
        self,
        target_size: float,
        *,
        key: str = "diameter_mm",
        exponent: float = 1.0,
        center: Center = "mass",
        mode: str = "bilinear",
        p: float = 1.0,
    ) -> None:
        super().__init__(center=center, mode=mode, p=p)
        self._set_target(target_size, key, exponent)

    def sample_params(
        self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None
    ) -> Params:
        return {"scale": self._factors(shape, metadata)}


def _target_factors(metadata: Any, key: str, batch: int, target: float, exponent: float, owner: str) -> Tensor:
    source = metadata_values(metadata, key, batch, owner=owner)
    if source.numel() and not bool((source.isfinite() & (source > 0)).all()):
        raise ValueError(f"metadata[{key!r}] must hold positive sizes, got {describe(source)}")
    return (target / source) ** exponent


class StretchToTarget(_ToTarget, _StretchWarp):
    """Stretch each sample across its contact strip so its object looks ``target_size``
    large: factor (target / source)^γ.

    The scene's simulation of a size gap. A cylinder pressed into an elastic layer makes a
    contact strip whose half-width grows as √(F·D) under line contact while the pad
    fixes its length, so γ = ½ and only the width changes (thin layers behave closer to
    γ = ⅓). The paper's isotropic zoom (:class:`ResizeToTarget`, β = D₂/D₁) also lengthens
    the strip and multiplies its events by β²; see
    :func:`event_transforms.functional.stretch` for the fidelity measured on the simulator.

    ``make_params`` reads each sample's source size from its metadata (see
    :func:`metadata_values`) and stores the factor in ``params["factor"]``.

    Args:
        target_size: the size to imitate (e.g. 15.0 mm).
        key: the metadata entry holding each sample's size.
        exponent: γ above (> 0).
        axis, center, mode: as in :class:`~event_transforms.Stretch` (the contact axis by
            default).
        p: probability that a sample is stretched.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtypes as in :class:`~event_transforms.Stretch`.

    Example:
        >>> transform = StretchToTarget(15.0, center="image")
        >>> frames = torch.zeros(2, 1, 2, 5, 5)
        >>> frames[:, 0, 0, 2, 1:4] = 1.0  # horizontal strips
        >>> out = transform(frames, metadata={"diameter_mm": torch.tensor([3.75, 15.0])})
        >>> out[0, 0, 0, :, 2].tolist(), out[1, 0, 0, :, 2].tolist()  # doubled in width, unchanged
        ([0.0, 0.5, 1.0, 0.5, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0])
    """

    def __init__(
        self,
        target_size: float,
        *,
        key: str = "diameter_mm",
        exponent: float = 0.5,
        axis: str | float = CONTACT,
        center: Center = "mass",
        mode: str = "bilinear",
        p: float = 1.0,
    ) -> None:
        super().__init__(axis=axis, center=center, mode=mode, p=p)
        self._set_target(target_size, key, exponent)

    def sample_params(
        self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None
    ) -> Params:
        return {"factor": self._factors(shape, metadata)}


def _positive(value: object, name: str) -> float:
    return check_positive(value, name)


@dataclass(frozen=True)
class Scene:
    """What varies in a setup, and so which effects an augmentation policy simulates.

    Leave a field at its default when the effect does not vary: the policy then builds no
    transform for it, and an effect that is absent costs nothing.

    Attributes:
        training_sizes: object sizes in the training data (e.g. ``(12.0, 18.0)`` mm).
        target_size: object size to generalise to (e.g. ``15.0``); with the training sizes
            differing from it, the policy makes each sample look that size.
        size_key: the metadata entry holding each sample's size.
        size_transform: ``"stretch"`` (default): :class:`StretchToTarget`, across the
            contact strip only, the physics of a cylinder pressed into an elastic layer; ``"resize"``:
            :class:`ResizeToTarget`, the paper's isotropic zoom, kept for comparison.
        size_exponent: factor = (target / source) ** size_exponent; ``None`` for the size
            transform's own: ½ for the stretch (line contact: width ∝ √D), 1 for the
            paper's resize (β = D₂/D₁).
        orientation_deg: range of the contact orientation, ``d`` for ±d or ``(min, max)``
            degrees; ``None`` or 0 if the orientation does not vary.
        lag_shifts: lags between force and events to simulate, in frames, as candidate
            shifts (e.g. ``(-1,)`` or ``range(-2, 1)``); ``None`` if the lag does not vary.
        lag_fraction: ``None`` shifts whole frames (FS); a fraction ζ or a ``(min, max)``
            range moves only that share of each frame's events (TES).
        contact_shift_px: how far the contact centre moves between recordings, in pixels
            of the frames: ``m`` or ``(max_dy, max_dx)`` for integer shifts in ±m; ``None``
            or 0 if the contact is always at the same place.
        noise: background activity: static-scene frames ``(N, 2, H, W)`` (e.g. quiet
            frames of recordings) or a rate in Hz per pixel and
            polarity (a number or ``(min, max)``); ``None`` for none.
        frame_ms: frame length, for a noise rate.
        evidence: what the scene was inferred from, if it was
            (:func:`~event_transforms.scenes.infer_scene` fills it: each factor's estimates
            in training and deployment with their uncertainty); not compared.

    Shape:
        ``noise``: ``(N, 2, H, W)`` static-scene frames. :meth:`policy` returns a transform of
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` frames.

    Example:
        >>> scene = Scene(training_sizes=(12.0, 18.0), target_size=15.0, lag_shifts=(-1,))
        >>> scene.effects
        ('lag', 'size')
        >>> policy = scene.policy()
        >>> frames = torch.zeros(4, 36, 2, 70, 75)
        >>> meta = {"diameter_mm": torch.tensor([12.0, 18.0, 12.0, 18.0])}
        >>> policy(frames, metadata=meta, generator=torch.Generator().manual_seed(0)).shape
        torch.Size([4, 36, 2, 70, 75])
    """

    training_sizes: tuple[float, ...] = ()
    target_size: float | None = None
    size_key: str = "diameter_mm"
    size_exponent: float | None = None
    orientation_deg: float | tuple[float, float] | None = None
    lag_shifts: Sequence[int] | None = None
    lag_fraction: float | tuple[float, float] | None = None
    contact_shift_px: int | tuple[int, int] | None = None
    noise: Tensor | float | tuple[float, float] | None = field(default=None, compare=False)
    frame_ms: float = 10.0
    size_transform: str = "stretch"
    evidence: Mapping[str, Any] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "training_sizes", tuple(_positive(s, "training_sizes") for s in self.training_sizes)
        )
        if self.target_size is not None:
            _positive(self.target_size, "target_size")
        if self.size_exponent is not None:
            _positive(self.size_exponent, "size_exponent")
        if self.size_transform not in SIZE_TRANSFORMS:
            raise ValueError(f"size_transform must be one of {SIZE_TRANSFORMS}, got {self.size_transform!r}")
        _positive(self.frame_ms, "frame_ms")
        if self.contact_shift_px is not None:
            try:
                self._contact_shift()
            except (TypeError, ValueError) as error:
                raise type(error)(f"contact_shift_px: {error}") from None
        if self.noise is not None and not isinstance(self.noise, (Tensor, int, float, tuple, list)):
            raise TypeError(
                f"noise must be static-scene frames (N, 2, H, W), a rate in Hz or a (min, max) "
                f"range, got {type(self.noise).__name__}"
            )
        # Every setting is checked here, under its own name (not first at policy()).
        if self.lag_shifts is not None:
            _check_shifts(self.lag_shifts)
        if self.lag_fraction is not None:
            _check_range(self.lag_fraction, "lag_fraction", low=0.0, high=1.0)
        if self.orientation_deg is not None:
            _check_range(self.orientation_deg, "orientation_deg", symmetric=True)
        if self.noise is not None and not isinstance(self.noise, Tensor):
            _check_range(self.noise, "noise", low=0.0)
        elif isinstance(self.noise, Tensor) and (self.noise.dim() != 4 or self.noise.shape[1] != 2):
            raise ValueError(f"noise frames must be (N, 2, H, W), got shape {tuple(self.noise.shape)}")

    @property
    def effects(self) -> tuple[str, ...]:
        """The effects this scene declares, in the hybrid's order."""
        found = []
        if self.lag_shifts is not None and any(int(s) != 0 for s in self.lag_shifts):
            found.append("lag")
        if self.target_size is not None and (
            not self.training_sizes or any(s != self.target_size for s in self.training_sizes)
        ):
            found.append("size")
        if self.orientation_deg is not None and _spread(self.orientation_deg) > 0:
            found.append("orientation")
        if self.contact_shift_px is not None and any(self._contact_shift()):
            found.append("position")
        if self.noise is not None and (isinstance(self.noise, Tensor) or _spread(self.noise, low=0) > 0):
            found.append("noise")
        return tuple(found)

    @property
    def gaps(self) -> tuple[str, ...]:
        """The declared effects named as the factors of a benchmark scene: ``lag`` is a
        ``timing`` gap, ``position`` a ``center`` gap; ``size``, ``orientation`` and
        ``noise`` keep their names."""
        names = {"lag": "timing", "position": "center"}
        return tuple(names.get(effect, effect) for effect in self.effects)

    def _contact_shift(self) -> tuple[int, int]:
        return RandomTranslate(self.contact_shift_px).max_shift  # type: ignore[arg-type]

    def transforms(self, *, center: Center = "mass", mode: str = "bilinear") -> list[EventTransform]:
        """One transform per declared effect, in :attr:`effects` order."""
        built: list[EventTransform] = []
        for effect in self.effects:
            if effect == "lag":
                shifts = tuple(int(s) for s in self.lag_shifts if int(s) != 0)  # type: ignore[union-attr]
                if self.lag_fraction is None:
                    built.append(RandomFrameShift(shifts))
                else:
                    built.append(RandomTemporalEventShift(shifts, self.lag_fraction))
            elif effect == "size":
                kind = StretchToTarget if self.size_transform == "stretch" else ResizeToTarget
                exponent = _DEFAULT_EXPONENT[self.size_transform] if self.size_exponent is None else self.size_exponent
                built.append(
                    kind(self.target_size, key=self.size_key, exponent=exponent, center=center, mode=mode)  # type: ignore[arg-type]
                )
            elif effect == "orientation":
                built.append(RandomRotation(self.orientation_deg, center=center, mode=mode))  # type: ignore[arg-type]
            elif effect == "position":
                built.append(RandomTranslate(self._contact_shift()))
            elif isinstance(self.noise, Tensor):
                built.append(AddNoise(self.noise))
            else:
                built.append(AddPoissonNoise(self.noise, frame_ms=self.frame_ms))  # type: ignore[arg-type]
        return built

    def policy(
        self,
        combination: str = "independent",
        *,
        weights: Sequence[float] | None = None,
        center: Center = "mass",
        mode: str = "bilinear",
    ) -> OneOf | Compose:
        """Build the transform simulating this scene's effects.

        Args:
            combination: ``"independent"`` (one effect per sample, :class:`OneOf`; the
                paper's better choice) or ``"hybrid"`` (all effects on every sample,
                :class:`Compose`).
            weights: for the independent combination, relative probabilities of the
                effects, in :attr:`effects` order (default equal).
            center, mode: passed to the resize and rotation.

        Returns:
            A plain :class:`~event_transforms.OneOf` (independent) or
            :class:`~event_transforms.Compose` (hybrid); call it with ``metadata=`` when
            the scene resizes (``AugmentedDataset`` passes each item's metadata). A scene
            without effects gives an empty ``Compose``, the identity.
        """
        if combination not in _COMBINATIONS:
            raise ValueError(f"combination must be one of {_COMBINATIONS}, got {combination!r}")
        members = self.transforms(center=center, mode=mode)
        if combination == "independent" and members:
            container: OneOf | Compose = OneOf(members, weights=weights)
        else:
            if weights is not None:
                raise ValueError("weights apply to the independent combination only")
            container = Compose(members)
        return container


def _check_shifts(shifts: object) -> None:
    """``lag_shifts``: whole frames, as a sequence of integers."""
    if isinstance(shifts, (str, bytes)) or not isinstance(shifts, (Sequence, range)):
        raise TypeError(f"lag_shifts must be a sequence of whole frames (integers), got {shifts!r}")
    for shift in shifts:
        if isinstance(shift, bool) or not isinstance(shift, (int, np.integer)):
            raise ValueError(f"lag_shifts must hold whole frames (integers), got {list(shifts)!r}")


def _check_range(value: object, name: str, *, low: float | None = None, high: float | None = None,
                 symmetric: bool = False) -> None:
    """A finite number (``±d`` when ``symmetric``) or a ``(min, max)`` pair, within ``[low, high]``."""
    numbers: list[Any] = list(value) if isinstance(value, (tuple, list)) else [value]
    if len(numbers) not in (1, 2) or isinstance(value, (tuple, list)) and len(numbers) != 2 or any(
        isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) for v in numbers
    ):
        raise TypeError(f"{name} must be a number or a (min, max) pair, got {value!r}")
    floats = [float(v) for v in numbers]
    if not all(math.isfinite(v) for v in floats):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if len(floats) == 2 and floats[0] > floats[1]:
        raise ValueError(f"{name} must be (min, max) with min <= max, got {value!r}")
    if symmetric and len(floats) == 1:
        floats = [-abs(floats[0]), abs(floats[0])]
    if (low is not None and min(floats) < low) or (high is not None and max(floats) > high):
        bounds = f"[{low if low is not None else '-inf'}, {high if high is not None else 'inf'}]"
        raise ValueError(f"{name} must lie in {bounds}, got {value!r}")


def _spread(value: object, low: float | None = None) -> float:
    """Width of a range given as ``d`` (meaning ±d, or the rate itself) or ``(min, max)``."""
    if isinstance(value, bool):
        raise TypeError(f"expected a number or a (min, max) pair, got {value!r}")
    if isinstance(value, (int, float)):
        return abs(float(value))
    if isinstance(value, (tuple, list)) and len(value) == 2:
        first, second = (float(v) for v in value)
        return max(abs(first), abs(second)) if low is not None else second - first
    raise TypeError(f"expected a number or a (min, max) pair, got {value!r}")
