"""event-transforms: batched, reproducible augmentations for event-camera frames."""

from __future__ import annotations

from . import functional
from .transforms import *  # noqa: F401,F403
from .transforms import __all__ as _transforms

__version__ = "0.1.0"

__all__ = ["functional", "__version__", *_transforms]
