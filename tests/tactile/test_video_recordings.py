"""Videos into the recording layout (``event-transforms convert VIDEO``): the restricted label
unpickler, a synthetic video end to end (PyAV, the ``video`` extra), and one recorded grasp."""

from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

from event_transforms.tactile import cli
from event_transforms.tactile.recordings.video import (GEL_SIZE, VideoEmulation, convert_video, convert_video_folder,
                                                       read_array_pickle, rectify_gel, video_luminance)

av = pytest.importorskip("av", reason="the video extra (PyAV) is not installed")
from event_transforms.tactile.recordings.video import _write_test_video  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "gelsight-wedge"
SMALL = VideoEmulation(corners_xy=None, threshold=0.2)


class _Shell:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


class _Eval:
    def __reduce__(self):
        return (eval, ("__import__('sys').exit(3)",))


class TestLabelPickles:
    def test_a_numpy_array_is_read(self, tmp_path):
        (tmp_path / "f.pkl").write_bytes(pickle.dumps(np.array([0.5, -1.0, 3.0])))
        assert read_array_pickle(tmp_path / "f.pkl").tolist() == [0.5, -1.0, 3.0]

    def test_a_malicious_pickle_is_refused_by_name_and_nothing_runs(self, tmp_path):
        marker = tmp_path / "ran"
        (tmp_path / "bad.pkl").write_bytes(pickle.dumps(_Shell(marker)))
        with pytest.raises(ValueError, match=r"bad\.pkl: refused global (posix|os|nt)\.system"):
            read_array_pickle(tmp_path / "bad.pkl")
        assert not marker.exists()
        (tmp_path / "eval.pkl").write_bytes(pickle.dumps(_Eval()))
        with pytest.raises(ValueError, match=r"refused global builtins\.eval"):
            read_array_pickle(tmp_path / "eval.pkl")

    def test_anything_but_a_1d_numeric_array_is_refused(self, tmp_path):
        (tmp_path / "list.pkl").write_bytes(pickle.dumps([1.0, 2.0]))
        with pytest.raises(ValueError, match="expected a 1-D numeric array, got list"):
            read_array_pickle(tmp_path / "list.pkl")
        (tmp_path / "2d.pkl").write_bytes(pickle.dumps(np.zeros((2, 2))))
        with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
            read_array_pickle(tmp_path / "2d.pkl")


def _press_video(path: Path, frames: int = 12) -> np.ndarray:
    """A grey gel with a bright disc growing from frame 4: the force rises with it."""
    video = np.full((frames, 32, 48, 3), 70, np.uint8)
    y, x = np.mgrid[:32, :48]
    force = np.zeros(frames)
    for k in range(4, frames):
        video[k][(y - 16) ** 2 + (x - 24) ** 2 < (k - 3) ** 2] = 200
        force[k] = 2.0 * (k - 3)
    _write_test_video(path, video)
    return force


class TestConvert:
    def test_a_video_and_its_force_csv_become_a_recording(self, tmp_path):
        force = _press_video(tmp_path / "press.avi")
        times = np.arange(force.size) * 1e6 / 30
        with open(tmp_path / "press.csv", "w") as handle:
            handle.write("t_us,force_n\n" + "".join(f"{t},{f}\n" for t, f in zip(times, force)))
        row = convert_video(tmp_path / "press.avi", tmp_path / "rec", force=tmp_path / "press.csv", settings=SMALL)
        events = np.load(tmp_path / "rec" / "events" / "press.npz")
        assert events["sensor_size"].tolist() == [32, 48] and events["t"].size > 0
        assert int(events["t"].min()) >= 4 * 1e6 / 30 - 34_000  # nothing before the disc appears
        labels = np.loadtxt(tmp_path / "rec" / "force" / "press.csv", delimiter=",", skiprows=1)
        assert labels[:, 1] == pytest.approx(force) and labels[:, 0] == pytest.approx(times, abs=0.2)  # as given
        settings = json.loads((tmp_path / "rec" / "emulator.json").read_text())
        assert settings["settings"]["threshold"] == 0.2 and "interpolat" in settings["settings"]["model"]
        assert row["force"] == "force/press.csv"
        from event_transforms.tactile.recordings import RecordingSet

        data = RecordingSet(tmp_path / "rec", split="train", frame_ms=33.0, frames=4, pool=1, crop=(0, 0, 32, 48),
                           cache=tmp_path / "c")
        frames, labels_t, meta = data[len(data) - 1]
        assert frames.shape == (4, 2, 32, 48) and float(frames.sum()) > 0 and float(labels_t.max()) > 0

    def test_the_command_line_converts_a_video_and_refuses_a_second_time(self, tmp_path, capsys):
        force = _press_video(tmp_path / "press.avi")
        (tmp_path / "press.csv").write_text("t_s,force_n\n0,0\n1,10\n")
        out = tmp_path / "rec"
        base = ["convert", str(tmp_path / "press.avi"), "--force", str(tmp_path / "press.csv"), "--out", str(out),
                "--whole-frame", "--threshold", "0.3", "--role", "deploy"]
        assert cli.main(base) == 0
        assert ",deploy," in (out / "recordings.csv").read_text().splitlines()[1]
        printed = capsys.readouterr().out
        assert "frames ->" in printed and "clipped to 0 N" in printed
        assert json.loads((out / "emulator.json").read_text())["settings"]["threshold"] == 0.3
        assert cli.main(base) == 2
        assert "already a row" in capsys.readouterr().err
        assert cli.main([*base[:-4], "--threshold", "0.5", "--out", str(tmp_path / "r2"), "--events", "/dvs"]) == 2
        assert "--events is for ROS bags" in capsys.readouterr().err
        assert force.size == 12

    def test_a_folder_of_grasps_with_pickled_labels(self, tmp_path, capsys):
        day = tmp_path / "data" / "2024-01-01"
        day.mkdir(parents=True)
        for trial in range(2):
            force = _press_video(day / f"ball__t={trial}.avi", frames=8)
            force[2] = -5.0  # a glitch
            (day / f"ball__t={trial}_forces.pkl").write_bytes(pickle.dumps(force))
            (day / f"ball__t={trial}_widths.pkl").write_bytes(pickle.dumps(np.linspace(0.05, 0.04, 8)))
        assert cli.main(["convert", str(tmp_path / "data"), "--out", str(tmp_path / "rec"), "--whole-frame"]) == 0
        printed = capsys.readouterr().out
        assert "readings below -1 N in 2 grasps: 2024-01-01/ball__t=0 (min -5.0 N), 2024-01-01/ball__t=1" in printed
        assert "2 readings in all" in printed
        table = (tmp_path / "rec" / "recordings.csv").read_text().splitlines()
        assert table[0] == "events,force,role,object,session,trial,width,force_clipped,force_min_n"
        assert table[1].startswith("events/2024-01-01_ball__t=0.npz,force/2024-01-01_ball__t=0.csv,train,ball,2024-01-01,0,")
        labels = np.loadtxt(tmp_path / "rec" / "force" / "2024-01-01_ball__t=0.csv", delimiter=",", skiprows=1)
        assert labels[2, 1] == 0.0  # clipped, and counted
        width = np.loadtxt(tmp_path / "rec" / "width" / "2024-01-01_ball__t=0.csv", delimiter=",", skiprows=1)
        assert width.shape == (8, 2)

    def test_a_malicious_label_pickle_stops_the_folder(self, tmp_path, capsys):
        day = tmp_path / "data" / "d"
        day.mkdir(parents=True)
        _press_video(day / "x.avi", frames=4)
        marker = tmp_path / "ran"
        (day / "x_forces.pkl").write_bytes(pickle.dumps(_Shell(marker)))
        assert cli.main(["convert", str(tmp_path / "data"), "--out", str(tmp_path / "rec"), "--whole-frame"]) == 2
        assert "refused global" in capsys.readouterr().err and not marker.exists()

    def test_rectify_maps_the_quadrilateral_corners_to_the_rectangle_corners(self):
        import torch

        frames = torch.zeros(1, 1, 20, 30)
        corners = ((3.0, 2.0), (25.0, 4.0), (27.0, 17.0), (5.0, 15.0))
        for x, y in corners:
            frames[0, 0, int(y), int(x)] = 1.0
        out = rectify_gel(frames, corners, (10, 12))[0, 0]
        assert [float(out[r, c]) for r, c in ((0, 0), (0, 11), (9, 11), (9, 0))] == pytest.approx([1.0] * 4, abs=1e-4)


@pytest.mark.skipif(not DATA.is_dir(), reason=f"the recorded GelSight Wedge grasps are not at {DATA}")
def test_one_recorded_grasp_converts(tmp_path, capsys):
    """The shortest 2024-01-10 grasp with a force glitch: decoded, rectified, emulated; the files
    go to a temporary folder only (the data are not ours)."""
    source = DATA / "2024-01-10"
    folder = tmp_path / "data" / "2024-01-10"
    folder.mkdir(parents=True)
    for suffix in (".avi", "_forces.pkl", "_widths.pkl"):
        shutil.copy(source / f"bolt__t=1{suffix}", folder / f"bolt__t=1{suffix}")
    rows = convert_video_folder(tmp_path / "data", tmp_path / "rec", log=print)
    printed = capsys.readouterr().out
    forces = read_array_pickle(source / "bolt__t=1_forces.pkl")
    luminance, times = video_luminance(source / "bolt__t=1.avi", VideoEmulation())
    assert luminance.shape[1:] == GEL_SIZE and times.size == forces.size
    assert rows[0]["object"] == "bolt" and rows[0]["session"] == "2024-01-10" and rows[0]["trial"] == "1"
    negative = int((forces < 0).sum())
    assert negative > 0 and int(rows[0]["force_clipped"]) == negative
    assert f"{negative} readings in all" in printed
    events = np.load(tmp_path / "rec" / "events" / "2024-01-10_bolt__t=1.npz")
    count, last, span = int(events["t"].size), int(events["t"].max()), float(times[-1] - times[0])
    assert count > 1000 and last <= span


def test_the_command_line_defaults_are_the_converters():
    """The help states the converter's chosen defaults without importing it (no torch for --help)."""
    import argparse

    from event_transforms.tactile.cli_data import add_convert_command

    parser = argparse.ArgumentParser()
    add_convert_command(parser.add_subparsers(dest="command"))
    help_text = " ".join(parser._subparsers._group_actions[0].choices["convert"].format_help().split())
    default = VideoEmulation()
    assert default.channel == 1 and "default green" in help_text
    assert f"default {default.threshold:g}," in help_text and f"(default {default.mismatch:g})" in help_text
    assert default.refractory_us == 0 and "(default 0)" in help_text


def test_a_video_joins_a_table_with_other_columns(tmp_path):
    """Converting into a folder whose recordings.csv has its own columns keeps them (and its rows)."""
    out = tmp_path / "rec"
    out.mkdir()
    (out / "recordings.csv").write_text("events,force,role,diameter_mm\nevents/a.npy,force/a.csv,deploy,12\n")
    _press_video(tmp_path / "press.avi", frames=4)
    convert_video(tmp_path / "press.avi", out, force=None, settings=SMALL)
    lines = (out / "recordings.csv").read_text().splitlines()
    assert lines[0].startswith("events,force,role,diameter_mm,object")
    assert lines[1].startswith("events/a.npy,force/a.csv,deploy,12,") and lines[2].startswith("events/press.npz,,train,,")
