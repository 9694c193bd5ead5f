"""Tests for a user's own recordings: the layout, RecordingSet, force labels, splits, the cache,
bad input, the exported scene, the run store's resume keys, train/predict and the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from event_transforms.functional import events_to_frames
from event_transforms.tactile import cli, protocol, recordings
from event_transforms.tactile.methods import parse_method
from event_transforms.tactile.recordings import (
    RecordingSet,
    RecordingSettings,
    contact_crop,
    frame_labels,
    read_events,
    read_force,
    read_table,
)

pytestmark = pytest.mark.usefixtures("one_thread")

SENSOR = (30, 40)
EVENT_DTYPE = np.dtype([("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])


def grasp_events(seed: int, duration_us: int = 240_000, start_us: int = 1_000_000, lag_us: int = 0):
    """Background noise plus a contact strip whose event rate follows a force ramp; the force
    sampled at 1 kHz (times on the same clock)."""
    rng = np.random.default_rng(seed)
    t_force = np.arange(start_us, start_us + duration_us + 1, 1_000)
    phase = (t_force - start_us) / duration_us
    force = 2.0 + 18.0 * np.clip(np.minimum(phase * 4, (1 - phase) * 4), 0, 1) * (0.5 + rng.random())
    noise = rng.integers(0, duration_us, 600) + start_us
    strip_t = []
    for t, f in zip(t_force[:-1], force[:-1]):
        strip_t.append(t + lag_us + rng.integers(0, 1_000, rng.poisson(f * 0.6)))
    strip_t = np.concatenate(strip_t)
    n, m = noise.size, strip_t.size
    events = np.zeros(n + m, dtype=EVENT_DTYPE)
    events["t"] = np.concatenate([noise, strip_t])
    events["x"] = np.concatenate([rng.integers(0, SENSOR[1], n), rng.integers(12, 28, m)])
    events["y"] = np.concatenate([rng.integers(0, SENSOR[0], n), rng.integers(12, 17, m)])
    events["p"] = np.concatenate([rng.integers(0, 2, n), (rng.random(m) < 0.3).astype(int)])
    events = events[np.argsort(events["t"], kind="stable")]
    events = events[events["t"] < start_us + duration_us]
    return events, t_force, force


def write_force(path: Path, t, force) -> None:
    np.savetxt(path, np.c_[t, force], delimiter=",", header="t_us,force_n", comments="", fmt=["%d", "%.6f"])


def make_folder(root: Path, *, train: int = 6, deploy: int = 5, unlabeled: int = 1, lag_us: int = 0,
                extra: str = "") -> Path:
    root.mkdir(parents=True, exist_ok=True)
    rows = ["events,force,role,diameter_mm,object" + (",operator" if extra else "")]
    k = 0
    for role, count in (("train", train), ("deploy", deploy), ("unlabeled", unlabeled)):
        for _ in range(count):
            events, t, force = grasp_events(k, lag_us=lag_us if role != "train" else 0)
            np.save(root / f"r{k}.npy", events)
            force_cell = ""
            if role != "unlabeled":
                write_force(root / f"f{k}.csv", t, force)
                force_cell = f"f{k}.csv"
            rows.append(f"r{k}.npy,{force_cell},{'deploy' if role == 'unlabeled' else role},15,bolt"
                        + (f",{extra}" if extra else ""))
            k += 1
    (root / "recordings.csv").write_text("\n".join(rows) + "\n")
    return root


SMALL = {"sensor_size": SENSOR, "frames": 12, "pool": 2}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return make_folder(tmp_path_factory.mktemp("recordings"), extra="ann")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


class TestLayout:
    def test_splits_never_share_a_recording(self, folder):
        table = read_table(folder)
        by_split = {s: [r.row for r in table if r.split == s] for s in recordings.SPLITS}
        assert by_split == {"train": [2, 3, 4, 5], "holdout": [6, 7], "val": [8], "test": [9, 10, 11, 12],
                            "unlabeled": [13]}
        assert all(r.meta == {"object": "bolt", "operator": "ann"} for r in table)

    def test_split_column_overrides_the_rule(self, tmp_path):
        root = make_folder(tmp_path / "d", train=3, deploy=3, unlabeled=0)
        lines = (root / "recordings.csv").read_text().splitlines()
        lines[0] += ",split"
        splits = ["holdout", "train", "train", "test", "val", "test"]
        lines[1:] = [line + "," + s for line, s in zip(lines[1:], splits)]
        (root / "recordings.csv").write_text("\n".join(lines) + "\n")
        assert [r.split for r in read_table(root)] == splits

    def test_items_windows_and_meta(self, folder, cache):
        data = RecordingSet(folder, split="train", cache=cache, **SMALL)
        frames, force, meta = data[0]
        assert frames.dtype == torch.float32 and frames.shape == (12, 2, *[s // 2 for s in data.crop[2:]])
        assert force.shape == (12,) and force.dtype == torch.float32
        assert meta["diameter_mm"] == 15.0 and meta["object"] == "bolt" and meta["operator"] == "ann"
        assert meta["recording"] == "r0.npy" and meta["start_frame"] == 0
        # 240 ms in 10 ms frames, windows of 12 every 12 frames: 2 per recording, 4 recordings
        assert len(data) == 8 and data.left_out_frames == 0
        strided = RecordingSet(folder, split="train", cache=cache, stride=5, **SMALL)
        assert len(strided) == 4 * 3 and strided.left_out_frames == 4 * 2
        assert strided.meta(1)["start_frame"] == 5
        torch.testing.assert_close(strided[1][0], RecordingSet(folder, split="train", cache=cache, **SMALL)._data[0]
                                   ["frames"][5:17].float())

    def test_frames_equal_binning_the_file(self, folder, cache):
        data = RecordingSet(folder, split="val", cache=cache, crop=(4, 6, 20, 30), **SMALL)
        events = np.load(folder / "r6.npy")
        expected = events_to_frames(events, sensor_size=SENSOR, crop=(4, 6, 20, 30), pool=2)
        torch.testing.assert_close(torch.cat([data[0][0], data[1][0]]), expected[:24])
        assert data.crop_source == "given"

    def test_crop_from_the_contact_area(self, folder, cache):
        data = RecordingSet(folder, split="train", cache=cache, **SMALL)
        top, left, height, width = data.crop
        # the strip spans rows 12-16 and columns 12-27: inside the box, the box not the sensor
        assert top <= 12 and top + height >= 17 and left <= 12 and left + width >= 28
        assert height * width < SENSOR[0] * SENSOR[1] and height % 2 == 0 and width % 2 == 0
        assert data.crop_source == "contact area of 4 training recordings"

    def test_contact_crop_reference(self):
        totals = np.ones((50, 60), dtype=np.int64)
        totals[20:30, 10:50] = 40
        totals[2, 3] = 10_000  # a hot pixel stays outside
        assert contact_crop(totals, pool=2) == (19, 6, 12, 48)
        assert contact_crop(np.zeros((7, 9), dtype=np.int64), pool=2) == (0, 0, 6, 8)

    def test_recording_of_many_grasps_cut_into_windows(self, tmp_path, cache):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        data = RecordingSet(root, split="test", cache=cache, sensor_size=SENSOR, frames=5, stride=3, pool=2)
        # 24 frames; windows start at 0, 3, ..., 18
        assert [data.meta(i)["start_frame"] for i in range(len(data))] == [0, 3, 6, 9, 12, 15, 18]


def slow_labels(t, force, t_start, frame_us, n_frames):
    out = []
    for i in range(n_frames):
        lo, hi = t_start + i * frame_us, t_start + (i + 1) * frame_us
        inside = [f for tt, f in zip(t, force) if lo <= tt < hi]
        if inside:
            out.append(sum(inside) / len(inside))
        else:  # linear interpolation at the centre
            c = (lo + hi) / 2
            k = max(j for j in range(len(t)) if t[j] <= c)
            out.append(force[k] + (force[k + 1] - force[k]) * (c - t[k]) / (t[k + 1] - t[k]))
    return out


class TestForceLabels:
    @pytest.mark.parametrize("seed", range(4))
    def test_irregular_sampling_against_a_slow_reference(self, seed):
        rng = np.random.default_rng(seed)
        # dense in some frames, none in others
        t = np.sort(np.concatenate([rng.uniform(0, 100_000, 40), [0.0, 120_000.0]]))
        force = rng.normal(10, 3, t.size)
        got = frame_labels(t, force, t_start=0, frame_us=10_000, n_frames=12)
        assert got.tolist() == pytest.approx(slow_labels(t, force, 0, 10_000, 12), rel=1e-12)

    def test_one_sample_per_frame_is_exact(self):
        t = np.arange(5_000, 360_000, 10_000, dtype=np.float64)
        force = np.float32(np.random.default_rng(0).normal(10, 4, 36)).astype(np.float64)
        assert np.array_equal(frame_labels(t, force, t_start=0, frame_us=10_000, n_frames=36), force)

    def test_declared_offset(self, tmp_path):
        path = tmp_path / "f.csv"
        t = np.arange(0, 100_001, 1_000)
        write_force(path, t, t / 1000.0)  # force = time in ms
        shifted_t, shifted = read_force(path, offset_ms=7.0)
        labels = frame_labels(shifted_t, shifted, t_start=10_000, frame_us=10_000, n_frames=5)
        # bin [10, 20) ms on the events' clock holds force samples taken at 3..12 ms on the force clock
        assert labels.tolist() == pytest.approx([7.5, 17.5, 27.5, 37.5, 47.5])
        assert labels.tolist() == pytest.approx(slow_labels(shifted_t, shifted, 10_000, 10_000, 5))

    def test_offset_moves_the_items_labels(self, folder, cache):
        plain = RecordingSet(folder, split="val", cache=cache, **SMALL)
        offset = RecordingSet(folder, split="val", cache=cache, force_offset_ms=-10.0, **SMALL)
        # force one frame earlier on the events' clock: frame k now reads what frame k + 1 read
        torch.testing.assert_close(offset[0][1][:-1], plain[0][1][1:], atol=1e-5, rtol=0)
        with pytest.raises(ValueError, match="force must cover the recording"):
            RecordingSet(folder, split="val", cache=cache, force_offset_ms=10.0, **SMALL)


class TestFormats:
    @pytest.fixture
    def events(self):
        return grasp_events(3)[0]

    def check(self, path, events):
        got = read_events(path)
        for c in "xyt":
            assert np.array_equal(got[c].astype(np.int64), events[c].astype(np.int64)), c
        assert np.array_equal(got["p"].astype(np.int64) > 0, events["p"] > 0)

    def test_npy_structured_tonic_and_rows(self, tmp_path, events):
        tonic = np.zeros(len(events), dtype=[("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])
        for c in "txy":
            tonic[c] = events[c]
        tonic["p"] = events["p"] > 0
        np.save(tmp_path / "tonic.npy", tonic)
        self.check(tmp_path / "tonic.npy", events)
        rows = np.stack([events[c].astype(np.int64) for c in "xytp"], axis=1)
        np.save(tmp_path / "rows.npy", rows)
        self.check(tmp_path / "rows.npy", events)

    def test_npz_and_csv(self, tmp_path, events):
        np.savez(tmp_path / "e.npz", **{c: events[c] for c in "xytp"})
        self.check(tmp_path / "e.npz", events)
        np.savetxt(tmp_path / "e.csv", np.stack([events[c] for c in "tpxy"], 1), delimiter=",", fmt="%d",
                   header="timestamp,polarity,x,y", comments="")
        self.check(tmp_path / "e.csv", events)

    def test_hdf5(self, tmp_path, events):
        h5py = pytest.importorskip("h5py")
        with h5py.File(tmp_path / "a.h5", "w") as f:
            f["events"] = events
        with h5py.File(tmp_path / "b.hdf5", "w") as f:
            f.create_group("CD")["events"] = events
        with h5py.File(tmp_path / "c.h5", "w") as f:
            for c in "xytp":
                f[c] = events[c]
        for name in ("a.h5", "b.hdf5", "c.h5"):
            self.check(tmp_path / name, events)

    def test_aedat4_written_by_faery(self, tmp_path, events):
        """A real .aedat4 (faery's writer), read by the aedat package's decoder; its size stated."""
        pytest.importorskip("aedat")
        from tests.support.rig_files import write_aedat4

        write_aedat4(tmp_path / "e.aedat4", events, SENSOR)
        self.check(tmp_path / "e.aedat4", events)
        from event_transforms.events.io import EventFile, stated_sensor_size

        assert stated_sensor_size(tmp_path / "e.aedat4") == SENSOR == EventFile(tmp_path / "e.aedat4").sensor_size

    def test_same_frames_from_every_format(self, tmp_path, cache):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        events = np.load(root / "r3.npy")
        np.savez(root / "r3.npz", **{c: events[c] for c in "xytp"})
        table = (root / "recordings.csv").read_text().replace("r3.npy", "r3.npz")
        (root / "recordings.csv").write_text(table)
        a = RecordingSet(root, split="val", cache=cache, crop=(0, 0, 30, 40), **SMALL)
        assert a.recordings[0].events.name == "r3.npz"
        expected = events_to_frames(events, sensor_size=SENSOR, pool=2)
        torch.testing.assert_close(a[0][0], expected[:12])


class TestBadInput:
    def folder(self, tmp_path, **kwargs):
        return make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0, **kwargs)

    def edit_table(self, root, old, new):
        (root / "recordings.csv").write_text((root / "recordings.csv").read_text().replace(old, new, 1))

    def build(self, root, tmp_path, **kwargs):
        return RecordingSet(root, split="train", cache=tmp_path / "cache", **{**SMALL, **kwargs})

    def test_missing_files(self, tmp_path):
        root = self.folder(tmp_path)
        (root / "r1.npy").unlink()
        with pytest.raises(ValueError, match=r"row 3: events file .*r1.npy.* does not exist"):
            read_table(root)
        root = self.folder(tmp_path / "2")
        (root / "f2.csv").unlink()
        with pytest.raises(ValueError, match=r"row 4: force file .*f2.csv.* does not exist"):
            read_table(root)
        with pytest.raises(ValueError, match="holds no recordings.csv"):
            read_table(tmp_path / "nowhere")

    def test_roles_and_no_deploy(self, tmp_path):
        root = self.folder(tmp_path)
        self.edit_table(root, ",deploy,", ",deployment,")
        with pytest.raises(ValueError, match="row 5: role must be 'train' or 'deploy', got 'deployment'"):
            read_table(root)
        lines = (root / "recordings.csv").read_text().splitlines()
        (root / "recordings.csv").write_text("\n".join(lines[:4]) + "\n")
        with pytest.raises(ValueError, match="no deployment recording"):
            read_table(root)
        (root / "recordings.csv").write_text("\n".join(lines[:5]).replace("deployment", "deploy") + "\n")
        with pytest.raises(ValueError, match="1 labelled deployment recording"):
            read_table(root)

    @pytest.mark.parametrize("content, message", [
        ("time,force_n\n0,1\n", r"the time column 'time' does not say its unit.*force_time_unit='ns'"),
        ("when,force\n0,1\n", r"needs a time column t_us \(or t_ns, t_ms, t_s\) and force_n"),
        ("t_us,force_n\n0,1\n10,nan\n", r"f1.csv line 3: force_n is nan"),
        ("t_us,force_n\n0,1\nnan,2\n", r"f1.csv line 3: t_us is nan"),
        ("t_us,force_n\n-5,1\n10,2\n", r"f1.csv line 2: t_us is negative"),
        ("t_us,force_n\n1000000,1\n900000,2\n", r"f1.csv line 3: t_us goes back in time"),
        ("t_us,force_n\n1000000,1\n1100000,2\n", r"row 3.*f1.csv.*force must cover the recording"),
    ])
    def test_force_files(self, tmp_path, content, message):
        root = self.folder(tmp_path)
        (root / "f1.csv").write_text(content)
        with pytest.raises(ValueError, match=message):
            self.build(root, tmp_path)

    def test_unsorted_out_of_sensor_seconds_polarity(self, tmp_path):
        root = self.folder(tmp_path)
        events = np.load(root / "r1.npy")
        bad = events.copy()
        bad["t"][50], bad["t"][51] = bad["t"][51] + 10, bad["t"][50]
        np.save(root / "r1.npy", bad)
        with pytest.raises(ValueError, match=r"row 3 \(r1.npy\): events are not sorted by t: event 51"):
            self.build(root, tmp_path)
        bad = events.copy()
        bad["x"][7] = 40
        np.save(root / "r1.npy", bad)
        with pytest.raises(ValueError, match=r"row 3 \(r1.npy\): event 7 at \(x, y\) = \(40, .*outside the sensor"):
            self.build(root, tmp_path)
        seconds = np.zeros(len(events), dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<f8"), ("p", "<i1")])
        for c in "xyp":
            seconds[c] = events[c]
        seconds["t"] = events["t"] / 1e6
        np.save(root / "r1.npy", seconds)
        with pytest.raises(ValueError, match=r"row 3 \(r1.npy\): timestamps look like seconds"):
            self.build(root, tmp_path)
        bad = events.copy()
        bad["p"][3] = 2
        np.save(root / "r1.npy", bad)
        with pytest.raises(ValueError, match=r"row 3 \(r1.npy\): polarity must be"):
            self.build(root, tmp_path)

    def test_windows_shorter_than_t(self, tmp_path):
        root = self.folder(tmp_path)
        with pytest.raises(ValueError, match=r"row 2 \(r0.npy\): 24 frames of 10 ms, fewer than one window of frames=30; lower frames="):
            self.build(root, tmp_path, frames=30)

    def test_bad_settings_and_cells(self, tmp_path):
        with pytest.raises(ValueError, match="frames"):
            RecordingSettings(frames=0)
        with pytest.raises(ValueError, match="multiples of pool"):
            RecordingSettings(crop=(0, 0, 11, 10), pool=2)
        root = self.folder(tmp_path)
        self.edit_table(root, ",15,", ",-3,")
        with pytest.raises(ValueError, match="row 2: diameter_mm must be a positive number, got '-3'"):
            read_table(root)

    def test_nothing_half_written_stays(self, tmp_path, monkeypatch):
        root = self.folder(tmp_path)

        def interrupted(obj, stream, *args, **kwargs):
            stream.write(b"partial")
            raise KeyboardInterrupt

        monkeypatch.setattr(torch, "save", interrupted)
        with pytest.raises(KeyboardInterrupt):
            self.build(root, tmp_path)
        assert list((tmp_path / "cache").glob("*")) in ([], [tmp_path / "cache" / "hashes.json"])


def seconds_folder(source: Path, root: Path) -> Path:
    """A copy of ``source`` whose event files hold float64 seconds, ``(t_us + 0.5) / 1e6``: half
    a microsecond off the integer grid, so the rounding of the conversion back to microseconds
    cannot move an event across a bin edge (the frames must equal the microsecond file's)."""
    import shutil

    shutil.copytree(source, root)
    for path in root.glob("r*.npy"):
        events = np.load(path)
        seconds = np.zeros(len(events), dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<f8"), ("p", "<i1")])
        for c in "xyp":
            seconds[c] = events[c]
        seconds["t"] = (events["t"] + 0.5) / 1e6
        np.save(path, seconds)
    return root


class TestTimeUnit:
    def test_float_seconds_file_equals_the_microsecond_file(self, folder, cache, tmp_path):
        root = seconds_folder(folder, tmp_path / "s")
        for split in ("train", "val", "unlabeled"):
            us = RecordingSet(folder, split=split, cache=cache, **SMALL)
            s = RecordingSet(root, split=split, cache=tmp_path / "c", time_unit="s", **SMALL)
            assert len(s) == len(us) > 0 and s.crop == us.crop and s.crop_source == us.crop_source
            for i in range(len(us)):
                (f_us, force_us, meta_us), (f_s, force_s, meta_s) = us[i], s[i]
                assert torch.equal(f_us, f_s) and meta_us == meta_s
                assert torch.equal(force_us, force_s) or (force_us.isnan().all() and force_s.isnan().all())
        # the same as the library's binning of the seconds file (events_to_frames, time_unit="s")
        data = RecordingSet(root, split="val", cache=tmp_path / "c", time_unit="s", crop=(4, 6, 20, 30), **SMALL)
        expected = events_to_frames(np.load(root / "r6.npy"), sensor_size=SENSOR, crop=(4, 6, 20, 30), pool=2,
                                    time_unit="s")
        torch.testing.assert_close(torch.cat([data[0][0], data[1][0]]), expected[:24], rtol=0, atol=0)
        assert data.settings.as_dict()["time_unit"] == "s" and "time_unit" not in RecordingSettings().as_dict()

    def test_seconds_without_a_unit_are_refused_naming_it(self, folder, tmp_path):
        root = seconds_folder(folder, tmp_path / "s")
        with pytest.raises(ValueError, match=r"row 2 \(r0.npy\): timestamps look like seconds.*time_unit='s'"):
            RecordingSet(root, split="train", cache=tmp_path / "c", **SMALL)
        with pytest.raises(ValueError, match=r"time_unit must be one of .*got 'sec'"):
            RecordingSettings(time_unit="sec")
        with pytest.raises(ValueError, match=r"time_unit must be one of .*got 'sec'"):
            RecordingSet(root, split="train", cache=tmp_path / "c", time_unit="sec", **SMALL)

    def test_integer_milliseconds(self, tmp_path):
        """Whole-millisecond integer timestamps with time_unit="ms" bin like the same events in µs."""
        root = make_folder(tmp_path / "us", train=3, deploy=2, unlabeled=0)
        ms = tmp_path / "ms"
        import shutil

        shutil.copytree(root, ms)
        for path in sorted(root.glob("r*.npy")):
            events = np.load(path)
            events["t"] = events["t"] // 1000 * 1000  # whole milliseconds, still sorted
            np.save(path, events)
            events["t"] //= 1000
            np.save(ms / path.name, events)
        us_set = RecordingSet(root, split="train", cache=tmp_path / "c", **SMALL)
        ms_set = RecordingSet(ms, split="train", cache=tmp_path / "c", time_unit="ms", **SMALL)
        assert len(us_set) == len(ms_set) > 0
        assert all(torch.equal(us_set[i][0], ms_set[i][0]) and torch.equal(us_set[i][1], ms_set[i][1])
                   for i in range(len(us_set)))

    def test_cli_option_and_predict_read_the_unit(self, folder, tmp_path):
        from event_transforms.tactile.deployment import predict_stream
        from event_transforms.tactile.models import ForceRegressor

        args = cli.build_parser().parse_args(["infer-scene", "--data", str(folder), "--time-unit", "s"])
        assert cli._recording_settings(args).time_unit == "s"
        assert cli.build_parser().parse_args(["infer-scene", "--data", str(folder)]).time_unit is None
        root = seconds_folder(folder, tmp_path / "s")
        torch.manual_seed(0)
        model = ForceRegressor(hidden_channels=(2,), input_pool=2).eval()
        base = {"frame_ms": 10.0, "crop": [4, 6, 20, 30], "pool": 2, "sensor_size": list(SENSOR)}
        model.preprocessing = base
        predict_stream(model, folder / "r6.npy", tmp_path / "us.csv")
        model.preprocessing = {**base, "time_unit": "s"}  # what train records for --time-unit s
        predict_stream(model, root / "r6.npy", tmp_path / "s.csv")
        assert (tmp_path / "us.csv").read_text() == (tmp_path / "s.csv").read_text()
        with pytest.raises(ValueError, match="timestamps look like seconds"):
            model.preprocessing = base
            predict_stream(model, root / "r6.npy", tmp_path / "x.csv")


class TestCache:
    def test_read_back_without_binning(self, folder, tmp_path, monkeypatch):
        first = RecordingSet(folder, split="val", cache=tmp_path, **SMALL)
        monkeypatch.setattr(recordings.dataset, "_bin_recording", lambda *a: pytest.fail("binned again"))
        second = RecordingSet(folder, split="val", cache=tmp_path, **SMALL)
        torch.testing.assert_close(first[1][0], second[1][0])

    def test_content_change_rebins(self, tmp_path):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        a = RecordingSet(root, split="val", cache=tmp_path / "c", crop=(0, 0, 30, 40), **SMALL)
        events = np.load(root / "r3.npy")
        events["p"] = 1 - events["p"]
        np.save(root / "r3.npy", events)
        b = RecordingSet(root, split="val", cache=tmp_path / "c", crop=(0, 0, 30, 40), **SMALL)
        torch.testing.assert_close(b[0][0], a[0][0].flip(1))
        assert a.dataset_hash != b.dataset_hash

    def test_corrupt_cache_file_is_named_and_rebuilt(self, tmp_path):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        expected = RecordingSet(root, split="val", cache=tmp_path / "c", **SMALL)[0][0]
        for path in (tmp_path / "c").glob("recording-*.pt"):
            truncate(path, 100)
        with pytest.warns(UserWarning, match=r"discarded the unreadable cache file .*recording-.*\.pt"):
            b = RecordingSet(root, split="val", cache=tmp_path / "c", **SMALL)
        torch.testing.assert_close(expected, b[0][0])

    def test_corrupt_simulated_cache_is_named_and_rebuilt(self, tmp_path):
        from event_transforms.tactile.datasets import TactileGrasps

        a = TactileGrasps("val", root=tmp_path, paper_split=True, scene="control")
        expected = a[0][0].clone()
        truncate(a.path, 1000)
        with pytest.warns(UserWarning, match=f"discarded the unreadable cache file {a.path}"):
            b = TactileGrasps("val", root=tmp_path, paper_split=True, scene="control")
        torch.testing.assert_close(b[0][0], expected)


def truncate(path: Path, size: int) -> None:
    """A truncated copy in the file's place (a new inode: memory maps of the old one stay valid)."""
    head = path.read_bytes()[:size]
    path.unlink()
    path.write_bytes(head)


TINY = protocol.ProtocolConfig(steps=3, batch_size=4, eval_every=2, hidden_channels=(2,), input_pool=4)


@pytest.fixture(scope="module")
def data(folder, cache):
    return recordings.load_recording_data(folder, RecordingSettings(**SMALL), cache=cache, name="mine")


class TestProtocolOnRecordings:
    def test_results_name_the_data_and_count_recordings(self, data, tmp_path):
        results = protocol.run_protocol(["mine"], [0, 1], tmp_path, config=TINY, methods=["none", "fs1"],
                                          data={"mine": data}, group="method", budget_check=False)
        assert "simulated" not in results["data"] and data.dataset["content_hash"][:16] in results["data"]
        scene = results["scenes"]["mine"]
        assert scene["recordings"] == {"train": 4, "holdout": 2, "val": 1, "test": 4, "unlabeled": 1}
        assert scene["split_sizes"] == {"train": 8, "val": 2, "test": 8, "holdout": 4}
        assert "physics least-squares" in scene["baselines"]
        report = (tmp_path / "results.md").read_text()
        assert "the intervals rest on 4 test recordings" in report

    def test_inferred_reads_no_deployment_force(self, folder, tmp_path, monkeypatch):
        """The scene is inferred from frames: deployment forces are never read for it."""
        root = make_folder(tmp_path / "d", train=6, deploy=5, unlabeled=1, lag_us=20_000)
        read = []
        real = recordings.read_force
        monkeypatch.setattr(recordings.dataset, "read_force", lambda path, **k: (read.append(Path(path).name), real(path, **k))[1])
        data = recordings.load_recording_data(root, RecordingSettings(**{**SMALL, "frames": 24}), cache=tmp_path / "c")
        deploy_forces = {r.force.name for r in read_table(root) if r.role == "deploy" and r.force is not None}
        # every labelled file is read once to label its windows, never for the inference: binning order
        assert sorted(read) == sorted({r.force.name for r in read_table(root) if r.force is not None})
        # deployment events come 20 ms later: a timing gap, a shift to later frames
        assert data.scene.gaps == ("timing",) and data.scene.inferred.lag_shifts[0] > 0
        assert deploy_forces  # (the test folder has labelled deployment recordings)
        method = parse_method("inferred", scene=data.scene)
        assert type(method.build(data.noise_bank)).__name__ == "OneOf"

    def test_unlabeled_items_have_no_force(self, folder, cache):
        unlabeled = RecordingSet(folder, split="unlabeled", cache=cache, **SMALL)
        assert len(unlabeled) == 2 and bool(unlabeled[0][1].isnan().all())


@pytest.mark.slow
def test_exported_scene_matches_the_built_in_scene(tmp_path, monkeypatch):
    """export -> RecordingSet -> protocol gives the built-in scene's per-seed test MSEs."""
    from event_transforms.tactile import datasets
    from event_transforms.tactile.copies import load_scene_data

    monkeypatch.setattr(datasets, "SPLIT_SIZES", {"train": 6, "holdout": 3, "val": 3, "test": 6})
    recordings.export_scene("paper", tmp_path / "export")
    data = recordings.load_recording_data(tmp_path / "export", cache=tmp_path / "c")
    built_in = load_scene_data("paper", str(tmp_path / "sim"))
    for split in ("train", "holdout", "val", "test"):
        a, b = getattr(data, split), getattr(built_in, split)
        assert len(a) == len(b)
        for i in range(len(a)):
            assert torch.equal(a[i][0], b[i][0]) and torch.equal(a[i][1], b[i][1])
    config = protocol.ProtocolConfig(steps=4, batch_size=4, eval_every=2, hidden_channels=(2,), input_pool=14)
    methods = ["none", "stretch", "fs-1"]
    ours = protocol.run_protocol(["export"], [0, 1], tmp_path / "a", config=config, methods=methods,
                                   data={"export": data}, group="method", budget_check=False)
    theirs = protocol.run_protocol(["paper"], [0, 1], tmp_path / "b", config=config, methods=methods,
                                     data={"paper": built_in}, group="method", budget_check=False)
    assert data.scene.gaps == ("size",) and data.scene.target_size == 15.0
    for method in methods:
        assert ours["scenes"]["export"]["methods"][method]["test_mse"] == pytest.approx(
            theirs["scenes"]["paper"]["methods"][method]["test_mse"], rel=1e-6)


@pytest.fixture(scope="module")
def fake():
    from tests.tactile.test_cli import fake_data

    return fake_data("control")


class TestResume:
    def run(self, out, data, seeds=(0, 1), config=TINY, log=None):
        return protocol.run_protocol(["control"], list(seeds), out, config=config, methods=["none", "fs2"],
                                       data={"control": data}, group="method", budget_check=False, log=log)

    def test_seeds_data_and_settings_changed_recompute(self, fake, tmp_path):
        from tests.tactile.test_cli import fake_data

        data = fake
        first = self.run(tmp_path, data)
        lines = []
        again = self.run(tmp_path, data, log=lines.append)
        timed = {"generation_s", "single_wall_s", "online_aug_s_per_epoch", "online_wall_s"}

        def untimed(value):  # the time columns are measured again on every run; the results are not
            if isinstance(value, dict):
                return {k: untimed(v) for k, v in value.items() if k not in timed}
            return value

        assert sum("resumed from disk" in line for line in lines) == 2
        assert untimed(again["scenes"]) == untimed(first["scenes"])
        # other seeds: their own units, never a mix
        more = self.run(tmp_path, data, seeds=(0, 1, 2))
        assert more["scenes"]["control"]["methods"]["none"]["seeds"] == [0, 1, 2]
        # other data under the same name and settings: recomputed, the reason named
        other = fake_data("control")
        other.train = type(other.train)(6, seed=11)
        lines = []
        changed = self.run(tmp_path, other, log=lines.append)
        assert sum("was made with other data: recomputing" in line for line in lines) == 2
        assert changed["scenes"]["control"]["methods"]["none"]["test_mse"] != \
            first["scenes"]["control"]["methods"]["none"]["test_mse"]
        # other settings (a model default included): recomputed
        lines = []
        self.run(tmp_path, data, config=protocol.ProtocolConfig(**{**TINY.__dict__, "lr": 5e-3}), log=lines.append)
        assert not any("resumed" in line for line in lines)

    def test_model_defaults_and_version_are_in_the_key(self, monkeypatch):
        from event_transforms.tactile import runs

        key = runs.folder_name(TINY, [0])
        monkeypatch.setattr(runs, "model_defaults", lambda: {"features": "linear"})
        assert runs.folder_name(TINY, [0]) != key
        monkeypatch.undo()
        monkeypatch.setattr(runs, "_version", lambda: "9.9")
        assert runs.folder_name(TINY, [0]) != key

    @pytest.mark.parametrize("damage", [b"", b"{\"key\": ", b"[1, 2]"])
    def test_corrupt_run_file_is_named_and_rebuilt(self, fake, tmp_path, damage):
        data = fake
        first = self.run(tmp_path, data)
        (path,) = [p for p in (tmp_path / "runs").rglob("control_none.json")]
        path.write_bytes(damage)
        lines = []
        again = self.run(tmp_path, data, log=lines.append)
        assert any(f"discarded the unreadable run file {path}" in line for line in lines)
        assert again["scenes"]["control"]["methods"]["none"]["test_mse"] == \
            first["scenes"]["control"]["methods"]["none"]["test_mse"]


class TestModelFile:
    def test_train_predict_round_trip(self, folder, tmp_path, capsys):
        from event_transforms.tactile.models import ForceRegressor

        model_path = tmp_path / "model.pt"
        common = ["--sensor-size", "30", "40", "--frames", "12", "--pool", "2"]
        assert cli.main(["train", "--data", str(folder), "--out", str(model_path), "--steps", "4",
                         "--input-pool", "3", "--hidden-channels", "2", *common]) == 0
        out = capsys.readouterr().out
        assert "wrote" in out and "test MSE" in out
        model = ForceRegressor.load(model_path)
        assert model.preprocessing["frame_ms"] == 10.0 and model.preprocessing["pool"] == 2
        assert model.config["input_pool"] == 3 and model.package_version
        assert model.preprocessing["force_scale_n"] > 0
        force_csv = tmp_path / "force.csv"
        assert cli.main(["predict", str(model_path), str(folder / "r6.npy"), "--out", str(force_csv)]) == 0
        assert "p50" in capsys.readouterr().out
        rows = np.loadtxt(force_csv, delimiter=",", skiprows=1)
        # the stream equals the model on the whole recording's frames
        events = np.load(folder / "r6.npy")
        frames = events_to_frames(events, sensor_size=SENSOR, crop=tuple(model.preprocessing["crop"]), pool=2)
        with torch.no_grad():
            expected = model(frames.unsqueeze(0))[0]
        assert rows.shape == (24, 2) and rows[:, 1] == pytest.approx(expected.numpy(), rel=1e-5)
        t0 = events["t"][0] // 10_000 * 10_000
        assert rows[:, 0].tolist() == [t0 + 5_000 + 10_000 * k for k in range(24)]

    def test_corrupt_checkpoint_is_named(self, tmp_path):
        from event_transforms.tactile.models import ForceRegressor

        path = tmp_path / "model.pt"
        ForceRegressor(hidden_channels=(2,), input_pool=2).save(path)
        path.write_bytes(path.read_bytes()[:200])
        with pytest.raises(ValueError, match=f"cannot load a model from '{path}'"):
            ForceRegressor.load(path)
        assert cli.main(["predict", str(path), str(path)]) == 2

    def test_infer_scene_command(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=6, deploy=5, unlabeled=1, lag_us=20_000)
        assert cli.main(["infer-scene", "--data", str(root), "--sensor-size", "30", "40", "--frames", "24"]) == 0
        out = capsys.readouterr().out
        assert "gaps ['timing']" in out and "timing: onset_ms train" in out and "GAP" in out

    def test_cli_errors_are_one_line(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        (root / "f1.csv").write_text("t_us,force\n0,1\n")
        assert cli.main(["reproduce", "--data", str(root), "--sensor-size", "30", "40", "--frames", "12",
                         "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert "f1.csv" in err and "force_n" in err and "Traceback" not in err


class TestLimitsBeforeTraining:
    """Every limit of the recordings path is checked before any training, named as the interface
    the caller used spells it (issue 44, item 1); counts say recordings and windows apart."""

    common = ["--sensor-size", "30", "40", "--pool", "2"]

    def reproduce(self, root, tmp_path, *extra):
        return cli.main(["reproduce", "--data", str(root), *self.common, "--steps", "2", "--seeds", "0,1",
                         "--out", str(tmp_path / "o"), "--root", str(tmp_path / "c"), "--no-plots", *extra])

    @pytest.fixture
    def trained_nothing(self, monkeypatch):
        from event_transforms.tactile import training

        def refuse(*args, **kwargs):
            raise AssertionError("trained before the limits were checked")

        monkeypatch.setattr(training, "fit_ensemble", refuse)

    def test_frames_under_the_phase_scores_are_refused_by_option(self, folder, cache, tmp_path, capsys,
                                                                 trained_nothing):
        assert self.reproduce(folder, tmp_path, "--frames", "8") == 2
        err = capsys.readouterr().err
        assert "windows of 8 frames (--frames 8)" in err and "give --frames 11 or more" in err
        data = recordings.load_recording_data(folder, RecordingSettings(**{**SMALL, "frames": 8}), cache=cache,
                                              name="short")
        with pytest.raises(ValueError, match=r"windows of 8 frames \(frames=8\).*give frames=11 or more"):
            protocol.run_protocol(["short"], [0, 1], tmp_path / "py", config=TINY, methods=["none"],
                                    data={"short": data}, budget_check=False)

    def test_a_batch_larger_than_the_training_windows_is_refused(self, folder, tmp_path, capsys, trained_nothing):
        assert self.reproduce(folder, tmp_path, "--frames", "12", "--batch-size", "1000") == 2
        err = capsys.readouterr().err
        assert "--batch-size 1000 is more than its 8 training windows (4 recordings)" in err
        assert "give --batch-size 8 or fewer" in err

    def test_the_default_sensor_is_named_when_events_lie_outside_it(self, tmp_path):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        events = np.load(root / "r0.npy")
        events["x"][5] = 300  # a DVXplorer's column, past a DAVIS240
        np.save(root / "r0.npy", events)
        with pytest.raises(ValueError, match=r"outside the sensor .*No event file states its sensor size and none "
                                             r"was given, so the default \(180, 240\) \(a DAVIS240\) was assumed"):
            RecordingSet(root, split="train", cache=tmp_path / "cache", frames=12, pool=2)

    def test_train_model_names_batch_size_in_python(self, data, trained_nothing):
        from event_transforms.tactile.deployment import train_model

        with pytest.raises(ValueError, match=r"batch_size=1000 is more than the 8 training windows.*give batch_size=8"):
            train_model(data, batch_size=1000, steps=2)

    def test_too_few_quiet_frames_for_noise_are_refused(self, tmp_path, capsys, trained_nothing):
        root = make_folder(tmp_path / "d", train=6, deploy=2, unlabeled=0)
        assert self.reproduce(root, tmp_path, "--frames", "12", "--methods", "none", "noise") == 2
        err = capsys.readouterr().err
        assert "method 'noise' adds recorded noise from a bank of 8 frames" in err
        assert "fewer than a window's 12 frames" in err and "--methods" in err

    def test_a_recording_in_two_roles_is_refused(self, tmp_path):
        root = make_folder(tmp_path / "d", train=3, deploy=2, unlabeled=0)
        lines = (root / "recordings.csv").read_text().splitlines()
        lines.append(lines[1].replace(",train,", ",deploy,"))
        (root / "recordings.csv").write_text("\n".join(lines) + "\n")
        with pytest.raises(ValueError, match=r"rows 2 and 7 list the same events file .*r0.npy.* as 'train' and as "
                                             r"'deploy'"):
            read_table(root)

    def test_no_hold_out_is_said_not_nan(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=2, deploy=2, unlabeled=0)
        assert cli.main(["train", "--data", str(root), *self.common, "--frames", "12", "--steps", "2",
                         "--input-pool", "3", "--hidden-channels", "2", "--out", str(tmp_path / "m.pt")]) == 0
        out = capsys.readouterr().out
        assert "no hold-out: 2 training recording(s), of which the last third (2 // 3 = 0)" in out
        assert "batch size 4: the folder's 4 training windows are fewer than the default 8" in out
        assert "final weights kept: no hold-out (2 training recordings)" in out and "nan" not in out

    def test_counts_say_recordings_and_windows_apart(self, tmp_path, capsys):
        root = make_folder(tmp_path / "d", train=6, deploy=2, unlabeled=2)
        assert cli.main(["infer-scene", "--data", str(root), *self.common, "--frames", "12"]) == 0
        out = capsys.readouterr().out
        assert ("8 training windows of 4 recordings and 6 deployment windows of 1 validation and 2 unlabeled "
                "recordings") in out
        assert "unlabeled recordings:" not in out and "from 6 unlabeled deployment windows" in out

    def test_default_rows_say_why_a_row_was_left_out(self, folder, tmp_path, capsys):
        assert self.reproduce(folder, tmp_path, "--frames", "12", "--plan") == 0
        out = capsys.readouterr().out
        assert ("left out, as the scene cannot build them: stretch, inferred, prior, everything (simulates a "
                "scene's gaps; scene") in out and "only none (and none-local" in out

    def test_every_reader_is_in_an_extra_the_message_names(self):
        import tomllib

        from event_transforms.events import io

        extras = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["project"][
            "optional-dependencies"]
        source = Path(io.__file__).read_text()
        for extra, package in (("aedat", "aedat"), ("hdf5", "h5py"), ("prophesee", "evt3")):
            assert any(d.startswith(package) for d in extras[extra]), extra
            assert f"pip install 'event-transforms[{extra}]'" in source, extra
        assert "pip install aedat)" not in source and "pip install h5py)" not in source
