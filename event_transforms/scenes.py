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
from torch import Tensor

from ._validation import check_positive
from .functional._warp import Center
from .transforms.base import EventTransform
from .transforms.containers import Compose, OneOf
from .transforms.noise import AddNoise, AddPoissonNoise
from .transforms.geometry import RandomTranslate
from .transforms.affine import RandomRotation
from .transforms._to_target import ResizeToTarget, StretchToTarget, metadata_values
from .transforms.temporal import RandomFrameShift, RandomTemporalEventShift

_COMBINATIONS = ("independent", "hybrid")
#: How a scene simulates a size gap: ``"stretch"`` across the contact strip (physics) or
#: ``"resize"``, the paper's isotropic zoom.
SIZE_TRANSFORMS = ("stretch", "resize")
#: The width exponent γ of each size transform's default: the contact strip's half-width
#: grows as √D under line contact (γ = ½); the paper's zoom uses β = D₂/D₁ (γ = 1).
_DEFAULT_EXPONENT = {"stretch": 0.5, "resize": 1.0}

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
        >>> import torch
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
