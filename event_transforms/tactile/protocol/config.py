"""A protocol run's settings, the first stage of a run: :class:`ProtocolConfig` (the full
configuration's are the defaults) and :func:`read_settings`, the one place a run reads its
seeds, scenes, configuration and options (:class:`RunSettings`)."""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..._validation import check_positive
from ..resampling import check_resample
from ..benchmark_scenes import SCENES
from .environment import git_commit

if TYPE_CHECKING:
    from ..copies import SceneData

__all__ = ["ProtocolConfig", "RunSettings", "read_settings"]


@dataclass
class ProtocolConfig:
    """Settings of one protocol run (the full configuration's are the defaults).

    Attributes:
        steps: optimiser steps of every run (the same for every method).
        batch_size: sequences per step.
        lr: peak learning rate of the one-cycle schedule.
        clip: gradient-norm limit per model.
        eval_every: steps between passes over the hold-out sequences of the training session;
            the weights with the lowest hold-out MSE are kept (the stopping rule; every method
            has the same step cap).
        hidden_channels: ConvLSTM channels per layer of the regressor.
        input_pool: the regressor's first average-pool factor.
        cumulative: the regressor also reads running event totals (see ``ForceRegressor``).
        fixed: the synthetic copies are made once before training (the paper's offline
            doubling; timed as "aug once") rather than drawn afresh for every batch, on the
            training device (timed as "aug s/epoch").
        copies: synthetic copies per item for names without ``x<k>``.
        paper_split: evaluate on the paper's 6 + 6 sequences instead of 24 + 96.
        paired: for a seed, every method reads the same original items at the same steps
            (:func:`~event_transforms.tactile.copies.paired_batches`); ``False`` shuffles each
            method's own set (the pairing of earlier releases: initial weights only).
        resample: ``"fresh"`` (the default): each seed draws its own simulated data set (new
            training, hold-out, validation and test grasps from the same sessions:
            :func:`~event_transforms.tactile.copies.load_scene_data` with ``data_seed``), so an
            interval over seeds covers new data sets from the simulator; a run on given data (a
            folder of recordings, where no new data can be drawn) reads ``"bootstrap"`` instead
            and says so. ``"bootstrap"``: each seed trains on its own bootstrap resample of the
            training sequences and is scored on its own resamples of the validation and test
            sequences (:mod:`~event_transforms.tactile.resampling`), so an interval over seeds
            covers resamples of the data too (not new data sets); ``"none"``: every seed reads
            the same data.
    """

    steps: int = 1500
    batch_size: int = 8
    lr: float = 1e-2
    clip: float = 1.0
    eval_every: int = 100
    hidden_channels: tuple[int, ...] = (8, 16)
    input_pool: int = 4
    cumulative: bool = True
    fixed: bool = True
    copies: int = 1
    paper_split: bool = False
    paired: bool = True
    resample: str = "fresh"

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "eval_every", "input_pool", "copies"):
            check_positive(getattr(self, name), name, integer=True)
        for name in ("lr", "clip"):
            check_positive(getattr(self, name), name)
        channels = tuple(self.hidden_channels)
        if not channels or any(isinstance(c, bool) or not isinstance(c, int) or c < 1 for c in channels):
            raise ValueError(f"hidden_channels must be positive ints, got {self.hidden_channels!r}")
        self.hidden_channels = channels
        check_resample(self.resample)
        if self.resample == "bootstrap" and not self.paired:
            raise ValueError(f"resample={self.resample!r} needs paired=True (each seed's resample is read through "
                             "the paired batches)")

    def key(self) -> str:
        """A short hash of the settings, so results of different settings never mix."""
        text = json.dumps(asdict(self), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:10]

    def training_settings(self) -> dict[str, Any]:
        """The keyword arguments of :func:`~event_transforms.tactile.training.train` these settings fix.

        Example:
            >>> ProtocolConfig(steps=10).training_settings()["steps"]
            10
        """
        return {name: getattr(self, name) for name in (
            "steps", "batch_size", "lr", "clip", "eval_every", "hidden_channels", "input_pool", "cumulative",
            "fixed", "copies", "paired", "resample")}


@dataclass(frozen=True)
class RunSettings:
    """Everything one protocol run reads from its caller, read once (:func:`read_settings`):
    the scenes, the seeds, the configuration, the options and the commit that trains.

    Every later stage (:mod:`~event_transforms.tactile.protocol.plan`,
    :mod:`~event_transforms.tactile.protocol.phases`,
    :mod:`~event_transforms.tactile.protocol.statistics`,
    :mod:`~event_transforms.tactile.protocol.results`) reads its seeds and settings from here.
    """

    scenes: list[str]
    seeds: list[int]
    out: Path
    config: ProtocolConfig
    methods: Mapping[str, Sequence[str]] | Sequence[str] | None
    full: bool
    root: str | None
    jobs: int
    device: str
    threads: int | None
    group: str
    #: the given data (scene name -> ``SceneData``), ``None`` for the simulated scenes
    given: dict[str, SceneData] | None
    progress: bool | None
    log: Callable[[str], None] | None
    budget_check: bool
    measure_time: bool
    equal_time: bool
    cost_table: str | Path | Mapping[str, Any] | None
    cli: bool
    #: the code that trains: read before the run, not after (the checkout may move)
    commit: str | None
    #: ``time.perf_counter()`` at the start of the run
    start: float

    @property
    def fresh(self) -> bool:
        """Each seed draws its own data set (``config.resample == "fresh"``)."""
        return self.config.resample == "fresh"


def read_settings(
    scenes: Sequence[str] | None, seeds: Sequence[int], out: str | Path, *, config: ProtocolConfig | None = None,
    methods: Mapping[str, Sequence[str]] | Sequence[str] | None = None, full: bool = False, root: str | None = None,
    jobs: int = 1, device: str = "cpu", threads: int | None = 1, group: str = "scene",
    data: dict[str, SceneData] | None = None, progress: bool | None = None, log: Callable[[str], None] | None = None,
    budget_check: bool = True, measure_time: bool = True, equal_time: bool = False,
    cost_table: str | Path | Mapping[str, Any] | None = None, cli: bool = False,
) -> RunSettings:
    """A run's settings from :func:`~event_transforms.tactile.protocol.run.run_protocol`'s
    arguments, checked: ``group`` and ``jobs`` refused when invalid, the seeds as ints, the
    scenes (default: every built-in scene), and on given data (where no new data can be drawn)
    ``resample="fresh"`` read as ``"bootstrap"`` (said through ``log``).

    Example:
        >>> settings = read_settings(["control"], [0, 1.0], "out", config=ProtocolConfig(steps=10))
        >>> settings.seeds, settings.config.steps, settings.fresh
        ([0, 1], 10, True)
    """
    config = config or ProtocolConfig()
    if data is not None and config.resample == "fresh":  # a folder cannot draw new data: resample it
        config = replace(config, resample="bootstrap")
        if log:
            log("data per seed: the data are given (no new data can be drawn from them), so each seed reads its own "
                "bootstrap resample by recording instead of fresh data (resample='bootstrap')")
    if group not in ("scene", "method"):
        raise ValueError(f"group must be 'scene' or 'method', got {group!r}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive int, got {jobs!r}")
    return RunSettings(
        scenes=list(scenes or SCENES), seeds=[int(s) for s in seeds], out=Path(out), config=config, methods=methods,
        full=full, root=root, jobs=jobs, device=device, threads=threads, group=group, given=data, progress=progress,
        log=log, budget_check=budget_check, measure_time=measure_time, equal_time=equal_time, cost_table=cost_table,
        cli=cli, commit=git_commit(), start=time.perf_counter())
