"""event-transforms: batched, reproducible augmentations for event-camera frames.

The library:

- :mod:`event_transforms.functional`: pure kernels (tensor first, options keyword-only);
- :mod:`event_transforms.transforms`: ``nn.Module`` transforms, :class:`EventsToFrames`
  (event streams, tonic's arrays included, to frames) and the containers
  :class:`Compose`, :class:`OneOf`, :class:`RandomApply` (all re-exported here);
- :mod:`event_transforms.scenes`: :class:`Scene`, which builds only the transforms for the
  physical effects a setup declares;
- :mod:`event_transforms.inference`: :func:`infer_scene`, a scene estimated from training
  frames and unlabeled deployment frames;
- :mod:`event_transforms.data`: :class:`AugmentedDataset`, synthetic copies of any data set;
- :mod:`event_transforms.authoring`: what writing a transform needs (:class:`EventTransform`,
  ``Param``, ``Params``, ``as_transform``, ``check_args``, ``slice_params``), apart from the
  transforms (also importable from the top level, not listed in ``__all__``);
- :mod:`event_transforms.viz`: pictures of event frames.

Names are imported on first use (PEP 562), so ``import event_transforms`` costs little
and the command line answers ``--help`` without importing torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.2.0.dev0"

# public name -> the module that defines it; every name in ``transforms.__all__`` (the one
# list of transforms) is a top-level name as well, looked up there on first use
_NAMES: dict[str, str] = {
    "Scene": "scenes",
    "ResizeToTarget": "scenes",
    "StretchToTarget": "scenes",
    "infer_scene": "inference",
    "AugmentedDataset": "data",
    "EventBatch": "events",
    "collate_events": "events",
    "count_dropped": "events",
    "set_compiled_kernels": "_compile",
    "compiled_kernels": "_compile",
    "compiled_kernels_enabled": "_compile",
}
_SUBMODULES = ("functional", "events", "transforms", "authoring", "scenes", "inference", "data", "viz")

#: Importable from the top level for compatibility, not listed in ``__all__``: the authoring
#: names live in :mod:`event_transforms.authoring` (the transforms are what ``__all__`` lists).
_AUTHORING = ("EventTransform", "Param", "Params", "as_transform", "slice_params", "check_args")


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    # the `as` aliases mark these as re-exports (__all__ is computed, so linters cannot see it)
    from . import data as data, functional as functional, inference as inference, scenes as scenes
    from . import authoring as authoring, transforms as transforms, viz as viz
    from .authoring import EventTransform as EventTransform, Param as Param, Params as Params
    from .authoring import as_transform as as_transform, check_args as check_args, slice_params as slice_params
    from .data import AugmentedDataset as AugmentedDataset
    from .events import EventBatch as EventBatch, collate_events as collate_events, count_dropped as count_dropped
    from ._compile import compiled_kernels as compiled_kernels, compiled_kernels_enabled as compiled_kernels_enabled
    from ._compile import set_compiled_kernels as set_compiled_kernels
    from .inference import infer_scene as infer_scene
    from .scenes import ResizeToTarget as ResizeToTarget, Scene as Scene, StretchToTarget as StretchToTarget
    from .transforms import *  # noqa: F403


def _transform_names() -> list[str]:
    return list(importlib.import_module(f"{__name__}.transforms").__all__)


def __getattr__(name: str) -> Any:
    if name == "__all__":  # imports the transforms (``from event_transforms import *``)
        return ["__version__", *_SUBMODULES, *_transform_names(), *_NAMES]
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _NAMES or name in _AUTHORING:
        value = getattr(importlib.import_module(f"{__name__}.{_NAMES.get(name, 'authoring')}"), name)
        globals()[name] = value  # later lookups skip this function
        return value
    if not name.startswith("_") and name[:1].isupper() and name in _transform_names():
        value = getattr(importlib.import_module(f"{__name__}.transforms"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__getattr__("__all__")))
