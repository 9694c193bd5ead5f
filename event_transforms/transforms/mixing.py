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
``params`` (``partner``, ``weight``, for CutMix ``top, left, height, width``, and for
MixUp the per-sample ``seed`` of its event draws), so a call replays and the weights can be
logged.

**On an EventBatch** (``module(batch, labels)``) the events are mixed as whole events and
the labels exactly as on frames: CutMix takes the partner's events inside the box instead
of the sample's own, MixUp keeps each own event with probability λ and takes each of the
partner's with probability 1 - λ (counter-based draws keyed by ``params["seed"]``), so the
binned frames equal frame MixUp's in expectation; see
:mod:`event_transforms.functional.mixing`.

Use CutMix and MixUp on a collated batch, as torchvision's are used after the DataLoader.
They declare :attr:`~event_transforms.EventTransform.couples_samples`: a
:class:`~event_transforms.Compose` holding one mixes the labels too (it runs every member
on the whole batch), while :class:`~event_transforms.OneOf` and
:class:`~event_transforms.RandomApply`, which hand members sub-batches, refuse them at
construction with a ``TypeError`` (use ``CutMix(p=...)`` for a per-sample gate).

Mixing the regression targets of two sequences is a heuristic (a pasted box does not carry
a share of the target proportional to its area); it is offered because NDA uses CutMix, not
because it simulates a physical effect a scene declares.
"""

from __future__ import annotations

from typing import Any

from collections.abc import Sequence

import math

import torch
from torch import Tensor

from .._validation import as_number, check_positive
from ..events.batch import EventBatch
from ..functional._frame_ops import frame_size
from .. import functional as F
from ..functional._dispatch import call_kernel
from ..functional._frame_ops import blend_labels, check_classes
from ..functional.mixing import CUTOUT_SPEC, cutmix_spec, mix_labels_spec, mixup_spec
from .base import EventTransform, Param, Params, _draw_device, integers, seeds

__all__ = ["Cutout", "CutMix", "MixUp"]


def _centred_box(
    size_h: Tensor, size_w: Tensor, shape: Sequence[int], generator: torch.Generator | None
) -> dict[str, Tensor]:
    """Boxes of (B,) sizes at uniform centres, clipped to the frame: top, left, height, width."""
    b, height, width = shape[0], shape[-2], shape[-1]
    cy = integers(max(height, 1), b, generator)
    cx = integers(max(width, 1), b, generator)
    top = (cy - size_h // 2).clamp(0, height)
    left = (cx - size_w // 2).clamp(0, width)
    bottom = (cy - size_h // 2 + size_h).clamp(0, height)
    right = (cx - size_w // 2 + size_w).clamp(0, width)
    return {"top": top, "left": left, "height": bottom - top, "width": right - left}


#: Marsaglia-Tsang candidates per draw and round (each accepted with probability above 0.95).
_GAMMA_CANDIDATES = 4
#: Rounds after which :func:`_log_gamma` gives up (never reached in practice: 0.05**(4 * 64)).
_GAMMA_ROUNDS = 64


def _log_gamma(alpha: float, size: int, generator: torch.Generator | None) -> Tensor:
    """``log`` of ``size`` Gamma(alpha, 1) draws (float64, CPU) from ``generator``.

    Marsaglia & Tsang (2000) for shape ``a = max(alpha, alpha + 1)``: ``d = a - 1/3``,
    ``c = 1 / sqrt(9 d)``, candidate ``d v`` with ``v = (1 + c x)**3`` for a standard normal x,
    accepted when ``log u < x**2 / 2 + d - d v + d log v``; ``_GAMMA_CANDIDATES`` candidates per
    draw and round, the first accepted kept, rounds until all are accepted (CPU tensors, no
    device read). For ``alpha < 1`` the draw of shape ``alpha + 1`` is boosted by
    ``U**(1 / alpha)``, added as ``log U / alpha`` (logs, so tiny draws do not underflow).
    """
    shape = alpha if alpha >= 1.0 else alpha + 1.0
    d = shape - 1.0 / 3.0
    c = 1.0 / math.sqrt(9.0 * d)
    device = _draw_device(generator)
    out = torch.zeros(size, dtype=torch.float64)
    pending = torch.ones(size, dtype=torch.bool)
    column = torch.arange(_GAMMA_CANDIDATES)
    for _ in range(_GAMMA_ROUNDS):
        x = torch.randn(size, _GAMMA_CANDIDATES, generator=generator, device=device, dtype=torch.float64).cpu()
        u = torch.rand(size, _GAMMA_CANDIDATES, generator=generator, device=device, dtype=torch.float64).cpu()
        v = (1.0 + c * x) ** 3
        log_v = v.clamp_min(1e-300).log()
        accept = (v > 0) & (u.log() < 0.5 * x * x + d - d * v + d * log_v)
        first = torch.where(accept, column, _GAMMA_CANDIDATES).amin(1)
        chosen = (math.log(d) + log_v).gather(1, first.clamp_max(_GAMMA_CANDIDATES - 1).unsqueeze(1)).squeeze(1)
        found = pending & (first < _GAMMA_CANDIDATES)
        out = torch.where(found, chosen, out)
        pending &= ~found
        if not bool(pending.any()):
            break
    else:  # pragma: no cover - probability below 1e-300
        raise RuntimeError("Gamma sampling did not finish")
    if alpha < 1.0:
        boost = torch.rand(size, generator=generator, device=device, dtype=torch.float64).cpu()
        out = out + boost.log() / alpha
    return out


def _beta(alpha: float, batch: int, generator: torch.Generator | None) -> Tensor:
    """``batch`` Beta(alpha, alpha) draws (float64, CPU) from ``generator`` (or torch's RNG):
    ``X / (X + Y)`` for independent Gamma(alpha) draws X, Y (:func:`_log_gamma`), computed
    as ``sigmoid(log X - log Y)``."""
    log_xy = _log_gamma(alpha, 2 * batch, generator)
    return torch.sigmoid(log_xy[:batch] - log_xy[batch:])


class Cutout(EventTransform):
    """Empty a box of each sequence, at a uniform random centre, in all its frames.

    DeVries & Taylor's Cutout as Neuromorphic Data Augmentation uses it: a box of
    ``size`` centred at a uniformly drawn pixel, clipped at the border (so near the border
    it is smaller). Counts elsewhere and the dtype are kept. On an EventBatch the events in
    the box are removed. The clipped box is in
    ``params`` (``top, left, height, width``).

    Args:
        size: ``n`` or ``(h, w)`` pixels.
        p: probability that a sample is cut.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept.

    Example:
        >>> out = Cutout(3)(torch.ones(2, 4, 2, 9, 11), generator=torch.Generator().manual_seed(0))
        >>> out.shape, (out == 0).any().item()
        (torch.Size([2, 4, 2, 9, 11]), True)
    """

    def __init__(self, size: int | Sequence[int], *, p: float = 1.0) -> None:
        super().__init__(p=p)
        self.size = frame_size(size, "size")

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b = shape[0]
        h = torch.full((b,), self.size[0], dtype=torch.int64)
        w = torch.full((b,), self.size[1], dtype=torch.int64)
        return _centred_box(h, w, shape, generator)

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return CUTOUT_SPEC

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.cutout, inputs, params["top"], params["left"], params["height"], params["width"])

    def _settings(self) -> str:
        return f"size={self.size}"


class _Mixing(EventTransform):
    """Mixes each sample with ``params["partner"]`` of the same batch; mixes the labels too.

    Declares :attr:`~EventTransform.couples_samples` and its :attr:`~EventTransform.partner_key`:
    the base class hands it the labels through :meth:`apply_labels`, and its per-sample
    gate ``p`` gathers the chosen samples with the partners they read (an unchosen sample
    and its labels stay, and is still read as a partner, unchanged).
    """

    couples_samples = True
    partner_key = "partner"

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

    def apply_labels(self, labels: Tensor, params: Params) -> Tensor:
        """Mix ``labels`` (B, ...) with the partners and weights of ``params`` (the base-class hook)."""
        return blend_labels(labels, params["partner"], params["weight"], check_classes(labels, self.num_classes))

    def keep_labels(self, labels: Tensor) -> Tensor:
        """Labels of samples the gate skips: their own, as one-hot targets for class indices."""
        own = torch.arange(labels.shape[0])
        return blend_labels(labels, own, torch.ones(labels.shape[0], dtype=torch.float64), check_classes(labels, self.num_classes))

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

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; dtype and device kept. The labels:
        float ``(B, ...)`` kept in shape and dtype; integer class indices ``(B,)`` -> float
        ``(B, num_classes)``.

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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b, height, width = shape[0], shape[-2], shape[-1]
        partner = self._partners(b, generator)
        side = torch.sqrt(1 - _beta(self.alpha, b, generator))
        box = _centred_box((side * height).floor().long(), (side * width).floor().long(), shape, generator)
        area = max(height * width, 1)
        weight = 1 - (box["height"] * box["width"]).double() / area
        return {"partner": partner, "weight": weight, **box}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return {**cutmix_spec(shape), "weight": mix_labels_spec(shape[0])["weight"]}

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.cutmix, inputs, params["partner"], params["top"], params["left"], params["height"], params["width"])

    def _settings(self) -> str:
        return self._common()


class MixUp(_Mixing):
    """Blend each sequence with a random partner's, ``λ·x + (1 - λ)·x'``, and mix the labels alike.

    Zhang et al.'s MixUp: partners are a random permutation of the batch, λ ~ Beta(α, α)
    per sample (``params["weight"]``). Values are blended, so the output is float (the
    input dtype for float input, float32 for integer input). Mixes the second input (see
    the module docstring). On an EventBatch a share λ of the sample's events and 1 - λ of
    its partner's are kept, drawn per event from ``params["seed"]`` (unused on frames).

    Args:
        alpha: Beta parameter (> 0); small values keep λ near 0 or 1.
        num_classes, label_key, p: as in :class:`CutMix`.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, unchanged; float input keeps its dtype, integer
        input gives float32 (a weighted sum). The labels: float ``(B, ...)`` kept in shape and dtype; integer class
        indices ``(B,)`` -> float ``(B, num_classes)``.

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

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        b = shape[0]
        partner, weight = self._partners(b, generator), _beta(self.alpha, b, generator)
        return {"partner": partner, "weight": weight, "seed": seeds(b, generator)}

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return mixup_spec(shape)

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return call_kernel(F.mixup, inputs, params["partner"], params["weight"], params["seed"])

    def _settings(self) -> str:
        return self._common()
