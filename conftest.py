"""Fixtures for every test of the repository (``tests/``, the benchmarks' tests, the doctests)."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True, scope="session")
def _cache_root(tmp_path_factory):
    """Data-set caches go to a temporary folder, never to ``~/.cache``."""
    patch = pytest.MonkeyPatch()
    patch.setenv("EVENT_TRANSFORMS_CACHE", str(tmp_path_factory.mktemp("cache")))
    yield
    patch.undo()
