"""infer_scene's detection rate against gap size, over independent seed blocks.

For every point (a factor and a gap size), each seed block simulates 48 training grasps
of the base session (15 mm, 60 ms start jitter, ±10° contact angles) and 24 deployment
grasps with one setting changed, crops them with the benchmark's fixed sensor-centred
window, and runs :func:`event_transforms.infer_scene` on the frames (no labels). The table
gives how often the changed factor's gap was declared, how often any *other* factor's was
(a false gap), and the median resolvable limit (``z_gap`` standard errors) of the changed
factor. Blocks share seeds across points (common random numbers), so the points differ
only in the changed setting. The ``none`` point measures false gaps.

The ``labelled k/side`` columns run the timing test again from the lags of the first k
grasps of each side measured against their force labels (:mod:`event_transforms.tactile.lags`).

Run: ``python benchmarks/tactile/detection_rate.py`` (20 blocks; ``--quick``: 2 blocks of 12 + 6).
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from typing import Any

import torch

from benchmarks._common import apply_threads, base_parser, command, environment_lines, markdown_table, publish

from event_transforms.inference import infer_scene
from event_transforms.tactile.lags import infer_scene_with_lags
from event_transforms.tactile.benchmark_scenes import BASE_SESSION
from event_transforms.tactile.simulation import simulate_grasps

__all__ = ["POINTS", "run", "main"]

_BASE = BASE_SESSION.config
#: point -> (factor, gap size in words, deployment settings).
POINTS: dict[str, tuple[str | None, str, dict[str, Any]]] = {
    "none": (None, "no change", {}),
    "timing 10 ms": ("timing", "delay +10 ms (one frame)", {"delay_ms": (10.0, 14.0)}),
    "timing 20 ms": ("timing", "delay +20 ms (two frames)", {"delay_ms": (20.0, 24.0)}),
    "angle ±20°": ("orientation", "±10° → ±20°", {"angle_deg": (-20.0, 20.0)}),
    "angle ±30°": ("orientation", "±10° → ±30°", {"angle_deg": (-30.0, 30.0)}),
    "background 3×": ("noise", "shot-noise rates 3×",
                      {"shot_noise_hz": tuple(3 * v for v in _BASE.shot_noise_hz)}),
    "hot pixels 10×": ("noise", "hot-pixel fraction 10×", {"hot_pixel_fraction": 10 * _BASE.hot_pixel_fraction}),
}
_FACTORS = ("timing", "orientation", "noise")


#: Labelled recordings per side for the timing test from lags (the first k of each side's grasps).
LABELLED = (2, 8, 24)


def _frames(session, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    recordings = simulate_grasps(session.grasps(n, seed=seed), session.config)
    frames = torch.stack([r.frames(crop=r.sensor_crop((140, 150)), pool=2) for r in recordings])
    return frames, torch.stack([torch.as_tensor(r.force, dtype=torch.float32) for r in recordings])


def run(blocks: int = 20, n_train: int = 48, n_deploy: int = 24) -> dict[str, dict[str, Any]]:
    """point -> {"detected": k, "false": k, "blocks": n, "limit": [per block], "shifts": [...]}."""
    out = {name: {"detected": 0, "false": 0, "blocks": 0, "limit": [], "shifts": [],
                  "labelled": {k: [] for k in LABELLED}} for name in POINTS}
    train_session = BASE_SESSION
    for block in range(blocks):
        train, train_force = _frames(train_session, n_train, 100_000 + 1_000 * block)
        for name, (factor, _, settings) in POINTS.items():
            deploy, deploy_force = _frames(train_session.replace(**settings), n_deploy, 500_000 + 1_000 * block)
            if factor in (None, "timing"):  # the timing test from k labelled recordings a side
                for k in LABELLED:
                    if k <= min(n_train, n_deploy):
                        labelled = infer_scene_with_lags(train, deploy, frame_ms=train_session.config.frame_ms,
                                                         labelled_train=(train[:k], train_force[:k]),
                                                         labelled_deploy=(deploy[:k], deploy_force[:k]))
                        out[name]["labelled"][k].append(
                            (labelled.lag_shifts[0] if labelled.lag_shifts else 0, "timing" in labelled.gaps))
            scene = infer_scene(train, deploy, frame_ms=train_session.config.frame_ms)
            evidence = scene.evidence
            record = out[name]
            record["blocks"] += 1
            gaps = {f for f in _FACTORS if evidence[f]["gap"]}
            if factor is not None:
                record["detected"] += factor in gaps
                record["limit"].append(evidence[factor]["resolvable_limit"])
            record["false"] += bool(gaps - {factor})
            if scene.lag_shifts:
                record["shifts"].append(scene.lag_shifts[0])
    return out


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "detection_rate")
    parser.add_argument("--blocks", type=int, default=20, help="seed blocks per point (default 20)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    blocks, n_train, n_deploy = (2, 12, 6) if args.quick else (args.blocks, 48, 24)
    results = run(blocks, n_train, n_deploy)
    rows = []
    for name, record in results.items():
        factor, words, _ = POINTS[name]
        limit = f"{statistics.median(record['limit']):.3g}" if record["limit"] else "—"
        shifts = (", ".join(f"{s:+d}×{record['shifts'].count(s)}" for s in sorted(set(record["shifts"])))
                  if record["shifts"] else "—")
        labelled = []
        for k in LABELLED:
            found = record["labelled"][k]
            labelled.append("—" if not found else
                            f"{sum(g for _, g in found)}/{len(found)} gap; "
                            + ", ".join(f"{s:+d}×{[x for x, _ in found].count(s)}" for s in sorted({x for x, _ in found})))
        rows.append([name, words, factor or "—",
                     f"{record['detected']}/{record['blocks']}" if factor else "—",
                     f"{record['false']}/{record['blocks']}", limit, shifts, *labelled])
    body = "\n\n".join(
        [
            "## infer_scene detection rate against gap size",
            f"{blocks} independent seed blocks per point; each block: {n_train} training grasps of the base session "
            f"(15 mm, 60 ms start jitter, ±10°) and {n_deploy} deployment grasps with one setting changed, fixed "
            "sensor-centred crop, `infer_scene` on the frames only (z_gap 3). `detected`: blocks declaring the changed "
            "factor's gap; `false gaps`: blocks declaring any other factor's; `limit`: median resolvable difference "
            "of the changed factor (3 standard errors: ms for timing, degrees of |angle| for orientation, log "
            "background rate for noise); `shift`: the frame shifts the inferred policies chose; `labelled k/side` (timing "
            "points and `none`): the timing test from the lags of the first k grasps a side against their force "
            "labels: blocks declaring a timing gap, and the shifts chosen (0: none). Synthetic data. "
            f"Command: `{command('tactile/detection_rate.py', argv)}`.",
            "\n".join(environment_lines()),
            markdown_table(["point", "gap", "factor", "detected", "false gaps", "limit", "shift",
                            *(f"labelled {k}/side" for k in LABELLED)], rows),
        ]
    )
    publish(body, args)
    return results


if __name__ == "__main__":
    main()
