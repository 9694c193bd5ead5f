"""Latency of the reference model on a stream: ``ForceRegressor.step`` per 10 ms frame.

One CPU thread (``torch.set_num_threads(1)``), batch of one, under
``torch.inference_mode()``. Frames come from simulated grasps (36 frames of
(2, 70, 75) each); the state is reset at the start of every grasp. Each ``step`` call is
timed on its own with ``time.perf_counter_ns`` (we need the tail, not a mean), after a
warm-up grasp. The full-sequence ``forward`` of one grasp is timed with
``torch.utils.benchmark`` for comparison (per frame = time / 36). Goal: p99 ≤ 2 ms per
frame, i.e. a 10 ms frame is processed well within its own duration.

Run: ``python benchmarks/tactile/streaming.py`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Sequence
from typing import Any

import torch

from benchmarks._common import base_parser, command, environment_lines, fmt_ms, markdown_table, time_call, publish

from event_transforms.tactile.models import ForceRegressor
from event_transforms.tactile.simulation import SimulatorConfig, draw_grasp, simulate_grasps

__all__ = ["grasp_frames", "step_latencies", "run", "main"]

P99_GOAL_S = 2e-3


def grasp_frames(count: int, seed: int = 100) -> torch.Tensor:
    """``count`` simulated grasps as frames (count, 36, 2, 70, 75), cropped and pooled as in the paper."""
    config = SimulatorConfig()
    grasps = [draw_grasp((12.0, 15.0, 18.0)[i % 3], seed=seed + i, config=config) for i in range(count)]
    recordings = simulate_grasps(grasps, config)
    return torch.stack([r.frames(crop=r.contact_crop(), pool=2) for r in recordings])


def _percentile(values: Sequence[float], q: float) -> float:
    ordered = sorted(values)
    index = min(len(ordered) - 1, max(0, round(q / 100 * (len(ordered) - 1))))
    return ordered[index]


def step_latencies(model: ForceRegressor, sequences: torch.Tensor, repeats: int = 1) -> list[float]:
    """Seconds of every ``model.step`` call over ``sequences`` (N, T, 2, H, W), state reset per sequence."""
    times: list[float] = []
    with torch.inference_mode():
        for _ in range(repeats):
            for sequence in sequences:
                state = None
                for frame in sequence:
                    frame = frame.unsqueeze(0)
                    start = time.perf_counter_ns()
                    _, state = model.step(frame, state)
                    times.append((time.perf_counter_ns() - start) * 1e-9)
    return times


def run(*, sequences: int = 12, repeats: int = 5, min_run_time: float = 1.0) -> dict[str, Any]:
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        torch.manual_seed(0)
        model = ForceRegressor().eval()
        frames = grasp_frames(sequences)
        step_latencies(model, frames[:1])  # warm up
        steps = step_latencies(model, frames, repeats)
        with torch.inference_mode():
            one = frames[:1]
            full = time_call(lambda: model(one), min_run_time=min_run_time)
    finally:
        torch.set_num_threads(previous)
    t = frames.shape[1]
    return {
        "frames_timed": len(steps),
        "median": statistics.median(steps),
        "p90": _percentile(steps, 90),
        "p99": _percentile(steps, 99),
        "max": max(steps),
        "full_sequence": full.median,
        "full_sequence_iqr": full.iqr,
        "full_per_frame": full.median / t,
        "frame_shape": tuple(frames.shape[2:]),
        "model": repr(model).splitlines()[0] + " (default settings)",
        "parameters": sum(p.numel() for p in model.parameters()),
    }


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "streaming")
    parser.add_argument("--sequences", type=int, default=None, help="simulated grasps (default 12, quick 2)")
    parser.add_argument("--repeats", type=int, default=None, help="passes over them (default 5, quick 1)")
    args = parser.parse_args(argv)
    sequences = args.sequences or (2 if args.quick else 12)
    repeats = args.repeats or (1 if args.quick else 5)
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        result = run(sequences=sequences, repeats=repeats, min_run_time=0.05 if args.quick else 1.0)
        environment = "\n".join(environment_lines())
    finally:
        torch.set_num_threads(previous)
    verdict = "met" if result["p99"] <= P99_GOAL_S else "MISSED"
    rows = [
        ["`step`, one 10 ms frame (median)", fmt_ms(result["median"])],
        ["`step` p90", fmt_ms(result["p90"])],
        ["`step` p99", f"{fmt_ms(result['p99'])} (goal ≤ 2 ms: {verdict})"],
        ["`step` max", fmt_ms(result["max"])],
        ["`forward`, whole 36-frame grasp (median)", f"{fmt_ms(result['full_sequence'])} (IQR {fmt_ms(result['full_sequence_iqr'])})"],
        ["`forward` per frame", fmt_ms(result["full_per_frame"])],
    ]
    body = "\n\n".join(
        [
            "## Streaming: `ForceRegressor.step` latency per frame",
            f"Default `ForceRegressor()` ({result['parameters']:,} parameters), batch 1, frames "
            f"{result['frame_shape']}, one thread, `torch.inference_mode()`; {result['frames_timed']} `step` calls "
            f"timed one by one (`perf_counter_ns`). Command: `{command('tactile/streaming.py', argv)}`.",
            environment,
            markdown_table(["measure", "time"], rows),
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
