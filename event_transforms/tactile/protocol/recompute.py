"""A table's verdicts recomputed from the per-seed values alone, with the rules of the version
the table names (DESIGN.md §14): what a committed results page must agree with.

:func:`seed_values` keeps, of a ``results.json``, what its verdicts are computed from — per
scene the rows' per-seed test MSEs (all frames and the paper's 6 + 6 split), whether each
ensemble converged, the baselines' scores and the budget check's per-seed values at twice the
steps — small enough to commit beside a page of simulated results (never beside recorded data).
:func:`recompute` rebuilds every Δ, interval, p-value and verdict from them
(:func:`~event_transforms.tactile.stats.scene_deltas`, :func:`judge_budget`) under the recorded
rules, and :func:`~event_transforms.tactile.report.format_summary_table` of the result is the
summary table the page must print, cell for cell.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ..stats import paired_t, replicated, scene_deltas, seed_blocks, significant
from .rules import RULES, RULES_V1, Rules, rules_for, version_of

__all__ = ["judge_budget", "seed_values", "recompute"]

#: The per-seed fields of a row that its verdicts are computed from.
ROW_FIELDS = ("seeds", "test_mse", "test_mse_paper_split", "converged")


def judge_budget(method: str, steps: int, delta: dict[str, Any], none_2n: Mapping[str, Sequence[Any]],
                 method_2n: Mapping[str, Sequence[Any]], converged_2n: bool, *,
                 rules: Rules | None = None) -> dict[str, Any]:
    """The budget check of a headline from its Δ at ``steps`` and both rows' per-seed test MSEs at
    the rules' ``budget_factor`` × the steps (``{"seeds", "test_mse"}`` each).

    A headline resolved at ``steps`` is robust when the sign agrees at twice the steps and the
    change is smaller than the half-width of its Bonferroni interval at ``steps`` (the interval
    the table shows). A headline that is not resolved at ``steps`` is not judged (``robust`` is
    ``None``); if its models had not converged there, the twice-as-long run answers instead
    (``resolved_2n``: both ensembles converged, its paired 95 % interval, a pre-declared family of
    one, excludes 0, and under rules version 1 the direction holds in each half of the seeds).

    Example:
        >>> delta = {"mean": -1.0, "ci_family": [-1.5, -0.5]}
        >>> check = judge_budget("fs2", 300, delta, {"seeds": [0, 1, 2], "test_mse": [2.0, 2.1, 2.2]},
        ...                      {"seeds": [0, 1, 2], "test_mse": [1.1, 1.0, 1.3]}, True)
        >>> check["robust"], round(check["delta_2n"], 2), check["steps_2n"]
        (True, -0.97, 600)
    """
    rules = RULES if rules is None else rules
    none = dict(zip(none_2n["seeds"], none_2n["test_mse"]))
    pairs = [(none[s], v) for s, v in zip(method_2n["seeds"], method_2n["test_mse"]) if s in none]
    first, second = [a for a, _ in pairs], [b for _, b in pairs]
    test = paired_t(first, second, level=rules.unadjusted_level)
    ci = delta.get("ci_family") or delta.get("ci95")
    half = (ci[1] - ci[0]) / 2 if ci else math.nan
    robust: bool | None = None
    if significant(delta, rules.alpha):
        robust = bool(ci) and (delta["mean"] > 0) == (test.mean > 0) and abs(delta["mean"] - test.mean) < half
    resolved_2n = bool(delta.get("not_converged") and converged_2n and test.ci is not None
                       and (test.ci[1] < 0 or test.ci[0] > 0)
                       and (rules.replication == "none" or replicated(test.mean, seed_blocks(first, second))))
    return {"method": method, "steps": steps, "steps_2n": rules.budget_factor * steps, "delta": delta["mean"],
            "delta_2n": test.mean, "ci95_2n": list(test.ci) if test.ci else None, "ci_family_halfwidth": half,
            "robust": robust, "converged_2n": converged_2n, "resolved_2n": resolved_2n,
            "none_2n": {"seeds": list(none_2n["seeds"]), "test_mse": list(none_2n["test_mse"])},
            "method_2n": {"seeds": list(method_2n["seeds"]), "test_mse": list(method_2n["test_mse"])}}


def seed_values(results: dict[str, Any]) -> dict[str, Any]:
    """What the verdicts of a ``results.json`` dict are computed from (see the module's docstring).

    Raises:
        ValueError: a budget check without its per-seed values at twice the steps (a file written
            before they were recorded).
    """
    scenes: dict[str, Any] = {}
    for name, summary in results["scenes"].items():
        entry: dict[str, Any] = {
            "matched_methods": list(summary["matched_methods"]),
            "baselines": {b: {k: v[k] for k in ("test_mse", "test_mse_paper_split") if k in v}
                          for b, v in summary["baselines"].items()},
            "methods": {m: {k: s[k] for k in ROW_FIELDS if k in s} for m, s in summary["methods"].items()},
        }
        check = summary.get("budget_check")
        if check:
            if "none_2n" not in check:
                raise ValueError(f"results: scene {name!r}'s budget check has no per-seed values at twice the steps "
                                 "(written before they were recorded): rerun it")
            entry["budget_check"] = {k: check[k] for k in ("method", "steps", "converged_2n", "none_2n", "method_2n")}
        scenes[name] = entry
    return {"commit": results.get("commit"), "rules": results.get("rules"), "scenes": scenes}


def recompute(values: dict[str, Any]) -> dict[str, Any]:
    """A ``results.json``-shaped dict (``rules`` and per scene ``baselines``, ``matched_methods``,
    ``methods`` with every Δ, ``budget_check``) recomputed from :func:`seed_values`' output under
    the rules of its recorded version (version 1 where none is recorded)."""
    version = version_of(values)
    rules = RULES_V1 if version is None else rules_for(version)
    scenes: dict[str, Any] = {}
    for name, entry in values["scenes"].items():
        rows = {m: dict(s) for m, s in entry["methods"].items()}
        for m, fields in scene_deltas(rows, entry["matched_methods"], rules=rules).items():
            rows[m].update(fields)
        summary: dict[str, Any] = {"baselines": entry["baselines"], "matched_methods": entry["matched_methods"],
                                   "methods": rows}
        check = entry.get("budget_check")
        if check:
            summary["budget_check"] = judge_budget(
                check["method"], check["steps"], rows[check["method"]]["delta_vs_none"], check["none_2n"],
                check["method_2n"], check["converged_2n"], rules=rules)
        scenes[name] = summary
    return {"rules": rules.to_dict(), "scenes": scenes}
