"""What the protocol's bootstrap intervals cover: resamples of one data set, measured against new data sets.

With ``ProtocolConfig.resample = "bootstrap"`` each seed of a run trains and is scored on its own
bootstrap resample of one simulated data set, so the mean over seeds centres on that data set's
own value: an interval over seeds covers another resample of the same grasps, not another data
set. The simulator can draw new data sets, so this is measured here with a Δ that depends on the
data alone (no network, no training randomness): the physics least-squares model's test MSE minus
the cumulative-count ridge's on a scene (default ``paper``).

For each of ``--datasets`` independently simulated data sets (train 48, val 24, test 96 grasps,
sequence seeds offset by 100,000 per data set) the protocol's 8 bootstrap resamples
(:func:`event_transforms.tactile.resampling.split_resample`, seeds 0–7) give 8 values of Δ: their
mean and its nominal standard error (sd / √8), what an interval over the seeds of a run rests on.
Across data sets, the spread (sd) of those means is what an interval that covers new data would
have to reflect. Their ratio is the under-coverage: how many times too small the nominal standard
error is; beside it the share of the data sets whose nominal 95 % t-interval covers the mean over
all data sets.

    python -m benchmarks.tactile.resampling_coverage [--scene paper] [--datasets 16] [--quick] [--no-write]

It writes ``benchmarks/tactile/resampling_coverage.md``. The grasps are simulated into a temporary cache.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import torch

from event_transforms.tactile.baselines import evaluate_baselines, stack_items
from event_transforms.tactile.datasets import TactileGrasps
from event_transforms.tactile.resampling import split_resample
from event_transforms.tactile.stats import student_t_quantile

__all__ = ["dataset_deltas", "coverage", "main"]

ROOT = Path(__file__).resolve().parents[2]
OUTPUT = ROOT / "benchmarks" / "tactile" / "resampling_coverage.md"
#: The Δ measured: the first baseline's test MSE minus the second's.
PAIR = ("physics least-squares", "cumulative-count-ridge")
#: Sequence seeds of data set d start at d × this (the protocol's own data set is d = 0).
OFFSET = 100_000
SEEDS = tuple(range(8))


def dataset_deltas(scene: str, dataset: int, root: str, seeds: Sequence[int] = SEEDS) -> dict[str, object]:
    """Δ (``PAIR``) on data set ``dataset`` of ``scene``: on the whole data set and on each seed's
    bootstrap resample, as the protocol's baselines are scored (train, val and test resampled)."""
    splits = {split: TactileGrasps(split, root=root, scene=scene, seed=dataset * OFFSET)
              for split in ("train", "val", "test")}
    stacked = {split: stack_items(data) for split, data in splits.items()}
    full = evaluate_baselines(stacked["train"], stacked["val"], stacked["test"])
    per_seed = []
    for seed in seeds:
        picked = {}
        for split, (frames, force) in stacked.items():
            index = split_resample(splits[split], seed, split)
            picked[split] = (frames[index], force[index])
        scores = evaluate_baselines(picked["train"], picked["val"], picked["test"])
        per_seed.append(scores[PAIR[0]]["test_mse"] - scores[PAIR[1]]["test_mse"])
    return {"full": full[PAIR[0]]["test_mse"] - full[PAIR[1]]["test_mse"], "per_seed": per_seed}


def coverage(results: Sequence[dict[str, object]]) -> dict[str, float]:
    """The spread of the data sets' resample means against their nominal standard error.

    Example:
        >>> out = coverage([{"full": 0.0, "per_seed": [0.0, 0.2, 0.1, 0.1]}, {"full": 1.0, "per_seed": [1.0, 1.2, 1.1, 1.1]}])
        >>> round(out["spread_of_means"], 3), round(out["nominal_se"], 3), out["covered"]
        (0.707, 0.041, 0.0)
    """
    means = [statistics.fmean(r["per_seed"]) for r in results]  # type: ignore[arg-type]
    ses = [statistics.stdev(r["per_seed"]) / math.sqrt(len(r["per_seed"])) for r in results]  # type: ignore[arg-type]
    centre = statistics.fmean(means)
    n = len(results[0]["per_seed"])  # type: ignore[arg-type]
    q = student_t_quantile(0.975, n - 1)
    covered = statistics.fmean(1.0 if abs(m - centre) <= q * se else 0.0 for m, se in zip(means, ses))
    spread = statistics.stdev(means)
    nominal = statistics.fmean(ses)
    return {"spread_of_means": spread, "nominal_se": nominal, "ratio": spread / nominal, "covered": covered,
            "centre": centre, "spread_of_full": statistics.stdev([float(r["full"]) for r in results])}  # type: ignore[arg-type]


def run(scene: str, datasets: int) -> str:
    torch.set_num_threads(1)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as root:
        results = [dataset_deltas(scene, d, root) for d in range(datasets)]
    out = coverage(results)
    rows = ["| data set | Δ on the whole data set | mean of the 8 resamples | nominal s.e. (sd / √8) |", "|---:|---:|---:|---:|"]
    for d, r in enumerate(results):
        values = r["per_seed"]
        rows.append(f"| {d} | {r['full']:+.3f} | {statistics.fmean(values):+.3f} | "  # type: ignore[arg-type]
                    f"{statistics.stdev(values) / math.sqrt(len(values)):.3f} |")  # type: ignore[arg-type]
    return "\n".join([
        "# What the bootstrap intervals cover (resamples of one data set, against new data sets)",
        "",
        f"Written by `python -m benchmarks.tactile.resampling_coverage --scene {scene} --datasets {datasets}`. Δ = "
        f"{PAIR[0]} − {PAIR[1]} test MSE (N²) on `{scene}`, a Δ that depends on the data alone; {datasets} "
        f"independently simulated data sets (48 train, 24 val, 96 test grasps each), each scored on the protocol's "
        f"8 bootstrap resamples (seeds 0–7, train, val and test resampled as the protocol's baselines are). Synthetic "
        "data.",
        "",
        *rows,
        "",
        f"Spread (sd) of the resample means over the data sets: **{out['spread_of_means']:.3f}**; the nominal standard "
        f"error an interval over the 8 seeds uses (mean over the data sets): **{out['nominal_se']:.3f}**: "
        f"**{out['ratio']:.1f}×** too small for new data. The nominal 95 % t-interval of a data set covers the mean "
        f"over all data sets for {out['covered']:.0%} of them (sd of the whole-data-set Δ: {out['spread_of_full']:.3f}). "
        "So an interval of the protocol with `resample=\"bootstrap\"` covers training randomness and resamples of the "
        "run's one data set; it does not cover another data set of the same size. A folder of recordings is in the "
        "same position: its intervals cover resamples of its recordings, not new recordings.",
        "",
        f"Computed in {time.perf_counter() - start:.0f} s on one thread.",
    ])


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="paper", help="the scene (default %(default)s)")
    parser.add_argument("--datasets", type=int, default=16, help="independent data sets (default %(default)s)")
    parser.add_argument("--quick", action="store_true", help="3 data sets (a smoke test; writes nothing)")
    parser.add_argument("--no-write", action="store_true", help="print only; do not write the page")
    parser.add_argument("--output", type=Path, default=OUTPUT, help="the page to write (default %(default)s)")
    args = parser.parse_args(argv)
    if args.datasets < 2:
        parser.error(f"--datasets must be at least 2, got {args.datasets}")
    page = run(args.scene, 3 if args.quick else args.datasets)
    print(page)
    if not args.no_write and not args.quick:
        args.output.write_text(page + "\n")
    return page


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
