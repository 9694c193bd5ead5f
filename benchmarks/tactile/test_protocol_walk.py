"""Smoke test of the protocol-walk benchmark: its main() on one seed of a tiny run."""

from __future__ import annotations

from benchmarks._sections import results_file as _results, section as _section
from benchmarks.tactile import protocol_walk


def test_quick_run(tmp_path):
    path = _results(tmp_path)
    figures = protocol_walk.main(["--quick", "--root", str(tmp_path / "cache"), "--results", str(path)])
    assert figures["walk"][0] == protocol_walk.RUN  # the walk starts at run_protocol
    assert figures["rooms"] == len(figures["per_room"]) and sum(figures["per_room"].values()) == figures["entries"]
    assert figures["returns"] == figures["entries"] - figures["rooms"]
    assert 0.0 < figures["outside_share"] < 1.0
    stages = figures["stages"]
    assert stages["walk"][0] == protocol_walk.RUN and stages["entries"] <= figures["entries"]
    assert "run.py entries" in _section(path, "protocol-walk")
