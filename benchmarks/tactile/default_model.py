"""The library's default model against the quick one, on the gapped scenes' verdicts.

The quick configuration's model (``ForceRegressor(hidden_channels=(4,), input_pool=14)``, a
5 × 5 input) decides the README's verdicts; the library's default ((8, 16) channels, input
pool 4, 18 × 19 cells) is about 30 times its cost per step. This script runs the protocol
(:func:`~event_transforms.tactile.protocol.run.run_protocol`) twice on the same scenes,
methods and seeds — once per model, everything else the quick configuration's (steps, batch,
learning rate, hold-out stopping rule, bootstrap resamples), no budget check, no equal cost —
and compares the verdicts both print (:func:`~event_transforms.tactile.report.run_verdicts`,
:func:`~event_transforms.tactile.report.compare_verdicts`): the same, changed significance,
or reversed. It writes ``benchmarks/tactile/default_model.md`` with both summary tables, the commit,
the machine and the wall times. Run it on a clean commit (the page names the commit).

Methods per scene: ``none``, the scene's first matched method (its pre-declared headline) and
``stretch`` where the scene has a size gap (:func:`comparison_methods`).

Run: ``OMP_NUM_THREADS=1 python benchmarks/tactile/default_model.py`` (one thread, one job; the
finished units are kept under ``--out`` so an interrupted run resumes).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from event_transforms.tactile.commands import QUICK
from event_transforms.tactile.methods import parse_method
from event_transforms.tactile.protocol.config import ProtocolConfig
from event_transforms.tactile.protocol.environment import git_commit
from event_transforms.tactile.protocol.run import run_protocol
from event_transforms.tactile.report import (
    compare_verdicts,
    format_summary_table,
    format_verdict_comparison,
    interval_coverage,
    run_verdicts,
)
from event_transforms.tactile.benchmark_scenes import get_scene

__all__ = ["SCENES", "MODELS", "comparison_methods", "model_config", "run_model", "format_comparison", "main"]

ROOT = Path(__file__).resolve().parents[2]
OUTPUT = ROOT / "benchmarks" / "tactile" / "default_model.md"
#: The gapped scenes of the quick configuration.
SCENES = ("paper", "paper-offset", "paper-membrane", "timing", "orientation")
#: The two models: (hidden channels, input pool).
MODELS: dict[str, tuple[tuple[int, ...], int]] = {
    "quick": (tuple(QUICK["hidden_channels"]), int(QUICK["input_pool"])),
    "default": ((8, 16), 4),
}


def comparison_methods(scenes: Sequence[str], stretch: bool = True) -> dict[str, tuple[str, ...]]:
    """Per scene: ``none``, its first matched method and (with ``stretch``) ``stretch`` where the
    scene takes it.

    Example:
        >>> comparison_methods(["paper", "timing"])
        {'paper': ('none', 'resize', 'stretch'), 'timing': ('none', 'fs2')}
        >>> comparison_methods(["paper"], stretch=False)
        {'paper': ('none', 'resize')}
    """
    out = {}
    for name in scenes:
        scene = get_scene(name)
        methods = ["none", *scene.matched_methods[:1]]
        if not stretch:
            out[name] = tuple(methods)
            continue
        try:
            parse_method("stretch", scene=scene)
        except ValueError:  # no size gap: stretch has nothing to simulate
            pass
        else:
            methods.append("stretch")
        out[name] = tuple(dict.fromkeys(methods))
    return out


def model_config(model: str, steps: int = int(QUICK["steps"]), eval_every: int = int(QUICK["eval_every"]),
                 batch_size: int = int(QUICK["batch_size"])) -> ProtocolConfig:
    """The quick configuration with ``model``'s channels and input pool (a name of :data:`MODELS`).

    Example:
        >>> model_config("default", steps=10, eval_every=5).hidden_channels
        (8, 16)
    """
    if model not in MODELS:
        raise ValueError(f"model must be one of {sorted(MODELS)}, got {model!r}")
    channels, pool = MODELS[model]
    return ProtocolConfig(steps=steps, eval_every=min(eval_every, steps), batch_size=batch_size, lr=float(QUICK["lr"]),
                          hidden_channels=channels, input_pool=pool, resample="bootstrap")  # as its page was made


def run_model(config: ProtocolConfig, methods: Mapping[str, Sequence[str]], seeds: Sequence[int], out: Path, *,
              data: dict[str, Any] | None = None, log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """One protocol run (one job, one thread, no budget check, no time columns, no equal cost);
    ``{"results", "text", "wall_s", "s_per_member_step"}`` (``text``: its ``results.md``)."""
    tick = time.perf_counter()
    results = run_protocol(list(methods), seeds, out, config=config, methods=methods, jobs=1, threads=1, data=data,
                           progress=False, log=log, budget_check=False, measure_time=False, equal_time=False)
    wall = time.perf_counter() - tick
    trained = results["plan"]["trained_members"] * config.steps
    return {"results": results, "text": (out / "results.md").read_text(), "wall_s": wall,
            "s_per_member_step": wall / trained if trained else float("nan")}


def format_comparison(runs: Mapping[str, Mapping[str, Any]], seeds: Sequence[int], note: str = "") -> str:
    """The page: settings, machine, wall times, the verdict comparison and both summary tables.

    ``runs``: ``{"quick": run_model(...), "default": run_model(...)}``.
    """
    quick, default = runs["quick"], runs["default"]
    config = quick["results"]["config"]
    env = default["results"]["environment"]
    a, b = run_verdicts(quick["text"]), run_verdicts(default["text"])
    outcome = compare_verdicts(a, b)
    methods = "; ".join(f"{s}: {', '.join(quick['results']['scenes'][s]['methods'])}" for s in config["scenes"])
    lines = [
        "# The default model against the quick one: which verdicts the larger model keeps",
        "",
        f"Produced by `python benchmarks/tactile/default_model.py` at commit `{quick['results']['commit']}` "
        f"(default-model run: `{default['results']['commit']}`); CPU {env['cpu_model']} "
        f"({env['cpu_capability']} kernels), torch {env['torch']}, 1 thread, 1 job, on a shared machine "
        "(wall times are as measured, not a cost table).",
        "",
        f"Both runs: scenes {', '.join(config['scenes'])}; seeds {', '.join(map(str, seeds))}; "
        f"{config['steps']} steps, batch {config['batch_size']}, lr {config['lr']}, hold-out checked every "
        f"{config['eval_every']} steps (the weights with the lowest hold-out MSE kept), resample "
        f"{config['resample']}; no budget check, no equal cost. Methods: {methods}. "
        + interval_coverage(config["resample"]),
        "",
        "| model | hidden channels | input pool | members trained | wall s | s per member-step |",
        "|---|---|---|---|---|---|",
    ]
    for name, run in runs.items():
        c = run["results"]["config"]
        lines.append(f"| {name} | {tuple(c['hidden_channels'])} | {c['input_pool']} | "
                     f"{run['results']['plan']['trained_members']} | {run['wall_s']:.0f} | "
                     f"{run['s_per_member_step']:.4f} |")
    kept = len(outcome["same"])
    lines += ["", "## Verdicts", "",
              f"Of the {len(a.keys() & b.keys())} verdicts both runs print, the default model keeps {kept} "
              "(the same sign and significance, or unresolved in both).", "",
              format_verdict_comparison(a, b, ("quick", "default")), ""]
    if note:
        lines += [note, ""]
    for name, run in runs.items():
        lines += [f"## Summary table, {name} model", "", format_summary_table(run["results"]), ""]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4, help="seeds 0..N-1 (default 4)")
    parser.add_argument("--steps", type=int, default=int(QUICK["steps"]))
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--no-stretch", action="store_true",
                        help="leave stretch out (none and each scene's first matched method only), for time")
    parser.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "event-transforms-default-model",
                        help="where the runs' units are kept (resumable)")
    parser.add_argument("--output", type=Path, default=OUTPUT, help="the page to write")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    seeds = list(range(args.seeds))
    methods = comparison_methods(args.scenes, stretch=not args.no_stretch)

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    commit = git_commit()
    runs = {}
    for model in MODELS:
        log(f"== {model} model: {MODELS[model]}")
        runs[model] = run_model(model_config(model, args.steps), methods, seeds, args.out / model, log=log)
        log(f"== {model} model: {runs[model]['wall_s']:.0f} s")
    notes = []
    if commit != runs["quick"]["results"]["commit"]:
        notes.append(f"(The script started at commit `{commit}`.)")
    if args.no_stretch:
        notes.append("Sized for the machine: `stretch` was left out (`--no-stretch`), so each scene has `none` and "
                     "its first matched method (the pre-declared headline) only; the default model costs about 30 "
                     "times the quick one per member-step, and the machine was shared with other work.")
    left_out = [s for s in SCENES if s not in args.scenes]
    if left_out:
        notes.append(f"Sized for the machine: the scene(s) {', '.join(left_out)} were left out (`--scenes`).")
    note = " ".join(notes)
    page = format_comparison(runs, seeds, note)
    args.output.write_text(page + "\n")
    print(page)
    return page


if __name__ == "__main__":
    main()
