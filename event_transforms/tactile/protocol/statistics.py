"""The run's statistics, the fourth stage of a run: each scene's entry of ``results.json`` from
the trained units (:func:`summarize_protocol`).

Per scene: the rows' per-seed values and Δ vs ``none``
(:func:`~event_transforms.tactile.stats.summarize_scene`), the baselines (fitted and scored on
each seed's data, as the networks are), which data each seed read, the time columns, the cost
curve, the budget check (:func:`~event_transforms.tactile.protocol.recompute.judge_budget`) and
the rows at equal cost. Results on the package's simulated scenes are results on synthetic data,
not the paper's.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from typing import Any

from ..copies import SceneData, data_seed_offset
from ..resampling import split_resample
from ..stats import behind_unconverged, converged, deltas_vs_none, ensemble_drop, summarize_scene
from .config import RunSettings
from .costs import cost_curve
from .phases import Trained
from .plan import ProtocolPlan
from .recompute import judge_budget
from .shared import content_key, records_by_method, seed_values, training_key

__all__ = ["summarize_protocol"]


def summarize_protocol(settings: RunSettings, plan: ProtocolPlan, trained: Trained) -> dict[str, dict[str, Any]]:
    """Each scene's entry of ``results.json`` (``scenes.NAME``), from rank 0's results.

    Args:
        settings: the run's settings (:func:`~event_transforms.tactile.protocol.config.read_settings`).
        plan: the run's plan (:func:`~event_transforms.tactile.protocol.plan.plan_protocol`).
        trained: what the run trained (:func:`~event_transforms.tactile.protocol.phases.train_protocol`).

    Returns:
        ``{scene: its entry}``, in the run's scene order; nothing given is modified.
    """
    seeds, config, by_seed, data, phases = settings.seeds, settings.config, plan.by_seed, plan.data, plan.phases
    scene_results = {}
    for scene in settings.scenes:
        d = data[scene]
        sizes = {"train": len(d.train), "val": len(d.val), "test": len(d.test)}
        if d.holdout is not None:
            sizes["holdout"] = len(d.holdout)
        summary = summarize_scene(d.scene, records_by_method(phases.units, trained.results, scene, plan.chosen[scene]),
                                  _baselines(d, seeds, config.resample,
                                             {s: by_seed[s][scene] for s in seeds} if settings.fresh else None), sizes)
        summary["generation_s"] = sum(by_seed[s][scene].seconds for s in by_seed)
        summary["data_per_seed"] = _data_identity(scene, by_seed, seeds, config.resample)
        dataset = getattr(d, "dataset", None)
        if isinstance(dataset, dict):  # a folder of recordings: how many recordings the intervals rest on
            summary["recordings"] = dataset["recordings"]
            summary["dataset"] = dataset
        timing = trained.timing
        if timing:
            wall = timing["single_model_wall_s"]
            epochs_of = lambda s_: config.steps * config.batch_size / max(s_["train_items"], 1)  # noqa: E731
            for method, s_ in summary["methods"].items():
                cost = timing["online_aug_s_per_epoch"][scene].get(method)
                s_["single_wall_s"] = wall
                s_["online_aug_s_per_epoch"] = cost
                s_["online_wall_s"] = wall["median"] + (cost or 0.0) * epochs_of(s_)
        if trained.curve:
            none_at: dict[float, Any] = {}
            none_runs: dict[float, list[dict[str, Any]]] = {}
            for ratio, (curve_units, done) in trained.curve.items():
                if done is not None:
                    none_runs[ratio] = records_by_method(curve_units, done, scene, ("none",))["none"]
            if scene in phases.budget_methods:
                none_runs[2.0] = records_by_method(phases.budget_units, trained.budget, scene, ("none",))["none"]
            none_at = {ratio: seed_values(records) for ratio, records in none_runs.items()}
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
        if scene in phases.choices:
            method = phases.choices[scene]
            summary["budget_check"] = _budget_check(
                method, config.steps, summary["methods"][method]["delta_vs_none"],
                records_by_method(phases.budget_units, trained.budget, scene, ("none", method)),
            )
        scene_results[scene] = summary
    for scene, ratios in trained.cost_ratio.items():
        for method, ratio in ratios.items():
            scene_results[scene]["methods"][method]["cost_ratio"] = ratio
    for scene, per in trained.steps_of.items():
        _attach_equal_time(scene_results[scene], per, trained.equal_runs.get(scene, {}), config.steps)
    return scene_results


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


def _budget_check(method: str, steps: int, delta: dict[str, Any], runs_2n: dict[str, list]) -> dict[str, Any]:
    """The headline's Δ at ``steps`` and at twice the steps, judged by :func:`judge_budget` (with
    both rows' per-seed test MSEs at twice the steps, recorded so the verdict can be recomputed)."""
    converged_2n = all(converged(ensemble_drop(runs_2n[m])) for m in ("none", method))
    return judge_budget(method, steps, delta, seed_values(runs_2n["none"]), seed_values(runs_2n[method]),
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
