"""Operations, one topic file each: a public dispatcher and its kernels per input type.

Each operation (``rotate``, ``frame_shift``, ``drop_random``, ...) is a dispatcher that
takes event frames ``(T, 2, H, W)`` / ``(B, T, 2, H, W)`` or an
:class:`~event_transforms.EventBatch`, checks its arguments and calls the kernel registered
for the input's type (:func:`register_kernel`): ``<op>_frames`` or ``<op>_events``, side by
side in the same file. Nothing is modified in place; the device is kept. An input type
without a kernel is refused by name (``TypeError``).
"""

from __future__ import annotations

from .affine import *  # noqa: F401,F403
from .affine import __all__ as _affine
from .perspective import *  # noqa: F401,F403
from .perspective import __all__ as _perspective
from .elastic import *  # noqa: F401,F403
from .elastic import __all__ as _elastic
from .stretch import *  # noqa: F401,F403
from .stretch import __all__ as _stretch
from .temporal import *  # noqa: F401,F403
from .temporal import __all__ as _temporal
from .timestamps import *  # noqa: F401,F403
from .timestamps import __all__ as _timestamps
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
from .emulate import *  # noqa: F401,F403
from .emulate import __all__ as _emulate

from ..events.batch import *  # noqa: F401,F403
from ..events.batch import __all__ as _event_batch
from ._dispatch import call_kernel, has_kernel, kernel_for, register_kernel

__all__ = [
    *_affine, *_perspective, *_elastic, *_stretch, *_temporal, *_timestamps, *_noise, *_events, *_streaming, *_geometry, *_polarity, *_mixing, *_cleaning, *_drop,
    *_representations, *_emulate, *_event_batch, "register_kernel", "kernel_for", "call_kernel", "has_kernel",
]
