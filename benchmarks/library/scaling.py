"""How each transform's cost grows with batch size, sequence length, frame area and events.

For every transform we time a sweep along one axis at a time from a base batch
(8, 36, 2, 70, 75) with ≈5 % non-zero pixels, and fit the slope of log(time) against
log(size). A slope near 1 means linear cost; below 1, fixed overheads still dominate.

The events sweep keeps the non-zero pixels of a small batch (2, 4, 2, 32, 32) fixed and
multiplies their counts, from about 10² to 10⁷ events per frame: the count-preserving TES
modes work on non-zero pixels, not on single events, so their cost should barely grow
(slope ≪ 1; the goal is no worse than N log N). Each point also reports the process's
peak resident memory growth for the largest frame.

Run: ``python benchmarks/library/scaling.py`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

import math
import resource
import sys
from collections.abc import Sequence
from typing import Any

import torch

from benchmarks._common import (
    allocator_suffix, apply_threads, base_parser, command, environment_lines, fmt_ms, loglog_slope,
    markdown_table, synthetic_frames, time_call, time_interleaved, publish,
)

import event_transforms as et

__all__ = ["transforms_for", "sweeps", "run", "main"]

BASE = (8, 36, 2, 70, 75)


def transforms_for(t: int, h: int, w: int) -> dict[str, torch.nn.Module]:
    """The transforms swept (a noise bank sized for ``t`` frames of ``h``×``w``)."""
    bank = synthetic_frames((t + 8, 2, h, w), density=0.002, mean_count=1.0, seed=1)
    return {
        "clone (baseline)": _Clone(),
        "RandomRotation": et.RandomRotation(180.0),
        "RandomResize": et.RandomResize(choices=(15 / 18, 15 / 12)),
        "RandomFrameShift": et.RandomFrameShift([-2, -1, 1, 2]),
        "TES exact": et.TemporalEventShift(-2, 0.5, mode="exact"),
        "TES binomial": et.TemporalEventShift(-2, 0.5, mode="binomial"),
        "TES expected": et.TemporalEventShift(-2, 0.5, mode="expected"),
        "AddNoise": et.AddNoise(bank),
        "AddPoissonNoise": et.AddPoissonNoise((0.1, 10.0)),
        "RandomEventDrop": et.RandomEventDrop(fraction=(0.1, 0.5)),
        "RandomHorizontalFlip": et.RandomHorizontalFlip(0.5),
    }


class _Clone(torch.nn.Module):
    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        return frames.clone()


def sweeps(quick: bool) -> dict[str, list[tuple[float, tuple[int, ...]]]]:
    """Axis -> list of (size value, batch shape)."""
    if quick:
        return {
            "B": [(b, (b, 6, 2, 12, 11)) for b in (1, 2)],
            "T": [(t, (2, t, 2, 12, 11)) for t in (4, 8)],
            "H·W": [(h * w, (2, 6, 2, h, w)) for h, w in ((6, 5), (12, 11))],
        }
    b, t, _, h, w = BASE
    return {
        "B": [(n, (n, t, 2, h, w)) for n in (2, 4, 8, 16, 32)],
        "T": [(n, (b, n, 2, h, w)) for n in (9, 18, 36, 72, 144)],
        "H·W": [(hh * ww, (b, t, 2, hh, ww)) for hh, ww in ((18, 19), (35, 38), (70, 75), (140, 150), (280, 300))],
    }


EVENT_SHAPE = (2, 4, 2, 32, 32)
EVENT_MODULES = ("TES exact", "TES binomial", "TES expected", "RandomEventDrop", "RandomFrameShift", "clone (baseline)")


def _events_frames(scale: int, shape: Sequence[int]) -> tuple[torch.Tensor, float]:
    """Fixed ≈5 % pattern of non-zero pixels with counts multiplied by ``scale`` (float64 keeps them exact)."""
    base = synthetic_frames(shape, dtype=torch.float64)
    frames = base * scale
    per_frame = float(frames.sum()) / (shape[0] * shape[1])
    return frames, per_frame


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run(*, quick: bool = False, min_run_time: float = 0.2, rounds: int = 3) -> dict[str, Any]:
    results: dict[str, dict[str, list[tuple[float, float]]]] = {}
    for axis, points in sweeps(quick).items():
        # All points of one sweep are timed in interleaved rounds, so that the machine's
        # drift over the run does not tilt the fitted slopes.
        cases: dict[tuple[str, float], Any] = {}
        for value, shape in points:
            frames = synthetic_frames(shape)
            for name, module in transforms_for(shape[1], shape[3], shape[4]).items():
                cases[(name, value)] = lambda m=module, f=frames: m(f)
        timings, _ = time_interleaved(
            cases, baseline=next(iter(cases)), rounds=rounds, min_run_time=min_run_time, progress=False
        )
        for (name, value), timing in timings.items():
            results.setdefault(name, {}).setdefault(axis, []).append((value, timing.median))
        print(f"  sweep over {axis}: done", file=sys.stderr, flush=True)

    scales = (1, 100) if quick else (1, 10, 100, 10**3, 10**4, 10**5)
    shape = (1, 2, 2, 8, 8) if quick else EVENT_SHAPE
    events: dict[str, list[tuple[float, float]]] = {}
    rss_before = _peak_rss_mb()
    for scale in scales:
        frames, per_frame = _events_frames(scale, shape)
        modules = transforms_for(shape[1], shape[3], shape[4])
        for name in EVENT_MODULES:
            module = modules[name]
            timing = time_call(lambda m=module: m(frames), min_run_time=min_run_time)
            events.setdefault(name, []).append((per_frame, timing.median))
        print(f"  events/frame = {per_frame:.3g}: done", file=sys.stderr, flush=True)
    rss_growth = _peak_rss_mb() - rss_before

    # One frame holding 10**7 events in a single pixel (and 10**7 spread over the frame):
    # the exact sampler must neither expand events nor blow up memory.
    single = torch.zeros(1, 3, 2, 70, 75, dtype=torch.int64)
    single[0, 1, 1, 35, 37] = 10**7
    spread = torch.zeros(1, 3, 2, 70, 75, dtype=torch.int64)
    spread[0, 1] = 10**7 // (2 * 70 * 75)
    extreme = {}
    before = _peak_rss_mb()
    for label, frames in (("10⁷ events in one pixel", single), ("10⁷ events spread over the frame", spread)):
        module = et.TemporalEventShift(-1, 0.5, mode="exact")
        extreme[label] = time_call(lambda: module(frames), min_run_time=min_run_time).median
    extreme_rss = _peak_rss_mb() - before

    over = {
        axis: [value for value, shape in points if 4 * math.prod(shape) > 32 * 2**20]
        for axis, points in sweeps(quick).items()
    }
    return {"sizes": results, "over_mmap_threshold": over, "events": events, "event_rss_mb": rss_growth, "extreme": extreme, "extreme_rss_mb": extreme_rss}


def tables(result: dict[str, Any]) -> str:
    sizes = result["sizes"]
    axes = list(next(iter(sizes.values())).keys())
    slope_rows = []
    for name, by_axis in sizes.items():
        row = [name]
        for axis in axes:
            xs, ys = zip(*by_axis[axis])
            row.append(f"{loglog_slope(xs, ys):.2f}")
        slope_rows.append(row)
    parts = [
        "Log-log slope of time against each size (1 = linear):",
        markdown_table(["transform", *[f"slope in {a}" for a in axes]], slope_rows),
    ]
    for axis in axes:
        values = [v for v, _ in next(iter(sizes.values()))[axis]]
        rows = [[name, *[fmt_ms(t) for _, t in by_axis[axis]]] for name, by_axis in sizes.items()]
        parts += [f"Median time, sweeping {axis}:", markdown_table(["transform", *[f"{axis}={v:g}" for v in values]], rows)]

    big = result.get("over_mmap_threshold", {})
    if any(big.values()):
        listed = "; ".join(f"{axis} = {', '.join(f'{v:g}' for v in values)}" for axis, values in big.items() if values)
        parts.append(
            f"Batches over 32 MiB ({listed}) are above glibc's largest mmap threshold: with default settings "
            "every fresh output of that size is returned to the OS when freed and page-faulted in again, "
            "which bends the slopes upward; run with `MALLOC_MMAP_THRESHOLD_` raised to see the kernels alone."
        )

    events = result["events"]
    per_frame = [v for v, _ in next(iter(events.values()))]
    rows = []
    for name, points in events.items():
        xs, ys = zip(*points)
        rows.append([name, *[fmt_ms(t) for t in ys], f"{loglog_slope(xs, ys):.2f}"])
    parts += [
        f"Events per frame (counts on a fixed ≈5 % pixel pattern of {EVENT_SHAPE}, float64), median time and slope:",
        markdown_table(["transform", *[f"{v:.2g} ev/frame" for v in per_frame], "slope"], rows),
        f"Peak RSS growth during the events sweep: {result['event_rss_mb']:.0f} MB.",
        "Exact TES on one frame of 10⁷ events (int64, (1, 3, 2, 70, 75)): "
        + "; ".join(f"{k}: {fmt_ms(v)}" for k, v in result["extreme"].items())
        + f"; peak RSS growth {result['extreme_rss_mb']:.0f} MB.",
    ]
    return "\n\n".join(parts)


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "scaling")
    parser.add_argument("--min-run-time", type=float, default=None, help="seconds per point and round (default 0.1, quick 0.01)")
    parser.add_argument("--rounds", type=int, default=None, help="interleaved rounds per sweep (default 3, quick 1)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    min_run_time = args.min_run_time if args.min_run_time is not None else (0.01 if args.quick else 0.1)
    rounds = args.rounds or (1 if args.quick else 3)
    result = run(quick=args.quick, min_run_time=min_run_time, rounds=rounds)
    body = "\n\n".join(
        [
            "## Scaling: cost against B, T, H·W and events per frame" + allocator_suffix(),
            f"Base batch {BASE} float32, ≈5 % non-zero pixels; one axis varied at a time; "
            f"{rounds} interleaved rounds per sweep of `blocked_autorange` (min_run_time {min_run_time} s), median "
            f"of all blocks. Command: `{command('library/scaling.py', argv)}`.",
            "\n".join(environment_lines()),
            tables(result),
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
