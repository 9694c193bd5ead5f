"""The simulator's export: a built-in scene's grasps written in the recording-set layout."""

from __future__ import annotations

__all__ = ["export_scene"]

import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from .._files import atomic_write


def export_scene(scene: Any, out: str | os.PathLike[str], *, root: str | None = None, log: Any = None) -> Path:
    """Write a built-in scene's grasps in the recording-set layout.

    Every grasp of the scene's splits (training: ``train`` then ``holdout``; deployment:
    ``val`` then ``test``, all labelled) is simulated again from its seed and written as
    ``events/<split>_<k>.npy`` (structured ``x, y, t, p``) and ``force/<split>_<k>.csv`` (one
    sample per frame at its centre, the simulator's F/T reading), with ``diameter_mm``,
    ``split``, the grasp's crop window (the fixed 140 × 150 window centred on the sensor, as
    the built-in data set crops) and the seed in ``recordings.csv``. So
    ``reproduce --data OUT`` reads the same frames and labels as ``reproduce --scenes NAME``.

    Returns:
        The path of ``recordings.csv``.
    """
    from ..datasets import _SPLIT_SEED, SPLIT_SIZES
    from ..benchmark_scenes import get_scene
    from ..simulation import draw_grasp, simulate_grasps

    scene = get_scene(scene)
    out = Path(out)
    (out / "events").mkdir(parents=True, exist_ok=True)
    (out / "force").mkdir(parents=True, exist_ok=True)
    rows = ["events,force,role,diameter_mm,split,crop_top,crop_left,crop_height,crop_width,seed,scene"]
    for split in ("train", "holdout", "val", "test"):
        session = scene.train if split in ("train", "holdout") else scene.deploy
        role = "train" if split in ("train", "holdout") else "deploy"
        first = _SPLIT_SEED[split]
        tick = time.perf_counter()
        for block in range(0, SPLIT_SIZES[split], 24):
            seeds = range(first + block, first + min(block + 24, SPLIT_SIZES[split]))
            grasps = [draw_grasp(session.diameter(s - first), seed=s, config=session.config) for s in seeds]
            for seed, grasp, recording in zip(seeds, grasps, simulate_grasps(grasps, session.config)):
                k = seed - first
                name = f"{split}_{k:03d}"
                np.save(out / "events" / f"{name}.npy", recording.events)
                force = np.c_[recording.force_t_us.astype(np.float64), recording.force.astype(np.float64)]
                with open(out / "force" / f"{name}.csv", "w") as handle:
                    handle.write("t_us,force_n\n")
                    handle.writelines(f"{int(t)},{float(np.float32(f))!r}\n" for t, f in force)
                top, left, height, width = recording.sensor_crop((140, 150))
                rows.append(f"events/{name}.npy,force/{name}.csv,{role},{grasp.diameter_mm:g},{split},"
                            f"{top},{left},{height},{width},{seed},{scene.name}")
        if log:
            log(f"exported {SPLIT_SIZES[split]} {split} grasps of {scene.name!r} in {time.perf_counter() - tick:.1f} s")
    table = out / "recordings.csv"
    with atomic_write(table) as handle:
        handle.write("\n".join(rows) + "\n")
    return table
