"""Network verdicts under each size model: does the headline hold when the physics changes?

``physics_sensitivity.py`` scores the size transforms without a network. This benchmark
trains the protocol's network (the quick configuration: 300 steps, ConvLSTM channels (4,),
input pool 14, fixed copies, the stopping rule on hold-out grasps of the training session)
on the scenes ``paper``, ``paper-offset`` and ``paper-membrane`` rebuilt under each size
model of :data:`event_transforms.tactile.simulation.SIZE_MODELS` (both sessions), and reports
each headline verdict's paired Δ with its family-wise interval (one family per scene and
size model, as in the protocol):

- ``paper``: stretch beats the paper's zoom (``stretch`` − ``resize``, paired by seed);
- ``paper-offset``: FS-1 helps (``fs-1`` − ``none``);
- ``paper-membrane``: a time shift does not undo a lag that differs between sessions
  (``fs-1`` − ``none`` hurts).

Synthetic data; intervals cover training randomness with the data fixed. Each size model
simulates its own grasps (cached under the package cache).

Run: ``python benchmarks/tactile/size_model_network.py --threads 1`` (``--seeds 0-3`` fewer seeds,
``--models thin-layer`` one size model, ``--quick``: 2 seeds, 30 steps, smoke test).
"""

from __future__ import annotations

import dataclasses
import statistics
import tempfile
from collections.abc import Sequence
from typing import Any

from benchmarks._common import apply_threads, base_parser, command, environment_lines, markdown_table, publish

from event_transforms.tactile.cli import _seeds as parse_seeds
from event_transforms.tactile.copies import load_scene_data
from event_transforms.tactile.protocol import ProtocolConfig, run_protocol
from event_transforms.tactile.benchmark_scenes import SCENES, BenchmarkScene
from event_transforms.tactile.simulation import SIZE_MODELS
from event_transforms.tactile.stats import paired_t, significant

__all__ = ["METHODS", "VERDICTS", "variant", "run", "main"]

#: The methods trained per scene (``none`` first: the family's reference).
METHODS: dict[str, tuple[str, ...]] = {
    "paper": ("none", "resize", "stretch"),
    "paper-offset": ("none", "fs-1"),
    "paper-membrane": ("none", "fs-1"),
}
#: The headline verdicts: (scene, method, reference, what the README claims of method − reference).
VERDICTS: tuple[tuple[str, str, str, str], ...] = (
    ("paper", "stretch", "resize", "stretch beats the paper's zoom"),
    ("paper", "stretch", "none", "stretch helps"),
    ("paper", "resize", "none", "zoom shows no resolved change"),
    ("paper-offset", "fs-1", "none", "FS-1 undoes the clock offset"),
    ("paper-membrane", "fs-1", "none", "FS-1 hurts (a lag is not an offset)"),
)


def variant(scene: BenchmarkScene, model: str) -> BenchmarkScene:
    """``scene`` with both sessions simulated under the size model ``model``."""
    settings = SIZE_MODELS[model]
    return dataclasses.replace(
        scene, name=f"{scene.name}@{model}", description=f"{scene.description} [size model {model}]",
        train=scene.train.replace(**settings), deploy=scene.deploy.replace(**settings),
    )


def run(models: Sequence[str], seeds: Sequence[int], config: ProtocolConfig, *, jobs: int = 2,
        threads: int = 1, out: str | None = None) -> dict[str, Any]:
    """size model -> the protocol's ``results.json`` dict over the three scenes' variants."""
    results = {}
    for model in models:
        scenes = {f"{name}@{model}": variant(SCENES[name], model) for name in METHODS}
        data = {name: load_scene_data(scene) for name, scene in scenes.items()}
        methods = {f"{name}@{model}": METHODS[name] for name in METHODS}
        with tempfile.TemporaryDirectory() as tmp:
            results[model] = run_protocol(
                list(scenes), seeds, out or tmp, config=config, methods=methods, jobs=jobs, threads=threads,
                group="method", data=data, budget_check=False, measure_time=False, log=print,
            )
    return results


def verdict_rows(results: dict[str, Any]) -> list[list[str]]:
    """One row per size model and headline verdict: the paired Δ with its family interval."""
    rows = []
    for model, result in results.items():
        for scene, method, reference, claim in VERDICTS:
            methods = result["scenes"][f"{scene}@{model}"]["methods"]
            if reference == "none":
                delta = methods[method]["delta_vs_none"]
            else:  # a paired comparison outside the family: its own 95 % interval, Bonferroni over 1
                test = paired_t(methods[reference]["test_mse"], methods[method]["test_mse"])
                delta = {"mean": test.mean, "ci_family": list(test.ci), "n": test.n}
            lo, hi = delta["ci_family"]
            sign = "better" if hi < 0 else "worse" if lo > 0 else "not resolved"
            better = sum(b < a for a, b in zip(methods[reference]["test_mse"], methods[method]["test_mse"]))
            rows.append([model, scene, f"{method} − {reference}", claim,
                         f"{'**' if significant(delta) else ''}{delta['mean']:+.2f} [{lo:+.2f}, {hi:+.2f}]"
                         f"{'**' if significant(delta) else ''}",
                         f"{better}/{len(methods[method]['test_mse'])}", sign,
                         f"{statistics.fmean(methods['none']['test_mse']):.2f}"])
    return rows


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "size_model_network")
    parser.add_argument("--models", nargs="+", default=list(SIZE_MODELS), choices=list(SIZE_MODELS))
    parser.add_argument("--seeds", default="0-7", help="seeds, e.g. 0-7 (default) or 0,1")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = parser.parse_args(argv)
    apply_threads(args.threads or 1)  # the data simulation here; every job trains on 1 thread too
    seeds = parse_seeds("0-1" if args.quick else args.seeds)
    config = ProtocolConfig(steps=30 if args.quick else 300, hidden_channels=(4,), input_pool=14,
                            eval_every=10 if args.quick else 50, resample="bootstrap")  # as its page was made
    results = run(args.models, seeds, config, jobs=1 if args.quick else args.jobs, threads=args.threads or 1)
    body = "\n\n".join(
        [
            "## Network verdicts under each size model",
            "The quick configuration's network (300 steps, ConvLSTM (4,), input pool 14, fixed copies, "
            f"{len(seeds)} paired seeds) on `paper`, `paper-offset` and `paper-membrane` rebuilt under each size "
            "model (`SIZE_MODELS`; both sessions). Δ test MSE (N²) with the family-wise paired 95 % interval "
            "(Bonferroni over the scene's methods vs `none`; `stretch − resize` is one paired t-interval outside "
            "the family); bold: the interval excludes 0; `seeds better`: seeds where the method's MSE is lower. "
            "Synthetic data; intervals cover training randomness with the data fixed. "
            f"Command: `{command('tactile/size_model_network.py', argv)}`.",
            "\n".join(environment_lines()),
            markdown_table(["size model", "scene", "Δ", "README's claim (hertz)", "Δ [family 95 % CI]",
                            "seeds better", "verdict", "none MSE"], verdict_rows(results)),
        ]
    )
    publish(body, args)
    return results


if __name__ == "__main__":
    main()
