"""Share of a training epoch spent in augmentation, for each of the paper's methods.

Uses the protocol's own bookkeeping: :func:`event_transforms.tactile.protocol.run_method` trains
the reference :class:`~event_transforms.tactile.models.ForceRegressor` on the simulated grasps
(48 training sequences + synthetic copies, validation on the 15 mm bolt) and records, per
epoch, the wall time of the training pass and the time spent inside the augmentation (a
``TimedTransform`` around each method's transform, data loaded in the main process).

Two ways of making the copies:

- **on the fly** (``fixed=False``): fresh copies every epoch, drawn per sample in
  ``Dataset.__getitem__``; share = augmentation seconds / training-pass seconds per epoch.
- **fixed copies** (``fixed=True``, the paper's offline doubling): copies made once before
  training; we report that one-off cost and its size relative to one training epoch.

Only a couple of epochs per method are run (the share per epoch does not depend on how
many); the model's accuracy is not the point here. Goal: ≤ 5 % of an epoch.

Run: ``python benchmarks/training.py`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

import dataclasses
import statistics
import tempfile
from collections.abc import Sequence
from typing import Any

import torch

if __package__:
    from ._common import apply_threads, base_parser, command, environment_lines, markdown_table, publish
else:  # run as a script
    from _common import (  # type: ignore[no-redef]
        apply_threads, base_parser, command, environment_lines, markdown_table, publish,
    )

from event_transforms.tactile import protocol

__all__ = ["run", "main"]

SHARE_GOAL = 0.05


def _tiny_data() -> protocol.ProtocolData:
    """A few small random sequences standing in for the data set (smoke runs only)."""
    from torch.utils.data import Dataset

    class Items(Dataset):
        def __init__(self, n: int, diameters: Sequence[float], seed: int) -> None:
            g = torch.Generator().manual_seed(seed)
            self.frames = torch.poisson(torch.full((n, 12, 2, 16, 16), 0.3), generator=g)
            self.force = self.frames.sum((2, 3, 4)) / 50
            self.diameters = [diameters[i % len(diameters)] for i in range(n)]

        def __len__(self) -> int:
            return len(self.diameters)

        def meta(self, index: int) -> dict[str, Any]:
            return {"diameter_mm": self.diameters[index]}

        def __getitem__(self, index: int) -> tuple[Any, ...]:
            return self.frames[index], self.force[index], self.meta(index)

    bank = torch.poisson(torch.full((20, 2, 16, 16), 0.05))
    return protocol.ProtocolData(Items(4, (12.0, 18.0), 0), Items(2, (15.0,), 1), Items(2, (15.0,), 2), bank, "tiny random data")


def run(
    methods: Sequence[str] = protocol.PAPER_METHODS,
    *,
    epochs: int = 2,
    quick: bool = False,
) -> dict[str, Any]:
    data = _tiny_data() if quick else protocol.load_data()
    base = protocol.ProtocolConfig(epochs=epochs, patience=epochs)
    if quick:
        base = dataclasses.replace(base, hidden_channels=(2,), input_pool=2, batch_size=2)
    rows: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory() as directory:
        for name in methods:
            row: dict[str, Any] = {}
            for fixed in (False, True):
                config = dataclasses.replace(base, fixed=fixed)
                (result,) = protocol.run_method(name, data, config, [0], f"{directory}/{fixed}", progress=False)
                epochs_seen = result["history"]
                train_s = statistics.median(r["train_s"] for r in epochs_seen)
                aug_s = statistics.median(r["augmentation_s"] for r in epochs_seen)
                row["fixed" if fixed else "on_the_fly"] = {
                    "items": result["train_items"],
                    "train_s_per_epoch": train_s,
                    "augmentation_s_per_epoch": aug_s,
                    "augmentation_setup_s": result["augmentation_setup_s"],
                }
            rows[name] = row
    return {"methods": rows, "epochs": epochs, "data": data.description, "config": dataclasses.asdict(base)}


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
    parser.add_argument("--epochs", type=int, default=None, help="epochs per method and mode (default 2, quick 1)")
    parser.add_argument("--methods", nargs="*", default=None, help=f"protocol method names (default: {' '.join(protocol.PAPER_METHODS)})")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    methods = args.methods or (["none", "fs-1", "tes-2:0.5", "noise"] if args.quick else list(protocol.PAPER_METHODS))
    epochs = args.epochs or (1 if args.quick else 2)
    result = run(methods, epochs=epochs, quick=args.quick)
    config = result["config"]
    body = "\n\n".join(
        [
            "## Training: share of an epoch spent in augmentation",
            f"Data: {result['data']}. Reference `ForceRegressor(hidden_channels={tuple(config['hidden_channels'])}, "
            f"input_pool={config['input_pool']})`, Adam, batch {config['batch_size']}, {epochs} epoch(s) per method "
            f"and mode, seed 0, data in the main process; per-epoch times are the medians over epochs of the times "
            f"`event_transforms.tactile.protocol.run_method` records. Command: `{command('training.py', argv)}`.",
            "\n".join(environment_lines()),
            table(result),
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
