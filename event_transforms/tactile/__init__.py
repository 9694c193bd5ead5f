"""The tactile application built on the library: the paper's grasping scenes, simulated.

Submodules (imported when first used, so ``import event_transforms`` stays light):

- :mod:`~event_transforms.tactile.simulation`: a seeded simulator of a bolt pressed into a
  silicone membrane watched by a DVS;
- :mod:`~event_transforms.tactile.generators`: the DVS pixel model both generators share and the
  optical generator (taxim; ``pip install 'event-transforms[optical]'``);
- :mod:`~event_transforms.tactile.benchmark_scenes`: sessions and benchmark scenes (a gap and a control
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

``__all__`` lists what a user calls: the command line (:func:`main`), the model
(:class:`~event_transforms.tactile.models.ForceRegressor`), your recordings (:class:`RecordingSet`,
:func:`load_recording_data`, :func:`export_scene`, :func:`convert_bag`), and each command's Python
entry point (``reproduce``: :func:`run_protocol` with :class:`ProtocolConfig`; ``train`` /
``predict``: :func:`train_model` / :func:`predict_stream`; ``simulate`` / ``show-scene``:
:func:`load_scene_data` / :func:`get_scene`; ``compare``: :func:`run_verdicts`,
:func:`compare_verdicts`). The protocol's internals are imported from their modules.

Results obtained on the simulated scenes are results on synthetic data, never the paper's.
"""

from __future__ import annotations

import importlib
from typing import Any

_SUBMODULES = (
    "simulation", "generators", "benchmark_scenes", "datasets", "models", "ensemble", "baselines", "training",
    "methods", "copies", "stats", "report", "distributed", "protocol", "cli", "commands", "figures", "recordings",
    "deployment", "runs",
)

#: What a user calls, each the Python entry point of a command or what it reads and writes
#: (``__all__``): name -> the module that defines it, loaded on first use. The protocol's
#: internals (``paired_batches``, ``format_budget_check``, ...) are imported from their modules
#: (:mod:`~event_transforms.tactile.copies`, :mod:`~event_transforms.tactile.report`, ...).
_NAMES = {
    "main": "cli",  # the command line: main(["reproduce", "--plan"])
    "ForceRegressor": "models",  # the reference model; train's checkpoint (ForceRegressor.load)
    "RecordingSet": "recordings",  # a folder of your recordings as (frames, force, meta) items
    "RecordingSettings": "recordings",
    "load_recording_data": "recordings",  # a folder as the protocol's data (reproduce --data, infer-scene)
    "export_scene": "recordings",  # simulate --export
    "convert_bag": "recordings",  # convert
    "ProtocolConfig": "protocol",
    "run_protocol": "protocol",  # reproduce
    "load_scene_data": "copies",  # a built-in scene's data (simulate)
    "get_scene": "benchmark_scenes",  # show-scene
    "train_model": "deployment",  # train
    "predict_stream": "deployment",  # predict
    "run_verdicts": "report",  # compare
    "compare_verdicts": "report",
}

__all__ = list(_NAMES)


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _NAMES:
        return getattr(importlib.import_module(f"{__name__}.{_NAMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | set(_SUBMODULES))
