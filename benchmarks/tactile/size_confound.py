"""Why the non-size scenes hold the bolt size fixed: the events see force × diameter.

Under Hertz line contact the contact strip's half-width is b ∝ √(F·D), so the events of a
grasp measure the product F·D. This script fits one least-squares model of force on the
running signed event total (OFF − ON, and its square), the per-frame totals and per-frame
intercepts, on 48 training grasps of a session that mixes 12 and 18 mm bolts, and scores it
on 96 test grasps of the same session — once from the events alone, and once also told each
grasp's bolt size (the totals divided by D). The gap between the two is the ambiguity a
mixed-size scene builds into every method's error; for comparison the same model on a
one-size (15 mm) session.

Run: ``python benchmarks/tactile/size_confound.py`` (``--quick``: fewer grasps).
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from typing import Any

import torch

from benchmarks._common import apply_threads, base_parser, command, environment_lines, markdown_table, publish

from event_transforms.tactile.baselines import PhysicsLeastSquares
from event_transforms.tactile.datasets import TactileGrasps
from event_transforms.tactile.benchmark_scenes import BASE_SESSION, BenchmarkScene

__all__ = ["fit_and_score", "main"]


def fit_and_score(train: TactileGrasps, test: TactileGrasps, *, told_size: bool) -> float:
    """Test MSE (N²) of :class:`~event_transforms.tactile.baselines.PhysicsLeastSquares`
    (``size_aware=told_size``) fitted on ``train``."""
    def sizes(data: TactileGrasps) -> dict[str, torch.Tensor]:
        if not told_size:
            return {}
        return {"diameters": torch.tensor([data.meta(i)["diameter_mm"] for i in range(len(data))])}

    model = PhysicsLeastSquares(size_aware=told_size).fit(train.frames, train.forces, **sizes(train))
    prediction = model.predict(test.frames, **sizes(test))
    return float((prediction - test.forces.double()).square().mean())


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
            f"Command: `{command('tactile/size_confound.py', argv)}`.",
            "\n".join(environment_lines()),
            table,
        ]
    )
    publish(body, args)
    return rows


if __name__ == "__main__":
    main()
