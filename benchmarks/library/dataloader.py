"""DataLoader throughput: binning and augmenting per sample, per batch, and tonic's way.

256 grasps (32 simulated grasps, :func:`benchmarks.library.events_pipeline.grasp_streams`, cycled
8 times to keep the set-up short), ``batch_size=8``, ``num_workers=0`` by default (the machine this
ran on has 2 cores shared with other jobs: workers would measure the scheduler; every path
does the same work per sample in a worker, so the ratios carry over); ``--workers N`` loads
the per-sample and tonic paths with N worker processes (one torch thread each, persistent). One epoch, timed as
samples per second (median of a few epochs):

- **per sample in the dataset**: ``EventsToFrames`` (crop 140×150, pool 2, 36 bins of
  10 ms) then ``OneOf(RandomResize(0.8, 1.25), FrameShift(-1), TES-2(0.5))`` on the
  sample's frames; torch's default collate stacks them;
- **batched in the main process**: the dataset returns the raw stream, ``collate_events``
  builds an ``EventBatch`` (``validate=False``: the simulator's streams are trusted), the
  same ``OneOf`` runs on the batch's events, then ``EventsToFrames`` bins the batch;
- **tonic per sample**: ``Compose([DropEvent(0.1), SpatialJitter(var 1), ToFrame(10 ms)])``
  then the same crop and 2×2 pool in numpy (tonic has neither), default collate.

    MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 \\
        python benchmarks/library/dataloader.py --threads 1 [--quick] [--workers 2] [--no-write]
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from benchmarks._common import (
    allocator_suffix, apply_threads, base_parser, command, environment_lines, markdown_table, publish,
    time_repeated,
)
from benchmarks.library.events_pipeline import CROP, N_FRAMES, SENSOR, grasp_streams

import event_transforms as et

__all__ = ["loaders", "run", "main"]

BATCH = 8


class Streams(Dataset):
    """Event streams, each passed through ``transform`` when read."""

    def __init__(self, streams: Sequence[np.ndarray], transform: Callable[[np.ndarray], Any] | None = None) -> None:
        self.streams, self.transform = list(streams), transform

    def __len__(self) -> int:
        return len(self.streams)

    def __getitem__(self, index: int) -> Any:
        stream = self.streams[index]
        return stream if self.transform is None else self.transform(stream)


def _augment() -> torch.nn.Module:
    return et.OneOf([et.RandomResize((0.8, 1.25)), et.FrameShift(-1), et.TemporalEventShift(-2, 0.5)])


def _tonic_transform() -> Callable[[np.ndarray], Any] | None:
    try:
        import tonic.transforms as T
    except ImportError:
        return None
    sensor = (SENSOR[1], SENSOR[0], 2)
    compose = T.Compose([T.DropEvent(p=0.1), T.SpatialJitter(sensor_size=sensor, var_x=1.0, var_y=1.0,
                                                             clip_outliers=True),
                         T.ToFrame(sensor_size=sensor, time_window=10_000.0)])
    top, left, height, width = CROP

    def transform(stream: np.ndarray) -> torch.Tensor:
        frames = compose(stream)[:N_FRAMES, :, top : top + height, left : left + width]
        frames = np.pad(frames, ((0, N_FRAMES - len(frames)), (0, 0), (0, 0), (0, 0)))
        pooled = frames.reshape(N_FRAMES, 2, height // 2, 2, width // 2, 2).sum(axis=(3, 5))
        return torch.from_numpy(pooled.astype(np.float32))

    return transform


def _one_thread(worker: int) -> None:
    torch.set_num_threads(1)


def loaders(streams: Sequence[np.ndarray], workers: int = 0) -> dict[str, Callable[[], int]]:
    """One epoch per path, returning the number of samples seen; the per-sample and tonic
    paths load with ``workers`` worker processes (one torch thread each, kept between epochs)."""
    to_frames = et.EventsToFrames(SENSOR, frame_ms=10.0, t_start=0, n_frames=N_FRAMES, crop=CROP, pool=2)
    augment = _augment()

    def per_sample(stream: np.ndarray) -> torch.Tensor:
        return augment(to_frames(stream))

    collate = partial(et.collate_events, sensor_size=SENSOR, frame_ms=10.0, t_start=0, n_frames=N_FRAMES,
                      validate=False)
    paths: dict[str, Callable[[], int]] = {}

    def epoch(loader: DataLoader, step: Callable[[Any], torch.Tensor]) -> int:
        seen = 0
        for item in loader:
            seen += step(item).shape[0]
        return seen

    pool = {"num_workers": workers, "worker_init_fn": _one_thread if workers else None,
            "persistent_workers": workers > 0}
    sample_loader = DataLoader(Streams(streams, per_sample), batch_size=BATCH, **pool)
    paths["per sample in the dataset (EventsToFrames → OneOf)"] = lambda: epoch(sample_loader, lambda b: b)
    batch_loader = DataLoader(Streams(streams), batch_size=BATCH, num_workers=0, collate_fn=collate)
    paths["collated EventBatch, OneOf + EventsToFrames in the main process"] = lambda: epoch(
        batch_loader, lambda b: to_frames(augment(b)))
    tonic = _tonic_transform()
    if tonic is not None:
        tonic_loader = DataLoader(Streams(streams, tonic), batch_size=BATCH, **pool)
        paths["tonic per sample (DropEvent, SpatialJitter, ToFrame, crop/pool in numpy)"] = lambda: epoch(
            tonic_loader, lambda b: b)
    return paths


def run(streams: Sequence[np.ndarray], *, repeats: int = 3, workers: int = 0) -> dict[str, Any]:
    rates = {}
    for name, fn in loaders(streams, workers).items():
        timing = time_repeated(fn, repeats=repeats, warmup=1)
        rates[name] = len(streams) / timing.median
    first = next(iter(rates))
    tonic = next((k for k in rates if k.startswith("tonic")), None)
    rows = [[name, f"{rate:,.0f}", f"{rate / rates[tonic]:.1f}×" if tonic else "n/a"] for name, rate in rates.items()]
    return {"rates": rates, "table": markdown_table(["path", "samples/s", "× tonic"], rows), "per_sample": first,
            "tonic": tonic}


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "dataloader")
    parser.add_argument("--before", type=float, default=104.0,
                        help="per-sample samples/s measured on 732b169, before the event-path work, for the goal line")
    parser.add_argument("--before-tonic", type=float, default=30.0,
                        help="tonic's samples/s measured in the same run as --before")
    parser.add_argument("--workers", type=int, default=0,
                        help="DataLoader workers of the per-sample and tonic paths (default 0: the main process)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    unique = grasp_streams(4 if args.quick else 32)
    streams = [unique[i % len(unique)] for i in range(16 if args.quick else 256)]
    result = run(streams, repeats=1 if args.quick else 3, workers=args.workers)
    rates, first, tonic = result["rates"], result["per_sample"], result["tonic"]
    goals = [f"- per-sample path: {rates[first]:,.0f} samples/s against {args.before:g} measured on 732b169 (a "
             "different machine load: not comparable as such)"]
    if tonic:
        before, now = args.before / args.before_tonic, rates[first] / rates[tonic]
        goals.append(f"- per-sample path in units of tonic's rate in the same run: {before:.1f}× tonic on 732b169, "
                     f"{now:.1f}× now: {now / before:.1f}× today's (goal ≥ 3×: {'met' if now >= 3 * before else 'missed'})")
        ratio = rates[first] / rates[tonic]
        goals.append(f"- per-sample path vs tonic: {ratio:.1f}× (goal ≥ 10×: {'met' if ratio >= 10 else 'missed'})")
    body = "\n\n".join([
        "## DataLoader throughput: per sample, batched, tonic" + allocator_suffix(),
        f"`{command('library/dataloader.py', argv)}`. {len(streams)} grasps ({len(unique)} simulated, cycled), batch "
        f"{BATCH}, num_workers={args.workers} for the per-sample and tonic paths (2 shared cores), one CPU thread "
        "per process; samples/s = grasps / median epoch time.",
        result["table"],
        "Goals:",
        "\n".join(goals),
        *environment_lines(["tonic"]),
    ])
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
