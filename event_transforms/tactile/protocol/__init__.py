"""The benchmark protocol: every scene, every method, paired seeds, equal budgets, statistics,
tables (:func:`run_protocol`).

A run is five stages, each one module entered once, in this order:

- :mod:`~event_transforms.tactile.protocol.config`: the settings (:class:`ProtocolConfig`), read
  once with the seeds and the options (:func:`~event_transforms.tactile.protocol.config.read_settings`);
- :mod:`~event_transforms.tactile.protocol.plan`: each scene's methods, the data, every limit of
  the data checked before any training
  (:func:`~event_transforms.tactile.protocol.limits.check_run_limits`), the units of every phase
  and the cost (:func:`plan_run`);
- :mod:`~event_transforms.tactile.protocol.phases`: every phase's units trained over the ranks,
  resumed from disk (one unit: :func:`run_unit`, which calls the one trainer
  :func:`~event_transforms.tactile.training.train`), the time columns
  (:mod:`~event_transforms.tactile.protocol.timing`) and the equal-cost units
  (:mod:`~event_transforms.tactile.protocol.costs`);
- :mod:`~event_transforms.tactile.protocol.statistics`: each scene's Δ vs ``none``, intervals,
  budget check and cost curve (:mod:`~event_transforms.tactile.stats`,
  :mod:`~event_transforms.tactile.protocol.recompute`);
- :mod:`~event_transforms.tactile.protocol.results`: ``results.json`` and ``results.md``
  (the tables: :mod:`~event_transforms.tactile.report`).

:mod:`~event_transforms.tactile.protocol.run` holds :func:`run_protocol`, the five stages in a
row. A run's methods, data and tables are their own modules' names
(:mod:`~event_transforms.tactile.methods`, :mod:`~event_transforms.tactile.copies`,
:mod:`~event_transforms.tactile.report`, :mod:`~event_transforms.tactile.stats`): import them from there.
"""

from __future__ import annotations

from .config import ProtocolConfig
from .limits import check_run_limits
from .plan import PROGRESS_LEGEND, plan_run
from .run import run_protocol
from .unit import run_unit

__all__ = ["ProtocolConfig", "run_protocol", "plan_run", "check_run_limits", "run_unit", "PROGRESS_LEGEND"]
