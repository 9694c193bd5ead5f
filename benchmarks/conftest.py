"""The benchmarks' own tests (``test_*.py`` beside the scripts) are collected; the scripts are
run, not imported for doctests (some import optional peers such as tonic at module level)."""

from __future__ import annotations

from pathlib import Path


def pytest_ignore_collect(collection_path: Path, config: object) -> bool | None:
    name = collection_path.name
    if collection_path.suffix == ".py" and not name.startswith(("test_", "conftest")):
        return True
    return None
