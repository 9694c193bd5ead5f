"""Gated (p=0.5) against ungated (p=1) calls on 32 × 40k events and the (32, 36, 2, 70, 75) frame batch.

Issue 36, goal 1: a gated call should cost at most 10 % more than the ungated kernel on every
sample. Prints the median of ``--rounds`` ``blocked_autorange`` runs per case and the ratio
gated / ungated; the clone of the frame batch is timed in the same run as the baseline.

Run: ``MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 OMP_NUM_THREADS=1
python -m benchmarks.gating``
"""

from __future__ import annotations

import argparse
import statistics
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from torch.utils import benchmark

import event_transforms as et

SENSOR = (180, 240)
FRAMES = (32, 36, 2, 70, 75)


def streams(count: int = 32, n: int = 40_000, seed: int = 0) -> list[np.ndarray]:
    """``count`` uniform random streams of ``n`` events (x, y, t, p), t sorted in µs over 360 ms."""
    rng = np.random.default_rng(seed)
    dtype = np.dtype([("x", np.int16), ("y", np.int16), ("t", np.int64), ("p", np.int8)])
    out = []
    for _ in range(count):
        s = np.empty(n, dtype=dtype)
        s["x"] = rng.integers(0, SENSOR[1], n)
        s["y"] = rng.integers(0, SENSOR[0], n)
        s["t"] = np.sort(rng.integers(0, 360_000, n))
        s["p"] = rng.integers(0, 2, n)
        out.append(s)
    return out


def median_time(fn: Callable[[], Any], rounds: int, min_run_time: float) -> float:
    """Median seconds per call over ``rounds`` ``blocked_autorange`` runs."""
    timer = benchmark.Timer(stmt="fn()", globals={"fn": fn})
    return statistics.median(timer.blocked_autorange(min_run_time=min_run_time).median for _ in range(rounds))


def cases() -> dict[str, Callable[[float], et.EventTransform]]:
    return {
        "RandomHorizontalFlip": lambda p: et.RandomHorizontalFlip(p),
        "RandomRotation(30)": lambda p: et.RandomRotation(30, p=p),
        "SpatialJitter(1)": lambda p: et.SpatialJitter(1, p=p),
        "RandomTimeReversal": lambda p: et.RandomTimeReversal(p),
        "RandomVerticalFlip": lambda p: et.RandomVerticalFlip(p),
        "RandomFlipPolarity": lambda p: et.RandomFlipPolarity(p),
    }


def main(argv: Sequence[str] | None = None) -> list[list[str]]:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--min-run-time", type=float, default=0.2)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    batch = et.EventBatch.from_streams(streams(), sensor_size=SENSOR, frame_ms=10.0, t_start=0, n_frames=36)
    frames = torch.rand(FRAMES)
    clone = median_time(frames.clone, args.rounds, args.min_run_time)
    print(f"frames.clone(): {clone * 1e3:.2f} ms")
    rows = []
    for name, make in cases().items():
        for label, x in (("events", batch), ("frames", frames)):
            times = {}
            try:
                make(1.0)(x)
            except TypeError:  # an events-only transform
                continue
            for p in (1.0, 0.5):
                module = make(p)
                gen = torch.Generator().manual_seed(0)
                times[p] = median_time(lambda m=module, g=gen: m(x, generator=g), args.rounds, args.min_run_time)
            ratio = times[0.5] / times[1.0]
            row = [
                name,
                label,
                f"{times[1.0] * 1e3:.2f}",
                f"{times[0.5] * 1e3:.2f}",
                f"{ratio:.2f}",
                f"{times[0.5] / clone:.2f}",
            ]
            rows.append(row)
            print(" | ".join(row), flush=True)
    return rows


if __name__ == "__main__":
    main()
