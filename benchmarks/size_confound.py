"""Why the non-size scenes hold the bolt size fixed: the events see force × diameter.

Under Hertz line contact the contact strip's half-width is b ∝ √(F·D), so the events of a
grasp measure the product F·D. This script fits one least-squares model of force on the
running signed event total (OFF − ON, and its square), the per-frame totals and per-frame
intercepts, on 48 training grasps of a session that mixes 12 and 18 mm bolts, and scores it
on 96 test grasps of the same session — once from the events alone, and once also told each
grasp's bolt size (the totals divided by D). The gap between the two is the ambiguity a
mixed-size scene builds into every method's error; for comparison the same model on a
one-size (15 mm) session.

Run: ``python benchmarks/size_confound.py`` (``--quick``: fewer grasps).
"""

from __future__ import annotations

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

from event_transforms.tactile.datasets import TactileGrasps
from event_transforms.tactile.scenes import BASE_SESSION, BenchmarkScene

__all__ = ["features", "fit_and_score", "main"]


def features(frames: torch.Tensor, diameters: torch.Tensor | None) -> torch.Tensor:
    """Design matrix rows (one per frame): signed running total and its square (in
    thousands of events), per-frame totals, per-frame intercepts; with ``diameters`` (N,),
    also the two running-total terms divided by D / 15 mm."""
    totals = frames.double().sum((3, 4))  # (N, T, 2)
    running = totals.cumsum(1)
    signed = (running[..., 0] - running[..., 1]).unsqueeze(-1) / 1000
    n, t, _ = totals.shape
    columns = [signed, signed**2, totals / 1000]
    if diameters is not None:
        size = (diameters.double() / 15.0).view(n, 1, 1).expand(n, t, 1)
        columns += [signed**2 / size, signed / size]
    columns.append(torch.eye(t, dtype=torch.float64).expand(n, t, t))
    return torch.cat(columns, -1).reshape(n * t, -1)


def fit_and_score(train: TactileGrasps, test: TactileGrasps, *, told_size: bool) -> float:
    """Test MSE (N²) of the least-squares model fitted on ``train``."""
    def sizes(data: TactileGrasps) -> torch.Tensor | None:
        return torch.tensor([data.meta(i)["diameter_mm"] for i in range(len(data))]) if told_size else None

    x = features(train.frames, sizes(train))
    weights = torch.linalg.lstsq(x, train.forces.double().reshape(-1, 1)).solution
    prediction = (features(test.frames, sizes(test)) @ weights).squeeze(1)
    return float((prediction - test.forces.double().reshape(-1)).square().mean())


def run(quick: bool = False) -> dict[str, Any]:
    rows = {}
    with tempfile.TemporaryDirectory() as root:
        for label, sizes in (("12 + 18 mm", (12.0, 18.0)), ("15 mm only", (15.0,))):
            session = BASE_SESSION.replace(diameters_mm=sizes)
            scene = BenchmarkScene(label, label, session, session)
            train = TactileGrasps("train", root=root, scene=scene, paper_split=False)
            test = TactileGrasps("test", root=root, scene=scene, paper_split=quick)
            rows[label] = {
                "events only": fit_and_score(train, test, told_size=False),
                "events + bolt size": fit_and_score(train, test, told_size=True),
                "test sequences": len(test),
            }
    return rows


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "size_confound")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    rows = run(quick=args.quick)
    table = markdown_table(
        ["session (train and test)", "test sequences", "test MSE, events only", "test MSE, events + bolt size"],
        [[label, str(r["test sequences"]), f"{r['events only']:.2f}", f"{r['events + bolt size']:.2f}"]
         for label, r in rows.items()],
    )
    body = "\n\n".join(
        [
            "## Size confound: the events see force × diameter",
            "Least squares of force on the running signed event total (and its square), per-frame totals and "
            "per-frame intercepts, fitted on 48 simulated training grasps and scored on the test grasps of the "
            "same session (synthetic data; `BASE_SESSION` with the sizes shown). "
            f"Command: `{command('size_confound.py', argv)}`.",
            "\n".join(environment_lines()),
            table,
        ]
    )
    publish(body, args)
    return rows


if __name__ == "__main__":
    main()
