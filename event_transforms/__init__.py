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
- :mod:`event_transforms.viz`: pictures of event frames.

The tactile application built on it (simulator, data sets, reference model, training,
protocol, command line) lives in :mod:`event_transforms.tactile`.

Names are imported on first use (PEP 562), so ``import event_transforms`` costs little
and the command line answers ``--help`` without importing torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.2.0.dev0"

# public name -> the module that defines it
_TRANSFORMS = (
    "EventTransform", "Params", "Lambda", "as_transform",
    "Rotate", "RandomRotation", "Resize", "RandomResize",
    "HorizontalFlip", "VerticalFlip", "RandomHorizontalFlip", "RandomVerticalFlip",
    "FrameShift", "RandomFrameShift", "TemporalEventShift", "RandomTemporalEventShift",
    "AddNoise", "AddPoissonNoise", "RandomEventDrop",
    "Compose", "OneOf", "RandomApply", "EventsToFrames",
    # transform coverage (issue 13)
    "Affine", "RandomAffine", "Translate", "RandomTranslate", "RandomCrop", "CenterCrop", "Downsample",
    "FlipPolarity", "RandomFlipPolarity", "TimeReversal", "RandomTimeReversal", "MergePolarities",
    "CropTime", "RandomCropTime", "Cutout", "CutMix", "MixUp",
    "DropPixel", "RandomDropPixel", "Denoise",
    # events (issue 20)
    "SpatialJitter", "TimeJitter", "TimeSkew", "RefractoryPeriod", "Decimation",
    # sequence warps (issue 19)
    "RandomPerspective", "RandomElastic",
    # scenes (issue 18)
    "Stretch", "RandomStretch",
)
_NAMES: dict[str, str] = {
    **{name: "transforms" for name in _TRANSFORMS},
    "Scene": "scenes",
    "ResizeToTarget": "scenes",
    "StretchToTarget": "scenes",
    "infer_scene": "inference",
    "AugmentedDataset": "data",
    "EventBatch": "functional",
    "collate_events": "functional",
}
_SUBMODULES = ("functional", "events", "transforms", "scenes", "inference", "data", "viz", "tactile")

__all__ = ["__version__", *_SUBMODULES, *_NAMES]

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from . import data, functional, inference, scenes, tactile, transforms, viz
    from .data import AugmentedDataset
    from .functional import EventBatch, collate_events
    from .inference import infer_scene
    from .scenes import ResizeToTarget, Scene, StretchToTarget
    from .transforms import *  # noqa: F403


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _NAMES:
        value = getattr(importlib.import_module(f"{__name__}.{_NAMES[name]}"), name)
        globals()[name] = value  # later lookups skip this function
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
