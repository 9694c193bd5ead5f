"""The benchmarks' shared helpers (benchmarks/_common.py): result sections, tables, timing."""

from __future__ import annotations

import math

import pytest
import torch

from benchmarks import _common
from benchmarks._sections import results_file as _results, section as _section


class TestCommon:
    def test_write_section_replaces_only_its_own(self, tmp_path):
        path = _results(tmp_path)
        _common.write_section("transforms", "first", path)
        _common.write_section("scaling", "other", path)
        _common.write_section("transforms", "second\n| a | b |", path)
        assert _section(path, "transforms").strip() == "second\n| a | b |"
        assert _section(path, "scaling").strip() == "other"

    def test_write_section_creates_the_file(self, tmp_path):
        path = tmp_path / "new.md"
        _common.write_section("peers", "body", path)
        assert "<!-- peers:start -->\nbody\n<!-- peers:end -->" in path.read_text()

    def test_write_section_rejects_odd_names(self, tmp_path):
        with pytest.raises(ValueError, match="name"):
            _common.write_section("a b", "x", tmp_path / "r.md")

    def test_write_section_keeps_backslashes_literal(self, tmp_path):
        path = _results(tmp_path)
        _common.write_section("x", r"a \1 \n b", path)
        _common.write_section("x", r"c \g<0>", path)
        assert _section(path, "x").strip() == r"c \g<0>"

    def test_loglog_slope(self):
        xs = [1, 2, 4, 8]
        assert _common.loglog_slope(xs, [3 * x**2 for x in xs]) == pytest.approx(2.0)
        assert math.isnan(_common.loglog_slope([2, 2], [1, 3]))

    def test_markdown_table_shape(self):
        table = _common.markdown_table(["a", "b"], [["x", 1], ["yy", 22]])
        lines = table.splitlines()
        assert len(lines) == 4 and all(line.count("|") == 3 for line in lines)

    def test_synthetic_frames_are_sparse_whole_counts(self):
        frames = _common.synthetic_frames((2, 6, 2, 20, 30), seed=3)
        assert frames.dtype == torch.float32
        assert torch.equal(frames, frames.round()) and bool((frames >= 0).all())
        assert 0.02 < float((frames > 0).float().mean()) < 0.08
        assert torch.equal(frames, _common.synthetic_frames((2, 6, 2, 20, 30), seed=3))

    def test_time_interleaved_ratios(self):
        timings, ratios = _common.time_interleaved(
            {"a": lambda: None, "b": lambda: sum(range(100))}, baseline="a", rounds=2,
            min_run_time=0.001, progress=False,
        )
        assert ratios["a"] == 1.0 and set(timings) == {"a", "b"}
        with pytest.raises(ValueError, match="baseline"):
            _common.time_interleaved({"a": lambda: None}, baseline="z")
