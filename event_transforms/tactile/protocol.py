"""The benchmark protocol: every scene, every method, paired seeds, equal budgets, statistics.

For each :class:`~event_transforms.tactile.scenes.BenchmarkScene`, a method's training set is
the scene's 48 training sequences plus ``copies`` synthetic copies of each (the paper doubles
the set: ``copies=1``); validation (24) and test (96) sequences come from the deployment
session. Every method and seed trains the reference
:class:`~event_transforms.tactile.models.ForceRegressor` for the **same number of optimiser
steps** (copies add data, not steps), with Adam, a one-cycle learning rate and per-member
gradient clipping, all seeds (and methods) of a scene in lockstep as one
:class:`~event_transforms.tactile.ensemble.EnsembleForceRegressor`. The **final weights** are
evaluated (no selection on validation data, so validation and test are two independent
estimates). Seed ``s`` gives every method the same initial weights, the same shuffling
stream and the same augmentation seed, so methods are compared pair by pair: Δ vs ``none``
on test MSE with a 95 % paired t-interval and an exact Wilcoxon signed-rank p-value,
Holm-corrected within each scene (:mod:`event_transforms.tactile.stats`). Trivial baselines
(:mod:`event_transforms.tactile.baselines`) appear as rows beside the network.

Method names (:func:`parse_method`):

=================  ===============================================================
``none``           no synthetic copies
``rot<deg>``       ``RandomRotation(±deg)`` about the event centroid, e.g. ``rot45``
``resize``         ``ResizeToTarget(scene target)``: β = target / the sample's size
``resize-hertz``   the same with β = (target / size)^½ (Hertz contact width ∝ √D)
``noise``          ``AddNoise`` with static-scene frames of the deployment camera
``fs<j>``          ``FrameShift(j)``, e.g. ``fs-1`` (one frame earlier), ``fs2``
``tes<j>:<ζ>``     ``TemporalEventShift(j, ζ)``, e.g. ``tes-2:0.5``
``independent``    the scene's policy, one effect per copy (``OneOf``); on ``paper``,
                   the paper's resize or FS-1
``hybrid``         the same effects stacked on every copy (``Compose``)
``<name>x<k>``     ``k`` synthetic copies per item, e.g. ``tes-2:0.5x10``
=================  ===============================================================

Runs are spread over ``jobs`` processes with :mod:`torch.distributed` (gloo on the CPU,
nccl on GPUs; or the ranks of ``torchrun``); rank 0 gathers and writes ``results.json``.
Every finished unit (scene, method) is kept on disk, so an interrupted run resumes.
Results on the package's simulated scenes are results on synthetic data, not the paper's.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import re
import socket
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.utils.data import Dataset

from ..data import AugmentedDataset
from ..scenes import ResizeToTarget, Scene
from ..transforms import AddNoise, FrameShift, RandomRotation, TemporalEventShift
from .scenes import SCENES, BenchmarkScene, get_scene
from .training import Stopwatch, TimedTransform, phase_mse, write_json_atomic

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
]

#: The methods the paper compares, in its order.
PAPER_METHODS: tuple[str, ...] = (
    "none", "rot45", "resize", "noise", "fs-1", "tes-2:0.5", "independent", "hybrid",
    "tes-2:0.5x10",
)

#: The paper's scene policy: sizes 12 and 18 mm to 15 mm, and FS-1 (the paper's best shift).
PAPER_SCENE = Scene(training_sizes=(12.0, 18.0), target_size=15.0, lag_shifts=(-1,))


@dataclass(frozen=True)
class Method:
    """A named augmentation: the transform every training item's synthetic copies get.

    The transform is called with each item's metadata, so one transform serves every
    bolt size (:class:`~event_transforms.ResizeToTarget` reads the size from it).

    Args:
        name: label in tables and file names.
        make: builds the transform from the noise bank (``None`` if there is none), or
            ``None`` for no synthetic copies.
        copies: synthetic copies per training item (0 = none).
        needs_noise_bank: the transform needs a static-scene noise bank.
    """

    name: str
    make: Callable[[torch.Tensor | None], nn.Module] | None
    copies: int = 1
    needs_noise_bank: bool = False

    @classmethod
    def from_transform(cls, name: str, transform: nn.Module, copies: int = 1) -> Method:
        """A method applying ``transform`` to every item."""
        if not isinstance(transform, nn.Module):
            raise TypeError(f"transform must be an nn.Module, got {type(transform).__name__}")
        return cls(name, lambda bank: transform, copies)

    @classmethod
    def from_scene(cls, name: str, scene: Scene, copies: int = 1, *, combination: str = "independent") -> Method:
        """A method from a :class:`~event_transforms.scenes.Scene`'s policy.

        Example:
            >>> scene = Scene(training_sizes=(12.0, 18.0), target_size=15.0, lag_shifts=(-1,))
            >>> [type(t).__name__ for t in Method.from_scene("scene", scene).build().transforms]
            ['RandomFrameShift', 'ResizeToTarget']
        """
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
        return cls(name, lambda bank: scene.policy(combination), copies)

    def build(self, noise_bank: torch.Tensor | None = None) -> nn.Module | None:
        """The transform of the synthetic copies, or ``None`` for none."""
        if self.make is None or self.copies == 0:
            return None
        if self.needs_noise_bank and noise_bank is None:
            raise ValueError(f"method {self.name!r} needs a static-scene noise bank, got None")
        return self.make(noise_bank)


_NUMBER = r"[+-]?\d+(?:\.\d*)?(?:[eE][+-]?\d+)?"
_PATTERN = re.compile(
    rf"^(?P<base>none|resize-hertz|resize|noise|independent|hybrid|rot(?P<deg>{_NUMBER})"
    rf"|fs(?P<fs>[+-]?\d+)|tes(?P<tes>[+-]?\d+):(?P<frac>{_NUMBER}))(?:x(?P<copies>\d+))?$"
)


def parse_method(name: str, *, copies: int = 1, scene: str | BenchmarkScene = "paper") -> Method:
    """Turn a method name (see the module docstring) into a :class:`Method` for ``scene``.

    Args:
        name: e.g. ``"none"``, ``"rot45"``, ``"resize"``, ``"fs-1"``, ``"tes-2:0.5x10"``.
        copies: synthetic copies per item when the name has no ``x<k>`` suffix.
        scene: the benchmark scene (its target size, gaps and policy).

    Example:
        >>> m = parse_method("tes-2:0.5x10")
        >>> m.copies, m.build()
        (10, TemporalEventShift(shift=-2, fraction=0.5, mode='exact'))
        >>> parse_method("resize").build()
        ResizeToTarget(target_size=15.0, key='diameter_mm', exponent=1.0, center='mass', mode='bilinear')
        >>> parse_method("resize-hertz", scene="size-extrapolation").build().target_size
        18.0
        >>> parse_method("none").copies
        0
    """
    if not isinstance(name, str):
        raise TypeError(f"method name must be a str, got {type(name).__name__}")
    scene = get_scene(scene)
    match = _PATTERN.match(name.strip().lower())
    if match is None:
        raise ValueError(
            f"unknown method {name!r}; expected none, rot<deg>, resize, resize-hertz, noise, fs<j>, "
            "tes<j>:<fraction>, independent or hybrid, optionally followed by x<copies>"
        )
    base = match["base"]
    if match["copies"] is not None:
        copies = int(match["copies"])
    if isinstance(copies, bool) or not isinstance(copies, int) or copies < 0:
        raise ValueError(f"copies must be a non-negative int, got {copies!r}")
    if base == "none":
        return Method(name, None, 0)
    if base in ("resize", "resize-hertz"):
        target = scene.target_size
        if target is None:
            raise ValueError(
                f"method {name!r} needs a scene whose deployment size differs from training; "
                f"scene {scene.name!r} has none"
            )
        exponent = 0.5 if base == "resize-hertz" else 1.0
        return Method(name, lambda bank: ResizeToTarget(target, exponent=exponent), copies)
    if base == "noise":
        return Method(name, lambda bank: AddNoise(bank), copies, needs_noise_bank=True)
    if base in ("independent", "hybrid"):
        if scene.name == "paper":
            return Method.from_scene(name, PAPER_SCENE, copies, combination=base)
        needs_bank = "noise" in scene.gaps
        return Method(
            name, lambda bank: scene.library_scene(bank).policy(base), copies, needs_noise_bank=needs_bank
        )
    if match["deg"] is not None:
        degrees = float(match["deg"])
        return Method(name, lambda bank: RandomRotation(degrees), copies)
    if match["fs"] is not None:
        shift = int(match["fs"])
        return Method(name, lambda bank: FrameShift(shift), copies)
    shift, fraction = int(match["tes"]), float(match["frac"])
    if not 0 <= fraction <= 1:
        raise ValueError(f"TES fraction must lie in [0, 1], got {fraction!r} in {name!r}")
    return Method(name, lambda bank: TemporalEventShift(shift, fraction), copies)


#: Quick mode's methods of the scenes without a paper list: none and the matched ones;
#: the control runs the other scenes' matched methods that need no size gap.
QUICK_METHODS: dict[str, tuple[str, ...]] = {
    "paper": PAPER_METHODS,
    "control": ("none", "rot50", "fs2", "noise"),
}


def methods_for(scene: str | BenchmarkScene, *, full: bool = False) -> tuple[str, ...]:
    """The methods a scene runs: quick — ``none`` + its matched methods (the paper's list on
    ``paper``, other scenes' matched methods on ``control``); full — the paper's list (where
    defined) and every scene's matched methods that the scene can build (``independent`` and
    ``hybrid`` only where they combine two effects or more: on ``paper``).

    Example:
        >>> methods_for("timing")
        ('none', 'fs2', 'tes2:0.5')
    """
    scene = get_scene(scene)
    if not full:
        return QUICK_METHODS.get(scene.name, ("none", *scene.matched_methods))
    names = list(PAPER_METHODS) + [m for s in SCENES.values() for m in s.matched_methods]
    usable = []
    for name in dict.fromkeys(names):
        if name in ("independent", "hybrid") and scene.name != "paper" and len(scene.gaps) < 2:
            continue  # with one effect or none, the combinations are the matched method or a copy
        try:
            parse_method(name, scene=scene)
        except ValueError:
            continue
        usable.append(name)
    return tuple(usable)


@dataclass
class ProtocolConfig:
    """Settings of one protocol run (the full configuration's are the defaults).

    Attributes:
        steps: optimiser steps of every run (the same for every method).
        batch_size: sequences per step.
        lr: peak learning rate of the one-cycle schedule.
        clip: gradient-norm limit per model.
        eval_every: steps between validation passes (recorded; the final weights are kept).
        hidden_channels: ConvLSTM channels per layer of the regressor.
        input_pool: the regressor's first average-pool factor.
        cumulative: the regressor also reads running event totals (see ``ForceRegressor``).
        fixed: the synthetic copies are made once before training (the paper's offline
            doubling; timed as "aug once") rather than drawn afresh for every batch, on the
            training device (timed as "aug s/epoch").
        copies: synthetic copies per item for names without ``x<k>``.
        paper_split: evaluate on the paper's 6 + 6 sequences instead of 24 + 96.
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

    def key(self) -> str:
        """A short hash of the settings, so results of different settings never mix."""
        text = json.dumps(asdict(self), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:10]


@dataclass
class SceneData:
    """Training, validation and test sets of one scene, and the deployment camera's noise bank."""

    scene: BenchmarkScene
    train: Dataset
    val: Dataset
    test: Dataset
    noise_bank: torch.Tensor | None = None
    seconds: float = 0.0


def load_scene_data(
    scene: str | BenchmarkScene, root: str | None = None, *, paper_split: bool = False, noise_frames: int = 360
) -> SceneData:
    """The simulated grasps of ``scene`` (generated into the cache on first use).

    The noise bank is ``noise_frames`` frames of a simulated static scene seen by the
    deployment camera.
    """
    from . import datasets

    scene = get_scene(scene)
    start = time.perf_counter()
    splits = {
        split: datasets.TactileGrasps(split, root=root, scene=scene, paper_split=paper_split)
        for split in ("train", "val", "test")
    }
    bank = datasets.noise_bank(noise_frames, seed=0, config=scene.deploy.config)
    return SceneData(scene, splits["train"], splits["val"], splits["test"], bank, time.perf_counter() - start)


class MaterializedDataset(Dataset):
    """Every item of ``data`` computed once and kept in memory: the paper's offline copies.

    Integer-valued frames are stored as int16 when they fit (a quarter of float32's
    memory) and returned as float32, so an item reads back exactly as it was computed.
    """

    def __init__(self, data: Dataset) -> None:
        self.items = []
        for index in range(len(data)):
            frames, force, *rest = data[index]
            frames = torch.as_tensor(frames)
            compact = (
                frames.numel() > 0
                and bool((frames == frames.round()).all())
                and float(frames.abs().max()) <= 32767
            )
            self.items.append((frames.to(torch.int16) if compact else frames, force, *rest))

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> tuple[Any, ...]:
        frames, *rest = self.items[index]
        return (frames.to(torch.float32), *rest)


def build_training_set(
    method: Method, data: SceneData, *, seed: int, fixed: bool, stopwatch: Stopwatch
) -> Dataset:
    """The training items followed by ``method.copies`` synthetic copies of each.

    One :class:`~event_transforms.AugmentedDataset` whose transform (wrapped in a
    :class:`~event_transforms.tactile.training.TimedTransform` reporting to ``stopwatch``)
    receives each item's metadata. Fixed copies are made here, once (timed).
    """
    transform = method.build(data.noise_bank)
    if transform is None:
        return data.train
    augmented = AugmentedDataset(data.train, TimedTransform(transform, stopwatch), method.copies, fixed=fixed, seed=seed)
    return MaterializedDataset(augmented) if fixed else augmented


class OnlineCopies(Dataset):
    """The training items followed by ``copies`` *untransformed* copies of each, marked in the
    metadata (``meta["copy"]``: 0 for originals, c ≥ 1 for copy c), so that a
    :class:`DeviceAugment` can transform the copies of each batch on the training device.

    Example:
        >>> base = [(torch.ones(2, 2, 3, 3), torch.zeros(2), {"diameter_mm": 12.0})]
        >>> copies = OnlineCopies(base, 2)
        >>> len(copies), copies[2][2]
        (3, {'diameter_mm': 12.0, 'copy': 2})
    """

    def __init__(self, base: Dataset, copies: int) -> None:
        if isinstance(copies, bool) or not isinstance(copies, int) or copies < 0:
            raise ValueError(f"copies must be a non-negative int, got {copies!r}")
        self.base, self.copies = base, copies

    def __len__(self) -> int:
        return len(self.base) * (1 + self.copies)

    def __getitem__(self, index: int) -> tuple[Any, ...]:
        copy, item = divmod(int(index), len(self.base))
        frames, force, *rest = self.base[item]
        meta = dict(rest[0]) if rest else {}
        meta["copy"] = copy
        return frames, force, meta


class DeviceAugment:
    """Transform the copies of a batch on its device, per sample, with a seeded CPU generator.

    Called as ``(frames (B, T, 2, H, W), metas) -> frames`` by
    :func:`~event_transforms.tactile.ensemble.fit_ensemble`: the rows whose metadata say
    ``copy >= 1`` go through ``transform`` (its parameters drawn from a CPU generator seeded
    with ``seed``, so a run is reproducible and the device never waits for a draw), the
    originals pass unchanged.

    Example:
        >>> from event_transforms import FrameShift
        >>> frames = torch.ones(2, 3, 2, 1, 1)
        >>> out = DeviceAugment(FrameShift(1), seed=0)(frames, [{"copy": 0}, {"copy": 1}])
        >>> out[:, :, 0, 0, 0].tolist()
        [[1.0, 1.0, 1.0], [0.0, 1.0, 1.0]]
    """

    def __init__(self, transform: nn.Module, seed: int, stopwatch: Stopwatch | None = None) -> None:
        self.transform = transform
        self.generator = torch.Generator().manual_seed(int(seed))
        self.stopwatch = stopwatch if stopwatch is not None else Stopwatch()

    def __call__(self, frames: torch.Tensor, metas: list) -> torch.Tensor:
        rows = [i for i, meta in enumerate(metas) if meta.get("copy", 0) >= 1]
        if not rows:
            return frames
        with self.stopwatch:
            index = torch.tensor(rows, device=frames.device)
            metadata = [{k: v for k, v in metas[i].items() if k != "copy"} for i in rows]
            changed = self.transform(frames.index_select(0, index), generator=self.generator, metadata=metadata)
            return frames.index_copy(0, index, changed.to(frames.dtype))


def _force_stats(data: Dataset) -> tuple[float, float]:
    forces = torch.stack([torch.as_tensor(data[i][1]).double() for i in range(len(data))])
    return float(forces.mean()), float(forces.std()) if forces.numel() > 1 else 1.0


def _evaluate(model: nn.Module, data: Dataset, batch_size: int = 16) -> tuple[torch.Tensor, torch.Tensor]:
    """Predicted and measured force ``(M, N, T)`` / ``(N, T)`` (float64) of an ensemble."""
    from .baselines import stack_items

    frames, force = stack_items(data)
    was_training = model.training
    model.eval()
    device = next(model.parameters()).device
    preds = []
    with torch.no_grad():
        for start in range(0, frames.shape[0], batch_size):
            preds.append(model(frames[start : start + batch_size].to(device)).double().cpu())
    model.train(was_training)
    return torch.cat(preds, dim=1), force.double()


def run_unit(
    scene: str | BenchmarkScene,
    methods: Sequence[str],
    seeds: Sequence[int],
    config: ProtocolConfig,
    data: SceneData,
    *,
    device: str | torch.device = "cpu",
    progress: bool | None = None,
    description: str | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """Train ``methods`` × ``seeds`` of one scene as one ensemble; per-method, per-seed results.

    Member (method, seed) starts from the weights ``ForceRegressor`` draws after
    ``torch.manual_seed(seed)`` (the same for every method), shuffles with ``seed`` and
    makes its copies with ``seed``.
    """
    from .ensemble import EnsembleForceRegressor, fit_ensemble
    from .models import ForceRegressor

    scene = get_scene(scene)
    parsed = [parse_method(m, copies=config.copies, scene=scene) for m in methods]
    offset, scale = _force_stats(data.train)
    models, train_sets, member_seeds, aug_once, augment = [], [], [], [], []
    watch = Stopwatch()
    for method in parsed:
        for seed in seeds:
            torch.manual_seed(seed)
            models.append(ForceRegressor(hidden_channels=config.hidden_channels, input_pool=config.input_pool,
                                         cumulative=config.cumulative))
            before = watch.seconds
            transform = method.build(data.noise_bank)
            if config.fixed or transform is None:
                train_sets.append(build_training_set(method, data, seed=seed, fixed=True, stopwatch=watch))
                augment.append(None)
            else:  # on the fly: copies are transformed batch by batch on the training device
                train_sets.append(OnlineCopies(data.train, method.copies))
                augment.append(DeviceAugment(transform.to(device), seed))
            aug_once.append(watch.seconds - before)
            member_seeds.append(int(seed))
    ensemble = EnsembleForceRegressor.from_models(models).to(device)
    ensemble.set_force_scaling([offset] * len(models), [max(scale, 1e-6)] * len(models))
    result = fit_ensemble(
        ensemble, train_sets, data.val, steps=config.steps, batch_size=config.batch_size, seeds=member_seeds,
        lr_max=config.lr, clip=config.clip, schedule="one-cycle", eval_every=config.eval_every, select="final",
        device=device, progress=progress, augment=augment, fixed_data=True,  # every set here is fixed
        description=description or f"{scene.name}: {', '.join(methods)}",
    )
    val_pred, val_target = _evaluate(ensemble, data.val)
    test_pred, test_target = _evaluate(ensemble, data.test)
    passes = config.steps * config.batch_size  # sequences read per member
    out: dict[str, list[dict[str, Any]]] = {}
    for index, record in enumerate(result.members):
        method = parsed[index // len(seeds)]
        size = len(train_sets[index])
        test_phases = phase_mse(test_pred[index], test_target)
        out.setdefault(method.name, []).append(
            {
                "seed": member_seeds[index],
                "copies": method.copies,
                "train_items": size,
                "steps": result.steps,
                "test_mse": test_phases["all"],
                "test_phase_mse": test_phases,
                "val_mse": phase_mse(val_pred[index], val_target)["all"],
                # the paper's 6 + 6 split: the first 6 sequences of val and test
                "val_mse_paper_split": phase_mse(val_pred[index, :6], val_target[:6])["all"],
                "test_mse_paper_split": phase_mse(test_pred[index, :6], test_target[:6])["all"],
                "converged": bool(record.converged),
                "final_train_loss": record.train_loss[-1] if record.train_loss else math.nan,
                "val_history": {"steps": record.val_steps, "mse": record.val_loss},
                "aug_s_once": aug_once[index],
                # online copies: this member's augmentation time, per pass over its set
                "aug_s_per_epoch": (
                    augment[index].stopwatch.seconds * size / max(passes, 1) if augment[index] is not None else 0.0
                ),
                # one ensemble trains every member at once: its time is shared equally
                "train_s": result.train_s / len(result.members),
                "ensemble_members": len(result.members),
                "ensemble_train_s": result.train_s,
                "test_examples": {
                    "predicted": test_pred[index, :2].tolist(),
                    "measured": test_target[:2].tolist(),
                },
            }
        )
    return out


# --------------------------------------------------------------------------- statistics


def _mean_sd(values: Sequence[float]) -> tuple[float, float]:
    values = [float(v) for v in values]
    return statistics.fmean(values), (statistics.stdev(values) if len(values) > 1 else math.nan)


def _deltas(methods: dict[str, Any], key: str) -> dict[str, dict[str, Any]]:
    """Δ of ``key`` vs ``none`` for every other method, paired seed by seed: the paired
    t-interval, the exact Wilcoxon p, and both Holm-corrected within the family given."""
    from .stats import holm, paired_t

    reference = methods.get("none")
    if reference is None:
        return {}
    base = dict(zip(reference["seeds"], reference[key]))
    tests = {}
    for name, method in methods.items():
        if name == "none":
            continue
        pairs = [(base[s], v) for s, v in zip(method["seeds"], method[key]) if s in base]
        if pairs:
            tests[name] = paired_t([a for a, _ in pairs], [b for _, b in pairs])
    adjusted = dict(zip(tests, holm([t.wilcoxon_p_value for t in tests.values()])))
    adjusted_t = dict(zip(tests, holm([t.t_p_value for t in tests.values()])))
    return {
        name: {
            "mean": test.mean,
            "ci95": list(test.ci) if test.ci is not None else None,
            "p_value": test.wilcoxon_p_value,
            "p_holm": adjusted[name],
            "t_p_value": test.t_p_value,
            "t_p_holm": adjusted_t[name],
            "significant": _significant({"ci95": test.ci, "t_p_holm": adjusted_t[name]}),
            "n": test.n,
        }
        for name, test in tests.items()
    }


def summarize_scene(
    scene: BenchmarkScene, per_method: dict[str, list[dict[str, Any]]], baselines: dict[str, dict[str, float]],
    split_sizes: dict[str, int],
) -> dict[str, Any]:
    """One scene's entry of ``results.json``: gaps, baselines, and per method the per-seed
    values and Δ vs ``none`` on test MSE (``delta_vs_none``) and on the paper's 6 + 6 split
    (``delta_vs_none_paper_split``), each Holm-corrected within the scene."""
    methods: dict[str, Any] = {}
    for name, runs in per_method.items():
        runs = sorted(runs, key=lambda r: r["seed"])
        methods[name] = {
            "seeds": [r["seed"] for r in runs],
            "test_mse": [r["test_mse"] for r in runs],
            "val_mse": [r["val_mse"] for r in runs],
            "test_mse_paper_split": [r["test_mse_paper_split"] for r in runs],
            "val_mse_paper_split": [r["val_mse_paper_split"] for r in runs],
            "converged": [r["converged"] for r in runs],
            "steps": runs[0]["steps"],
            "copies": runs[0]["copies"],
            "train_items": runs[0]["train_items"],
            "delta_vs_none": None,
            "delta_vs_none_paper_split": None,
            "aug_s_once": statistics.fmean(r["aug_s_once"] for r in runs),
            "aug_s_per_epoch": statistics.fmean(r["aug_s_per_epoch"] for r in runs),
            "train_s": statistics.fmean(r["train_s"] for r in runs),
            "test_phase_mse": {
                phase: statistics.fmean(r["test_phase_mse"][phase] for r in runs) for phase in ("grasp", "hold", "release")
            },
        }
    for key, field_name in (("test_mse", "delta_vs_none"), ("test_mse_paper_split", "delta_vs_none_paper_split")):
        for name, delta in _deltas(methods, key).items():
            methods[name][field_name] = delta
    return {
        "description": scene.description,
        "gaps": list(scene.gaps),
        "gap_sizes": {f: {k: [list(v) if isinstance(v, tuple) else v for v in pair] for k, pair in d.items()}
                      for f, d in scene.gap_sizes().items()},
        "matched_methods": list(scene.matched_methods),
        "split_sizes": dict(split_sizes),
        "baselines": baselines,
        "methods": methods,
    }


def _fmt_mean_sd(values: Sequence[float]) -> str:
    mean, sd = _mean_sd(values)
    return f"{mean:.2f}" if len(values) < 2 else f"{mean:.2f} ± {sd:.2f}"


def _significant(delta: dict[str, Any] | None, alpha: float = 0.05) -> bool:
    """The paired t-test, Holm-corrected within the scene, rejects "no change" at ``alpha``.

    The exact Wilcoxon p-value is reported beside it but cannot decide with few seeds: with
    n pairs it is at least 2 / 2**n (0.0625 for 5 seeds), so it never reaches 0.05.
    """
    if not delta or not delta.get("ci95"):
        return False
    lo, hi = delta["ci95"]
    p = delta.get("t_p_holm")
    return bool((hi < 0 or lo > 0) and p is not None and not math.isnan(p) and p <= alpha)


def format_scene_table(name: str, summary: dict[str, Any], *, timings: bool = True, key: str = "test_mse") -> str:
    """A markdown table of one scene: baselines, then methods (MSE in N²)."""
    head = ["method", "test MSE", "Δ vs none [95 % CI]", "Holm p: t / Wilcoxon", "converged"]
    if timings:
        head += ["aug s once", "aug s/epoch", "train s"]
    rows = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    baseline_key = "test_mse_paper_split" if key.endswith("paper_split") else "test_mse"
    for base, values in summary["baselines"].items():
        cells = [f"*{base}* (baseline)", f"{values[baseline_key]:.2f}", "—", "—", "—"]
        rows.append("| " + " | ".join(cells + (["—"] * 3 if timings else [])) + " |")
    matched = set(summary["matched_methods"])
    for method, s in summary["methods"].items():
        delta = s["delta_vs_none" if key == "test_mse" else "delta_vs_none_paper_split"]
        if delta is None:
            delta_text, p_text = "—", "—"
        else:
            ci = delta["ci95"]
            mark = "**" if _significant(delta) else ""
            delta_text = f"{mark}{delta['mean']:+.2f} [{ci[0]:+.2f}, {ci[1]:+.2f}]{mark}" if ci else f"{delta['mean']:+.2f}"
            p_text = (f"{delta['t_p_holm']:.3f} / {delta['p_holm']:.3f}"
                      if not math.isnan(delta["p_holm"]) else "—")
        label = f"{method} (matched)" if method in matched else method
        cells = [label, _fmt_mean_sd(s[key]), delta_text, p_text,
                 f"{sum(s['converged'])}/{len(s['converged'])}"]
        if timings:
            cells += [f"{s['aug_s_once']:.2f}", f"{s['aug_s_per_epoch']:.3f}", f"{s['train_s']:.1f}"]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def format_findings(name: str, summary: dict[str, Any]) -> list[str]:
    """One sentence per method: what it buys (Δ test MSE and its interval) and costs."""
    lines = []
    best_baseline = min(summary["baselines"].items(), key=lambda kv: kv[1]["test_mse"], default=None)
    none = summary["methods"].get("none")
    if none and best_baseline:
        mean = statistics.fmean(none["test_mse"])
        lines.append(
            f"{name}: without augmentation the network scores {mean:.2f} N² on test against "
            f"{best_baseline[1]['test_mse']:.2f} for the best trivial baseline ({best_baseline[0]}), "
            f"ratio {mean / best_baseline[1]['test_mse']:.2f}."
        )
    for method, s in summary["methods"].items():
        delta = s["delta_vs_none"]
        if delta is None or not delta.get("ci95"):
            continue
        lo, hi = delta["ci95"]
        verdict = ("buys" if hi < 0 else "costs") if _significant(delta) else "shows no resolved change:"
        lines.append(
            f"{name} / {method}: {verdict} {delta['mean']:+.2f} N² test MSE (95 % CI {lo:+.2f} to {hi:+.2f}, "
            f"Holm p {delta['t_p_holm']:.3f} by the t-test, {delta['p_holm']:.3f} by Wilcoxon), for "
            f"{s['aug_s_once']:.2f} s of augmentation once and {s['train_s']:.0f} s of training per run."
        )
    return lines


# --------------------------------------------------------------------------- running


@dataclass
class _Unit:
    scene: str
    methods: tuple[str, ...]

    @property
    def slug(self) -> str:
        return re.sub(r"[^a-z0-9.+-]+", "_", f"{self.scene}__{'+'.join(self.methods)}".lower())


def _units(scenes: Sequence[str], methods: dict[str, Sequence[str]], group: str) -> list[_Unit]:
    """Work units; the costly ones (many copies) first, so ranks finish together."""
    units = []
    for scene in scenes:
        names = tuple(methods[scene])
        if group == "scene":
            units.append(_Unit(scene, names))
        else:
            units.extend(_Unit(scene, (m,)) for m in names)
    return sorted(units, key=lambda u: -max(parse_method(m, scene=u.scene).copies for m in u.methods))


def _environment() -> dict[str, Any]:
    return {
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }


def _baselines(data: SceneData) -> dict[str, dict[str, float]]:
    from .baselines import evaluate_baselines, stack_items

    train, val, test = (stack_items(d) for d in (data.train, data.val, data.test))
    scores = evaluate_baselines(train, val, test)
    small = evaluate_baselines(train, (val[0][:6], val[1][:6]), (test[0][:6], test[1][:6]))
    return {
        name: {**values, "test_mse_paper_split": small[name]["test_mse"], "val_mse_paper_split": small[name]["val_mse"]}
        for name, values in scores.items()
    }


def _work(
    rank: int, world: int, units: list[_Unit], seeds: list[int], config: ProtocolConfig, runs: Path,
    root: str | None, device: str, threads: int | None, log: Callable[[str], None] | None, progress: bool | None,
    given: dict[str, SceneData] | None = None,
) -> None:
    """Rank ``rank``'s share of the units (every ``world``-th), each saved as it finishes."""
    if threads:
        torch.set_num_threads(threads)
    cache: dict[str, SceneData] = dict(given or {})
    for index, unit in enumerate(units):
        if index % world != rank:
            continue
        path = runs / f"{unit.slug}.json"
        if path.exists():
            if log:
                log(f"[rank {rank}] {unit.scene}: {', '.join(unit.methods)} — resumed from disk")
            continue
        if unit.scene not in cache:
            cache[unit.scene] = load_scene_data(unit.scene, root, paper_split=False)
        tick = time.perf_counter()
        result = run_unit(unit.scene, unit.methods, seeds, config, cache[unit.scene], device=device,
                          progress=progress, description=f"[rank {rank}] {unit.scene}: {', '.join(unit.methods)}")
        write_json_atomic(path, result)
        if log:
            scores = "; ".join(
                f"{m} {statistics.fmean(r['test_mse'] for r in rs):.2f}" for m, rs in result.items()
            )
            log(f"[rank {rank}] {unit.scene}: test MSE {scores} ({time.perf_counter() - tick:.0f} s)")


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _die_with_parent() -> None:
    """On Linux, have the kernel stop this worker when its parent dies (``PR_SET_PDEATHSIG``),
    so a killed ``reproduce`` leaves no training processes behind."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover - no prctl: nothing to do
            pass


def _spawned(rank: int, world: int, port: int, arguments: tuple) -> None:
    """Entry point of a ``--jobs`` worker: join the gloo group, work, gather to rank 0."""
    import torch.distributed as dist

    _die_with_parent()
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    try:
        _work(rank, world, *arguments)
        dist.barrier()
    finally:
        dist.destroy_process_group()


def run_protocol(
    scenes: Sequence[str] | None,
    seeds: Sequence[int],
    out: str | Path,
    *,
    config: ProtocolConfig | None = None,
    methods: dict[str, Sequence[str]] | Sequence[str] | None = None,
    full: bool = False,
    root: str | None = None,
    jobs: int = 1,
    device: str = "cpu",
    threads: int | None = 1,
    group: str = "scene",
    data: dict[str, SceneData] | None = None,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run every scene's methods for every seed; write ``results.json`` and ``results.md``.

    Work is split into units — a scene's methods trained together as one ensemble
    (``group="scene"``) or one method at a time (``group="method"``) — spread over ranks:
    ``jobs`` local processes joined by :mod:`torch.distributed` (gloo), or the ranks of an
    already initialised process group (``torchrun``). Each finished unit is kept under
    ``out/runs/<settings hash>/`` so an interrupted run resumes; rank 0 gathers everything
    (``dist.gather_object`` under torchrun) and writes the results.

    ``data`` (scene name -> :class:`SceneData`) replaces the simulated scenes, e.g. with your
    own recordings; it is sent to every worker. Without it, workers read the data cache.

    Returns:
        The ``results.json`` dict (on rank 0; other ranks of a torchrun group get ``{}``).
    """
    import torch.distributed as dist

    config = config or ProtocolConfig()
    scenes = list(scenes or SCENES)
    for scene in scenes:
        get_scene(scene)
    if isinstance(methods, dict):
        chosen = {s: tuple(methods.get(s, methods_for(s, full=full))) for s in scenes}
    elif methods is not None:
        chosen = {s: tuple(methods) for s in scenes}
    else:
        chosen = {s: methods_for(s, full=full) for s in scenes}
    for scene, names in chosen.items():
        if len(set(names)) != len(names):
            raise ValueError(f"methods must be distinct, got {names} for scene {scene!r}")
        for name in names:
            parse_method(name, scene=scene)  # fail before any training
    if group not in ("scene", "method"):
        raise ValueError(f"group must be 'scene' or 'method', got {group!r}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive int, got {jobs!r}")
    out = Path(out)
    runs = out / "runs" / config.key()
    seeds = [int(s) for s in seeds]
    units = _units(scenes, chosen, group)
    start = time.perf_counter()

    # Data first, in this process: the cache is written once, workers only read it.
    given = data
    data = dict(given) if given is not None else {scene: load_scene_data(scene, root) for scene in scenes}
    missing = [scene for scene in scenes if scene not in data]
    if missing:
        raise ValueError(f"data must hold every scene, missing {missing}")
    if log:
        for scene, d in data.items():
            log(f"data: scene {scene!r} ({d.scene.description}): {len(d.train)} train, {len(d.val)} val, "
                f"{len(d.test)} test sequences, ready in {d.seconds:.1f} s")
    arguments = (units, seeds, config, runs, root, device, threads, log, progress, given)
    write_json_atomic(runs / "config.json", asdict(config))
    if dist.is_available() and dist.is_initialized():
        rank, world = dist.get_rank(), dist.get_world_size()
        _work(rank, world, *arguments)
        dist.barrier()
        mine = {u.slug: json.loads((runs / f"{u.slug}.json").read_text())
                for i, u in enumerate(units) if i % world == rank}
        gathered = [None] * world if rank == 0 else None
        dist.gather_object(mine, gathered, dst=0)
        if rank != 0:
            return {}
        results = {k: v for part in gathered for k, v in part.items()}
    elif jobs > 1:
        import torch.multiprocessing as mp

        mp.spawn(_spawned, args=(jobs, _free_port(), arguments), nprocs=jobs, join=True)
        results = {u.slug: json.loads((runs / f"{u.slug}.json").read_text()) for u in units}
    else:
        _work(0, 1, *arguments)
        results = {u.slug: json.loads((runs / f"{u.slug}.json").read_text()) for u in units}

    scene_results = {}
    for scene in scenes:
        per_method: dict[str, list[dict[str, Any]]] = {}
        for unit in units:
            if unit.scene == scene:
                for name, runs_ in results[unit.slug].items():
                    per_method.setdefault(name, []).extend(runs_)
        per_method = {m: per_method[m] for m in chosen[scene] if m in per_method}
        d = data[scene]
        sizes = {"train": len(d.train), "val": len(d.val), "test": len(d.test)}
        scene_results[scene] = summarize_scene(d.scene, per_method, _baselines(d), sizes)
        scene_results[scene]["generation_s"] = d.seconds
    results_json = {
        "config": {**asdict(config), "seeds": seeds, "scenes": scenes, "jobs": jobs, "device": device,
                   "threads_per_job": threads, "group": group, "full": full},
        "wall_s": time.perf_counter() - start,
        "environment": _environment(),
        "data": "simulated tactile grasps (synthetic data, not the paper's recordings)",
        "scenes": scene_results,
    }
    write_json_atomic(out / "results.json", results_json)
    (out / "results.md").write_text(format_report(results_json) + "\n")
    return results_json


def format_report(results: dict[str, Any], *, timings: bool = True) -> str:
    """Every scene's table and findings, and the paper-split tables, as markdown."""
    parts = []
    for name, summary in results["scenes"].items():
        gaps = ", ".join(summary["gaps"]) or "none (control)"
        sizes = summary["split_sizes"]
        parts.append(f"### {name}: {summary['description']}\n\ngaps: {gaps}; "
                     f"{sizes['train']} train / {sizes['val']} val / {sizes['test']} test sequences\n")
        parts.append(format_scene_table(name, summary, timings=timings))
        parts.append("")
        parts.extend(f"- {line}" for line in format_findings(name, summary))
        parts.append("")
    parts.append("### The same runs scored on the paper's 6 + 6 split (first 6 val and test sequences)\n")
    for name, summary in results["scenes"].items():
        parts.append(f"#### {name}\n")
        parts.append(format_scene_table(name, summary, timings=False, key="test_mse_paper_split"))
        parts.append("")
    return "\n".join(parts)
