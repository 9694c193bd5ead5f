"""Cost from a table, not a stopwatch: each method's cost per training step, relative to ``none``.

MSE at equal cost retrains every method for the steps its online augmentation leaves in the
time ``none`` takes for the run's steps. Reading those step counts off a stopwatch during the
run made them move with the machine's load (the same method got 200 steps in one run and 175
in the next). So the protocol reads them from a **cost table**: per scene and method, the ratio
of one training step with the method's online augmentation to one plain step,

    ratio = 1 + (augmentation seconds per step) / (training seconds per step),

measured once by :func:`measure_costs` — the plain training and every method's augmentation
timed in turns (interleaved, so a change of load hits both), the ratio the median over
``repeats`` rounds — and kept with the machine it was measured on. A method then affords
``equal_cost_steps(steps, ratio) = floor(steps / ratio)`` steps: no rounding to a grain, and
the same count on every machine that reads the same table. The README's quick run reads the
committed table (``cost_table_quick.json`` beside this module; ``python
benchmarks/tactile/cost_table.py`` measures it again); a run whose configuration the table was not
measured for measures its own at the start and writes it to ``OUT/cost_table.json``. Wall times
stay in the tables as measured, named as such.

Example:
    >>> equal_cost_steps(300, 1.25), equal_cost_steps(300, 1.0), equal_cost_steps(300, 3.9)
    (240, 300, 76)
"""

from __future__ import annotations

import json
import math
import statistics
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from ..copies import OnlineCopies, SceneData
from ..methods import parse_method
from .config import ProtocolConfig
from .environment import environment, git_commit
from .timing import online_augmentation_cost
from .unit import run_unit

__all__ = ["COST_TABLE_FORMAT", "QUICK_COST_TABLE", "CURVE_RATIOS", "cost_key", "measure_costs", "equal_cost_steps",
           "load_cost_table", "ratio_of", "cost_curve"]

#: The cost ratios of the published curve: Δ of each method at the run's steps against ``none``
#: trained for ``ratio`` × the steps (1: the main table's Δ; 2: ``none`` of the budget check).
CURVE_RATIOS = (1.0, 1.5, 2.0)

#: The format of a cost table file.
COST_TABLE_FORMAT = 1
#: The committed cost table of the README's quick configuration.
QUICK_COST_TABLE = Path(__file__).resolve().parent / "cost_table_quick.json"



def cost_key(config: ProtocolConfig) -> dict[str, Any]:
    """What a cost ratio depends on besides the method: the batch, the copies and the model."""
    settings = asdict(config)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in settings.items()
            if k in ("batch_size", "copies", "hidden_channels", "input_pool", "cumulative")}


def equal_cost_steps(steps: int, ratio: float) -> int:
    """The steps a method of cost ``ratio`` (per step, relative to ``none``) affords in the time
    ``none`` takes for ``steps``: ``floor(steps / ratio)``, at least 1, at most ``steps``.

    Raises:
        ValueError: ``ratio`` is not a finite number of at least 1.
    """
    if not (isinstance(ratio, (int, float)) and math.isfinite(ratio) and ratio >= 1.0):
        raise ValueError(f"ratio must be a finite number >= 1 (a step with augmentation costs at least one "
                         f"without), got {ratio!r}")
    return min(steps, max(1, math.floor(steps / ratio + 1e-9)))


def _train_seconds_per_step(scene: Any, data: SceneData, config: ProtocolConfig, steps: int) -> float:
    tick = time.perf_counter()
    run_unit(scene, ["none"], [0], ProtocolConfig(**{**asdict(config), "steps": steps}), data, progress=False)
    return (time.perf_counter() - tick) / steps


def measure_costs(scenes: Sequence[str], chosen: Mapping[str, Sequence[str]], data: Mapping[str, SceneData],
                  config: ProtocolConfig, *, repeats: int = 5, probe_steps: int = 50,
                  threads: int | None = 1) -> dict[str, Any]:
    """The cost table of a run: per scene and method, one step with online augmentation over one
    plain step, interleaved (each round times ``probe_steps`` plain training steps, then every
    method's augmentation of one epoch) and the median over ``repeats`` rounds.

    Returns:
        ``{"format", "config", "repeats", "train_s_per_step", "ensemble_s_per_member_step",
        "ratios": {scene: {method: ratio}}, "environment", "commit"}``; ``none`` and methods
        without copies have ratio 1.
    """
    if threads:
        torch.set_num_threads(threads)
    first = scenes[0]
    per_round: dict[str, dict[str, list[float]]] = {s: {m: [] for m in chosen[s]} for s in scenes}
    train_steps: list[float] = []
    for _ in range(repeats):
        train = _train_seconds_per_step(data[first].scene, data[first], config, probe_steps)
        train_steps.append(train)
        for scene in scenes:
            for method in chosen[scene]:
                aug = online_augmentation_cost(method, data[scene].scene, data[scene], batch_size=config.batch_size,
                                               copies=config.copies, repeats=1)
                if aug is None:
                    per_round[scene][method].append(1.0)
                    continue
                parsed = parse_method(method, copies=config.copies, scene=data[scene].scene)
                items = len(OnlineCopies(data[scene].train, parsed.copies))
                per_round[scene][method].append(1.0 + aug * config.batch_size / items / train)
    # what --plan multiplies member-steps by: one member-step of an ensemble of 32 (none x 32 seeds), a unit's size
    tick = time.perf_counter()
    run_unit(data[first].scene, ["none"], list(range(32)), ProtocolConfig(**{**asdict(config), "steps": probe_steps}),
             data[first], progress=False)
    member_step = (time.perf_counter() - tick) / (32 * probe_steps)
    return {
        "format": COST_TABLE_FORMAT,
        "config": cost_key(config),
        "repeats": repeats,
        "train_s_per_step": statistics.median(train_steps),
        "ensemble_s_per_member_step": member_step,
        "ratios": {s: {m: statistics.median(v) for m, v in per.items()} for s, per in per_round.items()},
        "environment": environment("cpu", threads),
        "commit": git_commit(),
    }


def load_cost_table(source: str | Path | Mapping[str, Any]) -> dict[str, Any]:
    """A cost table from a file (or a dict), checked: its format and ratios of at least 1.

    Raises:
        ValueError: the file is no cost table of this format, or a ratio is below 1.
    """
    try:
        table = dict(source) if isinstance(source, Mapping) else json.loads(Path(source).read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f"cost table {source}: cannot be read as JSON ({error})") from None
    if table.get("format") != COST_TABLE_FORMAT or not isinstance(table.get("ratios"), dict):
        raise ValueError(f"cost table {source if not isinstance(source, Mapping) else '(given)'}: not a cost table of "
                         f"format {COST_TABLE_FORMAT} (measure one with benchmarks/tactile/cost_table.py)")
    for scene, per in table["ratios"].items():
        for method, ratio in per.items():
            equal_cost_steps(1, ratio)  # refuses a ratio below 1 or not finite, by name below
    return table


def ratio_of(table: Mapping[str, Any], scene: str, method: str) -> float:
    """The table's ratio for ``method`` on ``scene``.

    Raises:
        ValueError: the table has none (naming the scene, the method and how to measure it).
    """
    ratio = table["ratios"].get(scene, {}).get(method)
    if ratio is None:
        raise ValueError(f"the cost table has no ratio for {method!r} on scene {scene!r}: measure one for this run "
                         "(reproduce without --cost-table measures its own) or with benchmarks/tactile/cost_table.py")
    return float(ratio)


def cost_curve(methods: Mapping[str, Any], none_at: Mapping[float, Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Δ against steps, for a reader's own cost ratio: per method (not ``none``, not a duplicate
    row), its test MSE at the run's steps against ``none`` trained for ``ratio`` × those steps,
    paired by seed, with the Bonferroni interval of the scene's family (the methods that have the
    point). A method whose augmentation costs ``r`` × a plain step is at equal cost with ``none``
    at ``ratio = r``: read the curve there.

    Args:
        methods: a scene's ``methods`` of ``results.json`` (``{"seeds", "test_mse", ...}``).
        none_at: per ratio above 1, ``none``'s ``{"seeds", "test_mse"}`` at ``ratio`` × the steps.

    Returns:
        ``{method: {ratio (str): Δ dict}}``, the ratio 1 being the main table's Δ vs none.

    Example:
        >>> methods = {"none": {"seeds": [0, 1, 2], "test_mse": [2.0, 2.2, 2.1]},
        ...            "fs1": {"seeds": [0, 1, 2], "test_mse": [1.0, 1.3, 1.1]}}
        >>> curve = cost_curve(methods, {2.0: {"seeds": [0, 1, 2], "test_mse": [1.5, 1.6, 1.7]}})
        >>> sorted(curve["fs1"]), round(curve["fs1"]["2.0"]["mean"], 2)
        (['1.0', '2.0'], -0.47)
    """
    from ..stats import family_prior, paired_delta

    family = [m for m, s in methods.items() if m != "none" and not s.get("duplicate_of")]
    out: dict[str, dict[str, Any]] = {m: {} for m in family}
    points = {1.0: methods.get("none"), **{float(r): v for r, v in none_at.items()}}
    for ratio, none in sorted(points.items()):
        if none is None:
            continue
        prior = family_prior(dict(none), {m: dict(methods[m]) for m in family}, "test_mse")
        for method in family:
            delta = paired_delta(dict(none), dict(methods[method]), "test_mse", len(family), prior)
            if delta is not None:
                out[method][f"{ratio:.1f}"] = delta
    return out
