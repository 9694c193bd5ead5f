"""Fidelity of the size and time-shift augmentations, measured without a network.

For each scene: fit the physics least-squares model (running signed OFF − ON total and its
square, per-frame totals, per-frame intercepts) on the deployment's 96 test grasps, then
score (a) the deployment's 24 validation grasps (the reference: real deployment data the
model was not fitted on), (b) the training grasps untransformed, and (c) the training
grasps after each augmentation, against their own unchanged labels. A faithful
augmentation scores near (a). Size methods on the size scenes, split by training bolt;
time shifts on ``paper-offset`` (a clock offset) and ``paper-membrane`` (a colder membrane's
lag), after the stretch too, since those scenes also have the size gap. See :mod:`event_transforms.tactile.fidelity`.

Run: ``python benchmarks/tactile/fidelity.py`` (``--quick``: the paper's 6 + 6 evaluation split).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from benchmarks._common import apply_threads, base_parser, command, environment_lines, markdown_table, publish

import event_transforms as et
from event_transforms.tactile.datasets import TactileGrasps
from event_transforms.tactile.fidelity import SIZE_METHODS, TIME_METHODS, fidelity
from event_transforms.tactile.benchmark_scenes import get_scene

__all__ = ["run", "main"]

SIZE_SCENES = ("paper", "size-extrapolation")


def _split(scene: str, root: str | None, quick: bool) -> dict[str, Any]:
    train = TactileGrasps("train", root=root, scene=scene)
    val = TactileGrasps("val", root=root, scene=scene, paper_split=quick)
    test = TactileGrasps("test", root=root, scene=scene, paper_split=quick)
    metadata = [train.meta(i) for i in range(len(train))]
    return {"train": (train.frames, train.forces, metadata), "val": (val.frames, val.forces), "test": (test.frames, test.forces)}


def _subset(training: tuple, size: float) -> tuple:
    frames, forces, metadata = training
    keep = [i for i, m in enumerate(metadata) if m["diameter_mm"] == size]
    return frames[keep], forces[keep], [metadata[i] for i in keep]


def run(quick: bool = False, root: str | None = None) -> dict[str, dict[str, dict[str, float]]]:
    """scene -> training subset -> method -> MSE (N²)."""
    results: dict[str, dict[str, dict[str, float]]] = {}
    for name in SIZE_SCENES:
        scene = get_scene(name)
        data = _split(name, root, quick)
        target = scene.target_size
        methods = {"none": None, **{m: build(target) for m, build in SIZE_METHODS.items()}}
        results[name] = {
            f"{size:g} mm": fidelity(data["test"], data["val"], _subset(data["train"], size), methods)
            for size in scene.train.diameters_mm
        }
    for name in ("paper-offset", "paper-membrane"):
        scene = get_scene(name)
        data = _split(name, root, quick)
        stretch = SIZE_METHODS["stretch"](scene.target_size)
        methods: dict[str, Any] = {"none": None, "stretch": stretch}
        for m in scene.matched_methods:
            methods[m] = TIME_METHODS[m]()
            methods[f"{m} + stretch"] = et.Compose([TIME_METHODS[m](), SIZE_METHODS["stretch"](scene.target_size)])
        results[name] = {"12 + 18 mm": fidelity(data["test"], data["val"], data["train"], methods)}
    return results


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "fidelity")
    parser.add_argument("--root", default=None, help="data-set cache directory (default: the package's)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    results = run(quick=args.quick, root=args.root)
    tables = []
    for scene, subsets in results.items():
        methods = list(next(iter(subsets.values())))
        rows = [[subset] + [f"{scores[m]:.2f}" for m in methods] for subset, scores in subsets.items()]
        tables.append(f"**{scene}** (MSE in N², model fitted on the deployment's test grasps)\n\n"
                      + markdown_table(["training grasps", *methods], rows))
    body = "\n\n".join(
        [
            "## Fidelity: augmented training grasps scored by a physics model of deployment",
            "The physics least-squares model (running signed OFF − ON total and its square, per-frame totals, "
            "per-frame intercepts) is fitted on the deployment's test grasps; `real deployment` scores it on the "
            "deployment's validation grasps, every other column on the training grasps (after the method) against "
            "their own labels. A faithful simulation of the gap scores near `real deployment` (synthetic data). "
            f"Command: `{command('tactile/fidelity.py', argv)}`.",
            "\n".join(environment_lines()),
            *tables,
        ]
    )
    publish(body, args)
    return results


if __name__ == "__main__":
    main()
