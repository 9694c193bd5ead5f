"""The benchmark protocol, in one place to import from: every scene, every method, paired
seeds, equal budgets, statistics, tables.

The protocol's own modules, one job each, in the order a run enters them:

- :mod:`~event_transforms.tactile.protocol.config`: the settings (:class:`ProtocolConfig`);
- :mod:`~event_transforms.tactile.protocol.plan`: work units, each scene's methods
  (:func:`~event_transforms.tactile.protocol.plan.choose_methods`) and the cost (:func:`plan_run`);
- :mod:`~event_transforms.tactile.protocol.limits`: every limit of the data checked before any
  training (:func:`~event_transforms.tactile.protocol.limits.check_run_limits`);
- :mod:`~event_transforms.tactile.protocol.unit`: one unit trained and scored (:func:`run_unit`;
  the training is the one trainer, :func:`~event_transforms.tactile.training.train`);
- :mod:`~event_transforms.tactile.protocol.run`: the resumable run with its budget check
  (:func:`run_protocol`);
- :mod:`~event_transforms.tactile.protocol.timing`: the time columns and equal wall time;
- :mod:`~event_transforms.tactile.protocol.environment`: what a result depends on besides the code.

Their public names, and those of the modules the protocol uses, are re-exported here:

- :mod:`~event_transforms.tactile.methods`: method names (:func:`parse_method`) and which
  methods a scene runs (:func:`methods_for`);
- :mod:`~event_transforms.tactile.copies`: a scene's data (:class:`SceneData`), training sets
  with synthetic copies, and the paired batch order (:func:`paired_batches`);
- :mod:`~event_transforms.tactile.stats`: Δ vs ``none``, intervals, Holm (:func:`summarize_scene`);
- :mod:`~event_transforms.tactile.report`: tables and findings (:func:`format_report`);
- :mod:`~event_transforms.tactile.distributed`: local ranks, ``torchrun``, worker errors.
"""

from __future__ import annotations

from ..copies import (
    DeviceAugment,
    MaterializedDataset,
    OnlineCopies,
    SceneData,
    build_training_set,
    load_scene_data,
    paired_batches,
)
from ..methods import PAPER_METHODS, PAPER_SCENE, QUICK_METHODS, Method, methods_for, parse_method
from ..report import format_budget_check, format_findings, format_report, format_scene_table
from ..stats import summarize_scene
from .config import ProtocolConfig
from .limits import check_run_limits
from .plan import plan_run
from .run import PROGRESS_LEGEND, run_protocol
from .unit import run_unit

__all__ = [
    "PAPER_METHODS", "QUICK_METHODS", "PAPER_SCENE", "Method", "parse_method", "methods_for",
    "ProtocolConfig", "SceneData", "load_scene_data", "MaterializedDataset", "OnlineCopies", "DeviceAugment",
    "build_training_set", "paired_batches", "run_unit", "run_protocol", "plan_run", "check_run_limits", "PROGRESS_LEGEND",
    "summarize_scene", "format_scene_table", "format_budget_check", "format_findings", "format_report",
]
