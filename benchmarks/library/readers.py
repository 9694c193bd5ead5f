"""Reading speed and memory of every event-file format (``event_transforms.events.io``).

``python benchmarks/library/readers.py --events 10000000`` writes one synthetic recording (random
pixels on a 260 × 346 sensor, sorted microsecond timestamps at 1e6 events/s, random polarity)
in every format into a temporary folder, then reads each file in a fresh process (cold: nothing
of it cached in Python, one torch/numpy thread) through ``EventFile.chunks()`` (the chunked read
``RecordingSet`` and ``predict`` do), checking the event count and the timestamps' sum. Reported
per format: the file's size, the read's wall time and events per second, the peak resident
memory during the read above the resident memory before it (the peak reset through Linux's
``/proc/self/clear_refs``; memory-mapped pages read count) and the peak of Python-traced
allocations (``tracemalloc``, numpy's buffers included).

The ROS 2 bag (CDR) is deserialised message by message by rosbags (one Python object per event)
and is measured on ``--bag2-events`` events (1e6 by default) and scaled; the ROS 1 bag is read as
packed arrays. The machine is shared, so absolute figures are noisy; the page cache is not
dropped (the files were just written), so "cold" is the process, not the disk.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import base_parser, command, environment_lines, publish

__all__ = ["synthetic", "write", "measure", "main"]

SENSOR = (260, 346)
FORMATS = ("npy", "npy-rows", "npz", "csv", "h5", "h5-rows", "aedat4", "dat", "raw", "bag1", "bag2")


def synthetic(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    events = np.zeros(n, dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("p", "u1")])
    events["t"] = np.sort(rng.integers(0, n, n))  # 1e6 events per second
    events["x"], events["y"] = rng.integers(0, SENSOR[1], n), rng.integers(0, SENSOR[0], n)
    events["p"] = rng.integers(0, 2, n)
    return events


def write(kind: str, events: np.ndarray, folder: Path) -> Path:
    """``events`` written as ``kind``; the path."""
    rows = np.stack([events[c].astype(np.int64) for c in "xytp"], axis=1)
    if kind == "npy":
        path = folder / "e.npy"
        np.save(path, events)
    elif kind == "npy-rows":
        path = folder / "rows.npy"
        np.save(path, rows)
    elif kind == "npz":
        path = folder / "e.npz"
        np.savez(path, **{c: events[c] for c in "xytp"})
    elif kind == "csv":
        path = folder / "e.csv"
        with open(path, "w") as handle:
            handle.write("x,y,t,p\n")
            for start in range(0, len(rows), 1_000_000):
                np.savetxt(handle, rows[start:start + 1_000_000], fmt="%d", delimiter=",")
    elif kind in ("h5", "h5-rows"):
        import h5py

        path = folder / f"{kind}.h5"
        with h5py.File(path, "w") as f:
            f["events"] = events if kind == "h5" else rows
            f.attrs["width"], f.attrs["height"] = SENSOR[1], SENSOR[0]
    elif kind == "aedat4":
        from event_transforms._fixtures import write_aedat4

        path = folder / "e.aedat4"
        write_aedat4(path, events, SENSOR)
    elif kind == "dat":
        path = folder / "e.dat"
        data = (events["x"].astype(np.uint32) | events["y"].astype(np.uint32) << 14
                | events["p"].astype(np.uint32) << 28)
        records = np.zeros(len(events), dtype=[("t", "<u4"), ("data", "<u4")])
        records["t"], records["data"] = events["t"], data
        with open(path, "wb") as handle:
            handle.write(f"% Version 2\n% Width {SENSOR[1]}\n% Height {SENSOR[0]}\n".encode() + bytes([0x0C, 8]))
            handle.write(records.tobytes())
    elif kind == "raw":  # EVT 3.0, written by faery (a test dependency)
        import faery

        path = folder / "e.raw"
        packed = np.zeros(len(events), dtype=faery.EVENTS_DTYPE)
        packed["t"], packed["x"], packed["y"], packed["p"] = events["t"], events["x"], events["y"], events["p"] > 0
        faery.events_stream_from_array(packed, dimensions=(SENSOR[1], SENSOR[0])).to_file(path, version="evt3",
                                                                                         zero_t0=False)
    elif kind == "bag1":
        path = folder / "e.bag"
        write_bag1(path, events)
    elif kind == "bag2":
        from event_transforms._fixtures import write_bag

        path = folder / "e2"
        write_bag(path, events, SENSOR, np.zeros(0), np.zeros((0, 3)), ros2=True, per_message=10_000)
    else:
        raise ValueError(f"unknown format {kind!r}")
    return path


def write_bag1(path: Path, events: np.ndarray, per_message: int = 10_000) -> None:
    """A ROS 1 bag of dvs_msgs/EventArray messages, serialised with numpy (the packed layout)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from event_transforms.events.bags import _ROS1_EVENT, EVENT_MESSAGES

    store = get_typestore(Stores.ROS1_NOETIC)
    event_type, event_msg, array_msg = EVENT_MESSAGES["dvs_msgs/msg/EventArray"]
    store.register({**get_types_from_msg(event_msg, event_type),
                    **get_types_from_msg(array_msg, "dvs_msgs/msg/EventArray")})
    with Writer(path) as writer:
        connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
        for k, start in enumerate(range(0, len(events), per_message)):
            part = events[start:start + per_message]
            records = np.zeros(len(part), dtype=_ROS1_EVENT)
            records["x"], records["y"], records["p"] = part["x"], part["y"], part["p"]
            records["sec"], records["nsec"] = part["t"] // 1_000_000, part["t"] % 1_000_000 * 1000
            last = int(part["t"][-1])
            head = np.array([k, last // 1_000_000, last % 1_000_000 * 1000, 3], dtype="<u4").tobytes() + b"cam"
            body = np.array([SENSOR[0], SENSOR[1], len(part)], dtype="<u4").tobytes() + records.tobytes()
            writer.write(connection, last * 1000, head + body)


def _status(field: str) -> int:
    """A ``/proc/self/status`` field in kB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


def _reset_peak_rss() -> int | None:
    """Reset the process's peak RSS (Linux ``clear_refs``) and return the current RSS in kB, or
    ``None`` where the peak cannot be reset (the imports' peak then counts)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return _status("VmRSS")
    except OSError:
        return None


def measure(kind: str, path: str, n: int) -> dict[str, float]:
    """Read ``path`` in this process (one thread); time, events/s, memory."""
    import resource
    import tracemalloc

    import torch

    torch.set_num_threads(1)
    from event_transforms.events.io import EventFile, read_bag_events

    base_kb = _reset_peak_rss()
    tracemalloc.start()
    tick = time.perf_counter()
    if kind.startswith("bag"):
        columns, _ = read_bag_events(path, "/dvs/events")
        count, total = len(columns["t"]), int((columns["t"] // 1000).sum())
    else:
        count, total = 0, 0
        for chunk in EventFile(path).chunks():
            count += len(chunk["t"])
            total += int(chunk["t"].astype(np.int64).sum())
    seconds = time.perf_counter() - tick
    traced = tracemalloc.get_traced_memory()[1]
    peak_kb = _status("VmHWM") if base_kb is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    base_kb = base_kb if base_kb is not None else 0
    assert count == n, (kind, count, n)
    return {"seconds": seconds, "events_per_s": count / seconds, "rss_mb": (peak_kb - base_kb) / 1024,
            "traced_mb": traced / 2**20, "total": total}


def main(argv: list[str] | None = None) -> str:
    parser = base_parser(__doc__.splitlines()[0], "readers")
    parser.add_argument("--events", type=int, default=10_000_000)
    parser.add_argument("--bag2-events", type=int, default=1_000_000)
    parser.add_argument("--formats", nargs="+", default=list(FORMATS), choices=FORMATS)
    parser.add_argument("--measure", nargs=3, metavar=("KIND", "PATH", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.measure:
        kind, path, n = args.measure
        line = json.dumps(measure(kind, path, int(n)))
        print(line)
        return line
    if args.quick:
        args.events, args.bag2_events = 20_000, 2_000
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")])}
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for kind in args.formats:
            n = args.bag2_events if kind == "bag2" else args.events
            events = synthetic(n)
            path = write(kind, events, Path(folder))
            del events
            size = sum(p.stat().st_size for p in ([path] if path.is_file() else path.rglob("*")) if p.is_file())
            out = subprocess.run([sys.executable, __file__, "--measure", kind, str(path), str(n)], env=env,
                                 capture_output=True, text=True, check=True)
            result = json.loads(out.stdout.strip().splitlines()[-1])
            note = f" ({n:,} events)" if n != args.events else ""
            rows.append(f"| {kind}{note} | {size / 2**20:.0f} | {result['seconds']:.2f} | "
                        f"{result['events_per_s']:.3g} | {result['rss_mb']:.0f} | {result['traced_mb']:.0f} |")
            print(rows[-1], flush=True)
            for p in sorted(Path(folder).iterdir()):
                if p.is_file():
                    p.unlink()
    body = "\n".join([
        f"## Reading recordings: {args.events:,} events per format, one thread, a fresh process each",
        "", *environment_lines(), "", f"Command: `{command('library/readers.py', argv)}`", "",
        "| format | file MB | read s | events/s | peak RSS during the read MB | traced peak MB |",
        "|---|---|---|---|---|---|", *rows])
    publish(body, args)
    return body


if __name__ == "__main__":
    main()
