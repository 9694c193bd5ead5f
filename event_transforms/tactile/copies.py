"""A scene's data and the synthetic copies of its training items, in a paired order.

:class:`SceneData` holds a scene's splits: ``train`` (48) and ``holdout`` (24) from the training
session, ``val`` (24) and ``test`` (96) from the deployment session, and the deployment
camera's noise bank. A method's training set is the training items followed by its copies
(:func:`build_training_set`: made once, the paper's offline doubling, or
:class:`OnlineCopies` + :class:`DeviceAugment`: drawn batch by batch on the device), and
:func:`paired_batches` orders every method's batches so that, for a seed, every method sees the
same original item at the same step and slot (a copy takes an original's place at
deterministic visits), so per-seed differences between methods share their noise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torch.utils.data import Dataset

from .._validation import check_positive
from ..data import AugmentedDataset, SizedDataset
from .methods import Method
from .benchmark_scenes import BenchmarkScene, get_scene
from .stopwatch import Stopwatch, TimedTransform

__all__ = [
    "SceneData",
    "load_scene_data",
    "data_seed_offset",
    "MaterializedDataset",
    "WithLabels",
    "OnlineCopies",
    "DeviceAugment",
    "build_training_set",
    "paired_batches",
]


@dataclass
class SceneData:
    """Training, validation and test sets of one scene, and the deployment camera's noise bank.

    ``holdout`` holds sequences of the *training* session that are not training items: the
    stopping rule's data (never deployment data). Without one, the final weights are kept.
    ``dataset`` describes a folder of recordings (folder, files, content hash, settings, counts;
    :func:`~event_transforms.tactile.recordings.load_recording_data`); ``None`` for the built-in
    scenes. ``labelled``: the labelled deployment recordings ``inferred`` reads (``with-labels``
    adds them to training); ``None``: ``val``. With fresh data per seed they are the base data
    set's validation grasps, as ``inferred`` is inferred once from the base data set.
    """

    scene: BenchmarkScene
    train: SizedDataset
    val: SizedDataset
    test: SizedDataset
    noise_bank: torch.Tensor | None = None
    seconds: float = 0.0
    holdout: SizedDataset | None = None
    dataset: dict[str, Any] | None = None
    labelled: SizedDataset | None = None


#: The sequence seeds of protocol seed ``s``'s own data set start at ``(s + 1)`` times this:
#: above every split of the base data set (sequence seeds below 50,000) and of every other
#: protocol seed, so no two data sets share a grasp.
DATA_SEED_STRIDE = 100_000


def data_seed_offset(seed: int | None) -> int:
    """The sequence-seed offset (:class:`~event_transforms.tactile.datasets.TactileGrasps`'s
    ``seed``) of protocol seed ``seed``'s fresh data set; ``None``: the base data set (0).

    Example:
        >>> data_seed_offset(None), data_seed_offset(0), data_seed_offset(7)
        (0, 100000, 800000)
    """
    if seed is None:
        return 0
    from .._validation import check_seed

    return (check_seed(seed, "seed") + 1) * DATA_SEED_STRIDE


def load_scene_data(
    scene: str | BenchmarkScene, root: str | None = None, *, paper_split: bool = False, noise_frames: int = 360,
    data_seed: int | None = None,
) -> SceneData:
    """The simulated grasps of ``scene`` (generated into the cache on first use).

    The noise bank is ``noise_frames`` frames of a simulated static scene seen by the
    deployment camera. ``data_seed``: protocol seed ``s`` draws its own data set, new grasps
    (training, hold-out, validation and test) and a new noise bank from the same sessions
    (sequence seeds offset by :func:`data_seed_offset`); ``None``: the base data set. Scenes
    whose training sessions agree still share their training data within a seed.
    """
    from . import datasets

    scene = get_scene(scene)
    offset = data_seed_offset(data_seed)
    start = time.perf_counter()
    splits = {
        split: datasets.TactileGrasps(split, root=root, scene=scene, paper_split=paper_split, seed=offset)
        for split in ("train", "holdout", "val", "test")
    }
    # a fresh bank sits at +60,000 in the seed's block, where no split's grasp seeds are
    bank = datasets.noise_bank(noise_frames, seed=offset + 60_000 if offset else 0, config=scene.deploy.config)
    # what inferred reads (the base data set's validation grasps, whatever the seed): with-labels' extra items
    labelled = (splits["val"] if not offset and not paper_split
                else datasets.TactileGrasps("val", root=root, scene=scene))
    return SceneData(scene, splits["train"], splits["val"], splits["test"], bank, time.perf_counter() - start,
                     holdout=splits["holdout"], labelled=labelled)


class WithLabels(Dataset):
    """The training items followed by the deployment's labelled validation items: the training
    set of ``with-labels`` (the comparator of ``inferred``, which reads those labels). ``meta``
    forwards each item's metadata, so a folder's items are still resampled by recording.

    Example:
        >>> both = WithLabels([(1, 2, {"a": 0})], [(3, 4, {"a": 1}), (5, 6, {"a": 2})])
        >>> len(both), both[2], both.meta(1)
        (3, (5, 6, {'a': 2}), {'a': 1})
    """

    def __init__(self, train: SizedDataset, labelled: SizedDataset) -> None:
        self.parts = (train, labelled)

    def __len__(self) -> int:
        return len(self.parts[0]) + len(self.parts[1])

    def _locate(self, index: int) -> tuple[SizedDataset, int]:
        index = int(index)
        if not 0 <= index < len(self):
            raise IndexError(f"index must be in [0, {len(self)}), got {index}")
        first = len(self.parts[0])
        return (self.parts[0], index) if index < first else (self.parts[1], index - first)

    def __getitem__(self, index: int) -> tuple[Any, ...]:
        part, at = self._locate(index)
        return part[at]

    def meta(self, index: int) -> dict[str, Any]:
        """The item's metadata: its split's ``meta``, else the item's own dict."""
        part, at = self._locate(index)
        meta = getattr(part, "meta", None)
        if callable(meta):
            return dict(meta(at))
        item = part[at]
        return dict(item[2]) if len(item) > 2 and isinstance(item[2], dict) else {}


class MaterializedDataset(Dataset):
    """Every item of ``data`` computed once and kept in memory: the paper's offline copies.

    Integer-valued frames are stored as int16 when they fit (a quarter of float32's
    memory) and returned as float32, so an item reads back exactly as it was computed.
    """

    def __init__(self, data: SizedDataset) -> None:
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
) -> SizedDataset:
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

    def __init__(self, base: SizedDataset, copies: int) -> None:
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
    :func:`~event_transforms.tactile.training.fit_ensemble`: the rows whose metadata say
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


def paired_batches(items: int, copies: int, batch_size: int, steps: int, *, seed: int) -> Tensor:
    """Indices ``(steps, batch_size)`` into ``items`` originals followed by ``copies`` copies of each.

    The originals' order is :func:`~event_transforms.tactile.training.shuffled_batches` of
    ``items`` with ``seed``, the same for every method of that seed. Each slot then holds the
    original or one of its copies: visit ``v`` of item ``i`` takes variant
    ``(v + r_i) mod (1 + copies)`` (variant 0 is the original, ``c`` the copy at index
    ``c * items + i``), with offsets ``r_i`` drawn from ``(seed, copies)``. So every variant is
    read equally often, as a shuffle of the whole set would, and for a seed every method sees
    the same original item at the same step and slot: the methods differ only in what the
    augmentation did to it.

    Example:
        >>> none = paired_batches(4, 0, 2, 6, seed=0)
        >>> doubled = paired_batches(4, 1, 2, 6, seed=0)
        >>> torch.equal(doubled % 4, none), sorted(set((doubled // 4).flatten().tolist()))
        (True, [0, 1])
    """

    if isinstance(copies, bool) or not isinstance(copies, int) or copies < 0:
        raise ValueError(f"copies must be a non-negative int, got {copies!r}")
    base = shuffled_batches(items, batch_size, steps, seed=seed)
    if copies == 0:
        return base
    state = np.random.SeedSequence([int(seed), int(copies)]).generate_state(1, np.uint64)[0] >> np.uint64(1)
    offsets = torch.randint(0, 1 + copies, (items,), generator=torch.Generator().manual_seed(int(state)))
    flat = base.flatten().tolist()
    visits = [0] * items
    variants = []
    for item in flat:
        variants.append((visits[item] + int(offsets[item])) % (1 + copies))
        visits[item] += 1
    return (torch.tensor(variants, dtype=torch.int64) * items + base.flatten()).view(steps, batch_size)


def shuffled_batches(length: int, batch_size: int, steps: int, *, seed: int) -> Tensor:
    """Indices ``(steps, batch_size)`` of ``steps`` batches drawn from ``length`` items.

    The items are visited in passes; each pass is a fresh ``torch.randperm`` from one
    ``torch.Generator`` seeded with ``seed``, and batches run on across the end of a pass
    (no item is dropped, no batch is short), so a data set with copies gives more distinct
    data to the same number of steps.

    Example:
        >>> batches = shuffled_batches(5, 2, 4, seed=0)
        >>> tuple(batches.shape), sorted(batches.flatten()[:5].tolist())
        ((4, 2), [0, 1, 2, 3, 4])
    """
    for name, value in (("length", length), ("batch_size", batch_size), ("steps", steps)):
        check_positive(value, name, integer=True)
    generator = torch.Generator().manual_seed(seed)
    needed = steps * batch_size
    passes = [torch.randperm(length, generator=generator) for _ in range(-(-needed // length))]
    return torch.cat(passes)[:needed].view(steps, batch_size)
