"""The protocol's report: per-scene markdown tables, one-sentence findings, the whole report.

Reads the ``results.json`` dict that :func:`~event_transforms.tactile.experiment.run_protocol`
writes (per scene: baselines, and per method the per-seed values and Δ vs ``none``).
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from typing import Any

from .stats import mean_sd, significant

__all__ = ["format_summary_table", "format_scene_table", "format_budget_check", "format_findings", "format_report"]

#: The columns of the summary table (the README's table), in order.
SUMMARY_COLUMNS = ("scene", "method", "test MSE", "Δ vs none [95 % CI]", "unpaired CI", "r",
                   "Holm p: t / Wilcoxon", "budget check")


def _format_mean_sd(values: Sequence[float]) -> str:
    mean, sd = mean_sd(values)
    return f"{mean:.2f}" if len(values) < 2 else f"{mean:.2f} ± {sd:.2f}"


def format_scene_table(name: str, summary: dict[str, Any], *, timings: bool = True, key: str = "test_mse") -> str:
    """A markdown table of one scene: baselines, then methods (MSE in N²).

    Columns: test MSE (mean ± sd over seeds); Δ vs none with its paired 95 % interval (bold
    where significant after Holm); the unpaired (Welch) interval of the same Δ and the
    correlation r of ``none``'s and the method's per-seed MSEs (what the pairing bought);
    Holm-corrected p-values; the median step whose weights the stopping rule kept.
    """
    head = ["method", "test MSE", "Δ vs none [95 % CI]", "unpaired CI", "r", "Holm p: t / Wilcoxon", "kept step"]
    if timings:
        head += ["aug s once", "aug s/epoch", "train s"]
    rows = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    baseline_key = "test_mse_paper_split" if key.endswith("paper_split") else "test_mse"
    for base, values in summary["baselines"].items():
        cells = [f"*{base}* (baseline)", f"{values[baseline_key]:.2f}", "—", "—", "—", "—", "—"]
        rows.append("| " + " | ".join(cells + (["—"] * 3 if timings else [])) + " |")
    matched = set(summary["matched_methods"])
    for method, s in summary["methods"].items():
        delta = s["delta_vs_none" if key == "test_mse" else "delta_vs_none_paper_split"]
        welch_text = r_text = "—"
        if delta is None:
            delta_text, p_text = "—", "—"
        else:
            welch = delta.get("ci95_welch")
            welch_text = f"[{welch[0]:+.2f}, {welch[1]:+.2f}]" if welch else "—"
            r = delta.get("correlation")
            r_text = f"{r:+.2f}" if r is not None and not math.isnan(r) else "—"
            ci = delta["ci95"]
            mark = "**" if significant(delta) else ""
            delta_text = f"{mark}{delta['mean']:+.2f} [{ci[0]:+.2f}, {ci[1]:+.2f}]{mark}" if ci else f"{delta['mean']:+.2f}"
            p_text = (f"{delta['t_p_holm']:.3f} / {delta['p_holm']:.3f}"
                      if not math.isnan(delta["p_holm"]) else "—")
        label = f"{method} (matched)" if method in matched else method
        kept = [step for step in s.get("best_step", []) if step is not None]
        cells = [label, _format_mean_sd(s[key]), delta_text, welch_text, r_text, p_text,
                 f"{statistics.median(kept):.0f}/{s['steps']}" if kept else "—"]
        if timings:
            cells += [f"{s['aug_s_once']:.2f}", f"{s['aug_s_per_epoch']:.3f}", f"{s['train_s']:.1f}"]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def format_summary_table(results: dict[str, Any]) -> str:
    """Every scene's rows in one markdown table: the table the README shows, printed by the run.

    One row per baseline and per method; the cells are those of :func:`format_scene_table`
    (same formatting), plus the scene and the budget check on the method it checked.
    """
    rows = ["| " + " | ".join(SUMMARY_COLUMNS) + " |", "|" + "|".join(["---"] * len(SUMMARY_COLUMNS)) + "|"]
    for name, summary in results["scenes"].items():
        table = format_scene_table(name, summary, timings=False).splitlines()
        head = [c.strip() for c in table[0].strip("|").split("|")]
        check = summary.get("budget_check")
        for line in table[2:]:
            cells = dict(zip(head, (c.strip() for c in line.strip("|").split("|"))))
            method = cells["method"].removesuffix(" (matched)")
            verdict = "—"
            if check and method == check["method"]:
                verdict = f"{'robust' if check['robust'] else 'not robust'}: Δ {check['delta_2n']:+.2f} at {check['steps_2n']} steps"
            values = {**cells, "scene": name, "budget check": verdict}
            rows.append("| " + " | ".join(values[c] for c in SUMMARY_COLUMNS) + " |")
    return "\n".join(rows)


def format_budget_check(check: dict[str, Any] | None) -> str:
    """One line: the verdict of the largest |Δ| at the run's steps and at twice as many.

    Example:
        >>> format_budget_check({"method": "fs2", "steps": 400, "steps_2n": 800, "delta": -4.21,
        ...                      "delta_2n": -3.01, "ci95_halfwidth": 1.15, "robust": False})
        'budget check: fs2 Δ -4.21 at 400 steps, -3.01 at 800 (CI half-width 1.15): not robust (the verdict moves with the budget)'
    """
    if not check:
        return "budget check: not run (no gap, or no method beside none)"
    verdict = ("robust (same sign, moved less than the CI half-width)" if check["robust"]
               else "not robust (the verdict moves with the budget)")
    return (f"budget check: {check['method']} Δ {check['delta']:+.2f} at {check['steps']} steps, "
            f"{check['delta_2n']:+.2f} at {check['steps_2n']} (CI half-width {check['ci95_halfwidth']:.2f}): {verdict}")


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
    """Every scene's table, budget check and findings, and the paper-split tables, as markdown.

    The first line names the commit that produced the results (``results["commit"]``).
    """
    parts = [f"Produced by commit `{results.get('commit', 'unknown')}`.\n",
             "### Summary (the README's table)\n", format_summary_table(results), ""]
    for name, summary in results["scenes"].items():
        gaps = ", ".join(summary["gaps"]) or "none (control)"
        sizes = summary["split_sizes"]
        holdout = f" ({sizes['holdout']} hold-out from the training session)" if "holdout" in sizes else ""
        counts = summary.get("recordings")  # a folder of recordings: what the intervals rest on
        recorded = (f" from {counts['train']} train / {counts['holdout']} hold-out / {counts['val']} val / "
                    f"{counts['test']} test recordings (the intervals rest on {counts['test']} test recordings)"
                    if counts else "")
        parts.append(f"### {name}: {summary['description']}\n\ngaps: {gaps}; "
                     f"{sizes['train']} train{holdout} / {sizes['val']} val / {sizes['test']} test sequences"
                     f"{recorded}\n")
        parts.append(format_scene_table(name, summary, timings=timings))
        parts.append("")
        if summary["gaps"]:
            parts.append(format_budget_check(summary.get("budget_check")))
            parts.append("")
        parts.extend(f"- {line}" for line in format_findings(name, summary))
        parts.append("")
    parts.append("### The same runs scored on the paper's 6 + 6 split (first 6 val and test sequences)\n")
    for name, summary in results["scenes"].items():
        parts.append(f"#### {name}\n")
        parts.append(format_scene_table(name, summary, timings=False, key="test_mse_paper_split"))
        parts.append("")
    return "\n".join(parts)
