"""Event streams as other tools hand them over: units, column orders, data frames, files.

Every case is checked against the same events given as int64 microsecond (x, y, t, p) rows,
the form the binning is tested on (tests/library/test_events_to_frames.py).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

import event_transforms as et
from event_transforms.functional import EventBatch, collate_events, events_to_frames, iter_frames

SENSOR = (6, 8)
T0 = 1_700_000_000_000_000  # absolute microseconds, as cameras stamp them


def reference(n: int = 60, seed: int = 0, t0: int = T0) -> np.ndarray:
    """(N, 4) int64 rows of (x, y, t, p), t in microseconds, sorted."""
    rng = np.random.default_rng(seed)
    t = t0 + np.sort(rng.integers(0, 55_000, n))
    return np.stack([rng.integers(0, SENSOR[1], n), rng.integers(0, SENSOR[0], n), t, rng.integers(0, 2, n)], 1)


def binned(events, **options):
    return events_to_frames(events, sensor_size=SENSOR, **options)


class TestTimeUnit:
    @pytest.mark.parametrize("unit, factor", [("ms", 1_000), ("s", 1_000_000)])
    def test_float_units_equal_integer_microseconds(self, unit, factor):
        rows = reference(t0=0)
        scaled = rows.astype(np.float64)
        scaled[:, 2] /= factor
        assert torch.equal(binned(scaled, time_unit=unit), binned(rows))

    def test_integer_milliseconds_and_nanoseconds(self):
        rows = reference(t0=0)
        rows[:, 2] -= rows[:, 2] % 1000  # whole milliseconds
        ms = rows.copy()
        ms[:, 2] //= 1000
        ns = rows.copy()
        ns[:, 2] = ns[:, 2] * 1000 + 999  # sub-microsecond parts are floored
        assert torch.equal(binned(ms, time_unit="ms"), binned(rows))
        assert torch.equal(binned(ns, time_unit="ns"), binned(rows))

    def test_float_seconds_without_a_unit_are_refused_by_name(self):
        rows = reference(t0=0).astype(np.float64)
        rows[:, 2] /= 1e6  # seconds, as importRosbag and evlib's HDF5 give them
        with pytest.raises(ValueError, match=r"looks like\s+seconds.*time_unit='s'"):
            binned(rows)
        with pytest.raises(ValueError, match="time_unit"):
            EventBatch.from_streams([rows], sensor_size=SENSOR)
        with pytest.raises(ValueError, match="time_unit"):
            list(iter_frames([rows], sensor_size=SENSOR))
        epoch_seconds = rows.copy()
        epoch_seconds[:, 2] += 1.7e9
        with pytest.raises(ValueError, match="seconds"):
            binned(epoch_seconds)

    def test_an_explicit_unit_is_believed(self):
        rows = reference(t0=0).astype(np.float64)
        rows[:, 2] = np.linspace(0.5, 999.5, len(rows))  # sub-millisecond float microseconds
        assert binned(rows, time_unit="us").shape[0] == 1

    def test_whole_float_microseconds_pass(self):
        rows = reference().astype(np.float64)  # float64 holds these exactly
        assert torch.equal(binned(rows), binned(reference()))

    def test_float32_absolute_microseconds_are_refused(self):
        rows = reference().astype(np.float32)
        with pytest.raises(ValueError, match=r"float32 .* lost microseconds"):
            binned(rows)
        with pytest.raises(ValueError, match="float32"):
            binned(torch.from_numpy(rows))
        relative = reference(t0=0).astype(np.float32)  # under 2**24 us: exact
        assert torch.equal(binned(relative), binned(reference(t0=0)))

    @pytest.mark.parametrize("bad", ["sec", "", 1, "US"])
    def test_bad_unit(self, bad):
        with pytest.raises(ValueError, match="time_unit must be one of"):
            binned(reference(), time_unit=bad)
        with pytest.raises(ValueError, match="time_unit must be one of"):
            et.EventsToFrames(SENSOR, time_unit=bad)

    def test_module_batch_and_stream_take_the_unit(self):
        rows = reference(t0=0)
        seconds = rows.astype(np.float64)
        seconds[:, 2] /= 1e6
        expected = binned(rows)
        assert torch.equal(et.EventsToFrames(SENSOR, time_unit="s")(seconds), expected)
        batch = collate_events([seconds], sensor_size=SENSOR, time_unit="s")
        assert torch.equal(batch.t, torch.from_numpy(rows[:, 2]).double())
        chunks = [seconds[:30], seconds[30:]]
        assert torch.equal(torch.stack(list(iter_frames(chunks, sensor_size=SENSOR, time_unit="s"))), expected)

    def test_input_not_modified(self):
        rows = reference().astype(np.float64)
        before = rows.copy()
        binned(rows, time_unit="us")
        assert np.array_equal(rows, before)


class TestTimeTypedColumns:
    def columns(self, unit: str) -> dict[str, np.ndarray]:
        rows = reference()
        return {"x": rows[:, 0], "y": rows[:, 1], "t": (rows[:, 2] * {"us": 1, "ns": 1000}[unit]).astype(f"timedelta64[{unit}]"),
                "p": rows[:, 3]}

    @pytest.mark.parametrize("unit", ["us", "ns"])
    def test_timedelta_columns_carry_their_unit(self, unit):
        assert torch.equal(binned(self.columns(unit)), binned(reference()))

    def test_datetime_column(self):
        events = self.columns("us")
        events["t"] = events["t"].astype(np.int64).astype("datetime64[us]")
        assert torch.equal(binned(events), binned(reference()))

    def test_contradicting_unit_and_nat_are_refused(self):
        with pytest.raises(ValueError, match="contradicts"):
            binned(self.columns("us"), time_unit="ms")
        events = self.columns("us")
        events["t"][3] = np.timedelta64("NaT")
        with pytest.raises(ValueError, match="NaT"):
            binned(events)
        events = self.columns("us")
        events["t"] = events["t"].astype("timedelta64[m]")
        with pytest.raises(ValueError, match="timedelta64"):
            binned(events)

    def test_structured_array_with_timedelta_field(self):
        rows = reference()
        events = np.zeros(len(rows), dtype=[("t", "m8[us]"), ("x", "<u2"), ("y", "<u2"), ("p", "?")])
        events["t"] = rows[:, 2].astype("m8[us]")
        events["x"], events["y"], events["p"] = rows[:, 0], rows[:, 1], rows[:, 3]
        assert torch.equal(binned(events), binned(rows))


class TestColumns:
    def test_t_first_rows(self):
        rows = reference()
        txyp = rows[:, [2, 0, 1, 3]]
        assert torch.equal(binned(txyp, columns="txyp"), binned(rows))
        assert torch.equal(binned(torch.from_numpy(txyp), columns=["t", "x", "y", "p"]), binned(rows))

    def test_skipped_columns(self):
        rows = reference()
        wide = np.concatenate([rows[:, [2]], np.full((len(rows), 1), 7), rows[:, [0, 1, 3]]], axis=1)
        assert torch.equal(binned(wide, columns="t_xyp"), binned(rows))

    def test_batch_and_module(self):
        rows = reference()
        txyp = rows[:, [2, 0, 1, 3]]
        assert torch.equal(et.EventsToFrames(SENSOR, columns="txyp")(txyp), binned(rows))
        batch = EventBatch.from_streams([txyp], sensor_size=SENSOR, columns="txyp")
        assert torch.equal(batch.t, torch.from_numpy(rows[:, 2]))

    def test_five_columns_without_names_are_refused(self):
        with pytest.raises(ValueError, match="columns="):
            binned(np.zeros((3, 5)))

    @pytest.mark.parametrize("bad", ["txy", "txyy", "txypq", 5, "tx_p"])
    def test_bad_columns(self, bad):
        with pytest.raises(ValueError, match="columns"):
            binned(reference(), columns=bad)

    def test_columns_for_a_mapping_are_refused(self):
        rows = reference()
        with pytest.raises(ValueError, match="read by name"):
            binned({"x": rows[:, 0], "y": rows[:, 1], "t": rows[:, 2], "p": rows[:, 3]}, columns="xytp")


class TestDataFrames:
    def test_pandas(self):
        pd = pytest.importorskip("pandas")
        rows = reference()
        frame = pd.DataFrame({"t": pd.to_timedelta(rows[:, 2], unit="us"), "x": rows[:, 0], "y": rows[:, 1],
                              "polarity": rows[:, 3].astype(bool), "extra": 1.5})
        assert torch.equal(binned(frame), binned(rows))
        plain = pd.DataFrame({"x": rows[:, 0], "y": rows[:, 1], "t": rows[:, 2], "p": rows[:, 3]})
        assert torch.equal(binned(plain), binned(rows))
        with pytest.raises(ValueError, match="missing p"):
            binned(plain.drop(columns="p"))

    def test_polars_with_a_duration_column(self):
        pl = pytest.importorskip("polars")
        rows = reference()
        frame = pl.DataFrame({"x": rows[:, 0].astype(np.int16), "y": rows[:, 1].astype(np.int16),
                              "t": pl.Series(rows[:, 2]).cast(pl.Duration("us")), "p": rows[:, 3].astype(np.int8)})
        assert torch.equal(binned(frame), binned(rows))
        assert torch.equal(EventBatch.from_streams([frame], sensor_size=SENSOR).t, torch.from_numpy(rows[:, 2]))


class TestFiles:
    """Synthetic files in the layouts the readers of the field write."""

    def test_hdf5_group_of_columns(self, tmp_path):
        h5py = pytest.importorskip("h5py")
        rows = reference()
        with h5py.File(tmp_path / "events.h5", "w") as f:  # DSEC's events/{x, y, t, p}, t in us
            group = f.create_group("events")
            for k, name in enumerate("xytp"):
                group.create_dataset(name, data=rows[:, k])
        with h5py.File(tmp_path / "events.h5", "r") as f:
            assert torch.equal(binned(f["events"]), binned(rows))

    def test_hdf5_float_seconds(self, tmp_path):
        h5py = pytest.importorskip("h5py")
        rows = reference(t0=0)
        with h5py.File(tmp_path / "seconds.h5", "w") as f:  # evlib-style: float64 seconds
            for k, name in enumerate("xytp"):
                f.create_dataset(name, data=rows[:, k] / 1e6 if name == "t" else rows[:, k])
        with h5py.File(tmp_path / "seconds.h5", "r") as f:
            with pytest.raises(ValueError, match="seconds"):
                binned(f)
            assert torch.equal(binned(f, time_unit="s"), binned(rows))

    def test_aedat4_written_by_faery_read_by_aedat_and_faery(self, tmp_path):
        faery = pytest.importorskip("faery")
        rows = reference()
        events = np.zeros(len(rows), dtype=faery.EVENTS_DTYPE)
        events["t"], events["x"], events["y"], events["p"] = rows[:, 2], rows[:, 0], rows[:, 1], rows[:, 3]
        path = tmp_path / "recording.aedat4"
        faery.events_stream_from_array(events, dimensions=(SENSOR[1], SENSOR[0])).to_file(path, zero_t0=False)
        expected = binned(rows)
        assert torch.equal(binned(faery.events_stream_from_file(path).to_array()), expected)
        aedat = pytest.importorskip("aedat")
        packets = [p["events"] for p in aedat.Decoder(path) if "events" in p]
        assert torch.equal(torch.stack(list(iter_frames(packets, sensor_size=SENSOR))), expected)


class TestNumpyFrames:
    """tonic's ToFrame and DiskCachedDataset hand over numpy frames."""

    def frames(self) -> np.ndarray:
        return np.random.default_rng(0).poisson(1.0, (3, 2, 6, 8)).astype(np.int16)  # ToFrame's dtype

    def test_transform_and_compose_take_numpy(self):
        frames = self.frames()
        before = frames.copy()
        tensor = torch.from_numpy(frames.copy())
        flip = et.HorizontalFlip()
        assert torch.equal(flip(frames), flip(tensor))
        pipeline = et.Compose([et.HorizontalFlip(), et.RandomRotation(30)])
        assert torch.equal(pipeline(frames, generator=torch.Generator().manual_seed(1)),
                           pipeline(tensor, generator=torch.Generator().manual_seed(1)))
        assert np.array_equal(frames, before)  # never written

    def test_compose_with_from_numpy_member(self):
        frames = self.frames()
        pipeline = et.Compose([torch.from_numpy, et.HorizontalFlip()])
        assert torch.equal(pipeline(frames), et.HorizontalFlip()(torch.from_numpy(frames)))

    def test_read_only_memory_map(self, tmp_path):
        np.save(tmp_path / "sample.npy", self.frames())
        cached = np.load(tmp_path / "sample.npy", mmap_mode="r")  # as DiskCachedDataset reads it back
        out = et.HorizontalFlip()(cached)
        assert isinstance(out, torch.Tensor) and torch.equal(out, torch.from_numpy(self.frames()).flip(-1))

    def test_dict_and_labels(self):
        frames = self.frames()
        out, label = et.HorizontalFlip()({"frames": frames}, 3)
        assert torch.equal(out["frames"], torch.from_numpy(frames).flip(-1)) and label == 3

    @pytest.mark.parametrize("dtype", [np.uint16, np.complex64, object])
    def test_other_dtypes_are_refused_by_name(self, dtype):
        with pytest.raises(TypeError, match="frames as a numpy array"):
            et.HorizontalFlip()(np.zeros((1, 2, 2, 2), dtype=dtype))
