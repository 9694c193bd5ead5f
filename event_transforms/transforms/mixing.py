"""Mixing modules: :class:`Cutout` (per sample) and :class:`CutMix` / :class:`MixUp` (across a batch).

**Calling convention.** Every module here is called like any other:
``module(frames, *rest, generator=None, params=None, metadata=None)``. :class:`CutMix` and
:class:`MixUp` then differ in one way, on purpose: **they mix the second input**, the
labels, with the same partners and weights as the frames, and return
``(frames, labels, *rest)``; inputs after the second still pass through untouched. For a
dict input ``{"frames": ..., "force": ...}`` they mix the entry named by ``label_key``.
Labels may be float targets ``(B, ...)`` (force per frame ``(B, T)``, soft or one-hot
classes), mixed linearly, or integer class indices ``(B,)`` with ``num_classes`` set, which
come back as soft targets ``(B, num_classes)``. The partners, boxes and weights are in
``params`` (``partner``, ``weight``, and for CutMix ``top, left, height, width``), so a call
replays and the weights can be logged.

Use CutMix and MixUp on a collated batch, as torchvision's are used after the DataLoader,
and call them directly: inside a container (:class:`~event_transforms.Compose`, ...) only
the frames would be mixed, and the labels would pass through unmixed.

Mixing the force of two grasps is a regression heuristic (a pasted box does not carry a
share of the force proportional to its area); it is offered because NDA uses CutMix, not
because it simulates a physical effect of a tactile scene.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from .._validation import as_batch, as_number, check_frames, check_positive
from ..functional.geometry import _size
from ..functional.mixing import _check_classes, _cutmix, _cutout, _mix_labels, _mixup
from .base import FRAMES_KEY, EventTransform, Params, _draw_device, _video_of, integers, seeds

__all__ = ["Cutout", "CutMix", "MixUp"]


def _centred_box(size_h: Tensor, size_w: Tensor, shape: Sequence[int], generator) -> dict[str, Tensor]:
    """Boxes of (B,) sizes at uniform centres, clipped to the frame: top, left, height, width."""
    b, height, width = shape[0], shape[-2], shape[-1]
    cy = integers(max(height, 1), b, generator)
    cx = integers(max(width, 1), b, generator)
    top = (cy - size_h // 2).clamp(0, height)
    left = (cx - size_w // 2).clamp(0, width)
    bottom = (cy - size_h // 2 + size_h).clamp(0, height)
    right = (cx - size_w // 2 + size_w).clamp(0, width)
    return {"top": top, "left": left, "height": bottom - top, "width": right - left}


def _beta(alpha: float, batch: int, generator: torch.Generator | None) -> Tensor:
    """``batch`` Beta(alpha, alpha) draws (float64, CPU), seeded from ``generator`` (or torch's RNG)."""
    seed = int(seeds(1, generator)[0])
    return torch.from_numpy(np.random.default_rng(seed).beta(alpha, alpha, batch))


class Cutout(EventTransform):
    """Empty a box of each sequence, at a uniform random centre, in all its frames.

    DeVries & Taylor's Cutout as Neuromorphic Data Augmentation uses it: a box of
    ``size`` centred at a uniformly drawn pixel, clipped at the border (so near the border
    it is smaller). Counts elsewhere and the dtype are kept. The clipped box is in
    ``params`` (``top, left, height, width``).

    Args:
        size: ``n`` or ``(h, w)`` pixels.
        p: probability that a sample is cut.

    Example:
        >>> out = Cutout(3)(torch.ones(2, 4, 2, 9, 11), generator=torch.Generator().manual_seed(0))
        >>> out.shape, (out == 0).any().item()
        (torch.Size([2, 4, 2, 9, 11]), True)
    """

    def __init__(self, size: int | Sequence[int], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.size = _size(size, "size")

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        b = shape[0]
        h = torch.full((b,), self.size[0], dtype=torch.int64)
        w = torch.full((b,), self.size[1], dtype=torch.int64)
        return _centred_box(h, w, shape, generator)

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        return _cutout(frames, params["top"], params["left"], params["height"], params["width"])

    def _settings(self) -> str:
        return f"size={self.size}"


class _Mixing(EventTransform):
    """Mixes each sample with ``params["partner"]`` of the same batch; mixes the labels too.

    The per-sample gate ``p`` is folded into the mixing (an unchosen sample is its own
    partner with weight 1), because a partner lies outside any sub-batch.
    """

    def __init__(
        self, alpha: float, *, num_classes: int | None, label_key: str | None, p: float
    ) -> None:
        super().__init__(p=p)
        self.alpha = check_positive(alpha, "alpha")
        self.num_classes = None if num_classes is None else as_number(num_classes, "num_classes", integer=True, low=1)
        if label_key is not None and not isinstance(label_key, str):
            raise TypeError(f"label_key must be a string or None, got {label_key!r}")
        self.label_key = label_key

    def _partners(self, b: int, generator: torch.Generator | None) -> Tensor:
        return torch.randperm(b, generator=generator, device=_draw_device(generator)).cpu()

    def _effective(self, params: Params) -> tuple[Tensor, Tensor]:
        """Partner and weight with the gate applied (unchosen samples: themselves, weight 1)."""
        partner, weight = params["partner"], params["weight"]
        gate = params.get("apply")
        if gate is not None:
            partner = torch.where(gate, partner, torch.arange(partner.shape[0]))
            weight = torch.where(gate, weight, torch.ones_like(weight))
        return partner, weight

    def _run(self, frames: Tensor, params: Params) -> Tensor:
        return self.apply(frames, params)  # the gate is folded in by _effective

    def forward(
        self,
        *inputs: Any,
        generator: torch.Generator | None = None,
        params: Params | None = None,
        metadata: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None = None,
    ) -> Any:
        """Mix the frames (first input) and the labels (second input, or ``label_key``).

        See the module docstring: returns ``(frames, labels, *rest)`` for several inputs,
        the frames alone for one, and for a dict the dict with ``"frames"`` and
        ``label_key`` mixed.
        """
        if not inputs:
            raise TypeError(f"{type(self).__name__} needs frames as its first input, got no inputs")
        first = inputs[0]
        frames = first.get(FRAMES_KEY) if isinstance(first, Mapping) else first
        if params is None and isinstance(frames, Tensor):
            if isinstance(first, Mapping) and metadata is None:
                metadata = {k: v for k, v in first.items() if k != FRAMES_KEY}
            plain = frames.as_subclass(Tensor) if _video_of(frames) is not None else frames
            batch, _ = as_batch(check_frames(plain))
            params = self.make_params(batch.shape, generator=generator, metadata=metadata)
        out = super().forward(*inputs, params=params, metadata=metadata)  # checks frames and params
        single = isinstance(frames, Tensor) and frames.dim() == 4
        if isinstance(first, Mapping):
            if self.label_key is not None:
                if self.label_key not in first:
                    raise ValueError(f"label_key {self.label_key!r} is not in the input dict (keys {sorted(first)})")
                out = {**out, self.label_key: self._labels(first[self.label_key], params, single)}
            return out
        if len(inputs) < 2:
            return out
        return (out[0], self._labels(inputs[1], params, single), *out[2:])

    def _labels(self, labels: object, params: Params, single: bool) -> Tensor:
        if not isinstance(labels, Tensor):
            raise TypeError(f"{type(self).__name__} mixes the second input, the labels: expected a tensor, got {type(labels).__name__}")
        batch = labels.unsqueeze(0) if single else labels
        b = params["partner"].shape[0]
        if batch.dim() == 0 or batch.shape[0] != b:
            raise ValueError(
                f"labels must have the batch size {b} first, got shape {tuple(labels.shape)}"
            )
        partner, weight = self._effective(params)
        mixed = _mix_labels(batch, partner, weight, _check_classes(batch, self.num_classes))
        return mixed.squeeze(0) if single else mixed

    def _common(self) -> str:
        settings = f"alpha={self.alpha}"
        if self.num_classes is not None:
            settings += f", num_classes={self.num_classes}"
        if self.label_key is not None:
            settings += f", label_key={self.label_key!r}"
        return settings


class CutMix(_Mixing):
    """Paste a box of a random partner's sequence into each sequence, and mix the labels.

    Yun et al.'s CutMix on event frames (as Neuromorphic Data Augmentation uses it): the
    partners are a random permutation of the batch; λ ~ Beta(α, α), the box has about
    ``(1 - λ)·H·W`` pixels (sides ``√(1 - λ)·H`` and ``√(1 - λ)·W``) at a uniform centre,
    clipped at the border, the same in all frames; the label weight is recomputed from the
    clipped box, ``weight = 1 - h·w / (H·W)``. Counts are moved, so the dtype is kept.
    Mixes the second input (see the module docstring).

    Args:
        alpha: Beta parameter (> 0); 1 draws λ uniformly.
        num_classes: for integer class-index labels, returned as soft targets.
        label_key: for dict inputs, the entry holding the labels.
        p: probability that a sample is mixed (unchosen samples and their labels stay).

    Example:
        >>> frames = torch.poisson(torch.full((4, 6, 2, 9, 11), 0.3))
        >>> force = torch.rand(4, 6)
        >>> mixed, mixed_force = CutMix()(frames, force, generator=torch.Generator().manual_seed(0))
        >>> mixed.shape, mixed_force.shape
        (torch.Size([4, 6, 2, 9, 11]), torch.Size([4, 6]))
        >>> classes = torch.tensor([0, 1, 2, 1])
        >>> CutMix(num_classes=3)(frames, classes)[1].shape
        torch.Size([4, 3])
    """

    def __init__(
        self, alpha: float = 1.0, *, num_classes: int | None = None, label_key: str | None = None, p: float = 1.0
    ) -> None:
        super().__init__(alpha, num_classes=num_classes, label_key=label_key, p=p)

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        b, height, width = shape[0], shape[-2], shape[-1]
        partner = self._partners(b, generator)
        side = torch.sqrt(1 - _beta(self.alpha, b, generator))
        box = _centred_box((side * height).floor().long(), (side * width).floor().long(), shape, generator)
        area = max(height * width, 1)
        weight = 1 - (box["height"] * box["width"]).double() / area
        return {"partner": partner, "weight": weight, **box}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        partner, _ = self._effective(params)
        return _cutmix(frames, partner, params["top"], params["left"], params["height"], params["width"])

    def _settings(self) -> str:
        return self._common()


class MixUp(_Mixing):
    """Blend each sequence with a random partner's, ``λ·x + (1 - λ)·x'``, and mix the labels alike.

    Zhang et al.'s MixUp: partners are a random permutation of the batch, λ ~ Beta(α, α)
    per sample (``params["weight"]``). Values are blended, so the output is float (the
    input dtype for float input, float32 for integer input). Mixes the second input (see
    the module docstring).

    Args:
        alpha: Beta parameter (> 0); small values keep λ near 0 or 1.
        num_classes, label_key, p: as in :class:`CutMix`.

    Example:
        >>> frames = torch.poisson(torch.full((4, 6, 2, 9, 11), 0.3)).to(torch.int16)
        >>> mixed, force = MixUp(0.4)(frames, torch.rand(4, 6), generator=torch.Generator().manual_seed(0))
        >>> mixed.dtype, force.shape
        (torch.float32, torch.Size([4, 6]))
    """

    def __init__(
        self, alpha: float = 0.2, *, num_classes: int | None = None, label_key: str | None = None, p: float = 1.0
    ) -> None:
        super().__init__(alpha, num_classes=num_classes, label_key=label_key, p=p)

    def sample_params(self, shape, *, generator=None, metadata=None) -> Params:
        b = shape[0]
        return {"partner": self._partners(b, generator), "weight": _beta(self.alpha, b, generator)}

    def apply(self, frames: Tensor, params: Params) -> Tensor:
        partner, weight = self._effective(params)
        return _mixup(frames, partner, weight)

    def _settings(self) -> str:
        return self._common()
