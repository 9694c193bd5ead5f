"""Synthetic copies of any data set: the paper's offline doubling, or fresh draws per access.

:class:`AugmentedDataset` adds ``copies`` transformed versions of every item of a data set of
``(frames, label, meta)`` items, labels unchanged (the paper keeps the ground truth).
"""

from __future__ import annotations

__all__ = ["AugmentedDataset"]

from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import Dataset

from ._validation import check_seed
from .transforms.base import EventTransform, as_transform


def _copy_seed(seed: int, index: int) -> int:
    """A 63-bit seed for synthetic item ``index``, mixed by ``SeedSequence``."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1, np.uint64)[0] >> np.uint64(1))


class SizedDataset(Protocol):
    """A map-style data set as this module reads it: ``len(data)`` items ``data[i]`` (a
    ``torch.utils.data.Dataset`` that defines ``__len__``, or a plain list of items)."""

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> Any: ...


class AugmentedDataset(Dataset):
    """A data set followed by ``copies`` synthetic versions of each of its items.

    Item ``i < len(base)`` is the original; item ``c · len(base) + j`` (``c ≥ 1``) is
    synthetic copy ``c`` of item ``j``: ``transform`` applied to its frames, its label and
    metadata unchanged (the paper keeps the ground truth). With ``fixed=True`` each copy
    is a deterministic function of ``(seed, i)`` — a ``torch.Generator`` seeded from both —
    so every epoch and every worker sees the same set, as the paper's offline doubling.
    With ``fixed=False`` copies are drawn afresh on every access from torch's global RNG
    (DataLoader workers are seeded differently, so they differ).

    The transform is called as ``transform(frames, generator=g, metadata=meta)`` with the
    item's metadata dict (so a scene policy can resize by target / source size); a plain
    callable is wrapped by :func:`~event_transforms.as_transform` and called as
    ``transform(frames)``. Fixed copies draw from a CPU generator, so the base items should
    be CPU tensors (move batches to the GPU later).

    Args:
        base: a data set of ``(frames, label, meta)`` or ``(frames, label)`` items.
        transform: an event transform, or a callable ``frames -> frames``.
        copies: synthetic copies per item (1 doubles the set).
        fixed: deterministic copies (True) or fresh ones per access (False).
        seed: seed of the fixed copies.

    Shape:
        Each item's frames ``(T, 2, H, W)``; a copy's frames have the shape the transform gives.

    Example:
        >>> def add_one(frames):
        ...     return frames + 1
        >>> base = [(torch.zeros(36, 2, 4, 4), torch.ones(36), {"index": 0})]
        >>> data = AugmentedDataset(base, add_one, copies=2)
        >>> len(data), [float(data[i][0].max()) for i in range(3)]
        (3, [0.0, 1.0, 1.0])
    """

    def __init__(
        self,
        base: SizedDataset,
        transform: EventTransform | Callable[[Tensor], Tensor],
        copies: int = 1,
        *,
        fixed: bool = True,
        seed: int = 0,
    ) -> None:
        if isinstance(copies, bool) or not isinstance(copies, (int, np.integer)) or copies < 0:
            raise ValueError(f"copies must be a non-negative integer, got {copies!r}")
        if not (hasattr(base, "__len__") and hasattr(base, "__getitem__")) or isinstance(base, (str, bytes)):
            raise TypeError(
                f"base must be a map-style data set (with __len__ and __getitem__), got {type(base).__name__} {base!r}"[:200]
            )
        self.base = base
        self.transform = as_transform(transform)
        self.copies = int(copies)
        self.fixed = bool(fixed)
        self.seed = check_seed(seed)

    def __len__(self) -> int:
        return len(self.base) * (1 + self.copies)

    def __getitem__(self, index: int) -> tuple[Any, ...]:
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise TypeError(f"index must be an integer, got {type(index).__name__}")
        if not -len(self) <= index < len(self):
            raise IndexError(f"index {index} is out of range for {len(self)} items")
        index = int(index) % len(self)
        item = self.base[index % len(self.base)]
        if index < len(self.base):
            return item
        frames, rest = item[0], tuple(item[1:])
        meta = rest[1] if len(rest) > 1 and isinstance(rest[1], Mapping) else {}
        generator = torch.Generator().manual_seed(_copy_seed(self.seed, index)) if self.fixed else None
        with torch.no_grad():
            frames = self.transform(frames, generator=generator, metadata=meta)
        return (frames, *rest)

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(n={len(self)}, copies={self.copies}, fixed={self.fixed}, "
            f"seed={self.seed}, transform={self.transform!r})"
        )
