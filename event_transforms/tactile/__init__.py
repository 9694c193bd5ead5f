"""The tactile application built on the library: the paper's grasping scenes, simulated.

Submodules (imported when first used, so ``import event_transforms`` stays light):

- :mod:`~event_transforms.tactile.simulation`: a seeded simulator of a bolt pressed into a
  silicone membrane watched by a DVS;
- :mod:`~event_transforms.tactile.scenes`: sessions and benchmark scenes (a gap and a control
  for each augmentation);
- :mod:`~event_transforms.tactile.datasets`: the simulated grasps as data sets, and noise banks;
- :mod:`~event_transforms.tactile.models`: the reference ConvLSTM force regressor;
- :mod:`~event_transforms.tactile.ensemble`: many force regressors trained in lockstep;
- :mod:`~event_transforms.tactile.baselines`: baselines the network must beat (trivial ones and a
  physics least-squares model);
- :mod:`~event_transforms.tactile.training`: the training loop;
- :mod:`~event_transforms.tactile.stats`: paired t-intervals, Wilcoxon signed-rank, Holm;
- :mod:`~event_transforms.tactile.protocol`: the benchmark protocol and its tables;
- :mod:`~event_transforms.tactile.cli`: the ``event-transforms`` command.

Results obtained on the simulated scenes are results on synthetic data, never the paper's.
"""

from __future__ import annotations

import importlib
from typing import Any

_SUBMODULES = (
    "simulation", "scenes", "datasets", "models", "ensemble", "baselines", "training", "stats", "protocol",
    "cli",
)

__all__ = list(_SUBMODULES)


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUBMODULES))
