"""The whole protocol run as its five stages (:func:`run_protocol`): the settings
(:func:`~event_transforms.tactile.protocol.config.read_settings`), the plan
(:func:`~event_transforms.tactile.protocol.plan.plan_protocol`), the training of every phase
(:func:`~event_transforms.tactile.protocol.phases.train_protocol`), the statistics
(:func:`~event_transforms.tactile.protocol.statistics.summarize_protocol`) and the report
(:func:`~event_transforms.tactile.protocol.results.write_results`).

Each stage is one module, entered once, and reads the seeds and the settings from the first
stage's :class:`~event_transforms.tactile.protocol.config.RunSettings`. Results on the package's
simulated scenes are results on synthetic data, not the paper's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..copies import SceneData
from .config import ProtocolConfig, read_settings
from .phases import train_protocol
from .plan import plan_protocol
from .results import write_results
from .statistics import summarize_protocol

__all__ = ["run_protocol"]


def run_protocol(
    scenes: Sequence[str] | None,
    seeds: Sequence[int],
    out: str | Path,
    *,
    config: ProtocolConfig | None = None,
    methods: Mapping[str, Sequence[str]] | Sequence[str] | None = None,
    full: bool = False,
    root: str | None = None,
    jobs: int = 1,
    device: str = "cpu",
    threads: int | None = 1,
    group: str = "scene",
    data: dict[str, SceneData] | None = None,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
    budget_check: bool = True,
    measure_time: bool = True,
    equal_time: bool = False,
    cost_table: str | Path | Mapping[str, Any] | None = None,
    cli: bool = False,
) -> dict[str, Any]:
    """Run every scene's methods for every seed; write ``results.json`` and ``results.md``.

    The run is five stages, each a module's one function: the settings read once
    (:func:`~event_transforms.tactile.protocol.config.read_settings`), the plan
    (:func:`~event_transforms.tactile.protocol.plan.plan_protocol`), every phase trained
    (:func:`~event_transforms.tactile.protocol.phases.train_protocol`), the statistics
    (:func:`~event_transforms.tactile.protocol.statistics.summarize_protocol`) and the report
    (:func:`~event_transforms.tactile.protocol.results.write_results`).

    Before any training, every limit of the data is checked
    (:func:`~event_transforms.tactile.protocol.limits.check_run_limits`: window length, hold-out,
    validation and test windows, batch size, noise banks); ``cli=True`` names the options as
    the command line spells them (``--frames``) in those errors.

    Work is split into units — a scene's methods trained together as one ensemble
    (``group="scene"``) or one method at a time (``group="method"``) — spread over ranks:
    ``jobs`` local processes joined by :mod:`torch.distributed` (gloo), or the ranks of an
    already initialised process group (``torchrun``). Each finished unit is kept under
    ``out/runs/<settings hash>/`` so an interrupted run resumes; rank 0 gathers everything
    and writes the results.

    With ``budget_check``, every scene with a gap then trains ``none`` and its pre-declared
    headline (the first matched method the run trains,
    :func:`~event_transforms.tactile.protocol.plan.headline`) again at twice the steps (its units
    kept under their own settings hash) and records
    ``scenes.NAME.budget_check = {"method", "steps", "steps_2n", "delta", "delta_2n",
    "ci_family_halfwidth", "robust"}``: robust when Δ keeps its sign and moves by less than the
    half-width of its Bonferroni interval.

    With ``measure_time``, rank 0 then measures the time columns: one model trained alone
    for ``config.steps`` steps, three times
    (:func:`~event_transforms.tactile.protocol.timing.single_model_wall`), and per method the
    online augmentation cost of one epoch
    (:func:`~event_transforms.tactile.protocol.timing.online_augmentation_cost`); per method
    ``online_wall_s`` is one model's time plus that cost times the epochs of a run.

    With ``equal_time`` (and ``measure_time``), every method that is not ``none`` and not a
    duplicate row is trained again, like the main runs (same seeds, same augmentation mode),
    for the steps its cost per step leaves in the time ``none`` takes for ``config.steps``:
    ``floor(steps / ratio)`` with the ratio from ``cost_table`` (a file or dict,
    :mod:`~event_transforms.tactile.protocol.costs`), or from a table measured once at the
    start of that phase (written to ``out/cost_table.json``) when none is given — never from the
    wall times of the run; ``scenes.NAME.methods.M.equal_time`` records the steps, the per-seed
    test MSEs and the Δ vs ``none``'s main run (one family per scene, as above), and
    ``cost_ratio`` the ratio. A method whose ratio is 1 keeps its main run.

    ``results.json`` records the environment
    (:func:`~event_transforms.tactile.protocol.environment.environment`): package version and commit,
    torch, CPU model, kernel set, threads and device.

    ``data`` (scene name -> :class:`~event_transforms.tactile.copies.SceneData`) replaces the
    simulated scenes, e.g. with your own recordings; it is sent to every worker. Without it,
    workers read the data cache.

    Returns:
        The ``results.json`` dict (on rank 0; other ranks of a torchrun group get ``{}``).
    """
    settings = read_settings(scenes, seeds, out, config=config, methods=methods, full=full, root=root, jobs=jobs,
                             device=device, threads=threads, group=group, data=data, progress=progress, log=log,
                             budget_check=budget_check, measure_time=measure_time, equal_time=equal_time,
                             cost_table=cost_table, cli=cli)
    plan = plan_protocol(settings)
    trained = train_protocol(settings, plan)
    if not trained.rank0:  # a torchrun rank other than 0
        return {}
    return write_results(settings, plan, trained, summarize_protocol(settings, plan, trained))
