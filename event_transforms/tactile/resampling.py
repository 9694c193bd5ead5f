"""Intervals over data too: each seed of a protocol run reads its own bootstrap resample.

With the data fixed, the seeds of a run differ only in training randomness (initial weights,
batch order, augmentation draws), so an interval over seeds says nothing about another set of
grasps. On the simulated scenes a protocol run draws fresh data per seed instead
(``ProtocolConfig.resample = "fresh"``, the default: new grasps, so the intervals cover new data
sets); where no new data can be drawn (a folder of recordings), ``resample = "bootstrap"``: seed ``s`` draws
its own data: a bootstrap resample (``n`` items drawn with replacement) of the training
sequences it trains on and, separately, of the validation and test sequences it is scored on
(:func:`bootstrap_indices`, a function of the seed, the split and its size only). Every
method of a seed reads the same resample (the Δ stays paired) and so does every scene that
shares the split; the hold-out set of the stopping rule is not resampled. A folder of the
user's recordings is resampled by recording (its windows drawn together: :func:`item_groups`). The variation between seeds then
includes the variation between resamples of the one data set (the baselines are fitted and scored
on the same resamples, seed by seed), but the mean over seeds still centres on that data set's own
value: an interval covers resamples of these grasps, not new grasps. Measured on the simulator
(``benchmarks/tactile/resampling_coverage.md``), the spread of the 8-resample mean over independently
simulated data sets is 3.7× the nominal standard error.

Example:
    >>> bootstrap_indices(5, seed=0, split="train").tolist() == bootstrap_indices(5, 0, "train").tolist()
    True
    >>> idx = bootstrap_indices(1000, seed=3, split="test")
    >>> bool(idx.min() >= 0 and idx.max() < 1000), round(idx.unique().numel() / 1000, 1)
    (True, 0.6)
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import numpy as np
import torch
from torch import Tensor

from .._validation import check_seed

__all__ = ["RESAMPLING", "SPLIT_CODES", "bootstrap_indices", "check_resample", "item_groups", "resample_batches",
           "split_resample"]

#: The data rules a protocol run knows: ``"fresh"`` (each seed draws its own simulated data
#: set: :func:`~event_transforms.tactile.copies.load_scene_data` with ``data_seed``), ``"bootstrap"``
#: (each seed reads its own resample of one data set: a folder of recordings, where no new data can
#: be drawn) and ``"none"`` (every seed reads the same data).
RESAMPLING = ("fresh", "bootstrap", "none")
#: A distinct stream per split, so a seed's training and test resamples are independent.
SPLIT_CODES = {"train": 1, "val": 2, "test": 3}


def check_resample(resample: object) -> str:
    """``resample`` checked: one of :data:`RESAMPLING`.

    Raises:
        ValueError: anything else, named.

    Example:
        >>> check_resample("fresh")
        'fresh'
    """
    if resample not in RESAMPLING:
        raise ValueError(f"resample must be one of {RESAMPLING}, got {resample!r}")
    return str(resample)


def bootstrap_indices(n: int, seed: int, split: str, groups: Sequence[Hashable] | None = None) -> Tensor:
    """The ``n`` item indices (int64, drawn with replacement) of seed ``seed``'s bootstrap
    resample of a split of ``n`` items (``split`` in :data:`SPLIT_CODES`).

    Without ``groups`` each item is drawn on its own (a simulated grasp is independent of the
    others). With ``groups`` (one label per item, e.g. the recording a window was cut from)
    whole groups are drawn with replacement and their items taken in order until ``n`` are
    reached (the last group cut short): windows of one recording share its session, so they are
    resampled together.

    Raises:
        ValueError: ``n`` is not a positive int, ``split`` is unknown, ``groups`` does not
            hold ``n`` labels, or ``seed`` is invalid.

    Example:
        >>> bootstrap_indices(6, 0, "test", groups=["a", "a", "a", "b", "b", "c"]).tolist()  # b, b, c, c
        [3, 4, 3, 4, 5, 5]
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"n must be a positive int (the split's size), got {n!r}")
    if split not in SPLIT_CODES:
        raise ValueError(f"split must be one of {tuple(SPLIT_CODES)}, got {split!r}")
    seed = check_seed(seed, "seed")
    state = np.random.SeedSequence([seed, SPLIT_CODES[split], n]).generate_state(1, np.uint64)[0] >> np.uint64(1)
    generator = torch.Generator().manual_seed(int(state))
    if groups is None:
        return torch.randint(0, n, (n,), generator=generator)
    if len(groups) != n:
        raise ValueError(f"groups must hold one label per item ({n}), got {len(groups)}")
    members: dict[Hashable, list[int]] = {}
    for index, label in enumerate(groups):
        members.setdefault(label, []).append(index)
    clusters = list(members.values())
    picked: list[int] = []
    while len(picked) < n:
        picked.extend(clusters[int(torch.randint(0, len(clusters), (1,), generator=generator))])
    return torch.tensor(picked[:n], dtype=torch.int64)


def item_groups(dataset: object) -> list[Hashable] | None:
    """The recording each item of ``dataset`` comes from, where the data set says so (a
    ``meta(index)`` method whose dicts carry ``"recording"``, as a folder of recordings'
    :class:`~event_transforms.tactile.recordings.RecordingSet` does); ``None`` otherwise
    (simulated grasps: every item is its own grasp; the first item without one decides).

    Example:
        >>> class Folder(list):
        ...     def meta(self, index):
        ...         return {"recording": self[index]}
        >>> item_groups(Folder(["a.npy", "a.npy", "b.npy"])), item_groups([1, 2])
        (['a.npy', 'a.npy', 'b.npy'], None)
    """
    meta = getattr(dataset, "meta", None)
    if not callable(meta):
        return None
    labels: list[Hashable] = []
    try:
        for index in range(len(dataset)):  # type: ignore[arg-type]
            label = meta(index).get("recording")
            if label is None:  # simulated grasps say no recording: stop at the first item
                return None
            labels.append(label)
    except (TypeError, AttributeError):
        return None
    return labels


def split_resample(dataset: object, seed: int, split: str) -> Tensor:
    """:func:`bootstrap_indices` for ``dataset``'s items, grouped by recording where it has
    recordings (:func:`item_groups`).

    Example:
        >>> torch.equal(split_resample([10, 20, 30], 1, "val"), bootstrap_indices(3, 1, "val"))
        True
    """
    return bootstrap_indices(len(dataset), seed, split, item_groups(dataset))  # type: ignore[arg-type]


def resample_batches(batches: Tensor, items: int, indices: Tensor) -> Tensor:
    """``batches`` (indices into ``items`` originals followed by their copies, copy ``c`` of
    item ``i`` at ``c * items + i``) read through a resample: original ``i`` becomes
    ``indices[i]`` and its copies follow it.

    Example:
        >>> resample_batches(torch.tensor([[0, 5], [3, 2]]), 4, torch.tensor([2, 2, 0, 1])).tolist()
        [[2, 6], [1, 0]]
    """
    if indices.shape != (items,):
        raise ValueError(f"indices must hold one index per item ({items}), got shape {tuple(indices.shape)}")
    return torch.div(batches, items, rounding_mode="floor") * items + indices[batches % items]
