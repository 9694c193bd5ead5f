"""Transforms whose factor comes from each sample's metadata: a size change to a target size.

:class:`ResizeToTarget` (the paper's isotropic zoom) and :class:`StretchToTarget` (across the
contact strip) read each sample's source size from its metadata and scale by
``(target / source) ** exponent``. :class:`~event_transforms.Scene` builds them for a size gap;
they are public from :mod:`event_transforms.scenes` and the top level.
"""

from __future__ import annotations

__all__ = ["Metadata", "metadata_values", "ResizeToTarget", "StretchToTarget"]

from collections.abc import Mapping, Sequence
from typing import Any

import torch
from torch import Tensor

from .._params import Param, check_args
from .._validation import check_positive, describe
from ..functional._warp import Center
from ..functional.stretch import CONTACT
from .affine import _Zoom
from .base import Params
from .stretch import _StretchWarp


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
