"""benchmarks/library/speed_goals.py: its tonic stand-in bins as tonic's ToFrame does, its verdicts follow
the goals, and a quick run writes its section."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from benchmarks.library import speed_goals
from benchmarks.library.binning import stream


def test_numpy_stand_in_bins_like_events_to_frames_from_the_first_event(monkeypatch):
    """Without tonic, the peer is tonic's ToFrame algorithm in numpy: windows of 10 ms from the
    first event, per (p, y, x) counts; the library's binning with t_start="first" is the reference."""
    import builtins

    real_import = builtins.__import__

    def no_tonic(name, *args, **kwargs):
        if name.startswith("tonic"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_tonic)
    to_frame, label = speed_goals._tonic_to_frame()
    assert "numpy" in label
    events = stream(5_000, (12, 16), seed=3)
    frames = to_frame(events, (12, 16))
    import event_transforms as et

    expected = et.functional.events_to_frames(events, sensor_size=(12, 16), frame_ms=10.0, t_start="first")
    assert frames.shape == tuple(expected.shape)
    assert np.array_equal(frames.astype(np.int64), expected.to(torch.int64).numpy())


def _times(**rows):
    return {"eager": {speed_goals.CLONE: [1.0, 1.0], **rows}, "compiled": {}}


def test_verdicts_follow_each_kind_of_goal():
    clone_goal = speed_goals.Goal("row", "clone", 3.5, ops=30)
    assert speed_goals.judge(clone_goal, _times(row=[3.0, 3.4]), {"row": 20}, "eager") == ("3.20× clone", True)
    assert speed_goals.judge(clone_goal, _times(row=[3.0, 3.4]), {"row": 31}, "eager")[1] is False  # too many ops
    peer_goal = speed_goals.Goal("row", "peer", 3.0, "peer")
    assert speed_goals.judge(peer_goal, _times(row=[1.0, 1.0], peer=[2.9, 2.9]), {}, "eager") == ("2.9× faster", False)
    ratio_goal = speed_goals.Goal("row", "ratio", 1.1, "peer")
    assert speed_goals.judge(ratio_goal, _times(row=[1.05, 1.0], peer=[1.0, 1.0]), {}, "eager")[1] is True
    assert speed_goals.judge(speed_goals.Goal("row", "clone", None), _times(row=[9.0, 9.0]), {}, "eager")[1] is None


def test_every_goal_row_is_a_timed_case():
    names = set(speed_goals.build_cases(speed_goals.make_data(quick=True))[0])
    for goal in speed_goals.GOALS:
        assert goal.row in names and (goal.peer is None or goal.peer in names), goal


@pytest.mark.slow
def test_quick_run_writes_its_section(tmp_path):
    path = tmp_path / "RESULTS.md"
    speed_goals.main(["--quick", "--results", str(path), "--threads", "1"])
    text = path.read_text()
    assert "<!-- speed-goals:start -->" in text and "EventsToFrames(EventBatch)" in text
