"""Running the benchmark: settings, a scene's data and training sets, one unit, the whole run.

For each :class:`~event_transforms.tactile.scenes.BenchmarkScene`, a method's training set is
the scene's 48 training sequences plus ``copies`` synthetic copies of each (the paper doubles
the set: ``copies=1``); validation (24) and test (96) sequences come from the deployment
session. Every method and seed trains the reference
:class:`~event_transforms.tactile.models.ForceRegressor` for the **same number of optimiser
steps** (copies add data, not steps), with Adam, a one-cycle learning rate and per-member
gradient clipping, all seeds (and methods) of a unit in lockstep as one
:class:`~event_transforms.tactile.ensemble.EnsembleForceRegressor` trained by
:func:`~event_transforms.tactile.ensemble.fit_ensemble` (the one trainer). Seed ``s`` gives
every method the same initial weights, the same shuffling stream and the same augmentation
seed. Statistics are in :mod:`~event_transforms.tactile.stats`, tables in
:mod:`~event_transforms.tactile.report`, processes in
:mod:`~event_transforms.tactile.distributed`.

Work is split into units (a scene's methods, or one method of a scene); every finished unit
is kept on disk, so an interrupted run resumes (:func:`run_protocol`).
Results on the package's simulated scenes are results on synthetic data, not the paper's.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import re
import statistics
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from .._validation import check_positive
from . import distributed
from .copies import (
    DeviceAugment,
    OnlineCopies,
    SceneData,
    SizedDataset,
    build_training_set,
    load_scene_data,
    paired_batches,
)
from .methods import methods_for, parse_method
from .report import format_report
from .scenes import SCENES, BenchmarkScene, get_scene
from .stats import deltas_vs_none, paired_t, summarize_scene
from .runs import data_key, folder_key, folder_name, read_unit, unit_key, write_unit
from .training import Stopwatch, phase_mse, write_json_atomic

if TYPE_CHECKING:
    from .ensemble import EnsembleForceRegressor

__all__ = [
    "ProtocolConfig",
    "run_unit",
    "run_protocol",
    "choose_methods",
    "plan_run",
    "PROGRESS_LEGEND",
    "environment",
    "online_augmentation_cost",
    "single_model_wall",
]

#: What the columns of the plain progress lines mean (printed once at the start of a run).
PROGRESS_LEGEND = (
    "progress lines: [rank r] unit k/N (this unit's place among all units of the run) scene: methods — "
    "step s/S of this unit; train MSE = the last step's training MSE, mean over the unit's members "
    "(each method × seed), N²; hold-out MSE a–b = lowest–highest member MSE on the hold-out sequences "
    "of the training session (the stopping rule's data, never deployment data), N²; ETA = this unit's "
    "time left, then the whole run's on this rank (budget check included)"
)


@dataclass
class ProtocolConfig:
    """Settings of one protocol run (the full configuration's are the defaults).

    Attributes:
        steps: optimiser steps of every run (the same for every method).
        batch_size: sequences per step.
        lr: peak learning rate of the one-cycle schedule.
        clip: gradient-norm limit per model.
        eval_every: steps between passes over the hold-out sequences of the training session;
            the weights with the lowest hold-out MSE are kept (the stopping rule; every method
            has the same step cap).
        hidden_channels: ConvLSTM channels per layer of the regressor.
        input_pool: the regressor's first average-pool factor.
        cumulative: the regressor also reads running event totals (see ``ForceRegressor``).
        fixed: the synthetic copies are made once before training (the paper's offline
            doubling; timed as "aug once") rather than drawn afresh for every batch, on the
            training device (timed as "aug s/epoch").
        copies: synthetic copies per item for names without ``x<k>``.
        paper_split: evaluate on the paper's 6 + 6 sequences instead of 24 + 96.
        paired: for a seed, every method reads the same original items at the same steps
            (:func:`~event_transforms.tactile.copies.paired_batches`); ``False`` shuffles each
            method's own set (the pairing of earlier releases: initial weights only).
    """

    steps: int = 1500
    batch_size: int = 8
    lr: float = 1e-2
    clip: float = 1.0
    eval_every: int = 100
    hidden_channels: tuple[int, ...] = (8, 16)
    input_pool: int = 4
    cumulative: bool = True
    fixed: bool = True
    copies: int = 1
    paper_split: bool = False
    paired: bool = True

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "eval_every", "input_pool", "copies"):
            check_positive(getattr(self, name), name, integer=True)
        for name in ("lr", "clip"):
            check_positive(getattr(self, name), name)
        channels = tuple(self.hidden_channels)
        if not channels or any(isinstance(c, bool) or not isinstance(c, int) or c < 1 for c in channels):
            raise ValueError(f"hidden_channels must be positive ints, got {self.hidden_channels!r}")
        self.hidden_channels = channels

    def key(self) -> str:
        """A short hash of the settings, so results of different settings never mix."""
        text = json.dumps(asdict(self), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:10]


def _force_stats(data: SizedDataset) -> tuple[float, float]:
    forces = torch.stack([torch.as_tensor(data[i][1]).double() for i in range(len(data))])
    return float(forces.mean()), float(forces.std()) if forces.numel() > 1 else 1.0


def _evaluate(model: EnsembleForceRegressor, data: SizedDataset, batch_size: int = 16) -> tuple[torch.Tensor, torch.Tensor]:
    """Predicted and measured force ``(M, N, T)`` / ``(N, T)`` (float64, CPU) of an ensemble."""
    from .baselines import stack_items
    from .ensemble import predict_ensemble

    frames, force = stack_items(data)
    return predict_ensemble(model, frames, batch_size=batch_size).double().cpu(), force.double()


def run_unit(
    scene: str | BenchmarkScene,
    methods: Sequence[str],
    seeds: Sequence[int],
    config: ProtocolConfig,
    data: SceneData,
    *,
    device: str | torch.device = "cpu",
    progress: bool | None = None,
    description: str | None = None,
    on_validation: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """Train ``methods`` × ``seeds`` of one scene as one ensemble; per-method, per-seed results.

    Member (method, seed) starts from the weights ``ForceRegressor`` draws after
    ``torch.manual_seed(seed)`` (the same for every method), reads the batches of
    :func:`~event_transforms.tactile.copies.paired_batches` for ``seed`` (the same originals at
    the same steps for every method) and makes its copies with ``seed``. Every member takes
    ``config.steps`` steps; the weights with the lowest MSE on ``data.holdout`` (checked every
    ``config.eval_every`` steps) are kept, then scored on validation and test.
    """
    from .ensemble import EnsembleForceRegressor, fit_ensemble
    from .models import ForceRegressor

    scene = data.scene if isinstance(scene, str) and scene == data.scene.name else get_scene(scene)
    parsed = [parse_method(m, copies=config.copies, scene=scene) for m in methods]
    offset, scale = _force_stats(data.train)
    augment: list[DeviceAugment | None]
    models, train_sets, member_seeds, aug_once, augment, batches = [], [], [], [], [], []
    watch = Stopwatch()
    for method in parsed:
        for seed in seeds:
            torch.manual_seed(seed)
            models.append(ForceRegressor(hidden_channels=config.hidden_channels, input_pool=config.input_pool,
                                         cumulative=config.cumulative))
            before = watch.seconds
            transform = method.build(data.noise_bank)
            if config.fixed or transform is None:
                train_sets.append(build_training_set(method, data, seed=seed, fixed=True, stopwatch=watch))
                augment.append(None)
            else:  # on the fly: copies are transformed batch by batch on the training device
                train_sets.append(OnlineCopies(data.train, method.copies))
                augment.append(DeviceAugment(transform.to(device), seed))
            aug_once.append(watch.seconds - before)
            member_seeds.append(int(seed))
            copies = method.copies if transform is not None else 0
            if config.paired:
                batches.append(paired_batches(len(data.train), copies, config.batch_size, config.steps, seed=seed))
    ensemble = EnsembleForceRegressor.from_models(models).to(device)
    ensemble.set_force_scaling([offset] * len(models), [max(scale, 1e-6)] * len(models))
    holdout = data.holdout is not None
    result = fit_ensemble(
        ensemble, train_sets, data.holdout if holdout else data.train, steps=config.steps,
        batch_size=config.batch_size, seeds=member_seeds, lr_max=config.lr, clip=config.clip, schedule="one-cycle",
        eval_every=config.eval_every, select="best" if holdout else "final", device=device, progress=progress,
        augment=augment, batches=batches if config.paired else None, on_validation=on_validation,
        fixed_data=True,  # every training set here is fixed (on-the-fly copies go through augment)
        description=description or f"{scene.name}: {', '.join(methods)}",
    )
    val_pred, val_target = _evaluate(ensemble, data.val)
    test_pred, test_target = _evaluate(ensemble, data.test)
    passes = config.steps * config.batch_size  # sequences read per member
    out: dict[str, list[dict[str, Any]]] = {}
    for index, record in enumerate(result.members):
        method = parsed[index // len(seeds)]
        size = len(train_sets[index])
        member_augment = augment[index]
        test_phases = phase_mse(test_pred[index], test_target)
        out.setdefault(method.name, []).append(
            {
                "seed": member_seeds[index],
                "copies": method.copies,
                "train_items": size,
                "steps": result.steps,
                # the stopping rule: the step whose weights were kept, and their hold-out MSE
                "stopping": "best hold-out MSE" if holdout else "final weights (no hold-out)",
                "best_step": record.best_step if holdout else result.steps,
                "holdout_mse": record.selected_val_loss if holdout else math.nan,
                "test_mse": test_phases["all"],
                "test_phase_mse": test_phases,
                "val_mse": phase_mse(val_pred[index], val_target)["all"],
                # the paper's 6 + 6 split: the first 6 sequences of val and test
                "val_mse_paper_split": phase_mse(val_pred[index, :6], val_target[:6])["all"],
                "test_mse_paper_split": phase_mse(test_pred[index, :6], test_target[:6])["all"],
                "final_train_loss": record.train_loss[-1] if record.train_loss else math.nan,
                "holdout_history": {"steps": record.val_steps, "mse": record.val_loss},
                "aug_s_once": aug_once[index],
                # online copies: this member's augmentation time, per pass over its set
                "aug_s_per_epoch": (
                    member_augment.stopwatch.seconds * size / max(passes, 1) if member_augment is not None else 0.0
                ),
                # one ensemble trains every member at once: its time is shared equally
                "train_s": result.train_s / len(result.members),
                "ensemble_members": len(result.members),
                "ensemble_train_s": result.train_s,
                "test_examples": {
                    "predicted": test_pred[index, :2].tolist(),
                    "measured": test_target[:2].tolist(),
                },
            }
        )
    return out


# --------------------------------------------------------------------------- running


@dataclass
class _Unit:
    scene: str
    methods: tuple[str, ...]

    @property
    def slug(self) -> str:
        return re.sub(r"[^a-z0-9.+-]+", "_", f"{self.scene}__{'+'.join(self.methods)}".lower())


def _resolve(scene: str, data: dict[str, SceneData] | None) -> BenchmarkScene:
    """A scene by name: the given data's own scene (e.g. a folder of recordings), else a built-in one."""
    if isinstance(scene, str) and data and scene in data:
        return data[scene].scene
    return get_scene(scene)


def _units(
    scenes: Sequence[str], methods: Mapping[str, Sequence[str]], group: str, data: dict[str, SceneData] | None = None
) -> list[_Unit]:
    """Work units; the costly ones (many copies) first, so ranks finish together."""
    units = []
    for scene in scenes:
        names = tuple(methods[scene])
        if group == "scene":
            units.append(_Unit(scene, names))
        else:
            units.extend(_Unit(scene, (m,)) for m in names)
    return sorted(units, key=lambda u: -max(parse_method(m, scene=_resolve(u.scene, data)).copies for m in u.methods))


def _budget_scenes(
    scenes: Sequence[str], chosen: Mapping[str, Sequence[str]], data: dict[str, SceneData] | None = None
) -> list[str]:
    """The scenes whose verdicts get a budget check: a gap, ``none`` and another method."""
    return [s for s in scenes if _resolve(s, data).gaps and "none" in chosen[s] and len(chosen[s]) > 1]


def choose_methods(
    scenes: Sequence[str], methods: Mapping[str, Sequence[str]] | Sequence[str] | None = None, *, full: bool = False,
    data: dict[str, SceneData] | None = None,
) -> dict[str, tuple[str, ...]]:
    """Each scene's methods: given per scene, given for all, or :func:`methods_for`; every name
    checked (:func:`parse_method`) before any work.

    Example:
        >>> choose_methods(["control"], ["none", "fs2"])
        {'control': ('none', 'fs2')}
    """
    resolved = {s: _resolve(s, data) for s in scenes}
    if isinstance(methods, Mapping):
        chosen = {s: tuple(methods.get(s, methods_for(resolved[s], full=full))) for s in scenes}
    elif methods is not None:
        chosen = {s: tuple(methods) for s in scenes}
    else:
        chosen = {s: methods_for(resolved[s], full=full) for s in scenes}
    for scene, names in chosen.items():
        if len(set(names)) != len(names):
            raise ValueError(f"methods must be distinct, got {names} for scene {scene!r}")
        for name in names:
            parse_method(name, scene=resolved[scene])  # fail before any training
    return chosen


def plan_run(
    scenes: Sequence[str], methods: Mapping[str, Sequence[str]], seeds: Sequence[int], config: ProtocolConfig, *,
    group: str = "method", budget_check: bool = True, data: dict[str, SceneData] | None = None,
) -> dict[str, Any]:
    """What a run costs before it starts: units, members and member-steps (one member = one
    method × seed trained for ``config.steps``), the budget check's share included.

    Multiply ``member_steps`` by the measured seconds per member-step (printed after a unit:
    ``ensemble_train_s / (ensemble_members · steps)`` in a unit file) for the run's time.

    Example:
        >>> plan = plan_run(["control", "timing"], {"control": ["none", "fs2"], "timing": ["none", "fs2"]},
        ...                 range(8), ProtocolConfig(steps=100))
        >>> plan["units"], plan["members"], plan["member_steps"], plan["budget_member_steps"]
        (4, 32, 3200, 3200)
    """
    units = _units(scenes, methods, group, data)
    members = sum(len(u.methods) for u in units) * len(seeds)
    checked = _budget_scenes(scenes, methods, data) if budget_check else []
    budget_members = 2 * len(checked) * len(seeds)
    return {
        "units": len(units),
        "members": members,
        "member_steps": members * config.steps,
        "budget_check_scenes": checked,
        "budget_units": len(checked) if group == "scene" else 2 * len(checked),
        "budget_members": budget_members,
        "budget_member_steps": budget_members * 2 * config.steps,
        "total_member_steps": members * config.steps + budget_members * 2 * config.steps,
    }


def _cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; ``platform.processor()`` elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment(device: str = "cpu", threads: int | None = None) -> dict[str, Any]:
    """What a result depends on besides the code: package version and commit, torch, the CPU
    model and the kernel set torch dispatches to (``ATEN_CPU_CAPABILITY``, and what
    ``torch.backends.cpu.get_cpu_capability()`` reports), threads and device. The same code
    under another kernel set gives per-seed MSEs that differ in the last digits, and training
    amplifies that: compare verdicts (sign, significance) across machines, not digits."""
    from .. import __version__

    try:
        capability = torch.backends.cpu.get_cpu_capability()
    except (AttributeError, RuntimeError):  # pragma: no cover - older torch
        capability = "unknown"
    return {
        "package_version": __version__,
        "commit": git_commit(),
        "torch": torch.__version__,
        "cpu_model": _cpu_model(),
        "cpu_capability": capability,
        "ATEN_CPU_CAPABILITY": os.environ.get("ATEN_CPU_CAPABILITY"),
        "threads": threads if threads is not None else torch.get_num_threads(),
        "device": str(device),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }


def git_commit() -> str:
    """The package checkout's ``git rev-parse HEAD`` (``-dirty`` when tracked files differ from
    it), or ``"unknown"`` outside a git checkout."""
    import subprocess

    where = Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=10)
        if head.returncode != 0:
            return "unknown"
        dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "."], cwd=where, timeout=10).returncode
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head.stdout.strip() + ("-dirty" if dirty == 1 else "")


def _baselines(data: SceneData) -> dict[str, dict[str, float]]:
    from .baselines import evaluate_baselines, stack_items

    train, val, test = (stack_items(d) for d in (data.train, data.val, data.test))
    scores = evaluate_baselines(train, val, test)
    small = evaluate_baselines(train, (val[0][:6], val[1][:6]), (test[0][:6], test[1][:6]))
    return {
        name: {**values, "test_mse_paper_split": small[name]["test_mse"], "val_mse_paper_split": small[name]["val_mse"]}
        for name, values in scores.items()
    }


class _Progress:
    """Plain progress lines of one rank: unit k/N, this unit's ETA and the whole run's."""

    def __init__(self, costs: list[float], later: float) -> None:
        self.left, self.later = sum(costs), later
        self.done, self.start = 0.0, time.perf_counter()

    def eta(self, done_now: float) -> float:
        elapsed = time.perf_counter() - self.start
        return elapsed / done_now * (self.left - done_now + self.later) if done_now > 0 else math.nan

    def callback(self, label: str, cost: float) -> Callable[[dict[str, Any]], None]:
        def report(info: dict[str, Any]) -> None:
            fraction = info["step"] / info["steps"]
            unit_eta = info["elapsed_s"] / fraction * (1 - fraction)
            val = info["val_mse"]
            print(f"{label}: step {info['step']}/{info['steps']}, train MSE {info['train_loss']:.3g}, "
                  f"hold-out MSE {min(val):.3g}–{max(val):.3g}, unit ETA {unit_eta:.0f} s, "
                  f"overall ETA {self.eta(self.done + fraction * cost) / 60:.1f} min", file=sys.stderr, flush=True)

        return report

    def finished(self, cost: float) -> str:
        self.done += cost
        return f"overall ETA {self.eta(self.done) / 60:.1f} min" if self.left - self.done + self.later > 0 else "rank done"


def _work(
    rank: int, world: int, units: list[_Unit], seeds: list[int], config: ProtocolConfig, runs: Path,
    root: str | None, device: str, threads: int | None, log: Callable[[str], None] | None, progress: bool | None,
    given: dict[str, SceneData] | None = None, phase: str = "unit", later_cost: float = 0.0,
    keys: dict[str, dict[str, Any]] | None = None,
) -> None:
    """Rank ``rank``'s share of the units (every ``world``-th), each saved as it finishes; a
    unit whose file holds its key (:mod:`~event_transforms.tactile.runs`) is read back instead
    (the one resume loop)."""
    if threads:
        torch.set_num_threads(threads)
    cache: dict[str, SceneData] = dict(given or {})
    mine = [(index, unit) for index, unit in enumerate(units) if index % world == rank]
    cost = {index: len(unit.methods) * len(seeds) * config.steps for index, unit in mine}
    plain = progress is None and not sys.stderr.isatty()
    tracker = _Progress(list(cost.values()), later_cost / world)
    for index, unit in mine:
        label = f"[rank {rank}] {phase} {index + 1}/{len(units)} {unit.scene}: {', '.join(unit.methods)}"
        path = runs / f"{unit.slug}.json"
        stored, reason = read_unit(path, (keys or {}).get(unit.slug, {}))
        if stored is not None:
            tracker.left -= cost[index]
            if log:
                log(f"{label} — resumed from disk")
            continue
        if reason and log:
            log(f"{label} — {reason}: recomputing")
        if unit.scene not in cache:
            cache[unit.scene] = load_scene_data(unit.scene, root, paper_split=False)
        tick = time.perf_counter()
        result = run_unit(unit.scene, unit.methods, seeds, config, cache[unit.scene], device=device,
                          progress=False if plain else progress, description=label,
                          on_validation=tracker.callback(label, cost[index]) if plain else None)
        write_unit(path, (keys or {}).get(unit.slug, {}), result)
        eta = tracker.finished(cost[index])
        if log:
            scores = "; ".join(
                f"{m} {statistics.fmean(r['test_mse'] for r in rs):.2f}" for m, rs in result.items()
            )
            log(f"{label}: test MSE {scores} ({time.perf_counter() - tick:.0f} s; {eta})")


def _run_units(
    units: list[_Unit], seeds: list[int], config: ProtocolConfig, out: Path, jobs: int, options: tuple,
    phase: str, later_cost: float, data_keys: dict[str, str],
) -> dict[str, Any] | None:
    """Run ``units`` on the ranks (torchrun's, ``jobs`` spawned ones, or this process); every
    unit's result on rank 0, ``None`` on the other ranks of a torchrun group. Units are kept
    under ``out/runs/<hash of settings, seeds, model defaults, version>/``."""
    folder = folder_key(config, seeds)
    runs = out / "runs" / folder_name(config, seeds)
    keys = {u.slug: unit_key(folder, u.scene, u.methods, data_keys[u.scene]) for u in units}
    arguments = (units, seeds, config, runs, *options, phase, later_cost, keys)
    write_json_atomic(runs / "config.json", folder)

    def read(unit: _Unit) -> dict[str, Any]:
        result, reason = read_unit(runs / f"{unit.slug}.json", keys[unit.slug])
        if result is None:
            raise ValueError(f"unit {unit.slug}: {reason or 'its run file is missing'} after the run")
        return result

    group = distributed.current_group()
    if group is not None:  # the ranks of torchrun
        rank, world = group
        _work(rank, world, *arguments)
        mine = {u.slug: read(u) for i, u in enumerate(units) if i % world == rank}
        return distributed.gather_to_rank0(mine)
    if jobs > 1:
        distributed.spawn(_work, arguments, jobs)
    else:
        _work(0, 1, *arguments)
    return {u.slug: read(u) for u in units}


def _per_method(units: list[_Unit], results: dict[str, Any], scene: str, names: Sequence[str]) -> dict[str, list]:
    per_method: dict[str, list[dict[str, Any]]] = {}
    for unit in units:
        if unit.scene == scene:
            for name, runs_ in results[unit.slug].items():
                per_method.setdefault(name, []).extend(runs_)
    return {m: sorted(per_method[m], key=lambda r: r["seed"]) for m in names if m in per_method}


def _budget_choices(units: list[_Unit], results: dict[str, Any], scenes: list[str],
                    chosen: Mapping[str, Sequence[str]]) -> dict[str, str]:
    """Per checked scene, the method with the largest |Δ test MSE| vs ``none``."""
    choices = {}
    for scene in scenes:
        per_method = _per_method(units, results, scene, chosen[scene])
        methods = {m: {"seeds": [r["seed"] for r in rs], "test_mse": [r["test_mse"] for r in rs]}
                   for m, rs in per_method.items()}
        deltas = deltas_vs_none(methods, "test_mse")
        if deltas:
            choices[scene] = max(deltas, key=lambda m: abs(deltas[m]["mean"]))
    return choices


def _budget_check(method: str, steps: int, delta: dict[str, Any], runs_2n: dict[str, list]) -> dict[str, Any]:
    """Δ at ``steps`` and at twice the steps; robust when the sign agrees and the change is
    smaller than the CI half-width at ``steps``."""
    none = {r["seed"]: r["test_mse"] for r in runs_2n["none"]}
    pairs = [(none[r["seed"]], r["test_mse"]) for r in runs_2n[method] if r["seed"] in none]
    test = paired_t([a for a, _ in pairs], [b for _, b in pairs])
    ci = delta.get("ci95")
    half = (ci[1] - ci[0]) / 2 if ci else math.nan
    robust = bool(ci) and (delta["mean"] > 0) == (test.mean > 0) and abs(delta["mean"] - test.mean) < half
    return {"method": method, "steps": steps, "steps_2n": 2 * steps, "delta": delta["mean"],
            "delta_2n": test.mean, "ci95_2n": list(test.ci) if test.ci else None, "ci95_halfwidth": half,
            "robust": robust}


def _describe_data(data: dict[str, SceneData], scenes: Sequence[str]) -> str:
    """What the results rest on: simulated grasps, or folders of recordings (path, files, content hash)."""
    parts = []
    for scene in scenes:
        dataset = getattr(data[scene], "dataset", None)
        if isinstance(dataset, dict):
            parts.append(f"{scene}: recordings in {dataset['folder']} ({dataset['files']} files, content hash "
                         f"{dataset['content_hash'][:16]})")
    simulated = [s for s in scenes if not isinstance(getattr(data[s], "dataset", None), dict)]
    if simulated:
        parts.append(f"{', '.join(simulated)}: simulated tactile grasps (synthetic data, not the paper's recordings)")
    return "; ".join(parts)
def online_augmentation_cost(method_name: str, scene: str | BenchmarkScene, data: SceneData, *,
                             batch_size: int = 8, copies: int = 1, repeats: int = 3, seed: int = 0) -> float | None:
    """Seconds to augment one epoch's copies online, as a DataLoader would: every training
    item's ``copies`` copies transformed once, ``batch_size`` at a time, through the
    :class:`~event_transforms.tactile.copies.DeviceAugment` the online protocol uses (median of
    ``repeats`` passes; ``None`` for a method without copies)."""
    method = parse_method(method_name, copies=copies, scene=scene)
    transform = method.build(data.noise_bank)
    if transform is None:
        return None
    online = OnlineCopies(data.train, method.copies)
    order = list(range(len(data.train), len(online)))  # the copies
    times = []
    for _ in range(repeats):
        augment = DeviceAugment(transform, seed)
        for start in range(0, len(order), batch_size):
            items = [online[i] for i in order[start:start + batch_size]]
            frames = torch.stack([torch.as_tensor(item[0]) for item in items]).float()
            augment(frames, [item[2] for item in items])
        times.append(augment.stopwatch.seconds)
    return statistics.median(times)


def single_model_wall(scene: str | BenchmarkScene, data: SceneData, config: ProtocolConfig, *,
                      repeats: int = 3, seed: int = 0) -> dict[str, Any]:
    """One model (``none``, one seed) trained alone for ``config.steps`` steps, ``repeats``
    times: wall seconds per run (median, min, max). With fixed copies every method does this
    same training work, so it is every method's training time per run."""
    times = []
    for _ in range(repeats):
        tick = time.perf_counter()
        run_unit(scene, ["none"], [seed], config, data, progress=False)
        times.append(time.perf_counter() - tick)
    return {"median": statistics.median(times), "min": min(times), "max": max(times), "repeats": repeats,
            "runs_s": times}


def _timing(scenes: Sequence[str], chosen: Mapping[str, Sequence[str]], data: dict[str, SceneData],
            config: ProtocolConfig, threads: int | None) -> dict[str, Any]:
    """The time columns: one model's wall time per run (measured on the first scene: every
    scene's data have the same shape) and each scene's methods' online augmentation cost."""
    if threads:
        torch.set_num_threads(threads)
    wall = single_model_wall(data[scenes[0]].scene, data[scenes[0]], config)
    online: dict[str, dict[str, float | None]] = {}
    for scene in scenes:
        online[scene] = {m: online_augmentation_cost(m, data[scene].scene, data[scene], batch_size=config.batch_size,
                                                     copies=config.copies) for m in chosen[scene]}
    return {"single_model_wall_s": wall, "single_model_scene": scenes[0], "online_aug_s_per_epoch": online}


def run_protocol(
    scenes: Sequence[str] | None,
    seeds: Sequence[int],
    out: str | Path,
    *,
    config: ProtocolConfig | None = None,
    methods: Mapping[str, Sequence[str]] | Sequence[str] | None = None,
    full: bool = False,
    root: str | None = None,
    jobs: int = 1,
    device: str = "cpu",
    threads: int | None = 1,
    group: str = "scene",
    data: dict[str, SceneData] | None = None,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
    budget_check: bool = True,
    measure_time: bool = True,
) -> dict[str, Any]:
    """Run every scene's methods for every seed; write ``results.json`` and ``results.md``.

    Work is split into units — a scene's methods trained together as one ensemble
    (``group="scene"``) or one method at a time (``group="method"``) — spread over ranks:
    ``jobs`` local processes joined by :mod:`torch.distributed` (gloo), or the ranks of an
    already initialised process group (``torchrun``). Each finished unit is kept under
    ``out/runs/<settings hash>/`` so an interrupted run resumes; rank 0 gathers everything
    and writes the results.

    With ``budget_check``, every scene with a gap then trains ``none`` and the method with
    the largest |Δ| again at twice the steps (its units kept under their own settings hash)
    and records ``scenes.NAME.budget_check = {"method", "steps", "steps_2n", "delta",
    "delta_2n", "ci95_halfwidth", "robust"}``: robust when Δ keeps its sign and moves by less
    than the CI half-width.

    With ``measure_time``, rank 0 then measures the time columns: one model trained alone
    for ``config.steps`` steps, three times (:func:`single_model_wall`), and per method the
    online augmentation cost of one epoch (:func:`online_augmentation_cost`); per method
    ``online_wall_s`` is one model's time plus that cost times the epochs of a run.

    ``results.json`` records the environment (:func:`environment`): package version and
    commit, torch, CPU model, kernel set, threads and device.

    ``data`` (scene name -> :class:`~event_transforms.tactile.copies.SceneData`) replaces the
    simulated scenes, e.g. with your own recordings; it is sent to every worker. Without it,
    workers read the data cache.

    Returns:
        The ``results.json`` dict (on rank 0; other ranks of a torchrun group get ``{}``).
    """
    config = config or ProtocolConfig()
    scenes = list(scenes or SCENES)
    chosen = choose_methods(scenes, methods, full=full, data=data)
    if group not in ("scene", "method"):
        raise ValueError(f"group must be 'scene' or 'method', got {group!r}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive int, got {jobs!r}")
    out = Path(out)
    seeds = [int(s) for s in seeds]
    given = data
    units = _units(scenes, chosen, group, given)
    plan = plan_run(scenes, chosen, seeds, config, group=group, budget_check=budget_check, data=given)
    start = time.perf_counter()

    # Data first, in this process: the cache is written once, workers only read it.
    data = dict(given) if given is not None else {scene: load_scene_data(scene, root) for scene in scenes}
    missing = [scene for scene in scenes if scene not in data]
    if missing:
        raise ValueError(f"data must hold every scene, missing {missing}")
    data_keys = {scene: data_key(data[scene]) for scene in scenes}
    if log:
        for scene, d in data.items():
            holdout = f"{len(d.holdout)} hold-out (training session), " if d.holdout is not None else ""
            log(f"data: scene {scene!r} ({d.scene.description}): {len(d.train)} train, {holdout}{len(d.val)} val, "
                f"{len(d.test)} test sequences, ready in {d.seconds:.1f} s")
        log(f"plan: {plan['units']} units, {plan['members']} members × {config.steps} steps = "
            f"{plan['member_steps']:,} member-steps; budget check of {len(plan['budget_check_scenes'])} gapped "
            f"scene(s) at {2 * config.steps} steps: {plan['budget_units']} more units, "
            f"{plan['budget_member_steps']:,} member-steps; total {plan['total_member_steps']:,}")
        log(PROGRESS_LEGEND)
    options = (root, device, threads, log, progress, given)
    results = _run_units(units, seeds, config, out, jobs, options, "unit", plan["budget_member_steps"], data_keys)

    # The budget check: none and the method with the largest |Δ|, at twice the steps.
    checked = plan["budget_check_scenes"]
    choices: dict[str, str] = {}
    if checked:
        if results is not None:
            choices = _budget_choices(units, results, checked, chosen)
        if distributed.current_group() is not None:
            choices = distributed.broadcast_from_rank0(choices)
    double = ProtocolConfig(**{**asdict(config), "steps": 2 * config.steps})
    budget_units = _units(list(choices), {s: ("none", m) for s, m in choices.items()}, group, given)
    budget_results = (_run_units(budget_units, seeds, double, out, jobs, options, "budget check", 0.0, data_keys)
                      if budget_units else {})
    if results is None or budget_results is None:  # a torchrun rank other than 0
        return {}
    timing = _timing(scenes, chosen, data, config, threads) if measure_time else {}

    scene_results = {}
    for scene in scenes:
        d = data[scene]
        sizes = {"train": len(d.train), "val": len(d.val), "test": len(d.test)}
        if d.holdout is not None:
            sizes["holdout"] = len(d.holdout)
        summary = summarize_scene(d.scene, _per_method(units, results, scene, chosen[scene]), _baselines(d), sizes)
        summary["generation_s"] = d.seconds
        dataset = getattr(d, "dataset", None)
        if isinstance(dataset, dict):  # a folder of recordings: how many recordings the intervals rest on
            summary["recordings"] = dataset["recordings"]
            summary["dataset"] = dataset
        if timing:
            wall = timing["single_model_wall_s"]
            epochs_of = lambda s_: config.steps * config.batch_size / max(s_["train_items"], 1)  # noqa: E731
            for method, s_ in summary["methods"].items():
                cost = timing["online_aug_s_per_epoch"][scene].get(method)
                s_["single_wall_s"] = wall
                s_["online_aug_s_per_epoch"] = cost
                s_["online_wall_s"] = wall["median"] + (cost or 0.0) * epochs_of(s_)
        if scene in choices:
            method = choices[scene]
            summary["budget_check"] = _budget_check(
                method, config.steps, summary["methods"][method]["delta_vs_none"],
                _per_method(budget_units, budget_results, scene, ("none", method)),
            )
        scene_results[scene] = summary
    results_json = {
        "commit": git_commit(),
        "config": {**asdict(config), "seeds": seeds, "scenes": scenes, "jobs": jobs, "device": device,
                   "threads_per_job": threads, "group": group, "full": full, "budget_check": budget_check},
        "plan": plan,
        "wall_s": time.perf_counter() - start,
        "environment": environment(device, threads),
        "timing": timing,
        "data": _describe_data(data, scenes),
        "scenes": scene_results,
    }
    write_json_atomic(out / "results.json", results_json)
    (out / "results.md").write_text(format_report(results_json) + "\n")
    return results_json
