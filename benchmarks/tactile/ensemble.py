"""Cost of an optimiser step for M force regressors: one grouped-convolution ensemble vs a loop.

For each ``input_pool`` and number of members M, one training step (forward, MSE, backward,
per-member gradient clipping at 1.0, Adam) of

- **loop**: M separate ``ForceRegressor`` models, each with its own Adam, stepped one after
  another in Python (what training M seeds one by one costs per step), and
- **ensemble**: one ``EnsembleForceRegressor(M)`` (every convolution one grouped
  convolution), one Adam, ``clip_grad_norm_per_member_``,

is timed on the same batch (8 sequences per member of 36 frames of 70×75, sparse counts),
interleaved in rounds so drift on a shared machine stays out of the ratio; ratios are given in
wall time and in this thread's CPU time.
Ratio < 1 means the ensemble is faster.

Run: ``python benchmarks/tactile/ensemble.py --threads 1`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from typing import Any

import torch
import torch.nn.functional as F

from benchmarks._common import (
    apply_threads, base_parser, command, environment_lines, fmt_ms, fmt_ratio, markdown_table, publish,
    synthetic_frames,
)

from event_transforms.tactile.ensemble import EnsembleForceRegressor
from event_transforms.tactile.models import ForceRegressor
from event_transforms.tactile.training import clip_grad_norm_per_member_

__all__ = ["loop_step", "ensemble_step", "run", "main"]


def loop_step(models: Sequence[ForceRegressor], frames: torch.Tensor, force: torch.Tensor) -> Callable[[], None]:
    """One step of each of ``models`` on ``frames[m]`` ``(M, B, T, 2, H, W)``, in a Python loop."""
    optimisers = [torch.optim.Adam(m.parameters(), lr=1e-3) for m in models]

    def step() -> None:
        for m, (model, optimiser) in enumerate(zip(models, optimisers)):
            loss = F.mse_loss(model(frames[m]), force[m])
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            optimiser.step()

    return step


def ensemble_step(model: EnsembleForceRegressor, frames: torch.Tensor, force: torch.Tensor) -> Callable[[], None]:
    """One step of the whole ensemble on ``frames`` ``(M, B, T, 2, H, W)``."""
    params = list(model.parameters())
    optimiser = torch.optim.Adam(params, lr=1e-3)

    def step() -> None:
        loss = (model(frames) - force).square().mean(dim=(1, 2)).sum()
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        clip_grad_norm_per_member_(params, 1.0)
        optimiser.step()

    return step


def _time_rounds(
    cases: dict[str, Callable[[], None]], *, rounds: int, min_run_time: float, device: str
) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Per round and case, the mean wall and thread-CPU seconds per call, cases interleaved.

    On a shared CPU, other processes stretch wall time but not this thread's CPU time
    (``time.thread_time``), so the CPU-time ratio is the steadier one there; on a GPU only
    wall time means anything (the device is synchronised around each block of calls).
    """
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
    for fn in cases.values():  # warm up (allocator, lazy initialisation, Adam state)
        fn()
        fn()
    sync()
    wall: dict[str, list[float]] = {name: [] for name in cases}
    cpu: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(rounds):
        for name, fn in cases.items():
            calls, start_wall, start_cpu = 0, time.perf_counter(), time.thread_time()
            while True:
                fn()
                calls += 1
                sync()
                if time.perf_counter() - start_wall >= min_run_time:
                    break
            wall[name].append((time.perf_counter() - start_wall) / calls)
            cpu[name].append((time.thread_time() - start_cpu) / calls)
    return wall, cpu


def run(
    *,
    pools: Sequence[int] = (5, 10),
    members: Sequence[int] = (1, 5, 15),
    hidden_channels: Sequence[int] = (8,),
    batch: int = 8,
    steps: int = 36,
    size: tuple[int, int] = (70, 75),
    rounds: int = 3,
    min_run_time: float = 0.5,
    device: str = "cpu",
) -> list[dict[str, Any]]:
    rows = []
    for pool in pools:
        for count in members:
            frames = synthetic_frames((count, batch, steps, 2, *size), seed=count).to(device)
            force = (torch.rand(count, batch, steps, generator=torch.Generator().manual_seed(1)) * 20).to(device)
            models = []
            for seed in range(count):
                torch.manual_seed(seed)
                models.append(ForceRegressor(hidden_channels=hidden_channels, input_pool=pool).to(device))
            ensemble = EnsembleForceRegressor.from_models(models)
            cases = {"loop": loop_step(models, frames, force), "ensemble": ensemble_step(ensemble, frames, force)}
            wall, cpu = _time_rounds(cases, rounds=rounds, min_run_time=min_run_time, device=device)
            row = {"input_pool": pool, "members": count}
            for name, table in (("wall", wall), ("cpu", cpu)):
                row[f"loop_{name}_s"] = statistics.median(table["loop"])
                row[f"ensemble_{name}_s"] = statistics.median(table["ensemble"])
                row[f"{name}_ratio"] = statistics.median(e / loop for e, loop in zip(table["ensemble"], table["loop"]))
            rows.append(row)
            print(f"  pool {pool}, M={count}: wall ratio {row['wall_ratio']:.2f}, "
                  f"CPU-time ratio {row['cpu_ratio']:.2f}", flush=True)
    return rows


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    parser = base_parser(__doc__.splitlines()[0], "ensemble")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (default: %(default)s)")
    parser.add_argument("--device", default="cpu", help="torch device (default: %(default)s)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    if args.quick:
        args.rounds = 1
        rows = run(pools=(2,), members=(1, 2), hidden_channels=(2,), batch=2, steps=4, size=(12, 10),
                   rounds=1, min_run_time=0.01, device=args.device)
    else:
        rows = run(rounds=args.rounds, device=args.device)
    table = markdown_table(
        ["input_pool", "members M", "loop of M models / step", "ensemble / step", "ensemble / loop (wall)",
         "ensemble / loop (CPU time)"],
        [[r["input_pool"], r["members"], fmt_ms(r["loop_wall_s"]), fmt_ms(r["ensemble_wall_s"]),
          fmt_ratio(r["wall_ratio"]), fmt_ratio(r["cpu_ratio"])] for r in rows],
    )
    body = "\n".join([
        "## Ensemble training step: grouped convolutions vs a loop of models",
        "",
        *environment_lines(),
        "",
        "One optimiser step (forward, MSE, backward, gradient clipping per member, Adam) of "
        "`ForceRegressor(hidden_channels=(8,))` at batch 8 per member, T = 36, 70×75 frames: M separate "
        f"models stepped in a Python loop against one `EnsembleForceRegressor(M)` on {args.device}. "
        f"Cases interleaved in {args.rounds} rounds; times are medians over rounds of wall time per step; "
        "ratios are medians over rounds of ensemble / loop measured in the same round, in wall time and in "
        "this thread's CPU time (steadier on a shared CPU, where other processes stretch wall time). "
        f"Ratio < 1: the ensemble is faster. Command: `{command('tactile/ensemble.py', argv)}`.",
        "",
        table,
    ])
    publish(body, args)
    return rows


if __name__ == "__main__":
    main()
