"""Accuracy against cost: each protocol method's MSE next to its time, and TES's three modes.

Part 1 reads a protocol ``results.json`` (written by ``event-transforms reproduce``) and
places every method of one scene (``paper`` by default) by its test MSE (mean ± sd over seeds) against its total
time cost (training + augmentation, mean over seeds, seconds); the methods on the Pareto
front (no other method is both more accurate and cheaper) are marked. With matplotlib
installed, the same is drawn to a PNG.

Part 2 compares the modes of temporal event shifting on the simulated training grasps:
how far the number of moved events ΣZ of each frame and polarity lands from ζ·N (exact:
k = round(ζN) by construction; binomial: only in expectation; expected: ζ·X moved as
fractions), the time per batch, and, where ``results.json`` holds methods trained with a
given mode (a name containing ``binomial`` or ``expected``), their MSE.

ΣZ is measured through the public module: with a shift of T frames every moved event
leaves the sequence, so ``frames - output`` is Z itself.

Run: ``python benchmarks/tactile/accuracy.py RESULTS_JSON [--png PATH]`` (``--quick`` for a smoke
run of part 2 on fewer sequences).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from benchmarks._common import (
    apply_threads, base_parser, command, environment_lines, fmt_ms, markdown_table,
    synthetic_frames, time_call, publish,
)

import event_transforms as et

__all__ = ["load_methods", "pareto_front", "method_table", "plot", "tes_modes", "main"]

MODES = ("exact", "binomial", "expected")


def load_methods(path: str | Path, scene: str | None = None) -> list[dict[str, Any]]:
    """One row per method of one scene of a protocol ``results.json``: test MSE (mean, sd) and costs.

    ``scene`` defaults to ``paper`` when present, else the first scene.
    """
    data = json.loads(Path(path).read_text())
    if "scenes" not in data or not data["scenes"]:
        raise ValueError(f"{path}: not a protocol results.json (no 'scenes' key); keys: {sorted(data)}")
    name = scene or ("paper" if "paper" in data["scenes"] else next(iter(data["scenes"])))
    if name not in data["scenes"]:
        raise ValueError(f"scene {name!r} is not in {path}; it holds {sorted(data['scenes'])}")
    rows = []
    for method, s in data["scenes"][name]["methods"].items():
        values = s["test_mse"]
        mean = sum(values) / len(values)
        std = (sum((v - mean) ** 2 for v in values) / (len(values) - 1)) ** 0.5 if len(values) > 1 else 0.0
        val = s["val_mse"]
        rows.append(
            {
                "method": method,
                "copies": s.get("copies"),
                "val_mean": sum(val) / len(val),
                "test_mean": mean,
                "test_std": std,
                "time_s": s["train_s"] + s["aug_s_once"],
                "aug_once_s": s["aug_s_once"],
                "aug_epoch_s": s["aug_s_per_epoch"],
                "seeds": len(s.get("seeds", [])),
            }
        )
    return rows


def pareto_front(rows: Sequence[dict[str, Any]], x: str = "time_s", y: str = "test_mean") -> set[str]:
    """Names of the rows not dominated (another row ≤ in both and < in one) on (x, y), both minimised."""
    front = set()
    for r in rows:
        dominated = any(
            o[x] <= r[x] and o[y] <= r[y] and (o[x] < r[x] or o[y] < r[y]) for o in rows if o is not r
        )
        if not dominated:
            front.add(r["method"])
    return front


def method_table(rows: Sequence[dict[str, Any]]) -> str:
    front = pareto_front(rows)
    body = [
        [
            r["method"],
            str(r["copies"]),
            f"{r['test_mean']:.2f} ± {r['test_std']:.2f}",
            f"{r['test_mean']:.2f} ± {r['test_std']:.2f}",
            f"{r['time_s']:.1f}",
            f"{1000 * r['aug_once_s']:.0f}",
            f"{1000 * r['aug_epoch_s']:.1f}",
            "yes" if r["method"] in front else "",
        ]
        for r in sorted(rows, key=lambda r: r["time_s"])
    ]
    return markdown_table(
        ["method", "copies", "val MSE (N²)", "test MSE (N²)", "total time s", "aug ms once", "aug ms/epoch", "Pareto"],
        body,
    )


def plot(rows: Sequence[dict[str, Any]], path: str | Path) -> Path | None:
    """MSE (mean ± std) against total time, Pareto front joined; ``None`` without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    front = pareto_front(rows)
    fig, ax = plt.subplots(figsize=(6.5, 4.5), dpi=120)
    for r in rows:
        on = r["method"] in front
        ax.errorbar(r["time_s"], r["test_mean"], yerr=r["test_std"], fmt="o", capsize=3,
                    color="tab:red" if on else "tab:gray")
        ax.annotate(r["method"], (r["time_s"], r["test_mean"]), textcoords="offset points", xytext=(5, 4), fontsize=8)
    line = sorted((r for r in rows if r["method"] in front), key=lambda r: r["time_s"])
    ax.step([r["time_s"] for r in line], [r["test_mean"] for r in line], where="post", color="tab:red",
            linewidth=1, label="Pareto front")
    times = [r["time_s"] for r in rows if r["time_s"] > 0]
    if times and max(times) > 10 * min(times):
        ax.set_xscale("log")
        from matplotlib.ticker import FormatStrFormatter

        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(FormatStrFormatter("%g"))
    ax.set_xlabel("total time per training run (s)")
    ax.set_ylabel("test MSE (N²), mean ± sd over seeds")
    ax.set_title("Augmentation methods: accuracy against cost (synthetic data)")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def _frames(count: int | None) -> tuple[torch.Tensor, str]:
    """Training grasps as float32 frames (B, 36, 2, 70, 75), or synthetic ones if unavailable."""
    try:
        from event_transforms.tactile.datasets import TactileGrasps

        data = TactileGrasps(split="train")
        frames = data.frames if isinstance(data.frames, torch.Tensor) else data.frames()
        frames = frames if count is None else frames[:count]
        return frames.to(torch.float32), f"{frames.shape[0]} simulated training grasps (TactileGrasps train)"
    except Exception as error:  # noqa: BLE001 - fall back to synthetic frames, and say so
        frames = synthetic_frames((count or 48, 36, 2, 70, 75))
        return frames, f"synthetic frames (TactileGrasps unavailable: {type(error).__name__})"


def tes_modes(
    fraction: float = 0.5, shift: int = -2, *, count: int | None = None, min_run_time: float = 0.5, seed: int = 0
) -> dict[str, Any]:
    """ΣZ against ζN per frame and polarity, and time per batch, for each TES mode."""
    frames, source = _frames(count)
    t = frames.shape[1]
    n = frames.double().sum(dim=(-2, -1))  # (B, T, 2) events per frame and polarity
    target = fraction * n
    out: dict[str, Any] = {"source": source, "shape": tuple(frames.shape), "fraction": fraction, "shift": shift}
    for mode in MODES:
        drop_all = et.TemporalEventShift(t, fraction, mode=mode)  # every moved event leaves
        moved = (frames.double() - drop_all(frames, generator=torch.Generator().manual_seed(seed)).double()).sum(dim=(-2, -1))
        error = (moved - target)[n > 0]
        relative = (error.abs() / n[n > 0])
        module = et.TemporalEventShift(shift, fraction, mode=mode)
        timing = time_call(lambda m=module: m(frames), min_run_time=min_run_time)
        out[mode] = {
            "mean_abs_error": float(error.abs().mean()) if error.numel() else 0.0,
            "max_abs_error": float(error.abs().max()) if error.numel() else 0.0,
            "mean_relative_error": float(relative.mean()) if relative.numel() else 0.0,
            "total_error": float(error.sum()) if error.numel() else 0.0,
            "time_s": timing.median,
            "time_iqr_s": timing.iqr,
        }
    out["events_per_frame"] = float(n.sum(-1).mean())
    return out


def tes_table(modes: dict[str, Any], rows: Sequence[dict[str, Any]] | None) -> str:
    mse = {}
    for r in rows or []:
        for mode in MODES:
            if r["method"].startswith("tes") and (mode in r["method"] or (mode == "exact" and not any(m in r["method"] for m in MODES[1:]))):
                mse.setdefault(mode, []).append(f"{r['method']}: {r['test_mean']:.2f} ± {r['test_std']:.2f}")
    body = []
    for mode in MODES:
        m = modes[mode]
        body.append(
            [
                mode,
                f"{m['mean_abs_error']:.3f}",
                f"{m['max_abs_error']:.2f}",
                f"{100 * m['mean_relative_error']:.2f} %",
                f"{m['total_error']:+.1f}",
                f"{fmt_ms(m['time_s'])} (IQR {fmt_ms(m['time_iqr_s'])})",
                "; ".join(mse.get(mode, [])) or "not in results.json",
            ]
        )
    return markdown_table(
        ["TES mode", "mean abs(ΣZ − ζN)", "max abs(ΣZ − ζN)", "mean abs(ΣZ − ζN) / N", "Σ(ΣZ − ζN)", "time per batch", "val MSE"],
        body,
    )


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "accuracy")
    parser.add_argument("results_json", nargs="?", default=None, help="protocol results.json (part 1 skipped without it)")
    parser.add_argument("--png", default=None, help="figure path (default: accuracy.png next to the results file)")
    parser.add_argument("--fraction", type=float, default=0.5, help="ζ for part 2 (default 0.5)")
    parser.add_argument("--shift", type=int, default=-2, help="j for part 2's timing (default -2)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    rows = load_methods(args.results_json) if args.results_json else None
    parts = ["## Accuracy against cost"]
    parts.append(f"Command: `{command('tactile/accuracy.py', argv)}`.")
    parts.append("\n".join(environment_lines()))
    figure = None
    if rows is not None:
        parts.append(
            f"From `{args.results_json}` ({rows[0]['seeds'] if rows else 0} seeds; synthetic data, not the paper's). "
            "MSE is the test MSE of the final weights; total time is training plus augmentation per run; "
            "'Pareto' marks methods no other method beats on both."
        )
        parts.append(method_table(rows))
        png = Path(args.png) if args.png else Path(args.results).with_name("accuracy.png")
        figure = plot(rows, png)
        parts.append(f"Figure: `{figure}`." if figure else "Figure: skipped (matplotlib is not installed; `pip install event-transforms[plot]`).")
    else:
        parts.append("Part 1 skipped: no results.json given.")
    modes = tes_modes(args.fraction, args.shift, count=4 if args.quick else None, min_run_time=0.05 if args.quick else 0.5)
    parts.append(
        f"TES modes, ζ = {args.fraction}, on {modes['source']} {modes['shape']} "
        f"(≈{modes['events_per_frame']:.0f} events per frame); errors over frames and polarities with N > 0; "
        f"time for shift {args.shift} (median, `blocked_autorange`)."
    )
    parts.append(tes_table(modes, rows))
    body = "\n\n".join(parts)
    publish(body, args)
    return {"methods": rows, "tes": modes, "figure": figure}


if __name__ == "__main__":
    main()
