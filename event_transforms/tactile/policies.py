"""Policies a user could run without the oracle: inferred, prior, everything, stretch.

The matched ("oracle") methods of a benchmark scene are told the answer: the shift comes
from the deployment's configured delay, the rotation range from its configured angles, the
noise bank from its own camera. Their gains are upper bounds. These policies show what a
user gets without that knowledge, and what simulating effects the scene does not call for
costs:

- ``inferred``: :func:`event_transforms.infer_scene` on the training grasps and the
  deployment's *validation* grasps (frames, and their force labels for the lags), bolt
  sizes as metadata; its policy.
- ``prior``: generic ranges a user could guess without data, one effect per copy (the
  independent combination): frame shifts in [−3, 3] (never 0), rotation ±45°, a ±3 px
  contact shift, a noise bank recorded by a *different* camera (another sensor seed of the
  training camera's model), and the stretch to the deployment size where the bolt sizes
  differ (sizes are metadata a user has).
- ``everything``: *the same* effects with the same ranges, all stacked on every copy (the
  hybrid combination): the naive "augment with everything" policy. ``prior`` vs
  ``everything`` tests one thing, the combination; what stacking means here, named: every
  copy of ``everything`` is shifted by 1–3 frames (the frame shift draws no 0), rotated and
  translated, where a ``prior`` copy gets one of the five effects.
- ``stretch``: :class:`~event_transforms.StretchToTarget`, across the contact strip by
  (D₂/D₁)^½ (Hertz line contact), on scenes whose deployment size differs.
"""

from __future__ import annotations

__all__ = [
    "POLICY_METHODS",
    "PRIOR_SHIFTS",
    "PRIOR_DEGREES",
    "other_camera_bank",
    "stretch_policy",
    "prior_scene",
    "prior_policy",
    "everything_policy",
    "inferred_scene",
    "inferred_policy",
    "policy_rows",
]

import functools
from typing import Any

from torch import Tensor, nn

from ..scenes import Scene, StretchToTarget
from .benchmark_scenes import BenchmarkScene, get_scene

#: Method names whose policies this module builds.
POLICY_METHODS = ("stretch", "inferred", "prior", "everything")
#: The prior's frame shifts (every non-zero shift in [−3, 3]).
PRIOR_SHIFTS = (-3, -2, -1, 1, 2, 3)
#: The prior's rotation range, degrees.
PRIOR_DEGREES = 45.0
#: The "everything" policy's contact shift, pixels.
PRIOR_CONTACT_SHIFT_PX = 3


def stretch_policy(scene: str | BenchmarkScene) -> nn.Module:
    """The stretch to the scene's deployment size (``ValueError`` where sizes do not differ).

    Example:
        >>> stretch_policy("paper")
        StretchToTarget(target_size=15.0, key='diameter_mm', exponent=0.5, axis='contact', center='mass', mode='bilinear')
    """
    scene = get_scene(scene)
    if scene.target_size is None:
        raise ValueError(f"stretch needs a scene whose deployment size differs from training; {scene.name!r} has none")
    return StretchToTarget(scene.target_size)


def other_camera_bank(scene: str | BenchmarkScene, n_frames: int = 360) -> Tensor:
    """Static-scene frames from a camera that is *not* the deployment's: the training
    camera's model with other pixels (sensor seed + 1), as a user could record on any
    camera at hand."""
    from .datasets import noise_bank

    scene = get_scene(scene)
    prior_bank = getattr(scene, "prior_bank", None)
    if prior_bank is not None:  # a folder of recordings: its training camera
        return prior_bank
    config = scene.train.config
    return noise_bank(n_frames, seed=1, config=config.replace(sensor_seed=config.sensor_seed + 1))


def prior_scene(scene: str | BenchmarkScene, bank: Tensor, *, position: bool = True) -> Scene:
    """The generic :class:`~event_transforms.Scene` of ``prior`` and ``everything``
    (``position``: with the ±3 px contact shift; both policies use it)."""
    scene = get_scene(scene)
    sizes: dict[str, Any] = {}
    if scene.target_size is not None:
        sizes = {"training_sizes": scene.train.diameters_mm, "target_size": scene.target_size}
    return Scene(
        lag_shifts=PRIOR_SHIFTS,
        orientation_deg=PRIOR_DEGREES,
        noise=bank,
        contact_shift_px=PRIOR_CONTACT_SHIFT_PX if position else None,
        frame_ms=scene.train.config.frame_ms,
        **sizes,
    )


def prior_policy(scene: str | BenchmarkScene, bank: Tensor | None = None) -> nn.Module:
    """``prior``: generic ranges, one effect per copy.

    Example:
        >>> import torch
        >>> policy = prior_policy("timing", torch.zeros(8, 2, 70, 75))
        >>> [type(t).__name__ for t in policy.transforms]
        ['RandomFrameShift', 'RandomRotation', 'RandomTranslate', 'AddNoise']
    """
    bank = other_camera_bank(scene) if bank is None else bank
    return prior_scene(scene, bank).policy("independent")


def everything_policy(scene: str | BenchmarkScene, bank: Tensor | None = None) -> nn.Module:
    """``everything``: ``prior``'s effects, all stacked on each copy.

    Example:
        >>> import torch
        >>> policy = everything_policy("paper", torch.zeros(8, 2, 70, 75))
        >>> [type(t).__name__ for t in policy.transforms]
        ['RandomFrameShift', 'StretchToTarget', 'RandomRotation', 'RandomTranslate', 'AddNoise']
    """
    bank = other_camera_bank(scene) if bank is None else bank
    return prior_scene(scene, bank, position=True).policy("hybrid")


@functools.lru_cache(maxsize=16)
def _inferred(scene: BenchmarkScene, root: str | None) -> Scene:
    from .lags import infer_scene_with_lags
    from .datasets import TactileGrasps

    train = TactileGrasps("train", root=root, scene=scene)
    deploy = TactileGrasps("val", root=root, scene=scene)
    return infer_scene_with_lags(
        train.frames,
        deploy.frames,
        train_sizes=scene.train.diameters_mm,
        deploy_sizes=scene.deploy.diameters_mm,
        frame_ms=scene.train.config.frame_ms,
        # the timing gap from lags against the force labels (validation data, never test data)
        labelled_train=(train.frames, train.forces),
        labelled_deploy=(deploy.frames, deploy.forces),
    )


def inferred_scene(scene: str | BenchmarkScene, root: str | None = None) -> Scene:
    """:func:`~event_transforms.infer_scene` on the scene's 48 training grasps and its 24
    deployment validation grasps (frames, and the force labels for the lags), bolt sizes as metadata (cached per scene); a
    scene of recordings (:class:`~event_transforms.tactile.recordings.RecordingScene`) holds its own."""
    scene = get_scene(scene)
    inferred = getattr(scene, "inferred", None)
    if inferred is not None:
        return inferred
    return _inferred(scene, None if root is None else str(root))


def inferred_policy(scene: str | BenchmarkScene, root: str | None = None) -> nn.Module:
    """``inferred``: the independent policy of :func:`inferred_scene`."""
    return inferred_scene(scene, root).policy("independent")


def policy_rows(scene: str | BenchmarkScene) -> tuple[str, ...]:
    """The rows these policies add to a scene's table: ``stretch`` where the deployment
    size differs, and ``inferred``, ``prior``, ``everything`` on every gapped scene.

    Example:
        >>> policy_rows("paper"), policy_rows("timing"), policy_rows("control")
        (('stretch', 'inferred', 'prior', 'everything'), ('inferred', 'prior', 'everything'), ())
    """
    scene = get_scene(scene)
    if not scene.gaps:
        return ()
    return (("stretch",) if scene.target_size is not None else ()) + ("inferred", "prior", "everything")


def build_policy(name: str, scene: str | BenchmarkScene) -> nn.Module:
    """The transform of policy method ``name`` (one of :data:`POLICY_METHODS`) on ``scene``."""
    builders = {
        "stretch": stretch_policy,
        "inferred": inferred_policy,
        "prior": prior_policy,
        "everything": everything_policy,
    }
    if name not in builders:
        raise ValueError(f"name must be one of {POLICY_METHODS}, got {name!r}")
    return builders[name](scene)
