"""The protocol's decision rules in one place with a version: the rules are
one frozen object; stats, report and run read them from there; every result records their
version and ``compare`` says when two runs were judged by different rules."""

from __future__ import annotations

import dataclasses

import pytest

from event_transforms.tactile import cli
from event_transforms.tactile.protocol.rules import HISTORY, RULES, RULES_V1, RULES_VERSION, rules_for, version_of
from event_transforms.tactile.report import SUMMARY_COLUMNS, format_report, format_rules, rules_version
from event_transforms.tactile.stats import converged, deltas_vs_none, holdout_drop, paired_t, significant


class TestTheRules:
    def test_one_frozen_object_per_version(self):
        assert RULES_VERSION == RULES.version == "2" and HISTORY == {"1": RULES_V1, "2": RULES}
        with pytest.raises(dataclasses.FrozenInstanceError):
            RULES.alpha = 0.1  # type: ignore[misc]
        assert rules_for("1") is RULES_V1
        with pytest.raises(ValueError, match="version must be one of \\['1', '2'\\], got '3'"):
            rules_for("3")

    def test_what_changed_from_version_1(self):
        changed = {k for k, v in RULES.to_dict().items() if RULES_V1.to_dict()[k] != v}
        assert {"variances", "prior_min_rows", "replication", "borderline"} <= changed
        assert RULES.borderline is None and RULES_V1.borderline  # no cell can read "borderline" now
        same = ("alpha", "family_wise", "convergence_tolerance", "convergence_window", "budget_factor")
        assert all(getattr(RULES, k) == getattr(RULES_V1, k) for k in same)

    @pytest.mark.parametrize("rules", list(HISTORY.values()), ids=list(HISTORY))
    def test_the_words_say_the_numbers(self, rules):
        assert f"1 − {rules.alpha:g}/m" in rules.interval
        assert f"more than {rules.convergence_tolerance * 100:g} % in the last quarter" in rules.convergence
        assert rules.convergence_window == 0.75 and "twice the steps" in rules.budget_check
        assert ("moderated" in rules.interval) == (rules.variances == "moderated")

    def test_the_old_constant_is_the_rules_tolerance(self):
        from event_transforms.tactile.stats import STILL_FALLING

        assert STILL_FALLING == RULES.convergence_tolerance

    @pytest.mark.parametrize("change,message", [
        ({"variances": "pooled"}, "variances must be 'raw' or 'moderated', got 'pooled'"),
        ({"replication": "thirds"}, "replication must be 'none' or 'halves', got 'thirds'"),
        ({"prior_min_rows": 3}, "prior_min_rows must be set exactly with moderated variances, got 3"),
        ({"alpha": 1.5}, "alpha must lie in \\(0, 1\\), got 1.5"),
        ({"family_wise": "holm"}, "family_wise must be 'bonferroni', got 'holm'"),
        ({"budget_factor": 3}, "budget_factor must be 2"),
    ])
    def test_invalid_rules_name_the_field(self, change, message):
        with pytest.raises(ValueError, match=message):
            dataclasses.replace(RULES, **change)

    def test_the_version_a_result_records(self):
        assert version_of({"rules": RULES.to_dict()}) == "2" and version_of({"rules": {}}) is None
        assert format_rules({"rules": RULES.to_dict()}) == RULES.line()
        assert format_rules({}).startswith("Decision rules: not recorded")
        other = {**RULES.to_dict(), "alpha": 0.1}
        assert "as recorded in results.json" in format_rules({"rules": other})
        assert rules_version(format_rules({"rules": RULES_V1.to_dict()})) == "1"
        assert rules_version(format_rules({})) is None


class TestTheCodeReadsTheRules:
    """No copy of a rule's number elsewhere: another ``Rules`` changes the decision."""

    none = {"seeds": list(range(8)), "x": [2.0, 2.1, 1.9, 2.05, 2.0, 1.95, 2.1, 2.0]}
    method = {"seeds": list(range(8)), "x": [1.8, 1.85, 1.8, 1.9, 2.0, 1.7, 1.95, 1.8]}

    def test_the_level(self):
        loose = dataclasses.replace(RULES, alpha=0.2)
        strict = deltas_vs_none({"none": self.none, "a": self.method}, "x")["a"]
        wide = deltas_vs_none({"none": self.none, "a": self.method}, "x", rules=loose)["a"]
        for delta, level in ((strict, 0.95), (wide, 0.8)):
            assert delta["ci_family"] == pytest.approx(list(paired_t(self.none["x"], self.method["x"], level=level).ci))
        assert significant(strict) and significant(wide)

    def test_the_convergence_tolerance_and_window(self):
        history = {"steps": [10, 20, 30, 40], "mse": [4.0, 2.0, 2.0, 1.9]}
        assert holdout_drop([history], 40) == pytest.approx(0.05) and converged(0.05)
        assert not converged(0.05, rules=dataclasses.replace(RULES, convergence_tolerance=0.04))
        early = dataclasses.replace(RULES, convergence_window=0.25)  # the lowest mean before step 10: 4.0
        assert holdout_drop([history], 40, rules=early) == pytest.approx(1 - 1.9 / 4.0)


def _page(version: str | None) -> str:
    """A results.md with one verdict, judged by the rules of ``version`` (none: an older file)."""
    results = {"commit": "0" * 40, "environment": {}, "scenes": {}}
    if version is not None:
        results["rules"] = rules_for(version).to_dict()
    row = "| s | m | 1.00 ± 0.10 | **-1.00 [-1.50, -0.50]** | — | — | — | — |"
    table = "\n".join(["| " + " | ".join(SUMMARY_COLUMNS) + " |", "|" + "---|" * len(SUMMARY_COLUMNS), row])
    return format_report(results).replace("| scene | method |", "| old |", 1) + "\n\n" + table + "\n"


class TestCompareAcrossVersions:
    def test_the_report_names_the_version(self):
        assert rules_version(_page("2")) == "2" and rules_version(_page(None)) is None

    def test_warns_when_the_versions_differ_and_refuses_with_same_rules(self, tmp_path, capsys):
        old, new, newer = tmp_path / "v1.md", tmp_path / "v2.md", tmp_path / "v2b.md"
        old.write_text(_page("1"))
        new.write_text(_page("2"))
        newer.write_text(_page("2"))
        assert cli.main(["compare", str(new), str(newer)]) == 0
        assert "different decision rules" not in capsys.readouterr().err
        assert cli.main(["compare", str(old), str(new)]) == 0
        captured = capsys.readouterr()
        assert "different decision rules" in captured.err and "version 1" in captured.out
        assert "1 verdicts in both runs: 1 the same" in captured.out
        assert cli.main(["compare", str(old), str(new), "--same-rules"]) == 2
        assert "--same-rules refuses" in capsys.readouterr().err
        older = tmp_path / "older.md"
        older.write_text(_page(None))
        assert cli.main(["compare", str(older), str(new)]) == 0
        assert "no version (written before the rules carried one)" in capsys.readouterr().out
