"""Peak memory of binning large recordings: 10^6 against 10^8 events.

Each measurement runs in a fresh Python process, so its peak resident set (``VmHWM``; not
``ru_maxrss``, which inherits the parent's high-water mark) is that measurement's alone; a thread also samples the anonymous part
(``RssAnon``: heap and tensors, not pages of a mapped file) every 2 ms. The events are
never all in memory: they come from

* a generator of 2**20-event chunks (a DVXplorer-sized 240×320 sensor, tonic's aedat4
  dtype ``[('t', '<u8'), ('x', '<u2'), ('y', '<u2'), (('p', 'on'), '?')]``, absolute
  timestamps from 1.7e15 µs, 1 M events per second, sorted) fed to
  :func:`~event_transforms.functional.iter_frames`, which yields one 10 ms frame at a time;
* the same events written to a ``.npy`` file and opened with ``np.load(mmap_mode="r")``,
  binned by :func:`~event_transforms.functional.events_to_frames` into 100 frames (the
  bin width is the recording's length / 100). Pages of the mapped file count in the
  resident set while read (the page cache, given back under memory pressure), so the
  table shows the anonymous peak beside it.

The baseline, in the same run, is ``events_to_frames`` converting the whole input at
once (``chunk_size`` = N, what it did before chunking), on in-memory arrays of 10^6 and
10^7 events; 10^8 events would need about 10 GB that way. Memory figures are MiB above a
process that only imported torch and the package.

    python benchmarks/library/events.py [--quick] [--threads 1] [--no-write]
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from benchmarks._common import child_env, apply_threads, base_parser, command, environment_lines, markdown_table, publish

AEDAT4 = np.dtype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])
SENSOR = (240, 320)
CHUNK = 2**20
START_US = 1_700_000_000_000_000
RATE_PER_US = 1.0  # 1 M events per second


def chunks(n_events: int, seed: int = 0) -> Iterator[np.ndarray]:
    """``n_events`` sorted events in chunks of ``CHUNK``, made on the fly."""
    rng = np.random.default_rng(seed)
    for first in range(0, n_events, CHUNK):
        n = min(CHUNK, n_events - first)
        span = int(n / RATE_PER_US)
        events = np.empty(n, dtype=AEDAT4)
        events["t"] = START_US + int(first / RATE_PER_US) + np.sort(rng.integers(0, span, n))
        events["x"] = rng.integers(0, SENSOR[1], n)
        events["y"] = rng.integers(0, SENSOR[0], n)
        events["p"] = rng.random(n) < 0.5
        yield events


def write_file(path: Path, n_events: int) -> None:
    out = np.lib.format.open_memmap(path, mode="w+", dtype=AEDAT4, shape=(n_events,))
    for first, chunk in zip(range(0, n_events, CHUNK), chunks(n_events)):
        out[first : first + len(chunk)] = chunk
    out.flush()
    del out


def _status_kib(field: str) -> int:
    """A ``/proc/self/status`` field in KiB (``VmHWM``: this process's peak RSS, reset by exec)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


class _Sampler(threading.Thread):
    """Peak ``RssAnon`` (KiB), sampled every 2 ms."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.peak = 0
        self.done = threading.Event()

    @staticmethod
    def anon_kib() -> int:
        return _status_kib("RssAnon")

    def run(self) -> None:
        while not self.done.is_set():
            self.peak = max(self.peak, self.anon_kib())
            time.sleep(0.002)


def child(mode: str, n_events: int, path: str, threads: int | None) -> dict[str, float]:
    """One measurement, in this (fresh) process."""
    apply_threads(threads)
    import torch

    from event_transforms.functional import events_to_frames, iter_frames

    sampler = _Sampler()
    sampler.peak = sampler.anon_kib()
    sampler.start()
    start = time.perf_counter()
    total = 0
    frames = 0
    if mode == "stream":
        for frame in iter_frames(chunks(n_events), sensor_size=SENSOR):
            total += int(frame.sum())
            frames += 1
    elif mode == "mmap":
        events = np.load(path, mmap_mode="r")
        frame_ms = n_events / RATE_PER_US / 1000 / 100
        out = events_to_frames(events, sensor_size=SENSOR, t_start=START_US, frame_ms=frame_ms, n_frames=100)
        total, frames = int(out.sum()), out.shape[0]
    elif mode == "whole":
        events = np.concatenate(list(chunks(n_events)))
        sampler.peak = sampler.anon_kib()  # the input is not the subject
        start = time.perf_counter()
        frame_ms = n_events / RATE_PER_US / 1000 / 100
        out = events_to_frames(
            events, sensor_size=SENSOR, t_start=START_US, frame_ms=frame_ms, n_frames=100, chunk_size=n_events
        )
        total, frames = int(out.sum()), out.shape[0]
        input_kib = events.nbytes / 1024
    elif mode != "import":
        raise ValueError(f"mode must be import, stream, mmap or whole, got {mode!r}")
    seconds = time.perf_counter() - start
    sampler.done.set()
    sampler.join()
    result = {
        # not ru_maxrss: Linux carries the parent's high-water mark into it across fork and exec
        "peak_rss_kib": _status_kib("VmHWM"),
        "peak_anon_kib": sampler.peak,
        "seconds": seconds,
        "events_binned": total,
        "frames": frames,
        "torch": torch.__version__,
    }
    if mode == "whole":
        result["input_kib"] = input_kib
    return result


#: glibc's fixed mmap threshold: without it, each large free raises the threshold and later
#: chunks come from a heap that fragments, so the peak creeps up with the number of chunks.
FIXED_MMAP = {"MALLOC_MMAP_THRESHOLD_": str(2**20)}


def measure(mode: str, n_events: int, path: str, threads: int | None, env: dict[str, str] | None = None) -> dict:
    argv = [sys.executable, __file__, "--child", mode, str(n_events), path]
    if threads is not None:
        argv += ["--threads", str(threads)]
    done = subprocess.run(argv, check=True, capture_output=True, text=True, env=child_env(env))
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> dict[str, object] | None:
    parser = base_parser(__doc__.splitlines()[0], "events")
    parser.add_argument("--child", nargs=3, metavar=("MODE", "N", "PATH"), help=argparse_hidden())
    args = parser.parse_args(argv)
    if args.child:
        mode, n, path = args.child
        print(json.dumps(child(mode, int(n), path, args.threads)))
        return
    apply_threads(args.threads)
    sizes = (10**4, 10**5, 3 * 10**5) if args.quick else (10**6, 10**7, 10**8)
    whole_large = 10**5 if args.quick else 10**7
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = measure("import", 0, "", args.threads)
        base_rss, base_anon = base["peak_rss_kib"], base["peak_anon_kib"]
        fixed = measure("import", 0, "", args.threads, FIXED_MMAP)

        def row(label: str, n: int, result: dict[str, float], note: str = "", base: dict | None = None) -> None:
            if result["events_binned"] != n:
                raise RuntimeError(f"{label}: binned {result['events_binned']} of {n} events")
            rss, anon = (base_rss, base_anon) if base is None else (base["peak_rss_kib"], base["peak_anon_kib"])
            rows.append([
                label, f"{n:.0e}".replace("e+0", "e"), f"{(result['peak_rss_kib'] - rss) / 1024:,.0f}",
                f"{(result['peak_anon_kib'] - anon) / 1024:,.0f}",
                f"{n / result['seconds'] / 1e6:.1f}", note,
            ])

        for n in sizes:
            print(f"iter_frames, {n} events", file=sys.stderr, flush=True)
            result = measure("stream", n, "", args.threads)
            row("iter_frames, generator of 2^20-event chunks", n, result, f"{result['frames']:,} frames of 10 ms")
        for n in sizes[1:]:
            print(f"iter_frames, {n} events, fixed mmap threshold", file=sys.stderr, flush=True)
            result = measure("stream", n, "", args.threads, FIXED_MMAP)
            row("iter_frames, same, MALLOC_MMAP_THRESHOLD_=1 MiB", n, result, f"{result['frames']:,} frames of 10 ms",
                base=fixed)
        for n in sizes:
            path = Path(tmp) / f"events_{n}.npy"
            print(f"events_to_frames on a memory-mapped file, {n} events", file=sys.stderr, flush=True)
            write_file(path, n)
            result = measure("mmap", n, str(path), args.threads)
            row("events_to_frames, memory-mapped .npy (chunk 2^20)", n, result, "100 frames; file pages in RSS")
            path.unlink()
        for n in (sizes[0], whole_large):
            print(f"baseline: whole input at once, {n} events", file=sys.stderr, flush=True)
            result = measure("whole", n, "", args.threads)
            row("baseline: events_to_frames, chunk_size = N (in memory)", n, result,
                f"100 frames; input itself {result['input_kib'] / 1024:,.0f} MiB not counted in anon")
    table = markdown_table(
        ["path", "events", "peak RSS (MiB over import)", "peak anon (MiB over import)", "M events/s", "note"], rows
    )
    body = "\n".join([
        "## Large recordings in bounded memory (events)",
        "",
        f"Command: `{command('library/events.py', argv)}`",
        "",
        *environment_lines(),
        "",
        f"Process after importing torch and the package: {base_rss / 1024:,.0f} MiB peak RSS. Sensor 240×320, "
        "tonic's aedat4 dtype, absolute timestamps from 1.7e15 µs, 1 M events/s, sorted.",
        "",
        table,
        "",
        "Peak RSS is the process's high-water mark (`VmHWM`); peak anon samples `RssAnon` every 2 ms "
        "(heap and tensors, without pages of a mapped file). Events per second from one run, for scale only. "
        "With glibc's default allocator settings the peak of `iter_frames` creeps up with the number of chunks "
        "(each large free raises glibc's mmap threshold, and later chunks come from a heap that fragments); "
        "with the threshold fixed it is the same for 10^7 and 10^8 events, so nothing accumulates.",
    ])
    publish(body, args)
    return {"rows": rows, "import_rss_kib": base_rss}


def argparse_hidden() -> str:
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    main()
