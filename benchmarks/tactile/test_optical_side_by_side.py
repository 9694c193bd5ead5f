"""The optical side-by-side: its outcomes recomputed from two summary tables, and the committed
pages' side-by-side recomputed from the committed runs (``reproduce_quick.md``, ``optical.md``)."""

from __future__ import annotations

import re
from pathlib import Path

from benchmarks.tactile import optical

from event_transforms.tactile.report import SUMMARY_COLUMNS

ROOT = Path(__file__).resolve().parents[2]
RERENDER = "python -m benchmarks.tactile.optical --render-only"


def _summary(*rows: tuple[str, str, str]) -> str:
    """A summary table of (scene, method, Δ vs none cell) rows, the other cells empty."""
    lines = ["| " + " | ".join(SUMMARY_COLUMNS) + " |", "|---" * len(SUMMARY_COLUMNS) + "|"]
    for scene, method, cell in rows:
        lines.append(f"| {scene} | {method} | 1.00 | {cell} | — | — | — | — |")
    return "\n".join(lines)


def _section(path: Path) -> str:
    text = path.read_text()
    found = re.search(r"<!-- optical-side-by-side:start -->\n(.*?)\n<!-- optical-side-by-side:end -->", text, re.DOTALL)
    assert found, f"{path.relative_to(ROOT)} has no optical-side-by-side section: run {RERENDER}"
    return found.group(1)


def test_outcomes_follow_the_two_verdicts():
    builtin = _summary(("paper", "stretch", "**-0.90 [-1.20, -0.60]**"), ("paper", "fs-1", "**+0.90 [+0.30, +1.50]**"),
                       ("paper", "noise", "+0.10 [-0.50, +0.70]"), ("paper", "resize", "-0.20 [-0.90, +0.50]"),
                       ("control", "fs2", "**+1.30 [+1.00, +1.60]**"))
    generated = _summary(("optical-paper", "stretch", "-0.20 [-1.70, +1.30]"),
                         ("optical-paper", "fs-1", "**-0.60 [-1.00, -0.20]**"),
                         ("optical-paper", "noise", "**-0.80 [-1.40, -0.20]**"),
                         ("optical-paper", "resize", "+0.40 [-0.50, +1.30]"),
                         ("optical-control", "fs2", "**+1.90 [+0.40, +3.40]**"),
                         ("optical-orientation-hex", "rot50", "**+2.00 [+1.00, +3.00]**"))  # no built-in twin
    table, counts = optical.side_by_side(builtin, generated)
    outcome = {tuple(c.strip() for c in line.strip("|").split("|"))[1]: line.rsplit("|", 2)[-2].strip()
               for line in table.splitlines()[2:]}
    assert outcome == {"fs2": "holds", "stretch": "unresolved", "fs-1": "flips", "noise": "new", "resize": "holds"}
    assert counts == {"holds": 2, "flips": 1, "unresolved": 1, "new": 1}
    assert "**-0.90** (by construction)" in table  # the stretch undoes the size gap on the built-in generator
    # resolved the same way under two labels of the budget check column: holds, not a flip
    robust = "| " + " | ".join(SUMMARY_COLUMNS) + " |\n" + "|---" * len(SUMMARY_COLUMNS) + "|\n"
    same = optical.side_by_side(robust + "| paper | fs1 | 1.00 | -0.10 [-0.50, +0.30] | — | — | — | robust: Δ -1.71 at 600 steps |",
                                robust + "| optical-paper | fs1 | 1.00 | -0.10 [-0.50, +0.30] | — | — | — | resolved at 2×: Δ "
                                "-0.59 [-1.14, -0.04] at 600 steps |")[1]
    assert same["flips"] == 0 and same["holds"] == 2
    assert optical.counts_sentence(counts) == ("Of the 5 verdicts both runs have, **2 hold, 1 flips, 1 becomes "
                                               "unresolved and 1 is new**.")


def test_the_committed_side_by_side_is_recomputed_from_the_committed_runs():
    """docs/results.md and optical.md show the side-by-side that the committed built-in run and the
    committed optical run give, and name the commits those runs record."""
    builtin_text = (ROOT / "benchmarks" / "tactile" / "reproduce_quick.md").read_text()
    optical_text = optical.optical_run_text((ROOT / "benchmarks" / "tactile" / "optical.md").read_text())
    expected, counts = optical.side_by_side_section(builtin_text, optical_text, "benchmarks/tactile/reproduce_quick.md")
    assert sum(counts.values()) > 0
    for page in (ROOT / "docs" / "results.md", ROOT / "benchmarks" / "tactile" / "optical.md"):
        assert _section(page) == expected, (
            f"{page.relative_to(ROOT)}'s side-by-side is not the one the committed runs give: run {RERENDER}")
    assert f"produced by commit `{optical.produced_by(builtin_text)[:7]}`" in expected
    assert optical.produced_by(optical_text) != "unknown"


def test_render_only_rewrites_both_sections_from_the_committed_pages(tmp_path, monkeypatch):
    """--render-only needs no data and no training: it reads the two committed pages."""
    for name in ("OPTICAL_PAGE", "RESULTS_PAGE"):
        copy = tmp_path / f"{name}.md"
        copy.write_text(re.sub(r"<!-- optical-side-by-side:start -->.*?<!-- optical-side-by-side:end -->",
                               "<!-- optical-side-by-side:start -->\nstale\n<!-- optical-side-by-side:end -->",
                               getattr(optical, name).read_text(), flags=re.DOTALL))
        monkeypatch.setattr(optical, name, copy)
    result = optical.main(["--render-only"])
    assert sum(result["counts"].values()) > 0
    for name in ("OPTICAL_PAGE", "RESULTS_PAGE"):
        assert "stale" not in _section(getattr(optical, name))
