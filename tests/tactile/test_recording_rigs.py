"""Recordings as the field records them: HDF5 arrays, any clock and label column,
the sensor size from the file, integer milliseconds, trigger sync, training-only folders, and
each case a newcomer hit, through RecordingSet, the readers and the command line."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from event_transforms.events.io import EventFile, read_events
from event_transforms.functional import events_to_frames
from event_transforms.tactile import cli
from event_transforms.tactile.recordings import RecordingSet, read_force

from tests.support.rig_files import write_aedat4
from tests.tactile.test_recordings import SENSOR, SMALL, grasp_events, make_folder, write_force

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(autouse=True)
def own_cache(tmp_path, monkeypatch):
    """Commands without --root bin into the package cache: each test gets its own, so that no
    other test finds these recordings binned (the files of make_folder repeat across tests)."""
    monkeypatch.setenv("EVENT_TRANSFORMS_CACHE", str(tmp_path / "package-cache"))


def rows_of(events: np.ndarray, order: str = "xytp") -> np.ndarray:
    return np.stack([events[c].astype(np.int64) for c in order], axis=1)


def frames_of(data: RecordingSet) -> list[torch.Tensor]:
    return [data[i][0] for i in range(len(data))]


def swap_events(root, k: int, suffix: str, write) -> None:
    """Replace recording k's event file by another format written by ``write(path, events)``."""
    events = np.load(root / f"r{k}.npy")
    write(root / f"r{k}{suffix}", events)
    table = (root / "recordings.csv").read_text().replace(f"r{k}.npy,", f"r{k}{suffix},")
    (root / "recordings.csv").write_text(table)


class TestHdf5Arrays:
    def test_plain_rows_with_and_without_columns(self, tmp_path):
        h5py = pytest.importorskip("h5py")
        events = grasp_events(0)[0]
        with h5py.File(tmp_path / "a.h5", "w") as f:
            f["events"] = rows_of(events)
        with h5py.File(tmp_path / "b.h5", "w") as f:  # NVBTS writes x, y, t_ns, p: here t, x, y, p
            f["events"] = rows_of(events, "txyp")
        for name, columns in (("a.h5", None), ("b.h5", "txyp")):
            got = read_events(tmp_path / name, columns=columns)
            for c in "xytp":
                assert np.array_equal(got[c], events[c].astype(np.int64)), (name, c)
        with pytest.raises(ValueError, match="columns='txyp'"):
            read_events(tmp_path / "b.h5")

    def test_recording_set_reads_an_hdf5_array_like_the_npy(self, tmp_path):
        h5py = pytest.importorskip("h5py")
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        before = RecordingSet(root, split="train", cache=tmp_path / "c", crop=(0, 0, 30, 40), **SMALL)

        def write(path, events):
            with h5py.File(path, "w") as f:
                f["events"] = rows_of(events, "txyp")

        swap_events(root, 0, ".h5", write)
        after = RecordingSet(root, split="train", cache=tmp_path / "c", crop=(0, 0, 30, 40), columns="txyp", **SMALL)
        for a, b in zip(frames_of(before), frames_of(after)):
            assert torch.equal(a, b)

    def test_a_filter_hdf5_lacks_is_named(self, tmp_path, monkeypatch):
        h5py = pytest.importorskip("h5py")
        events = grasp_events(0)[0]
        with h5py.File(tmp_path / "p.h5", "w") as f:
            f.create_group("CD")["events"] = events
        with h5py.File(tmp_path / "c.h5", "w") as f:
            f["events"] = rows_of(events)

        def unreadable(self, index):  # as h5py reports a missing filter plugin
            raise OSError("Can't read data (can't open directory: /usr/local/hdf5/lib/plugin)")

        monkeypatch.setattr(h5py.Dataset, "__getitem__", unreadable)
        for name, where in (("p.h5", "/CD/events"), ("c.h5", "/events")):
            with pytest.raises(ValueError, match=f"{name}: dataset {where} cannot be read .*Prophesee's files use "
                                                 "their ECF codec"):
                read_events(tmp_path / name)

    def test_sensor_size_from_attributes(self, tmp_path):
        h5py = pytest.importorskip("h5py")
        events = grasp_events(0)[0]
        with h5py.File(tmp_path / "p.h5", "w") as f:
            f.create_group("CD")["events"] = events
            f.attrs["geometry"] = f"{SENSOR[1]}x{SENSOR[0]}"  # Prophesee: WIDTHxHEIGHT
        with h5py.File(tmp_path / "w.h5", "w") as f:
            f["events"] = rows_of(events)
            f["events"].attrs["width"], f["events"].attrs["height"] = SENSOR[1], SENSOR[0]
        assert EventFile(tmp_path / "p.h5").sensor_size == SENSOR == EventFile(tmp_path / "w.h5").sensor_size


def test_a_logged_set_pickles_for_workers(tmp_path):
    import pickle

    root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
    data = RecordingSet(root, split="train", cache=tmp_path / "c", log=print, **SMALL)
    again = pickle.loads(pickle.dumps(data))
    assert torch.equal(again[1][0], data[1][0])


class TestWrongFiles:
    def test_txyp_rows_get_the_columns_advice(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        swap_events(root, 0, ".npy", lambda path, events: np.save(path, rows_of(events, "txyp")))
        with pytest.raises(ValueError, match=r"row 2 \(r0.npy\).*look like t, x, y, p order; pass columns='txyp'"):
            RecordingSet(root, split="train", cache=tmp_path / "c", **SMALL)
        assert cli.main(["infer-scene", "--data", str(root), "--sensor-size", "30", "40", "--frames", "12"]) == 2
        assert "pass --columns txyp" in capsys.readouterr().err
        assert len(RecordingSet(root, split="train", cache=tmp_path / "c", columns="txyp", **SMALL))

    def test_corrupt_and_mislabelled_files_say_what_they_are_not(self, tmp_path):
        (tmp_path / "bad.npy").write_bytes(b"x,y,t,p\n1,2,3,1\n")
        with pytest.raises(ValueError, match=r"bad.npy: not a NumPy file .*text: a CSV\? name it .csv"):
            read_events(tmp_path / "bad.npy")
        np.save(tmp_path / "cut.npy", np.zeros((100, 4), dtype=np.int64))
        (tmp_path / "cut.npy").write_bytes((tmp_path / "cut.npy").read_bytes()[:60])
        with pytest.raises(ValueError, match="cut.npy: a damaged NumPy file"):
            read_events(tmp_path / "cut.npy")
        write_force(tmp_path / "force.csv", np.arange(3), np.ones(3))
        with pytest.raises(ValueError, match="this looks like a force file, not an event file"):
            read_events(tmp_path / "force.csv")
        (tmp_path / "x.h5").write_bytes(b"nothing")
        pytest.importorskip("h5py")
        with pytest.raises(ValueError, match="x.h5: not an HDF5 file"):
            read_events(tmp_path / "x.h5")

    def test_predict_names_a_model_that_is_not_one(self, tmp_path, capsys):
        write_force(tmp_path / "force.csv", np.arange(3), np.ones(3))
        np.save(tmp_path / "e.npy", rows_of(grasp_events(0)[0]))
        assert cli.main(["predict", str(tmp_path / "force.csv"), str(tmp_path / "e.npy")]) == 2
        err = capsys.readouterr().err
        assert "MODEL" in err and "force.csv" in err and "is not a checkpoint" in err and "IndexError" not in err


class TestForceFiles:
    T_US = np.arange(1_000_000, 1_240_001, 1_000)

    def write(self, path, header, columns):
        np.savetxt(path, np.stack(columns, 1), delimiter=",", header=header, comments="", fmt="%.17g")

    def test_time_units_by_name_and_option(self, tmp_path):
        force = np.linspace(1, 5, self.T_US.size)
        self.write(tmp_path / "us.csv", "t_us,force_n", [self.T_US, force])
        reference = read_force(tmp_path / "us.csv")
        for name, scale, unit in (("t_ns", 1e3, None), ("t_ms", 1e-3, None), ("t_s", 1e-6, None),
                                  ("time", 1e-6, "s"), ("timestamp", 1e3, "ns")):
            self.write(tmp_path / "f.csv", f"{name},force_n", [self.T_US * scale, force])
            lines: list[str] = []
            t, f = read_force(tmp_path / "f.csv", time_unit=unit, log=lines.append)
            np.testing.assert_allclose(t, reference[0], rtol=0, atol=1e-3)
            assert np.array_equal(f, reference[1])
            assert lines == [f"f.csv: time column {name} ({ {1e3: 'nanoseconds', 1e-3: 'milliseconds', 1e-6: 'seconds'}[scale]}) "
                             "read as microseconds"]
        with pytest.raises(ValueError, match="force_time_unit='ms' but the column t_ns names its unit"):
            self.write(tmp_path / "f.csv", "t_ns,force_n", [self.T_US * 1e3, force])
            read_force(tmp_path / "f.csv", time_unit="ms")

    def test_unix_seconds_keep_microseconds(self, tmp_path):
        t_s = 1.7e9 + self.T_US / 1e6  # float Unix seconds, as NeuTouch logs them
        self.write(tmp_path / "f.csv", "t_s,force_n", [t_s, np.ones(self.T_US.size)])
        t, _ = read_force(tmp_path / "f.csv")
        np.testing.assert_allclose(t - 1.7e15, self.T_US, rtol=0, atol=0.5)

    def test_wrench_reduced_as_asked(self, tmp_path):
        rng = np.random.default_rng(0)
        fx, fy, fz = rng.normal(size=(3, self.T_US.size))
        self.write(tmp_path / "w.csv", "t_us,fx,fy,fz,tx", [self.T_US, fx, fy, fz, fz])
        _, magnitude = read_force(tmp_path / "w.csv", column="magnitude")
        np.testing.assert_allclose(magnitude, [np.linalg.norm(v) for v in zip(fx, fy, fz)], rtol=1e-12)
        assert np.array_equal(read_force(tmp_path / "w.csv", column="fz")[1], fz)
        with pytest.raises(ValueError, match="holds a wrench \\(fx, fy, fz\\): pass force_column='magnitude'"):
            read_force(tmp_path / "w.csv")
        with pytest.raises(ValueError, match="force_column='mz' is not a column"):
            read_force(tmp_path / "w.csv", column="mz")
        fz[7] = np.nan
        self.write(tmp_path / "w.csv", "t_us,fx,fy,fz", [self.T_US, fx, fy, fz])
        with pytest.raises(ValueError, match=r"w.csv line 9: fz is nan"):
            read_force(tmp_path / "w.csv", column="magnitude")

    def test_recording_set_says_each_conversion_once(self, tmp_path):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        before = RecordingSet(root, split="train", cache=tmp_path / "c", crop=(0, 0, 30, 40), **SMALL)
        for k in range(5):
            t, f = np.loadtxt(root / f"f{k}.csv", delimiter=",", skiprows=1, unpack=True)
            self.write(root / f"f{k}.csv", "t_ns,fx,fy,fz", [t * 1000, 0 * f, 0.6 * f, -0.8 * f])
        lines: list[str] = []
        after = RecordingSet(root, split="train", cache=tmp_path / "c", crop=(0, 0, 30, 40), force_column="magnitude",
                             log=lines.append, **SMALL)
        said = [line for line in lines if "read as microseconds" in line]
        assert len(said) == 2  # one per file name: f0.csv, f1.csv (the training split)
        for i in range(len(before)):
            torch.testing.assert_close(after[i][1], before[i][1])


class TestMilliseconds:
    def events_ms(self):
        rng = np.random.default_rng(0)
        n = 37_024  # a 0.37 s recording stamped in integer milliseconds
        events = np.zeros(n, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
        events["t"] = np.sort(rng.integers(0, 370, n))
        events["x"], events["y"], events["p"] = rng.integers(0, 40, n), rng.integers(0, 30, n), rng.integers(0, 2, n)
        return events

    def test_events_to_frames_refuses_and_reads_them(self):
        events = self.events_ms()
        with pytest.raises(ValueError, match="look like milliseconds.*time_unit='ms'"):
            events_to_frames(events, sensor_size=SENSOR)
        frames = events_to_frames(events, sensor_size=SENSOR, time_unit="ms")
        assert frames.shape[0] == 37 and int(frames.sum()) == len(events)
        as_us = events.copy()
        as_us["t"] = events["t"] * 1000
        assert torch.equal(frames, events_to_frames(as_us, sensor_size=SENSOR))
        events_to_frames(events, sensor_size=SENSOR, time_unit="us")  # said to be microseconds: one frame, asked
        from event_transforms.functional import iter_frames

        # a stream's chunk is not a recording: a dense chunk of a fast camera is never refused
        assert len(list(iter_frames([events], sensor_size=SENSOR))) == 1

    def test_recording_set_and_predict_refuse_them_by_name(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        np.save(root / "r0.npy", self.events_ms())
        with pytest.raises(ValueError, match=r"row 2 \(r0.npy\): 37,024 integer timestamps .* milliseconds.*"
                                             r"time_unit='ms'"):
            RecordingSet(root, split="train", cache=tmp_path / "c", **SMALL)
        assert cli.main(["infer-scene", "--data", str(root), "--sensor-size", "30", "40", "--frames", "12"]) == 2
        assert "--time-unit ms" in capsys.readouterr().err


class TestSensorSize:
    def folder(self, tmp_path, sensor=SENSOR):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        pytest.importorskip("aedat")
        for k in range(5):
            swap_events(root, k, ".aedat4", lambda path, events: write_aedat4(path, events, sensor))
        return root

    def test_read_from_the_file_and_a_mismatch_named(self, tmp_path, capsys):
        root = self.folder(tmp_path)
        options = {"frames": 12, "pool": 2, "crop": (0, 0, 30, 40)}
        data = RecordingSet(root, split="train", cache=tmp_path / "c", **options)
        assert data.sensor_size == SENSOR and len(data)
        with pytest.raises(ValueError, match=r"states a sensor of \(H, W\) = \(30, 40\), but sensor_size=\(60, 80\)"):
            RecordingSet(root, split="train", cache=tmp_path / "c", sensor_size=(60, 80), **options)
        assert cli.main(["infer-scene", "--data", str(root), "--sensor-size", "60", "80", "--frames", "12"]) == 2
        err = capsys.readouterr().err
        assert "--sensor-size 60 80" in err and "sensor_size" not in err
        assert cli.main(["infer-scene", "--data", str(root), "--frames", "12"]) == 0

    def test_events_outside_advise_the_interface_option(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        with pytest.raises(ValueError, match=r"pass sensor_size=\(H, W\) of the camera \(at least \(30, 40\)"):
            RecordingSet(root, split="train", cache=tmp_path / "c", sensor_size=(20, 20), frames=12)
        assert cli.main(["infer-scene", "--data", str(root), "--sensor-size", "20", "20", "--frames", "12"]) == 2
        assert "pass --sensor-size H W of the camera" in capsys.readouterr().err


class TestTrainingOnly:
    def test_loads_for_training_and_trains(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=4, deploy=0, unlabeled=0)
        data = RecordingSet(root, split="train", cache=tmp_path / "c", **SMALL)
        assert len(data) == 6  # 3 of 4 recordings train (the last third holds out), 2 windows each
        with pytest.raises(ValueError, match="no deployment recording.*loads with split='train'"):
            RecordingSet(root, split="val", cache=tmp_path / "c", **SMALL)
        model = tmp_path / "m.pt"
        assert cli.main(["train", "--data", str(root), "--out", str(model), "--steps", "2", "--input-pool", "3",
                         "--hidden-channels", "2", "--sensor-size", "30", "40", "--frames", "12"]) == 0
        out = capsys.readouterr().out
        assert "not scored: the folder holds no labelled deployment recordings" in out and model.is_file()
        assert cli.main(["reproduce", "--data", str(root), "--sensor-size", "30", "40", "--frames", "12",
                         "--out", str(tmp_path / "o")]) == 2
        assert "no deployment recording" in capsys.readouterr().err

    def test_too_few_windows_name_frames(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=1, deploy=2, unlabeled=0)
        assert cli.main(["infer-scene", "--data", str(root), "--sensor-size", "30", "40", "--frames", "24"]) == 2
        assert "the scene inference needs at least 2" in capsys.readouterr().err


class TestPredict:
    @pytest.fixture(scope="class")
    @classmethod
    def model_path(cls, tmp_path_factory):
        tmp = tmp_path_factory.mktemp("model")
        root = make_folder(tmp / "d", train=3, deploy=2, unlabeled=0)
        path = tmp / "m.pt"
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("EVENT_TRANSFORMS_CACHE", str(tmp / "package-cache"))
            assert cli.main(["train", "--data", str(root), "--out", str(path), "--steps", "2", "--input-pool", "3",
                             "--hidden-channels", "2", "--sensor-size", "30", "40", "--frames", "12",
                             "--crop", "0", "0", "30", "40"]) == 0
        return path

    def test_another_grid_in_one_line_or_refused(self, model_path, tmp_path, capsys):
        events = grasp_events(7)[0]
        np.save(tmp_path / "e.npy", events)
        capsys.readouterr()
        assert cli.main(["predict", str(model_path), str(tmp_path / "e.npy"), "--out", str(tmp_path / "a.csv")]) == 0
        wide = events.copy()
        wide["x"] += 20
        np.save(tmp_path / "wide.npy", wide)
        assert cli.main(["predict", str(model_path), str(tmp_path / "wide.npy"), "--out", str(tmp_path / "b.csv"),
                         "--sensor-size", "30", "80"]) == 0
        out = capsys.readouterr().out
        assert out.count("trained on a (30, 40) (H, W) sensor, this file's is (30, 80)") == 1
        assert cli.main(["predict", str(model_path), str(tmp_path / "wide.npy"), "--sensor-size", "20", "80"]) == 2
        assert "does not fit this file's (20, 80) sensor" in capsys.readouterr().err

    def test_time_unit_option(self, model_path, tmp_path):
        events = grasp_events(7)[0]
        np.save(tmp_path / "us.npy", events)
        seconds = np.zeros(len(events), dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<f8"), ("p", "<i1")])
        for c in "xyp":
            seconds[c] = events[c]
        seconds["t"] = events["t"] / 1e6
        np.save(tmp_path / "s.npy", seconds)
        assert cli.main(["predict", str(model_path), str(tmp_path / "us.npy"), "--out", str(tmp_path / "a.csv")]) == 0
        assert cli.main(["predict", str(model_path), str(tmp_path / "s.npy"), "--out", str(tmp_path / "b.csv"),
                         "--time-unit", "s"]) == 0
        assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()


class TestTriggerSync:
    LAG_US = 12_345  # the force logger's clock runs this far behind the camera's

    def folder(self, tmp_path, drop_one=False):
        pytest.importorskip("aedat")
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        rng = np.random.default_rng(5)
        for k in range(5):
            events = np.load(root / f"r{k}.npy")
            t, f = np.loadtxt(root / f"f{k}.csv", delimiter=",", skiprows=1, unpack=True)
            # the logger samples every 1 ms on its own clock and marks the sample a pulse fell on; the
            # camera stamps the pulse on its clock, LAG_US later
            t_logger = t - self.LAG_US
            marked = np.sort(rng.choice(np.arange(10, t.size - 10, 20), 12, replace=False))
            pulses = (t_logger[marked] + self.LAG_US).astype(np.int64)
            flags = np.zeros(t.size, dtype=int)
            flags[marked] = 1
            if drop_one and k == 1:
                flags[np.flatnonzero(flags)[0]] = 0
            np.savetxt(root / f"f{k}.csv", np.c_[t_logger, f, flags], delimiter=",", header="t_us,force_n,trigger",
                       comments="", fmt=["%d", "%.6f", "%d"])
            write_aedat4(root / f"r{k}.aedat4", events, SENSOR, triggers=pulses, sources=1)
            (root / "recordings.csv").write_text((root / "recordings.csv").read_text().replace(f"r{k}.npy,",
                                                                                                 f"r{k}.aedat4,"))
        return root

    def test_known_offset_recovered(self, tmp_path):
        root = self.folder(tmp_path)
        options = {"frames": 12, "pool": 2, "crop": (0, 0, 30, 40)}
        lines: list[str] = []
        synced = RecordingSet(root, split="train", cache=tmp_path / "c", sync="triggers", log=lines.append, **options)
        offset = RecordingSet(root, split="train", cache=tmp_path / "c", force_offset_ms=self.LAG_US / 1000,
                              **options)
        said = [line for line in lines if "force clock aligned" in line]
        assert len(said) == 2 and all("+12.345 ms from 12 triggers (spread 0.0 µs)" in line for line in said), said
        for i in range(len(synced)):
            torch.testing.assert_close(synced[i][1], offset[i][1])

    def test_count_mismatch_refused(self, tmp_path, capsys):
        root = self.folder(tmp_path, drop_one=True)
        with pytest.raises(ValueError, match=r"row 3 \(r1.aedat4\).*f1.csv.*12 camera trigger\(s\) but 11"):
            RecordingSet(root, split="train", cache=tmp_path / "c", sync="triggers", frames=12)
        with pytest.raises(ValueError, match="leave force_offset_ms at 0"):
            RecordingSet(root, split="train", sync="triggers", force_offset_ms=1.0)


def test_recording_entry_and_no_alias():
    from event_transforms.tactile import recordings

    assert not hasattr(recordings, "Recording")  # the former name of RecordingEntry, removed
    alias = recordings.RecordingEntry
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from event_transforms.tactile.recordings import RecordingEntry  # noqa: F401
    from event_transforms.tactile.simulation import Recording

    assert Recording is not alias  # one Recording: the simulator's


class TestBags:
    @pytest.fixture(scope="class", params=[False, True], ids=["ros1", "ros2"])
    @classmethod
    def converted(cls, request, tmp_path_factory):
        from tests.support.rig_files import write_bag

        tmp = tmp_path_factory.mktemp("bags")
        for k, role in enumerate(["train"] * 3 + ["deploy"] * 2):
            events, t, force = grasp_events(k)
            bag = tmp / (f"g{k}" if request.param else f"g{k}.bag")
            write_bag(bag, events, SENSOR, t, np.c_[0.6 * force, 0 * force, -0.8 * force], ros2=request.param)
            assert cli.main(["convert", str(bag), "--events", "/dvs/events", "--force", "/ft", "--role", role,
                             "--out", str(tmp / "rec")]) == 0
        return tmp

    def test_bags_read_like_the_npy_layout(self, converted, tmp_path, capsys):
        reference = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        options = {"frames": 12, "pool": 2, "crop": (0, 0, 30, 40)}
        want = RecordingSet(reference, split="train", cache=tmp_path / "c", sensor_size=SENSOR, **options)
        got = RecordingSet(converted / "rec", split="train", cache=tmp_path / "c", **options)  # size from the files
        assert got.sensor_size == SENSOR and len(got) == len(want)
        for i in range(len(got)):
            assert torch.equal(got[i][0], want[i][0])
            torch.testing.assert_close(got[i][1], want[i][1], atol=1e-5, rtol=1e-6)
        assert (converted / "rec" / "recordings.csv").read_text().splitlines()[:2] == [
            "events,force,role", "events/g0.npz,force/g0.csv,train"]

    @pytest.mark.parametrize("ros2", [False, True], ids=["ros1", "ros2"])
    def test_prophesee_event_arrays(self, tmp_path, ros2):
        from event_transforms.events.bags import read_bag_events

        from tests.support.rig_files import write_bag

        events, t, force = grasp_events(3)
        write_bag(tmp_path / ("p" if ros2 else "p.bag"), events, SENSOR, t, np.c_[force, force, force], ros2=ros2,
                  events_type="prophesee_event_msgs/msg/EventArray", per_message=333)
        columns, sensor = read_bag_events(tmp_path / ("p" if ros2 else "p.bag"), "/dvs/events")
        assert sensor == SENSOR
        for c in "xyp":
            assert np.array_equal(columns[c], events[c].astype(np.int64)), c
        assert np.array_equal(columns["t"], events["t"].astype(np.int64) * 1000)

    def test_receive_times_on_request(self, tmp_path, capsys):
        from tests.support.rig_files import write_bag

        events, t, force = grasp_events(0)
        write_bag(tmp_path / "a.bag", events, SENSOR, t, np.c_[0 * force, 0 * force, force])
        for stamps in ("header", "receive"):
            assert cli.main(["convert", str(tmp_path / "a.bag"), "--events", "/dvs/events", "--force", "/ft",
                             "--force-field", "fz", "--stamps", stamps, "--out", str(tmp_path / stamps)]) == 0
            assert f"fz of geometry_msgs/msg/WrenchStamped, {stamps} " in capsys.readouterr().out
        header = np.loadtxt(tmp_path / "header" / "force" / "a.csv", delimiter=",", skiprows=1)
        receive = np.loadtxt(tmp_path / "receive" / "force" / "a.csv", delimiter=",", skiprows=1)
        assert np.array_equal(header[:, 0], t) and np.array_equal(receive[:, 0], t + 3_000)
        np.testing.assert_allclose(header[:, 1], force, rtol=1e-12)

    def test_bad_bags_name_file_topic_and_fix(self, tmp_path, capsys):
        from tests.support.rig_files import write_bag

        events, t, force = grasp_events(0)
        wrench = np.c_[0 * force, 0 * force, force]
        wrench[5, 2] = np.nan
        write_bag(tmp_path / "a.bag", events, SENSOR, t, wrench, float_topic=True)
        base = ["convert", str(tmp_path / "a.bag"), "--out", str(tmp_path / "o")]
        cases = [
            (["--events", "/events", "--force", "/ft"], ["a.bag", "no topic '/events'", "/dvs/events (dvs_msgs",
                                                        "name one of them"]),
            (["--events", "/dvs/events", "--force", "/ft"], ["a.bag", "topic '/ft', message 5",
                                                            "magnitude is nan", "drop or filter"]),
            (["--events", "/dvs/events", "--force", "/grip", "--force-field", "data"],
             ["topic '/grip', message 0", "has no header", "--stamps receive"]),
            (["--events", "/ft", "--force", "/grip"], ["carries geometry_msgs/msg/WrenchStamped, not an event array"]),
        ]
        for extra, words in cases:
            assert cli.main([*base, *extra]) == 2
            err = capsys.readouterr().err
            assert all(w in err for w in words), (err, words)
        assert cli.main([*base, "--events", "/dvs/events", "--force", "/grip", "--force-field", "data", "--stamps",
                         "receive"]) == 2  # receive times need no header; the value at message 5 is NaN
        assert "topic '/grip', message 5: data is nan" in capsys.readouterr().err
        assert not (tmp_path / "o").exists()  # nothing half-written

    def test_trigger_topics_align_the_force_clock(self, tmp_path, capsys):
        from tests.support.rig_files import write_bag

        events, t, force = grasp_events(0)
        pulses = t[10:-10:25] + 137  # between samples
        write_bag(tmp_path / "a.bag", events, SENSOR, t, np.c_[0 * force, 0 * force, force], force_lag_us=7_250,
                  triggers_us=pulses)
        base = ["convert", str(tmp_path / "a.bag"), "--events", "/dvs/events", "--force", "/ft", "--out"]
        assert cli.main([*base, str(tmp_path / "o"), "--triggers", "/dvs/trigger", "/ft/trigger"]) == 0
        assert "force clock aligned to the camera's by +7.250 ms from 9 triggers (spread 0.0 µs)" in \
            capsys.readouterr().out
        synced = np.loadtxt(tmp_path / "o" / "force" / "a.csv", delimiter=",", skiprows=1)
        assert np.array_equal(synced[:, 0], t)
        assert cli.main([*base, str(tmp_path / "p"), "--triggers", "/dvs/trigger", "/ft"]) == 2
        assert "9 camera trigger(s) but 241 on the force clock" in capsys.readouterr().err

    def test_missing_package_names_the_extra(self, tmp_path, monkeypatch):
        import sys

        from event_transforms.events.bags import read_bag_events

        monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
        with pytest.raises(ValueError, match=r"pip install 'event-transforms\[bag\]'"):
            read_bag_events(tmp_path / "a.bag", "/dvs/events")


class TestFromRigToVerdict:
    """Each path of docs/rig.md, its commands read from the page and run on files the test writes,
    with a reduced training configuration appended to ``reproduce``."""

    PAGE = "docs/rig.md"

    def commands(self, section: str) -> list[str]:
        from pathlib import Path

        page = (Path(__file__).resolve().parents[2] / self.PAGE).read_text()
        text = page.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
        block = text.split("```bash\n", 1)[1].split("```", 1)[0]
        lines = [line for line in block.splitlines() if line.strip()]
        assert 1 <= len(lines) <= 3, lines
        return lines

    def run(self, section, tmp_path, monkeypatch, capsys):
        import glob
        import shlex
        import subprocess

        monkeypatch.chdir(tmp_path)
        reduced = ["--methods", "none", "--seeds", "0", "--steps", "2", "--hidden-channels", "2", "--input-pool", "3",
                   "--batch-size", "4", "--jobs", "1", "--no-plots", "--no-budget-check", "--no-equal-time",
                   "--frames", "12", "--root", str(tmp_path / "cache"), "--out", str(tmp_path / "results")]
        for line in self.commands(section):
            if line.startswith("printf"):
                subprocess.run(line, shell=True, check=True, cwd=tmp_path)
                continue
            words = shlex.split(line)
            assert words[0] == "event-transforms", line
            args = [a for w in words[1:] for a in (sorted(glob.glob(w)) if "*" in w else [w])]
            assert cli.main(args + (reduced if args[0] == "reproduce" else [])) == 0, capsys.readouterr().err
        assert (tmp_path / "results" / "results.md").is_file()
        out = capsys.readouterr().out
        # then a model from the same folder, with the reproduce command's reading options, streamed on a recording
        options = shlex.split(line)[4:]  # after "event-transforms reproduce --data rig"
        assert cli.main(["train", "--data", "rig", "--out", "model.pt", "--steps", "2", "--input-pool", "3",
                         "--hidden-channels", "2", "--frames", "12", *options]) == 0
        table = (tmp_path / "rig" / "recordings.csv").read_text().splitlines()
        first = tmp_path / "rig" / table[1].split(",")[0]
        reading = [w for w in ("--time-unit", "--sensor-size", "--columns") if w in options]
        given = [v for w in reading for v in options[options.index(w):options.index(w) + (3 if w == "--sensor-size"
                                                                                              else 2)]]
        assert cli.main(["predict", "model.pt", str(first), "--out", "estimate.csv", *given]) == 0
        assert len(np.loadtxt(tmp_path / "estimate.csv", delimiter=",", skiprows=1)) == 24
        return out

    def test_a_ros_bag(self, tmp_path, monkeypatch, capsys):
        from tests.support.rig_files import write_bag

        for k, name in enumerate(["train_0", "train_1", "train_2", "deploy_0", "deploy_1"]):
            events, t, force = grasp_events(k)
            write_bag(tmp_path / f"{name}.bag", events, SENSOR, t, np.c_[0.6 * force, 0 * force, 0.8 * force],
                      force_topic="/ft_sensor/wrench")
            np.savetxt(tmp_path / f"{name}.csv", [])  # noise beside the bags, never read
        out = self.run("A ROS bag", tmp_path, monkeypatch, capsys)
        assert out.count("magnitude of geometry_msgs/msg/WrenchStamped, header stamps") == 5

    def test_an_aedat4_recording_and_an_ft_log(self, tmp_path, monkeypatch, capsys):
        (tmp_path / "rig").mkdir()
        for k in range(1, 5):
            events, t, force = grasp_events(k)
            marked = np.arange(15, t.size - 15, 20)
            write_aedat4(tmp_path / "rig" / f"g{k}.aedat4", events, SENSOR, triggers=t[marked].astype(np.int64))
            flags = np.zeros(t.size, dtype=int)
            flags[marked] = 1
            t_ns = t * 1000 + 5_000_000_000  # the logger's clock reads 5 s more than the camera's
            np.savetxt(tmp_path / "rig" / f"g{k}.csv", np.c_[t_ns, 0.6 * force, 0 * force, 0.8 * force, flags],
                       delimiter=",", header="t_ns,fx,fy,fz,trigger", comments="", fmt="%.17g")
        out = self.run("An .aedat4 recording and an F/T log", tmp_path, monkeypatch, capsys)
        assert out.count("time column t_ns (nanoseconds) read as microseconds; force = |(fx, fy, fz)|") == 4
        assert out.count("force clock aligned to the camera's by -5000.000 ms from 11 triggers (spread 0.0 µs)") == 4

    def test_an_hdf5_array(self, tmp_path, monkeypatch, capsys):
        h5py = pytest.importorskip("h5py")
        (tmp_path / "rig").mkdir()
        for k in range(1, 5):
            events, t, force = grasp_events(k)
            rows = rows_of(events)
            rows[:, 2] *= 1000  # nanoseconds
            with h5py.File(tmp_path / "rig" / f"g{k}.h5", "w") as f:
                f["events"] = rows
            np.savetxt(tmp_path / "rig" / f"g{k}.csv", np.c_[t * 1000, force], delimiter=",", header="t_ns,fz",
                       comments="", fmt="%.17g")
        out = self.run("An HDF5 array", tmp_path, monkeypatch, capsys)
        assert out.count("time column t_ns (nanoseconds) read as microseconds; force = column fz") == 4


class TestPropheseeDat:
    def test_dat_written_by_faery_reads_with_its_size(self, tmp_path):
        faery = pytest.importorskip("faery")
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        want = RecordingSet(root, split="train", cache=tmp_path / "c", sensor_size=SENSOR, frames=12,
                            crop=(0, 0, 30, 40))

        def write(path, events):
            packed = np.zeros(len(events), dtype=faery.EVENTS_DTYPE)
            packed["t"], packed["x"], packed["y"], packed["p"] = events["t"], events["x"], events["y"], events["p"] > 0
            faery.events_stream_from_array(packed, dimensions=(SENSOR[1], SENSOR[0])).to_file(path, zero_t0=False)

        for k in range(5):
            swap_events(root, k, ".dat", write)
        got = read_events(root / "r0.dat")
        events = grasp_events(0)[0]
        for c in "xytp":
            assert np.array_equal(got[c].astype(np.int64), events[c].astype(np.int64)), c
        data = RecordingSet(root, split="train", cache=tmp_path / "c", frames=12, crop=(0, 0, 30, 40))
        assert data.sensor_size == SENSOR
        for i in range(len(data)):
            assert torch.equal(data[i][0], want[i][0])
        (tmp_path / "bad.dat").write_bytes(b"\x0c\x08" + bytes(16))
        with pytest.raises(ValueError, match="bad.dat: not a Prophesee .dat file"):
            read_events(tmp_path / "bad.dat")

    def test_raw_evt3_written_by_faery(self, tmp_path, monkeypatch):
        import sys

        faery = pytest.importorskip("faery")
        pytest.importorskip("evt3")
        events = grasp_events(0)[0]
        packed = np.zeros(len(events), dtype=faery.EVENTS_DTYPE)
        packed["t"], packed["x"], packed["y"], packed["p"] = events["t"], events["x"], events["y"], events["p"] > 0
        stream = faery.events_stream_from_array(packed, dimensions=(SENSOR[1], SENSOR[0]))
        stream.to_file(tmp_path / "e.raw", version="evt3", zero_t0=False)
        got = read_events(tmp_path / "e.raw")
        for c in "xytp":
            assert np.array_equal(got[c].astype(np.int64), events[c].astype(np.int64)), c
        assert EventFile(tmp_path / "e.raw").sensor_size == SENSOR
        faery.events_stream_from_array(packed, dimensions=(SENSOR[1], SENSOR[0])).to_file(
            tmp_path / "old.raw", version="evt2", zero_t0=False)
        with pytest.raises(ValueError, match="only Prophesee .raw files in EVT 3.0 are read, this one says evt 2.0"):
            read_events(tmp_path / "old.raw")
        monkeypatch.setitem(sys.modules, "evt3", None)
        with pytest.raises(ValueError, match=r"pip install 'event-transforms\[prophesee\]'"):
            read_events(tmp_path / "e.raw")
