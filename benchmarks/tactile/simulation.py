"""How long the synthetic data set takes to make and to read, and what it looks like.

Times, in one run:

* generating every benchmark scene (48 train + 24 val + 96 test sequences, simulation,
  events to frames, atomic save) into an empty cache, scene by scene;
* simulating the paper scene's 48 training grasps in one call, against one call per grasp
  (the baseline: no vectorisation across grasps);
* opening the cached paper scene and reading all of its items;
* ``events_to_frames`` on the 48 recordings' events, against ``numpy.add.at``.

Writes one PNG of a grasp per bolt size (12, 15, 18 mm) and one per scene (training grasps
above deployment grasps, ``scene_<name>.png``) and replaces the ``simulation`` section of
``benchmarks/tactile/RESULTS.md``.

    python benchmarks/tactile/simulation.py [--quick] [--out DIR] [--no-write]
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from benchmarks._common import (
    apply_threads, base_parser, command, environment_lines, fmt_ms, fmt_ratio,
    markdown_table, time_repeated, publish,
)

import time

from event_transforms.tactile import cli
from event_transforms.tactile.datasets import SPLIT_SIZES, TactileGrasps
from event_transforms.tactile.benchmark_scenes import SCENES, get_scene
from event_transforms.tactile.simulation import simulate_grasp, simulate_grasps
from event_transforms.viz import save_event_grid


def _numpy_frames(events: np.ndarray, crop: tuple[int, int, int, int]) -> np.ndarray:
    """Baseline: the same binning with ``np.add.at``."""
    top, left, height, width = crop
    out = np.zeros((36, 2, height // 2, width // 2), dtype=np.int64)
    frame = events["t"] // 10_000
    keep = (
        (frame >= 0) & (frame < 36)
        & (events["y"] >= top) & (events["y"] < top + height)
        & (events["x"] >= left) & (events["x"] < left + width)
    )
    e = events[keep]
    np.add.at(
        out,
        (frame[keep], (e["p"] > 0).astype(np.int64), (e["y"] - top) // 2, (e["x"] - left) // 2),
        1,
    )
    return out


def main(argv: Sequence[str] | None = None) -> None:
    parser = base_parser(__doc__.splitlines()[0], "simulation")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent), help="folder for the PNGs")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    repeats = 1 if args.quick else 3
    session = get_scene("paper").train
    config = session.config
    grasps = session.grasps(8 if args.quick else SPLIT_SIZES["train"], seed=0)
    n = len(grasps)

    scene_seconds = {}
    with tempfile.TemporaryDirectory() as root:
        for name in (["control"] if args.quick else list(SCENES)):
            tick = time.perf_counter()
            sizes = [len(TactileGrasps(split, root=root, scene=name)) for split in ("train", "val", "test")]
            scene_seconds[name] = (time.perf_counter() - tick, sizes)
    batched = time_repeated(lambda: simulate_grasps(grasps, config), repeats=repeats)
    one_by_one = time_repeated(
        lambda: [simulate_grasps([g], config) for g in grasps], repeats=1 if args.quick else 2
    )

    with tempfile.TemporaryDirectory() as root:
        for split in ("train", "val", "test"):
            TactileGrasps(split, root=root)

        def read_all() -> None:
            for split in ("train", "val", "test"):
                data = TactileGrasps(split, root=root)
                for i in range(len(data)):
                    data[i]

        reading = time_repeated(read_all, repeats=2 if args.quick else 10)

    recordings = simulate_grasps(grasps, config)
    crops = [r.contact_crop() for r in recordings]
    n_events = sum(len(r.events) for r in recordings)
    binning = time_repeated(
        lambda: [r.frames(crop=c, pool=2) for r, c in zip(recordings, crops)], repeats=repeats * 3
    )
    numpy_binning = time_repeated(
        lambda: [_numpy_frames(r.events, c) for r, c in zip(recordings, crops)], repeats=repeats * 3
    )
    for r, c in zip(recordings[:3], crops):
        assert np.array_equal(r.frames(crop=c, pool=2, dtype=torch.int64).numpy(), _numpy_frames(r.events, c))

    out = Path(args.out)
    pictures = []
    for diameter in (12.0, 15.0, 18.0):
        recording = simulate_grasp(diameter, seed=0, config=config)
        path = out / f"grasp_{int(diameter)}mm.png"
        save_event_grid(recording.frames(crop=recording.contact_crop(), pool=2), path, upscale=2)
        pictures.append(path)
    if not args.quick:
        cli.main(["show-scene", "--out", str(out)])
        pictures += [out / f"scene_{name}.png" for name in SCENES]

    rows = [
        [f"scene {name!r}: simulate + bin + save {'/'.join(map(str, sizes))} sequences (train/val/test)",
         fmt_ms(seconds), "—", "—"]
        for name, (seconds, sizes) in scene_seconds.items()
    ] + [
        [f"simulate_grasps, {n} grasps in one call", fmt_ms(batched.median), fmt_ms(batched.iqr), "1.00×"],
        [
            f"baseline: {n} calls of one grasp each",
            fmt_ms(one_by_one.median),
            fmt_ms(one_by_one.iqr),
            fmt_ratio(one_by_one.ratio(batched)),
        ],
        ["open the cached paper scene and read all 168 items", fmt_ms(reading.median), fmt_ms(reading.iqr), "—"],
        [f"events_to_frames, {n} recordings ({n_events / 1e6:.2f} M events)", fmt_ms(binning.median),
         fmt_ms(binning.iqr), "1.00×"],
        ["baseline: numpy.add.at", fmt_ms(numpy_binning.median), fmt_ms(numpy_binning.iqr),
         fmt_ratio(numpy_binning.ratio(binning))],
    ]
    table = markdown_table(["task", "median", "IQR", "time / fast path"], rows)
    body = "\n".join(
        [
            "## Synthetic data set (simulation)",
            "",
            f"Command: `{command('tactile/simulation.py', argv)}`",
            "",
            *environment_lines(),
            "",
            table,
            "",
            "Scene generation times are single runs into an empty cache (scenes that share a session share its "
            "file, so a later scene can reuse an earlier one's training split).",
            "",
            "Pictures (OFF red, ON blue, 12 frames per row, 140×150 crop pooled 2×2; scene pictures: training "
            "grasps above deployment grasps): "
            + ", ".join(f"`{p.name}`" for p in pictures),
            "",
            "Synthetic data from `event_transforms.tactile.simulation`, not the paper's recordings.",
        ]
    )
    publish(body, args)


if __name__ == "__main__":
    main()
