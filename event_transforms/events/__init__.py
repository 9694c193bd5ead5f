"""Event streams: the padded :class:`EventBatch`, binning into frames, streaming.

- :mod:`event_transforms.events.binning`: :func:`events_to_frames` (streams to ``(T, 2, H, W)``
  or ``(B, T, 2, H, W)`` frames) and the warnings it gives for events it drops;
- :mod:`event_transforms.events.batch`: :class:`EventBatch`, :func:`collate_events`,
  :func:`bin_events`;
- :mod:`event_transforms.events.streaming`: :func:`iter_frames`, frames from a stream read
  in chunks.

Every name here is also importable from :mod:`event_transforms.functional`.
"""

from __future__ import annotations

from .batch import EventBatch, bin_events, collate_events
from .binning import CHUNK_EVENTS, MAX_BYTES, EventsOutsideSensorWarning, EventsOutsideWindowWarning, events_to_frames
from .streaming import iter_frames

__all__ = [
    "EventBatch", "events_to_frames", "iter_frames", "collate_events", "bin_events",
    "EventsOutsideSensorWarning", "EventsOutsideWindowWarning", "CHUNK_EVENTS", "MAX_BYTES",
]
