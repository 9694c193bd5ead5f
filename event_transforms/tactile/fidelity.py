"""Fidelity of an augmentation, measured without any network.

An augmentation simulates a physical effect; if it simulates it well, augmented training
grasps look like real deployment grasps *with the same forces*. A model that knows the
physics and nothing else can check that: fit a small least-squares model of force on
deployment-like grasps, then score it on

- real deployment grasps it was not fitted on (the reference: the best an augmented copy
  can do),
- the training grasps untransformed (what no augmentation gives), and
- the training grasps after each augmentation, against their own, unchanged labels.

A faithful augmentation scores near the reference; one that simulates the wrong physics
scores far above it, whatever a network later makes of it. The model is the physics
least-squares model of the design notes: force per frame from the running signed event
total (OFF − ON: the membrane's indentation), its square, the frame's own totals and a
per-frame intercept (40 weights for 36 frames):
:class:`~event_transforms.tactile.baselines.PhysicsLeastSquares`, the same model that is a
row of every benchmark table.

Measured on the simulator (``benchmarks/tactile/fidelity.py``): 12 mm grasps made to look like
15 mm score 92 N² after the paper's zoom, 6.5 after a zoom by β^½, 0.4 after a stretch
across the strip by (15/12)^½, against 0.4 for real 15 mm grasps.
"""

from __future__ import annotations

__all__ = ["fidelity", "SIZE_METHODS", "TIME_METHODS"]

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import torch
from torch import Tensor

from .baselines import PhysicsLeastSquares

#: Size methods: name -> (target size) -> transform reading ``diameter_mm`` metadata.
SIZE_METHODS: dict[str, Callable[[float], Any]] = {}
#: Time-shift methods: name -> transform.
TIME_METHODS: dict[str, Callable[[], Any]] = {}


def _size_methods() -> None:
    from ..scenes import ResizeToTarget, StretchToTarget
    from ..transforms.temporal import FrameShift, TemporalEventShift

    SIZE_METHODS.update(
        {
            "resize": lambda target: ResizeToTarget(target, exponent=1.0),
            "resize-hertz": lambda target: ResizeToTarget(target, exponent=0.5),
            "stretch": lambda target: StretchToTarget(target, exponent=0.5),
        }
    )
    TIME_METHODS.update(
        {
            "fs-1": lambda: FrameShift(-1),
            "tes-2:0.5": lambda: TemporalEventShift(-2, 0.5),
            "fs1": lambda: FrameShift(1),
            "tes1:0.5": lambda: TemporalEventShift(1, 0.5),
        }
    )


_size_methods()


def fidelity(
    fit: tuple[Tensor, Tensor],
    reference: tuple[Tensor, Tensor],
    training: tuple[Tensor, Tensor, Sequence[Mapping[str, Any]]],
    methods: Mapping[str, Any],
    *,
    seed: int = 0,
) -> dict[str, float]:
    """Score augmented training copies with a physics model fitted on deployment-like data.

    Args:
        fit: ``(frames, forces)`` of deployment-like grasps to fit the model on.
        reference: ``(frames, forces)`` of other real deployment grasps.
        training: ``(frames, forces, metadata)`` of the training grasps (metadata: one dict
            per grasp, e.g. ``{"diameter_mm": 12.0}``, handed to the transforms).
        methods: name -> transform (``None`` for the untransformed copies), each called on
            the training frames with ``metadata=`` and a seeded generator.
        seed: the generator's seed.

    Returns:
        ``{"real deployment": mse, name: mse, ...}`` in N².

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> frames = torch.randint(0, 3, (6, 4, 2, 3, 3), generator=g).float()
        >>> forces = frames.sum((2, 3, 4)) / 10
        >>> out = fidelity((frames, forces), (frames, forces), (frames, forces, [{}] * 6), {"none": None})
        >>> sorted(out), out["none"] < 1e-12
        (['none', 'real deployment'], True)
    """
    model = PhysicsLeastSquares().fit(*fit)

    def mse(frames: Tensor, forces: Tensor) -> float:
        target = torch.as_tensor(forces, dtype=torch.float64).reshape(frames.shape[:2])
        return float((model.predict(frames) - target).square().mean())

    scores = {"real deployment": mse(*reference)}
    frames, forces, metadata = training
    collated = {key: torch.tensor([float(m[key]) for m in metadata]) for key in (metadata[0] if metadata else {})}
    for name, transform in methods.items():
        copies = frames
        if transform is not None:
            copies = transform(frames, metadata=collated, generator=torch.Generator().manual_seed(seed))
        scores[name] = mse(copies, forces)
    return scores
