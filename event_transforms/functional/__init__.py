"""Pure kernels: tensor first, options keyword-only, per-sample parameters as (B,) tensors.

Every kernel accepts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` event frames, never modifies
its input, and returns a tensor on the input's device.
"""

from __future__ import annotations

from .affine import *  # noqa: F401,F403
from .affine import __all__ as _affine
from .stretch import *  # noqa: F401,F403
from .stretch import __all__ as _stretch
from .temporal import *  # noqa: F401,F403
from .temporal import __all__ as _temporal
from .noise import *  # noqa: F401,F403
from .noise import __all__ as _noise
from ..events.binning import *  # noqa: F401,F403
from ..events.binning import __all__ as _events
from ..events.streaming import *  # noqa: F401,F403
from ..events.streaming import __all__ as _streaming

from .geometry import *  # noqa: F401,F403
from .geometry import __all__ as _geometry
from .polarity import *  # noqa: F401,F403
from .polarity import __all__ as _polarity
from .mixing import *  # noqa: F401,F403
from .mixing import __all__ as _mixing
from .cleaning import *  # noqa: F401,F403
from .cleaning import __all__ as _cleaning
from .drop import *  # noqa: F401,F403
from .drop import __all__ as _drop
from .representations import *  # noqa: F401,F403
from .representations import __all__ as _representations

from ..events.batch import *  # noqa: F401,F403
from ..events.batch import __all__ as _event_batch
from .event_kernels import *  # noqa: F401,F403
from .event_kernels import __all__ as _event_kernels

__all__ = [
    *_affine, *_temporal, *_noise, *_events, *_streaming, *_geometry, *_polarity, *_mixing, *_cleaning, *_drop, *_representations,
    *_event_batch, *_event_kernels,
]
