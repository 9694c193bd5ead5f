"""Every speed goal in one run: eager and compiled side by side, op counts, met or missed.

Data: 32 simulated grasps (:func:`benchmarks.library.events_pipeline.grasp_streams`, 1.3 M events) as an
``EventBatch`` with a 10 ms grid of 36 bins, binned (crop 140×150, pool 2) to the
``(32, 36, 2, 70, 75)`` float32 batch that the frame rows start from; the gating rows use 32
uniform streams of 40k events (:func:`streams`); the per-stream row 10⁵
sorted events on a 240×320 sensor (:func:`benchmarks.library.binning.stream`). Every row is timed in
the same interleaved rounds as ``frames.clone()`` of the frame batch (the baseline), each
round once eager and once with ``et.compiled_kernels()`` for the rows whose kernels compile
(binning on an EventBatch, the affine warp); '× clone' is the median over rounds of the ratio
to the clone of the same round. Ops are top-level aten calls of one eager call
(:func:`event_transforms._profiling.count_ops`). Goals with a tonic peer use tonic when it is installed,
else a numpy re-implementation of the same per-stream steps (tonic's ``ToFrame``: slice the
stream per time window, ``np.add.at`` per slice; named in the table).

``--profile`` adds, per missed goal, the top aten ops by self CPU time (torch.profiler), eager
and compiled. ``--ref GITREV`` also times every row on an older commit (a ``git worktree`` in a
temporary folder; a child process per tree, one round each, the two trees alternating) and
prints before/after ratios; rows the old commit cannot run read "n/a". ``--quick``: 4 grasps,
one round, short timings (a smoke run; ~1 min).

    MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 OMP_NUM_THREADS=1 \\
        python -m benchmarks.library.speed_goals --threads 1 [--quick] [--profile] [--ref 4182d62] [--no-write]
"""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils import benchmark as tbench

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run as a script, or in a child with another tree first on the path
    sys.path.append(str(ROOT))

import event_transforms as et  # noqa: E402

SENSOR = (180, 240)
CROP = (20, 45, 140, 150)
N_FRAMES = 36
CLONE = "frames.clone() (baseline)"


@dataclass(frozen=True)
class Goal:
    """A goal: ``kind`` "clone" (× clone ≤ limit), "peer" (peer time / ours ≥ limit) or
    "ratio" (ours / ``peer`` ≤ limit); ``ops`` an op-count limit or None."""

    row: str
    kind: str
    limit: float | None
    peer: str | None = None
    ops: int | None = None
    text: str = ""


GOALS = [
    Goal("events_to_frames per stream, 1e5 events", "peer", 3.0, "tonic ToFrame per stream, 1e5 events",
         text="≥ 3× faster than tonic ToFrame"),
    Goal("EventsToFrames(EventBatch) (binning only)", "clone", 3.5, text="≤ 3.5× clone"),
    Goal("RandomRotation(180°) on events + binning", "clone", 4.5, text="≤ 4.5× clone"),
    Goal("TES-2(0.5) exact on events + binning", "clone", 8.0, text="≤ 8× clone"),
    Goal("FrameShift(-1) on events", "clone", 4.0, text="≤ 4× clone"),
    Goal("jitter + time jitter + drop + binning (EventBatch)", "peer", 5.0, "tonic-style Compose per stream",
         text="≥ 5× faster than tonic"),
    Goal("RandomHorizontalFlip(p=1) on frames", "clone", 1.5, text="≤ 1.5× clone"),
    Goal("RandomRotation(30°) on frames", "ratio", 1.2, "bare batched affine_grid + grid_sample",
         text="≤ 1.2× a bare grid_sample"),
    Goal("AddPoissonNoise(1-10 Hz) on frames", "clone", 3.0, ops=30, text="≤ 30 ops, ≤ 3× clone"),
    Goal("TES-2(0.5) binomial on frames", "clone", 3.0, ops=40, text="≤ 40 ops, ≤ 3× clone"),
    Goal("TES-2(0.5) exact on frames", "clone", 6.0, ops=80, text="≤ 80 ops, ≤ 6× clone (item 3: ≤ 200, ≤ 8×)"),
    Goal("OneOf(resize, fs, tes) on frames", "clone", None, text="(545 ops, 9.4× on 4182d62: measured, no limit)"),
    *[Goal(f"{name} gated p=0.5 on {kind}", "ratio", 1.1, f"{name} p=1 on {kind}",
           text="≤ 1.1× the ungated call")
      for name in ("RandomHorizontalFlip", "RandomRotation(30)") for kind in ("events", "frames")],
    Goal("per-sample path: EventsToFrames → OneOf on one grasp", "peer", 60.0, None,
         text="≥ 60 samples/s on 2 workers (estimate: 2 / time per sample)"),
]
#: rows whose kernels have a compiled form (the others run the same code either way)
COMPILED_ROWS = ("EventsToFrames(EventBatch)", "on events + binning", "drop + binning", "RandomRotation(30°) on frames",
                 "RandomRotation(30) gated", "RandomRotation(30) p=1", "per-sample path")


# --------------------------------------------------------------------------- data


def streams(count: int = 32, n: int = 40_000, seed: int = 0) -> list[np.ndarray]:
    """``count`` uniform random streams of ``n`` events (x, y, t, p), t sorted in µs over 360 ms."""
    rng = np.random.default_rng(seed)
    dtype = np.dtype([("x", np.int16), ("y", np.int16), ("t", np.int64), ("p", np.int8)])
    out = []
    for _ in range(count):
        s = np.empty(n, dtype=dtype)
        s["x"] = rng.integers(0, SENSOR[1], n)
        s["y"] = rng.integers(0, SENSOR[0], n)
        s["t"] = np.sort(rng.integers(0, 360_000, n))
        s["p"] = rng.integers(0, 2, n)
        out.append(s)
    return out


def make_data(quick: bool) -> dict[str, Any]:
    """Streams of the grasps, the gating streams and the per-stream stream (numpy, picklable)."""
    from benchmarks.library.binning import stream
    from benchmarks.library.events_pipeline import grasp_streams

    count = 4 if quick else 32
    return {"grasps": grasp_streams(count), "gating": streams(count, 40_000), "single": stream(100_000, (240, 320))}


def _tonic_to_frame() -> tuple[Callable[[np.ndarray, tuple[int, int]], Any], str]:
    """tonic's ToFrame(time_window=10 ms) if installed, else its algorithm in numpy."""
    try:
        import tonic.transforms as T

        def with_tonic(events: np.ndarray, sensor: tuple[int, int]) -> Any:
            return T.ToFrame(sensor_size=(sensor[1], sensor[0], 2), time_window=10_000.0)(events)

        return with_tonic, "tonic"
    except ImportError:
        pass

    def numpy_to_frame(events: np.ndarray, sensor: tuple[int, int]) -> np.ndarray:
        t = events["t"]
        starts = np.arange(t[0], t[-1] + 1, 10_000)
        lo, hi = np.searchsorted(t, starts), np.searchsorted(t, starts + 10_000)
        frames = np.zeros((len(starts), 2, *sensor), dtype=np.int16)
        for i, (a, b) in enumerate(zip(lo, hi)):
            piece = events[a:b]
            np.add.at(frames[i], (piece["p"].astype(int), piece["y"], piece["x"]), 1)
        return frames

    return numpy_to_frame, "numpy re-implementation of tonic's ToFrame (tonic not installed)"


def _tonic_jitter(to_frame: Callable[..., Any]) -> Callable[[np.ndarray, np.random.Generator], Any]:
    """tonic's SpatialJitter(σ=1, clip) → TimeJitter(100 µs) → DropEvent(0.1) → ToFrame, per stream."""
    try:
        import tonic.transforms as T

        sensor = (SENSOR[1], SENSOR[0], 2)
        compose = T.Compose([T.SpatialJitter(sensor_size=sensor, var_x=1.0, var_y=1.0, clip_outliers=True),
                             T.TimeJitter(std=100.0, clip_negative=True), T.DropEvent(p=0.1),
                             T.ToFrame(sensor_size=sensor, time_window=10_000.0)])
        return lambda events, rng: compose(events)
    except ImportError:
        pass

    def numpy_jitter(events: np.ndarray, rng: np.random.Generator) -> Any:
        events = events.copy()
        events["x"] = events["x"] + rng.normal(0, 1.0, len(events))
        events["y"] = events["y"] + rng.normal(0, 1.0, len(events))
        keep = (events["x"] >= 0) & (events["x"] < SENSOR[1]) & (events["y"] >= 0) & (events["y"] < SENSOR[0])
        events = events[keep]
        events["t"] = np.clip(events["t"] + rng.normal(0, 100.0, len(events)), 0, None)
        events = events[np.sort(rng.choice(len(events), int(len(events) * 0.9), replace=False))]
        return to_frame(events, SENSOR)

    return numpy_jitter


def build_cases(data: dict[str, Any]) -> tuple[dict[str, Callable[[], Any]], str]:
    """name -> call; and what stood in for tonic. Only APIs the older commits have too."""
    batch = et.EventBatch.from_streams(data["grasps"], sensor_size=SENSOR, frame_ms=10.0, t_start=0, n_frames=N_FRAMES)
    to_frames = et.EventsToFrames(SENSOR, frame_ms=10.0, n_frames=N_FRAMES, crop=CROP, pool=2)
    frames = to_frames(batch)
    g = lambda: torch.Generator().manual_seed(0)  # noqa: E731
    rotation, tes, shift = et.RandomRotation(180.0), et.TemporalEventShift(-2, 0.5), et.FrameShift(-1)
    jitter = et.Compose([et.SpatialJitter(1.0), et.TimeJitter(100.0), et.RandomEventDrop(0.1, methods=("random",)),
                         et.EventsToFrames(SENSOR, frame_ms=10.0, n_frames=N_FRAMES)])
    to_frame, peer = _tonic_to_frame()
    tonic_jitter = _tonic_jitter(to_frame)
    single = data["single"]
    gating = et.EventBatch.from_streams(data["gating"], sensor_size=SENSOR, frame_ms=10.0, t_start=0, n_frames=36)
    rotate30 = et.RandomRotation(30.0)
    theta = torch.tensor([[0.8, -0.6, 0.1], [0.6, 0.8, -0.1]]).expand(frames.shape[0], 2, 3)
    folded = frames.reshape(frames.shape[0], -1, *frames.shape[-2:])
    binomial = et.TemporalEventShift(-2, 0.5, mode="binomial")
    noise = et.AddPoissonNoise((1.0, 10.0))
    one_of = et.OneOf([et.RandomResize((0.8, 1.25)), et.RandomFrameShift((-1, 1)), et.TemporalEventShift(-2, 0.5)])
    sample_stream = data["grasps"][0]
    per_sample = et.Compose([et.EventsToFrames(SENSOR, frame_ms=10.0, n_frames=N_FRAMES, crop=CROP, pool=2), one_of])

    def sample_path() -> Any:
        one = et.EventBatch.from_streams([sample_stream], sensor_size=SENSOR, frame_ms=10.0, t_start=0,
                                         n_frames=N_FRAMES)
        return per_sample(one, generator=g())

    cases: dict[str, Callable[[], Any]] = {
        CLONE: frames.clone,
        "events_to_frames per stream, 1e5 events": lambda: et.functional.events_to_frames(
            single, sensor_size=(240, 320), frame_ms=10.0, t_start="first"),
        "tonic ToFrame per stream, 1e5 events": lambda: to_frame(single, (240, 320)),
        "EventsToFrames(EventBatch) (binning only)": lambda: to_frames(batch),
        "RandomRotation(180°) on events + binning": lambda: to_frames(rotation(batch, generator=g())),
        "TES-2(0.5) exact on events + binning": lambda: to_frames(tes(batch, generator=g())),
        "FrameShift(-1) on events": lambda: shift(batch),
        "jitter + time jitter + drop + binning (EventBatch)": lambda: jitter(batch, generator=g()),
        "tonic-style Compose per stream": lambda: [tonic_jitter(s, np.random.default_rng(0)) for s in data["grasps"]],
        "RandomHorizontalFlip(p=1) on frames": lambda: et.RandomHorizontalFlip(1.0)(frames, generator=g()),
        "RandomRotation(30°) on frames": lambda: rotate30(frames, generator=g()),
        "bare batched affine_grid + grid_sample": lambda: F.grid_sample(
            folded, F.affine_grid(theta, list(folded.shape), align_corners=True), align_corners=True),
        "AddPoissonNoise(1-10 Hz) on frames": lambda: noise(frames, generator=g()),
        "TES-2(0.5) binomial on frames": lambda: binomial(frames, generator=g()),
        "TES-2(0.5) exact on frames": lambda: tes(frames, generator=g()),
        "OneOf(resize, fs, tes) on frames": lambda: one_of(frames, generator=g()),
        "per-sample path: EventsToFrames → OneOf on one grasp": sample_path,
    }
    gated = {"RandomHorizontalFlip": lambda p: et.RandomHorizontalFlip(p), "RandomRotation(30)":
             lambda p: et.RandomRotation(30.0, p=p)}
    for name, make in gated.items():
        for kind, inputs in (("events", gating), ("frames", frames)):
            for p, label in ((1.0, "p=1"), (0.5, "gated p=0.5")):
                module = make(p)
                cases[f"{name} {label} on {kind}"] = lambda m=module, x=inputs: m(x, generator=g())
    return cases, peer


# --------------------------------------------------------------------------- timing


def _compiled(on: bool) -> Any:
    if on and hasattr(et, "compiled_kernels"):
        return et.compiled_kernels()
    return contextlib.nullcontext()


def _has_compiled() -> bool:
    from event_transforms import _compile

    return _compile.unavailable_reason() is None


def time_rounds(cases: dict[str, Callable[[], Any]], rounds: int, min_run_time: float, compiled: bool,
                progress: bool = True) -> dict[str, dict[str, list[float]]]:
    """{mode: {row: [seconds per round]}}, mode "eager" and (``compiled``) "compiled" for the rows
    that compile; every round times the clone first, then each row eager, then compiled."""
    out: dict[str, dict[str, list[float]]] = {"eager": {n: [] for n in cases}, "compiled": {}}
    modes = [False, True] if compiled else [False]
    for on in modes:  # warm up (and compile) once
        for name, fn in cases.items():
            if not on or any(k in name for k in COMPILED_ROWS):
                with _compiled(on):
                    _safe(fn)
    for r in range(rounds):
        for on in modes:
            for name, fn in cases.items():
                if on and not any(k in name for k in COMPILED_ROWS):
                    continue
                with _compiled(on):
                    seconds = _time(fn, min_run_time)
                out["compiled" if on else "eager"].setdefault(name, []).append(seconds)
        if progress:
            print(f"  round {r + 1}/{rounds}", file=sys.stderr, flush=True)
    return out


def _safe(fn: Callable[[], Any]) -> bool:
    try:
        fn()
        return True
    except Exception as error:  # noqa: BLE001 - an older commit may lack a row's API
        print(f"  skipped: {type(error).__name__}: {error}", file=sys.stderr)
        return False


def _time(fn: Callable[[], Any], min_run_time: float) -> float:
    try:
        return tbench.Timer(stmt="fn()", globals={"fn": fn}).blocked_autorange(min_run_time=min_run_time).median
    except Exception:  # noqa: BLE001
        return float("nan")


def _ratio(times: dict[str, list[float]], clone: list[float], name: str) -> float:
    values = [a / b for a, b in zip(times.get(name, []), clone) if a == a]
    return statistics.median(values) if values else float("nan")


def _median(values: list[float]) -> float:
    values = [v for v in values if v == v]
    return statistics.median(values) if values else float("nan")


def op_count(fn: Callable[[], Any]) -> int | str:
    from benchmarks._common import count_ops

    try:
        return count_ops(fn).ops
    except Exception:  # noqa: BLE001
        return "n/a"


# --------------------------------------------------------------------------- goals


def judge(goal: Goal, times: dict[str, dict[str, list[float]]], ops: dict[str, Any], mode: str) -> tuple[str, bool | None]:
    """The measured figure of ``goal`` in ``mode`` and whether it is met (None: no limit)."""
    rows = times[mode] if goal.row in times[mode] else times["eager"]
    eager = times["eager"]
    clone = eager[CLONE]
    if goal.kind == "clone":
        value = _ratio(rows, clone, goal.row)
        met = None if goal.limit is None else value <= goal.limit
        if goal.ops is not None and isinstance(ops.get(goal.row), int):
            met = bool(met) and ops[goal.row] <= goal.ops
        return f"{value:.2f}× clone", met
    if goal.kind == "ratio":
        assert goal.peer is not None
        value = _median([a / b for a, b in zip(rows[goal.row], rows.get(goal.peer, eager[goal.peer]))])
        return f"{value:.2f}×", value <= (goal.limit or 0)
    if goal.peer is None:  # samples per second on 2 workers
        rate = 2.0 / _median(rows[goal.row])
        return f"{rate:.0f} samples/s", rate >= (goal.limit or 0)
    speedup = _median(eager[goal.peer]) / _median(rows[goal.row])
    return f"{speedup:.1f}× faster", speedup >= (goal.limit or 0)


def profile_top(fn: Callable[[], Any], compiled: bool, top: int = 6) -> str:
    """The ``top`` aten ops by self CPU time of one call, as 'name share%' items."""
    from torch.profiler import ProfilerActivity, profile

    with _compiled(compiled):
        fn()
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            fn()
    averages = [e for e in prof.key_averages() if e.self_cpu_time_total > 0]
    total = sum(e.self_cpu_time_total for e in averages) or 1.0
    named = [("compiled graph" if "CompiledFxGraph" in e.key else e.key.replace("aten::", ""), e.self_cpu_time_total)
             for e in averages if e.key.startswith("aten::") or "CompiledFxGraph" in e.key]
    named.sort(key=lambda item: -item[1])
    return ", ".join(f"{name} {100 * share / total:.0f}%" for name, share in named[:top])


# --------------------------------------------------------------------------- --ref


def _child(data_path: str, rounds: int, min_run_time: float) -> None:
    """Child mode: time every row eager on whichever event_transforms is first on the path; JSON out."""
    torch.set_num_threads(1)
    data = torch.load(data_path, weights_only=False)
    cases, _ = build_cases(data)
    working = {name: fn for name, fn in cases.items() if _safe(fn)}
    times = time_rounds(working, rounds, min_run_time, compiled=False, progress=False)
    print(json.dumps({"times": times["eager"], "module": et.__file__}))


def run_ref(ref: str, data: dict[str, Any], rounds: int, min_run_time: float) -> dict[str, dict[str, list[float]]]:
    """Time the rows on ``ref`` and on this tree, alternating child processes (one round each)."""
    out: dict[str, dict[str, list[float]]] = {"ref": {}, "this": {}}
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "ref"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), ref], check=True,
                       capture_output=True)
        try:
            data_path = str(Path(tmp) / "data.pt")
            torch.save(data, data_path)
            for r in range(rounds):
                for label, path in (("ref", tree), ("this", ROOT)):
                    env = {**os.environ, "PYTHONPATH": str(path), "OMP_NUM_THREADS": "1"}
                    result = subprocess.run(
                        [sys.executable, str(Path(__file__).resolve()), "--child", data_path, "--child-rounds", "1",
                         "--child-min-run-time", str(min_run_time)],
                        env=env, cwd=str(path), capture_output=True, text=True, check=True)
                    payload = json.loads(result.stdout.strip().splitlines()[-1])
                    for name, values in payload["times"].items():
                        out[label].setdefault(name, []).extend(values)
                print(f"  --ref round {r + 1}/{rounds}", file=sys.stderr, flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], capture_output=True)
    return out


# --------------------------------------------------------------------------- main


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    from benchmarks._common import (
        allocator_suffix, apply_threads, base_parser, command, environment_lines, fmt_ms, markdown_table, publish,
    )

    parser = base_parser(__doc__.splitlines()[0], "speed-goals")
    parser.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 5, 1 with --quick)")
    parser.add_argument("--profile", action="store_true", help="top ops of each missed goal, eager and compiled")
    parser.add_argument("--ref", default=None, help="also time the rows on this git revision (before/after)")
    parser.add_argument("--child", default=None, help=argparse_suppress())
    parser.add_argument("--child-rounds", type=int, default=1, help=argparse_suppress())
    parser.add_argument("--child-min-run-time", type=float, default=0.2, help=argparse_suppress())
    args = parser.parse_args(argv)
    if args.child:
        _child(args.child, args.child_rounds, args.child_min_run_time)
        return {}
    apply_threads(args.threads)
    rounds = args.rounds or (1 if args.quick else 5)
    min_run_time = 0.02 if args.quick else 0.2
    data = make_data(args.quick)
    cases, peer = build_cases(data)
    compiled = _has_compiled()
    times = time_rounds(cases, rounds, min_run_time, compiled)
    ops = {name: op_count(fn) for name, fn in cases.items() if "tonic" not in name}
    clone = _median(times["eager"][CLONE])
    rows = []
    missed = []
    for goal in GOALS:
        eager, met = judge(goal, times, ops, "eager")
        compiled_cell = "—"
        if compiled and goal.row in times["compiled"]:
            value, compiled_met = judge(goal, times, ops, "compiled")
            compiled_cell = f"{value} ({'met' if compiled_met else 'missed'})"
        verdict = "—" if met is None else ("met" if met else "missed")
        if met is False:
            missed.append(goal)
        rows.append([goal.row, fmt_ms(_median(times["eager"][goal.row])), eager, compiled_cell, ops.get(goal.row, ""),
                     goal.text, verdict])
    table = markdown_table(["goal row", "eager median", "eager", "compiled", "ops", "goal", "eager verdict"], rows)
    parts = [
        "## Speed goals: eager and compiled side by side" + allocator_suffix(),
        f"`{command('library/speed_goals.py', argv)}` on commit `{_commit()}`. {len(data['grasps'])} simulated grasps, "
        f"{sum(len(s) for s in data['grasps']):,} events, binned to ({len(data['grasps'])}, 36, 2, 70, 75) float32; "
        f"`frames.clone()` of that batch took {fmt_ms(clone)} (median of {rounds} interleaved rounds). Peers: {peer}. "
        "'compiled' runs the row inside `et.compiled_kernels()` (only rows whose kernels compile); "
        "'—': the same code either way. Ops: top-level aten calls of one eager call.",
        table,
    ]
    if args.profile and missed:
        profile_rows = []
        for goal in missed:
            profile_rows.append([goal.row, profile_top(cases[goal.row], False),
                                 profile_top(cases[goal.row], True) if compiled and goal.row in times["compiled"] else "—"])
        parts += ["Where the missed rows spend their time (self CPU time share of the top aten ops, one call):",
                  markdown_table(["missed row", "eager: top ops", "compiled: top ops"], profile_rows)]
    if args.ref:
        ref = run_ref(args.ref, data, rounds, min_run_time)
        ref_rows = []
        for name in cases:
            if name == CLONE:
                continue
            before, after = _ratio(ref["ref"], ref["ref"].get(CLONE, []), name), _ratio(ref["this"], ref["this"][CLONE], name)
            ref_rows.append([name, "n/a" if before != before else f"{before:.2f}×", f"{after:.2f}×"])
        parts += [f"Before/after, eager, × clone of the same child process (`{args.ref}` vs this tree, alternating; "
                  "the bare affine_grid + grid_sample row runs the same code in both: its gap is this comparison's noise):",
                  markdown_table(["row", f"× clone on {args.ref}", "× clone now"], ref_rows)]
    parts += environment_lines(["tonic"])
    publish("\n\n".join(parts), args)
    return {"times": times, "ops": ops}


def argparse_suppress() -> str:
    import argparse

    return argparse.SUPPRESS


def _commit() -> str:
    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


if __name__ == "__main__":
    main(sys.argv[1:])
