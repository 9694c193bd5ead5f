"""The paper's evaluation protocol: augmentation methods by name, seeds, tables.

Train on the 12 mm and 18 mm bolts (48 sequences) plus ``copies`` synthetic copies of each
(the paper doubles the set: ``copies=1``), validate and test on the unseen 15 mm bolt, with
the reference :class:`~event_transforms.tactile.models.ForceRegressor`, Adam, MSE and early
stopping (:func:`~event_transforms.tactile.training.fit`). Each method runs once per seed; the
summary gives mean ± standard deviation over seeds (sample standard deviation, n − 1).

Method names (:func:`parse_method`):

=================  ===============================================================
``none``           no synthetic copies (48 sequences)
``rot<deg>``       ``RandomRotation(±deg)`` about the event centroid, e.g. ``rot45``
``resize``         ``ResizeToTarget(15 mm)``: β = 15 mm / the sample's diameter, read
                   from each item's metadata (1.25 for 12 mm, 0.83 for 18 mm)
``noise``          ``AddNoise`` with a static-scene bank
``fs<j>``          ``FrameShift(j)``, e.g. ``fs-1`` (one frame earlier)
``tes<j>:<ζ>``     ``TemporalEventShift(j, ζ)``, e.g. ``tes-2:0.5``
``independent``    the :class:`~event_transforms.scenes.Scene` of sizes 12 and 18 mm to
                   15 mm with a lag of one frame earlier: its independent policy
                   (``OneOf``: each copy gets resize or FS-1)
``hybrid``         the same scene's hybrid policy (``Compose``: FS-1, then resize)
``<name>x<k>``     ``k`` synthetic copies per item, e.g. ``tes-2:0.5x10``
=================  ===============================================================

Any other policy enters as a :class:`Method` built from a transform
(:meth:`Method.from_transform`) or a scene (:meth:`Method.from_scene`).
Results on the package's simulated grasps are results on synthetic data, not the paper's.
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import re
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.utils.data import Dataset

from ..data import AugmentedDataset
from ..scenes import ResizeToTarget, Scene
from ..transforms import AddNoise, FrameShift, RandomRotation, TemporalEventShift
from .models import ForceRegressor
from .training import (
    Stopwatch,
    TimedTransform,
    fit,
    phase_mse,
    predict,
    run_seeds,
    seed_everything,
    write_json_atomic,
)

__all__ = [
    "PAPER_METHODS",
    "TARGET_DIAMETER_MM",
    "PAPER_SCENE",
    "Method",
    "parse_method",
    "ProtocolConfig",
    "ProtocolData",
    "load_data",
    "MaterializedDataset",
    "build_training_set",
    "run_method",
    "run_protocol",
    "summarize",
    "format_table",
]

#: The methods the paper compares, in its order.
PAPER_METHODS: tuple[str, ...] = (
    "none", "rot45", "resize", "noise", "fs-1", "tes-2:0.5", "independent", "hybrid",
    "tes-2:0.5x10",
)
#: Diameter of the validation/test bolt: the resize target.
TARGET_DIAMETER_MM = 15.0



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
        needs_noise_bank: the transform needs :attr:`ProtocolData.noise_bank`.
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
            >>> from event_transforms.scenes import Scene
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


#: The paper's scene: 12 and 18 mm bolts in training, the 15 mm bolt to generalise to, and
#: events one frame later than the paper's best shift undoes (FS-1).
PAPER_SCENE = Scene(training_sizes=(12.0, 18.0), target_size=TARGET_DIAMETER_MM, lag_shifts=(-1,))

_NUMBER = r"[+-]?\d+(?:\.\d*)?(?:[eE][+-]?\d+)?"
_PATTERN = re.compile(
    rf"^(?P<base>none|resize|noise|independent|hybrid|rot(?P<deg>{_NUMBER})"
    rf"|fs(?P<fs>[+-]?\d+)|tes(?P<tes>[+-]?\d+):(?P<frac>{_NUMBER}))(?:x(?P<copies>\d+))?$"
)


def parse_method(name: str, *, copies: int = 1) -> Method:
    """Turn a method name (see the module docstring) into a :class:`Method`.

    Args:
        name: e.g. ``"none"``, ``"rot45"``, ``"resize"``, ``"fs-1"``, ``"tes-2:0.5x10"``.
        copies: synthetic copies per item when the name has no ``x<k>`` suffix.

    Example:
        >>> m = parse_method("tes-2:0.5x10")
        >>> m.copies, m.build()
        (10, TemporalEventShift(shift=-2, fraction=0.5, mode='exact'))
        >>> parse_method("resize").build()
        ResizeToTarget(target_size=15.0, key='diameter_mm', exponent=1.0, center='mass', mode='bilinear')
        >>> parse_method("none").copies
        0
    """
    if not isinstance(name, str):
        raise TypeError(f"method name must be a str, got {type(name).__name__}")
    match = _PATTERN.match(name.strip().lower())
    if match is None:
        raise ValueError(
            f"unknown method {name!r}; expected none, rot<deg>, resize, noise, fs<j>, "
            "tes<j>:<fraction>, independent or hybrid, optionally followed by x<copies>"
        )
    base = match["base"]
    if match["copies"] is not None:
        copies = int(match["copies"])
    if isinstance(copies, bool) or not isinstance(copies, int) or copies < 0:
        raise ValueError(f"copies must be a non-negative int, got {copies!r}")
    if base == "none":
        return Method(name, None, 0)
    if base == "resize":
        return Method(name, lambda bank: ResizeToTarget(TARGET_DIAMETER_MM), copies)
    if base == "noise":
        return Method(name, lambda bank: AddNoise(bank), copies, needs_noise_bank=True)
    if base in ("independent", "hybrid"):
        return Method.from_scene(name, PAPER_SCENE, copies, combination=base)
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


@dataclass
class ProtocolConfig:
    """Settings of one protocol run (the paper's are the defaults).

    Attributes:
        epochs: maximum epochs per training run.
        patience: early-stopping patience (epochs).
        batch_size: sequences per step.
        lr: Adam learning rate.
        hidden_channels: ConvLSTM channels per layer of the regressor.
        input_pool: the regressor's first average-pool factor.
        fixed: the synthetic copies are made once before training and every epoch sees
            the same ones (the paper's offline doubling; time counted as "aug once"),
            rather than drawn afresh every epoch in the data loader ("aug/epoch").
        copies: synthetic copies per item for names without ``x<k>``.
    """

    epochs: int = 500
    patience: int = 20
    batch_size: int = 8
    lr: float = 1e-3
    hidden_channels: tuple[int, ...] = (8, 16)
    input_pool: int = 4
    fixed: bool = True
    copies: int = 1

    def key(self) -> str:
        """A short hash of the settings, so results of different settings never mix."""
        text = json.dumps(asdict(self), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:10]


@dataclass
class ProtocolData:
    """Training, validation and test sets of ``(frames, force, meta)`` items.

    ``meta["diameter_mm"]`` of the training items drives the resize policy;
    ``noise_bank`` ``(N, 2, H, W)`` feeds the ``noise`` method.
    """

    train: Dataset
    val: Dataset
    test: Dataset
    noise_bank: torch.Tensor | None = None
    description: str = "custom data"


def load_data(root: str | None = None, *, noise_frames: int = 360) -> ProtocolData:
    """The simulated tactile grasps: 48 train (12 and 18 mm), val and test (15 mm).

    The noise bank is ``noise_frames`` frames of a simulated static scene (same camera).
    """
    from . import datasets

    train = datasets.TactileGrasps(split="train", root=root)
    val = datasets.TactileGrasps(split="val", root=root)
    test = datasets.TactileGrasps(split="test", root=root)
    bank = datasets.noise_bank(noise_frames, seed=0)
    return ProtocolData(train, val, test, bank, "simulated tactile grasps (synthetic data)")


def build_training_set(
    method: Method, data: ProtocolData, *, seed: int, fixed: bool, stopwatch: Stopwatch
) -> Dataset:
    """The training items followed by ``method.copies`` synthetic copies of each.

    One :class:`~event_transforms.AugmentedDataset` whose transform (wrapped in a
    :class:`~event_transforms.tactile.training.TimedTransform` reporting to ``stopwatch``)
    receives each item's metadata.
    """
    transform = method.build(data.noise_bank)
    if transform is None:
        return data.train
    return AugmentedDataset(data.train, TimedTransform(transform, stopwatch), method.copies, fixed=fixed, seed=seed)


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


def _force_stats(data: Dataset) -> tuple[float, float]:
    forces = torch.stack([torch.as_tensor(data[i][1]).double() for i in range(len(data))])
    return float(forces.mean()), float(forces.std()) if forces.numel() > 1 else 1.0


def run_method(
    method: Method | str,
    data: ProtocolData,
    config: ProtocolConfig,
    seeds: Sequence[int],
    directory: str | Path,
    *,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Train ``method`` once per seed (resumably, under ``directory``); per-seed results."""
    if isinstance(method, str):
        method = parse_method(method, copies=config.copies)
    if method.needs_noise_bank and data.noise_bank is None:
        raise ValueError(f"method {method.name!r} needs data.noise_bank, got None")
    offset, scale = _force_stats(data.train)

    def run_one(seed: int) -> dict[str, Any]:
        seed_everything(seed)
        model = ForceRegressor(hidden_channels=config.hidden_channels, input_pool=config.input_pool)
        model.set_force_scaling(offset, max(scale, 1e-6))
        watch = Stopwatch()
        train = build_training_set(method, data, seed=seed, fixed=config.fixed, stopwatch=watch)
        if config.fixed and method.copies > 0:
            train = MaterializedDataset(train)  # the copies are made once, before training
        setup_s = watch.seconds
        result = fit(
            model, train, data.val, epochs=config.epochs, patience=config.patience,
            lr=config.lr, batch_size=config.batch_size, seed=seed, stopwatch=watch,
            progress=progress, description=f"{method.name} seed {seed}",
        )
        val_pred, val_target, _ = predict(model, data.val)
        test_pred, test_target, _ = predict(model, data.test)
        return {
            "method": method.name,
            "seed": seed,
            "copies": method.copies,
            "train_items": len(train),
            "best_val_mse": result.best_val_loss,
            "best_epoch": result.best_epoch,
            "epochs_run": result.epochs_run,
            "stopped_early": result.stopped_early,
            "val_phase_mse": phase_mse(val_pred, val_target),
            "test_mse": phase_mse(test_pred, test_target)["all"],
            "test_phase_mse": phase_mse(test_pred, test_target),
            "augmentation_setup_s": setup_s,
            "augmentation_s_per_epoch": result.augmentation_s_per_epoch,
            "train_s_per_epoch": result.train_s_per_epoch,
            "train_s_total": result.total_s + setup_s,
            "history": [asdict(r) for r in result.history],
            "test_examples": {
                "predicted": test_pred[:2].tolist(),
                "measured": test_target[:2].tolist(),
            },
        }

    def done(seed: int, result: dict[str, Any], resumed: bool) -> None:
        if log is not None:
            how = "resumed from disk" if resumed else f"{result['train_s_total']:.1f} s"
            log(
                f"  {method.name:>14} seed {seed}: val MSE {result['best_val_mse']:.3f}, "
                f"test MSE {result['test_mse']:.3f}, {result['epochs_run']} epochs ({how})"
            )

    slug = re.sub(r"[^a-z0-9.+-]+", "_", method.name.lower())
    return run_seeds(run_one, list(seeds), Path(directory) / slug, on_done=done)


def _mean_std(values: Sequence[float]) -> dict[str, Any]:
    values = [float(v) for v in values]
    std = statistics.stdev(values) if len(values) > 1 else 0.0
    return {"mean": statistics.fmean(values), "std": std, "values": values}


def summarize(per_seed: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean ± sample std over seeds of every reported quantity of one method."""
    if not per_seed:
        raise ValueError("per_seed must hold at least one seed's result, got none")
    first = per_seed[0]
    return {
        "method": first["method"],
        "copies": first["copies"],
        "train_items": first["train_items"],
        "seeds": [r["seed"] for r in per_seed],
        "best_val_mse": _mean_std([r["best_val_mse"] for r in per_seed]),
        "test_mse": _mean_std([r["test_mse"] for r in per_seed]),
        "test_phase_mse": {
            phase: _mean_std([r["test_phase_mse"][phase] for r in per_seed])
            for phase in ("grasp", "hold", "release")
        },
        "epochs_run": _mean_std([r["epochs_run"] for r in per_seed]),
        "augmentation_setup_s": _mean_std([r["augmentation_setup_s"] for r in per_seed]),
        "augmentation_s_per_epoch": _mean_std([r["augmentation_s_per_epoch"] for r in per_seed]),
        "train_s_per_epoch": _mean_std([r["train_s_per_epoch"] for r in per_seed]),
        "train_s_total": _mean_std([r["train_s_total"] for r in per_seed]),
    }


def format_table(summaries: dict[str, dict[str, Any]], *, timings: bool = True) -> str:
    """A markdown table, one row per method (MSE in N², Δ relative to ``none``).

    Args:
        summaries: method name -> :func:`summarize` output, in row order.
        timings: include the timing columns (they differ from run to run).
    """
    baseline = summaries.get("none", {}).get("best_val_mse", {}).get("mean")
    head = ["method", "copies", "val MSE", "Δ vs none", "test MSE", "grasp", "hold", "release"]
    if timings:
        head += ["aug ms once", "aug ms/epoch", "train s/epoch", "train s total"]
    rows = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    for name, s in summaries.items():
        val = s["best_val_mse"]
        delta = (
            f"{100 * (val['mean'] - baseline) / baseline:+.1f} %"
            if baseline and name != "none" and math.isfinite(baseline)
            else "—"
        )
        phases = s["test_phase_mse"]
        cells = [
            name,
            str(s["copies"]),
            f"{val['mean']:.2f} ± {val['std']:.2f}",
            delta,
            f"{s['test_mse']['mean']:.2f} ± {s['test_mse']['std']:.2f}",
            *(f"{phases[p]['mean']:.2f}" for p in ("grasp", "hold", "release")),
        ]
        if timings:
            cells += [
                f"{1000 * s['augmentation_setup_s']['mean']:.0f}",
                f"{1000 * s['augmentation_s_per_epoch']['mean']:.1f}",
                f"{s['train_s_per_epoch']['mean']:.2f}",
                f"{s['train_s_total']['mean']:.1f}",
            ]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


@dataclass
class ProtocolResults:
    """What :func:`run_protocol` returns and writes to ``results.json``."""

    config: dict[str, Any]
    seeds: list[int]
    methods: dict[str, dict[str, Any]]
    per_seed: dict[str, list[dict[str, Any]]]
    environment: dict[str, Any] = field(default_factory=dict)
    data: str = ""


def run_protocol(
    methods: Sequence[str | Method],
    seeds: Sequence[int],
    out: str | Path,
    *,
    config: ProtocolConfig | None = None,
    data: ProtocolData | None = None,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
) -> ProtocolResults:
    """Run every method for every seed; write ``results.json`` and ``results.md`` to ``out``.

    Finished seeds are kept under ``out/runs/<settings hash>/<method>/`` so an interrupted
    run resumes where it stopped. The markdown table is also returned in the results
    (``format_table(results.methods)``).
    """
    config = config or ProtocolConfig()
    out = Path(out)
    data = data if data is not None else load_data()
    parsed = [m if isinstance(m, Method) else parse_method(m, copies=config.copies) for m in methods]
    names = [m.name for m in parsed]
    if len(set(names)) != len(names):
        raise ValueError(f"methods must have distinct names, got {names}")
    runs = out / "runs" / config.key()
    write_json_atomic(runs / "config.json", asdict(config))
    per_seed, summaries = {}, {}
    start = time.perf_counter()
    for method in parsed:
        if log is not None:
            log(f"{method.name}: {method.copies} synthetic copies per item, seeds {list(seeds)}")
        per_seed[method.name] = run_method(
            method, data, config, seeds, runs, progress=progress, log=log
        )
        summaries[method.name] = summarize(per_seed[method.name])
    results = ProtocolResults(
        config=asdict(config),
        seeds=list(seeds),
        methods=summaries,
        per_seed=per_seed,
        environment={
            "torch": torch.__version__,
            "threads": torch.get_num_threads(),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "wall_s_this_invocation": time.perf_counter() - start,
        },
        data=data.description,
    )
    write_json_atomic(out / "results.json", asdict(results))
    (out / "results.md").write_text(format_table(summaries) + "\n")
    return results
