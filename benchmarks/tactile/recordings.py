"""Own recordings: the protocol on an exported scene against the built-in scene, and RecordingSet
on a folder of at least 1 GB of events (time and peak memory, from ``/usr/bin/time -v``).

``python benchmarks/tactile/recordings.py protocol --scene paper`` exports the scene into a temporary
folder and runs, each in a fresh process under ``/usr/bin/time -v``, ``reproduce --data`` and
``reproduce --scenes`` with the same reduced configuration (``--seeds 0-1 --steps 50 --methods
none stretch --jobs 1 --no-budget-check --no-plots``), first with empty caches (binning or
simulating included), then again with the caches warm (``--out`` emptied so the units are
trained again); it checks that the per-seed test MSEs agree.

``python benchmarks/tactile/recordings.py large --gigabytes 1.0`` writes synthetic ``.npy`` recordings
(100 s each, 100,000 events per second: background noise and a contact strip whose rate
follows a 1 kHz force) into a temporary folder until they hold the asked bytes, then builds
``RecordingSet`` on them in a fresh process (cold cache: hashing, scanning, binning) and again
(warm cache), reporting wall time and peak resident memory of each.

Both print one markdown table; the machine is shared, so absolute figures are noisy.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "MALLOC_MMAP_THRESHOLD_": "1073741824",
       "MALLOC_TRIM_THRESHOLD_": "1073741824"}
REDUCED = ["--seeds", "0-1", "--steps", "50", "--methods", "none", "stretch", "--jobs", "1", "--threads", "1",
           "--no-budget-check", "--no-plots"]


def timed(command: list[str], env: dict[str, str]) -> dict[str, float]:
    """Run ``command`` under /usr/bin/time -v: wall seconds and peak RSS (MiB)."""
    start = time.perf_counter()
    done = subprocess.run(["/usr/bin/time", "-v", *command], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{' '.join(command)} failed:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}")
    peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", done.stderr).group(1)) / 1024
    return {"wall_s": wall, "peak_mib": peak, "stdout": done.stdout}


def protocol(args: argparse.Namespace) -> None:
    work = Path(tempfile.mkdtemp(prefix="recordings-bench-"))
    cli = [sys.executable, "-m", "event_transforms.tactile.cli"]
    env = {**ENV, "EVENT_TRANSFORMS_CACHE": str(work / "cache")}
    export = work / "export"
    made = timed([*cli, "simulate", "--export", str(export), "--scene", args.scene], env)
    rows = [("simulate --export", "—", made)]
    for phase in ("cold", "warm"):
        if phase == "cold":
            shutil.rmtree(work / "cache", ignore_errors=True)
        for label, source in (("reproduce --data", ["--data", str(export)]), ("reproduce --scenes", ["--scenes", args.scene])):
            out = work / f"out-{label.split()[1]}"
            shutil.rmtree(out, ignore_errors=True)
            rows.append((label, phase, timed([*cli, "reproduce", *source, *REDUCED, "--out", str(out)], env)))
    ours = json.loads((work / "out---data" / "results.json").read_text())["scenes"]
    theirs = json.loads((work / "out---scenes" / "results.json").read_text())["scenes"][args.scene]
    (ours,) = ours.values()
    agree = all(ours["methods"][m]["test_mse"] == theirs["methods"][m]["test_mse"] for m in theirs["methods"])
    print(f"scene {args.scene}, reduced configuration {' '.join(REDUCED)}; one process per row, /usr/bin/time -v")
    print("| command | caches | wall s | peak RSS MiB |\n|---|---|---|---|")
    for label, phase, result in rows:
        print(f"| {label} | {phase} | {result['wall_s']:.1f} | {result['peak_mib']:.0f} |")
    print(f"per-seed test MSEs identical: {agree}")
    shutil.rmtree(work, ignore_errors=True)


def write_large(folder: Path, gigabytes: float, seconds: float = 100.0, rate: float = 1e5) -> int:
    import numpy as np

    dtype = np.dtype([("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
    per_file = int(seconds * rate)
    files = max(2, -(-int(gigabytes * 2**30) // (per_file * dtype.itemsize)))
    rows = ["events,force,role,diameter_mm"]
    for k in range(files):
        rng = np.random.default_rng(k)
        t = np.sort(rng.integers(0, int(seconds * 1e6), per_file)) + 1_700_000_000_000_000
        events = np.empty(per_file, dtype=dtype)
        events["t"] = t
        strip = rng.random(per_file) < 0.7
        events["x"] = np.where(strip, rng.integers(60, 180, per_file), rng.integers(0, 240, per_file))
        events["y"] = np.where(strip, rng.integers(80, 100, per_file), rng.integers(0, 180, per_file))
        events["p"] = rng.integers(0, 2, per_file)
        np.save(folder / f"r{k}.npy", events)
        t_force = np.arange(t[0] - t[0] % 1000, t[-1] + 1000, 1000)
        force = 10 + 5 * np.sin(np.arange(t_force.size) / 300.0)
        np.savetxt(folder / f"f{k}.csv", np.c_[t_force, force], delimiter=",", header="t_us,force_n",
                   comments="", fmt=["%d", "%.4f"])
        role = "train" if k < files - 2 else "deploy"
        rows.append(f"r{k}.npy,f{k}.csv,{role},15")
    (folder / "recordings.csv").write_text("\n".join(rows) + "\n")
    return sum(p.stat().st_size for p in folder.glob("*.npy"))


def large(args: argparse.Namespace) -> None:
    work = Path(tempfile.mkdtemp(prefix="recordings-large-"))
    folder = work / "data"
    folder.mkdir()
    tick = time.perf_counter()
    size = write_large(folder, args.gigabytes)
    made = time.perf_counter() - tick
    code = (f"import time; from event_transforms.tactile.recordings import RecordingSet; t = time.perf_counter(); "
            f"d = RecordingSet({str(folder)!r}, cache={str(work / 'cache')!r}); "
            "print(len(d), d.crop, d.crop_source, round(time.perf_counter() - t, 1))")
    cold = timed([sys.executable, "-c", code], ENV)
    warm = timed([sys.executable, "-c", code], ENV)
    print(f"{len(list(folder.glob('*.npy')))} .npy files, {size / 2**30:.2f} GiB of events "
          f"({size // 13:,} events of 13 bytes), written in {made:.0f} s; RecordingSet(folder) in a fresh process:")
    print("| cache | wall s | peak RSS MiB | windows, crop |\n|---|---|---|---|")
    for label, result in (("cold (hash, scan, bin)", cold), ("warm", warm)):
        print(f"| {label} | {result['wall_s']:.1f} | {result['peak_mib']:.0f} | {result['stdout'].strip()} |")
    shutil.rmtree(work, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("protocol")
    p.add_argument("--scene", default="paper")
    q = sub.add_parser("large")
    q.add_argument("--gigabytes", type=float, default=1.0)
    args = parser.parse_args()
    {"protocol": protocol, "large": large}[args.what](args)


if __name__ == "__main__":
    main()
