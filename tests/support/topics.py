"""The topic test files (``tests/library/test_<topic>.py``) and the battery entries each one declares."""

from __future__ import annotations

import importlib

TOPICS = ("affine", "geometry", "temporal", "noise", "drop", "polarity", "mixing", "cleaning", "stretch", "containers")


def collect(name: str) -> dict:
    """``{**test_<topic>.<name>}`` over every topic (``BATTERY``, ``SHAPE_BATTERY``, ``EVENT_BATTERY``)."""
    out: dict = {}
    for topic in TOPICS:
        entries = getattr(importlib.import_module(f"tests.library.test_{topic}"), name, {})
        clash = set(out) & set(entries)
        assert not clash, f"battery names declared twice: {sorted(clash)}"
        out.update(entries)
    return out
