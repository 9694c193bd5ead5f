"""One unit of a protocol run: a scene's methods × seeds trained together, then scored.

The training itself is :func:`~event_transforms.tactile.training.train` (the one trainer,
also behind ``event-transforms train``); this module turns its members into the per-method,
per-seed records a run keeps on disk.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import torch

from ..copies import SceneData
from ..resampling import bootstrap_indices, item_groups
from ..benchmark_scenes import BenchmarkScene, get_scene
from ..training import evaluate, phase_mse, train
from .config import ProtocolConfig
from .shared import SHARED_SEPARATOR

__all__ = ["run_unit"]


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
    on_validation: Callable[[dict[str, Any]], None] | None = None,
    also: Sequence[tuple[str, str, str]] = (),
    also_data: Mapping[str, SceneData] | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """Train ``methods`` × ``seeds`` of one scene as one ensemble; per-method, per-seed results.

    Member (method, seed) starts from the weights ``ForceRegressor`` draws after
    ``torch.manual_seed(seed)`` (the same for every method), reads the batches of
    :func:`~event_transforms.tactile.copies.paired_batches` for ``seed`` (the same originals at
    the same steps for every method) and makes its copies with ``seed``. Every member takes
    ``config.steps`` steps; the weights with the lowest MSE on ``data.holdout`` (checked every
    ``config.eval_every`` steps) are kept, then scored on validation and test. The training
    is :func:`~event_transforms.tactile.training.train` with ``config``'s settings.

    ``also`` lists members other scenes borrow (``(method, scene, its method)``, see
    :mod:`~event_transforms.tactile.protocol.shared`): the same weights are scored on the
    validation and test sets of ``also_data[scene]`` too, and kept under ``"scene::method"``.
    """
    scene = data.scene if isinstance(scene, str) and scene == data.scene.name else get_scene(scene)
    trained = train(data, methods, seeds, **config.training_settings(), scene=scene, device=device,
                    progress=progress, description=description, on_validation=on_validation)
    result, holdout = trained.result, trained.holdout
    passes = config.steps * config.batch_size  # sequences read per member
    out: dict[str, list[dict[str, Any]]] = {}
    scored = [(data, {m: [m] for m in methods}, "")]
    for method_name, other, other_method in also:
        if also_data is None or other not in also_data:
            raise ValueError(f"run_unit: also names scene {other!r}, which also_data lacks")
        scored.append((also_data[other], {method_name: [other_method]}, other))
    for target, names, prefix in scored:
        val_pred, val_target = evaluate(trained.model, target.val)
        test_pred, test_target = evaluate(trained.model, target.test)
        picks: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}
        if config.resample == "bootstrap":  # each seed's resamples, the recordings grouped once per split
            groups = item_groups(target.val), item_groups(target.test)
            picks = {seed: (bootstrap_indices(len(target.val), seed, "val", groups[0]),
                            bootstrap_indices(len(target.test), seed, "test", groups[1]))
                     for seed in set(trained.seeds)}
        for index, record in enumerate(result.members):
            for name in names.get(trained.methods[index].name, ()):
                key = f"{prefix}{SHARED_SEPARATOR}{name}" if prefix else name
                out.setdefault(key, []).append(_record(trained, index, record, result, holdout, passes,
                                                       val_pred, val_target, test_pred, test_target,
                                                       picks=picks.get(trained.seeds[index])))
    return out


def _record(trained: Any, index: int, record: Any, result: Any, holdout: bool, passes: int,
            val_pred: torch.Tensor, val_target: torch.Tensor, test_pred: torch.Tensor,
            test_target: torch.Tensor, *, picks: tuple[torch.Tensor, torch.Tensor] | None = None) -> dict[str, Any]:
    """One member's record: its training (shared by every scene that scores it) and its scores,
    on its seed's resample of the validation and test sequences where ``picks`` gives them
    (the paper's 6 + 6 split and the examples read the first sequences as they are)."""
    method = trained.methods[index]
    size = trained.train_items[index]
    member_augment = trained.augment[index]
    val_scored, val_measured = val_pred[index], val_target
    test_scored, test_measured = test_pred[index], test_target
    if picks is not None:
        val_scored, val_measured = val_scored[picks[0]], val_measured[picks[0]]
        test_scored, test_measured = test_scored[picks[1]], test_measured[picks[1]]
    test_phases = phase_mse(test_scored, test_measured)
    return {
        "seed": trained.seeds[index],
        "copies": method.copies,
        "train_items": size,
        "steps": result.steps,
        # the stopping rule: the step whose weights were kept, and their hold-out MSE
        "stopping": "best hold-out MSE" if holdout else "final weights (no hold-out)",
        "best_step": record.best_step if holdout else result.steps,
        "holdout_mse": record.selected_val_loss if holdout else math.nan,
        "test_mse": test_phases["all"],
        "test_phase_mse": test_phases,
        "val_mse": phase_mse(val_scored, val_measured)["all"],
        # with-labels trained on the validation items: its val_mse is in-sample (its test MSE is not)
        "trained_on_val": method.reads_deployment_labels,
        # the paper's 6 + 6 split: the first 6 sequences of val and test
        "val_mse_paper_split": phase_mse(val_pred[index, :6], val_target[:6])["all"],
        "test_mse_paper_split": phase_mse(test_pred[index, :6], test_target[:6])["all"],
        "final_train_loss": record.train_loss[-1] if record.train_loss else math.nan,
        "holdout_history": {"steps": record.val_steps, "mse": record.val_loss},
        "aug_s_once": trained.aug_s_once[index],
        # online copies: this member's augmentation time, per pass over its set
        "aug_s_per_epoch": (
            member_augment.stopwatch.seconds * size / max(passes, 1) if member_augment is not None else 0.0
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
