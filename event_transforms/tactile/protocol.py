"""The benchmark protocol, in one place to import from: every scene, every method, paired
seeds, equal budgets, statistics, tables.

The work is done by modules with one job each, and their public names are re-exported here:

- :mod:`~event_transforms.tactile.methods`: method names (:func:`parse_method`) and which
  methods a scene runs (:func:`methods_for`);
- :mod:`~event_transforms.tactile.experiment`: settings (:class:`ProtocolConfig`), a scene's
  data and training sets, one unit (:func:`run_unit`), the resumable run (:func:`run_protocol`);
- :mod:`~event_transforms.tactile.stats`: Δ vs ``none``, intervals, Holm (:func:`summarize_scene`);
- :mod:`~event_transforms.tactile.report`: tables and findings (:func:`format_report`);
- :mod:`~event_transforms.tactile.distributed`: local ranks, ``torchrun``, worker errors.
"""

from __future__ import annotations

from .experiment import (
    DeviceAugment,
    MaterializedDataset,
    OnlineCopies,
    ProtocolConfig,
    SceneData,
    build_training_set,
    load_scene_data,
    run_protocol,
    run_unit,
)
from .methods import PAPER_METHODS, PAPER_SCENE, QUICK_METHODS, Method, methods_for, parse_method
from .report import format_findings, format_report, format_scene_table
from .stats import summarize_scene

__all__ = [
    "PAPER_METHODS",
    "QUICK_METHODS",
    "PAPER_SCENE",
    "Method",
    "parse_method",
    "methods_for",
    "ProtocolConfig",
    "SceneData",
    "load_scene_data",
    "MaterializedDataset",
    "OnlineCopies",
    "DeviceAugment",
    "build_training_set",
    "run_unit",
    "run_protocol",
    "summarize_scene",
    "format_scene_table",
    "format_findings",
    "format_report",
]
