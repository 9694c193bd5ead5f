"""Where the benchmark run lived until this release; its names are re-exported from here.

The run is now split by job into the :mod:`event_transforms.tactile.protocol` package:

- settings: :class:`~event_transforms.tactile.protocol.config.ProtocolConfig`;
- planning: :func:`~event_transforms.tactile.protocol.plan.choose_methods`,
  :func:`~event_transforms.tactile.protocol.plan.plan_run`;
- one unit: :func:`~event_transforms.tactile.protocol.unit.run_unit` (its training is the one
  trainer, :func:`~event_transforms.tactile.training.train`);
- the run: :func:`~event_transforms.tactile.protocol.run.run_protocol`,
  :data:`~event_transforms.tactile.protocol.run.PROGRESS_LEGEND`;
- timing: :func:`~event_transforms.tactile.protocol.timing.online_augmentation_cost`,
  :func:`~event_transforms.tactile.protocol.timing.single_model_wall`,
  :func:`~event_transforms.tactile.protocol.timing.equal_time_steps`;
- environment: :func:`~event_transforms.tactile.protocol.environment.environment`,
  :func:`~event_transforms.tactile.protocol.environment.git_commit`.

Import them from :mod:`event_transforms.tactile.protocol` (or the modules above) in new code.
"""

from __future__ import annotations

from .copies import load_scene_data
from .methods import parse_method
from .protocol.config import ProtocolConfig
from .protocol.environment import environment, git_commit
from .protocol.plan import choose_methods, plan_run
from .protocol.run import PROGRESS_LEGEND, run_protocol
from .protocol.timing import equal_time_steps, online_augmentation_cost, single_model_wall
from .protocol.unit import run_unit

__all__ = [
    "ProtocolConfig",
    "run_unit",
    "run_protocol",
    "choose_methods",
    "plan_run",
    "PROGRESS_LEGEND",
    "environment",
    "online_augmentation_cost",
    "single_model_wall",
    "equal_time_steps",
    "git_commit",
    "load_scene_data",
    "parse_method",
]
