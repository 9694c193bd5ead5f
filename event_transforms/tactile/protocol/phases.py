"""The run's training, the third stage of a run: every phase's units spread over ranks, resumed
from disk (:func:`train_protocol`).

The phases, in order: the main units; the budget check (``none`` and each gapped scene's
pre-declared headline at twice the steps); the cost curve (``none`` at 1.5 × the steps); the
time columns (:func:`~event_transforms.tactile.protocol.timing.measure_timing`); the equal-cost
units (each method again for the steps its cost per step leaves, from the cost table). Each
rank trains its share of a phase's units (:func:`~event_transforms.tactile.protocol.unit.run_unit`,
which calls the one trainer :func:`~event_transforms.tactile.training.train`); every finished
unit is kept on disk (:mod:`~event_transforms.tactile.runs`), so an interrupted run resumes.
Processes are :mod:`~event_transforms.tactile.distributed`'s.
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import torch

from .. import distributed
from .._files import write_json_atomic
from ..copies import SceneData, load_scene_data
from ..methods import parse_method
from ..runs import folder_key, folder_name, read_unit, unit_key, write_unit
from ..stats import duplicates
from .config import ProtocolConfig, RunSettings
from .costs import (
    CURVE_RATIOS, QUICK_COST_TABLE, cost_key, equal_cost_steps, load_cost_table, measure_costs, ratio_of,
)
from .plan import ProtocolPlan, Unit, seed_units
from .rules import RULES
from .shared import SHARED_SEPARATOR, records_by_method, seed_values
from .timing import measure_timing
from .unit import run_unit

__all__ = ["Trained", "train_protocol"]


class _Progress:
    """Plain progress lines of one rank: unit k/N, this unit's ETA and the whole run's.

    The run's ETA comes from the cost table's seconds per member-step (``prior_s``, where the
    committed table covers the configuration) until this rank has finished a unit, then from
    the units it finished: never from the first seconds of the first unit (data loading and
    warm-up make those ETAs several times too long).
    """

    def __init__(self, costs: list[float], later: float, prior_s: float | None = None) -> None:
        self.left, self.later = sum(costs), later
        self.done, self.start = 0.0, time.perf_counter()
        self.prior_s = prior_s

    def eta(self, done_now: float) -> float:
        remaining = self.left - done_now + self.later
        if self.done == 0 and self.prior_s is not None:
            return self.prior_s * remaining
        elapsed = time.perf_counter() - self.start
        return elapsed / done_now * remaining if done_now > 0 else math.nan

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


def _prior_seconds(config: ProtocolConfig, device: str) -> float | None:
    """Seconds per member-step from the committed cost table, where it covers ``config`` on the
    CPU (the progress lines' ETA before a unit has finished); ``None`` otherwise."""
    if device != "cpu" or not QUICK_COST_TABLE.exists():
        return None
    try:
        table = load_cost_table(QUICK_COST_TABLE)
    except ValueError:
        return None
    value = table.get("ensemble_s_per_member_step")
    return float(value) if table.get("config") == cost_key(config) and value else None


def _work(
    rank: int, world: int, units: list[Unit], seeds: list[int], config: ProtocolConfig, runs: Path,
    root: str | None, device: str, threads: int | None, log: Callable[[str], None] | None, progress: bool | None,
    given: dict[str, SceneData] | None = None, prior_s: float | None = None, phase: str = "unit",
    later_cost: float = 0.0, keys: dict[str, dict[str, Any]] | None = None,
) -> None:
    """Rank ``rank``'s share of the units (every ``world``-th), each saved as it finishes; a
    unit whose file holds its key (:mod:`~event_transforms.tactile.runs`) is read back instead
    (the one resume loop)."""
    if threads:
        torch.set_num_threads(threads)
    cache: dict[tuple[str, int | None], SceneData] = {(scene, None): d for scene, d in (given or {}).items()}
    mine = [(index, unit) for index, unit in enumerate(units) if index % world == rank]
    cost = {index: unit.members(seeds) * (unit.steps or config.steps) for index, unit in mine}
    plain = progress is None and not sys.stderr.isatty()
    tracker = _Progress(list(cost.values()), later_cost / world, prior_s)
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
        for scene in {unit.scene, *(other for _, other, _ in unit.also)}:
            if (scene, unit.seed) not in cache:  # fresh data per seed: the unit's seed's own data set
                cache[(scene, unit.seed)] = load_scene_data(scene, root, paper_split=False, data_seed=unit.seed)
        tick = time.perf_counter()
        own = config if unit.steps is None else ProtocolConfig(**{**asdict(config), "steps": unit.steps})
        scored = {scene: d for (scene, seed), d in cache.items() if seed == unit.seed}
        result = run_unit(unit.scene, unit.methods, seeds if unit.seed is None else [unit.seed], own,
                          scored[unit.scene], device=device,
                          progress=False if plain else progress, description=label,
                          on_validation=tracker.callback(label, cost[index]) if plain else None,
                          also=unit.also, also_data=scored)
        write_unit(path, (keys or {}).get(unit.slug, {}), result)
        eta = tracker.finished(cost[index])
        if log:
            scores = "; ".join(
                f"{m} {statistics.fmean(r['test_mse'] for r in rs):.2f}" for m, rs in result.items()
                if SHARED_SEPARATOR not in m
            )
            if unit.also:
                scores += f"; also scored for {', '.join(f'{s_} {n}' for _, s_, n in unit.also)} (trained once)"
            log(f"{label}: test MSE {scores} ({time.perf_counter() - tick:.0f} s; {eta})")


def _runwork_units(
    units: list[Unit], seeds: list[int], config: ProtocolConfig, out: Path, jobs: int, options: tuple,
    phase: str, later_cost: float, data_keys: Mapping[tuple[str, int | None], str],
) -> dict[str, Any] | None:
    """Run ``units`` on the ranks (torchrun's, ``jobs`` spawned ones, or this process); every
    unit's result on rank 0, ``None`` on the other ranks of a torchrun group. Units are kept
    under ``out/runs/<hash of settings, seeds, model defaults, version>/``."""
    folder = folder_key(config, seeds)
    runs = out / "runs" / folder_name(config, seeds)
    keys = {u.slug: {**unit_key(folder, u.scene, u.methods, data_keys[(u.scene, u.seed)]),
                     **({"also": [[m, s_, n, data_keys[(s_, u.seed)]] for m, s_, n in u.also]} if u.also else {}),
                     **({"steps": u.steps} if u.steps is not None else {})}
            for u in units}
    arguments = (units, seeds, config, runs, *options, phase, later_cost, keys)
    write_json_atomic(runs / "config.json", folder)

    def read(unit: Unit) -> dict[str, Any]:
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


def _cost_table(given: str | Path | Mapping[str, Any] | None, scenes: Sequence[str],
                chosen: Mapping[str, Sequence[str]], data: Mapping[str, SceneData], config: ProtocolConfig,
                threads: int | None, out: Path, log: Callable[[str], None] | None) -> dict[str, Any]:
    """The run's cost table: the one given (checked against the run's configuration), else one
    measured now, interleaved, and written to ``out/cost_table.json``."""
    if given is not None:
        table = load_cost_table(given)
        if table["config"] != cost_key(config):
            raise ValueError(f"cost table {given if not isinstance(given, Mapping) else '(given)'} was measured for "
                             f"{table['config']}, this run is {cost_key(config)}: measure one for this configuration "
                             "(reproduce without --cost-table measures its own)")
        table["source"] = str(given) if not isinstance(given, Mapping) else "given"
    else:
        table = measure_costs(scenes, chosen, data, config, threads=threads)
        table["source"] = "measured at the start of the equal-cost phase of this run"
        write_json_atomic(out / "cost_table.json", table)
    if log:
        log(f"equal cost: step counts from the cost table ({table['source']}; measured on "
            f"{table.get('environment', {}).get('cpu_model', 'an unnamed CPU')} at commit "
            f"{str(table.get('commit', '?'))[:7]})")
    return table


@dataclass
class Trained:
    """What :func:`train_protocol` trained and measured, on rank 0 (``rank0``; the other ranks of a
    torchrun group hold ``rank0=False`` and nothing else): every phase's unit results by slug
    (``results``, ``budget``; ``curve``: per ratio its units and results), the time columns
    (``timing``), the cost table (``costs``), per scene the equal-cost phase's steps and cost
    ratio of each method (``steps_of``, ``cost_ratio``) and its records (``equal_runs``)."""

    rank0: bool
    results: dict[str, Any] = field(default_factory=dict)
    budget: dict[str, Any] = field(default_factory=dict)
    curve: dict[float, tuple[list[Unit], dict[str, Any] | None]] = field(default_factory=dict)
    timing: dict[str, Any] = field(default_factory=dict)
    costs: dict[str, Any] = field(default_factory=dict)
    steps_of: dict[str, dict[str, int]] = field(default_factory=dict)
    cost_ratio: dict[str, dict[str, float]] = field(default_factory=dict)
    equal_runs: dict[str, dict[str, list]] = field(default_factory=dict)


def train_protocol(settings: RunSettings, plan: ProtocolPlan) -> Trained:
    """Train every phase of the run (see the module docstring); on rank 0 every result, on the
    other ranks of a torchrun group ``Trained(rank0=False)``.

    Args:
        settings: the run's settings (:func:`~event_transforms.tactile.protocol.config.read_settings`).
        plan: the run's plan (:func:`~event_transforms.tactile.protocol.plan.plan_protocol`).

    Returns:
        The :class:`Trained` results the statistics read.
    """
    scenes, seeds, config, given = settings.scenes, settings.seeds, settings.config, settings.given
    jobs, group, out = settings.jobs, settings.group, settings.out
    by_seed, data, data_keys, phases = plan.by_seed, plan.data, plan.data_keys, plan.phases
    options = (settings.root, settings.device, settings.threads, settings.log, settings.progress, given,
               _prior_seconds(config, settings.device))
    results = _runwork_units(phases.units, seeds, config, out, jobs, options, "unit",
                             plan.counts["budget_member_steps"], data_keys)

    # The budget check: none and the scene's pre-declared headline (its matched method), at twice the steps.
    double = ProtocolConfig(**{**asdict(config), "steps": RULES.budget_factor * config.steps})
    budget = (_runwork_units(phases.budget_units, seeds, double, out, jobs, options, "budget check", 0.0, data_keys)
              if phases.budget_units else {})
    # The cost curve: none at 1.5 × the steps (2 × is the budget check's), Δ of every method against it.
    curve: dict[float, tuple[list[Unit], dict[str, Any] | None]] = {}
    if settings.equal_time and settings.measure_time:
        for ratio in (r for r in CURVE_RATIOS if 1.0 < r < 2.0):
            curve_methods = {s: ("none",) for s in scenes}
            longer = ProtocolConfig(**{**asdict(config), "steps": round(ratio * config.steps)})
            curve_units = seed_units(curve_methods, group, given, by_seed)[0]
            curve[ratio] = (curve_units, _runwork_units(
                curve_units, seeds, longer, out, jobs, options, f"cost curve (none at {longer.steps} steps)", 0.0,
                data_keys))
    rank0 = results is not None and budget is not None  # else a torchrun rank other than 0
    timing = (measure_timing(scenes, plan.chosen, data, config, settings.threads)
              if settings.measure_time and rank0 else {})

    # Equal cost: each method again for the steps its cost per step (from the cost table) leaves.
    costs: dict[str, Any] = {}
    steps_of: dict[str, dict[str, int]] = {}
    cost_ratio: dict[str, dict[str, float]] = {}
    equal_runs: dict[str, dict[str, list]] = {}
    if settings.equal_time and settings.measure_time:
        if rank0:
            assert results is not None
            costs = _cost_table(settings.cost_table, scenes, plan.chosen, data, config, settings.threads, out,
                                settings.log)
            for scene in scenes:
                rows = {m: seed_values(r) for m, r in
                        records_by_method(phases.units, results, scene, plan.chosen[scene]).items()}
                dupes = duplicates(rows)
                for method in rows:
                    if method == "none" or method in dupes:
                        continue
                    # a row without synthetic copies (with-labels) steps like none: ratio 1 by construction
                    plain = parse_method(method, scene=data[scene].scene).build(data[scene].noise_bank) is None
                    ratio = 1.0 if plain else ratio_of(costs, scene, method)
                    cost_ratio.setdefault(scene, {})[method] = ratio
                    steps_of.setdefault(scene, {})[method] = equal_cost_steps(config.steps, ratio)
        if distributed.current_group() is not None:
            steps_of = distributed.broadcast_from_rank0(steps_of)
        # one phase over every job: a unit per scene and step count (members sharing their training
        # at a step count trained once), each at its own steps, the longest first
        equal_units: list[Unit] = []
        subsets: list[tuple[list[Unit], dict[str, tuple[str, ...]]]] = []
        for steps in sorted({n for per in steps_of.values() for n in per.values() if n < config.steps},
                            reverse=True):
            subset = {s_: tuple(m for m, n in per.items() if n == steps) for s_, per in steps_of.items()}
            subset = {s_: ms for s_, ms in subset.items() if ms}
            mine = [replace(u, steps=steps) for u in seed_units(subset, group, given, by_seed)[0]]
            equal_units += mine
            subsets.append((mine, subset))
        done = (_runwork_units(equal_units, seeds, config, out, jobs, options, "equal cost", 0.0, data_keys)
                if equal_units else {})
        if done is not None:
            for mine, subset in subsets:
                for scene, names in subset.items():
                    equal_runs.setdefault(scene, {}).update(records_by_method(mine, done, scene, names))
    if not rank0:
        return Trained(rank0=False)
    assert results is not None and budget is not None  # rank 0 holds every unit's result
    return Trained(True, results, budget, curve, timing, costs, steps_of, cost_ratio, equal_runs)
