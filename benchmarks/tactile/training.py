"""Share of a training epoch spent in augmentation, for each of the paper's methods.

Uses the protocol's own bookkeeping: :func:`event_transforms.tactile.protocol.run_unit` trains
the reference :class:`~event_transforms.tactile.models.ForceRegressor` on the simulated
``paper`` scene (48 training sequences + synthetic copies) and records the training time and
the time spent inside the augmentation (a ``TimedTransform`` around each method's transform,
data loaded in the main process); an epoch is one pass over a method's training set.

Two ways of making the copies:

- **on the fly** (``fixed=False``): fresh copies every epoch, drawn per sample in
  ``Dataset.__getitem__``; share = augmentation seconds / training-pass seconds per epoch.
- **fixed copies** (``fixed=True``, the paper's offline doubling): copies made once before
  training; we report that one-off cost and its size relative to one training epoch.

Only a few optimiser steps per method are run (the share per epoch does not depend on how
many); the model's accuracy is not the point here. Goal: ≤ 5 % of an epoch.

Run: ``python benchmarks/tactile/training.py`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import torch

from benchmarks._common import apply_threads, base_parser, command, environment_lines, markdown_table, publish

from event_transforms.tactile import protocol
from event_transforms.tactile.copies import SceneData, load_scene_data
from event_transforms.tactile.methods import PAPER_METHODS

__all__ = ["run", "main"]

SHARE_GOAL = 0.05


def _tiny_data() -> SceneData:
    """A few small random sequences standing in for the data set (smoke runs only)."""
    from torch.utils.data import Dataset

    from event_transforms.tactile.benchmark_scenes import get_scene

    class Items(Dataset):
        def __init__(self, n: int, diameters: Sequence[float], seed: int) -> None:
            g = torch.Generator().manual_seed(seed)
            self.frames = torch.poisson(torch.full((n, 12, 2, 16, 16), 0.3), generator=g)
            self.force = self.frames.sum((2, 3, 4)) / 50
            self.diameters = [diameters[i % len(diameters)] for i in range(n)]

        def __len__(self) -> int:
            return len(self.diameters)

        def __getitem__(self, index: int) -> tuple[Any, ...]:
            return self.frames[index], self.force[index], {"diameter_mm": self.diameters[index]}

    bank = torch.poisson(torch.full((20, 2, 16, 16), 0.05))
    return SceneData(get_scene("paper"), Items(4, (12.0, 18.0), 0), Items(2, (15.0,), 1),
                              Items(2, (15.0,), 2), bank)


def run(
    methods: Sequence[str] = PAPER_METHODS,
    *,
    steps: int = 12,
    quick: bool = False,
) -> dict[str, Any]:
    data = _tiny_data() if quick else load_scene_data("paper")
    base = protocol.ProtocolConfig(steps=steps, eval_every=steps, hidden_channels=(8,), input_pool=10,
                                   resample="bootstrap")  # as its page was made
    if quick:
        base = dataclasses.replace(base, hidden_channels=(2,), input_pool=2, batch_size=2)
    rows: dict[str, dict[str, Any]] = {}
    for name in methods:
        row: dict[str, Any] = {}
        for fixed in (False, True):
            config = dataclasses.replace(base, fixed=fixed)
            (result,) = protocol.run_unit("paper", [name], [0], config, data, progress=False)[name]
            epoch_s = result["train_s"] * result["train_items"] / (config.steps * config.batch_size)
            row["fixed" if fixed else "on_the_fly"] = {
                "items": result["train_items"],
                "train_s_per_epoch": epoch_s,
                "augmentation_s_per_epoch": result["aug_s_per_epoch"],
                "augmentation_setup_s": result["aug_s_once"],
            }
        rows[name] = row
    description = "tiny random data" if quick else "the simulated paper scene (synthetic data)"
    return {"methods": rows, "steps": steps, "data": description, "config": dataclasses.asdict(base)}


def table(result: dict[str, Any]) -> str:
    rows = []
    worst = 0.0
    for name, row in result["methods"].items():
        fly, fixed = row["on_the_fly"], row["fixed"]
        share = fly["augmentation_s_per_epoch"] / fly["train_s_per_epoch"] if fly["train_s_per_epoch"] else 0.0
        once = fixed["augmentation_setup_s"] / fixed["train_s_per_epoch"] if fixed["train_s_per_epoch"] else 0.0
        worst = max(worst, share)
        rows.append(
            [
                name,
                str(fly["items"]),
                f"{fly['train_s_per_epoch']:.2f}",
                f"{1000 * fly['augmentation_s_per_epoch']:.1f}",
                f"{100 * share:.2f} %",
                f"{1000 * fixed['augmentation_setup_s']:.1f}",
                f"{100 * once:.2f} %",
            ]
        )
    text = markdown_table(
        [
            "method",
            "train items",
            "epoch s (on the fly)",
            "aug ms/epoch (on the fly)",
            "aug share of epoch",
            "aug ms once (fixed)",
            "once ÷ one fixed epoch",
        ],
        rows,
    )
    verdict = "met" if worst <= SHARE_GOAL else "MISSED"
    return text + f"\n\nLargest on-the-fly share: {100 * worst:.2f} % (goal ≤ {100 * SHARE_GOAL:.0f} %: {verdict})."


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "training")
    parser.add_argument("--steps", type=int, default=None, help="optimiser steps per method and mode (default 24, quick 4)")
    parser.add_argument("--methods", nargs="*", default=None, help=f"protocol method names (default: {' '.join(PAPER_METHODS)})")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    methods = args.methods or (["none", "fs-1", "tes-2:0.5", "noise"] if args.quick else list(PAPER_METHODS))
    steps = args.steps or (4 if args.quick else 24)
    result = run(methods, steps=steps, quick=args.quick)
    config = result["config"]
    body = "\n\n".join(
        [
            "## Training: share of an epoch spent in augmentation",
            f"Data: {result['data']}. Reference `ForceRegressor(hidden_channels={tuple(config['hidden_channels'])}, "
            f"input_pool={config['input_pool']}, cumulative=True)`, Adam, batch {config['batch_size']}, {steps} "
            f"optimiser steps per method and mode, seed 0, data in the main process; an epoch is one pass over the "
            f"method's training set, timed from what `event_transforms.tactile.protocol.run_unit` records. "
            f"Command: `{command('tactile/training.py', argv)}`.",
            "\n".join(environment_lines()),
            table(result),
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
