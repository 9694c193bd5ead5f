"""What a protocol run will do before it does it: work units, each scene's methods, the cost.

A unit is a scene's methods (``group="scene"``) or one method of a scene (``group="method"``);
:func:`work_units` orders them costly first, :func:`choose_methods` checks every method name
before any work, :func:`plan_run` counts members and member-steps (the budget check's and the
equal-time retraining's included).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..copies import SceneData
from ..methods import methods_for, parse_method
from ..scenes import BenchmarkScene, get_scene
from .config import ProtocolConfig
from .shared import Sharing
from .rules import RULES

__all__ = ["Unit", "resolve_scene", "work_units", "budget_scenes", "choose_methods", "plan_run"]


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
