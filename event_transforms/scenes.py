"""Scenes: say which physical effects vary in your setup; get the transform that simulates them.

An augmentation simulates a physical effect (DESIGN §5). A :class:`Scene` declares which
effects really vary between the training data and the data the model will meet, and
:meth:`Scene.policy` builds a transform that simulates exactly those and nothing else:

========================================  ===============================================
effect declared in the scene              transform built
========================================  ===============================================
object size differs from training sizes   :class:`ResizeToTarget`: β = target / source,
                                          per sample, from its metadata
contact orientation varies                :class:`~event_transforms.RandomRotation`
lag between force and events varies       :class:`~event_transforms.RandomFrameShift`, or
                                          :class:`~event_transforms.RandomTemporalEventShift`
                                          when only a fraction of the events lags
background activity                       :class:`~event_transforms.AddNoise` (static-scene
                                          frames) or :class:`~event_transforms.AddPoissonNoise`
========================================  ===============================================

The policy combines them independently by default (one effect per synthetic sample, the
paper's better combination: 5.71 N against 7.20 N for the hybrid) or stacks them
(``combination="hybrid"``) in physical order: lag first (event shifting needs whole
counts, so it runs before interpolation), then size, orientation, and noise last.
"""

from __future__ import annotations

__all__ = ["Scene", "ScenePolicy", "ResizeToTarget"]

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

from . import functional as F
from ._validation import check_number, per_sample
from .functional.spatial import Center
from .transforms.base import EventTransform, Params, apply_by_group
from .transforms.containers import Compose, OneOf
from .transforms.noise import AddNoise, AddPoissonNoise
from .transforms.spatial import RandomRotation, _check_center, _check_mode
from .transforms.temporal import RandomFrameShift, RandomTemporalEventShift

_COMBINATIONS = ("independent", "hybrid")


class ResizeToTarget(EventTransform):
    """Resize each sample so its object looks ``target_size`` large: β = (target / source)^e.

    The source size of each sample comes from its metadata (``metadata[key]``: a number
    for one sequence, a (B,) sequence or tensor for a batch, as ``default_collate`` makes
    it). The exponent ``e`` is 1 for the paper's β = target / source; a contact whose width
    grows as √D (Hertz line contact) calls for ``e = 1/2``.

    Args:
        target_size: the size to imitate (e.g. 15.0 mm).
        key: the metadata entry holding each sample's size.
        exponent: e above (> 0).
        center, mode: as in :func:`event_transforms.functional.resize`.

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
    ) -> None:
        super().__init__()
        self.target_size = check_number(target_size, "target_size", low=0.0)
        if self.target_size == 0 or math.isinf(self.target_size):
            raise ValueError(f"target_size must be a positive finite number, got {target_size!r}")
        self.exponent = check_number(exponent, "exponent", low=0.0, high=1e3)
        if self.exponent == 0:
            raise ValueError(f"exponent must be > 0, got {exponent!r}")
        if not isinstance(key, str):
            raise TypeError(f"key must be a string, got {key!r}")
        self.key = key
        self.center = _check_center(center)
        self.mode = _check_mode(mode)

    def scales(self, metadata: Mapping[str, Any] | None, batch_size: int) -> Tensor:
        """β for each of ``batch_size`` samples, as a float64 (B,) CPU tensor."""
        if not isinstance(metadata, Mapping) or self.key not in metadata:
            raise ValueError(
                f"{type(self).__name__} needs each sample's size: call it (or the scene policy "
                f"holding it) with metadata={{{self.key!r}: ...}}, got metadata={metadata!r}"
            )
        source = metadata[self.key]
        if isinstance(source, Tensor):
            source = source.detach().cpu()
        source = per_sample(source, batch_size, f"metadata[{self.key!r}]")
        if batch_size and not bool((torch.isfinite(source) & (source > 0)).all()):
            raise ValueError(f"metadata[{self.key!r}] must hold positive sizes, got {source.tolist()}")
        return (self.target_size / source) ** self.exponent

    def forward(
        self,
        frames: Tensor,
        *,
        generator: torch.Generator | None = None,
        params: Params | None = None,
        metadata: Mapping[str, Any] | None = None,
    ) -> Tensor:
        """Resize ``frames`` by each sample's β (from ``metadata`` unless ``params`` given)."""
        if params is None:
            batch_size = 1 if frames.dim() == 4 else frames.shape[0]
            params = {"scale": self.scales(metadata, batch_size)}
        return super().forward(frames, generator=generator, params=params)

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return {"scale": self.scales(None, batch_size)}  # raises: β needs metadata

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        return F.resize(frames, params["scale"], center=self.center, mode=self.mode)

    def extra_repr(self) -> str:
        return (
            f"target_size={self.target_size}, key={self.key!r}, exponent={self.exponent}, "
            f"center={self.center!r}, mode={self.mode!r}"
        )


class ScenePolicy(EventTransform):
    """The transform a :class:`Scene` builds: its effects combined independently or stacked.

    ``transform`` is the plain container (:class:`~event_transforms.OneOf` for the
    independent combination, :class:`~event_transforms.Compose` for the hybrid), kept for
    inspection; calling the policy runs the same combination and also hands each sample's
    β to :class:`ResizeToTarget` from ``metadata``.

    Args:
        transform: a ``OneOf`` or ``Compose`` of the effects' transforms.
        effects: the names of the effects, in the order of ``transform``'s members.
    """

    def __init__(self, transform: OneOf | Compose, effects: Sequence[str]) -> None:
        super().__init__()
        if not isinstance(transform, (OneOf, Compose)):
            raise TypeError(f"transform must be a OneOf or a Compose, got {type(transform).__name__}")
        if len(effects) != len(transform.transforms):
            raise ValueError(f"effects must name each of the {len(transform.transforms)} transforms, got {effects!r}")
        self.transform = transform
        self.effects = tuple(effects)

    @property
    def independent(self) -> bool:
        return isinstance(self.transform, OneOf)

    def _resize(self) -> ResizeToTarget | None:
        return next((t for t in self.transform.transforms if isinstance(t, ResizeToTarget)), None)

    def forward(
        self,
        frames: Tensor,
        *,
        generator: torch.Generator | None = None,
        params: Params | None = None,
        metadata: Mapping[str, Any] | None = None,
    ) -> Tensor:
        """Apply the policy; ``metadata`` gives each sample's size when the scene resizes."""
        resize = self._resize()
        if params is None and resize is not None:
            batch_size = 1 if frames.dim() == 4 else frames.shape[0]
            scale = resize.scales(metadata, batch_size)  # check before drawing anything
            params = {**self.make_params(batch_size, generator=generator), "scale": scale}
        return super().forward(frames, generator=generator, params=params)

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return self.transform.make_params(batch_size, generator=generator)

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        def run(transform: torch.nn.Module, sub: Tensor, index: Tensor) -> Tensor:
            if isinstance(transform, ResizeToTarget):
                return transform(sub, generator=generator, params={"scale": params["scale"][index]})
            return transform(sub, generator=generator)

        members = list(self.transform.transforms)
        if self.independent:
            branches = [lambda sub, index, t=t: run(t, sub, index) for t in members]
            return apply_by_group(frames, params["index"], branches)
        everything = torch.arange(frames.shape[0])
        for transform in members:
            frames = run(transform, frames, everything)
        return frames

    def extra_repr(self) -> str:
        combination = "independent" if self.independent else "hybrid"
        return f"effects={self.effects}, combination={combination!r}"


def _positive(value: object, name: str) -> float:
    number = check_number(value, name, low=0.0)
    if number == 0 or math.isinf(number):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return number


@dataclass(frozen=True)
class Scene:
    """What varies in a setup, and so which effects an augmentation policy simulates.

    Leave a field at its default when the effect does not vary: the policy then builds no
    transform for it, and an effect that is absent costs nothing.

    Attributes:
        training_sizes: object sizes in the training data (e.g. ``(12.0, 18.0)`` mm bolts).
        target_size: object size to generalise to (e.g. ``15.0``); with the training sizes
            differing from it, the policy resizes each sample by β = target / source.
        size_key: the metadata entry holding each sample's size.
        size_exponent: β = (target / source) ** size_exponent; 1 as in the paper, 1/2
            when the contact width grows as √D (Hertz line contact).
        orientation_deg: range of the contact orientation, ``d`` for ±d or ``(min, max)``
            degrees; ``None`` or 0 if the orientation does not vary.
        lag_shifts: lags between force and events to simulate, in frames, as candidate
            shifts (e.g. ``(-1,)`` or ``range(-2, 1)``); ``None`` if the lag does not vary.
        lag_fraction: ``None`` shifts whole frames (FS); a fraction ζ or a ``(min, max)``
            range moves only that share of each frame's events (TES).
        noise: background activity: static-scene frames ``(N, 2, H, W)`` (e.g. from
            :func:`event_transforms.tactile.datasets.noise_bank`) or a rate in Hz per pixel and
            polarity (a number or ``(min, max)``); ``None`` for none.
        frame_ms: frame length, for a noise rate.

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
    size_exponent: float = 1.0
    orientation_deg: float | tuple[float, float] | None = None
    lag_shifts: Sequence[int] | None = None
    lag_fraction: float | tuple[float, float] | None = None
    noise: Tensor | float | tuple[float, float] | None = field(default=None, compare=False)
    frame_ms: float = 10.0

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "training_sizes", tuple(_positive(s, "training_sizes") for s in self.training_sizes)
        )
        if self.target_size is not None:
            _positive(self.target_size, "target_size")
        _positive(self.size_exponent, "size_exponent")
        _positive(self.frame_ms, "frame_ms")
        if self.noise is not None and not isinstance(self.noise, (Tensor, int, float, tuple, list)):
            raise TypeError(
                f"noise must be static-scene frames (N, 2, H, W), a rate in Hz or a (min, max) "
                f"range, got {type(self.noise).__name__}"
            )

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
        if self.noise is not None and (isinstance(self.noise, Tensor) or _spread(self.noise, low=0) > 0):
            found.append("noise")
        return tuple(found)

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
                built.append(
                    ResizeToTarget(
                        self.target_size,  # type: ignore[arg-type]
                        key=self.size_key,
                        exponent=self.size_exponent,
                        center=center,
                        mode=mode,
                    )
                )
            elif effect == "orientation":
                built.append(RandomRotation(self.orientation_deg, center=center, mode=mode))  # type: ignore[arg-type]
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
    ) -> ScenePolicy:
        """Build the transform simulating this scene's effects.

        Args:
            combination: ``"independent"`` (one effect per sample, :class:`OneOf`; the
                paper's better choice) or ``"hybrid"`` (all effects on every sample,
                :class:`Compose`).
            weights: for the independent combination, relative probabilities of the
                effects, in :attr:`effects` order (default equal).
            center, mode: passed to the resize and rotation.

        Returns:
            A :class:`ScenePolicy`; call it with ``metadata=`` when the scene resizes
            (``AugmentedDataset`` passes each item's metadata). A scene without effects
            gives the identity.
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
        return ScenePolicy(container, self.effects)


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
