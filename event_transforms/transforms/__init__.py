"""Transform modules (settings + per-sample parameter draws) and containers.

``__all__`` lists the transforms; the names for writing one (:class:`EventTransform`, ``Param``,
``Params``, ``as_transform``) are importable from here and listed in :mod:`event_transforms.authoring`.
"""

from __future__ import annotations

from .base import Lambda
from .base import EventTransform as EventTransform, Param as Param, Params as Params, as_transform as as_transform
from .affine import *  # noqa: F401,F403
from .affine import __all__ as _affine
from .stretch import *  # noqa: F401,F403
from .stretch import __all__ as _stretch
from .temporal import *  # noqa: F401,F403
from .temporal import __all__ as _temporal
from .noise import *  # noqa: F401,F403
from .noise import __all__ as _noise
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
from .containers import *  # noqa: F401,F403
from .containers import __all__ as _containers
from .events import *  # noqa: F401,F403
from .events import __all__ as _events
from .emulate import *  # noqa: F401,F403
from .emulate import __all__ as _emulate

# The transforms only; the authoring names (EventTransform, Param, Params, as_transform) are
# importable from here too, and listed in event_transforms.authoring.
__all__ = [
    "Lambda",
    *_affine, *_stretch, *_temporal, *_noise, *_geometry, *_polarity, *_mixing, *_cleaning, *_drop, *_containers, *_events, *_emulate,
]
