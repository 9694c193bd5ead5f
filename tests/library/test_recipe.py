"""The recipe of ``docs/write_your_own.md`` is run exactly as a reader copies it.

The library, its tests, docs and configuration are copied to a scratch folder; each code block
of the page that follows a ``<!-- recipe: ... -->`` line is applied where that line says
("append to PATH", or "insert in PATH after the line containing `TEXT`"); then the suite's own
checks run on the copy: the new tests, the batteries on the new module, the public-name and
docstring checks, the structure checks and the doctests of the two edited library files.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "write_your_own.md"
STEP = re.compile(r"<!-- recipe: (?P<action>.*?) -->\n```[a-z]*\n(?P<code>.*?)```", re.S)


def recipe_steps(text: str) -> list[tuple[str, str]]:
    """``[(action, code)]`` of every marked block of the page, in order."""
    return [(m["action"].strip(), m["code"]) for m in STEP.finditer(text)]


def apply_step(root: Path, action: str, code: str) -> None:
    """Apply one step of the recipe to the copy at ``root``."""
    append = re.fullmatch(r"append to (\S+)", action)
    insert = re.fullmatch(r"insert in (\S+) after the line containing `(.+)`", action)
    if append:
        path = root / append[1]
        path.write_text(path.read_text().rstrip("\n") + "\n\n\n" + code)
    elif insert:
        path = root / insert[1]
        lines = path.read_text().splitlines(keepends=True)
        hits = [i for i, line in enumerate(lines) if insert[2] in line]
        assert len(hits) == 1, f"{action!r}: {len(hits)} lines of {insert[1]} contain {insert[2]!r}"
        lines.insert(hits[0] + 1, code)
        path.write_text("".join(lines))
    else:
        raise AssertionError(f"unknown recipe step {action!r}")


def test_the_page_marks_four_places():
    steps = recipe_steps(PAGE.read_text())
    targets = [re.search(r"(?:to|in) (\S+)", action)[1] for action, _ in steps]
    assert targets == ["event_transforms/functional/polarity.py", "event_transforms/transforms/polarity.py",
                       "tests/library/test_polarity.py", "docs/transforms.md"]


def test_a_step_that_does_not_apply_is_refused(tmp_path):
    (tmp_path / "a.md").write_text("x\ny\n")
    with pytest.raises(AssertionError, match="0 lines"):
        apply_step(tmp_path, "insert in a.md after the line containing `z`", "row\n")


@pytest.mark.slow
def test_the_recipe_copied_literally_passes_the_suite(tmp_path):
    copy = tmp_path / "repo"
    copy.mkdir()
    for name in ("event_transforms", "tests", "docs", "benchmarks"):
        shutil.copytree(ROOT / name, copy / name, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "mkdocs.yml", "README.md", "conftest.py"):
        shutil.copy(ROOT / name, copy / name)
    for action, code in recipe_steps(PAGE.read_text()):
        apply_step(copy, action, code)
    env = {**os.environ, "PYTHONPATH": str(copy), "OMP_NUM_THREADS": "1"}
    command = [
        sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", "-p", "no:randomly",
        "tests/library/test_polarity.py", "tests/library/test_public_names.py", "tests/test_structure.py",
        "tests/test_docs.py::test_every_public_name_has_args_shape_and_example",
        "event_transforms/functional/polarity.py", "event_transforms/transforms/polarity.py",
        "tests/library/test_battery.py", "tests/library/test_event_batch.py", "tests/library/test_params_spec.py", "-k",
        "DropPolarity or drop_polarity or test_polarity or public or structure or every_public or "
        "module_over or cycle or topic or apply",
    ]
    run = subprocess.run(command, cwd=copy, env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-3000:]
    assert "RandomDropPolarity" in (copy / "event_transforms/transforms/polarity.py").read_text()
    passed = [line for line in run.stdout.splitlines() if line.startswith("PASSED")]
    # the new tests, the module in the frame and event batteries, and the doctests of the new names
    for name in ("TestDropPolarity::test_frames_against_a_loop", "RandomDropPolarity", "drop_polarity_events",
                 "test_every_public_name_has_args_shape_and_example", "test_no_import_cycle"):
        assert any(name in line for line in passed), (name, run.stdout[-3000:])
    assert sum("DropPolarity" in line for line in passed) >= 20, len(passed)
