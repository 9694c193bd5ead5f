"""Command line: ``event-transforms reproduce | simulate | show | show-scene | infer-scene | train | predict | convert``.

``reproduce`` runs the benchmark protocol (:mod:`event_transforms.tactile.protocol`) on the
simulated scenes (:mod:`event_transforms.tactile.benchmark_scenes`). Without ``--full`` it runs a quick
configuration (:data:`QUICK`: 8 paired seeds; the control, ``paper``, ``paper-offset``,
``paper-membrane``, ``timing`` and ``orientation``; ``none``, the matched methods, the paper's list on ``paper``
and the policy rows ``stretch``/``inferred``/``prior``/``everything`` on gapped scenes; a
narrower model and fewer steps, with a budget check at twice the steps) that finishes in
minutes on a 2-core CPU; ``--full`` runs 10 seeds, every scene, every method that each scene
can build, and the paper-size model. Results are on synthetic data, never the paper's numbers.

``reproduce --data DIR`` runs the same protocol on a folder of your own recordings (the layout
of :mod:`event_transforms.tactile.recordings`), ``infer-scene --data DIR`` prints the gaps
inferred between its training and deployment recordings, ``train --data DIR`` saves a model
checkpoint with its preprocessing and ``predict MODEL EVENTS`` streams an event file through it;
``convert BAG --events TOPIC --force TOPIC --out DIR`` writes ROS bags in the layout;
``simulate --export DIR --scene NAME`` writes a built-in scene in that layout.

Under ``torchrun --nproc-per-node N -m event_transforms.tactile.cli reproduce ...`` the
runs are spread over the N ranks (gloo on the CPU, nccl with ``--device cuda``) and rank 0
writes the results; ``--jobs N`` starts N local ranks itself.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path


from . import commands
from .cli_data import add_convert_command, add_ingestion_options, as_flags, run_convert
from .cli_data import add_recording_options as _recording_options
from .commands import FULL, QUICK

#: ``--data`` options -> :class:`~event_transforms.tactile.recordings.RecordingSettings` (kept under its old name).
_recording_settings = commands.recording_settings


def _seeds(text: str) -> list[int]:
    """``"0"`` -> seed 0; ``"0,4,7"`` -> those seeds; ``"0-4"`` -> seeds 0 to 4."""
    try:
        seeds: list[int] = []
        for part in text.split(","):
            part = part.strip()
            if not part:
                continue
            if "-" in part[1:]:
                low, high = part.split("-", 1)
                first, last = int(low), int(high)
                if last < first:
                    raise ValueError
                seeds.extend(range(first, last + 1))
            else:
                seeds.append(int(part))
        if any(s < 0 for s in seeds):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--seeds must be seeds (e.g. 0), a list (0,4,7) or a range (0-4) of non-negative integers, got {text!r}"
        ) from None
    if len(set(seeds)) != len(seeds) or not seeds:
        raise argparse.ArgumentTypeError(f"--seeds must be distinct and non-empty, got {text!r}")
    return seeds


def _positive_number(cast: Callable[[str], float], what: str) -> Callable[[str], float]:
    """An argparse type: ``cast(text)``, finite and > 0, else one line naming the value."""

    def parse(text: str) -> float:
        try:
            value = cast(text)
        except ValueError:
            value = 0
        if not value > 0 or value == float("inf"):
            raise argparse.ArgumentTypeError(f"expected a positive {what}, got {text!r}")
        return value

    return parse


_positive = _positive_number(int, "integer")
_positive_float = _positive_number(float, "number")


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
        "Measurements' (IEEE Access 2022), benchmarked on simulated tactile scenes.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    rep = sub.add_parser(
        "reproduce",
        help="train the ConvLSTM regressor with each augmentation on every scene and tabulate test MSE",
        description="Run the benchmark protocol on the simulated scenes (paper, size-extrapolation, "
        "timing, orientation, noise, control, ...). Default: a quick configuration "
        f"({QUICK['seeds']} paired seeds, {QUICK['steps']} steps per run, the scenes {', '.join(QUICK['scenes'])}, "
        "ConvLSTM channels "
        f"{QUICK['hidden_channels']}, input pool {QUICK['input_pool']}, {QUICK['jobs']} jobs); --full: "
        f"{FULL['seeds']} seeds, {FULL['steps']} steps, channels {FULL['hidden_channels']}, input pool "
        f"{FULL['input_pool']}, every method on every scene. Every run takes the same number of "
        "optimiser steps (one-cycle lr, gradient clipping) and keeps the weights with the lowest MSE on "
        "hold-out sequences of the training session; on every gapped scene none and its pre-declared "
        "headline (its first matched method) are rerun at twice the steps (the budget check). Interrupted runs resume from the finished units under OUT/runs.",
    )
    rep.add_argument("--full", action="store_true", help="10 seeds, all methods, the paper-size model")
    rep.add_argument("--scenes", nargs="+", default=None, metavar="SCENE",
                     help="scenes by name (default: quick mode's scenes; --full: every scene)")
    rep.add_argument(
        "--methods", nargs="+", default=None, metavar="METHOD",
        help="methods by name for every scene (none rot45 resize resize-hertz noise fs-1 tes-2:0.5 "
        "independent hybrid tes-2:0.5x10 ...); default: none + each scene's matched methods",
    )
    rep.add_argument("--seeds", type=_seeds, help="seeds: 0 (one seed), 0,4,7 or 0-4")
    rep.add_argument("--out", type=Path, default=Path("results"), help="output folder (default ./results)")
    rep.add_argument("--steps", type=_positive, help="optimiser steps of every run")
    rep.add_argument("--lr", type=_positive_float, help="peak learning rate (one-cycle)")
    rep.add_argument("--hidden-channels", type=_channels, help="ConvLSTM channels per layer, e.g. 8,16")
    rep.add_argument("--input-pool", type=_positive, help="the model's first average-pool factor")
    rep.add_argument("--batch-size", type=_positive,
                     help="sequences per training step (default 8, or a folder's training windows if fewer; more "
                     "than the training items is refused before training)")
    rep.add_argument("--no-cumulative", action="store_true",
                     help="the model reads only the per-frame counts, not their running sums (ablation)")
    rep.add_argument("--copies", type=_positive, default=1,
                     help="synthetic copies per item, at least 1 (default 1: doubles the set)")
    rep.add_argument(
        "--online", action="store_true",
        help="redraw the augmentation at every access instead of making fixed copies once",
    )
    rep.add_argument("--group", choices=("scene", "method"),
                     help="one ensemble per scene and method (balances jobs) or per scene; default: per scene "
                          "with fresh data per seed (each unit is one seed's: a scene's methods keep the "
                          "ensemble large), per method on a folder of recordings")
    rep.add_argument("--jobs", type=_positive, help="worker processes (torch.distributed, gloo)")
    rep.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                     help="where to train (auto: cuda when available)")
    rep.add_argument("--root", type=Path, help="data cache folder (default: the package cache)")
    rep.add_argument(
        "--threads", type=_positive,
        help="torch CPU threads per job (default 1: the model is small, and on a shared machine "
        "more threads than free cores make every step wait for descheduled threads)",
    )
    rep.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    rep.add_argument("--quiet", action="store_true",
                     help="no progress bars or per-step and per-unit progress lines: the plan, one line per phase "
                     "and the tables only")
    rep.add_argument("--no-budget-check", action="store_true",
                     help="skip rerunning none and each gapped scene's pre-declared headline (its first matched "
                     "method) at twice the steps")
    rep.add_argument(
        "--equal-time", action=argparse.BooleanOptionalAction, default=None,
        help="also train every method for the steps its online augmentation leaves in the wall time one "
        "'none' model takes (MSE at equal wall time: a column and accuracy_at_equal_time.png; default: on in "
        "the quick configuration, off with --full; --no-equal-time skips it)",
    )
    rep.add_argument("--cost-table", type=Path, metavar="JSON", default=None,
                     help="the cost table the equal-cost step counts come from (each method's cost per training "
                     "step relative to none; default: the committed table of the quick configuration where it "
                     "covers the run, else one measured at the start of the equal-cost phase)")
    rep.add_argument("--plan", action="store_true",
                     help="print the run's units and member-steps (its cost) and exit without training")
    rep.add_argument("--data", type=Path, metavar="DIR",
                     help="a folder of your own recordings (recordings.csv; see docs/recordings.md) "
                     "instead of the simulated scenes")
    _recording_options(rep)

    sim = sub.add_parser("simulate", help="simulate every scene's data into the cache, or export one scene's grasps")
    sim.add_argument("--root", type=Path, help="cache folder (default: the package cache)")
    sim.add_argument("--export", type=Path, metavar="DIR",
                     help="write the grasps of --scene in the recording-set layout (recordings.csv, events/*.npy, "
                     "force/*.csv) to DIR")
    sim.add_argument("--scene", default="paper", help="the scene to export (default paper)")

    infer = sub.add_parser("infer-scene", help="infer the gaps between training and deployment recordings")
    infer.add_argument("--data", type=Path, metavar="DIR", required=True, help="a folder of recordings")
    _recording_options(infer)

    train = sub.add_parser("train", help="train the reference model on your recordings and save a checkpoint")
    train.add_argument("--data", type=Path, metavar="DIR", required=True, help="a folder of recordings")
    train.add_argument("--policy", default="none",
                       help="none, inferred (the policy infer-scene finds) or any method name of reproduce")
    train.add_argument("--out", type=Path, default=Path("model.pt"), help="checkpoint path (default model.pt)")
    train.add_argument("--seed", type=int, default=0, help="seed of the weights, batches and augmentation")
    train.add_argument("--steps", type=_positive, default=QUICK["steps"], help="optimiser steps")
    train.add_argument("--lr", type=_positive_float, default=QUICK["lr"], help="peak learning rate")
    train.add_argument("--batch-size", type=_positive, default=None,
                       help=f"windows per step (default {QUICK['batch_size']}, or the training windows if fewer; "
                       "more than the training windows is refused)")
    train.add_argument("--hidden-channels", type=_channels, default=QUICK["hidden_channels"],
                       help="ConvLSTM channels per layer")
    train.add_argument("--input-pool", type=_positive, default=QUICK["input_pool"], help="the model's first pool")
    train.add_argument("--threads", type=_positive, default=1, help="torch CPU threads")
    _recording_options(train)

    predict = sub.add_parser("predict", help="stream an event file through a saved model into a force CSV")
    predict.add_argument("model", type=Path, help="a checkpoint written by train")
    predict.add_argument("events", type=Path, help="an event file (.npy, .npz, .csv, .aedat4, .h5, .dat, .raw)")
    predict.add_argument("--out", type=Path, default=Path("force.csv"), help="output CSV t_us,force_n")
    predict.add_argument("--threads", type=_positive, default=1, help="torch CPU threads")
    add_ingestion_options(predict.add_argument_group(
        "reading the event file (default: what the model's training recordings used; the sensor size the file "
        "states)"))
    add_convert_command(sub)

    compare = sub.add_parser(
        "compare", help="compare the verdicts (sign, significance) of two runs' results.md, not their digits: the summary "
        "table's Δ vs none, Δ vs matched and budget check, and the scene tables' Δ at equal cost",
        description="Read the summary table of two runs (results.md of reproduce, or benchmarks/tactile/reproduce_quick.md) "
        "and print how many Δ verdicts (better / worse / unresolved, family-wise) agree and every cell that moved. "
        "Exit status 1 when a verdict is reversed (significant in both runs with opposite signs). Runs judged by "
        "different versions of the decision rules (the 'Decision rules version' line) are compared with a warning, "
        "or refused with --same-rules.",
    )
    compare.add_argument("a", type=Path, help="the first run's results.md")
    compare.add_argument("b", type=Path, help="the second run's results.md")
    compare.add_argument("--same-rules", action="store_true",
                         help="refuse (exit status 2) when the two runs name different decision-rule versions")
    show = sub.add_parser("show", help="write a before/after PNG grid of a named transform")
    show.add_argument("method", help="a method name as in reproduce, e.g. rot45, fs-1, tes-2:0.5")
    show.add_argument("--scene", default="paper", help="the scene whose training data to show (default paper)")
    show.add_argument("--out", type=Path, default=None, help="PNG path, or an existing folder to write <method>.png in (default ./<method>.png)")
    show.add_argument("--index", type=int, default=0, help="training sequence to show")
    show.add_argument("--seed", type=int, default=0, help="seed of the random draw")
    show.add_argument("--count", type=_positive, default=8, help="frames shown: those the method changes most (default 8)")
    show.add_argument("--upscale", type=_positive, default=2, help="pixel magnification (default 2)")
    show.add_argument("--root", type=Path, help="data cache folder")

    scene = sub.add_parser("show-scene", help="write a PNG of a scene's training and deployment grasps")
    scene.add_argument("scene", nargs="?", default=None, help="scene name (default: every scene)")
    scene.add_argument("--out", type=Path, default=Path("."), help="folder for scene_<name>.png (default .)")
    scene.add_argument("--count", type=_positive, default=6, help="grasps simulated per session, for the histograms (default 6)")
    scene.add_argument("--rows", type=_positive, default=2, help="grasps of each session drawn as frames (default 2)")
    scene.add_argument("--every", type=_positive, default=4, help="show every n-th frame (default 4)")
    scene.add_argument("--upscale", type=_positive, default=1, help="pixel magnification (default 1)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``event-transforms`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    handlers = {"reproduce": commands.reproduce, "simulate": commands.simulate, "show": commands.show,
                "show-scene": commands.show_scene, "infer-scene": commands.infer_scene, "train": commands.train,
                "predict": commands.predict, "compare": commands.compare,
                "convert": lambda a: run_convert(a, lambda line: print(line, flush=True))}
    try:
        if args.command in _TRAINING_COMMANDS:  # before any simulation: their progress bars need tqdm
            import tqdm  # noqa: F401
        return handlers[args.command](args)
    except KeyboardInterrupt:
        print("interrupted: finished units are kept; rerun the same command to resume",
              file=sys.stderr)
        return 130
    except ValueError as error:  # a name or setting the user gave (also from a worker): one line
        message = as_flags(" ".join(str(error).split()))  # the library's advice as this interface's flags
        print(f"{parser.prog} {args.command}: error: {message}", file=sys.stderr)
        return 2
    except ImportError as error:  # tqdm, matplotlib, torchvision: the app extra's packages
        if error.name not in _APP_PACKAGES:
            raise
        print(f"{parser.prog} {args.command}: error: {error.name} is not installed; the command line needs the "
              "app extra: pip install 'event-transforms[app]'", file=sys.stderr)
        return 2


#: Commands that show progress bars (tqdm's: the training loop, binning recordings, simulating
#: scenes); tqdm is checked before any work starts.
_TRAINING_COMMANDS = ("reproduce", "train", "simulate", "infer-scene")
#: What the `app` extra installs beyond the library (the ImportError names the command line reports).
_APP_PACKAGES = ("tqdm", "matplotlib", "torchvision")

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
