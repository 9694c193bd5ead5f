"""Running the benchmark: settings, a scene's data and training sets, one unit, the whole run.

For each :class:`~event_transforms.tactile.scenes.BenchmarkScene`, a method's training set is
the scene's 48 training sequences plus ``copies`` synthetic copies of each (the paper doubles
the set: ``copies=1``); validation (24) and test (96) sequences come from the deployment
session. Every method and seed trains the reference
:class:`~event_transforms.tactile.models.ForceRegressor` for the **same number of optimiser
steps** (copies add data, not steps), with Adam, a one-cycle learning rate and per-member
gradient clipping, all seeds (and methods) of a unit in lockstep as one
:class:`~event_transforms.tactile.ensemble.EnsembleForceRegressor` trained by
:func:`~event_transforms.tactile.ensemble.fit_ensemble` (the one trainer). Seed ``s`` gives
every method the same initial weights, the same shuffling stream and the same augmentation
seed. Statistics are in :mod:`~event_transforms.tactile.stats`, tables in
:mod:`~event_transforms.tactile.report`, processes in
:mod:`~event_transforms.tactile.distributed`.

Work is split into units (a scene's methods, or one method of a scene); every finished unit
is kept on disk, so an interrupted run resumes (:func:`run_protocol`).
Results on the package's simulated scenes are results on synthetic data, not the paper's.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import re
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.utils.data import Dataset

from .._validation import check_positive
from ..data import AugmentedDataset
from . import distributed
from .methods import Method, methods_for, parse_method
from .report import format_report
from .scenes import SCENES, BenchmarkScene, get_scene
from .stats import summarize_scene
from .training import Stopwatch, TimedTransform, phase_mse, write_json_atomic

__all__ = [
    "ProtocolConfig",
    "SceneData",
    "load_scene_data",
    "MaterializedDataset",
    "OnlineCopies",
    "DeviceAugment",
    "build_training_set",
    "run_unit",
    "run_protocol",
]


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

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "eval_every", "input_pool", "copies"):
            check_positive(getattr(self, name), name, integer=True)
        for name in ("lr", "clip"):
            check_positive(getattr(self, name), name)
        channels = tuple(self.hidden_channels)
        if not channels or any(isinstance(c, bool) or not isinstance(c, int) or c < 1 for c in channels):
            raise ValueError(f"hidden_channels must be positive ints, got {self.hidden_channels!r}")
        self.hidden_channels = channels

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
            extra = {"cumulative": True} if config.cumulative else {}
            models.append(
                ForceRegressor(hidden_channels=config.hidden_channels, input_pool=config.input_pool, **extra)
            )
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
        device=device, progress=progress, augment=augment,
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
    group_ = distributed.current_group()
    if group_ is not None:  # the ranks of torchrun
        rank, world = group_
        _work(rank, world, *arguments)
        mine = {u.slug: json.loads((runs / f"{u.slug}.json").read_text())
                for i, u in enumerate(units) if i % world == rank}
        results = distributed.gather_to_rank0(mine)
        if results is None:
            return {}
    else:
        if jobs > 1:
            distributed.spawn(_work, arguments, jobs)
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

