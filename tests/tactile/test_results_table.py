"""The results table of the docs is what the README's main command printed.

``event-transforms reproduce`` writes a summary table (``report.format_summary_table``) at the
top of ``results.md``; ``benchmarks/tactile/reproduce_quick.md`` is that output, and the Results page of
the docs (``docs/results.md``, moved there from the README) shows the same table. These tests parse the markdown tables and compare them cell by cell.
"""

from __future__ import annotations

import re
from pathlib import Path

from event_transforms.tactile.report import SUMMARY_COLUMNS

ROOT = Path(__file__).resolve().parents[2]


def markdown_tables(text: str) -> list[list[list[str]]]:
    """Every markdown table in ``text`` as rows of stripped cells (the separator row dropped)."""
    tables, current = [], []
    for line in text.splitlines() + [""]:
        line = line.strip()
        if line.startswith("|") and line.endswith("|"):
            cells = [cell.strip() for cell in line[1:-1].split("|")]
            if not all(re.fullmatch(r":?-{3,}:?", cell) for cell in cells):
                current.append(cells)
        elif current:
            tables.append(current)
            current = []
    return tables


def summary_table(text: str) -> list[list[str]] | None:
    """The table whose header is the summary table's, or ``None``."""
    for table in markdown_tables(text):
        if tuple(table[0]) == SUMMARY_COLUMNS:
            return table
    return None


def test_parser_reads_cells_and_skips_the_separator():
    text = "intro\n\n| a | b |\n|---|---|\n| 1 | x y |\n\ntext\n| c |\n|:---:|\n| 2 |\n"
    assert markdown_tables(text) == [[["a", "b"], ["1", "x y"]], [["c"], ["2"]]]


def test_readme_table_is_the_printed_table_cell_by_cell():
    printed = summary_table((ROOT / "benchmarks" / "tactile" / "reproduce_quick.md").read_text())
    assert printed is not None, (
        "benchmarks/tactile/reproduce_quick.md has no summary table: regenerate it and the table of docs/results.md with the "
        "README's main command on the release commit"
    )
    readme = summary_table((ROOT / "docs" / "results.md").read_text())
    assert readme is not None, "docs/results.md has no table with the summary table's columns"
    assert len(readme) == len(printed), f"docs/results.md has {len(readme) - 1} rows, the printed table {len(printed) - 1}"
    for index, (mine, theirs) in enumerate(zip(readme, printed)):
        for column, a, b in zip(SUMMARY_COLUMNS, mine, theirs):
            assert a == b, f"row {index} ({mine[0]} / {mine[1]}), column {column!r}: docs/results.md {a!r}, printed {b!r}"


def test_printed_table_names_a_clean_commit():
    text = (ROOT / "benchmarks" / "tactile" / "reproduce_quick.md").read_text()
    assert summary_table(text) is not None, "benchmarks/tactile/reproduce_quick.md has no summary table"
    match = re.search(r"Produced by commit `([^`]+)`", text)
    assert match and re.fullmatch(r"[0-9a-f]{40}", match[1]), f"not a clean commit hash: {match and match[1]!r}"
