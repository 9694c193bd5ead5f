"""Helpers of the benchmark scripts' tests: a results file with a section to keep, and a section's text."""

from __future__ import annotations

from pathlib import Path


def results_file(tmp_path: Path) -> Path:
    """A results file holding one section (``simulation``) that a script's run must keep as is."""
    path = tmp_path / "RESULTS.md"
    path.write_text(
        "# Benchmark results\n\n<!-- simulation:start -->\nkept as is\n<!-- simulation:end -->\n"
    )
    return path


def section(path: Path, name: str) -> str:
    """The text of section ``name``, checking it appears once and the kept section is untouched."""
    text = path.read_text()
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    assert text.count(start) == 1 and text.count(end) == 1
    assert "<!-- simulation:start -->\nkept as is\n<!-- simulation:end -->" in text
    return text[text.index(start) + len(start) : text.index(end)]
