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
per-frame intercept (41 weights for 36 frames). It is fitted here by a small private
function; after the model work lands it is :class:`~event_transforms.tactile.baselines`'
``PhysicsLeastSquares``.

Measured on the simulator (``benchmarks/fidelity.py``): 12 mm grasps made to look like
15 mm score 92 N² after the paper's zoom, 6.5 after a zoom by β^½, 0.4 after a stretch
across the strip by (15/12)^½, against 0.4 for real 15 mm grasps.
"""

from __future__ import annotations

__all__ = ["physics_features", "fit_physics", "physics_mse", "fidelity", "SIZE_METHODS", "TIME_METHODS"]

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import torch
from torch import Tensor

from .._validation import check_frames, describe

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
        }
    )


_size_methods()


def physics_features(frames: Tensor) -> Tensor:
    """Design matrix of the physics least-squares model, one row per frame.

    Columns: the running signed total OFF − ON and its square (in thousands of events),
    the frame's OFF and ON totals (thousands), and one intercept per frame index.

    Args:
        frames: event counts ``(N, T, 2, H, W)``.

    Returns:
        float64 ``(N·T, 4 + T)``.

    Example:
        >>> frames = torch.zeros(2, 3, 2, 4, 4)
        >>> frames[:, 0, 0] = 1.0  # 16 OFF events in the first frame
        >>> physics_features(frames)[:3, :4].tolist()
        [[0.016, 0.000256, 0.016, 0.0], [0.016, 0.000256, 0.0, 0.0], [0.016, 0.000256, 0.0, 0.0]]
    """
    frames = check_frames(frames)
    if frames.dim() != 5:
        raise ValueError(f"frames must be (N, T, 2, H, W), got {tuple(frames.shape)}")
    totals = frames.double().sum((3, 4)) / 1000  # (N, T, 2)
    running = totals.cumsum(1)
    signed = (running[..., 0] - running[..., 1]).unsqueeze(-1)
    n, t, _ = totals.shape
    intercepts = torch.eye(t, dtype=torch.float64).expand(n, t, t)
    return torch.cat([signed, signed**2, totals, intercepts], -1).reshape(n * t, -1)


def fit_physics(frames: Tensor, forces: Tensor) -> Tensor:
    """Least-squares weights of :func:`physics_features` for ``forces`` ``(N, T)``.

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> frames = torch.randint(0, 3, (8, 4, 2, 3, 3), generator=g).float()
        >>> weights = fit_physics(frames, torch.rand(8, 4, generator=g))
        >>> weights.shape
        torch.Size([8])
    """
    x = physics_features(frames)
    forces = torch.as_tensor(forces, dtype=torch.float64).reshape(-1, 1)
    if forces.shape[0] != x.shape[0]:
        raise ValueError(f"forces must be (N, T) = {tuple(frames.shape[:2])}, got {describe(forces)}")
    return torch.linalg.lstsq(x, forces).solution.squeeze(1)


def physics_mse(weights: Tensor, frames: Tensor, forces: Tensor) -> float:
    """Mean squared error (N²) of the fitted model on ``frames`` against ``forces``."""
    prediction = physics_features(frames) @ weights
    return float((prediction - torch.as_tensor(forces, dtype=torch.float64).reshape(-1)).square().mean())


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
    weights = fit_physics(*fit)
    scores = {"real deployment": physics_mse(weights, *reference)}
    frames, forces, metadata = training
    collated = {key: torch.tensor([float(m[key]) for m in metadata]) for key in (metadata[0] if metadata else {})}
    for name, transform in methods.items():
        copies = frames
        if transform is not None:
            copies = transform(frames, metadata=collated, generator=torch.Generator().manual_seed(seed))
        scores[name] = physics_mse(weights, copies, forces)
    return scores
