"""The benchmark protocol, in one place to import from: every scene, every method, paired
seeds, equal budgets, statistics, tables.

The work is done by modules with one job each, and their public names are re-exported here:

- :mod:`~event_transforms.tactile.methods`: method names (:func:`parse_method`) and which
  methods a scene runs (:func:`methods_for`);
- :mod:`~event_transforms.tactile.copies`: a scene's data (:class:`SceneData`), training sets
  with synthetic copies, and the paired batch order (:func:`paired_batches`);
- :mod:`~event_transforms.tactile.experiment`: settings (:class:`ProtocolConfig`), one unit
  (:func:`run_unit`), the resumable run with its budget check (:func:`run_protocol`) and its
  cost (:func:`plan_run`);
- :mod:`~event_transforms.tactile.stats`: Δ vs ``none``, intervals, Holm (:func:`summarize_scene`);
- :mod:`~event_transforms.tactile.report`: tables and findings (:func:`format_report`);
- :mod:`~event_transforms.tactile.distributed`: local ranks, ``torchrun``, worker errors.
"""

from __future__ import annotations

from .copies import (
    DeviceAugment,
    MaterializedDataset,
    OnlineCopies,
    SceneData,
    build_training_set,
    load_scene_data,
    paired_batches,
)
from .experiment import PROGRESS_LEGEND, ProtocolConfig, plan_run, run_protocol, run_unit
from .methods import PAPER_METHODS, PAPER_SCENE, QUICK_METHODS, Method, methods_for, parse_method
from .report import format_budget_check, format_findings, format_report, format_scene_table
from .stats import summarize_scene

__all__ = [
    "PAPER_METHODS", "QUICK_METHODS", "PAPER_SCENE", "Method", "parse_method", "methods_for",
    "ProtocolConfig", "SceneData", "load_scene_data", "MaterializedDataset", "OnlineCopies", "DeviceAugment",
    "build_training_set", "paired_batches", "run_unit", "run_protocol", "plan_run", "PROGRESS_LEGEND",
    "summarize_scene", "format_scene_table", "format_budget_check", "format_findings", "format_report",
]
