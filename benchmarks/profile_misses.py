"""Where the time goes in the event-path rows that miss issue 26's goals (torch.profiler, CPU).

For each row, one warm-up call and then ``--calls`` profiled calls on the events pipeline's batch
(32 simulated grasps): the share of the time spent in binning (``EventsToFrames``) and in the
augmentation, and the aten ops with the most self CPU time. The explanation of a miss, printed
by the repo rather than told.

Run (one thread, the glibc thresholds of the other benchmarks)::

    MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 PYTHONPATH=$PWD python benchmarks/profile_misses.py
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import torch
from torch.profiler import ProfilerActivity, profile

import event_transforms as et
from benchmarks.events_pipeline import CROP, N_FRAMES, SENSOR, grasp_streams


def rows(batch: et.EventBatch) -> dict[str, tuple[Callable[[], Any], Callable[[], Any] | None]]:
    """name -> (the augmentation alone or None, the whole row)."""
    g = lambda: torch.Generator().manual_seed(0)  # noqa: E731
    to_frames = et.EventsToFrames(SENSOR, frame_ms=10.0, n_frames=N_FRAMES, crop=CROP, pool=2)
    rotation, tes, shift = et.RandomRotation(180.0), et.TemporalEventShift(-2, 0.5), et.FrameShift(-1)
    jitter = et.Compose([et.SpatialJitter(1.0), et.TimeJitter(100.0), et.RandomEventDrop(0.1, methods=("random",))])
    full = et.EventsToFrames(SENSOR, frame_ms=10.0, n_frames=N_FRAMES)
    return {
        "EventsToFrames (crop, pool 2)": (lambda: to_frames(batch), None),
        "RandomRotation(180°) + binning": (lambda: to_frames(rotation(batch, generator=g())),
                                           lambda: rotation(batch, generator=g())),
        "TES-2(0.5) exact + binning": (lambda: to_frames(tes(batch, generator=g())), lambda: tes(batch, generator=g())),
        "FrameShift(-1) on events (no binning in this row)": (lambda: shift(batch), None),
        "jitter + time jitter + drop + binning": (lambda: full(jitter(batch, generator=g())),
                                                   lambda: jitter(batch, generator=g())),
    }


def per_sample_parts(streams: Sequence[Any]) -> dict[str, float]:
    """The DataLoader benchmark's per-sample path split into its steps: median ms per sample of
    binning one stream and of each branch of its ``OneOf`` on the binned sample."""
    to_frames = et.EventsToFrames(SENSOR, frame_ms=10.0, t_start=0, n_frames=N_FRAMES, crop=CROP, pool=2)
    frames = [to_frames(s) for s in streams]
    g = lambda: torch.Generator().manual_seed(0)  # noqa: E731
    branches = {"RandomResize(0.8, 1.25)": et.RandomResize((0.8, 1.25)), "FrameShift(-1)": et.FrameShift(-1),
                "TES-2(0.5) exact (frames)": et.TemporalEventShift(-2, 0.5)}
    parts = {"EventsToFrames (one stream)": median_ms(lambda: [to_frames(s) for s in streams], 3) / len(streams)}
    for name, branch in branches.items():
        parts[name] = median_ms(lambda b=branch: [b(f, generator=g()) for f in frames], 3) / len(frames)
    return parts


def median_ms(call: Callable[[], Any], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return sorted(times)[len(times) // 2] * 1e3


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=3)
    parser.add_argument("--top", type=int, default=6)
    parser.add_argument("--grasps", type=int, default=32)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")  # the shifts push events out of the window on purpose
    batch = et.EventBatch.from_streams(grasp_streams(args.grasps), sensor_size=SENSOR, frame_ms=10.0, t_start=0,
                                       n_frames=N_FRAMES)
    clone_of = et.EventsToFrames(SENSOR, frame_ms=10.0, n_frames=N_FRAMES, crop=CROP, pool=2)(batch)
    clone = median_ms(clone_of.clone, 9)
    print(f"{batch.num_events:,} events in {len(batch)} streams; frames.clone() {clone:.2f} ms (median of 9)\n")
    print("## DataLoader per-sample path, per sample (OneOf picks one branch per sample):")
    for name, ms in per_sample_parts(grasp_streams(8)).items():
        print(f"  {name:28s} {ms:7.2f} ms")
    print()
    for name, (whole, augment) in rows(batch).items():
        whole()
        total = median_ms(whole, 5)
        part = median_ms(augment, 5) if augment is not None else None
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            for _ in range(args.calls):
                whole()
        events = sorted(prof.key_averages(), key=lambda e: e.self_cpu_time_total, reverse=True)
        spent = sum(e.self_cpu_time_total for e in events) or 1
        share = "" if part is None else f"; augmentation alone {part:.1f} ms ({part / total:.0%}), binning the rest"
        print(f"## {name}: {total:.1f} ms = {total / clone:.2f}x the clone{share}")
        for e in events[: args.top]:
            print(f"  {e.key:28s} {e.self_cpu_time_total / spent:6.1%} of self CPU  ({e.count // args.calls} calls/call)")
        print()


if __name__ == "__main__":
    main()
