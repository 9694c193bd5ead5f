"""Command line: ``event-transforms reproduce | simulate | show``.

``reproduce`` runs the paper's protocol (:mod:`event_transforms.tactile.protocol`) on the simulated
tactile grasps. Without ``--full`` it runs a quick configuration (fewer seeds and epochs,
a narrower model) that finishes in minutes on a 2-core CPU; ``--full`` uses the paper's
10 seeds and patience 20. Results are on synthetic data, never the paper's numbers.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["main", "build_parser", "QUICK", "FULL"]

#: The quick configuration (default): stated in the output of every run.
QUICK: dict[str, Any] = {
    "seeds": 2,
    "epochs": 20,
    "patience": 5,
    "lr": 1e-2,
    "hidden_channels": (8,),
    "input_pool": 5,
    "batch_size": 4,
    "threads": 1,
}
#: The paper's configuration (``--full``).
FULL: dict[str, Any] = {
    "seeds": 10,
    "epochs": 500,
    "patience": 20,
    "lr": 1e-3,
    "hidden_channels": (8, 16),
    "input_pool": 4,
    "batch_size": 8,
    "threads": None,
}


def _seeds(text: str) -> list[int]:
    """``"3"`` -> seeds 0, 1, 2; ``"0,4,7"`` -> those seeds."""
    try:
        if "," in text:
            seeds = [int(s) for s in text.split(",") if s.strip()]
        else:
            count = int(text)
            if count < 1:
                raise ValueError
            seeds = list(range(count))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--seeds must be a count (e.g. 3) or a comma-separated list (e.g. 0,4,7), got {text!r}"
        ) from None
    if len(set(seeds)) != len(seeds) or not seeds:
        raise argparse.ArgumentTypeError(f"--seeds must be distinct and non-empty, got {text!r}")
    return seeds


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _channels(text: str) -> tuple[int, ...]:
    try:
        channels = tuple(int(c) for c in text.split(","))
    except ValueError:
        channels = ()
    if not channels or min(channels) < 1:
        raise argparse.ArgumentTypeError(
            f"--hidden-channels must be positive integers separated by commas, got {text!r}"
        )
    return channels


def build_parser() -> argparse.ArgumentParser:
    """The ``event-transforms`` argument parser (builds without importing torch)."""
    parser = argparse.ArgumentParser(
        prog="event-transforms",
        description="Event-camera augmentations from 'Event Augmentation for Contact Force "
        "Measurements' (IEEE Access 2022), with the paper's protocol on simulated grasps.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    rep = sub.add_parser(
        "reproduce",
        help="train the ConvLSTM regressor with each augmentation method and tabulate MSE",
        description="Run the paper's protocol on simulated tactile grasps. Default: a quick "
        f"configuration ({QUICK['seeds']} seeds, at most {QUICK['epochs']} epochs, patience "
        f"{QUICK['patience']}, Adam lr {QUICK['lr']:g}, ConvLSTM channels "
        f"{QUICK['hidden_channels']}); --full: {FULL['seeds']} seeds, at most {FULL['epochs']} "
        f"epochs, patience {FULL['patience']}, lr {FULL['lr']:g}, channels "
        f"{FULL['hidden_channels']}. "
        "Interrupted runs resume from the finished seeds under OUT/runs.",
    )
    rep.add_argument("--full", action="store_true", help="the paper's 10 seeds and patience 20")
    rep.add_argument(
        "--methods", nargs="+", default=None, metavar="METHOD",
        help="methods by name (none rot45 resize noise fs-1 tes-2:0.5 independent hybrid "
        "tes-2:0.5x10 ...); default: the paper's list",
    )
    rep.add_argument("--seeds", type=_seeds, help="a count (0..n-1) or a list like 0,4,7")
    rep.add_argument("--out", type=Path, default=Path("results"), help="output folder (default ./results)")
    rep.add_argument("--epochs", type=_positive, help="maximum epochs per run")
    rep.add_argument("--patience", type=_positive, help="early-stopping patience in epochs")
    rep.add_argument("--lr", type=_positive_float, help="Adam learning rate")
    rep.add_argument("--hidden-channels", type=_channels, help="ConvLSTM channels per layer, e.g. 8,16")
    rep.add_argument("--batch-size", type=_positive, help="sequences per training step")
    rep.add_argument("--copies", type=int, default=1, help="synthetic copies per item (default 1: doubles the set)")
    rep.add_argument(
        "--online", action="store_true",
        help="redraw the augmentation every epoch in the data loader instead of fixed copies",
    )
    rep.add_argument("--root", type=Path, help="data cache folder (default: the package cache)")
    rep.add_argument(
        "--threads", type=_positive,
        help="torch CPU threads (quick default 1: the model is small, and on a shared machine "
        "more threads than free cores make every step wait for descheduled threads)",
    )
    rep.add_argument("--no-plots", action="store_true", help="skip the PNG figures")

    sim = sub.add_parser("simulate", help="simulate the tactile-grasp data set into the cache")
    sim.add_argument("--root", type=Path, help="cache folder (default: the package cache)")

    show = sub.add_parser("show", help="write a before/after PNG grid of a named transform")
    show.add_argument("method", help="a method name as in reproduce, e.g. rot45, fs-1, tes-2:0.5")
    show.add_argument("--out", type=Path, default=None, help="PNG path (default ./<method>.png)")
    show.add_argument("--index", type=int, default=0, help="training sequence to show")
    show.add_argument("--seed", type=int, default=0, help="seed of the random draw")
    show.add_argument("--every", type=_positive, default=3, help="show every n-th frame (default 3)")
    show.add_argument("--upscale", type=_positive, default=2, help="pixel magnification (default 2)")
    show.add_argument("--root", type=Path, help="data cache folder")
    return parser


def _print(*args: Any) -> None:
    print(*args, flush=True)


def _reproduce(args: argparse.Namespace) -> int:
    import torch

    from .protocol import PAPER_METHODS, ProtocolConfig, format_table, load_data, run_protocol

    base = FULL if args.full else QUICK
    threads = args.threads or base["threads"]
    if threads:
        torch.set_num_threads(threads)
    seeds = args.seeds or list(range(base["seeds"]))
    config = ProtocolConfig(
        epochs=args.epochs or base["epochs"],
        patience=args.patience or base["patience"],
        batch_size=args.batch_size or base["batch_size"],
        lr=args.lr or base["lr"],
        hidden_channels=tuple(args.hidden_channels or base["hidden_channels"]),
        input_pool=base["input_pool"],
        fixed=not args.online,
        copies=args.copies,
    )
    label = "full (paper)" if args.full else "quick"
    _print(
        f"event-transforms reproduce: {label} configuration — seeds {seeds}, at most "
        f"{config.epochs} epochs, patience {config.patience}, Adam lr {config.lr:g}, "
        f"batch {config.batch_size}, "
        f"ConvLSTM channels {config.hidden_channels}, input pool {config.input_pool}, "
        f"{'on-the-fly' if args.online else 'fixed'} synthetic copies, "
        f"torch threads {torch.get_num_threads()}"
    )
    start = time.perf_counter()
    data = load_data(None if args.root is None else str(args.root))
    _print(f"data: {data.description} ({len(data.train)} train, {len(data.val)} val, "
           f"{len(data.test)} test sequences), loaded in {time.perf_counter() - start:.1f} s")
    results = run_protocol(
        args.methods or list(PAPER_METHODS), seeds, args.out, config=config, data=data, log=_print
    )
    table = format_table(results.methods)
    _print()
    _print(f"Results on synthetic data ({label} configuration; MSE in N² over all frames, "
           f"mean ± sample std over {len(seeds)} seeds; Δ = change of val MSE vs none; "
           "grasp/hold/release = test MSE of the first 5 / middle / last 5 frames):")
    _print(table)
    if not args.no_plots:
        for path in _plots(results, args.out):
            _print(f"wrote {path}")
    _print(f"wrote {args.out / 'results.json'} and {args.out / 'results.md'} "
           f"in {time.perf_counter() - start:.1f} s")
    return 0


def _plots(results: Any, out: Path) -> list[Path]:
    """MSE against training time per method, and predicted vs measured force."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        _print("matplotlib not installed (pip install 'event-transforms[plot]'): no figures")
        return []
    written = []
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, s in results.methods.items():
        x, y, err = s["train_s_total"]["mean"], s["best_val_mse"]["mean"], s["best_val_mse"]["std"]
        ax.errorbar([x], [y], yerr=[err], fmt="o", capsize=3)
        ax.annotate(name, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel("training time per run (s)")
    ax.set_ylabel("best validation MSE (N²)")
    ax.set_title("MSE against training time (synthetic data)")
    fig.tight_layout()
    path = out / "mse_vs_time.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    written.append(path)

    names = list(results.methods)
    best = min(names, key=lambda n: results.methods[n]["best_val_mse"]["mean"])
    shown = [n for n in dict.fromkeys(["none", best]) if n in results.per_seed]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), sharey=True)
    for column, ax in enumerate(axes):
        measured = None
        for name in shown:
            example = results.per_seed[name][0]["test_examples"]
            if column >= len(example["measured"]):
                continue
            measured = example["measured"][column]
            ax.plot(example["predicted"][column], label=f"predicted ({name})")
        if measured is not None:
            ax.plot(measured, "k--", label="measured")
        ax.set_title(f"test sequence {column}")
        ax.set_xlabel("frame (10 ms)")
    axes[0].set_ylabel("force (N)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    path = out / "predictions.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    written.append(path)
    return written


def _simulate(args: argparse.Namespace) -> int:
    from . import datasets

    start = time.perf_counter()
    root = None if args.root is None else str(args.root)
    sizes = {split: len(datasets.TactileGrasps(split=split, root=root)) for split in ("train", "val", "test")}
    bank = datasets.noise_bank()
    _print(f"simulated tactile grasps: {sizes}, static-scene bank {tuple(bank.shape)}, "
           f"in {time.perf_counter() - start:.1f} s (root: {root or 'package cache'})")
    return 0


def _show(args: argparse.Namespace) -> int:
    import torch

    from .. import viz
    from . import datasets
    from .protocol import parse_method

    root = None if args.root is None else str(args.root)
    train = datasets.TactileGrasps(split="train", root=root)
    if not 0 <= args.index < len(train):
        raise SystemExit(f"--index must lie in [0, {len(train) - 1}], got {args.index}")
    frames, _, meta = train[args.index]
    method = parse_method(args.method)
    bank = datasets.noise_bank() if method.needs_noise_bank else None
    transform = method.build(bank)
    generator = torch.Generator().manual_seed(args.seed)
    with torch.no_grad():  # transform the whole sequence, then show every n-th frame
        after = frames if transform is None else transform(frames, generator=generator, metadata=meta)
    shown = after[:: args.every]
    out = args.out or Path(f"{args.method.replace(':', '_')}.png")
    viz.compare_transform(frames[:: args.every], lambda _: shown, out, upscale=args.upscale)
    _print(f"wrote {out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``event-transforms`` console script."""
    args = build_parser().parse_args(argv)
    handlers = {"reproduce": _reproduce, "simulate": _simulate, "show": _show}
    try:
        return handlers[args.command](args)
    except KeyboardInterrupt:
        print("interrupted: finished seeds are kept; rerun the same command to resume",
              file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
