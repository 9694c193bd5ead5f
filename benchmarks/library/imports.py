"""Start-up cost: importing the library and asking the command line for help.

Each command runs in a fresh interpreter (``subprocess``), interleaved with the baseline
``import torch`` so drift on a shared machine tilts neither; medians over the repeats.
Goals: importing the transforms costs at most 1.5 s more than ``import torch``, and
``event-transforms --help`` answers in at most 1.5 s (it must not import torch).

Run: ``python benchmarks/library/imports.py`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

from benchmarks._common import base_parser, command, environment_lines, markdown_table, publish

__all__ = ["COMMANDS", "run", "main"]

GOAL_S = 1.5

#: label -> Python code run with ``python -c``
COMMANDS: dict[str, str] = {
    "import torch (baseline)": "import torch",
    "import event_transforms": "import event_transforms",
    "import event_transforms; use a transform": (
        "import torch, event_transforms as et; "
        "et.RandomRotation(10.0)(torch.zeros(1, 2, 2, 8, 8)); et.Scene; et.functional"
    ),
    "import torchvision (what viz used to pull in)": "import torch, torchvision",
    "event-transforms --help": (
        "import sys; sys.argv = ['event-transforms', '--help']; "
        "from event_transforms.tactile.cli import main; main()"
    ),
}


def _seconds(code: str) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def run(repeats: int) -> dict[str, Any]:
    """Median wall seconds of each command over ``repeats`` interleaved rounds."""
    samples: dict[str, list[float]] = {label: [] for label in COMMANDS}
    for _ in range(repeats):
        for label, code in COMMANDS.items():
            samples[label].append(_seconds(code))
    medians = {label: statistics.median(values) for label, values in samples.items()}
    torch_s = medians["import torch (baseline)"]
    torch_imported = subprocess.run(
        [sys.executable, "-c", COMMANDS["event-transforms --help"] + "\nimport sys; print('torch' in sys.modules)"],
        check=False, capture_output=True, text=True,
    )
    return {
        "medians": medians,
        "extra_over_torch": medians["import event_transforms; use a transform"] - torch_s,
        "help_s": medians["event-transforms --help"],
        "help_imports_torch": "True" in torch_imported.stdout,
        "repeats": repeats,
    }


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "imports")
    parser.add_argument("--repeats", type=int, default=None, help="interleaved rounds (default 7, quick 1)")
    args = parser.parse_args(argv)
    result = run(args.repeats or (1 if args.quick else 7))
    torch_s = result["medians"]["import torch (baseline)"]
    rows = [
        [f"`{label}`", f"{seconds:.2f} s", f"{seconds - torch_s:+.2f} s"]
        for label, seconds in result["medians"].items()
    ]
    extra, help_s = result["extra_over_torch"], result["help_s"]
    verdicts = [
        f"- Transforms cost {extra:+.2f} s over `import torch` (goal ≤ +{GOAL_S} s: "
        f"{'met' if extra <= GOAL_S else 'MISSED'}).",
        f"- `event-transforms --help` answers in {help_s:.2f} s (goal ≤ {GOAL_S} s: "
        f"{'met' if help_s <= GOAL_S else 'MISSED'}); it imports torch: {result['help_imports_torch']}.",
    ]
    body = "\n\n".join(
        [
            "## Start-up: imports and `--help`",
            f"Fresh interpreter per command, {result['repeats']} interleaved rounds, medians of wall time. "
            f"Command: `{command('library/imports.py', argv)}`.",
            "\n".join(environment_lines()),
            markdown_table(["command", "median", "vs `import torch`"], rows),
            "\n".join(verdicts),
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
