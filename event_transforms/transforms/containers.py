"""Containers: ``Compose`` (hybrid), ``OneOf`` (independent) and ``RandomApply``.

Containers only chain: they pass one generator through to every transform they hold, so a
seeded call is reproducible end to end. ``OneOf`` and ``RandomApply`` gather the samples
that take each branch and run the branch once on that sub-batch (no per-sample loop), so
an unused branch costs nothing.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from .._validation import check_number
from .base import EventTransform, Params, _sample_device, apply_by_group, bernoulli

__all__ = ["Compose", "OneOf", "RandomApply"]


def _call(transform: nn.Module, frames: Tensor, generator: torch.Generator | None) -> Tensor:
    if isinstance(transform, EventTransform):
        return transform(frames, generator=generator)
    return transform(frames)


def _check_modules(transforms: Sequence[nn.Module], name: str) -> nn.ModuleList:
    if isinstance(transforms, nn.Module) or not isinstance(transforms, Sequence):
        raise TypeError(f"{name} must be a sequence of nn.Module transforms, got {type(transforms).__name__}")
    for t in transforms:
        if not isinstance(t, nn.Module):
            raise TypeError(f"{name} must hold nn.Module transforms, got {type(t).__name__}")
    return nn.ModuleList(transforms)


class Compose(EventTransform):
    """Apply transforms one after another to every sample: the paper's *hybrid* combination.

    Args:
        transforms: ``nn.Module`` transforms; event-transforms modules receive the generator.

    Example:
        >>> from event_transforms import FrameShift, HorizontalFlip
        >>> hybrid = Compose([FrameShift(-1), HorizontalFlip()])
        >>> hybrid(torch.arange(8.).reshape(2, 2, 1, 2))[:, :, 0].tolist()
        [[[5.0, 4.0], [7.0, 6.0]], [[0.0, 0.0], [0.0, 0.0]]]
    """

    def __init__(self, transforms: Sequence[nn.Module]) -> None:
        super().__init__()
        self.transforms = _check_modules(transforms, "transforms")

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        for transform in self.transforms:
            frames = _call(transform, frames, generator)
        return frames


class OneOf(EventTransform):
    """Give each sample exactly one of the transforms: the paper's *independent* combination.

    Each sample draws its branch (uniformly, or by ``weights``); each branch runs once on
    the sub-batch that drew it. The output dtype is the promotion of every branch's dtype,
    whatever the draw.

    Args:
        transforms: ``nn.Module`` transforms, at least one.
        weights: non-negative relative probabilities, one per transform (default equal).

    Example:
        >>> from event_transforms import FrameShift, Resize
        >>> independent = OneOf([Resize(1.25), FrameShift(-1)])
        >>> params = independent.make_params(6, generator=torch.Generator().manual_seed(0))
        >>> params["index"].tolist()
        [1, 1, 0, 1, 1, 1]
    """

    def __init__(self, transforms: Sequence[nn.Module], weights: Sequence[float] | None = None) -> None:
        super().__init__()
        self.transforms = _check_modules(transforms, "transforms")
        if len(self.transforms) == 0:
            raise ValueError("transforms must hold at least one transform, got an empty sequence")
        if weights is None:
            weights = [1.0] * len(self.transforms)
        w = torch.as_tensor(weights, dtype=torch.float64)
        if w.shape != (len(self.transforms),):
            raise ValueError(f"weights must have one entry per transform ({len(self.transforms)}), got {list(weights)}")
        if not bool(torch.isfinite(w).all()) or bool((w < 0).any()) or float(w.sum()) <= 0:
            raise ValueError(f"weights must be finite, non-negative and not all zero, got {list(weights)}")
        self.register_buffer("weights", w / w.sum(), persistent=False)

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        if batch_size == 0:
            return {"index": torch.zeros(0, dtype=torch.long)}
        weights = self.weights.to(_sample_device(generator))
        index = torch.multinomial(weights, batch_size, replacement=True, generator=generator)
        return {"index": index.cpu()}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        branches = [
            (lambda sub, _, t=t: _call(t, sub, generator)) for t in self.transforms
        ]
        return apply_by_group(frames, params["index"], branches)

    def extra_repr(self) -> str:
        return f"weights={[round(w, 4) for w in self.weights.tolist()]}"


class RandomApply(EventTransform):
    """Apply ``transform`` to each sample with probability ``p``; other samples pass unchanged.

    Args:
        transform: an ``nn.Module`` transform.
        p: probability per sample, in [0, 1].

    Example:
        >>> from event_transforms import FrameShift
        >>> gate = RandomApply(FrameShift(1), p=0.5)
        >>> gate.make_params(4, generator=torch.Generator().manual_seed(0))["apply"].tolist()
        [False, False, True, False]
    """

    def __init__(self, transform: nn.Module, p: float = 0.5) -> None:
        super().__init__()
        if not isinstance(transform, nn.Module):
            raise TypeError(f"transform must be an nn.Module, got {type(transform).__name__}")
        self.transform = transform
        self.p = check_number(p, "p", low=0.0, high=1.0)

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        return {"apply": bernoulli(self.p, batch_size, generator)}

    def apply(self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None) -> Tensor:
        branch = lambda sub, _: _call(self.transform, sub, generator)  # noqa: E731
        return apply_by_group(frames, params["apply"].long(), [None, branch])

    def extra_repr(self) -> str:
        return f"p={self.p}"
