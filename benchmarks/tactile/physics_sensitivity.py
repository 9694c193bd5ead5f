"""Physics sensitivity: which size transform scores best under which size model.

The benchmark's size verdicts ("stretch, not zoom") come from the simulator's size model.
By default only the strip's half-width grows with the bolt diameter (as √D), so a stretch
across the strip by √(D₂/D₁) is the generator's exact inverse and must win. This benchmark
varies the size model (:data:`event_transforms.tactile.simulation.SIZE_MODELS`: width
exponent ½ or ⅓, strip length and contrast fixed or growing as √D) and, for each, scores
the size transforms without a network, fidelity-style
(:func:`event_transforms.tactile.fidelity.fidelity`): the physics least-squares model is
fitted on 15 mm deployment grasps; `real deployment` scores it on other 15 mm grasps; every
other column scores 12 mm or 18 mm training grasps after the transform against their own
labels. The best transform is the one nearest `real deployment`.

Assumption stated: frames are cut by a fixed 140×150 window centred on the sensor (the
benchmark's data crop), not around the true contact centre.

Run: ``python benchmarks/tactile/physics_sensitivity.py`` (``--quick``: 6 grasps per set).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch

from benchmarks._common import apply_threads, base_parser, command, environment_lines, markdown_table, publish

from event_transforms.tactile.fidelity import SIZE_METHODS, fidelity
from event_transforms.tactile.benchmark_scenes import BASE_SESSION
from event_transforms.tactile.simulation import SIZE_MODELS, simulate_grasps

__all__ = ["run", "main", "TRANSFORMS"]

#: The size transforms compared: the paper's zoom, the Hertz zoom, the stretch, nothing.
TRANSFORMS = ("none", "resize", "resize-hertz", "stretch")
_NAMES = {"none": "none", "resize": "zoom (β = D₂/D₁)", "resize-hertz": "Hertz zoom (β^½)",
          "stretch": "stretch (β^½ across)"}


def _grasps(session, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor, list[dict[str, Any]]]:
    recordings = simulate_grasps(session.grasps(n, seed=seed), session.config)
    frames = torch.stack([r.frames(crop=r.sensor_crop((140, 150)), pool=2) for r in recordings])
    forces = torch.stack([torch.from_numpy(r.force) for r in recordings])
    return frames, forces, [{"diameter_mm": r.grasp.diameter_mm} for r in recordings]


def run(quick: bool = False) -> dict[str, dict[str, dict[str, float]]]:
    """size model -> training size -> transform (or ``real deployment``) -> MSE (N²)."""
    n = 6 if quick else 24
    results: dict[str, dict[str, dict[str, float]]] = {}
    for model, settings in SIZE_MODELS.items():
        session = BASE_SESSION.replace(**settings)
        deploy = session.replace(diameters_mm=(15.0,))
        fit = _grasps(deploy, 2 * n, 50_000)
        reference = _grasps(deploy, n, 60_000)
        methods = {m: (None if m == "none" else SIZE_METHODS[m](15.0)) for m in TRANSFORMS}
        results[model] = {}
        for size in (12.0, 18.0):
            training = _grasps(session.replace(diameters_mm=(size,)), n, 0)
            results[model][f"{size:g} mm"] = fidelity(fit[:2], reference[:2], training, methods)
    return results


def best(scores: dict[str, float]) -> str:
    """The transform whose score is nearest the real deployment grasps'."""
    return min(TRANSFORMS, key=lambda m: abs(scores[m] - scores["real deployment"]))


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "physics_sensitivity")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    results = run(quick=args.quick)
    rows = []
    for model, subsets in results.items():
        settings = ", ".join(f"{k} {v:.3g}" for k, v in SIZE_MODELS[model].items())
        for subset, scores in subsets.items():
            rows.append([f"{model} ({settings})", subset, f"{scores['real deployment']:.2f}",
                         *[f"{scores[m]:.2f}" for m in TRANSFORMS], _NAMES[best(scores)]])
    body = "\n\n".join(
        [
            "## Physics sensitivity: the best size transform under each size model",
            "Fidelity without a network: the physics least-squares model is fitted on 15 mm deployment grasps of "
            "each size model; `real deployment` scores it on other 15 mm grasps, the other columns score 12 mm or "
            "18 mm training grasps after the transform against their own labels (MSE in N²; nearest `real "
            "deployment` is best). Size models (`SIZE_MODELS` in `tactile/simulation.py`): the half-width grows "
            "as D^e (e = ½ Hertz, ⅓ thin layer); `-growing`: the strip's half-length and contrast also grow as "
            "√D. Assumption: a fixed 140×150 crop centred on the sensor (no oracle crop). Synthetic data. "
            f"Command: `{command('tactile/physics_sensitivity.py', argv)}`.",
            "\n".join(environment_lines()),
            markdown_table(["size model", "training size", "real deployment", *TRANSFORMS, "best"], rows),
        ]
    )
    publish(body, args)
    return results


if __name__ == "__main__":
    main()
