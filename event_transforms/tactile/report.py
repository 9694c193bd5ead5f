"""The protocol's report: per-scene markdown tables, one-sentence findings, the whole report.

Reads the ``results.json`` dict that :func:`~event_transforms.tactile.experiment.run_protocol`
writes (per scene: baselines, and per method the per-seed values and Δ vs ``none``).
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from typing import Any

from .stats import _mean_sd, significant

__all__ = ["format_scene_table", "format_findings", "format_report"]


def _fmt_mean_sd(values: Sequence[float]) -> str:
    mean, sd = _mean_sd(values)
    return f"{mean:.2f}" if len(values) < 2 else f"{mean:.2f} ± {sd:.2f}"


def format_scene_table(name: str, summary: dict[str, Any], *, timings: bool = True, key: str = "test_mse") -> str:
    """A markdown table of one scene: baselines, then methods (MSE in N²)."""
    head = ["method", "test MSE", "Δ vs none [95 % CI]", "Holm p: t / Wilcoxon", "converged"]
    if timings:
        head += ["aug s once", "aug s/epoch", "train s"]
    rows = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    baseline_key = "test_mse_paper_split" if key.endswith("paper_split") else "test_mse"
    for base, values in summary["baselines"].items():
        cells = [f"*{base}* (baseline)", f"{values[baseline_key]:.2f}", "—", "—", "—"]
        rows.append("| " + " | ".join(cells + (["—"] * 3 if timings else [])) + " |")
    matched = set(summary["matched_methods"])
    for method, s in summary["methods"].items():
        delta = s["delta_vs_none" if key == "test_mse" else "delta_vs_none_paper_split"]
        if delta is None:
            delta_text, p_text = "—", "—"
        else:
            ci = delta["ci95"]
            mark = "**" if significant(delta) else ""
            delta_text = f"{mark}{delta['mean']:+.2f} [{ci[0]:+.2f}, {ci[1]:+.2f}]{mark}" if ci else f"{delta['mean']:+.2f}"
            p_text = (f"{delta['t_p_holm']:.3f} / {delta['p_holm']:.3f}"
                      if not math.isnan(delta["p_holm"]) else "—")
        label = f"{method} (matched)" if method in matched else method
        cells = [label, _fmt_mean_sd(s[key]), delta_text, p_text,
                 f"{sum(s['converged'])}/{len(s['converged'])}"]
        if timings:
            cells += [f"{s['aug_s_once']:.2f}", f"{s['aug_s_per_epoch']:.3f}", f"{s['train_s']:.1f}"]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def format_findings(name: str, summary: dict[str, Any]) -> list[str]:
    """One sentence per method: what it buys (Δ test MSE and its interval) and costs."""
    lines = []
    best_baseline = min(summary["baselines"].items(), key=lambda kv: kv[1]["test_mse"], default=None)
    none = summary["methods"].get("none")
    if none and best_baseline:
        mean = statistics.fmean(none["test_mse"])
        lines.append(
            f"{name}: without augmentation the network scores {mean:.2f} N² on test against "
            f"{best_baseline[1]['test_mse']:.2f} for the best trivial baseline ({best_baseline[0]}), "
            f"ratio {mean / best_baseline[1]['test_mse']:.2f}."
        )
    for method, s in summary["methods"].items():
        delta = s["delta_vs_none"]
        if delta is None or not delta.get("ci95"):
            continue
        lo, hi = delta["ci95"]
        verdict = ("buys" if hi < 0 else "costs") if significant(delta) else "shows no resolved change:"
        lines.append(
            f"{name} / {method}: {verdict} {delta['mean']:+.2f} N² test MSE (95 % CI {lo:+.2f} to {hi:+.2f}, "
            f"Holm p {delta['t_p_holm']:.3f} by the t-test, {delta['p_holm']:.3f} by Wilcoxon), for "
            f"{s['aug_s_once']:.2f} s of augmentation once and {s['train_s']:.0f} s of training per run."
        )
    return lines



def format_report(results: dict[str, Any], *, timings: bool = True) -> str:
    """Every scene's table and findings, and the paper-split tables, as markdown."""
    parts = []
    for name, summary in results["scenes"].items():
        gaps = ", ".join(summary["gaps"]) or "none (control)"
        sizes = summary["split_sizes"]
        parts.append(f"### {name}: {summary['description']}\n\ngaps: {gaps}; "
                     f"{sizes['train']} train / {sizes['val']} val / {sizes['test']} test sequences\n")
        parts.append(format_scene_table(name, summary, timings=timings))
        parts.append("")
        parts.extend(f"- {line}" for line in format_findings(name, summary))
        parts.append("")
    parts.append("### The same runs scored on the paper's 6 + 6 split (first 6 val and test sequences)\n")
    for name, summary in results["scenes"].items():
        parts.append(f"#### {name}\n")
        parts.append(format_scene_table(name, summary, timings=False, key="test_mse_paper_split"))
        parts.append("")
    return "\n".join(parts)
