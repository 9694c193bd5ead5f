"""Data sets: the synthetic tactile grasps of the paper's protocol, and augmented copies.

:class:`TactileGrasps` follows the paper's split: 48 training sequences (24 with the
12 mm bolt, 24 with the 18 mm bolt), 6 validation and 6 test sequences with the unseen
15 mm bolt, each sequence 36 frames of 10 ms cropped to 140×150 around the contact and
pooled 2×2 to 70×75. The data come from :mod:`event_transforms.tactile.simulation` (the paper's
recordings are not public), are generated once into a cache directory and reused.
Results on them are results on synthetic data.

:class:`AugmentedDataset` adds synthetic copies to any data set of ``(frames, label,
meta)`` items, the paper's offline doubling of the training set.
"""

from __future__ import annotations

__all__ = [
    "TactileGrasps",
    "noise_bank",
    "default_cache_dir",
    "SPLITS",
]

import dataclasses
import hashlib
import json
import os
import tempfile
from collections.abc import Callable, Mapping
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import Dataset

from ..transforms.base import as_transform
from ..functional.events import events_to_frames
from .simulation import (
    SIMULATOR_VERSION,
    Recording,
    SimulatorConfig,
    draw_grasp,
    simulate_grasps,
    simulate_static,
)

#: Layout of the data set: split -> list of (diameter_mm, number of sequences).
#: Each block alternates the two gripper settings, so every block holds both equally.
SPLITS: dict[str, list[tuple[float, int]]] = {
    "train": [(12.0, 24), (18.0, 24)],
    "val": [(15.0, 6)],
    "test": [(15.0, 6)],
}

_CACHE_FORMAT = 1
_NOISE_SEED_OFFSET = 1_000_000  # static-scene seeds never reuse a grasp's noise stream


def default_cache_dir() -> Path:
    """``$EVENT_TRANSFORMS_CACHE``, else ``$XDG_CACHE_HOME/event-transforms``, else
    ``~/.cache/event-transforms``."""
    if os.environ.get("EVENT_TRANSFORMS_CACHE"):
        return Path(os.environ["EVENT_TRANSFORMS_CACHE"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "event-transforms"
    return Path.home() / ".cache" / "event-transforms"


def _layout(seed: int) -> list[tuple[str, float, int, int]]:
    """(split, diameter, gripper, grasp seed) of every sequence, in storage order."""
    rows = []
    for split, blocks in SPLITS.items():
        for diameter, count in blocks:
            rows.extend((split, diameter, i % 2, 0) for i in range(count))
    return [(split, d, g, seed + i) for i, (split, d, g, _) in enumerate(rows)]


def _atomic_save(obj: object, path: Path) -> None:
    """``torch.save`` to a temporary file in the same folder, then ``os.replace``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as stream:
            torch.save(obj, stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        try:
            os.unlink(temporary)
        except FileNotFoundError:
            pass
        raise


def _cache_name(config: SimulatorConfig, seed: int, crop_size: tuple[int, int], pool: int) -> str:
    """File name keyed by a hash of everything that determines the data."""
    description = {
        "format": _CACHE_FORMAT,
        "simulator": SIMULATOR_VERSION,
        "config": dataclasses.asdict(config),
        "layout": _layout(seed),
        "crop_size": list(crop_size),
        "pool": pool,
    }
    text = json.dumps(description, sort_keys=True)
    return f"tactile-grasps-v{SIMULATOR_VERSION}-{hashlib.sha256(text.encode()).hexdigest()[:16]}.pt"


def _check_seed(seed: object) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


class TactileGrasps(Dataset):
    """Synthetic grasps of bolts on a DVS tactile sensor, split as in the paper.

    Items are ``frames, force, meta``: ``frames`` a float32 tensor ``(36, 2, 70, 75)`` of
    integer-valued event counts (channel 0 OFF, 1 ON), ``force`` float32 ``(36,)`` in
    newtons (the force/torque reading at each frame's centre), and ``meta`` a dict
    ``{"diameter_mm": float, "gripper": int, "seed": int, "index": int}`` of plain Python
    numbers, so ``torch.utils.data.default_collate`` batches it.

    The whole set (60 sequences) is simulated on first use, in a few seconds, and saved
    as one file in ``root`` named by a hash of the simulator settings, the data-set
    layout and the simulator version; the file is written to a temporary name and then
    renamed, so an interrupted run never leaves a corrupt cache. Later instances
    memory-map it.

    Args:
        split: ``"train"`` (12 and 18 mm bolts, 48 sequences), ``"val"`` or ``"test"``
            (15 mm bolt, 6 each).
        root: cache directory (default :func:`default_cache_dir`).
        config: simulator settings (default :class:`~event_transforms.tactile.simulation.SimulatorConfig`).
        seed: seed of the first sequence; sequence ``k`` of the whole set uses ``seed + k``.
        transform: optional event transform applied to the frames of each item, called
            with ``metadata=meta`` (a plain callable is called as ``transform(frames)``).
        crop_size: (height, width) of the window around the contact, in sensor pixels.
        pool: side of the sum-pooled blocks.

    Attributes:
        frames: the split's frames, float32 ``(N, 36, 2, 70, 75)`` (made on first access).
        forces: the split's forces, float32 ``(N, 36)``.
        path: the cache file.

    Example:
        >>> import tempfile
        >>> root = tempfile.mkdtemp()
        >>> train = TactileGrasps("train", root=root)
        >>> frames, force, meta = train[0]
        >>> len(train), tuple(frames.shape), tuple(force.shape), frames.dtype
        (48, (36, 2, 70, 75), (36,), torch.float32)
        >>> meta
        {'diameter_mm': 12.0, 'gripper': 0, 'seed': 0, 'index': 0}
        >>> len(TactileGrasps("test", root=root))  # reuses the cache
        6
    """

    def __init__(
        self,
        split: str = "train",
        root: str | os.PathLike[str] | None = None,
        *,
        config: SimulatorConfig | None = None,
        seed: int = 0,
        transform: Callable[..., Tensor] | None = None,
        crop_size: tuple[int, int] = (140, 150),
        pool: int = 2,
    ) -> None:
        if split not in SPLITS:
            raise ValueError(f"split must be one of {sorted(SPLITS)}, got {split!r}")
        if config is not None and not isinstance(config, SimulatorConfig):
            raise TypeError(f"config must be a SimulatorConfig, got {type(config).__name__}")
        self.split = split
        self.config = config or SimulatorConfig()
        self.seed = _check_seed(seed)
        self.crop_size = (int(crop_size[0]), int(crop_size[1]))
        self.pool = int(pool)
        self.transform = None if transform is None else as_transform(transform)
        self.root = Path(root) if root is not None else default_cache_dir()
        self.path = self.root / _cache_name(self.config, self.seed, self.crop_size, self.pool)
        if not self.path.exists():
            _atomic_save(self._generate(), self.path)
        data = torch.load(self.path, mmap=True, weights_only=True)
        rows = (data["split"] == list(SPLITS).index(split)).nonzero().squeeze(1)
        start, stop = int(rows[0]), int(rows[-1]) + 1  # a split is one contiguous block
        self._counts = data["frames"][start:stop]
        self.forces = data["force"][start:stop]
        self._diameter = data["diameter_mm"][start:stop].tolist()
        self._gripper = data["gripper"][start:stop].tolist()
        self._seeds = data["seed"][start:stop].tolist()

    # ------------------------------------------------------------------ cache
    def _generate(self) -> dict[str, Tensor]:
        layout = _layout(self.seed)
        grasps = [draw_grasp(d, gripper=g, seed=s, config=self.config) for _, d, g, s in layout]
        recordings = simulate_grasps(grasps, self.config)
        frames = torch.stack(
            [
                r.frames(crop=r.contact_crop(self.crop_size), pool=self.pool, dtype=torch.int64)
                for r in recordings
            ]
        )
        storage = torch.int16 if frames.numel() == 0 or int(frames.max()) <= 32767 else torch.int32
        return {
            "frames": frames.to(storage),
            "force": torch.from_numpy(np.stack([r.force for r in recordings])),
            "diameter_mm": torch.tensor([d for _, d, _, _ in layout], dtype=torch.float64),
            "gripper": torch.tensor([g for _, _, g, _ in layout]),
            "seed": torch.tensor([s for _, _, _, s in layout]),
            "split": torch.tensor([list(SPLITS).index(split) for split, _, _, _ in layout]),
        }

    # ------------------------------------------------------------------ access
    def __len__(self) -> int:
        return self._counts.shape[0]

    def meta(self, index: int) -> dict[str, Any]:
        """The metadata dict of item ``index``."""
        return {
            "diameter_mm": float(self._diameter[index]),
            "gripper": int(self._gripper[index]),
            "seed": int(self._seeds[index]),
            "index": int(index),
        }

    def __getitem__(self, index: int) -> tuple[Tensor, Tensor, dict[str, Any]]:
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise TypeError(f"index must be an integer, got {type(index).__name__}")
        if not -len(self) <= index < len(self):
            raise IndexError(f"index {index} is out of range for {len(self)} sequences")
        index = int(index) % len(self)
        frames = self._counts[index].to(torch.float32)
        meta = self.meta(index)
        if self.transform is not None:
            frames = self.transform(frames, metadata=meta)
        return frames, self.forces[index].clone(), meta

    @cached_property
    def frames(self) -> Tensor:
        """The split's frames as one float32 tensor ``(N, 36, 2, 70, 75)`` (no transform)."""
        return self._counts.to(torch.float32)

    def recording(self, index: int) -> Recording:
        """Re-simulate item ``index`` as a raw event stream (same seed, same events)."""
        meta = self.meta(index)
        grasp = draw_grasp(meta["diameter_mm"], gripper=meta["gripper"], seed=meta["seed"], config=self.config)
        return simulate_grasps([grasp], self.config)[0]

    def __repr__(self) -> str:
        return f"{type(self).__name__}(split={self.split!r}, n={len(self)}, path={str(self.path)!r})"


def noise_bank(
    n_frames: int = 360,
    *,
    seed: int = 0,
    config: SimulatorConfig | None = None,
    crop_size: tuple[int, int] = (140, 150),
    pool: int = 2,
) -> Tensor:
    """Frames of a simulated static scene, for :class:`~event_transforms.AddNoise`.

    The camera (threshold mismatch, noise rates, hot pixels) is the one of ``config``, as
    in :class:`TactileGrasps`; the crop is centred on the sensor. Seeds are offset so a
    bank never repeats the noise realisation of a grasp.

    Args:
        n_frames: number of frames N (the recording lasts ``N · frame_ms``).
        seed: seed of the noise realisation.
        config: simulator settings (default :class:`SimulatorConfig()`).
        crop_size: (height, width) window in sensor pixels.
        pool: side of the sum-pooled blocks.

    Returns:
        float32 tensor ``(N, 2, crop_h // pool, crop_w // pool)`` of event counts.

    Example:
        >>> bank = noise_bank(10, seed=0)
        >>> bank.shape, bool(bank.sum() > 0)
        (torch.Size([10, 2, 70, 75]), True)
    """
    config = config or SimulatorConfig()
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise ValueError(f"n_frames must be a positive integer, got {n_frames!r}")
    height, width = config.sensor_size
    crop_h, crop_w = crop_size
    top, left = (height - crop_h) // 2, (width - crop_w) // 2
    events = simulate_static(n_frames * config.frame_ms, seed=_check_seed(seed) + _NOISE_SEED_OFFSET, config=config)
    return events_to_frames(
        events,
        t_start=0,
        frame_ms=config.frame_ms,
        n_frames=int(n_frames),
        sensor_size=config.sensor_size,
        crop=(top, left, crop_h, crop_w),
        pool=pool,
    )
