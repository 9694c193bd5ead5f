"""The tactile application built on the library: the paper's grasping scenes, simulated.

Submodules (imported when first used, so ``import event_transforms`` stays light):

- :mod:`~event_transforms.tactile.simulation`: a seeded simulator of a bolt pressed into a
  silicone membrane watched by a DVS;
- :mod:`~event_transforms.tactile.generators`: the DVS pixel model both generators share and the
  optical generator (taxim; ``pip install 'event-transforms[optical]'``);
- :mod:`~event_transforms.tactile.scenes`: sessions and benchmark scenes (a gap and a control
  for each augmentation);
- :mod:`~event_transforms.tactile.datasets`: the simulated grasps as data sets, and noise banks;
- :mod:`~event_transforms.tactile.models`: the reference ConvLSTM force regressor;
- :mod:`~event_transforms.tactile.ensemble`: many force regressors run in lockstep (the ensemble model);
- :mod:`~event_transforms.tactile.baselines`: baselines the network must beat (trivial ones and a
  physics least-squares model);
- :mod:`~event_transforms.tactile.training`: the one trainer (:func:`~event_transforms.tactile.training.train`,
  ``fit_ensemble``, stopping rule, batch order), timing, scores;
- :mod:`~event_transforms.tactile.methods`: method names and which methods a scene runs;
- :mod:`~event_transforms.tactile.copies`: a scene's data, synthetic copies, the paired batch order;
- :mod:`~event_transforms.tactile.stats`: paired t-intervals, Wilcoxon signed-rank, Holm, summaries;
- :mod:`~event_transforms.tactile.report`: the benchmark's tables and findings;
- :mod:`~event_transforms.tactile.distributed`: local ranks, ``torchrun``, worker errors;
- :mod:`~event_transforms.tactile.protocol`: the protocol by job (config, plan, unit, run, timing,
  environment), every public name of the protocol in one place;
- :mod:`~event_transforms.tactile.recordings`: your own recordings (a folder layout,
  :class:`~event_transforms.tactile.recordings.RecordingSet`, the simulator's export);
- :mod:`~event_transforms.tactile.deployment`: train a model on recordings, stream force estimates;
- :mod:`~event_transforms.tactile.runs`: the protocol's run store (resume keys);
- :mod:`~event_transforms.tactile.cli`: the ``event-transforms`` command's arguments (the commands'
  bodies in :mod:`~event_transforms.tactile.commands`, the run's figures in
  :mod:`~event_transforms.tactile.figures`).

Results obtained on the simulated scenes are results on synthetic data, never the paper's.
"""

from __future__ import annotations

import importlib
from typing import Any

_SUBMODULES = (
    "simulation", "generators", "scenes", "datasets", "models", "ensemble", "baselines", "training", "methods",
    "copies", "experiment", "stats", "report", "distributed", "protocol", "cli", "commands", "figures", "recordings",
    "deployment", "runs",
)

#: Public names of the protocol, importable from here (loaded on first use).
_PROTOCOL_NAMES = (
    "PAPER_METHODS", "QUICK_METHODS", "PAPER_SCENE", "Method", "parse_method", "methods_for",
    "ProtocolConfig", "SceneData", "load_scene_data", "MaterializedDataset", "OnlineCopies",
    "DeviceAugment", "build_training_set", "paired_batches", "run_unit", "run_protocol", "plan_run",
    "PROGRESS_LEGEND", "summarize_scene", "format_scene_table", "format_budget_check", "format_findings",
    "format_report",
)

#: Public names of :mod:`~event_transforms.tactile.recordings`, importable from here.
_RECORDING_NAMES = ("RecordingSet", "RecordingSettings", "load_recording_data", "export_scene")

__all__ = [*_SUBMODULES, *_PROTOCOL_NAMES, *_RECORDING_NAMES]


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _RECORDING_NAMES:
        return getattr(importlib.import_module(f"{__name__}.recordings"), name)
    if name in _PROTOCOL_NAMES:
        return getattr(importlib.import_module(f"{__name__}.protocol"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
