"""A protocol run's settings: :class:`ProtocolConfig` (the full configuration's are the defaults)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from typing import Any

from ..._validation import check_positive
from ..resampling import check_resample

__all__ = ["ProtocolConfig"]


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
