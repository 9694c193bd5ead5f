"""Training loop of the paper's protocol: Adam, MSE, early stopping, seeds, timing, resume.

:func:`fit` trains a force regressor with Adam on the mean squared error, evaluates the
validation MSE after every epoch, stops after ``patience`` epochs without improvement and
restores the best weights. One ``seed`` fixes the shuffling and torch's global RNG (which
on-the-fly augmentation draws from when it is given no generator); seed model
initialisation by calling :func:`seed_everything` before building the model.

Time is recorded per epoch: the wall time of the epoch's training pass, of its validation
pass, and the part of the training pass spent inside the augmentation (a
:class:`TimedTransform` around the transform reports to a :class:`Stopwatch`). Data are
loaded in the main process (``num_workers=0``), so the stopwatch sees every call.

:func:`run_seeds` runs one function per seed and writes each finished seed's result to its
own JSON file atomically (temporary file + :func:`os.replace`); a rerun after an
interruption reads the finished seeds back and runs only the others.
"""

from __future__ import annotations

import copy
import json
import math
import os
import random
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn
from torch.utils.data import DataLoader, Dataset

from ..transforms.base import EventTransform, as_transform

__all__ = [
    "Stopwatch",
    "TimedTransform",
    "EpochRecord",
    "TrainResult",
    "seed_everything",
    "rank_seed",
    "collate",
    "fit",
    "predict",
    "mse",
    "phase_mse",
    "write_json_atomic",
    "run_seeds",
]


class Stopwatch:
    """Accumulates seconds spent in timed sections (``with stopwatch: ...``).

    Example:
        >>> watch = Stopwatch()
        >>> with watch:
        ...     _ = sum(range(10))
        >>> watch.calls, watch.seconds >= 0
        (1, True)
    """

    def __init__(self) -> None:
        self.seconds = 0.0
        self.calls = 0
        self._start: float | None = None

    def __enter__(self) -> Stopwatch:
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._start is None:
            raise RuntimeError("Stopwatch exited without being entered")
        self.seconds += time.perf_counter() - self._start
        self.calls += 1
        self._start = None

    def __repr__(self) -> str:
        return f"Stopwatch(seconds={self.seconds:.6f}, calls={self.calls})"


class TimedTransform(EventTransform):
    """Wrap a transform so the time spent inside it is added to ``stopwatch``.

    A measuring device, not a transform: it draws and applies exactly what the wrapped
    transform does (its parameter tree is the wrapped one's), timing both steps. The
    stopwatch counts only calls made in this process (use ``num_workers=0``, as
    :func:`fit` does).

    Args:
        transform: an event transform, or a callable ``frames -> frames``.
        stopwatch: where the seconds go; a new one if ``None``.

    Example:
        >>> import event_transforms as et
        >>> timed = TimedTransform(et.FrameShift(-1))
        >>> out = timed(torch.ones(3, 2, 4, 5))
        >>> timed.stopwatch.calls, out[:, 0, 0, 0].tolist()
        (2, [1.0, 1.0, 0.0])
    """

    def __init__(self, transform: nn.Module, stopwatch: Stopwatch | None = None) -> None:
        super().__init__()
        self.transform = as_transform(transform)
        self.stopwatch = Stopwatch() if stopwatch is None else stopwatch

    def sample_params(self, shape, *, generator=None, metadata=None):
        with self.stopwatch:
            return self.transform.make_params(shape, generator=generator, metadata=metadata)

    def output_shape(self, shape):
        return self.transform.output_shape(shape)

    def apply(self, frames: Tensor, params) -> Tensor:
        with self.stopwatch:
            return self.transform._run(frames, params)


@dataclass
class EpochRecord:
    """What one epoch cost and achieved (times in seconds, losses in N²)."""

    epoch: int
    train_loss: float
    val_loss: float
    train_s: float
    val_s: float
    augmentation_s: float


@dataclass
class TrainResult:
    """Outcome of :func:`fit`; the model holds the best weights afterwards."""

    best_val_loss: float
    best_epoch: int
    epochs_run: int
    stopped_early: bool
    total_s: float
    history: list[EpochRecord] = field(default_factory=list)

    @property
    def train_s_per_epoch(self) -> float:
        """Mean wall time of an epoch's training pass."""
        return sum(r.train_s for r in self.history) / max(len(self.history), 1)

    @property
    def augmentation_s_per_epoch(self) -> float:
        """Mean time per epoch spent inside the augmentation."""
        return sum(r.augmentation_s for r in self.history) / max(len(self.history), 1)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        out = asdict(self)
        out["train_s_per_epoch"] = self.train_s_per_epoch
        out["augmentation_s_per_epoch"] = self.augmentation_s_per_epoch
        return out


def seed_everything(seed: int) -> None:
    """Seed torch (CPU and CUDA), Python's ``random`` and NumPy with ``seed``."""
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise TypeError(f"seed must be an int, got {seed!r}")
    torch.manual_seed(seed)
    random.seed(seed)
    try:
        import numpy as np
    except ImportError:  # pragma: no cover - numpy is a dependency
        return
    np.random.seed(seed % 2**32)


def collate(items: Sequence[tuple]) -> tuple[Tensor, Tensor, list]:
    """Stack ``(frames, force, meta)`` items into ``(B, T, 2, H, W)``, ``(B, T)``, metas."""
    frames = torch.stack([torch.as_tensor(item[0]) for item in items])
    force = torch.stack([torch.as_tensor(item[1]) for item in items]).float()
    metas = [item[2] if len(item) > 2 else {} for item in items]
    return frames, force, metas


def _loader(data: Dataset, batch_size: int, shuffle: bool, seed: int, sampler: Any = None) -> DataLoader:
    if sampler is not None:
        return DataLoader(data, batch_size=batch_size, sampler=sampler, num_workers=0, collate_fn=collate)
    generator = torch.Generator().manual_seed(seed) if shuffle else None
    return DataLoader(
        data, batch_size=batch_size, shuffle=shuffle, generator=generator,
        num_workers=0, collate_fn=collate,
    )


def rank_seed(seed: int, rank: int) -> int:
    """The augmentation seed of ``rank`` in a run seeded ``seed``: distinct per rank, fixed per run.

    Example:
        >>> rank_seed(0, 0) != rank_seed(0, 1), rank_seed(3, 1) == rank_seed(3, 1)
        (True, True)
    """
    import numpy as np

    return int(np.random.SeedSequence([int(seed), int(rank)]).generate_state(1, np.uint64)[0] >> np.uint64(1))


def _distributed() -> tuple[int, int]:
    """(rank, world size) of the initialised process group, or (0, 1)."""
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def _model_device(model: nn.Module) -> torch.device:
    for p in model.parameters():
        return p.device
    return torch.device("cpu")


@torch.no_grad()
def predict(
    model: nn.Module, data: Dataset, *, batch_size: int = 16
) -> tuple[Tensor, Tensor, list]:
    """Predicted and measured force ``(N, T)`` (float64, CPU) for every item, and metas."""
    was_training = model.training
    model.eval()
    device = _model_device(model)
    preds, targets, metas = [], [], []
    try:
        for frames, force, meta in _loader(data, batch_size, False, 0):
            preds.append(model(frames.to(device)).double().cpu())
            targets.append(force.double())
            metas.extend(meta)
    finally:
        model.train(was_training)
    if not preds:
        raise ValueError("data must hold at least one item, got an empty dataset")
    return torch.cat(preds), torch.cat(targets), metas


def mse(pred: Tensor, target: Tensor) -> float:
    """Mean squared error over every frame of every sequence, in float64."""
    return float((pred.double() - target.double()).square().mean())


def phase_mse(pred: Tensor, target: Tensor, *, edge: int = 5) -> dict[str, float]:
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
        raise ValueError(f"phase_mse needs more than 2 * edge = {2 * edge} frames, got {steps}")
    err = (pred.double() - target.double()).square()
    return {
        "grasp": float(err[..., :edge].mean()),
        "hold": float(err[..., edge:-edge].mean()),
        "release": float(err[..., -edge:].mean()),
        "all": float(err.mean()),
    }


def fit(
    model: nn.Module,
    train_data: Dataset,
    val_data: Dataset,
    *,
    epochs: int = 500,
    patience: int = 20,
    lr: float = 1e-3,
    batch_size: int = 8,
    seed: int = 0,
    stopwatch: Stopwatch | None = None,
    progress: bool | None = None,
    description: str = "train",
    distributed: bool | None = None,
) -> TrainResult:
    """Train ``model`` with Adam on the MSE, early stopping on the validation MSE.

    After every epoch the validation MSE (over all frames of ``val_data``) is computed;
    training stops when it has not improved for ``patience`` epochs or after ``epochs``
    epochs, and the weights of the best epoch are loaded back into ``model``.

    Args:
        model: maps ``(B, T, 2, H, W)`` frames to ``(B, T)`` force.
        train_data: items ``(frames, force, meta)``; shuffled every epoch.
        val_data: items ``(frames, force, meta)`` for early stopping.
        epochs: maximum number of epochs.
        patience: epochs without improvement before stopping.
        lr: Adam learning rate.
        batch_size: sequences per step.
        seed: fixes shuffling and torch's global RNG (on-the-fly augmentation).
        stopwatch: the stopwatch of a :class:`TimedTransform` inside ``train_data``;
            its seconds per epoch are recorded as ``augmentation_s``.
        progress: show a tqdm bar; ``None`` shows it only when stderr is a terminal.
        description: label of the progress bar.
        distributed: data-parallel training over the initialised :mod:`torch.distributed`
            group (gloo on the CPU, nccl on GPUs), e.g. under ``torchrun``; ``None`` uses it
            when a group of more than one rank is initialised. The model is wrapped in
            ``DistributedDataParallel`` (rank 0's initial weights are broadcast), each rank
            reads its share of every epoch through a ``DistributedSampler`` seeded with
            ``seed``, and each rank's on-the-fly augmentation draws from torch's global RNG
            seeded with :func:`rank_seed` ``(seed, rank)``: ranks draw differently and a run
            is reproducible. Every rank validates on the whole validation set, so all ranks
            stop at the same epoch and keep the same weights.

    Example:
        >>> from torch.utils.data import TensorDataset
        >>> from event_transforms.tactile.models import ForceRegressor
        >>> seed_everything(0)
        >>> x = torch.poisson(torch.full((4, 6, 2, 12, 12), 0.5))
        >>> data = TensorDataset(x, x.sum((2, 3, 4)) / 100)
        >>> model = ForceRegressor(hidden_channels=(2,), input_pool=2)
        >>> result = fit(model, data, data, epochs=3, patience=2, progress=False)
        >>> result.epochs_run, len(result.history)
        (3, 3)
    """
    for name, value, low in (("epochs", epochs, 1), ("patience", patience, 1), ("batch_size", batch_size, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name} must be an int >= {low}, got {value!r}")
    if not (isinstance(lr, (int, float)) and lr > 0 and math.isfinite(lr)):
        raise ValueError(f"lr must be a positive number, got {lr!r}")
    from tqdm.auto import tqdm

    rank, world = _distributed()
    if distributed is None:
        distributed = world > 1
    elif distributed and world == 1:
        raise ValueError("distributed=True needs an initialised torch.distributed group of more than one rank")
    torch.manual_seed(rank_seed(seed, rank) if distributed else seed)
    device = _model_device(model)
    network: nn.Module = model
    sampler = None
    if distributed:
        from torch.nn.parallel import DistributedDataParallel
        from torch.utils.data.distributed import DistributedSampler

        network = DistributedDataParallel(model, device_ids=None if device.type == "cpu" else [device])
        sampler = DistributedSampler(train_data, num_replicas=world, rank=rank, shuffle=True, seed=seed)
    optimiser = torch.optim.Adam(model.parameters(), lr=lr)
    loader = _loader(train_data, batch_size, True, seed, sampler)
    watch = stopwatch if stopwatch is not None else Stopwatch()
    best_loss, best_epoch, best_state = math.inf, -1, None
    history: list[EpochRecord] = []
    waited = 0
    start = time.perf_counter()
    bar = tqdm(range(epochs), desc=description, disable=None if progress is None else not progress,
               leave=False, dynamic_ncols=True)
    for epoch in bar:
        model.train()
        if sampler is not None:
            sampler.set_epoch(epoch)
        aug_before, tick = watch.seconds, time.perf_counter()
        total, count = 0.0, 0
        for frames, force, _ in loader:
            frames, force = frames.to(device), force.to(device)
            pred = network(frames)
            loss = F.mse_loss(pred, force.to(pred.dtype))
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            optimiser.step()
            total += float(loss.detach()) * force.numel()
            count += force.numel()
        if distributed:
            import torch.distributed as dist

            sums = torch.tensor([total, float(count)], dtype=torch.float64, device=device)
            dist.all_reduce(sums)
            total, count = float(sums[0]), int(sums[1])
        train_s = time.perf_counter() - tick
        augmentation_s = watch.seconds - aug_before
        tick = time.perf_counter()
        val_loss = mse(*predict(model, val_data, batch_size=max(batch_size, 16))[:2])
        val_s = time.perf_counter() - tick
        history.append(EpochRecord(epoch, total / max(count, 1), val_loss, train_s, val_s, augmentation_s))
        if val_loss < best_loss:
            best_loss, best_epoch, waited = val_loss, epoch, 0
            best_state = copy.deepcopy(model.state_dict())
        else:
            waited += 1
        bar.set_postfix(val=f"{val_loss:.3g}", best=f"{best_loss:.3g}")
        if waited >= patience:
            break
    bar.close()
    if best_state is not None:
        model.load_state_dict(best_state)
    return TrainResult(
        best_val_loss=best_loss,
        best_epoch=best_epoch,
        epochs_run=len(history),
        stopped_early=waited >= patience,
        total_s=time.perf_counter() - start,
        history=history,
    )


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as JSON to ``path`` so readers see the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as handle:
            json.dump(obj, handle, indent=2)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def run_seeds(
    run_one: Callable[[int], dict[str, Any]],
    seeds: Iterable[int],
    directory: str | os.PathLike,
    *,
    on_done: Callable[[int, dict[str, Any], bool], None] | None = None,
) -> list[dict[str, Any]]:
    """Run ``run_one(seed)`` for each seed, resumably; return the results in seed order.

    Each finished seed's result goes to ``directory/seed-<seed>.json`` atomically. A seed
    whose file exists is read back instead of run, so a rerun after an interruption (Ctrl-C,
    a killed job) finishes only the missing seeds and loses nothing.

    Args:
        run_one: trains one seed and returns a JSON-ready dict.
        seeds: the seeds, in order.
        directory: where the per-seed files live.
        on_done: called as ``on_done(seed, result, resumed)`` after each seed.

    Example:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     first = run_seeds(lambda s: {"seed": s, "mse": s / 10}, [0, 1], d)
        ...     again = run_seeds(lambda s: 1 / 0, [0, 1], d)  # nothing runs twice
        >>> again == first
        True
    """
    directory = Path(directory)
    results = []
    for seed in seeds:
        path = directory / f"seed-{seed}.json"
        resumed = path.exists()
        if resumed:
            with path.open() as handle:
                result = json.load(handle)
        else:
            result = run_one(seed)
            write_json_atomic(path, result)
        results.append(result)
        if on_done is not None:
            on_done(seed, result, resumed)
    return results
