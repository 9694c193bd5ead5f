"""The protocol's report: per-scene markdown tables, one-sentence findings, the whole report.

Reads the ``results.json`` dict that :func:`~event_transforms.tactile.protocol.run.run_protocol`
writes (per scene: baselines, and per method the per-seed values and Δ vs ``none``).
"""

from __future__ import annotations

import math
import re
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .stats import current_rules, mean_sd, significant

__all__ = ["format_summary_table", "format_scene_table", "format_budget_check", "format_physics_comparison",
           "format_findings", "format_environment",
           "format_report", "format_rules", "rules_version", "Verdict", "summary_verdicts", "compare_verdicts",
           "format_verdict_comparison"]

#: The summary table's columns before the statistics standard was named (runs committed then):
#: the same Bonferroni intervals called "family", and an unadjusted unpaired interval beside them.
LEGACY_SUMMARY_COLUMNS = ("scene", "method", "test MSE", "Δ vs none [family 95 % CI]", "unpaired CI", "r",
                          "family p: t / Wilcoxon", "Δ vs matched [family 95 % CI]", "budget check")
_LEGACY_NAMES = {"Δ vs none [family 95 % CI]": "Δ vs none [Bonferroni 95 % CI]",
                 "Δ vs matched [family 95 % CI]": "Δ vs matched [Bonferroni 95 % CI]"}

#: The columns of the summary table (the README's table), in order.
#: One family-wise standard throughout: Bonferroni within each scene's family (its methods' Δ vs
#: none), for every interval and p-value the summary shows; the unadjusted unpaired interval is
#: only in the scene tables, labelled as such.
SUMMARY_COLUMNS = ("scene", "method", "test MSE", "Δ vs none [Bonferroni 95 % CI]", "r",
                   "Bonferroni p: t / Wilcoxon", "Δ vs matched [Bonferroni 95 % CI]", "budget check (headline)")


def _format_mean_sd(values: Sequence[float]) -> str:
    mean, sd = mean_sd(values)
    return f"{mean:.2f}" if len(values) < 2 else f"{mean:.2f} ± {sd:.2f}"


def _ci_text(delta: dict[str, Any] | None) -> str:
    """``Δ [lo, hi]`` with the family-wise interval, bold where it excludes 0."""
    if delta is None:
        return "—"
    ci = delta.get("ci_family") or delta.get("ci95")
    if not ci:
        return f"{delta['mean']:+.2f}"
    mark = "**" if significant(delta) else ""
    note = " (not converged)" if delta.get("not_converged") else " (borderline)" if delta.get("borderline") else ""
    return f"{mark}{delta['mean']:+.2f} [{ci[0]:+.2f}, {ci[1]:+.2f}]{mark}{note}"


def _p_text(delta: dict[str, Any]) -> str:
    t_p = delta.get("t_p_family", delta.get("t_p_holm", math.nan))
    if math.isnan(t_p):
        return "—"
    floor = delta.get("wilcoxon_floor", 0.0)
    wilcoxon = (f"{delta.get('p_family', delta['p_holm']):.3f}" if floor <= current_rules().alpha
                else f"n/a (floor {floor:.3g})")
    return f"{t_p:.3f} / {wilcoxon}"


def _time_cells(s: dict[str, Any]) -> list[str]:
    online = s.get("online_aug_s_per_epoch")
    wall = s.get("single_wall_s")
    return [
        f"{s['aug_s_once']:.2f}",
        "—" if online is None else f"{online:.3f}",
        "—" if not wall else f"{wall['median']:.1f} [{wall['min']:.1f}, {wall['max']:.1f}]",
        "—" if s.get("online_wall_s") is None else f"{s['online_wall_s']:.1f}",
    ]


def format_scene_table(name: str, summary: dict[str, Any], *, timings: bool = True, key: str = "test_mse") -> str:
    """A markdown table of one scene: baselines, then methods (MSE in N²).

    Columns: test MSE (mean ± sd over seeds); Δ vs none with its family-wise paired 95 %
    interval (bold where it excludes 0; a duplicate row says "= row X" and is not in the
    family); the unpaired (Welch) interval of the same Δ and the correlation r of ``none``'s
    and the method's per-seed MSEs (what the pairing bought); family-adjusted p-values (the
    Wilcoxon only where it can reach 0.05); the policy rows' Δ vs the scene's matched row;
    the median step whose weights the stopping rule kept and the share of members that
    stopped before the cap. Timings: augmentation once (fixed copies); online augmentation
    per epoch (every training item transformed once, batch by batch as a DataLoader would);
    one model's training wall time alone (median [min, max] over repeats); one model's wall
    time with online augmentation (training + online augmentation × epochs). Where the run
    measured MSE at equal cost: the steps each method affords in the time ``none`` takes when
    it augments online, from the cost table (``floor(steps / ratio)``), and its Δ vs ``none``
    retrained at those steps (a family of its own). Where the run has the cost curve: Δ of each
    method against ``none`` trained for 1.5× and 2× the steps (read it at your own cost ratio).
    """
    head = ["method", "test MSE", "Δ vs none [Bonferroni 95 % CI]", "unpaired 95 % CI (unadjusted)", "r",
            "Bonferroni p: t / Wilcoxon", "Δ vs matched [Bonferroni 95 % CI]", "kept step (stopped early)"]
    if timings:
        head += ["aug s once", "online aug s/epoch", "1 model s/run", "1 model s/run online"]
    equal = timings and key == "test_mse" and any("equal_time" in s for s in summary["methods"].values())
    if equal:
        head += ["steps at equal cost (cost table)", "Δ vs none at equal cost [Bonferroni 95 % CI]"]
    curve = summary.get("cost_curve") if timings and key == "test_mse" else None
    ratios = [r for r in (curve or {}).get("ratios", []) if r > 1.0]
    head += [f"Δ vs none at {r:g}× its steps ({curve['steps'][f'{r:.1f}']}) [Bonferroni 95 % CI]"  # type: ignore[index]
             for r in ratios]
    extra = len(head) - 8
    rows = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    baseline_key = "test_mse_paper_split" if key.endswith("paper_split") else "test_mse"
    for base, values in summary["baselines"].items():
        cells = [f"*{base}* (baseline)", f"{values[baseline_key]:.2f}"] + ["—"] * 6
        rows.append("| " + " | ".join(cells + ["—"] * extra) + " |")
    matched = set(summary["matched_methods"])
    for method, s in summary["methods"].items():
        delta = s["delta_vs_none" if key == "test_mse" else "delta_vs_none_paper_split"]
        welch_text = r_text = p_text = "—"
        original = s.get("duplicate_of")
        if original is not None:
            delta_text = f"= row {original}"
        else:
            delta_text = _ci_text(delta)
            if delta is not None:
                welch = delta.get("ci95_welch")
                welch_text = f"[{welch[0]:+.2f}, {welch[1]:+.2f}]" if welch else "—"
                r = delta.get("correlation")
                r_text = f"{r:+.2f}" if r is not None and not math.isnan(r) else "—"
                p_text = _p_text(delta)
        versus = "—"
        if "matched_row" in s and key == "test_mse":
            if s["matched_row"] is None:
                versus = "no matched row ran"
            elif original is not None and original == s["matched_row"]:
                versus = f"= row {original}"
            elif original is not None:
                versus = f"= row {original}"
            else:
                vs = s.get("delta_vs_matched")
                versus = f"{s['matched_row']}: {_ci_text(vs)}" if vs else "—"
        label = f"{method} (matched)" if method in matched else method
        kept = [step for step in s.get("best_step", []) if step is not None]
        early = s.get("stopped_before_cap")
        kept_text = f"{statistics.median(kept):.0f}/{s['steps']}" if kept else "—"
        if kept and early is not None:
            kept_text += f" ({early:.0%})"
        cells = [label, _format_mean_sd(s[key]), delta_text, welch_text, r_text, p_text, versus, kept_text]
        if timings:
            cells += _time_cells(s)
        if equal:
            same = s.get("equal_time")
            if method == "none":
                cells += [f"{s['steps']} (the budget)", "—"]
            elif same is None:
                cells += ["—", "—"]
            elif original is not None:
                cells += [str(same["steps"]), f"= row {original}"]
            else:
                cells += [str(same["steps"]), _ci_text(same["delta_vs_none"])]
        for ratio in ratios:
            point = (curve or {}).get("methods", {}).get(method, {}).get(f"{ratio:.1f}")
            cells.append(f"= row {original}" if original is not None and method != "none" else _ci_text(point))
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
                word = budget_word(check)
                ci = check.get("ci95_2n") if word == "resolved at 2×" else None
                interval = f" [{ci[0]:+.2f}, {ci[1]:+.2f}]" if ci else ""
                verdict = f"{word}: Δ {check['delta_2n']:+.2f}{interval} at {check['steps_2n']} steps"
            values = {**cells, "scene": name, "budget check (headline)": verdict}
            rows.append("| " + " | ".join(values[c] for c in SUMMARY_COLUMNS) + " |")
    return "\n".join(rows)


def budget_word(check: dict[str, Any]) -> str:
    """The budget check's verdict: ``"robust"``, ``"not robust"``, ``"resolved at 2×"`` (the
    headline's models had not converged at the run's steps and the twice-as-long run resolves it)
    or ``"unresolved"`` (the headline is not resolved: there is no verdict to re-check)."""
    if check.get("robust") is None:
        return "resolved at 2×" if check.get("resolved_2n") else "unresolved"
    return "robust" if check["robust"] else "not robust"


def format_budget_check(check: dict[str, Any] | None, *, skipped: bool = False) -> str:
    """One line: the scene's pre-declared headline (its matched method) at the run's steps and at
    twice as many, judged with the Bonferroni interval's half-width.

    Example:
        >>> format_budget_check({"method": "fs2", "steps": 400, "steps_2n": 800, "delta": -4.21,
        ...                      "delta_2n": -3.01, "ci_family_halfwidth": 1.15, "robust": False})
        'budget check of the headline: fs2 Δ -4.21 at 400 steps, -3.01 at 800 (Bonferroni half-width 1.15): not robust (the verdict moves with the budget)'
    """
    if not check:
        if skipped:
            return "budget check: not run (--no-budget-check, or budget_check=False)"
        return "budget check: not run (no gap, or no matched method beside none)"
    verdict = {"robust": "robust (same sign, moved less than the Bonferroni half-width)",
               "not robust": "not robust (the verdict moves with the budget)",
               "resolved at 2×": "resolved at twice the steps (its models had not converged at the run's steps; "
                                 "both converged at twice as many, and the paired 95 % interval excludes 0)",
               "unresolved": "not judged (the headline is not resolved at the run's steps)"}[budget_word(check)]
    half = check.get("ci_family_halfwidth", check.get("ci95_halfwidth", math.nan))
    return (f"budget check of the headline: {check['method']} Δ {check['delta']:+.2f} at {check['steps']} steps, "
            f"{check['delta_2n']:+.2f} at {check['steps_2n']} (Bonferroni half-width {half:.2f}): {verdict}")


def format_physics_comparison(summary: dict[str, Any]) -> str:
    """One line: whether the scene's best row (lowest mean test MSE) beats the physics
    least-squares model, with both MSEs. ``with-labels`` trained on deployment data the physics
    model never saw: it is not a candidate.

    Example:
        >>> format_physics_comparison({"baselines": {"physics least-squares": {"test_mse": 1.22}},
        ...     "methods": {"none": {"test_mse": [2.0, 2.1]}, "stretch": {"test_mse": [1.0, 1.1]}}})
        'best row: stretch 1.05 N² against the physics least-squares model 1.22: beats it by 0.17 N²'
    """
    physics = summary["baselines"].get("physics least-squares")
    rows = {m: statistics.fmean(s["test_mse"]) for m, s in summary["methods"].items()
            if s.get("test_mse") and m != "with-labels"}
    if physics is None or not rows:
        return "best row: no physics least-squares baseline or no method to compare"
    best = min(rows, key=lambda m: rows[m])
    gap = physics["test_mse"] - rows[best]
    verdict = f"beats it by {gap:.2f} N²" if gap > 0 else f"does not beat it (worse by {-gap:.2f} N²)"
    return (f"best row: {best} {rows[best]:.2f} N² against the physics least-squares model "
            f"{physics['test_mse']:.2f}: {verdict}")


def withheld_reason(delta: dict[str, Any]) -> str:
    """Why a Δ prints no resolved verdict, in a few words (for the findings' sentences).

    Example:
        >>> withheld_reason({"not_converged": True, "ci_family": [-3.8, -2.6]})
        'not converged: the side behind was still improving at the step cap'
        >>> withheld_reason({"ci_family": [-0.8, 0.4]})
        'its Bonferroni interval includes 0'
    """
    if delta.get("not_converged"):
        return "not converged: the side behind was still improving at the step cap"
    if delta.get("borderline"):
        return "borderline: the interval excludes 0 but one block of seeds points the other way"
    ci = delta.get("ci_family") or delta.get("ci95")
    if ci is not None and (ci[1] < 0 or ci[0] > 0):
        return "its Holm-corrected p is above 0.05"
    return "its Bonferroni interval includes 0"


def format_findings(name: str, summary: dict[str, Any]) -> list[str]:
    """One sentence per method: what it buys (Δ test MSE and its family-wise interval),
    against the matched row for the policy rows, and what it costs."""
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
        if s.get("duplicate_of"):
            lines.append(f"{name} / {method}: bit-identical per seed to {s['duplicate_of']} (the same copies); "
                         "not a separate test.")
            continue
        delta = s["delta_vs_none"]
        if delta is None or not (delta.get("ci_family") or delta.get("ci95")):
            continue
        lo, hi = delta.get("ci_family") or delta["ci95"]
        verdict = (("buys" if hi < 0 else "costs") if significant(delta) else
                   f"shows no resolved change ({withheld_reason(delta)}):")
        text = (f"{name} / {method}: {verdict} {delta['mean']:+.2f} N² test MSE vs none (Bonferroni 95 % CI {lo:+.2f} "
                f"to {hi:+.2f}, {delta.get('better_seeds', '?')}/{delta['n']} seeds better)")
        vs = s.get("delta_vs_matched")
        if vs and vs.get("ci_family"):
            mlo, mhi = vs["ci_family"]
            word = (("better than" if mhi < 0 else "worse than") if significant(vs) else
                    f"not resolved ({withheld_reason(vs)}) from")
            row = s["matched_row"]
            matched = "the matched row" if row == "matched" else f"the matched row {row}"
            text += (f"; {word} {matched} by {vs['mean']:+.2f} N² (Bonferroni 95 % CI {mlo:+.2f} "
                     f"to {mhi:+.2f}, {vs['better_seeds']}/{vs['n']} seeds better)")
        wall = s.get("single_wall_s")
        cost = f"{s['aug_s_once']:.2f} s of augmentation once"
        if wall:
            cost += f", {wall['median']:.1f} s for one model alone"
        if s.get("online_aug_s_per_epoch") is not None:
            cost += f", {s['online_aug_s_per_epoch']:.3f} s per epoch augmenting online"
        lines.append(text + f"; costs {cost}.")
    local = summary["methods"].get("none-local")
    if none and local and local.get("test_mse"):
        physics = summary["baselines"].get("physics least-squares", {}).get("test_mse")
        lines.append(
            f"{name}: the network on its own (none-local: the reference model without global inputs, its head reading "
            f"the ConvLSTM's features only) scores {statistics.fmean(local['test_mse']):.2f} N² against "
            f"{statistics.fmean(none['test_mse']):.2f} for none (with them"
            + (f"; physics least-squares {physics:.2f}" if physics is not None else "") + "). The verdicts use the "
            "model with global inputs (none and every augmentation row): it is the configuration the protocol fixed "
            "before these runs; none-local's Δ vs none above (a row of the family) is what removing them does.")
    labels, inferred = summary["methods"].get("with-labels"), summary["methods"].get("inferred")
    if labels and inferred and labels.get("test_mse") and inferred.get("test_mse"):
        gap = statistics.fmean(inferred["test_mse"]) - statistics.fmean(labels["test_mse"])
        lines.append(
            f"{name}: inferred (a policy inferred from the labelled deployment validation recordings) vs with-labels "
            f"(the same recordings added to training, the same budget, stopped on the training session's hold-out "
            f"like every row): {statistics.fmean(inferred['test_mse']):.2f} vs "
            f"{statistics.fmean(labels['test_mse']):.2f} N² test MSE, so inferring "
            + ("beats" if gap < 0 else "does not beat") + f" using the labels by the mean ({gap:+.2f} N²; each row's "
            "resolved verdict is its Δ vs none above).")
    return lines


def format_environment(results: dict[str, Any]) -> str:
    """One paragraph: the machine the numbers come from, and what they cover.

    Example:
        >>> format_environment({"environment": {"cpu_model": "X", "cpu_capability": "AVX2",
        ...     "ATEN_CPU_CAPABILITY": None, "torch": "2.0", "threads": 1, "device": "cpu",
        ...     "package_version": "0.1"}})[:45]
        "One machine's numbers: CPU X, torch 2.0 with "
    """
    env = results.get("environment", {})
    forced = env.get("ATEN_CPU_CAPABILITY")
    kernels = f"{env.get('cpu_capability', 'unknown')} kernels" + (f" (ATEN_CPU_CAPABILITY={forced})" if forced else "")
    return (f"One machine's numbers: CPU {env.get('cpu_model', 'unknown')}, torch {env.get('torch', '?')} with "
            f"{kernels}, {env.get('threads', '?')} thread(s) per job, device {env.get('device', '?')}, "
            f"event-transforms {env.get('package_version', '?')}. Another CPU kernel set changes per-seed MSEs in "
            "the last digits and training amplifies that, so compare verdicts (sign, significance), not digits. "
            + interval_coverage(results.get("config", {}).get("resample", "none")))


def table_coverage(resample: str) -> str:
    """What one table's intervals cover, in one line under the table (for a folder of recordings,
    what they cannot cover too).

    Example:
        >>> table_coverage("fresh")[:42]
        'Intervals over seeds: each seed its own si'
    """
    if resample == "fresh":
        return "Intervals over seeds: each seed its own simulated data set (fresh per seed): they cover new data sets."
    if resample == "bootstrap":
        return ("Intervals over seeds: each seed a bootstrap resample (by recording) of these data; they cover "
                "resamples of these recordings, not new recordings: on the simulator the 8-resample mean's spread "
                "over new data sets is 3.7× its nominal standard error (benchmarks/tactile/resampling_coverage.md).")
    return "Intervals over seeds: the data fixed (every seed the same data): they cover training randomness only."


def interval_coverage(resample: str) -> str:
    """What a run's intervals cover, in one sentence, for its ``resample`` setting.

    Example:
        >>> interval_coverage("none")[:40]
        'Intervals cover training randomness (ini'
    """
    if resample == "fresh":
        return ("Intervals cover training randomness (initial weights, batch order, augmentation draws) and new "
                "data sets from the simulator: each seed draws its own training, hold-out, validation and test "
                "grasps from the scene's sessions (fresh per seed; every method of a seed trains and is scored on "
                "the same ones, from the same initial weights, augmentation seed and batch order; the baselines "
                "fitted and scored on each seed's own data set; results.json records each seed's data: its "
                "sequence-seed offset and content hashes). They do not cover another simulator or real grasps.")
    if resample == "bootstrap":
        return ("Intervals cover training randomness (initial weights, batch order, augmentation draws) and the "
                "data: each seed trains on its own bootstrap resample of the training sequences and is scored on "
                "its own resamples of the validation and test sequences (every method of a seed on the same "
                "ones; the baselines fitted and scored on the same resamples, averaged over seeds; the hold-out "
                "set and the paper's 6 + 6 split are not resampled). They cover resamples of this one data set, "
                "not another data set: on the simulator the spread of the 8-resample mean over independently "
                "simulated data sets is 3.7× the nominal standard error (benchmarks/tactile/resampling_coverage.md).")
    return ("Intervals cover training randomness (initial weights, batch order, augmentation draws) with the "
            "data fixed: every seed trains and is tested on the same grasps.")


#: How a report names the rules its verdicts were judged by (read back by :func:`rules_version`).
_RULES_LINE = re.compile(r"^Decision rules version (?P<version>[\w.-]+) ", re.MULTILINE)


def format_rules(results: dict[str, Any]) -> str:
    """One paragraph: the version of the decision rules the verdicts were judged by, in words
    (:mod:`~event_transforms.tactile.protocol.rules`; ``results["rules"]``).

    Example:
        >>> format_rules({})[:48]
        'Decision rules: not recorded (results written be'
    """
    from .protocol.rules import HISTORY

    recorded = results.get("rules")
    if not isinstance(recorded, dict) or "version" not in recorded:
        return ("Decision rules: not recorded (results written before the rules carried a version: version 1 "
                "of event_transforms/tactile/protocol/rules.py or earlier).")
    version = str(recorded["version"])
    known = HISTORY.get(version)
    if known is not None and known.to_dict() == recorded:
        return known.line()
    return (f"Decision rules version {version} (as recorded in results.json, not as this code states version "
            f"{version}: read the rules there).")


def rules_version(text: str) -> str | None:
    """The decision rules' version a report (``results.md``) names, ``None`` where it names none.

    Example:
        >>> rules_version("Produced by commit `abc`.\\n\\nDecision rules version 2 (see rules.py): ...")
        '2'
    """
    match = _RULES_LINE.search(text)
    return match["version"] if match else None


def format_report(results: dict[str, Any], *, timings: bool = True) -> str:
    """Every scene's table, budget check and findings, and the paper-split tables, as markdown.

    The first line names the commit that produced the results (``results["commit"]``), the
    next paragraphs the machine and the decision rules' version (:func:`format_rules`).
    """
    parts = [f"Produced by commit `{results.get('commit', 'unknown')}`.\n", format_environment(results), "",
             format_rules(results), "",
             "### Summary (the README's table)\n", format_summary_table(results), ""]
    covers = table_coverage(results.get("config", {}).get("resample", "none"))
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
        parts.append(covers)
        parts.append("")
        parts.append(format_physics_comparison(summary))
        parts.append("")
        if summary["gaps"]:
            parts.append(format_budget_check(summary.get("budget_check"),
                                             skipped=results.get("config", {}).get("budget_check") is False))
            parts.append("")
        parts.extend(f"- {line}" for line in format_findings(name, summary))
        parts.append("")
    parts.append("### The same runs scored on the paper's 6 + 6 split (first 6 val and test sequences)\n")
    for name, summary in results["scenes"].items():
        parts.append(f"#### {name}\n")
        parts.append(format_scene_table(name, summary, timings=False, key="test_mse_paper_split"))
        parts.append("")
        parts.append(covers)
        parts.append("")
    return "\n".join(parts)


@dataclass(frozen=True)
class Verdict:
    """What one cell of the summary table says, without its digits.

    Attributes:
        mean: the Δ as printed (N²).
        significant: its family-wise interval excludes 0 and nothing withholds it (not converged;
            under rules version 1 a block of seeds pointing the other way): the cell is bold.
        borderline: the interval excludes 0 but one block of seeds points the other way (the
            cell says "(borderline)"; not significant). Only results judged by rules version 1
            have such cells.
        label: the word of a cell that is no interval (the budget check: ``"robust"`` /
            ``"not robust"`` / ``"unresolved"``, ``significant`` meaning robust).
    """

    mean: float
    significant: bool
    borderline: bool = False
    label: str | None = None

    @property
    def sign(self) -> int:
        """-1 (the method is better: lower MSE), +1 (worse) or 0."""
        return (self.mean > 0) - (self.mean < 0)

    @property
    def word(self) -> str:
        """``"better"`` / ``"worse"`` when significant, else ``"unresolved"`` (``"borderline"``
        where the interval excluded 0 but one block of seeds pointed the other way); a cell
        that is no interval says its ``label``."""
        if self.label is not None:
            return self.label
        if not self.significant:
            return "borderline" if self.borderline else "unresolved"
        return "better" if self.sign < 0 else "worse"


#: The summary table's columns that carry a verdict, and the short name used in comparisons.
VERDICT_COLUMNS = {"Δ vs none [Bonferroni 95 % CI]": "vs none", "Δ vs matched [Bonferroni 95 % CI]": "vs matched"}
#: The summary table's budget-check column and the scene tables' equal-cost column (former name
#: beside it), and their short names in comparisons.
BUDGET_COLUMN, BUDGET_SHORT = "budget check (headline)", "budget check"
EQUAL_COST_COLUMNS = ("Δ vs none at equal cost [Bonferroni 95 % CI]", "Δ vs none at equal time [Bonferroni 95 % CI]")
EQUAL_COST_SHORT = "at equal cost"
_BUDGET_CELL = re.compile(r"^(?P<word>robust|not robust|unresolved|resolved at 2×): Δ (?P<mean>[+-]?\d+\.\d+)"
                          r"(?: \[[+-]?\d+\.\d+, [+-]?\d+\.\d+\])? at \d+ steps$")
_CELL = re.compile(r"^(?:(?P<ref>[^:\[\]*]+): )?(?P<bold>\*\*)?(?P<mean>[+-]?\d+\.\d+) "
                   r"\[[+-]?\d+\.\d+, [+-]?\d+\.\d+\](?P=bold)?(?: \((?P<note>not converged|borderline)\))?$")


def summary_verdicts(text: str) -> dict[tuple[str, str, str], Verdict]:
    """The verdicts of the summary table in ``text`` (a ``results.md`` or the README).

    Keys are ``(scene, method, "vs none" | "vs matched")``; cells without an interval (``—``,
    ``= row X``, baselines) carry no verdict and are left out.

    Raises:
        ValueError: ``text`` holds no summary table, or a Δ cell cannot be read.

    Example:
        >>> table = "\\n".join(["| " + " | ".join(SUMMARY_COLUMNS) + " |", "|---" * 8 + "|",
        ...     "| paper | stretch | 1.07 | **-0.92 [-1.24, -0.60]** | — | — | — | — |"])
        >>> summary_verdicts(table)
        {('paper', 'stretch', 'vs none'): Verdict(mean=-0.92, significant=True, borderline=False, label=None)}
    """
    rows: list[list[str]] | None = None
    columns: tuple[str, ...] = SUMMARY_COLUMNS
    for line in text.splitlines() + [""]:
        line = line.strip()
        if line.startswith("|") and line.endswith("|"):
            cells = [cell.strip() for cell in line[1:-1].split("|")]
            if rows is None and tuple(cells) in (SUMMARY_COLUMNS, LEGACY_SUMMARY_COLUMNS):
                rows, columns = [], tuple(cells)
            elif rows is not None and not all(re.fullmatch(r":?-{3,}:?", c) for c in cells):
                rows.append(cells)
        elif rows is not None:
            break
    if rows is None:
        raise ValueError("text holds no summary table (a table whose header is SUMMARY_COLUMNS)")
    verdicts: dict[tuple[str, str, str], Verdict] = {}
    for cells in rows:
        if len(cells) != len(columns):
            raise ValueError(f"summary table row has {len(cells)} cells, expected {len(columns)}: {cells!r}")
        row = dict(zip(columns, cells))
        if columns == LEGACY_SUMMARY_COLUMNS:  # the same intervals under their former names
            row = {_LEGACY_NAMES.get(k, k): v for k, v in row.items()}
        method = row["method"].removesuffix(" (matched)")
        for column, short in VERDICT_COLUMNS.items():
            cell = row[column]
            if cell == "—" or cell.startswith("= row") or cell == "no matched row ran":
                continue
            match = _CELL.match(cell)
            if match is None:
                raise ValueError(f"cannot read the {column!r} cell of {row['scene']} / {method}: {cell!r}")
            verdicts[(row["scene"], method, short)] = Verdict(float(match["mean"]), bool(match["bold"]),
                                                              match["note"] == "borderline")
        budget = _BUDGET_CELL.match(row.get(BUDGET_COLUMN, row.get("budget check", "—")))
        if budget is not None:
            verdicts[(row["scene"], method, BUDGET_SHORT)] = Verdict(
                float(budget["mean"]), budget["word"] in ("robust", "resolved at 2×"), label=budget["word"])
    return verdicts


def scene_table_verdicts(text: str) -> dict[tuple[str, str, str], Verdict]:
    """The equal-cost verdicts of the scene tables in ``text`` (a run's ``results.md``): keys
    ``(scene, method, "at equal cost")``. A text without such tables gives none.

    Raises:
        ValueError: an equal-cost cell cannot be read.

    Example:
        >>> head = "| method | " + EQUAL_COST_COLUMNS[0] + " |"
        >>> scene_table_verdicts("\\n".join(["### timing: a delay", "", head, "|---|---|",
        ...                                  "| fs2 | **-3.10 [-3.50, -2.70]** |"]))
        {('timing', 'fs2', 'at equal cost'): Verdict(mean=-3.1, significant=True, borderline=False, label=None)}
    """
    verdicts: dict[tuple[str, str, str], Verdict] = {}
    scene: str | None = None
    column: int | None = None
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("#"):
            heading = line.lstrip("#").strip()
            # the scene tables ("### NAME: description"); the paper-split repeats have no equal-cost column
            scene = heading.split(":", 1)[0].strip() if line.startswith("### ") and ":" in heading else None
            column = None
            continue
        if scene is None or not (line.startswith("|") and line.endswith("|")):
            continue
        cells = [cell.strip() for cell in line[1:-1].split("|")]
        if column is None:
            column = next((cells.index(c) for c in EQUAL_COST_COLUMNS if c in cells), None)
            if column is None:
                scene = None
            continue
        if all(re.fullmatch(r":?-{3,}:?", c) for c in cells) or len(cells) <= column:
            continue
        cell, method = cells[column], cells[0].removesuffix(" (matched)")
        if cell == "—" or cell.startswith("= row") or method.endswith("(baseline)"):
            continue
        match = _CELL.match(cell)
        if match is None:
            raise ValueError(f"cannot read the equal-cost cell of {scene} / {method}: {cell!r}")
        verdicts[(scene, method, EQUAL_COST_SHORT)] = Verdict(float(match["mean"]), bool(match["bold"]),
                                                              match["note"] == "borderline")
    return verdicts


def run_verdicts(text: str) -> dict[tuple[str, str, str], Verdict]:
    """Every verdict a run's ``results.md`` prints: the summary table's (Δ vs none, Δ vs
    matched, the budget check) and the scene tables' Δ at equal cost. A README (summary
    table only) gives the summary's.

    Example:
        >>> text = "\\n".join(["| " + " | ".join(SUMMARY_COLUMNS) + " |", "|---" * 8 + "|",
        ...     "| timing | fs2 | 4.80 | **-3.16 [-3.86, -2.45]** | — | — | — | robust: Δ -3.35 at 600 steps |"])
        >>> sorted(column for _, _, column in run_verdicts(text))
        ['budget check', 'vs none']
    """
    return {**summary_verdicts(text), **scene_table_verdicts(text)}


def compare_verdicts(
    a: dict[tuple[str, str, str], Verdict], b: dict[tuple[str, str, str], Verdict]
) -> dict[str, list[tuple[str, str, str]]]:
    """Compare two runs' verdicts on the cells both have (sign and significance, not digits).

    Returns the cells by outcome: ``"same"`` (resolved in both with the same sign, or resolved
    in neither: a borderline cell is not resolved; the budget check: robust in both or neither),
    ``"reversed"`` (significant in both, opposite signs: the runs contradict each other),
    ``"significance"`` (significant in one run only; the point estimates' signs agree),
    ``"significance and sign"`` (significant in one run, the other's estimate has the other
    sign), and ``"only in one"`` (cells one run lacks).

    Example:
        >>> a = {("s", "m", "vs none"): Verdict(-1.0, True), ("s", "k", "vs none"): Verdict(0.2, False)}
        >>> b = {("s", "m", "vs none"): Verdict(+0.9, True), ("s", "k", "vs none"): Verdict(0.3, True)}
        >>> {k: v for k, v in compare_verdicts(a, b).items() if v}
        {'reversed': [('s', 'm', 'vs none')], 'significance': [('s', 'k', 'vs none')]}
    """
    out: dict[str, list[tuple[str, str, str]]] = {
        "same": [], "reversed": [], "significance": [], "significance and sign": [], "only in one": []}
    for key in sorted(set(a) | set(b)):
        if key not in a or key not in b:
            out["only in one"].append(key)
            continue
        x, y = a[key], b[key]
        if x.significant == y.significant and (not x.significant or x.sign == y.sign):
            out["same"].append(key)
        elif x.significant and y.significant:
            out["reversed"].append(key)
        elif x.sign == y.sign:
            out["significance"].append(key)
        else:
            out["significance and sign"].append(key)
    return out


def format_verdict_comparison(a: dict[tuple[str, str, str], Verdict], b: dict[tuple[str, str, str], Verdict],
                              names: tuple[str, str] = ("a", "b")) -> str:
    """A markdown paragraph and table: how many verdicts two runs share, and every cell that moved."""
    outcome = compare_verdicts(a, b)
    shared = len(a.keys() & b.keys())
    moved = [(kind, key) for kind in ("reversed", "significance and sign", "significance") for key in outcome[kind]]
    lines = [f"{shared} verdicts in both runs: {len(outcome['same'])} the same (better / worse / unresolved), "
             f"{len(outcome['significance'])} changed significance only, "
             f"{len(outcome['significance and sign'])} changed significance and sign, "
             f"{len(outcome['reversed'])} reversed (significant in both with opposite signs); "
             f"{len(outcome['only in one'])} cells in one run only.", ""]
    if moved:
        lines += [f"| scene | method | Δ | {names[0]} | {names[1]} | outcome |", "|---|---|---|---|---|---|"]
        for kind, (scene, method, column) in moved:
            x, y = a[(scene, method, column)], b[(scene, method, column)]
            lines.append(f"| {scene} | {method} | {column} | {x.mean:+.2f} ({x.word}) | {y.mean:+.2f} ({y.word}) "
                         f"| {kind} |")
    return "\n".join(lines)
