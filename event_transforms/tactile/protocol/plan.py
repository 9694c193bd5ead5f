"""What a protocol run will do before it does it, the second stage of a run: each scene's
methods, the data, every limit checked, the units of every phase, the cost (:func:`plan_protocol`).

A unit is a scene's methods (``group="scene"``) or one method of a scene (``group="method"``);
:func:`work_units` orders them costly first, :func:`choose_methods` checks every method name
before any work, :func:`plan_run` counts members and member-steps (the budget check's and the
equal-time retraining's included); :func:`phase_units` lists the units each phase trains after
train-once sharing (:mod:`~event_transforms.tactile.protocol.shared`) and :func:`count_phases`
adds them to the plan.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch

from ..copies import SceneData, load_scene_data
from ..methods import methods_for, parse_method
from ..runs import data_key
from ..benchmark_scenes import BenchmarkScene, get_scene
from .config import ProtocolConfig, RunSettings
from .limits import check_run_limits
from .rules import RULES
from .shared import Sharing, plan_sharing

__all__ = ["Unit", "resolve_scene", "work_units", "budget_scenes", "choose_methods", "plan_run", "Phases",
           "per_seed_data", "seed_units", "phase_units", "count_phases", "plan_line", "headline", "ProtocolPlan",
           "plan_protocol", "PROGRESS_LEGEND"]


@dataclass
class Unit:
    """A unit of work: ``methods`` of ``scene``, trained together as one ensemble, and scored too
    for the ``also`` members other scenes borrow (``(method, scene, its method)``; see
    :mod:`~event_transforms.tactile.protocol.shared`), for ``steps`` steps where it names its own.
    With fresh data per seed a unit holds one ``seed`` (its members read that seed's own data
    set); ``None``: every seed of the run."""

    scene: str
    methods: tuple[str, ...]
    also: tuple[tuple[str, str, str], ...] = ()
    #: the unit's own step count (the equal-cost phase: one per cost ratio); ``None``: the phase's
    steps: int | None = None
    #: the one seed whose own data set the unit trains on (fresh data per seed); ``None``: all seeds
    seed: int | None = None

    @property
    def slug(self) -> str:
        at = "" if self.steps is None else f"@{self.steps}"
        own = "" if self.seed is None else f"__seed{self.seed}"
        return re.sub(r"[^a-z0-9.+@-]+", "_", f"{self.scene}__{'+'.join(self.methods)}{at}{own}".lower())

    def members(self, seeds: Sequence[int]) -> int:
        """How many members the unit trains in a run of ``seeds``."""
        return len(self.methods) * (1 if self.seed is not None else len(seeds))


def resolve_scene(scene: str, data: dict[str, SceneData] | None) -> BenchmarkScene:
    """A scene by name: the given data's own scene (e.g. a folder of recordings), else a built-in one."""
    if isinstance(scene, str) and data and scene in data:
        return data[scene].scene
    return get_scene(scene)


def work_units(
    scenes: Sequence[str], methods: Mapping[str, Sequence[str]], group: str, data: dict[str, SceneData] | None = None,
    sharing: Sharing | None = None,
) -> list[Unit]:
    """Work units; the costly ones (many copies) first, so ranks finish together. With
    ``sharing``, only the members a scene owns are trained, each unit scored also for its
    borrowers; a scene that owns none has no unit."""
    units: list[Unit] = []
    for scene in scenes:
        names = tuple(methods.get(scene, ())) if sharing is None else sharing.owned.get(scene, ())
        if not names:
            continue
        if group == "scene":  # one ensemble per model setting (none-local's model is another)
            models: dict[Any, list[str]] = {}
            for name in names:
                models.setdefault(parse_method(name, scene=resolve_scene(scene, data)).model, []).append(name)
            units.extend(Unit(scene, tuple(ms), sharing.also(scene, tuple(ms)) if sharing else ())
                         for ms in models.values())
        else:
            units.extend(Unit(scene, (m,), sharing.also(scene, (m,)) if sharing else ()) for m in names)
    return sorted(units, key=lambda u: -max(parse_method(m, scene=resolve_scene(u.scene, data)).copies for m in u.methods))


def budget_scenes(
    scenes: Sequence[str], chosen: Mapping[str, Sequence[str]], data: dict[str, SceneData] | None = None
) -> list[str]:
    """The scenes whose headline gets a budget check: a gap, ``none`` and a matched method."""
    return [s for s in scenes if resolve_scene(s, data).gaps and "none" in chosen[s]
            and any(m in chosen[s] and m != "none" for m in resolve_scene(s, data).matched_methods)]


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
    resolved = {s: resolve_scene(s, data) for s in scenes}
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
    equal_time: bool = False,
) -> dict[str, Any]:
    """What a run costs before it starts: units, members and member-steps (one member = one
    method × seed trained for ``config.steps``), the budget check's share included.

    Multiply ``member_steps`` by the measured seconds per member-step (printed after a unit:
    ``ensemble_train_s / (ensemble_members · steps)`` in a unit file) for the run's time. With
    ``equal_time``, ``equal_time_member_steps_max`` bounds the retraining at equal wall time
    (its steps depend on the timings measured after the main units).

    Example:
        >>> plan = plan_run(["control", "timing"], {"control": ["none", "fs2"], "timing": ["none", "fs2"]},
        ...                 range(8), ProtocolConfig(steps=100, resample="bootstrap"))
        >>> plan["units"], plan["members"], plan["member_steps"], plan["budget_member_steps"]
        (4, 32, 3200, 3200)
        >>> plan_run(["control"], {"control": ["none", "fs2"]}, range(8), ProtocolConfig(steps=100))["units"]
        16
    """
    units = work_units(scenes, methods, group, data)
    members = sum(len(u.methods) for u in units) * len(seeds)
    checked = budget_scenes(scenes, methods, data) if budget_check else []
    budget_members = 2 * len(checked) * len(seeds)
    per_seed = len(seeds) if config.resample == "fresh" and data is None else 1  # fresh data: a unit per seed
    return {
        "units": len(units) * per_seed,
        "members": members,
        "member_steps": members * config.steps,
        "budget_check_scenes": checked,
        "budget_units": (len(checked) if group == "scene" else 2 * len(checked)) * per_seed,
        "budget_members": budget_members,
        "budget_member_steps": budget_members * RULES.budget_factor * config.steps,
        "total_member_steps": members * config.steps + budget_members * RULES.budget_factor * config.steps,
        # equal wall time retrains every method but none for at most config.steps (known after timing)
        "equal_time_member_steps_max": (
            sum(len([m for m in methods[s] if m != "none"]) for s in scenes) * len(seeds) * config.steps
            if equal_time else 0
        ),
    }


#: What the columns of the plain progress lines mean (printed once at the start of a run).
PROGRESS_LEGEND = (
    "progress lines: [rank r] unit k/N (this unit's place among all units of the run) scene: methods — "
    "step s/S of this unit; train MSE = the last step's training MSE, mean over the unit's members "
    "(each method × seed), N²; hold-out MSE a–b = lowest–highest member MSE on the hold-out sequences "
    "of the training session (the stopping rule's data, never deployment data), N²; ETA = this unit's "
    "time left, then the whole run's on this rank (budget check included)"
)


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


@dataclass
class ProtocolPlan:
    """What :func:`plan_protocol` settles before any training: each scene's methods
    (``chosen``), the plan's counts (``counts``: :func:`plan_run` completed by
    :func:`count_phases`, the ``plan`` of ``results.json``), the data (``by_seed``: ``{seed:
    {scene: SceneData}}`` with fresh data per seed, else ``{None: ...}``; ``data``: the first data
    set, which limits, timing, costs and sizes read), each data set's content key
    (``data_keys``) and the units of every phase (``phases``)."""

    chosen: dict[str, tuple[str, ...]]
    counts: dict[str, Any]
    by_seed: dict[int | None, dict[str, SceneData]]
    data: dict[str, SceneData]
    data_keys: dict[tuple[str, int | None], str]
    phases: Phases


def plan_protocol(settings: RunSettings) -> ProtocolPlan:
    """The run's plan: every method name checked, the cost counted, the data loaded (in this
    process: the cache is written once, workers only read it; with fresh data per seed every
    seed draws its own data set, new grasps from the same sessions), every limit of the data
    checked (:func:`~event_transforms.tactile.protocol.limits.check_run_limits`) and the units
    of every phase listed; the data and the plan said through ``settings.log``.

    Args:
        settings: the run's settings (:func:`~event_transforms.tactile.protocol.config.read_settings`).

    Returns:
        The :class:`ProtocolPlan` every later stage reads.

    Raises:
        ValueError: a method name unknown, the given data missing a scene, or a limit of the data
            exceeded, before any training.
    """
    scenes, seeds, config, given, log = settings.scenes, settings.seeds, settings.config, settings.given, settings.log
    chosen = choose_methods(scenes, settings.methods, full=settings.full, data=given)
    counts = plan_run(scenes, chosen, seeds, config, group=settings.group, budget_check=settings.budget_check,
                      data=given)
    by_seed: dict[int | None, dict[str, SceneData]]
    # the data are made here, in this process, before any worker starts: at the run's threads per job
    # (torch's default, every core, contends with the workers and other jobs: measured 10x slower)
    previous = torch.get_num_threads()
    if settings.threads:
        torch.set_num_threads(settings.threads)
    try:
        if settings.fresh:
            by_seed = {seed: {scene: load_scene_data(scene, settings.root, data_seed=seed) for scene in scenes}
                       for seed in seeds}
        else:
            by_seed = {None: dict(given) if given is not None else {scene: load_scene_data(scene, settings.root)
                                                                     for scene in scenes}}
    finally:
        torch.set_num_threads(previous)
    data = next(iter(by_seed.values()))  # the first data set: limits, timing, costs, sizes
    missing = [scene for scene in scenes if scene not in data]
    if missing:
        raise ValueError(f"data must hold every scene, missing {missing}")
    notes = check_run_limits(data, chosen, config, cli=settings.cli)
    if log and not settings.cli:  # the command line has printed them before its plan
        for note in notes:
            log(note)
    data_keys = {(scene, seed): data_key(d[scene]) for seed, d in by_seed.items() for scene in scenes}
    phases = phase_units(scenes, chosen, settings.group, by_seed, counts["budget_check_scenes"], settings.equal_time,
                         given, seeds)
    count_phases(counts, phases, seeds, config)
    if log:
        for scene, d in data.items():
            holdout = f"{len(d.holdout)} hold-out (training session), " if d.holdout is not None else ""
            ready = sum(by_seed[s][scene].seconds for s in by_seed)
            log(f"data: scene {scene!r} ({d.scene.description}): {len(d.train)} train, {holdout}{len(d.val)} val, "
                f"{len(d.test)} test sequences" + (f" per seed, each seed its own ({len(by_seed)} data sets)"
                                                   if settings.fresh else "") + f", ready in {ready:.1f} s")
        log(plan_line(counts, config))
        log(PROGRESS_LEGEND)
    return ProtocolPlan(chosen, counts, by_seed, data, data_keys, phases)
