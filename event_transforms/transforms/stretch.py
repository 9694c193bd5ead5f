"""Stretch modules: scale across the contact axis about the event centroid (one warp per sequence).

Why stretch, not zoom: under line contact a cylinder's contact strip widens as √(F·D)
while the pad fixes its length, so a size change D₁ → D₂ is a stretch across the
strip by (D₂/D₁)^½; the paper's isotropic zoom also lengthens the strip and multiplies its
events by β². See :func:`event_transforms.functional.stretch`.
"""

from __future__ import annotations

from typing import Any

from collections.abc import Sequence

import torch
from torch import Tensor

from .._validation import INTERPOLATIONS, as_number, check_choice, check_pair, check_positive
from ..events.batch import EventBatch
from ..functional._warp import Center, check_center
from .. import functional as F
from ..functional._dispatch import call_kernel
from ..functional.stretch import CONTACT, STRETCH_SPEC
from .base import EventTransform, Param, Params, choice, uniform

__all__ = ["Stretch", "RandomStretch"]


class _StretchWarp(EventTransform):
    """Applies ``params["factor"]`` (B,) across ``self.axis`` ("contact" or degrees)."""

    def __init__(self, *, axis: str | float, center: Center, mode: str, p: float) -> None:
        super().__init__(p=p)
        if isinstance(axis, str):
            self.axis: str | float = check_choice(axis, "axis", (CONTACT,))
        else:
            self.axis = as_number(axis, "axis")
        self.center = check_center(center)
        self.mode = check_choice(mode, "mode", INTERPOLATIONS)

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {"factor": STRETCH_SPEC["factor"]}

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        b = len(inputs) if isinstance(inputs, EventBatch) else inputs.shape[0]
        axis = self.axis if isinstance(self.axis, str) else torch.full((b,), self.axis, dtype=torch.float64)
        return call_kernel(F.stretch, inputs, params["factor"], axis, self.center, self.mode)

    def _common(self) -> str:
        return f"axis={self.axis!r}, center={self.center!r}, mode={self.mode!r}"


class Stretch(_StretchWarp):
    """Stretch every sequence by a fixed factor across its contact axis (or a given axis).

    The physically matched simulation of another object size: the contact strip of a cylinder
    pressed into an elastic layer widens as √D (line contact) while the pad fixes its
    length, so a D₁ → D₂ change is a stretch across the strip by (D₂/D₁)^½, not the
    paper's isotropic zoom by D₂/D₁ (see :func:`event_transforms.functional.stretch`, which
    it calls, for the maths and the measured fidelity). On an EventBatch each event moves to
    the nearest pixel (counts kept; ``mode`` does not apply).

    Args:
        factor: stretch factor k > 0 across the axis.
        axis: ``"contact"`` (each sequence's contact axis from its events' second moments)
            or the axis's angle in degrees, counter-clockwise on the displayed image.
        center: ``"mass"`` (event centroid of the sequence), ``"image"`` or ``(y, x)``.
        mode: ``"bilinear"`` (float output: input dtype for floats, float32 for integers)
            or ``"nearest"`` (dtype kept).
        p: probability that a sample is stretched.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5)
        >>> frames[0, 1, 1:4, 2] = 1.0  # a vertical strip
        >>> Stretch(2.0)(frames)[0, 1, 2].tolist()  # stretched horizontally
        [0.0, 0.5, 1.0, 0.5, 0.0]
    """

    def __init__(
        self, factor: float, *, axis: str | float = CONTACT, center: Center = "mass", mode: str = "bilinear", p: float = 1.0
    ) -> None:
        super().__init__(axis=axis, center=center, mode=mode, p=p)
        self.factor = check_positive(factor, "factor")

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        return {"factor": torch.full((shape[0],), self.factor, dtype=torch.float64)}

    def _settings(self) -> str:
        return f"factor={self.factor}, {self._common()}"


class RandomStretch(_StretchWarp):
    """Stretch each sequence by its own random factor across its contact axis.

    Give either ``factor``, a ``(min, max)`` range drawn uniformly, or ``choices``, factors
    drawn with equal probability (e.g. ``((15/18) ** 0.5, (15/12) ** 0.5)``, the line-contact
    match of the paper's 12 + 18 → 15 mm split). Why a stretch and not a zoom:
    :func:`event_transforms.functional.stretch`.

    Args:
        factor: ``(min, max)`` stretch range, both > 0.
        choices: stretch factors, all > 0.
        axis, center, mode: as in :class:`Stretch`.
        p: probability that a sample is stretched.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (``mode="nearest"`` keeps it).

    Example:
        >>> transform = RandomStretch((0.9, 1.1))
        >>> transform.make_params((3, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))["factor"].shape
        torch.Size([3])
    """

    def __init__(
        self,
        factor: Sequence[float] | None = None,
        *,
        choices: Sequence[float] | None = None,
        axis: str | float = CONTACT,
        center: Center = "mass",
        mode: str = "bilinear",
        p: float = 1.0,
    ) -> None:
        super().__init__(axis=axis, center=center, mode=mode, p=p)
        if (factor is None) == (choices is None):
            raise ValueError(f"give exactly one of factor or choices, got factor={factor!r}, choices={choices!r}")
        self.factor = None if factor is None else check_pair(factor, "factor")
        if self.factor is not None and self.factor[0] <= 0:
            raise ValueError(f"factor must be > 0, got {factor!r}")
        self.choices = None
        if choices is not None:
            if isinstance(choices, (str, bytes)) or not isinstance(choices, Sequence) or not choices:
                raise TypeError(f"choices must be a non-empty sequence of factors > 0, got {choices!r}")
            self.choices = tuple(check_positive(c, "choices") for c in choices)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        if self.choices is not None:
            return {"factor": choice(torch.tensor(self.choices, dtype=torch.float64), shape[0], generator)}
        assert self.factor is not None
        return {"factor": uniform(*self.factor, shape[0], generator)}

    def _settings(self) -> str:
        setting = f"choices={self.choices}" if self.choices is not None else f"factor={self.factor}"
        return f"{setting}, {self._common()}"


