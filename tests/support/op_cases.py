"""The op-count cases of the host-sync budgets (``tests/library/test_host_syncs.py``): aten ops and
host syncs per call of every event kernel (and exact TES on frames) at B = 4 and B = 32.

A kernel whose op count grows with the batch loops over samples in Python (one launch per
sample on an accelerator). Counted with :func:`event_transforms._profiling.count_ops`
(torch.profiler on the CPU: top-level aten ops, and syncs = ``.item()``/``nonzero``/``unique``/
library reads). Each event case runs its module on B synthetic streams (20-200 events each, 6
frames of 1 ms on 11 x 17 pixels) with params drawn from a fixed generator; the frame cases
run exact TES on B synthetic frames and dense Poisson noise on B zero frames.

Print the table (from the repository root)::

    python -m tests.support.op_cases            # every case
    python -m tests.support.op_cases --only TES  # cases whose name contains TES
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from typing import Any

import torch

import event_transforms as et
from event_transforms.events.batch import EventBatch
from event_transforms.events import batch as batch_module

from event_transforms._profiling import count_ops, synthetic_frames

SENSOR = (11, 17)
N_FRAMES = 6


def event_batch(b: int, seed: int = 0) -> EventBatch:
    """B sorted streams of 20-200 events (x, y, t, p) on SENSOR, t in [0, 6 ms), a 1 ms grid."""
    g = torch.Generator().manual_seed(seed)
    streams = []
    for _ in range(b):
        n = int(torch.randint(20, 200, (1,), generator=g))
        t = torch.sort(torch.randint(0, N_FRAMES * 1000, (n,), generator=g)).values
        x = torch.randint(0, SENSOR[1], (n,), generator=g)
        y = torch.randint(0, SENSOR[0], (n,), generator=g)
        p = torch.randint(0, 2, (n,), generator=g)
        streams.append(torch.stack([x, y, t, p], 1))
    return EventBatch.from_streams(streams, sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=N_FRAMES)


def _bank() -> torch.Tensor:
    return torch.poisson(torch.full((40, 2, *SENSOR), 0.3), generator=torch.Generator().manual_seed(1))


#: name -> module factory, one per event kernel (p = 1, one method: the kernel, not the gating).
EVENT_CASES: dict[str, Callable[[], Any]] = {
    "SpatialJitter": lambda: et.SpatialJitter((0.5, 2.0)),
    "TimeJitter": lambda: et.TimeJitter((10.0, 300.0)),
    "TimeSkew": lambda: et.TimeSkew((0.8, 1.2), (-100.0, 100.0)),
    "RandomEventDrop(random)": lambda: et.RandomEventDrop((0.1, 0.5), methods=("random",)),
    "RandomEventDrop(time)": lambda: et.RandomEventDrop((0.1, 0.5), methods=("time",)),
    "RandomEventDrop(area)": lambda: et.RandomEventDrop((0.1, 0.5), methods=("area",)),
    "DropPixel": lambda: et.DropPixel([[1, 1], [3, 5]]),
    "RandomDropPixel": lambda: et.RandomDropPixel((0.1, 0.4)),
    "RefractoryPeriod": lambda: et.RefractoryPeriod((100.0, 2000.0)),
    "Decimation": lambda: et.Decimation((1, 3)),
    "AddNoise": lambda: et.AddNoise(_bank()),
    "AddPoissonNoise": lambda: et.AddPoissonNoise((1.0, 100.0)),
    "FrameShift": lambda: et.FrameShift(-1),
    "RandomFrameShift": lambda: et.RandomFrameShift((-1, 1, 2)),
    "TES exact": lambda: et.RandomTemporalEventShift((-2, -1), (0.3, 0.7)),
    "TES binomial": lambda: et.RandomTemporalEventShift((-2, -1), (0.3, 0.7), mode="binomial"),
    "TimeReversal": lambda: et.TimeReversal(),
    "RandomTimeReversal": lambda: et.RandomTimeReversal(),
    "HorizontalFlip": lambda: et.HorizontalFlip(),
    "RandomHorizontalFlip": lambda: et.RandomHorizontalFlip(),
    "RandomTranslate": lambda: et.RandomTranslate((2, 3)),
    "FlipPolarity": lambda: et.FlipPolarity(),
    "RandomFlipPolarity": lambda: et.RandomFlipPolarity(),
    "RandomRotation": lambda: et.RandomRotation(30.0),
    "RandomResize": lambda: et.RandomResize((0.8, 1.25)),
    "RandomAffine": lambda: et.RandomAffine(20.0, translate=(0.1, 0.1)),
    "MergePolarities": lambda: et.MergePolarities(),
    "Downsample": lambda: et.Downsample(2),
    "Cutout": lambda: et.Cutout(4),
    "Denoise": lambda: et.Denoise(),
    "RandomStretch": lambda: et.RandomStretch((0.8, 1.25)),
    "RandomPerspective": lambda: et.RandomPerspective(0.5),
    "RandomElastic": lambda: et.RandomElastic(alpha=(2.0, 6.0), sigma=2.0),
    "CutMix": lambda: et.CutMix(),
    "MixUp": lambda: et.MixUp(0.4),
}

#: Event kernels whose CPU path loops over samples on purpose (event_centroid's slice sums and
#: the per-sample affine coefficients: 7 ms against 25 ms for the gathers on 32 x 40k events, the
#: random helper's measurement); on other devices they take one gather per coefficient.
CPU_LOOPS = ("RandomRotation", "RandomResize", "RandomAffine")

#: name -> (module factory, frames factory of B): exact TES on frames.
FRAME_CASES: dict[str, tuple[Callable[[], Any], Callable[[int], torch.Tensor]]] = {
    "TES exact frames 5%-dense": (
        lambda: et.TemporalEventShift(-2, 0.5), lambda b: synthetic_frames((b, 36, 2, 70, 75), seed=0)),
    "TES exact frames Poisson(0.3)": (
        lambda: et.TemporalEventShift(-2, 0.5),
        lambda b: torch.poisson(torch.full((b, 36, 2, 70, 75), 0.3), generator=torch.Generator().manual_seed(0))),
    # counts above the expansion limit (8): the whole-count binomial draws
    "TES exact frames counts to ~20": (
        lambda: et.TemporalEventShift(-2, 0.5),
        lambda b: synthetic_frames((b, 36, 2, 70, 75), mean_count=8.0, seed=0)),
    "AddPoissonNoise dense frames": (
        lambda: et.AddPoissonNoise(200.0), lambda b: torch.zeros(b, 20, 2, 32, 32, dtype=torch.int16)),
}


def counts_of(name: str, b: int) -> tuple[int, int]:
    """(syncs, ops) of one call of case ``name`` at batch size ``b`` (params drawn first).

    Gathers of whole streams (a gated call's kept streams, put back) are counted on their
    accelerator path, one ``index_select`` per field (``events.batch.SLICES_ON_CPU`` off):
    the CPU copies runs of events as slices instead, faster there, as many as the runs."""
    slices, batch_module.SLICES_ON_CPU = batch_module.SLICES_ON_CPU, False
    try:
        return _counts_of(name, b)
    finally:
        batch_module.SLICES_ON_CPU = slices


def _counts_of(name: str, b: int) -> tuple[int, int]:
    if name in EVENT_CASES:
        module, inputs = EVENT_CASES[name](), event_batch(b)
        shape = inputs.frame_shape
    else:
        make_module, make_frames = FRAME_CASES[name]
        module, inputs = make_module(), make_frames(b)
        shape = inputs.shape
    params = module.make_params(shape, generator=torch.Generator().manual_seed(0))
    counts = count_ops(lambda: module(inputs, params=params))
    return counts.syncs, counts.ops


def table(names: Sequence[str], sizes: Sequence[int] = (4, 32)) -> list[list[Any]]:
    rows = []
    for name in names:
        row: list[Any] = [name]
        for b in sizes:
            row += list(counts_of(name, b))
        rows.append(row)
    return rows


def main(argv: Sequence[str] | None = None) -> list[list[Any]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="cases whose name contains this text")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    names = [n for n in [*EVENT_CASES, *FRAME_CASES] if args.only in n]
    rows = table(names)
    print("| kernel | syncs B=4 | ops B=4 | syncs B=32 | ops B=32 |")
    print("|---|---|---|---|---|")
    for name, s4, o4, s32, o32 in rows:
        flag = "" if (s4, o4) == (s32, o32) else (
            "  <- grows with B: a CPU-only loop over samples (faster there than the gathers); "
            "the accelerator path is the same ops at any B" if name in CPU_LOOPS else "  <- grows with B")
        print(f"| {name} | {s4} | {o4} | {s32} | {o32} |{flag}")
    return rows


if __name__ == "__main__":
    main()
