"""The run's report, the last stage of a run: ``results.json`` and ``results.md``
(:func:`write_results`; the tables are :func:`~event_transforms.tactile.report.format_report`'s).

``results.json`` records the decision rules and their version, the configuration, the plan, the
environment (:func:`~event_transforms.tactile.protocol.environment.environment`: package version
and commit, torch, CPU model, kernel set, threads and device), the time columns, the cost table's
provenance, what the data are, and every scene's statistics.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict
from typing import Any

from .._files import write_json_atomic
from ..copies import SceneData
from ..report import format_report
from .config import RunSettings
from .environment import environment
from .phases import Trained
from .plan import ProtocolPlan
from .rules import RULES

__all__ = ["write_results"]


def write_results(settings: RunSettings, plan: ProtocolPlan, trained: Trained,
                  scenes: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Write ``results.json`` and ``results.md`` into ``settings.out``.

    Args:
        settings: the run's settings (:func:`~event_transforms.tactile.protocol.config.read_settings`).
        plan: the run's plan (:func:`~event_transforms.tactile.protocol.plan.plan_protocol`).
        trained: what the run trained (:func:`~event_transforms.tactile.protocol.phases.train_protocol`).
        scenes: each scene's statistics (:func:`~event_transforms.tactile.protocol.statistics.summarize_protocol`).

    Returns:
        The ``results.json`` dict.
    """
    config, costs = settings.config, trained.costs
    results_json = {
        "commit": settings.commit,
        "rules": RULES.to_dict(),  # the decision rules the verdicts were judged by, with their version
        "config": {**asdict(config), "seeds": settings.seeds, "scenes": settings.scenes, "jobs": settings.jobs,
                   "device": settings.device, "threads_per_job": settings.threads, "group": settings.group,
                   "full": settings.full, "budget_check": settings.budget_check, "equal_time": settings.equal_time},
        "plan": plan.counts,
        "wall_s": time.perf_counter() - settings.start,
        "environment": environment(settings.device, settings.threads),
        "timing": trained.timing,
        "cost_table": {k: costs[k] for k in ("source", "config", "environment", "commit", "train_s_per_step")
                       if k in costs},
        "data": _describe_data(plan.data, settings.scenes),
        "data_per_seed": config.resample,  # fresh: each seed its own data set; bootstrap: resamples of one
        "scenes": scenes,
    }
    write_json_atomic(settings.out / "results.json", results_json)
    (settings.out / "results.md").write_text(format_report(results_json) + "\n")
    return results_json


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
