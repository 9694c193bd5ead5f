"""Cost of an optimiser step for M force regressors: one grouped-convolution ensemble vs a loop.

For each ``input_pool`` and number of members M, one training step (forward, MSE, backward,
per-member gradient clipping at 1.0, Adam) of

- **loop**: M separate ``ForceRegressor`` models, each with its own Adam, stepped one after
  another in Python (what training M seeds one by one costs per step), and
- **ensemble**: one ``EnsembleForceRegressor(M)`` (every convolution one grouped
  convolution), one Adam, ``clip_grad_norm_per_member_``,

is timed on the same batch (8 sequences per member of 36 frames of 70×75, sparse counts),
interleaved in rounds so drift on a shared machine stays out of the ratio.
Ratio < 1 means the ensemble is faster.

Run: ``python benchmarks/ensemble.py --threads 1`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch
import torch.nn.functional as F

if __package__:
    from ._common import (
        apply_threads, base_parser, command, environment_lines, fmt_ms, fmt_ratio, markdown_table, publish,
        synthetic_frames, time_interleaved,
    )
else:  # run as a script
    from _common import (  # type: ignore[no-redef]
        apply_threads, base_parser, command, environment_lines, fmt_ms, fmt_ratio, markdown_table, publish,
        synthetic_frames, time_interleaved,
    )

from event_transforms.tactile.ensemble import EnsembleForceRegressor, clip_grad_norm_per_member_
from event_transforms.tactile.models import ForceRegressor

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


def run(
    *,
    pools: Sequence[int] = (5, 10),
    members: Sequence[int] = (1, 5, 15),
    hidden_channels: Sequence[int] = (8,),
    batch: int = 8,
    steps: int = 36,
    size: tuple[int, int] = (70, 75),
    rounds: int = 3,
    min_run_time: float = 0.2,
) -> list[dict[str, Any]]:
    rows = []
    for pool in pools:
        for count in members:
            frames = synthetic_frames((count, batch, steps, 2, *size), seed=count)
            force = torch.rand(count, batch, steps, generator=torch.Generator().manual_seed(1)) * 20
            models = []
            for seed in range(count):
                torch.manual_seed(seed)
                models.append(ForceRegressor(hidden_channels=hidden_channels, input_pool=pool))
            ensemble = EnsembleForceRegressor.from_models(models)
            timings, ratios = time_interleaved(
                {"loop": loop_step(models, frames, force), "ensemble": ensemble_step(ensemble, frames, force)},
                baseline="loop", rounds=rounds, min_run_time=min_run_time, progress=False,
            )
            rows.append({
                "input_pool": pool, "members": count,
                "loop_s": timings["loop"].median, "ensemble_s": timings["ensemble"].median,
                "ratio": ratios["ensemble"],
            })
            print(f"  pool {pool}, M={count}: ratio {ratios['ensemble']:.2f}", flush=True)
    return rows


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    parser = base_parser(__doc__.splitlines()[0], "ensemble")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    if args.quick:
        rows = run(pools=(2,), members=(1, 2), hidden_channels=(2,), batch=2, steps=4, size=(12, 10),
                   rounds=1, min_run_time=0.01)
    else:
        rows = run()
    table = markdown_table(
        ["input_pool", "members M", "loop of M models / step", "ensemble / step", "ensemble per member",
         "ensemble / loop"],
        [[r["input_pool"], r["members"], fmt_ms(r["loop_s"]), fmt_ms(r["ensemble_s"]),
          fmt_ms(r["ensemble_s"] / r["members"]), fmt_ratio(r["ratio"])] for r in rows],
    )
    body = "\n".join([
        "## Ensemble training step: grouped convolutions vs a loop of models",
        "",
        *environment_lines(),
        "",
        "One optimiser step (forward, MSE, backward, gradient clipping per member, Adam) of "
        "`ForceRegressor(hidden_channels=(8,))` at batch 8 per member, T = 36, 70×75 frames: M separate "
        "models stepped in a Python loop against one `EnsembleForceRegressor(M)`; median of interleaved "
        f"rounds, ratio = ensemble / loop measured in the same round. Command: `{command('ensemble.py', argv)}`.",
        "",
        table,
    ])
    publish(body, args)
    return rows


if __name__ == "__main__":
    main()
