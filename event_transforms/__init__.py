"""event-transforms: batched, reproducible augmentations for event-camera frames."""

from __future__ import annotations

from . import datasets, functional, models, scenes, simulation, viz
from .scenes import ResizeToTarget, Scene, ScenePolicy
from .transforms import *  # noqa: F401,F403
from .transforms import __all__ as _transforms

__version__ = "0.1.0"

__all__ = [
    "functional", "datasets", "models", "scenes", "simulation", "viz", "__version__",
    "Scene", "ScenePolicy", "ResizeToTarget", *_transforms,
]
