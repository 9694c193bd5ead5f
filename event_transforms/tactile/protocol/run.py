"""The whole protocol run: units spread over ranks, resumed from disk, the budget check, the
time columns, equal wall time, ``results.json`` and ``results.md`` (:func:`run_protocol`).

Each rank trains its share of the units (:func:`~event_transforms.tactile.protocol.unit.run_unit`,
which calls the one trainer :func:`~event_transforms.tactile.training.train`); every finished
unit is kept on disk (:mod:`~event_transforms.tactile.runs`), so an interrupted run resumes.
Statistics are in :mod:`~event_transforms.tactile.stats`, tables in
:mod:`~event_transforms.tactile.report`, processes in :mod:`~event_transforms.tactile.distributed`.
Results on the package's simulated scenes are results on synthetic data, not the paper's.
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import torch

from .. import distributed
from .._files import write_json_atomic
from ..copies import SceneData, data_seed_offset, load_scene_data
from ..resampling import split_resample
from ..report import format_report
from ..runs import data_key, folder_key, folder_name, read_unit, unit_key, write_unit
from ..scenes import SCENES
from ..stats import (
    behind_unconverged, converged, deltas_vs_none, ensemble_drop, summarize_scene,
)
from .config import ProtocolConfig
from .environment import environment, git_commit
from .limits import check_run_limits
from ..methods import parse_method
from .plan import Unit, choose_methods, plan_run, resolve_scene, work_units
from .recompute import judge_budget
from .rules import RULES
from .shared import SHARED_SEPARATOR, collect, content_key, plan_sharing, training_key
from .costs import (
    CURVE_RATIOS, QUICK_COST_TABLE, cost_curve, cost_key, equal_cost_steps, load_cost_table, measure_costs, ratio_of,
)
from .timing import measure_timing
from .unit import run_unit

__all__ = ["run_protocol", "PROGRESS_LEGEND"]

#: What the columns of the plain progress lines mean (printed once at the start of a run).
PROGRESS_LEGEND = (
    "progress lines: [rank r] unit k/N (this unit's place among all units of the run) scene: methods — "
    "step s/S of this unit; train MSE = the last step's training MSE, mean over the unit's members "
    "(each method × seed), N²; hold-out MSE a–b = lowest–highest member MSE on the hold-out sequences "
    "of the training session (the stopping rule's data, never deployment data), N²; ETA = this unit's "
    "time left, then the whole run's on this rank (budget check included)"
)


def _baselines(data: SceneData, seeds: Sequence[int] = (), resample: str = "none",
               seed_data: Mapping[int, SceneData] | None = None) -> dict[str, dict[str, Any]]:
    """The baselines' scores; with ``resample="bootstrap"`` fitted and scored on each seed's
    resamples (as the networks are), with ``resample="fresh"`` on each seed's own data set
    (``seed_data``), the mean over seeds with the per-seed values beside it."""
    from ..baselines import evaluate_baselines, stack_items

    if resample == "fresh" and seeds:
        if seed_data is None:
            raise ValueError("_baselines: resample='fresh' needs each seed's data set (seed_data)")
        fresh: dict[str, dict[str, list[float]]] = {}
        for seed in seeds:
            scores = _baselines(seed_data[seed])
            for name, values in scores.items():
                entry = fresh.setdefault(name, {})
                for key, value in values.items():
                    entry.setdefault(key, []).append(float(value))
        return {name: {**{key: statistics.fmean(v) for key, v in values.items()},
                       "test_mse_per_seed": values["test_mse"], "resample": resample}
                for name, values in fresh.items()}
    train, val, test = (stack_items(d) for d in (data.train, data.val, data.test))
    if resample == "none" or not seeds:
        scores = evaluate_baselines(train, val, test)
        small = evaluate_baselines(train, (val[0][:6], val[1][:6]), (test[0][:6], test[1][:6]))
        return {name: {**values, "test_mse_paper_split": small[name]["test_mse"],
                       "val_mse_paper_split": small[name]["val_mse"]} for name, values in scores.items()}
    per_seed: dict[str, dict[str, list[float]]] = {}
    for seed in seeds:
        picks = {split: split_resample(dataset, seed, split)
                 for split, dataset in (("train", data.train), ("val", data.val), ("test", data.test))}
        boot_train, boot_val, boot_test = ((pair[0][picks[split]], pair[1][picks[split]])
                                           for split, pair in (("train", train), ("val", val), ("test", test)))
        scores = evaluate_baselines(boot_train, boot_val, boot_test)
        small = evaluate_baselines(boot_train, (val[0][:6], val[1][:6]), (test[0][:6], test[1][:6]))
        for name, values in scores.items():
            entry = per_seed.setdefault(name, {})
            for key, value in (*values.items(), ("test_mse_paper_split", small[name]["test_mse"]),
                               ("val_mse_paper_split", small[name]["val_mse"])):
                entry.setdefault(key, []).append(float(value))
    return {name: {**{key: statistics.fmean(v) for key, v in values.items()},
                   "test_mse_per_seed": values["test_mse"], "resample": resample}
            for name, values in per_seed.items()}


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


def _per_method(units: list[Unit], results: dict[str, Any], scene: str, names: Sequence[str]) -> dict[str, list]:
    """Per method of ``scene``, its records by seed: trained by the scene's own units, or
    borrowed from the unit that trained the same member for another scene."""
    return collect({u.slug: u.scene for u in units}, results, scene, names)


def _seed_values(runs: list[dict[str, Any]]) -> dict[str, list]:
    """``{"seeds", "test_mse"}`` of one method's records, by seed."""
    runs = sorted(runs, key=lambda r: r["seed"])
    return {"seeds": [r["seed"] for r in runs], "test_mse": [r["test_mse"] for r in runs]}


@dataclass
class Phases:
    """The units a run trains, phase by phase, after train-once sharing (what the plan counts,
    the progress lines number ``k/N`` and the summary reports: the same lists). ``sharing`` is
    the first data set's; ``shared_members`` counts the borrowing members of every seed."""

    sharing: Any
    units: list[Unit]
    choices: dict[str, str]
    budget_methods: dict[str, tuple[str, ...]]
    budget_units: list[Unit]
    shared_members: int = 0


def per_seed_data(data: Mapping[Any, Any]) -> dict[int | None, Mapping[str, SceneData]]:
    """``data`` as ``{seed: {scene: SceneData}}``: given so (fresh data per seed), or one data set
    for every seed (``{None: data}``).

    Example:
        >>> per_seed_data({})
        {None: {}}
    """
    if data and all(isinstance(v, SceneData) for v in data.values()):
        return {None: data}
    return dict(data) if data else {None: {}}


def seed_units(methods: Mapping[str, Sequence[str]], group: str, given: dict[str, SceneData] | None,
               data: Mapping[Any, Any]) -> tuple[list[Unit], int, Any]:
    """The units of one phase (``methods`` per scene), members shared within a data set trained
    once: for fresh data per seed, a unit per seed (scenes that share training sessions still
    share a unit within the seed), the costly first. Also returns how many (scene, method,
    seed) members borrow, and the first data set's sharing."""
    units: list[Unit] = []
    shared, first = 0, None
    known: dict[int, Any] = {}  # one data set given for several seeds (the plan's): keyed once
    for seed, scenes_data in per_seed_data(data).items():
        if id(scenes_data) not in known:  # train once: members keyed by what their training reads
            known[id(scenes_data)] = plan_sharing(methods, scenes_data)
        sharing = known[id(scenes_data)]
        first = first or sharing
        shared += sharing.shared
        units += [replace(u, seed=seed) for u in work_units(list(methods), methods, group, given, sharing)]
    order = {id(u): i for i, u in enumerate(units)}
    costly = lambda u: -max(parse_method(m, scene=resolve_scene(u.scene, given)).copies for m in u.methods)  # noqa: E731
    return sorted(units, key=lambda u: (costly(u), order[id(u)])), shared, first


def phase_units(scenes: Sequence[str], chosen: Mapping[str, Sequence[str]], group: str, data: Mapping[Any, Any],
                checked: Sequence[str], equal_time: bool, given: dict[str, SceneData] | None = None,
                seeds: Sequence[int] = ()) -> Phases:
    """The main phase's and the budget check's units as the run will train them (shared members
    trained once), from the run's data: ``{scene: SceneData}`` (one data set for every seed) or
    ``{seed: {scene: SceneData}}`` (fresh data per seed). ``seeds``: the run's, to count the
    borrowing members of one shared data set."""
    units, shared, sharing = seed_units(chosen, group, given, data)
    first = next(iter(per_seed_data(data).values()))
    choices = {s: m for s in checked if (m := headline(s, chosen, first)) is not None}
    budget_methods: dict[str, tuple[str, ...]] = {s: ("none", m) for s, m in choices.items()}
    if checked and equal_time:  # the cost curve's last point: none at twice the steps on every scene (mostly borrowed)
        budget_methods.update({s: ("none",) for s in scenes if s not in choices})
    budget_units = seed_units(budget_methods, group, given, data)[0]
    fresh = None not in per_seed_data(data)
    return Phases(sharing, units, choices, budget_methods, budget_units,
                  shared if fresh else shared * len(seeds))


def count_phases(plan: dict[str, Any], phases: Phases, seeds: Sequence[int], config: ProtocolConfig) -> None:
    """Add to ``plan`` what the run trains after train-once sharing: ``shared_members``,
    ``trained_members``, ``trained_units``, ``budget_trained_units`` and the member-steps of both
    phases (``trained_member_steps``, ``budget_trained_member_steps``)."""
    plan["shared_members"] = phases.shared_members
    plan["trained_members"] = plan["members"] - plan["shared_members"]
    plan["trained_units"], plan["budget_trained_units"] = len(phases.units), len(phases.budget_units)
    plan["trained_member_steps"] = sum(u.members(seeds) for u in phases.units) * config.steps
    plan["budget_trained_member_steps"] = sum(u.members(seeds) for u in phases.budget_units) * 2 * config.steps


def plan_line(plan: Mapping[str, Any], config: ProtocolConfig) -> str:
    """The plan in one line, counting the units the run trains (after train-once sharing), as the
    progress lines number them (``plan`` completed by :func:`count_phases`)."""
    return (f"plan: {plan['trained_units']} units to train ({plan['units']} before train-once sharing), "
            f"{plan['members']} members × {config.steps} steps, of which {plan['shared_members']} borrow the "
            f"weights of a member of another scene that reads exactly what they read (the same training data, "
            f"built policy and seed) and {plan['trained_members']} are trained: "
            f"{plan['trained_member_steps']:,} member-steps; budget check of {len(plan['budget_check_scenes'])} "
            f"gapped scene(s) at {2 * config.steps} steps: {plan['budget_trained_units']} more units "
            f"({plan['budget_units']} before sharing), {plan['budget_trained_member_steps']:,} member-steps; total "
            f"{plan['trained_member_steps'] + plan['budget_trained_member_steps']:,} member-steps trained")


def headline(scene: str, chosen: Mapping[str, Sequence[str]], data: Mapping[str, SceneData]) -> str | None:
    """The scene's pre-declared headline: its first matched method that the run trains (``None``
    without one). Declared by the scene before any result, so the budget check never re-checks
    the largest |Δ| (which regresses toward the mean at twice the steps)."""
    return next((m for m in data[scene].scene.matched_methods if m in chosen[scene] and m != "none"), None)


def _budget_check(method: str, steps: int, delta: dict[str, Any], runs_2n: dict[str, list]) -> dict[str, Any]:
    """The headline's Δ at ``steps`` and at twice the steps, judged by :func:`judge_budget` (with
    both rows' per-seed test MSEs at twice the steps, recorded so the verdict can be recomputed)."""
    converged_2n = all(converged(ensemble_drop(runs_2n[m])) for m in ("none", method))
    return judge_budget(method, steps, delta, _seed_values(runs_2n["none"]), _seed_values(runs_2n[method]),
                        converged_2n)


def _attach_equal_time(summary: dict[str, Any], steps_of: dict[str, int], runs: dict[str, list],
                       steps: int) -> None:
    """Per method of ``steps_of``: ``equal_time`` = its steps, per-seed test MSEs and Δ vs ``none``'s
    main run (one family: the scene's methods at equal wall time); duplicates copy their row's."""
    methods = summary["methods"]
    none = methods["none"]
    table: dict[str, Any] = {"none": {"seeds": none["seeds"], "test_mse": none["test_mse"]}}
    for method, n in steps_of.items():
        if n >= steps:  # the online cost leaves every step: the main run is the equal-time run
            table[method] = {"seeds": methods[method]["seeds"], "test_mse": methods[method]["test_mse"]}
        else:
            table[method] = {"seeds": [r["seed"] for r in runs[method]],
                             "test_mse": [r["test_mse"] for r in runs[method]]}
    deltas = deltas_vs_none(table, "test_mse")
    for method, n in steps_of.items():
        records = runs.get(method, []) if n < steps else []
        done = converged(ensemble_drop(records)) if records else bool(methods[method].get("converged", True))
        delta = deltas.get(method)
        if delta is not None and behind_unconverged(delta["mean"], none.get("converged", True), done):
            delta["not_converged"], delta["significant"] = True, False  # no resolved verdict from unconverged models
        methods[method]["equal_time"] = {"steps": n, "test_mse": table[method]["test_mse"],
                                         "delta_vs_none": delta}
    for method, s_ in methods.items():
        original = s_.get("duplicate_of")
        if original and "equal_time" in methods.get(original, {}):
            s_["equal_time"] = dict(methods[original]["equal_time"])


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


def _data_identity(scene: str, by_seed: Mapping[int | None, Mapping[str, SceneData]], seeds: Sequence[int],
                   resample: str) -> dict[str, Any]:
    """Which data each seed read on ``scene``: with fresh data, per seed its sequence-seed offset
    and content hashes of its training (+ hold-out) and its validation + test items; else the one
    data set's hashes and the rule each seed read it by."""
    if resample == "fresh":
        return {"rule": "fresh", "seeds": {str(seed): {
            "sequence_seed_offset": data_seed_offset(seed),
            "training_hash": training_key(by_seed[seed][scene]),
            "evaluation_hash": content_key(by_seed[seed][scene].val, by_seed[seed][scene].test)} for seed in seeds}}
    d = by_seed[None][scene]
    return {"rule": resample, "training_hash": training_key(d), "evaluation_hash": content_key(d.val, d.test)}


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
    equal_time: bool = False,
    cost_table: str | Path | Mapping[str, Any] | None = None,
    cli: bool = False,
) -> dict[str, Any]:
    """Run every scene's methods for every seed; write ``results.json`` and ``results.md``.

    Before any training, every limit of the data is checked
    (:func:`~event_transforms.tactile.protocol.limits.check_run_limits`: window length, hold-out,
    validation and test windows, batch size, noise banks); ``cli=True`` names the options as
    the command line spells them (``--frames``) in those errors.

    Work is split into units — a scene's methods trained together as one ensemble
    (``group="scene"``) or one method at a time (``group="method"``) — spread over ranks:
    ``jobs`` local processes joined by :mod:`torch.distributed` (gloo), or the ranks of an
    already initialised process group (``torchrun``). Each finished unit is kept under
    ``out/runs/<settings hash>/`` so an interrupted run resumes; rank 0 gathers everything
    and writes the results.

    With ``budget_check``, every scene with a gap then trains ``none`` and its pre-declared
    headline (the first matched method the run trains, :func:`headline`) again at twice the
    steps (its units kept under their own settings hash) and records
    ``scenes.NAME.budget_check = {"method", "steps", "steps_2n", "delta", "delta_2n",
    "ci_family_halfwidth", "robust"}``: robust when Δ keeps its sign and moves by less than the
    half-width of its Bonferroni interval.

    With ``measure_time``, rank 0 then measures the time columns: one model trained alone
    for ``config.steps`` steps, three times (:func:`single_model_wall`), and per method the
    online augmentation cost of one epoch (:func:`online_augmentation_cost`); per method
    ``online_wall_s`` is one model's time plus that cost times the epochs of a run.

    With ``equal_time`` (and ``measure_time``), every method that is not ``none`` and not a
    duplicate row is trained again, like the main runs (same seeds, same augmentation mode),
    for the steps its cost per step leaves in the time ``none`` takes for ``config.steps``:
    ``floor(steps / ratio)`` with the ratio from ``cost_table`` (a file or dict,
    :mod:`~event_transforms.tactile.protocol.costs`), or from a table measured once at the
    start of that phase (written to ``out/cost_table.json``) when none is given — never from the
    wall times of the run; ``scenes.NAME.methods.M.equal_time`` records the steps, the per-seed
    test MSEs and the Δ vs ``none``'s main run (one family per scene, as above), and
    ``cost_ratio`` the ratio. A method whose ratio is 1 keeps its main run.

    ``results.json`` records the environment (:func:`environment`): package version and
    commit, torch, CPU model, kernel set, threads and device.

    ``data`` (scene name -> :class:`~event_transforms.tactile.copies.SceneData`) replaces the
    simulated scenes, e.g. with your own recordings; it is sent to every worker. Without it,
    workers read the data cache.

    Returns:
        The ``results.json`` dict (on rank 0; other ranks of a torchrun group get ``{}``).
    """
    config = config or ProtocolConfig()
    if data is not None and config.resample == "fresh":  # a folder cannot draw new data: resample it
        config = replace(config, resample="bootstrap")
        if log:
            log("data per seed: the data are given (no new data can be drawn from them), so each seed reads its own "
                "bootstrap resample by recording instead of fresh data (resample='bootstrap')")
    fresh = config.resample == "fresh"
    scenes = list(scenes or SCENES)
    chosen = choose_methods(scenes, methods, full=full, data=data)
    if group not in ("scene", "method"):
        raise ValueError(f"group must be 'scene' or 'method', got {group!r}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive int, got {jobs!r}")
    out = Path(out)
    seeds = [int(s) for s in seeds]
    given = data
    plan = plan_run(scenes, chosen, seeds, config, group=group, budget_check=budget_check, data=given)
    start = time.perf_counter()
    commit = git_commit()  # the code that trains: read before the run, not after (the checkout may move)

    # Data first, in this process: the cache is written once, workers only read it. With fresh data
    # per seed, every seed draws its own data set (new grasps from the same sessions).
    by_seed: dict[int | None, dict[str, SceneData]]
    if fresh:
        by_seed = {seed: {scene: load_scene_data(scene, root, data_seed=seed) for scene in scenes} for seed in seeds}
    else:
        by_seed = {None: dict(given) if given is not None else {scene: load_scene_data(scene, root) for scene in scenes}}
    data = next(iter(by_seed.values()))  # the first data set: limits, timing, costs, sizes
    missing = [scene for scene in scenes if scene not in data]
    if missing:
        raise ValueError(f"data must hold every scene, missing {missing}")
    notes = check_run_limits(data, chosen, config, cli=cli)
    if log and not cli:  # the command line has printed them before its plan
        for note in notes:
            log(note)
    data_keys = {(scene, seed): data_key(d[scene]) for seed, d in by_seed.items() for scene in scenes}
    phases = phase_units(scenes, chosen, group, by_seed, plan["budget_check_scenes"], equal_time, given, seeds)
    units = phases.units
    count_phases(plan, phases, seeds, config)
    if log:
        for scene, d in data.items():
            holdout = f"{len(d.holdout)} hold-out (training session), " if d.holdout is not None else ""
            ready = sum(by_seed[s][scene].seconds for s in by_seed)
            log(f"data: scene {scene!r} ({d.scene.description}): {len(d.train)} train, {holdout}{len(d.val)} val, "
                f"{len(d.test)} test sequences" + (f" per seed, each seed its own ({len(by_seed)} data sets)"
                                                   if fresh else "") + f", ready in {ready:.1f} s")
        log(plan_line(plan, config))
        log(PROGRESS_LEGEND)
    options = (root, device, threads, log, progress, given, _prior_seconds(config, device))
    results = _runwork_units(units, seeds, config, out, jobs, options, "unit", plan["budget_member_steps"], data_keys)

    # The budget check: none and the scene's pre-declared headline (its matched method), at twice the steps.
    choices, budget_methods, budget_units = phases.choices, phases.budget_methods, phases.budget_units
    double = ProtocolConfig(**{**asdict(config), "steps": RULES.budget_factor * config.steps})
    budget_results = (_runwork_units(budget_units, seeds, double, out, jobs, options, "budget check", 0.0, data_keys)
                      if budget_units else {})
    # The cost curve: none at 1.5 × the steps (2 × is the budget check's), Δ of every method against it.
    curve_results: dict[float, tuple[list[Unit], dict[str, Any] | None]] = {}
    if equal_time and measure_time:
        for ratio in (r for r in CURVE_RATIOS if 1.0 < r < 2.0):
            curve_methods = {s: ("none",) for s in scenes}
            longer = ProtocolConfig(**{**asdict(config), "steps": round(ratio * config.steps)})
            curve_units = seed_units(curve_methods, group, given, by_seed)[0]
            curve_results[ratio] = (curve_units, _runwork_units(
                curve_units, seeds, longer, out, jobs, options, f"cost curve (none at {longer.steps} steps)", 0.0,
                data_keys))
    rank0 = results is not None and budget_results is not None  # else a torchrun rank other than 0
    timing = measure_timing(scenes, chosen, data, config, threads) if measure_time and rank0 else {}

    scene_results = {}
    for scene in scenes if rank0 else ():
        assert results is not None and budget_results is not None  # rank 0 holds every unit's result
        d = data[scene]
        sizes = {"train": len(d.train), "val": len(d.val), "test": len(d.test)}
        if d.holdout is not None:
            sizes["holdout"] = len(d.holdout)
        summary = summarize_scene(d.scene, _per_method(units, results, scene, chosen[scene]),
                                  _baselines(d, seeds, config.resample,
                                             {s: by_seed[s][scene] for s in seeds} if fresh else None), sizes)
        summary["generation_s"] = sum(by_seed[s][scene].seconds for s in by_seed)
        summary["data_per_seed"] = _data_identity(scene, by_seed, seeds, config.resample)
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
        if curve_results:
            none_at: dict[float, Any] = {}
            none_runs: dict[float, list[dict[str, Any]]] = {}
            for ratio, (curve_units, done) in curve_results.items():
                if done is not None:
                    none_runs[ratio] = _per_method(curve_units, done, scene, ("none",))["none"]
            if scene in budget_methods:
                none_runs[2.0] = _per_method(budget_units, budget_results, scene, ("none",))["none"]
            none_at = {ratio: _seed_values(records) for ratio, records in none_runs.items()}
            curve = cost_curve(summary["methods"], none_at)
            for ratio, records in none_runs.items():  # no resolved verdict from unconverged models
                none_done = converged(ensemble_drop(records))
                for method, points in curve.items():
                    point = points.get(f"{ratio:.1f}")
                    if point is not None and behind_unconverged(
                            point["mean"], none_done, summary["methods"][method].get("converged", True)):
                        point["not_converged"], point["significant"] = True, False
            summary["cost_curve"] = {"ratios": [1.0, *sorted(none_at)],
                                     "steps": {f"{r:.1f}": round(r * config.steps) for r in [1.0, *sorted(none_at)]},
                                     "methods": curve}
        if scene in choices:
            method = choices[scene]
            summary["budget_check"] = _budget_check(
                method, config.steps, summary["methods"][method]["delta_vs_none"],
                _per_method(budget_units, budget_results, scene, ("none", method)),
            )
        scene_results[scene] = summary

    # Equal cost: each method again for the steps its cost per step (from the cost table) leaves.
    costs: dict[str, Any] = {}
    if equal_time and measure_time:
        steps_of: dict[str, dict[str, int]] = {}
        if rank0:
            costs = _cost_table(cost_table, scenes, chosen, data, config, threads, out, log)
            for scene, summary in scene_results.items():
                for method, s_ in summary["methods"].items():
                    if method == "none" or s_.get("duplicate_of"):
                        continue
                    # a row without synthetic copies (with-labels) steps like none: ratio 1 by construction
                    plain = parse_method(method, scene=data[scene].scene).build(data[scene].noise_bank) is None
                    s_["cost_ratio"] = 1.0 if plain else ratio_of(costs, scene, method)
                    steps_of.setdefault(scene, {})[method] = equal_cost_steps(config.steps, s_["cost_ratio"])
        if distributed.current_group() is not None:
            steps_of = distributed.broadcast_from_rank0(steps_of)
        equal_runs: dict[str, dict[str, list]] = {}
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
                    equal_runs.setdefault(scene, {}).update(_per_method(mine, done, scene, names))
        for scene, per in steps_of.items() if rank0 else ():
            _attach_equal_time(scene_results[scene], per, equal_runs.get(scene, {}), config.steps)
    if not rank0:  # a torchrun rank other than 0
        return {}
    results_json = {
        "commit": commit,
        "rules": RULES.to_dict(),  # the decision rules the verdicts were judged by, with their version
        "config": {**asdict(config), "seeds": seeds, "scenes": scenes, "jobs": jobs, "device": device,
                   "threads_per_job": threads, "group": group, "full": full, "budget_check": budget_check,
                   "equal_time": equal_time},
        "plan": plan,
        "wall_s": time.perf_counter() - start,
        "environment": environment(device, threads),
        "timing": timing,
        "cost_table": {k: costs[k] for k in ("source", "config", "environment", "commit", "train_s_per_step")
                       if k in costs},
        "data": _describe_data(data, scenes),
        "data_per_seed": config.resample,  # fresh: each seed its own data set; bootstrap: resamples of one
        "scenes": scene_results,
    }
    write_json_atomic(out / "results.json", results_json)
    (out / "results.md").write_text(format_report(results_json) + "\n")
    return results_json
