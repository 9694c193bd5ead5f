"""A recorded sweep of the quick model's configuration against the linear baselines.

For each configuration (ConvLSTM channels, input pool, steps) the script trains ``none`` with
4 seeds through the protocol's trainer (:func:`~event_transforms.tactile.training.train` with
:meth:`ProtocolConfig.training_settings`, the quick configuration's batch, learning rate,
hold-out stopping rule and bootstrap resamples) on each *distinct* training set of the quick
scenes (scenes whose training and hold-out data are the same bit for bit,
:func:`~event_transforms.tactile.protocol.shared.training_key`, share one), and scores

- the MSE on the training session's hold-out sequences (the stopping rule's data; the kept
  weights are those with the lowest of these, so the network's figure is slightly optimistic;
  the ridge picks its penalty on the same sequences), and
- the control scene's test MSE (each seed on its own bootstrap resample of the test
  sequences, as the protocol scores),

against the linear baselines (:mod:`~event_transforms.tactile.baselines`: cumulative-count
ridge and physics least squares), fitted per seed on the same bootstrap resample of the
training sequences the network reads and scored on the same sequences; plus the seconds per
member-step (the wall time of the ``train`` call, copies and hold-out passes included, over
members × steps; one thread). ``benchmarks/tactile/model_sweep.md`` gets the table, which
configurations beat both baselines on control and on every training-session hold-out, and the
estimated main-job time of each: ``event-transforms reproduce --plan``'s member-steps (at the
configuration's steps) × the measured seconds per member-step / 2 jobs.

Run: ``OMP_NUM_THREADS=1 python benchmarks/tactile/model_sweep.py`` on a clean commit (finished
configurations are kept in ``--state`` and skipped on a rerun).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from event_transforms.tactile.baselines import CumulativeCountRidge, PhysicsLeastSquares, stack_items
from event_transforms.tactile.commands import QUICK
from event_transforms.tactile.copies import SceneData
from event_transforms.tactile.protocol.config import ProtocolConfig
from event_transforms.tactile.protocol.environment import environment, git_commit
from event_transforms.tactile.protocol.shared import training_key
from event_transforms.tactile.resampling import split_resample
from event_transforms.tactile.training import evaluate, phase_mse, train

__all__ = ["CONFIGS", "BASELINES", "distinct_training_sets", "sweep_config", "baseline_scores", "parse_plan",
           "format_sweep", "main"]

ROOT = Path(__file__).resolve().parents[2]
OUTPUT = ROOT / "benchmarks" / "tactile" / "model_sweep.md"
#: (hidden channels, input pool, steps), cheapest first.
CONFIGS: tuple[tuple[tuple[int, ...], int, int], ...] = (
    ((4,), 14, 300), ((4,), 14, 600), ((8,), 14, 300), ((8,), 14, 600),
    ((4,), 7, 300), ((4,), 7, 600), ((8,), 7, 300), ((8,), 7, 600), ((8, 16), 7, 300),
)
#: A recorded main job of the quick configuration ((4,) / pool 14 / 300 steps), 2 jobs × 1 thread.
RECORDED_MAIN_JOB = (13.4, "docs/results.md: 13 min 23 s, the README's main command at commit 24bbbb8 (train once), 2 jobs on a shared 2-core machine")
#: The baselines a configuration must beat, by their table names.
BASELINES = ("cumulative-count-ridge", "physics least-squares")


def distinct_training_sets(data: Mapping[str, SceneData]) -> dict[str, list[str]]:
    """The first scene of each distinct training set (training and hold-out data) -> every scene
    that has it, in ``data``'s order.

    Example:
        >>> from event_transforms.tactile.benchmark_scenes import get_scene
        >>> g = torch.Generator().manual_seed(0)
        >>> def items(n):
        ...     frames = torch.poisson(torch.full((n, 12, 2, 6, 6), 0.5), generator=g)
        ...     return [(f, f.sum((1, 2, 3)), {"diameter_mm": 15.0}) for f in frames]
        >>> train, holdout = items(4), items(2)
        >>> data = {name: SceneData(get_scene(name), train if name != "paper" else items(4), items(2), items(2),
        ...                         holdout=holdout) for name in ("control", "paper", "timing")}
        >>> distinct_training_sets(data)
        {'control': ['control', 'timing'], 'paper': ['paper']}
    """
    first: dict[str, str] = {}
    out: dict[str, list[str]] = {}
    for name, scene_data in data.items():
        owner = first.setdefault(training_key(scene_data), name)
        out.setdefault(owner, []).append(name)
    return out


def _splits(data: SceneData, seed: int, resample: str) -> dict[str, Any]:
    """The seed's training resample and the hold-out and test sequences, as the network is scored."""
    train_frames, train_force = stack_items(data.train)
    test_pick = (split_resample(data.test, seed, "test") if resample == "bootstrap"
                 else torch.arange(len(data.test)))
    train_pick = (split_resample(data.train, seed, "train") if resample == "bootstrap"
                  else torch.arange(len(data.train)))
    return {"train": (train_frames[train_pick], train_force[train_pick]), "holdout": stack_items(data.holdout),
            "test": stack_items(data.test), "test_pick": test_pick}


def baseline_scores(data: SceneData, seeds: Sequence[int], resample: str = "bootstrap") -> dict[str, dict[str, list]]:
    """Per baseline of :data:`BASELINES`: ``{"holdout_mse", "test_mse"}`` per seed, each seed's
    fitted on that seed's training resample (the ridge's penalty picked on the hold-out set)."""
    out: dict[str, dict[str, list]] = {name: {"holdout_mse": [], "test_mse": []} for name in BASELINES}
    for seed in seeds:
        split = _splits(data, seed, resample)
        for model in (CumulativeCountRidge(), PhysicsLeastSquares()):
            if isinstance(model, CumulativeCountRidge):
                model.fit(*split["train"], val=split["holdout"])
            else:
                model.fit(*split["train"])
            holdout = model.predict(split["holdout"][0]) - split["holdout"][1].double()
            pick = split["test_pick"]
            test = model.predict(split["test"][0][pick]) - split["test"][1][pick].double()
            out[model.name]["holdout_mse"].append(float(holdout.square().mean()))
            out[model.name]["test_mse"].append(float(test.square().mean()))
    return out


def sweep_config(config: ProtocolConfig, data: SceneData, seeds: Sequence[int]) -> dict[str, Any]:
    """Train ``none`` × ``seeds`` on ``data`` with ``config``; per seed the hold-out MSE, the test
    MSE (on the seed's test resample) and the kept step; the wall time per member-step."""
    tick = time.perf_counter()
    trained = train(data, ["none"], seeds, **config.training_settings(), progress=False)
    wall = time.perf_counter() - tick
    holdout_pred, holdout_target = evaluate(trained.model, data.holdout)
    test_pred, test_target = evaluate(trained.model, data.test)
    holdout, test = [], []
    for index, seed in enumerate(trained.seeds):
        pick = split_resample(data.test, seed, "test") if config.resample == "bootstrap" else slice(None)
        holdout.append(phase_mse(holdout_pred[index], holdout_target)["all"])
        test.append(phase_mse(test_pred[index][pick], test_target[pick])["all"])
    return {"seeds": list(trained.seeds), "holdout_mse": holdout, "test_mse": test,
            "best_step": [m.best_step for m in trained.result.members], "wall_s": wall,
            "train_s": trained.result.train_s, "s_per_member_step": wall / (len(trained.seeds) * config.steps)}


def time_configs(data: SceneData, configs: Sequence[tuple[tuple[int, ...], int, int]], seeds: Sequence[int], *,
                 steps: int = 60, repeats: int = 3, batch_size: int = int(QUICK["batch_size"])) -> dict[str, float]:
    """Seconds per member-step of each configuration's model, interleaved: ``repeats`` rounds, each
    training every (channels, pool) for ``steps`` steps (one hold-out pass, as the main job makes
    one per ``eval_every`` = 50 steps) in turn; the median per configuration, keyed by
    :func:`_label` (a configuration's step count does not change its cost per step). Interleaving
    spreads a shared machine's slow spells over every configuration."""
    models = list(dict.fromkeys((tuple(c), p) for c, p, _ in configs))
    times: dict[tuple[tuple[int, ...], int], list[float]] = {m: [] for m in models}
    for _ in range(repeats):
        for channels, pool in models:
            config = ProtocolConfig(steps=steps, eval_every=steps, batch_size=batch_size, lr=float(QUICK["lr"]),
                                    hidden_channels=channels, input_pool=pool, resample="bootstrap")
            tick = time.perf_counter()
            train(data, ["none"], seeds, **config.training_settings(), progress=False)
            times[(channels, pool)].append((time.perf_counter() - tick) / (len(seeds) * steps))
    return {_label(c, p, n): statistics.median(times[(tuple(c), p)]) for c, p, n in configs}


_PLAN_TOTAL = re.compile(r"total at most ([\d,]+)")
_PLAN_MAIN = re.compile(r"members \(method × seed\), ([\d,]+) member-steps")
_PLAN_TRAINED = re.compile(r"([\d,]+) member-steps are trained in the main phase")


def parse_plan(text: str) -> dict[str, int]:
    """The member-steps ``event-transforms reproduce --plan`` prints: ``total`` (its "total at
    most", every phase, shared members counted), ``main`` and ``main_trained`` (the main phase,
    all and after train-once), ``trained`` (``total`` less the main phase's shared members).

    Example:
        >>> parse_plan("336 members (method × seed), 100,800 member-steps; ...\\n"
        ...            "... 76,800 member-steps are trained in the main phase ...\\n... total at most 246,000")
        {'total': 246000, 'main': 100800, 'main_trained': 76800, 'trained': 222000}
    """
    found = {}
    for name, pattern in (("total", _PLAN_TOTAL), ("main", _PLAN_MAIN), ("main_trained", _PLAN_TRAINED)):
        match = pattern.search(text)
        if match is None:
            raise ValueError(f"text: no {pattern.pattern!r} in the plan, got {text[-300:]!r}")
        found[name] = int(match.group(1).replace(",", ""))
    found["trained"] = found["total"] - (found["main"] - found["main_trained"])
    return found


def reproduce_plan(steps: int) -> dict[str, int]:
    """:func:`parse_plan` of ``event-transforms reproduce --plan --steps STEPS`` (the quick configuration)."""
    from event_transforms.tactile import cli

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        cli.main(["reproduce", "--plan", "--steps", str(steps)])
    return parse_plan(buffer.getvalue())


def _label(channels: Sequence[int], pool: int, steps: int) -> str:
    return f"{tuple(channels)} / pool {pool} / {steps} steps"


def _mean(values: Sequence[float]) -> float:
    return statistics.fmean(values)


def format_sweep(state: Mapping[str, Any], plans: Mapping[int, Mapping[str, int]], *, jobs: int = 2,
                 header: Sequence[str] = (), recorded_min: float | None = None) -> str:
    """The page: the table (one row per configuration and one per baseline; the mean over seeds
    of each score, bold where it beats both baselines), which configurations beat both
    everywhere, and each one's estimated main-job time (``plans``: steps -> :func:`parse_plan`).

    ``recorded_min``: a recorded main job's minutes for the first row's configuration; each row
    then also gets that time scaled by its model's cost relative to the first row's (the sweep's
    seconds per member-step, averaged over the rows of the same model) and by its plan's
    trained member-steps relative to the first row's.
    """
    sets = state["training_sets"]
    control = state["control"]
    columns = [f"{control} test", *(f"{s} hold-out" for s in sets)]
    base = {name: [_mean(state["baselines"][control][name]["test_mse"]),
                   *(_mean(state["baselines"][s][name]["holdout_mse"]) for s in sets)] for name in BASELINES}
    bar = [min(base[name][i] for name in BASELINES) for i in range(len(columns))]
    scaled_head = " | scaled from the recorded main job, min" if recorded_min is not None else ""
    lines = list(header) + [
        "| configuration (channels / input pool / steps) | " + " | ".join(columns)
        + " | beats both | s per member-step (sweep) | s per member-step (timed) | relative cost "
        "| est. main job, min (trained / plan total)" + scaled_head + " |",
        "|---|" + "---|" * (len(columns) + 5 + (recorded_min is not None)),
    ]
    swept = {label: _mean([row[s]["s_per_member_step"] for s in sets]) for label, row in state["configs"].items()}
    model_of = {label: (tuple(row["hidden_channels"]), row["input_pool"]) if "hidden_channels" in row else label
                for label, row in state["configs"].items()}
    per_model = {m: _mean([swept[lb] for lb in swept if model_of[lb] == m]) for m in set(model_of.values())}
    labels = list(state["configs"])
    winners = []
    first = None
    for label, row in state["configs"].items():
        scores = [_mean(row[control]["test_mse"]), *(_mean(row[s]["holdout_mse"]) for s in sets)]
        beats = [value < limit for value, limit in zip(scores, bar)]
        per_step = state.get("timing", {}).get(label, swept[label])
        first = first or per_step
        plan = plans.get(row["steps"])
        minutes = plan["trained"] * per_step / jobs / 60 if plan else float("nan")
        estimate = f"{minutes:.1f} / {plan['total'] * per_step / jobs / 60:.1f}" if plan else "—"
        cells = [f"**{v:.3f}**" if b else f"{v:.3f}" for v, b in zip(scores, beats)]
        scaled = ""
        if recorded_min is not None:
            head = state["configs"][labels[0]]
            first_plan = plans.get(head["steps"])
            if plan and first_plan:
                minutes = (recorded_min * per_model[model_of[label]] / per_model[model_of[labels[0]]]
                           * plan["trained"] / first_plan["trained"])
                scaled = f" {minutes:.1f} |"
            else:
                scaled = " — |"
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {sum(beats)}/{len(beats)} | {swept[label]:.4f} | "
                     f"{per_step:.4f} | {per_step / first:.1f}× | {estimate} |" + scaled)
        if all(beats):
            winners.append((label, minutes))
    blanks = " — |" * (5 + (recorded_min is not None))
    for name in BASELINES:
        lines.append(f"| *{name}* (baseline) | " + " | ".join(f"{v:.3f}" for v in base[name]) + " |" + blanks)
    lines.append("")
    how = "scaled from the recorded main job" if recorded_min is not None else "est."
    if winners:
        lines.append("Beat both baselines on the control's test set and on every training-session hold-out: "
                     + "; ".join(f"{label} (main job ≈ {m:.1f} min, {how})" for label, m in winners) + ".")
    else:
        lines.append("No configuration beats both baselines on the control's test set and on every "
                     "training-session hold-out.")
    return "\n".join(lines)


def run_sweep(data: Mapping[str, SceneData], configs: Sequence[tuple[tuple[int, ...], int, int]],
              seeds: Sequence[int], state_path: Path, *, control: str = "control",
              eval_every: int = int(QUICK["eval_every"]), batch_size: int = int(QUICK["batch_size"]),
              log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Sweep ``configs`` on the distinct training sets of ``data`` (``control`` first); finished
    configurations are kept in ``state_path`` and read back on a rerun."""
    sets = distinct_training_sets(data)
    if control not in sets:
        raise ValueError(f"control: {control!r} must be the first scene of its training set in data, got {list(sets)}")
    state: dict[str, Any] = json.loads(state_path.read_text()) if state_path.exists() else {}
    if state.get("seeds") != list(seeds) or state.get("training_sets") != sets:
        state = {"seeds": list(seeds), "training_sets": sets, "control": control, "configs": {},
                 "baselines": {s: baseline_scores(data[s], seeds) for s in sets}}
    for channels, pool, steps in configs:
        label = _label(channels, pool, steps)
        if label in state["configs"]:
            continue
        config = ProtocolConfig(steps=steps, eval_every=min(eval_every, steps), batch_size=batch_size,
                                lr=float(QUICK["lr"]), hidden_channels=tuple(channels), input_pool=pool,
                                resample="bootstrap")  # this page's resamples of one data set
        row: dict[str, Any] = {"hidden_channels": list(channels), "input_pool": pool, "steps": steps}
        for scene in sets:
            row[scene] = sweep_config(config, data[scene], seeds)
            if log:
                log(f"{label} on {scene}: hold-out {_mean(row[scene]['holdout_mse']):.3f}, test "
                    f"{_mean(row[scene]['test_mse']):.3f}, {row[scene]['s_per_member_step']:.4f} s/member-step")
        state["configs"][label] = row
        state_path.parent.mkdir(parents=True, exist_ok=True)
        state_path.write_text(json.dumps(state, indent=1))
    return state


def main(argv: Sequence[str] | None = None) -> str:
    from event_transforms.tactile.copies import load_scene_data

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4, help="seeds 0..N-1 (default 4)")
    parser.add_argument("--skip", nargs="*", default=[], help="configuration labels to leave out")
    parser.add_argument("--state", type=Path, default=Path(tempfile.gettempdir()) / "event-transforms-model-sweep.json")
    parser.add_argument("--output", type=Path, default=OUTPUT)
    parser.add_argument("--recorded-main-job", type=float, default=RECORDED_MAIN_JOB[0],
                        help="minutes of a recorded main job of the first configuration, to scale from "
                             f"(default {RECORDED_MAIN_JOB[0]}: {RECORDED_MAIN_JOB[1]})")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    commit = git_commit()

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    data = {s: load_scene_data(s) for s in QUICK["scenes"]}
    sets = distinct_training_sets(data)
    log(f"distinct training sets: {sets}")
    configs = [c for c in CONFIGS if _label(*c) not in args.skip]
    state = run_sweep(data, configs, list(range(args.seeds)), args.state, log=log)
    done = [c for c in configs if _label(*c) in state["configs"]]
    if any(_label(*c) not in state.get("timing", {}) for c in done):
        log("timing each model, interleaved")
        state["timing"] = time_configs(data["control"], done, list(range(args.seeds)))
        args.state.write_text(json.dumps(state, indent=1))
    plans = {steps: reproduce_plan(steps) for steps in sorted({c[2] for c in done})}
    env = environment("cpu", 1)
    allocator = ", ".join(f"{k}={v}" for k, v in sorted(os.environ.items()) if k.startswith("MALLOC_"))
    header = [
        "# The quick model's configuration against the linear baselines",
        "",
        f"Produced by `python benchmarks/tactile/model_sweep.py` at commit `{commit}`; CPU {env['cpu_model']} "
        f"({env['cpu_capability']} kernels), torch {env['torch']}, 1 thread; allocator "
        f"{allocator or 'glibc defaults'}; a shared 2-core machine (load average 3-5: another 1-thread job of this branch and other work ran beside it), so the "
        f"seconds are as measured, not a cost table. Training wall time, summed over configurations: "
        f"{sum(r[s]['wall_s'] for r in state['configs'].values() for s in sets):.0f} s.",
        "",
        f"`none`, seeds {', '.join(map(str, state['seeds']))}, through the protocol's trainer with the quick "
        f"configuration's settings (batch {QUICK['batch_size']}, lr {QUICK['lr']}, hold-out every "
        f"{QUICK['eval_every']} steps, the weights with the lowest hold-out MSE kept, each seed on its own "
        "bootstrap resample of the training sequences). One training run per distinct training set of the quick "
        "scenes: " + "; ".join(f"{s} (= {', '.join(v)})" for s, v in sets.items()) + ". Cells: mean MSE over "
        "seeds (N²); the hold-out is the training session's (the stopping rule's data: the network's figure is its "
        "minimum over the checks, slightly optimistic); the control's test MSE is on each seed's resample of the "
        "test sequences. Baselines fitted per seed on the same training resample, scored on the same sequences. "
        "Bold: below both baselines. s per member-step (sweep): the sweep's `train` calls' wall time (copies and "
        "hold-out passes included) over 4 members × steps, mean over the training sets, as the machine's load "
        "came; (timed): the median of 3 interleaved rounds of 60 steps of each model on the control's data, "
        "after the sweep (steadier); relative cost: the timed figure against the first row's. Est. main job: `event-transforms "
        "reproduce --plan --steps N`'s member-steps × s per member-step (timed) / 2 jobs; *trained* leaves out the main "
        "phase's members that train once and are shared, *plan total* is the plan's \"total at most\" (equal cost "
        "at its maximum); neither counts data loading, scoring or the cost table. The main job's ensembles are "
        "larger than these 4-member ones, so its seconds per member-step may be lower.",
        "",
    ]
    if args.skip:
        header += [f"Left out for time (`--skip`): {'; '.join(args.skip)}.", ""]
    header += [
        f"Scaled from the recorded main job: {args.recorded_main_job} min "
        f"({RECORDED_MAIN_JOB[1] if args.recorded_main_job == RECORDED_MAIN_JOB[0] else 'given'}) for the first row, "
        "times the row's model cost relative to the first row's (the sweep's seconds per member-step, averaged over "
        "the rows of the same model; the timed column's 60-step runs carry a fixed setup cost that flatters the "
        "larger models) and its plan's trained member-steps relative to the first row's; the 4-member ensembles "
        "here cost more per member-step than the main job's larger ones, which is why the plain estimate is "
        "several times the recorded time.", ""]
    page = format_sweep(state, plans, header=header, recorded_min=args.recorded_main_job)
    args.output.write_text(page + "\n")
    print(page)
    return page


if __name__ == "__main__":
    main()
