"""The one trainer: where a scene's methods are trained, by the protocol and by ``event-transforms train``.

Read from the top:

- :func:`train` — the entry point. It turns method names and seeds into members (one
  :class:`~event_transforms.tactile.models.ForceRegressor` per method × seed, the same initial
  weights for every method of a seed), builds each member's training set (synthetic copies
  made once, or on the training device batch by batch), the paired batch order, the force
  scaling, and trains them all in lockstep as one
  :class:`~event_transforms.tactile.ensemble.EnsembleForceRegressor` with :func:`fit_ensemble`.
  The protocol's unit (:func:`~event_transforms.tactile.protocol.unit.run_unit`) and
  :func:`~event_transforms.tactile.deployment.train_model` both call it.
- :func:`fit_ensemble` — the optimiser loop: Adam, a one-cycle (or cosine) learning rate,
  per-member gradient clipping (:func:`clip_grad_norm_per_member_`), periodic validation and
  the stopping rule (the weights with the lowest hold-out MSE), batch order
  :func:`shuffled_batches` unless given.
- :func:`evaluate` and :func:`force_stats` — a trained ensemble's predictions on a data set,
  and the training forces' mean and standard deviation.
- what the loop and the protocol share: :class:`Stopwatch`, :class:`TimedTransform` (time
  spent inside an augmentation), :func:`collate`, :func:`mse`, :func:`phase_mse`.

:func:`write_json_atomic` is re-exported from the application's one atomic writer,
:mod:`event_transforms.tactile._files`.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import torch
from torch import Tensor

from .._validation import check_positive, check_seed
from ._files import write_json_atomic
from .ensemble import EnsembleForceRegressor, predict_ensemble
from .copies import shuffled_batches
from .stopwatch import Stopwatch, TimedTransform

if TYPE_CHECKING:
    from ..data import SizedDataset
    from .copies import DeviceAugment, SceneData
    from .methods import Method
    from .benchmark_scenes import BenchmarkScene

__all__ = [
    "train",
    "TrainedEnsemble",
    "fit_ensemble",
    "MemberRecord",
    "EnsembleResult",
    "shuffled_batches",
    "clip_grad_norm_per_member_",
    "evaluate",
    "force_stats",
    "Stopwatch",
    "TimedTransform",
    "collate",
    "mse",
    "phase_mse",
    "PHASE_EDGE",
    "write_json_atomic",
]


# ----------------------------------------------------------------------------- the entry point


@dataclass
class TrainedEnsemble:
    """What :func:`train` made. Lists run over the members, method-major (member
    ``i`` is method ``i // len(seeds)``, seed ``seeds[i % len(seeds)]``).

    Attributes:
        model: the ensemble, holding the kept weights (on the training device).
        result: the trainer's record (losses, hold-out history, kept step, times).
        methods: each member's parsed method.
        seeds: each member's seed.
        train_items: each member's training-set size (originals and copies).
        aug_s_once: seconds spent making each member's fixed copies before training.
        augment: each member's on-device augmentation (its ``stopwatch`` holds the time), or ``None``.
        force_offset: the training forces' mean (every member's output offset).
        force_scale: their standard deviation (at least 1e-6; every member's output scale).
        holdout: the stopping rule had hold-out data (else the final weights were kept).
    """

    model: EnsembleForceRegressor
    result: EnsembleResult
    methods: list[Method]
    seeds: list[int]
    train_items: list[int]
    aug_s_once: list[float]
    augment: list[DeviceAugment | None]
    force_offset: float
    force_scale: float
    holdout: bool


def train(
    data: SceneData,
    methods: Sequence[str],
    seeds: Sequence[int],
    *,
    steps: int = 1500,
    batch_size: int = 8,
    lr: float = 1e-2,
    clip: float = 1.0,
    eval_every: int = 100,
    hidden_channels: Sequence[int] = (8, 16),
    input_pool: int = 4,
    cumulative: bool = True,
    fixed: bool = True,
    copies: int = 1,
    paired: bool = True,
    resample: str = "none",
    scene: BenchmarkScene | None = None,
    device: str | torch.device = "cpu",
    progress: bool | None = None,
    description: str | None = None,
    on_validation: Callable[[dict[str, Any]], None] | None = None,
) -> TrainedEnsemble:
    """Train ``methods`` × ``seeds`` on ``data`` as one ensemble: the protocol's rules, in one place.

    Member (method, seed) starts from the weights ``ForceRegressor`` draws after
    ``torch.manual_seed(seed)`` (the same for every method), reads the batches of
    :func:`~event_transforms.tactile.copies.paired_batches` for ``seed`` (the same originals
    at the same steps for every method; ``paired=False``: its own :func:`shuffled_batches`)
    and makes its copies with ``seed``. Every member takes ``steps`` Adam steps with a
    one-cycle learning rate peaking at ``lr`` and gradients clipped to ``clip`` per member,
    its output scaled by the training forces' mean and standard deviation; the weights with
    the lowest MSE on ``data.holdout`` (checked every ``eval_every`` steps) are kept, the
    final ones without a hold-out set. The defaults are
    :class:`~event_transforms.tactile.protocol.config.ProtocolConfig`'s.

    Args:
        data: the scene's training, hold-out, validation and test sets and noise bank
            (:class:`~event_transforms.tactile.copies.SceneData`).
        methods: method names (:func:`~event_transforms.tactile.methods.parse_method`).
        seeds: one member per method and seed.
        steps: optimiser steps of every member.
        batch_size: sequences per member per step.
        lr: peak learning rate of the one-cycle schedule.
        clip: gradient-norm limit per member.
        eval_every: steps between passes over the hold-out sequences (the stopping rule).
        hidden_channels: ConvLSTM channels per layer of every member.
        input_pool: the members' first average-pool factor.
        cumulative: the members also read running event totals.
        fixed: copies made once before training; ``False``: on the training device per batch.
        copies: synthetic copies per item for method names without ``x<k>``.
        paired: the paired batch order across methods.
        resample: ``"bootstrap"``: member (method, seed) reads seed's bootstrap resample of
            ``data.train`` (:func:`~event_transforms.tactile.resampling.bootstrap_indices`; the
            same for every method of the seed; needs ``paired``); ``"none"`` or ``"fresh"`` (``data``
            is already the seed's own data set): every item.
        scene: the scene the method names are read for; default ``data.scene``.
        device: where to train.
        progress: a progress bar (``None``: when stderr is a terminal).
        description: the progress label; default the scene and method names.
        on_validation: called after every validation pass (see :func:`fit_ensemble`).

    Example:
        >>> from event_transforms.tactile.copies import SceneData
        >>> from event_transforms.tactile.benchmark_scenes import get_scene
        >>> g = torch.Generator().manual_seed(0)
        >>> def items(n):
        ...     frames = torch.poisson(torch.full((n, 12, 2, 8, 8), 0.5), generator=g)
        ...     return [(f, f.sum((1, 2, 3)) / 20, {"diameter_mm": 15.0}) for f in frames]
        >>> data = SceneData(get_scene("paper"), items(6), items(3), items(3), holdout=items(2))
        >>> trained = train(data, ["none", "fs1"], [0, 1], steps=4, batch_size=2, eval_every=2,
        ...                 hidden_channels=(2,), input_pool=4, progress=False)
        >>> trained.model.members, trained.train_items, trained.seeds
        (4, [6, 6, 12, 12], [0, 1, 0, 1])
        >>> pred, measured = evaluate(trained.model, data.test)
        >>> tuple(pred.shape), tuple(measured.shape)
        ((4, 3, 12), (3, 12))
    """
    from .copies import DeviceAugment, OnlineCopies, WithLabels, build_training_set, paired_batches
    from .resampling import check_resample, resample_batches, split_resample
    from .methods import parse_method
    from .models import ForceRegressor

    if isinstance(methods, str) or not methods:
        raise ValueError(f"methods must be a non-empty sequence of method names, got {methods!r}")
    if isinstance(seeds, (str, bytes)) or not seeds:
        raise ValueError(f"seeds must be a non-empty sequence of ints, got {seeds!r}")
    seeds = [check_seed(seed, "seeds") for seed in seeds]
    if check_resample(resample) == "bootstrap" and not paired:
        raise ValueError(f"resample={resample!r} reads each seed's resample through the paired batches: "
                         "it needs paired=True")
    scene = data.scene if scene is None else scene
    parsed = [parse_method(m, copies=copies, scene=scene) for m in methods]
    if len({p.model for p in parsed}) > 1:
        raise ValueError(f"methods {list(methods)} build models of different settings "
                         f"({sorted({p.model for p in parsed})}): train them in separate ensembles")
    offset, scale = force_stats(data.train)
    augment: list[DeviceAugment | None]
    train_sets: list[Any] = []
    models, member_seeds, aug_once, augment, batches = [], [], [], [], []
    watch = Stopwatch()
    for method in parsed:
        for seed in seeds:
            torch.manual_seed(seed)
            models.append(ForceRegressor(hidden_channels=tuple(hidden_channels), input_pool=input_pool,
                                         cumulative=cumulative, **dict(method.model)))
            before = watch.seconds
            transform = method.build(data.noise_bank)
            if method.reads_deployment_labels:  # with-labels: the labelled deployment items added, no copies
                train_sets.append(WithLabels(data.train, data.val if data.labelled is None else data.labelled))
                augment.append(None)
            elif fixed or transform is None:
                train_sets.append(build_training_set(method, data, seed=seed, fixed=True, stopwatch=watch))
                augment.append(None)
            else:  # on the fly: copies are transformed batch by batch on the training device
                train_sets.append(OnlineCopies(data.train, method.copies))
                augment.append(DeviceAugment(transform.to(device), seed))
            aug_once.append(watch.seconds - before)
            member_seeds.append(int(seed))
            member_copies = method.copies if transform is not None else 0
            if paired:  # with-labels: its own paired order over its larger set (the seed's, every other draw alike)
                items = train_sets[-1] if method.reads_deployment_labels else data.train
                order = paired_batches(len(items), member_copies, batch_size, steps, seed=seed)
                if resample == "bootstrap":
                    order = resample_batches(order, len(items), split_resample(items, seed, "train"))
                batches.append(order)
    scale = max(scale, 1e-6)
    ensemble = EnsembleForceRegressor.from_models(models).to(device)
    ensemble.set_force_scaling([offset] * len(models), [scale] * len(models))
    holdout = data.holdout is not None
    result = fit_ensemble(
        ensemble, train_sets, data.holdout if holdout else data.train, steps=steps,
        batch_size=batch_size, seeds=member_seeds, lr_max=lr, clip=clip, schedule="one-cycle",
        eval_every=eval_every, select="best" if holdout else "final", device=device, progress=progress,
        augment=augment, batches=batches if paired else None, on_validation=on_validation,
        fixed_data=True,  # every training set here is fixed (on-the-fly copies go through augment)
        description=description or f"{scene.name}: {', '.join(methods)}",
    )
    return TrainedEnsemble(
        model=ensemble, result=result, methods=[parsed[i // len(seeds)] for i in range(len(models))],
        seeds=member_seeds, train_items=[len(s) for s in train_sets], aug_s_once=aug_once, augment=augment,
        force_offset=offset, force_scale=scale, holdout=holdout,
    )


def evaluate(model: EnsembleForceRegressor, data: Any, batch_size: int = 16) -> tuple[Tensor, Tensor]:
    """Predicted and measured force ``(M, N, T)`` / ``(N, T)`` (float64, CPU) of every member on ``data``
    (a Dataset of ``(frames, force, ...)`` items or a ``(frames, force)`` pair), through
    :func:`~event_transforms.tactile.ensemble.predict_ensemble`."""
    from .baselines import stack_items

    frames, force = stack_items(data)
    return predict_ensemble(model, frames, batch_size=batch_size).double().cpu(), force.double()


def force_stats(data: SizedDataset) -> tuple[float, float]:
    """Mean and standard deviation (1.0 for a single value) of every force of ``data``'s items.

    Example:
        >>> force_stats([(None, torch.tensor([1.0, 3.0])), (None, torch.tensor([5.0, 7.0]))])
        (4.0, 2.581988897471611)
    """
    forces = torch.stack([torch.as_tensor(data[i][1]).double() for i in range(len(data))])
    return float(forces.mean()), float(forces.std()) if forces.numel() > 1 else 1.0


# ----------------------------------------------------------------------------- the optimiser loop


def clip_grad_norm_per_member_(parameters: Sequence[Tensor], max_norm: float) -> Tensor:
    """Clip each member's gradient to norm ``max_norm``; return the norms before clipping.

    Every parameter's first dimension is the member. Member ``m``'s norm is the 2-norm over
    its slices of every gradient, and its slices are scaled by
    ``min(1, max_norm / (norm + 1e-6))``, as :func:`torch.nn.utils.clip_grad_norm_` does for
    one model. No host synchronisation.

    Example:
        >>> w = torch.zeros(2, 3, requires_grad=True)
        >>> w.grad = torch.tensor([[3.0, 4.0, 0.0], [0.3, 0.4, 0.0]])
        >>> clip_grad_norm_per_member_([w], 1.0).tolist()
        [5.0, 0.5]
        >>> [[round(v, 4) for v in row] for row in w.grad.tolist()]
        [[0.6, 0.8, 0.0], [0.3, 0.4, 0.0]]
    """
    grads = [p.grad for p in parameters if p.grad is not None]
    if not grads:
        return torch.zeros(0)
    # member by member: a row reduction of (M, K) sums in another order than the same row
    # alone, and a last-bit change in the clip scale made a seed's training depend on how
    # many members shared its ensemble (issue 24)
    squares = torch.stack(
        [torch.stack([g.detach()[m].square().sum() for g in grads]).sum() for m in range(grads[0].shape[0])]
    )
    norms = squares.sqrt()
    coef = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.detach().mul_(coef.view(-1, *([1] * (g.dim() - 1))).to(g.dtype))
    return norms


@dataclass
class MemberRecord:
    """What one member of :func:`fit_ensemble` did (losses in N², steps counted from 1)."""

    member: int
    seed: int
    steps: int
    train_loss: list[float] = field(default_factory=list)
    val_steps: list[int] = field(default_factory=list)
    val_loss: list[float] = field(default_factory=list)
    best_val_loss: float = math.inf
    best_step: int = 0
    stopped_step: int | None = None
    selected_val_loss: float = math.inf


@dataclass
class EnsembleResult:
    """Outcome of :func:`fit_ensemble`; the model holds the selected weights afterwards.

    ``train_s`` is the wall time of the optimiser steps (data loading and augmentation
    included), ``augmentation_s`` the part of it spent inside a timed augmentation
    (:class:`~event_transforms.tactile.training.Stopwatch`), ``val_s`` the validation time.
    """

    members: list[MemberRecord]
    steps: int
    select: str
    schedule: str
    train_s: float
    val_s: float
    augmentation_s: float
    total_s: float

    @property
    def seconds_per_step(self) -> float:
        """Training wall time per optimiser step (all members together)."""
        return self.train_s / max(self.steps, 1)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        out = asdict(self)
        out["seconds_per_step"] = self.seconds_per_step
        return out


def _stack_member_batch(
    data: Any, indices: Tensor, collate: Callable[[Sequence[Any]], tuple]
) -> tuple[Tensor, Tensor, list]:
    frames, force, metas = collate([data[int(i)] for i in indices])
    return frames, force, metas


def _validation_mse(model: EnsembleForceRegressor, frames: Tensor, force: Tensor, batch_size: int) -> Tensor:
    """Per-member MSE over every frame of the shared, pooled validation set, ``(M,)`` float64."""
    pred = predict_ensemble(model, frames, batch_size=batch_size, pooled=True)
    return (pred.double() - force.double()).square().mean(dim=(1, 2))


def fit_ensemble(
    model: EnsembleForceRegressor,
    train_sets: Sequence[Any],
    val_data: Any,
    *,
    steps: int,
    batch_size: int = 8,
    seeds: Sequence[int],
    lr_max: float = 1e-2,
    clip: float | None = 1.0,
    schedule: str = "one-cycle",
    eval_every: int | None = None,
    patience: int | None = None,
    select: str = "final",
    val_batch_size: int = 32,
    device: str | torch.device | None = None,
    progress: bool | None = None,
    stopwatch: Any | None = None,
    description: str = "ensemble",
    augment: Sequence[Callable[[Tensor, list], Tensor] | None] | None = None,
    batches: Sequence[Tensor] | None = None,
    on_validation: Callable[[dict[str, Any]], None] | None = None,
    fixed_data: bool = False,
) -> EnsembleResult:
    """Train every member of ``model`` for exactly ``steps`` optimiser steps, in lockstep.

    Member ``m`` reads ``train_sets[m]`` (items ``(frames, force, meta)``; sizes may differ:
    copies add data, not steps), in batches of ``batch_size`` from :func:`shuffled_batches`
    with ``seeds[m]``. The loss is the sum over members of each member's MSE, so every
    member gets its own gradient; Adam (elementwise) over all parameters, the learning rate
    following ``schedule``, gradients clipped per member (:func:`clip_grad_norm_per_member_`).

    Every ``eval_every`` steps and after the last step, each member's validation MSE on
    ``val_data`` (shared by all members) is computed. With ``patience``, a member whose
    validation MSE has not improved for ``patience`` evaluations is frozen: its slices are
    restored after every later optimiser step, so Adam's momentum cannot move it; training
    ends early when every member is frozen. At the end, ``select="best"`` loads each
    member's best-validation weights, ``"final"`` keeps the final ones (a frozen member's are
    those it had when frozen).

    Augmentation inside the data sets that draws from torch's global RNG is not seeded
    here; seed it before calling for reproducible runs. The force scaling of the members is
    not changed (set it first with :meth:`EnsembleForceRegressor.set_force_scaling`).

    Args:
        model: the ensemble; trained in place on ``device``.
        train_sets: one Dataset per member, items ``(frames, force, meta)``.
        val_data: a Dataset of such items, or a ``(frames, force)`` pair.
        steps: optimiser steps per member.
        batch_size: sequences per member per step.
        seeds: one shuffling seed per member.
        lr_max: peak (one-cycle) or initial (cosine, constant) learning rate.
        clip: per-member gradient-norm limit; ``None`` for no clipping.
        schedule: ``"one-cycle"`` (:class:`torch.optim.lr_scheduler.OneCycleLR` with its
            defaults: 30 % warm-up from ``lr_max / 25``, cosine annealing to
            ``lr_max / 25e4``), ``"cosine"`` (to zero) or ``"constant"``.
        eval_every: steps between validations; default ``max(1, steps // 20)``.
        patience: evaluations without improvement before a member is frozen; ``None`` never.
        select: ``"final"`` or ``"best"``.
        val_batch_size: sequences per validation forward pass.
        device: where to train; default the model's device.
        progress: a tqdm bar; ``None`` shows it only when stderr is a terminal.
        stopwatch: the :class:`~event_transforms.tactile.training.Stopwatch` of a
            ``TimedTransform`` inside the data sets; reported as ``augmentation_s``.
        description: label of the progress bar.
        augment: per member, ``None`` or a callable ``(frames, metas) -> frames`` applied to
            the member's batch ``(B, T, 2, H, W)`` after it is moved to ``device``: on-the-fly
            augmentation on the training device (its time is counted in ``train_s``).
        batches: per member, the item indices ``(steps, batch_size)`` of every step, instead
            of :func:`shuffled_batches` (e.g. a schedule that gives paired members the same
            items at the same steps).
        on_validation: called after every validation pass with a dict ``step``, ``steps``,
            ``train_loss`` (mean over members of the last step's MSE), ``val_mse`` (one per
            member), ``elapsed_s``.
        fixed_data: the training sets return the same item for an index every time (no
            randomness in ``__getitem__``, e.g. fixed copies): every item of a set is read
            and pooled (:meth:`EnsembleForceRegressor.pool`) once, before the first step,
            instead of at every step. Members with an ``augment`` callable still read and
            pool their batches at every step.

    With ``progress=None`` and stderr not a terminal, one plain line per validation pass
    (step, training loss, validation MSE range, elapsed time and ETA) replaces the bar.

    Example:
        >>> from torch.utils.data import TensorDataset
        >>> g = torch.Generator().manual_seed(0)
        >>> x = torch.poisson(torch.full((6, 5, 2, 8, 8), 0.5), generator=g)
        >>> data = TensorDataset(x, x.sum((2, 3, 4)) / 20)
        >>> _ = torch.manual_seed(0)
        >>> ensemble = EnsembleForceRegressor(2, hidden_channels=(2,), input_pool=2)
        >>> result = fit_ensemble(ensemble, [data, data], data, steps=6, batch_size=2,
        ...                       seeds=[0, 1], eval_every=3, select="best", progress=False)
        >>> [m.val_steps for m in result.members], len(result.members[0].train_loss)
        ([[3, 6], [3, 6]], 6)
    """
    try:
        from tqdm.auto import tqdm
    except ImportError as error:
        raise ImportError(
            "the training loop needs tqdm, which is not installed: pip install 'event-transforms[app]'",
            name="tqdm",
        ) from error

    from .baselines import stack_items

    if not isinstance(model, EnsembleForceRegressor):
        raise TypeError(f"model must be an EnsembleForceRegressor, got {type(model).__name__}")
    members = model.members
    steps = check_positive(steps, "steps", integer=True)
    batch_size = check_positive(batch_size, "batch_size", integer=True)
    val_batch_size = check_positive(val_batch_size, "val_batch_size", integer=True)
    eval_every = max(1, steps // 20) if eval_every is None else check_positive(eval_every, "eval_every", integer=True)
    if patience is not None:
        check_positive(patience, "patience", integer=True)
    if augment is not None and len(augment) != members:
        raise ValueError(f"augment must hold one callable or None per member ({members}), got {len(augment)}")
    if isinstance(train_sets, (str, bytes)) or not isinstance(train_sets, Sequence) or len(train_sets) != members:
        raise ValueError(f"train_sets must hold one Dataset per member ({members}), got {train_sets!r:.80}")
    seeds = list(seeds)
    if len(seeds) != members or not all(isinstance(s, int) and not isinstance(s, bool) for s in seeds):
        raise ValueError(f"seeds must be {members} ints, one per member, got {seeds!r}")
    if select not in ("final", "best"):
        raise ValueError(f"select must be 'final' or 'best', got {select!r}")
    if schedule not in ("one-cycle", "cosine", "constant"):
        raise ValueError(f"schedule must be 'one-cycle', 'cosine' or 'constant', got {schedule!r}")
    if not (isinstance(lr_max, (int, float)) and math.isfinite(lr_max) and lr_max > 0):
        raise ValueError(f"lr_max must be a positive number, got {lr_max!r}")
    if clip is not None and not (isinstance(clip, (int, float)) and math.isfinite(clip) and clip > 0):
        raise ValueError(f"clip must be a positive number or None, got {clip!r}")
    for index, data in enumerate(train_sets):
        if len(data) == 0:
            raise ValueError(f"train_sets[{index}] is empty")

    if not isinstance(fixed_data, bool):
        raise TypeError(f"fixed_data must be a bool, got {fixed_data!r}")
    device = model.head_weight.device if device is None else torch.device(device)
    model.to(device)
    val_frames, val_force = stack_items(val_data)
    val_frames, val_force = model.pool(val_frames.to(device)), val_force.to(device)
    # fixed data: each set's items pooled once, (N, T, C, h, w) and (N, T), shared by members
    pooled_sets: dict[int, tuple[Tensor, Tensor]] = {}
    if fixed_data:
        for m, data in enumerate(train_sets):
            if (augment is None or augment[m] is None) and id(data) not in pooled_sets:
                chunks, forces = [], []
                for first in range(0, len(data), 16):  # 16 raw items in memory at a time
                    frames, force, _ = collate([data[i] for i in range(first, min(first + 16, len(data)))])
                    chunks.append(model.pool(frames.to(device)))
                    forces.append(force.to(device))
                pooled_sets[id(data)] = (torch.cat(chunks), torch.cat(forces))
    if batches is None:
        batches = [shuffled_batches(len(data), batch_size, steps, seed=seed) for data, seed in zip(train_sets, seeds)]
    else:
        batches = [torch.as_tensor(b, dtype=torch.int64) for b in batches]
        if len(batches) != members:
            raise ValueError(f"batches must hold one index tensor per member ({members}), got {len(batches)}")
        for index, (b, data) in enumerate(zip(batches, train_sets)):
            if tuple(b.shape) != (steps, batch_size) or (b.numel() and not 0 <= int(b.min()) <= int(b.max()) < len(data)):
                raise ValueError(
                    f"batches[{index}] must be ({steps}, {batch_size}) indices into train_sets[{index}] "
                    f"({len(data)} items), got shape {tuple(b.shape)}"
                )
    watch = stopwatch if stopwatch is not None else Stopwatch()
    params = list(model.parameters())
    optimiser = torch.optim.Adam(params, lr=lr_max)
    scheduler: torch.optim.lr_scheduler.LRScheduler | None
    if schedule == "one-cycle":
        scheduler = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=lr_max, total_steps=steps)
    elif schedule == "cosine":
        scheduler = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=steps)
    else:
        scheduler = None

    records = [MemberRecord(member=m, seed=seeds[m], steps=0) for m in range(members)]
    losses = torch.zeros(steps, members, dtype=torch.float64, device=device)
    best = [p.detach().clone() for p in params]
    frozen = torch.zeros(members, dtype=torch.bool, device=device)
    frozen_host = [False] * members
    frozen_state: list[Tensor] | None = None
    waited = [0] * members
    logged = 0
    train_s = val_s = 0.0
    aug_start, start = watch.seconds, time.perf_counter()
    bar = tqdm(range(steps), desc=description, disable=None if progress is None else not progress,
               leave=False, dynamic_ncols=True)
    plain = progress is None and bool(bar.disable)  # not a terminal: plain progress lines
    model.train()
    step = 0
    for step in bar:
        tick = time.perf_counter()
        inputs, targets = [], []
        for m in range(members):
            indices = batches[m][step]
            if id(train_sets[m]) in pooled_sets and (augment is None or augment[m] is None):
                pooled, force = pooled_sets[id(train_sets[m])]
                rows = indices.to(device)
                inputs.append(pooled.index_select(0, rows))
                targets.append(force.index_select(0, rows))
                continue
            frames, force, metas = _stack_member_batch(train_sets[m], indices, collate)
            frames = frames.to(device, non_blocking=True)
            member_augment = None if augment is None else augment[m]
            if member_augment is not None:
                frames = member_augment(frames, metas)
            inputs.append(model.pool(frames))  # pooled per member: M small tensors stacked
            targets.append(force.to(device, non_blocking=True))
        frames, force = torch.stack(inputs), torch.stack(targets)
        pred = model(frames, pooled=True)
        per_member = (pred - force.to(pred.dtype)).square().mean(dim=(1, 2))
        optimiser.zero_grad(set_to_none=True)
        per_member.sum().backward()
        if clip is not None:
            clip_grad_norm_per_member_(params, clip)
        optimiser.step()
        if frozen_state is not None:
            with torch.no_grad():
                for p, saved in zip(params, frozen_state):
                    p.copy_(torch.where(frozen.view(-1, *([1] * (p.dim() - 1))), saved, p))
        if scheduler is not None:
            scheduler.step()
        losses[step] = per_member.detach().double()
        train_s += time.perf_counter() - tick
        if (step + 1) % eval_every and step + 1 != steps:
            continue
        tick = time.perf_counter()
        val = _validation_mse(model, val_frames, val_force, val_batch_size).tolist()
        history = losses[logged : step + 1].tolist()
        logged = step + 1
        newly_frozen = []
        for m, record in enumerate(records):
            if frozen_host[m]:
                continue
            record.train_loss.extend(row[m] for row in history)
            record.steps = step + 1
            record.val_steps.append(step + 1)
            record.val_loss.append(val[m])
            if val[m] < record.best_val_loss:
                record.best_val_loss, record.best_step, waited[m] = val[m], step + 1, 0
                with torch.no_grad():
                    for p, saved in zip(params, best):
                        saved[m].copy_(p[m])
            else:
                waited[m] += 1
                if patience is not None and waited[m] >= patience and step + 1 != steps:
                    newly_frozen.append(m)
        if newly_frozen:
            with torch.no_grad():
                if frozen_state is None:
                    frozen_state = [p.detach().clone() for p in params]
                for m in newly_frozen:
                    frozen_host[m] = True
                    records[m].stopped_step = step + 1
                    for p, saved in zip(params, frozen_state):
                        saved[m].copy_(p[m])
                frozen[newly_frozen] = True
        val_s += time.perf_counter() - tick
        active = [val[m] for m in range(members) if not frozen_host[m]]
        train_now = sum(history[-1]) / max(len(history[-1]), 1) if history else math.nan
        bar.set_postfix(loss=f"{train_now:.3g}", val=f"{min(val):.3g}-{max(val):.3g}", active=len(active))
        if on_validation is not None:
            on_validation({"step": step + 1, "steps": steps, "train_loss": train_now, "val_mse": val,
                           "elapsed_s": time.perf_counter() - start})
        if plain:
            elapsed = time.perf_counter() - start
            eta = elapsed / (step + 1) * (steps - step - 1)
            print(f"{description}: step {step + 1}/{steps}, train loss {train_now:.3g}, "
                  f"val MSE {min(val):.3g}-{max(val):.3g}, {elapsed:.0f} s elapsed, ETA {eta:.0f} s",
                  file=sys.stderr, flush=True)
        if all(frozen_host):
            break
    bar.close()

    with torch.no_grad():
        for m, record in enumerate(records):
            if select == "best":
                for p, saved in zip(params, best):
                    p[m].copy_(saved[m])
                record.selected_val_loss = record.best_val_loss
            else:
                record.selected_val_loss = record.val_loss[-1]
    return EnsembleResult(
        members=records,
        steps=step + 1,
        select=select,
        schedule=schedule,
        train_s=train_s,
        val_s=val_s,
        augmentation_s=watch.seconds - aug_start,
        total_s=time.perf_counter() - start,
    )


# ----------------------------------------------------------------------------- shared with the protocol


def collate(items: Sequence[tuple]) -> tuple[Tensor, Tensor, list]:
    """Stack ``(frames, force, meta)`` items into ``(B, T, 2, H, W)``, ``(B, T)``, metas."""
    frames = torch.stack([torch.as_tensor(item[0]) for item in items])
    force = torch.stack([torch.as_tensor(item[1]) for item in items]).float()
    metas = [item[2] if len(item) > 2 else {} for item in items]
    return frames, force, metas


def mse(pred: Tensor, target: Tensor) -> float:
    """Mean squared error over every frame of every sequence, in float64."""
    return float((pred.double() - target.double()).square().mean())


#: Frames of the grasp and of the release phase that :func:`phase_mse` scores apart.
PHASE_EDGE = 5


def phase_mse(pred: Tensor, target: Tensor, *, edge: int = PHASE_EDGE) -> dict[str, float]:
    """MSE per grasp phase: ``grasp`` (first ``edge`` frames), ``hold``, ``release`` (last).

    Args:
        pred: predicted force ``(N, T)``.
        target: measured force ``(N, T)``.
        edge: frames in the grasp and release phases; needs ``T > 2 * edge``.

    Example:
        >>> target = torch.zeros(1, 12)
        >>> pred = torch.tensor([[1.0] * 5 + [0.0] * 2 + [2.0] * 5])
        >>> phase_mse(pred, target)
        {'grasp': 1.0, 'hold': 0.0, 'release': 4.0, 'all': 2.0833333333333335}
    """
    steps = pred.shape[-1]
    if steps <= 2 * edge:
        raise ValueError(f"phase_mse needs more than 2 * edge = {2 * edge} frames, got {steps} (windows of at least "
                         f"{2 * edge + 1} frames: frames= in Python, --frames on the command line)")
    err = (pred.double() - target.double()).square()
    return {
        "grasp": float(err[..., :edge].mean()),
        "hold": float(err[..., edge:-edge].mean()),
        "release": float(err[..., -edge:].mean()),
        "all": float(err.mean()),
    }
