"""The GelSight Wedge grasps' natural splits as scenes: each a ``recordings.csv`` of roles and
splits over a converted folder, written by ``convert`` and read by ``reproduce --data``."""

from __future__ import annotations

import csv
import pickle
from pathlib import Path

import numpy as np
import pytest

from event_transforms.tactile import cli
from event_transforms.tactile.recordings import RecordingSet, read_table
from event_transforms.tactile.recordings.wedge_scenes import WEDGE_SCENES, wedge_scene_rows, write_wedge_scenes

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "gelsight-wedge"

FOAM = ("blue_foam_brick_harder", "yellow_foam_brick_softest", "red_foam_brick_softer")


def _rows(names: list[tuple[str, str, str]]) -> list[dict[str, str]]:
    return [{"events": f"events/{d}_{o}{t}.npz", "force": f"force/{d}_{o}{t}.csv", "role": "train", "object": o,
             "session": d, "trial": t} for d, o, t in names]


def _roles(rows: list[dict[str, str]]) -> dict[tuple[str, str, str], tuple[str, str]]:
    return {(r["session"], r["object"], r["trial"]): (r["role"], r["split"]) for r in rows}


def test_the_hardness_scene_trains_on_the_extremes_and_holds_out_a_trial_of_each():
    rows = _rows([(d, o, t) for d in ("2023-12-06", "2023-12-16") for o in
                  ("purple_ball_hardest", "orange_ball_softest", "green_ball_softer", "golf_ball") for t in "123"])
    scene = _roles(wedge_scene_rows(rows, "hardness-balls"))
    assert len(scene) == 18 and not any(o == "golf_ball" for _, o, _ in scene)
    assert scene[("2023-12-06", "purple_ball_hardest", "3")] == ("train", "holdout")
    assert scene[("2023-12-16", "orange_ball_softest", "1")] == ("train", "train")
    assert scene[("2023-12-06", "green_ball_softer", "1")] == ("deploy", "val")
    assert scene[("2023-12-16", "green_ball_softer", "2")] == ("deploy", "test")


def test_the_session_shape_and_control_scenes():
    rows = _rows([("2023-12-06", "foam_brick", "1"), ("2023-12-06", "golf_ball", "1"), ("2023-12-06", "golf_ball", "2"),
                  ("2023-12-16", "golf_ball", "0"), ("2023-12-16", "golf_ball", "2"), ("2023-12-16", "bolt", "0"),
                  ("2024-01-10", "bolt", "1"), ("2024-01-10", "rose_eraser", "0")])
    session = _roles(wedge_scene_rows(rows, "session"))
    assert set(session) == {("2023-12-06", "golf_ball", "1"), ("2023-12-06", "golf_ball", "2"),
                            ("2023-12-16", "golf_ball", "0"), ("2023-12-16", "golf_ball", "2")}  # no foam_brick
    assert session[("2023-12-16", "golf_ball", "0")] == ("deploy", "val")
    shape = _roles(wedge_scene_rows(rows, "shape"))
    assert shape[("2024-01-10", "rose_eraser", "0")] == ("deploy", "")  # one trial: the layout's rule
    assert shape[("2023-12-06", "golf_ball", "2")] == ("train", "holdout")
    control = _roles(wedge_scene_rows(rows, "control"))
    assert control == {("2023-12-16", "golf_ball", "0"): ("train", ""), ("2023-12-16", "golf_ball", "2"): ("deploy", ""),
                       ("2023-12-16", "bolt", "0"): ("train", "")}
    with pytest.raises(ValueError, match="scene must be one of"):
        wedge_scene_rows(rows, "hardness")
    with pytest.raises(ValueError, match=r"row 2: no \['trial'\] column"):
        wedge_scene_rows([{"events": "e.npz", "object": "x", "session": "d"}], "control")


def test_a_synthetic_folder_in_the_wedge_layout_converts_into_scenes_that_load(tmp_path, capsys):
    pytest.importorskip("av", reason="the video extra (PyAV) is not installed")
    from event_transforms.tactile.recordings.video import _write_test_video

    day = tmp_path / "data" / "2023-12-16"
    day.mkdir(parents=True)
    y, x = np.mgrid[:24, :32]
    for o in FOAM:
        for t in range(3):
            video = np.full((14, 24, 32, 3), 70, np.uint8)
            force = np.zeros(14)
            for k in range(3, 14):
                video[k][(y - 12) ** 2 + (x - 16) ** 2 < (k - 2) ** 2] = 200
                force[k] = float(k - 2)
            _write_test_video(day / f"{o}__t={t}.avi", video)
            (day / f"{o}__t={t}_forces.pkl").write_bytes(pickle.dumps(force))
            (day / f"{o}__t={t}_widths.pkl").write_bytes(pickle.dumps(np.linspace(0.05, 0.04, 14)))
    out = tmp_path / "rec"
    assert cli.main(["convert", str(tmp_path / "data"), "--out", str(out), "--whole-frame"]) == 0
    printed = capsys.readouterr().out
    assert "scene hardness-foam" in printed and "scene session: not written" in printed
    assert sorted(p.name for p in (out / "scenes").iterdir()) == ["control", "hardness-foam"]
    table = read_table(out / "scenes" / "hardness-foam")
    assert [(r.meta["object"][:3], r.role, r.split) for r in table] == [
        ("blu", "train", "train"), ("blu", "train", "train"), ("blu", "train", "holdout"),
        ("red", "deploy", "val"), ("red", "deploy", "test"), ("red", "deploy", "test"),
        ("yel", "train", "train"), ("yel", "train", "train"), ("yel", "train", "holdout")]
    assert all(r.events.resolve().parent == (out / "events").resolve() for r in table)  # nothing copied
    data = RecordingSet(out / "scenes" / "hardness-foam", split="test", frame_ms=66.6666, frames=4, pool=2,
                        crop=(0, 0, 24, 32), cache=tmp_path / "cache")
    frames, force, _ = data[0]
    assert tuple(frames.shape) == (4, 2, 12, 16) and float(force.max()) > 0
    with open(out / "scenes" / "control" / "recordings.csv", newline="") as handle:
        control = list(csv.DictReader(handle))
    assert sorted((r["trial"], r["role"]) for r in control)[-3:] == [("2", "deploy")] * 3
    assert write_wedge_scenes(out) == {n: out / "scenes" / n for n in ("hardness-foam", "control")}  # rewrites


@pytest.mark.skipif(not DATA.is_dir(), reason=f"the recorded GelSight Wedge grasps are not at {DATA}")
def test_the_recorded_grasps_give_every_scene():
    """The natural splits on the real folder's names (nothing decoded): each scene's counts."""
    from event_transforms.tactile.recordings.video import _TRIAL

    rows = []
    for video in sorted(DATA.glob("*/*.avi")):
        match = _TRIAL.match(video.stem)
        assert match, video.name
        rows.append({"events": f"events/{video.parent.name}_{video.stem}.npz", "force": "f", "role": "train",
                     "object": match["object"], "session": video.parent.name, "trial": match["t"] or match["n"]})
    assert len(rows) == 45
    counts = {}
    for name in WEDGE_SCENES:
        scene = wedge_scene_rows(rows, name)
        counts[name] = tuple(sum(r["role"] == role and r["split"] == split for r in scene)
                             for role, split in (("train", "train"), ("train", "holdout"), ("deploy", "val"),
                                                 ("deploy", "test"), ("deploy", "")))
    assert counts == {"hardness-balls": (8, 4, 2, 4, 0), "hardness-foam": (4, 2, 1, 2, 0),
                      "session": (8, 4, 4, 8, 0), "shape": (16, 8, 3, 6, 0), "control": (8, 8, 0, 0, 8)}
