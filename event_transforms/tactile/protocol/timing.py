"""The time columns of a protocol run, and the steps a method affords at equal wall time.

:func:`single_model_wall` times one model trained alone, :func:`online_augmentation_cost`
one epoch of a method's online augmentation, :func:`measure_timing` both for a run's scenes,
and :func:`equal_time_steps` turns them into the steps a method affords in ``none``'s time.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Mapping, Sequence
from typing import Any

import torch

from ..._validation import check_positive
from ..copies import DeviceAugment, OnlineCopies, SceneData
from ..methods import parse_method
from ..benchmark_scenes import BenchmarkScene
from .config import ProtocolConfig
from .unit import run_unit

__all__ = ["online_augmentation_cost", "single_model_wall", "measure_timing", "equal_time_steps"]


def online_augmentation_cost(method_name: str, scene: str | BenchmarkScene, data: SceneData, *,
                             batch_size: int = 8, copies: int = 1, repeats: int = 3, seed: int = 0) -> float | None:
    """Seconds to augment one epoch's copies online, as a DataLoader would: every training
    item's ``copies`` copies transformed once, ``batch_size`` at a time, through the
    :class:`~event_transforms.tactile.copies.DeviceAugment` the online protocol uses (median of
    ``repeats`` passes; ``None`` for a method without copies)."""
    method = parse_method(method_name, copies=copies, scene=scene)
    transform = method.build(data.noise_bank)
    if transform is None:
        return None
    online = OnlineCopies(data.train, method.copies)
    order = list(range(len(data.train), len(online)))  # the copies
    times = []
    for _ in range(repeats):
        augment = DeviceAugment(transform, seed)
        for start in range(0, len(order), batch_size):
            items = [online[i] for i in order[start:start + batch_size]]
            frames = torch.stack([torch.as_tensor(item[0]) for item in items]).float()
            augment(frames, [item[2] for item in items])
        times.append(augment.stopwatch.seconds)
    return statistics.median(times)


def single_model_wall(scene: str | BenchmarkScene, data: SceneData, config: ProtocolConfig, *,
                      repeats: int = 3, seed: int = 0) -> dict[str, Any]:
    """One model (``none``, one seed) trained alone for ``config.steps`` steps, ``repeats``
    times: wall seconds per run (median, min, max). With fixed copies every method does this
    same training work, so it is every method's training time per run."""
    times = []
    for _ in range(repeats):
        tick = time.perf_counter()
        run_unit(scene, ["none"], [seed], config, data, progress=False)
        times.append(time.perf_counter() - tick)
    return {"median": statistics.median(times), "min": min(times), "max": max(times), "repeats": repeats,
            "runs_s": times}


def measure_timing(scenes: Sequence[str], chosen: Mapping[str, Sequence[str]], data: dict[str, SceneData],
            config: ProtocolConfig, threads: int | None) -> dict[str, Any]:
    """The time columns: one model's wall time per run (measured on the first scene: every
    scene's data have the same shape) and each scene's methods' online augmentation cost."""
    if threads:
        torch.set_num_threads(threads)
    wall = single_model_wall(data[scenes[0]].scene, data[scenes[0]], config)
    online: dict[str, dict[str, float | None]] = {}
    for scene in scenes:
        online[scene] = {m: online_augmentation_cost(m, data[scene].scene, data[scene], batch_size=config.batch_size,
                                                     copies=config.copies) for m in chosen[scene]}
    return {"single_model_wall_s": wall, "single_model_scene": scenes[0], "online_aug_s_per_epoch": online}


def equal_time_steps(steps: int, single_wall_s: float, online_wall_s: float, *, grain: int = 1) -> int:
    """The optimiser steps a method affords in the wall time ``none`` takes for ``steps``.

    One model trains ``steps`` steps in ``single_wall_s`` seconds; augmenting online as well
    takes ``online_wall_s`` seconds for those steps, so per step the method costs
    ``online_wall_s / steps`` and affords ``steps · single_wall_s / online_wall_s`` steps in
    ``none``'s time, rounded down to a multiple of ``grain`` (at least ``grain``; never more
    than ``steps``).

    Example:
        >>> equal_time_steps(300, 45.7, 64.8, grain=25)  # 211.6 steps, rounded down
        200
        >>> equal_time_steps(300, 45.7, 45.7, grain=25)  # no online cost: the same steps
        300
    """
    check_positive(steps, "steps", integer=True)
    check_positive(grain, "grain", integer=True)
    check_positive(single_wall_s, "single_wall_s")
    if not math.isfinite(online_wall_s) or online_wall_s < single_wall_s:
        raise ValueError(f"online_wall_s must be finite and at least single_wall_s ({single_wall_s}), "
                         f"got {online_wall_s}")
    affordable = math.floor(steps * single_wall_s / online_wall_s + 1e-9)
    return min(steps, max(grain, affordable // grain * grain))
