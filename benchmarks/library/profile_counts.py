"""Host synchronisations and ops per call of each transform, counted with torch.profiler.

The device-free proxy for launch overhead: on the CPU, ``torch.profiler``
records every aten call, so the counts are deterministic for a given input and
parameters. *Ops* are top-level aten calls (views and metadata calls included, so an upper
bound of kernel launches); *host syncs* are ``_local_scalar_dense`` (``.item()``,
``bool(tensor)``), ``nonzero``, ``masked_select``, ``unique*`` and the library's own
marked reads of device values (``read_host``). See :func:`_common.count_ops`.

Each transform is counted twice: applied with given parameters, and with a CPU generator
(``make_params`` included). The exact temporal event shift takes one route on every
device (decided per row, for per-sample purity), so one count serves both.

Run: ``python benchmarks/library/profile_counts.py`` (``--quick`` for a small batch).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from benchmarks._common import base_parser, command, count_ops, environment_lines, markdown_table, publish, synthetic_frames

import event_transforms as et

__all__ = ["CASES", "run", "main"]

SHAPE = (32, 36, 2, 70, 75)
QUICK_SHAPE = (4, 36, 2, 70, 75)


def _bank() -> torch.Tensor:
    return synthetic_frames((144, 2, 70, 75), density=0.002, mean_count=1.0, seed=1)


# row -> (factory, goal syncs, goal ops).
CASES: dict[str, tuple[Callable[[], torch.nn.Module], int, int]] = {
    "FrameShift(-1)": (lambda: et.FrameShift(-1), 0, 15),
    "RandomFrameShift(±1, ±2)": (lambda: et.RandomFrameShift([-2, -1, 1, 2]), 0, 15),
    "HorizontalFlip": (lambda: et.HorizontalFlip(), 0, 15),
    "RandomHorizontalFlip(0.5)": (lambda: et.RandomHorizontalFlip(0.5), 0, 15),
    "RandomVerticalFlip(0.5)": (lambda: et.RandomVerticalFlip(0.5), 0, 15),
    "RandomRotation(±180°)": (lambda: et.RandomRotation(180.0), 0, 40),
    "RandomResize(15/18, 15/12)": (lambda: et.RandomResize(choices=(15 / 18, 15 / 12)), 0, 40),
    "AddNoise(static bank)": (lambda: et.AddNoise(_bank()), 0, 25),
    "AddPoissonNoise(0.1–10 Hz)": (lambda: et.AddPoissonNoise((0.1, 10.0)), 0, 30),
    "TES-2(0.5) binomial": (lambda: et.TemporalEventShift(-2, 0.5, mode="binomial"), 2, 40),
    "TES-2(0.5) exact": (lambda: et.TemporalEventShift(-2, 0.5), 8, 80),
    "OneOf[RandomResize, FrameShift(-1), TES-2(0.5)]": (
        lambda: et.OneOf([et.RandomResize(choices=(15 / 18, 15 / 12)), et.FrameShift(-1), et.TemporalEventShift(-2, 0.5)]),
        10,
        150,
    ),
    "RandomEventDrop(0.1–0.5)": (lambda: et.RandomEventDrop((0.1, 0.5)), -1, -1),
    "Compose[TES-2(0.5), RandomRotation]": (
        lambda: et.Compose([et.TemporalEventShift(-2, 0.5), et.RandomRotation(180.0)]), -1, -1
    ),
}


def _count(factory: Callable[[], torch.nn.Module], frames: torch.Tensor) -> tuple[Any, Any]:
    module = factory()
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    given = count_ops(lambda: module(frames, params=params))
    drawn = count_ops(lambda: module(frames, generator=torch.Generator().manual_seed(0)))
    return given, drawn


def _verdict(syncs: int, ops: int, goal_syncs: int, goal_ops: int) -> str:
    if goal_syncs < 0:
        return ""
    met = syncs <= goal_syncs and ops <= goal_ops
    return f"≤ {goal_syncs} / ≤ {goal_ops} {'met' if met else 'MISSED'}"


def run(shape: Sequence[int] = SHAPE) -> str:
    frames = synthetic_frames(shape)
    rows = []
    for name, (factory, goal_syncs, goal_ops) in CASES.items():
        for suffix in [""]:  # one route on every device (decided per row)
            given, drawn = _count(factory, frames)
            rows.append(
                [
                    name + suffix,
                    given.syncs,
                    given.ops,
                    drawn.syncs,
                    drawn.ops,
                    _verdict(given.syncs, given.ops, goal_syncs, goal_ops),
                ]
            )
    return markdown_table(
        ["transform", "syncs (params)", "ops (params)", "syncs (generator)", "ops (generator)", "goal syncs / ops"], rows
    )


def main(argv: Sequence[str] | None = None) -> str:
    parser = base_parser(__doc__.splitlines()[0], "profile")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads or 1)
    shape = QUICK_SHAPE if args.quick else SHAPE
    table = run(shape)
    body = "\n\n".join(
        [
            "## Profile: host syncs and ops per call (torch.profiler, CPU)",
            f"Batch {tuple(shape)} float32, ≈5 % non-zero pixels (counts 1 + Poisson(0.5)). 'params': the "
            "call given parameters drawn beforehand; 'generator': the call with a CPU `torch.Generator`, "
            "`make_params` included (its draws are CPU work, never device work). Ops are top-level aten "
            "calls, views and metadata calls included; syncs are `_local_scalar_dense`, `nonzero`, "
            "`masked_select`, `unique*` and the library's marked device reads (`read_host`). Goals are "
            "the sync-free goals and apply to the call with given parameters. The exact TES finish is chosen "
            "per device; the accelerator path is counted on the CPU by forcing that choice. No GPU was "
            f"lent for this run. Command: `{command('library/profile_counts.py', argv)}`.",
            "\n".join(environment_lines()),
            table,
        ]
    )
    publish(body, args)
    return table


if __name__ == "__main__":
    main()
