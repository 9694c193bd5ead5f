"""The protocol on the recorded GelSight Wedge grasps: the "Recorded grasps" section of docs/results.md.

One command: convert the grasps of ``--data`` into a recording folder under ``--work`` (once;
a folder converted before with the same emulator settings is reused), write the natural
splits as scenes (:mod:`event_transforms.tactile.recordings.wedge_scenes`), measure the bin
width on training grasps only, run ``event-transforms reproduce --data WORK/wedge/scenes/<scene>``
on each scene (the unchanged protocol, the quick configuration), and write the section between
``<!-- recorded-grasps:start -->`` and ``<!-- recorded-grasps:end -->`` of ``docs/results.md``:
the commit, the machine, the rules version, the emulator settings, the data's source, each
scene's verdict table (aggregate numbers only), the network against the linear models, and each
augmentation's verdict on the recorded grasps beside the two generators' verdicts for the same
role, read at generation time from ``benchmarks/tactile/reproduce_quick.md`` (built-in) and
``benchmarks/tactile/optical.md`` (optical).

Bins and windows (fixed here, before any scene was scored; the measurement that chose them is
printed again by every run, on training grasps only): a bin of two video frames (66.6666 ms,
a hair under 2 × 33.333 ms so that each bin holds exactly the force samples of its two frames,
whose times are written to 0.1 µs) and windows of 13 bins (26 frames, 0.87 s), the longest the
shortest recording (``2024-01-10/bolt__t=1``, 27 frames) holds. On the six grasps that are training
data in every gapped split (2023-12-06 hardest and softest balls) the events per bin correlate
with |ΔF| better at two frames a bin than at one in every grasp; three frames a bin would need
windows of 33 frames (11 bins, the protocol's least) and refuse the shortest deployment grasps.
The gel is used whole (``--crop 0 0 370 400``: the converter already cut the gel's border and
the side mirror), sum-pooled by 5 to 74 × 80 so that the quick model's input pool of 14 sees
5 × 5 blocks, as on the built-in 70 × 75 crop.

    python -m benchmarks.tactile.recorded_grasps --data ../shared/data/gelsight-wedge [--work DIR] [--seeds 0-7]
        [--explore SCENE ...]   # then a post-hoc exploration: none with 600 steps, channels (8,), input pool 7
        [--render]              # only rewrite the pages from the finished runs in --work

The recorded data are not ours (no licence): nothing row by row is written into the repository,
only the tables of errors and verdicts.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import environment_lines, write_section

ROOT = Path(__file__).resolve().parents[2]
RESULTS_PAGE = ROOT / "docs" / "results.md"
#: The committed run page: the section and each scene's whole protocol output (aggregate tables).
RUN_PAGE = ROOT / "benchmarks" / "tactile" / "recorded_grasps.md"
SECTION = "recorded-grasps"

#: The recording settings of every scene (see the module docstring).
FRAME_MS = 66.6666
FRAMES = 13
CROP = (0, 0, 370, 400)
POOL = 5
#: The grasps the bin width is measured on: training data in every gapped split.
TRAINING_GRASPS = tuple(f"2023-12-06_{o}_{k}" for o in ("purple_ball_hardest", "orange_ball_softest") for k in (1, 2, 3))

#: Each recorded scene's role among the generators' scenes (``None``: no counterpart) and the
#: quick configuration's methods of that role that a folder without sizes can build (``resize``
#: and ``stretch`` need ``diameter_mm``); ``inferred``, ``prior`` and ``everything`` are added
#: where the scene inference finds a gap.
ROLES: dict[str, tuple[str | None, tuple[str, ...]]] = {
    "control": ("control", ("none", "rot50", "fs2", "noise")),
    "hardness-balls": ("paper", ("none", "rot45", "noise", "fs-1", "tes-2:0.5", "tes-2:0.5x10")),
    "hardness-foam": ("paper", ("none", "rot45", "noise", "fs-1", "tes-2:0.5", "tes-2:0.5x10")),
    "session": (None, ("none", "rot45", "noise", "fs-1", "fs2", "tes-2:0.5")),
    "shape": (None, ("none", "rot45", "noise", "fs-1", "fs2", "tes-2:0.5")),
}
SOURCE = ("the public GitHub repository `GelSight-lab/EstimateModulus`, folder `example_data/`, commit `12cb137` "
          "(2024-03-27; MIT GelSight lab); **no licence is stated**, so the files are not in this repository: get "
          "them with `git clone https://github.com/GelSight-lab/EstimateModulus` and point `--data` at its "
          "`example_data/`")


def convert(data: Path, work: Path) -> tuple[Path, float | None]:
    """The converted folder under ``work`` (converted now unless done before); seconds, or ``None`` if reused."""
    from event_transforms.tactile.recordings.video import VideoEmulation, convert_video_folder
    from event_transforms.tactile.recordings.wedge_scenes import write_wedge_scenes

    out = work / "wedge"
    record = out / "emulator.json"
    if (out / "recordings.csv").is_file() and record.is_file():
        if json.loads(record.read_text())["settings"] != VideoEmulation().as_dict():
            raise SystemExit(f"{out} was converted with other emulator settings; remove it or give another --work")
        write_wedge_scenes(out, log=print)
        return out, None
    if out.exists():
        raise SystemExit(f"{out} holds an unfinished conversion; remove it")
    start = time.perf_counter()
    convert_video_folder(data, out, log=print)  # writes the scenes too
    return out, time.perf_counter() - start


def bin_measurement(folder: Path) -> list[list[Any]]:
    """Median (min) over :data:`TRAINING_GRASPS` of r(events per bin, |ΔF| over the bin) for bins
    of 1, 2 and 3 frames, and the windows of 11 bins (the protocol's least) in frames."""
    rows = []
    per: dict[int, list[float]] = {1: [], 2: [], 3: []}
    for name in TRAINING_GRASPS:
        force = np.loadtxt(folder / "force" / f"{name}.csv", delimiter=",", skiprows=1)[:, 1]
        t = np.load(folder / "events" / f"{name}.npz")["t"]
        intervals = force.size - 1
        counts = np.bincount(np.minimum((t // (1e6 / 30)).astype(np.int64), intervals - 1), minlength=intervals)
        for b in per:
            m = intervals // b
            c = counts[: m * b].reshape(m, b).sum(1)
            change = np.abs(force[b: m * b + 1: b] - force[0: m * b: b])
            per[b].append(float(np.corrcoef(c, change)[0, 1]))
    for b, values in per.items():
        better = sum(v > w for v, w in zip(values, per[1])) if b > 1 else None
        rows.append([f"{b} ({b * 1000 / 30:.1f} ms)", f"{np.median(values):+.2f} ({min(values):+.2f})",
                     "—" if better is None else f"{better}/{len(values)}", 11 * b])
    return rows


def methods_for(scene: str, folder: Path, cache: Path) -> tuple[list[str], Any]:
    """The scene's methods (:data:`ROLES`, plus the inferred rows where a gap is inferred) and its inferred scene."""
    from event_transforms.tactile.recordings import RecordingSettings, load_recording_data

    settings = RecordingSettings(frame_ms=FRAME_MS, frames=FRAMES, crop=CROP, pool=POOL)
    data = load_recording_data(folder, settings, cache=cache, name=scene)
    methods = list(ROLES[scene][1])
    if data.scene.gaps:
        methods += ["inferred", "prior", "everything"]
    return methods, data.scene.inferred


def run_scene(scene: str, folder: Path, out: Path, cache: Path, methods: Sequence[str], seeds: str | None) -> float:
    """``event-transforms reproduce --data FOLDER`` on one scene, as a user runs it; seconds."""
    command = [sys.executable, "-m", "event_transforms.tactile.cli", "reproduce", "--data", str(folder),
               "--frame-ms", str(FRAME_MS), "--frames", str(FRAMES), "--crop", *map(str, CROP), "--pool", str(POOL),
               "--out", str(out), "--root", str(cache), "--no-plots", "--quiet", "--methods", *methods]
    if seeds:
        command += ["--seeds", seeds]
    print("$", " ".join(command), flush=True)
    start = time.perf_counter()
    subprocess.run(command, check=True, cwd=ROOT)
    return time.perf_counter() - start


def _summary_rows(text: str) -> tuple[list[str], list[list[str]]]:
    """The header and rows of the summary table of a ``results.md``."""
    from event_transforms.tactile.report import LEGACY_SUMMARY_COLUMNS, SUMMARY_COLUMNS

    header: list[str] | None = None
    rows: list[list[str]] = []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("|") and line.endswith("|"):
            cells = [c.strip() for c in line[1:-1].split("|")]
            if header is None and tuple(cells) in (SUMMARY_COLUMNS, LEGACY_SUMMARY_COLUMNS):
                header = cells
            elif header is not None and not all(set(c) <= set("-:") and c for c in cells):
                rows.append(cells)
        elif header is not None and rows:
            break
    if header is None:
        raise ValueError("no summary table")
    return header, rows


def _mse(cell: str) -> float:
    return float(cell.split()[0])


def network_vs_linear(rows: list[list[str]]) -> list[str]:
    """``none`` (the network without augmentation) against the two linear models, by mean test MSE:
    the cells of the answer table (network, ridge, physics, the best augmented row, the answer)."""
    by = {r[1]: r[2] for r in rows}
    net = _mse(by["none"])
    ridge = _mse(by["*cumulative-count-ridge* (baseline)"])
    physics = _mse(by["*physics least-squares* (baseline)"])
    word = "yes, both" if net < min(ridge, physics) else ("one of them" if net < max(ridge, physics) else "**no**")
    methods = [r for r in rows if not r[1].startswith("*") and r[1] != "none" and r[2][:1].isdigit()]
    best = min(methods, key=lambda r: _mse(r[2]), default=None)
    sd = float(by["none"].split("±")[1]) if "±" in by["none"] else float("nan")
    margin = (min(ridge, physics) - net) / sd if sd > 0 else float("nan")
    return [by["none"], f"{ridge:.2f}", f"{physics:.2f}",
            "—" if best is None else f"{best[1]} {_mse(best[2]):.2f}", f"{net / min(ridge, physics):.2f}",
            f"{margin:+.1f}", word]


def _per_seed(run: Path, scene: str) -> tuple[list[float], dict[str, list[float]]]:
    """``none``'s test MSE per seed and each linear baseline's, from a run's ``results.json``."""
    result = json.loads((run / "results.json").read_text())["scenes"][scene]
    base = {k: list(result["baselines"][k]["test_mse_per_seed"])
            for k in ("cumulative-count-ridge", "physics least-squares")}
    return list(result["methods"]["none"]["test_mse"]), base


def _paired(a: Sequence[float], b: Sequence[float]) -> str:
    """``b - a`` paired over the seeds: mean [95 % t-interval, unadjusted]."""
    from event_transforms.tactile.stats import paired_t

    test = paired_t(a, b)
    return f"{test.mean:+.2f}" + ("" if test.ci is None else f" [{test.ci[0]:+.2f}, {test.ci[1]:+.2f}]")


def linear_interval(run: Path, scene: str) -> str:
    """The network's test MSE minus the best linear model's, paired over the seeds."""
    net, base = _per_seed(run, scene)
    best = min(base, key=lambda k: sum(base[k]))
    return f"{_paired(base[best], net)} ({'ridge' if best.startswith('cumulative') else 'physics'})"


#: The post-hoc exploration (``--explore``): ``none`` alone with one setting of the quick model changed.
EXPLORE = {"600 steps": ("steps600", ("--steps", "600")), "channels (8,)": ("ch8", ("--hidden-channels", "8")),
           "input pool 7": ("pool7", ("--input-pool", "7"))}


def explore(scenes: Sequence[str], folder: Path, work: Path, cache: Path, render: bool) -> str:
    """``none`` with more steps, more channels or a finer input pool on ``scenes``, paired over the
    seeds against the quick ``none`` of the main run and against the ridge (a post-hoc exploration)."""
    rows = []
    for scene in scenes:
        quick, base = _per_seed(work / "runs" / scene, scene)
        rows.append([scene, "quick (the verdict run)", f"{np.mean(quick):.2f}", "—", _paired(base["cumulative-count-ridge"], quick)])
        for label, (short, option) in EXPLORE.items():
            out = work / "explore" / f"{scene}-{short}"
            if not render:
                command = [sys.executable, "-m", "event_transforms.tactile.cli", "reproduce", "--data",
                           str(folder / "scenes" / scene), "--frame-ms", str(FRAME_MS), "--frames", str(FRAMES),
                           "--crop", *map(str, CROP), "--pool", str(POOL), "--out", str(out), "--root", str(cache),
                           "--no-plots", "--quiet", "--methods", "none", "--no-equal-time", "--no-budget-check", *option]
                subprocess.run(command, check=True, cwd=ROOT)
            net, base = _per_seed(out, scene)
            rows.append([scene, label, f"{np.mean(net):.2f}", _paired(quick, net), _paired(base["cumulative-count-ridge"], net)])
    from benchmarks._common import markdown_table

    return ("### Post-hoc exploration (not a verdict)\n\nChosen after the table above was seen, on the scenes where "
            "the network does not beat the ridge by a clear margin: `none` alone with one setting of the quick model "
            "changed (the same 8 seeds, resamples and recordings), paired over the seeds, 95 % t-intervals without "
            "any family adjustment. Nothing here is judged by the protocol's rules.\n\n"
            + markdown_table(["scene", "model", "test MSE (mean)", "Δ vs quick none", "Δ vs ridge"], rows))


def _verdicts(text: str) -> dict[tuple[str, str, str], Any]:
    from event_transforms.tactile.report import summary_verdicts

    return summary_verdicts(text)


def _word(verdict: Any) -> str:
    if verdict is None:
        return "—"
    mean = f"{verdict.mean:+.2f}"
    return f"**{mean}** ({verdict.word})" if verdict.significant else f"{mean} ({verdict.word})"


def _outcome(recorded: Any, generator: Any) -> str:
    """holds (resolved the same way on both), flips (resolved both ways), unresolved (resolved on
    the generator, not on the recorded grasps), new (resolved on the recorded grasps only),
    neither (resolved on neither)."""
    if generator is None:
        return "—"
    if recorded.significant and generator.significant:
        return "holds" if recorded.word == generator.word else "flips"
    if generator.significant:
        return "unresolved"
    return "new" if recorded.significant else "neither"


def comparison(recorded: dict[str, dict[tuple[str, str, str], Any]]) -> tuple[str, dict[str, dict[str, int]]]:
    """Each recorded verdict beside the built-in and the optical generator's for the same role."""
    builtin_page = (ROOT / "benchmarks" / "tactile" / "reproduce_quick.md").read_text()
    optical_page = (ROOT / "benchmarks" / "tactile" / "optical.md").read_text()
    optical_run = optical_page.split("## The optical run's output", 1)[-1]
    builtin, optical = _verdicts(builtin_page), _verdicts(optical_run)
    lines = ["| recorded scene | role (built-in / optical) | method | Δ | recorded | built-in | outcome | optical (rules v1) "
             "| outcome |", "|---|---|---|---|---|---|---|---|---|"]
    counts: dict[str, dict[str, int]] = {"built-in": {}, "optical": {}}
    for scene, verdicts in recorded.items():
        role = ROLES[scene][0]
        for (_, method, column), verdict in sorted(verdicts.items(), key=lambda kv: (kv[0][2], kv[0][1])):
            if column != "vs none":
                continue
            b = builtin.get((role, method, column)) if role else None
            o = optical.get((f"optical-{role}", method, column)) if role else None
            ob, oo = _outcome(verdict, b), _outcome(verdict, o)
            for name, outcome in (("built-in", ob), ("optical", oo)):
                if outcome != "—":
                    counts[name][outcome] = counts[name].get(outcome, 0) + 1
            where = f"{role} / optical-{role}" if role else "— (no counterpart)"
            lines.append(f"| {scene} | {where} | {method} | {column} | {_word(verdict)} | {_word(b)} | {ob} | "
                         f"{_word(o)} | {oo} |")
    return "\n".join(lines), counts


def _rules_of(page_text: str) -> str:
    """The decision rules' version a generator's page states, in words (for the comparison's header)."""
    import re

    found = re.search(r"[Dd]ecision rules version (\d+)", page_text)
    made = re.search(r"Produced by commit `([0-9a-f]{7})", page_text)
    return ((f"decision rules version {found[1]}" if found else "no rules version stated (made before the rules "
             "had versions)") + (f", commit `{made[1]}`" if made else ""))


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _evidence(inferred: Any) -> str:
    """The inferred scene in one line: its gaps and each factor's statistic, train against deploy."""
    gaps = ", ".join(inferred.gaps) or "none"
    parts = []
    for factor, e in (inferred.evidence or {}).items():
        if isinstance(e, dict) and "statistic" in e and "train" in e and "deploy" in e:
            parts.append(f"{factor}: {e['statistic']} {e['train']['mean']:.3g} → {e['deploy']['mean']:.3g}"
                         + (" (gap)" if factor in inferred.gaps else ""))
    verdicts = (inferred.evidence or {}).get("verdicts") or {}
    said = "; ".join(f"{factor}: {text}" for factor, text in verdicts.items())
    return (f"gaps {gaps}" + (f"; statistics (train → deploy) {'; '.join(parts)}" if parts else "")
            + (f"; verdicts {said}" if said else ""))


def page(args: argparse.Namespace, scenes: dict[str, dict[str, Any]], bins: list[list[Any]],
         convert_s: float | None) -> str:
    from benchmarks._common import markdown_table
    from event_transforms.tactile.protocol.rules import RULES
    from event_transforms.tactile.recordings.video import VideoEmulation

    commit = _commit()
    recorded = {name: _verdicts(s["results"]) for name, s in scenes.items()}
    builtin_rules = _rules_of((ROOT / "benchmarks" / "tactile" / "reproduce_quick.md").read_text())
    optical_rules = _rules_of((ROOT / "benchmarks" / "tactile" / "optical.md").read_text())
    table, counts = comparison(recorded)
    out = [
        "## Recorded grasps: the protocol on a real GelSight Wedge",
        f"Generated by `python -m benchmarks.tactile.recorded_grasps {' '.join(args.argv)}`: the protocol runs on "
        f"commit {', '.join(f'`{c}`' for c in sorted({s['commit'] for s in scenes.values()}))}, this page written on "
        f"`{commit}`; "
        f"decision rules version **{RULES.version}** (`event_transforms/tactile/protocol/rules.py`, frozen before any "
        "recorded grasp was scored). " + "; ".join(environment_lines()) + ".",
        f"**Data**: 45 grasps of a GelSight Wedge fingertip (30 frames/s video, grip force per frame) from {SOURCE}. "
        "Only aggregate errors and verdicts appear here.",
        f"**Emulator** (`event-transforms convert`, `emulator.json`): `{json.dumps(VideoEmulation().as_dict())}`; "
        "negative force readings clipped to 0 N and counted. "
        + (f"Conversion of the 45 grasps (decode, rectify, emulate, write): {convert_s:.0f} s, once; later runs "
           "reuse it." if convert_s is not None else "Conversion reused from an earlier run of this script (`--work`)."),
        f"**Recordings** (`reproduce --data`): bins of {FRAME_MS} ms (two video frames), windows of {FRAMES} bins, "
        f"stride {FRAMES}, crop {CROP} (the whole rectified gel), pool {POOL}; the hold-out is the last trial of "
        "each training object and day, validation the first trial of each deployment object and day "
        "(`control`: the layout's first fifth). Between two frames the emulator interpolates the log intensity "
        "linearly: timing finer than 33 ms is an interpolation, so a bin is never shorter than a frame. "
        "The bin width, measured on the six 2023-12-06 hardest/softest-ball grasps only (training data in every "
        "gapped split): r(events per bin, |ΔF|), median (worst) over the grasps:",
        markdown_table(["frames per bin", "median r (worst)", "grasps better than 1 frame", "least window (frames)"],
                       bins),
        "**Does the network beat the linear models?** Mean test MSE (N²) over the seeds of the quick model without "
        "augmentation (`none`) against the cumulative-count ridge and the physics least-squares model fitted on the "
        "same training recordings (no interval: the baselines are one fit per resample, averaged; a margin under "
        "one sd of the network's seeds is a tie, not a win). The budget check (none and a gapped scene's headline "
        "at twice the steps) runs on gapped scenes only: the scene inference finds no gap on any recorded scene, so "
        "it ran on none, and `inferred`, `prior` and `everything` have no row (with no gap inferred they simulate "
        "nothing):",
        markdown_table(["scene", "network (none)", "ridge", "physics", "best augmented row", "network / best linear",
                        "(best linear − network) / sd of the seeds", "beats them (by the mean)?",
                        "network − best linear, paired over seeds [95 % CI, unadjusted]"],
                       [[name, *network_vs_linear(_summary_rows(s["results"])[1]), s["paired"]]
                        for name, s in scenes.items()]),
    ]
    for name, s in scenes.items():
        header, rows = _summary_rows(s["results"])
        role = ROLES[name][0]
        out.append(f"### {name}: {s['what']}\n\n" + f"Counterpart: {role + ' / optical-' + role if role else 'none'}. "
                   f"Protocol run: {s['seconds']:.0f} s. Inferred scene (`inferred`): {_evidence(s['inferred'])}.\n\n"
                   + "\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
                               + ["| " + " | ".join(r) + " |" for r in rows]))
    out.append("### Recorded verdicts beside the generators'\n\n"
               "Δ vs none of each augmentation on the recorded scene, beside the built-in generator's verdict for the "
               f"same role (`benchmarks/tactile/reproduce_quick.md`, read when this section was generated: {builtin_rules}) "
               "and the "
               f"optical generator's (`benchmarks/tactile/optical.md`, read when this section was generated: "
               f"{optical_rules}). The roles: `control` is the generators' `control` (no gap); the two hardness "
               "interpolations take the role of `paper` (train on the extremes, deploy the middle: there of size, here "
               "of hardness); `session` and `shape` have no counterpart. holds: resolved the same way on both; flips: "
               "resolved both ways; unresolved: resolved on the generator, not on the recorded grasps; new: resolved "
               "on the recorded grasps only; neither: resolved on neither.\n\n" + table + "\n\n" + f"Counts: {json.dumps(counts)}")
    return "\n\n".join(out)


def write_pages(body: str, scenes: dict[str, dict[str, Any]]) -> None:
    """The section into ``docs/results.md`` and, with each scene's protocol output, :data:`RUN_PAGE`."""
    write_section(SECTION, body, RESULTS_PAGE)
    runs = "\n\n".join(f"## `{name}`: the protocol's output (`results.md`)\n\n{s['results'].strip()}"
                         for name, s in scenes.items())
    RUN_PAGE.write_text("# Recorded grasps (`benchmarks/tactile/recorded_grasps.py`)\n\n"
                        "The section of `docs/results.md` it writes, then each scene's whole output. Aggregate "
                        "errors and verdicts only: the recorded data are not in this repository.\n\n"
                        + body.replace("## Recorded grasps", "## Section: Recorded grasps", 1) + "\n\n" + runs + "\n")


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    from event_transforms.tactile.protocol.rules import RULES
    from event_transforms.tactile.recordings.wedge_scenes import WEDGE_SCENES

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="the GelSight Wedge grasps (<day>/<name>.avi ...)")
    parser.add_argument("--work", type=Path, default=Path("/tmp/event-transforms-recorded"),
                        help="conversion, cache and runs (outside the repository; default %(default)s)")
    parser.add_argument("--scenes", nargs="+", default=list(WEDGE_SCENES), choices=list(WEDGE_SCENES))
    parser.add_argument("--seeds", default=None, help="the protocol's seeds (default: its quick configuration's)")
    parser.add_argument("--no-write", action="store_true", help="print the section; do not update docs/results.md")
    parser.add_argument("--explore", nargs="*", default=[], choices=list(WEDGE_SCENES),
                        help="after the runs, a post-hoc exploration on these scenes: none with 600 steps, channels "
                             "(8,), input pool 7 (labelled as such on the page)")
    parser.add_argument("--render", action="store_true",
                        help="only rewrite the pages from the finished runs in --work (no conversion, no training)")
    args = parser.parse_args(argv)
    args.argv = [a for a in (argv if argv is not None else sys.argv[1:]) if a != "--render"]
    if not args.data.is_dir():
        raise SystemExit(f"--data {args.data}: no such folder (the recorded grasps; see this script's docstring)")
    args.work.mkdir(parents=True, exist_ok=True)
    if args.render:
        folder = args.work / "wedge"
    else:
        folder, convert_s = convert(args.data, args.work)
        if convert_s is not None:
            (folder / "convert_seconds.json").write_text(json.dumps({"seconds": convert_s}))
    timing = folder / "convert_seconds.json"
    convert_s = json.loads(timing.read_text())["seconds"] if timing.is_file() else None
    print(f"converted folder {folder}" + (f" in {convert_s:.0f} s" if convert_s is not None else ""))
    bins = bin_measurement(folder)
    for row in bins:
        print("bin", row)
    cache = args.work / "cache"
    scenes: dict[str, dict[str, Any]] = {}
    for name in args.scenes:
        methods, inferred = methods_for(name, folder / "scenes" / name, cache)
        out = args.work / "runs" / (name if args.seeds is None else f"{name}-seeds-{args.seeds}")
        if args.render:
            seconds = json.loads((out / "protocol_seconds.json").read_text())["seconds"]
        else:
            seconds = run_scene(name, folder / "scenes" / name, out, cache, methods, args.seeds)
            (out / "protocol_seconds.json").write_text(json.dumps({"seconds": seconds}))
        version = json.loads((out / "results.json").read_text()).get("rules", {}).get("version")
        if version != RULES.version:
            raise SystemExit(f"{out}: judged by decision rules version {version!r}, not {RULES.version!r}")
        scenes[name] = {"results": (out / "results.md").read_text(), "seconds": seconds, "inferred": inferred,
                        "what": WEDGE_SCENES[name][1], "paired": linear_interval(out, name),
                        "commit": json.loads((out / "results.json").read_text()).get("commit", "unknown")}
        print(f"scene {name}: {seconds:.0f} s", flush=True)
    body = page(args, scenes, bins, convert_s)
    if args.explore:
        body += "\n\n" + explore(args.explore, folder, args.work, cache, args.render)
    print(body)
    if not args.no_write:
        write_pages(body, scenes)
    return {"scenes": {n: s["seconds"] for n, s in scenes.items()}, "convert_s": convert_s}


if __name__ == "__main__":
    main()
