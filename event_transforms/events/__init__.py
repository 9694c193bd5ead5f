"""Event streams: the padded :class:`EventBatch`, binning into frames, streaming.

- :mod:`event_transforms.events._ingest` (private): every in-memory input form to canonical
  columns ``x, y, t, p`` in microseconds, and the checks of the binning's settings;
- :mod:`event_transforms.events.batch`: :class:`EventBatch`, :func:`collate_events`;
- :mod:`event_transforms.events.binning`: :func:`events_to_frames` (streams, or an
  :class:`EventBatch`, to ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` frames) and
  :func:`bin_events`, one binning kernel;
- :mod:`event_transforms.events.dropped`: :func:`count_dropped` (events dropped by design,
  counted) and the two warnings for events of the caller's input outside what it declared;
- :mod:`event_transforms.events.streaming`: :func:`iter_frames`, frames from a stream read
  in chunks.

Every name here is also importable from :mod:`event_transforms.functional`.

An :class:`EventBatch` is registered with ``torch.utils._pytree`` as a node that refuses to
be flattened: torchvision's v2 transforms flatten their inputs that way, so
``torchvision.transforms.v2.RandomRotation(30)(batch)`` raises a ``TypeError`` that names the
EventBatch instead of returning it untouched (v2 passes through every type it does not know).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from .batch import EventBatch, collate_events
from .binning import CHUNK_EVENTS, MAX_BYTES, bin_events, events_to_frames
from .dropped import DroppedEvents, EventsOutsideSensorWarning, EventsOutsideWindowWarning, count_dropped
from .streaming import iter_frames

from torch.utils import _pytree


def _refuse_flatten(batch: EventBatch) -> tuple[list, None]:
    raise TypeError(
        f"an EventBatch ({len(batch)} streams) cannot be taken apart into tensors: torchvision's transforms "
        "would pass it through untouched; use the event_transforms transforms (they take an EventBatch) or "
        "bin it first with event_transforms.EventsToFrames"
    )


def _unflatten(children: Iterable[Any], context: Any) -> EventBatch:  # pragma: no cover - never flattened
    raise TypeError("an EventBatch cannot be rebuilt from a pytree")


_pytree.register_pytree_node(EventBatch, _refuse_flatten, _unflatten)

__all__ = [
    "EventBatch", "events_to_frames", "iter_frames", "collate_events", "bin_events",
    "EventsOutsideSensorWarning", "EventsOutsideWindowWarning", "CHUNK_EVENTS", "MAX_BYTES",
    "count_dropped", "DroppedEvents",
]
