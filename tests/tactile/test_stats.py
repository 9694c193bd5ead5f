"""Tests for the paired statistics (reference values computed once with SciPy 1.17)."""

from __future__ import annotations

import itertools
import math

import pytest

from event_transforms.tactile.stats import holm, paired_t, student_t_cdf, student_t_quantile, wilcoxon_signed_rank

# (t, df, scipy.stats.t.cdf(t, df))
T_CDF = [(0.3, 1, 0.5927735790777423),
         (2.5, 3, 0.9561466764959672),
         (-1.5, 9, 0.08392532802853753),
         (7.0, 29, 0.9999999464986423),
         (2.0, 100, 0.9758939106344332)]


class TestStudentT:
    @pytest.mark.parametrize("t, df, expected", T_CDF)
    def test_cdf(self, t, df, expected):
        assert student_t_cdf(t, df) == pytest.approx(expected, abs=1e-9)

    @pytest.mark.parametrize("df, expected", [(1, 12.706204736), (4, 2.776445105), (9, 2.262157163), (29, 2.045229642)])
    def test_quantile(self, df, expected):
        assert student_t_quantile(0.975, df) == pytest.approx(expected, abs=1e-8)
        assert student_t_quantile(0.025, df) == pytest.approx(-expected, abs=1e-8)

    def test_bad_arguments(self):
        with pytest.raises(ValueError, match="df"):
            student_t_cdf(1.0, 0)
        with pytest.raises(ValueError, match="p must lie"):
            student_t_quantile(1.0, 3)


class TestPairedT:
    def test_against_scipy(self):
        # scipy.stats.ttest_rel(b, a) and t.interval(0.95, 4, mean, sem)
        test = paired_t([10.0, 11.0, 9.5, 10.5, 10.2], [9.0, 10.1, 9.0, 9.4, 9.5])
        assert test.n == 5 and test.mean == pytest.approx(-0.84)
        assert test.ci == pytest.approx((-1.13903228938904, -0.5409677106109596), abs=1e-9)
        assert test.t_p_value == pytest.approx(0.0014581089266073135, rel=1e-6)
        assert test.wilcoxon_p_value == 0.0625

    def test_one_pair_and_constant_differences(self):
        one = paired_t([1.0], [2.0])
        assert one.ci is None and math.isnan(one.sd) and math.isnan(one.t_p_value)
        same = paired_t([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
        assert same.mean == 0 and same.t_p_value == 1.0 and same.wilcoxon_p_value == 1.0

    def test_bad_pairs(self):
        with pytest.raises(ValueError, match="pair up"):
            paired_t([1.0, 2.0], [1.0])
        with pytest.raises(ValueError, match="at least one"):
            paired_t([], [])


def _brute_force(differences):
    """Two-sided exact signed-rank p-value by enumerating every sign pattern."""
    values = [d for d in differences if d != 0]
    magnitudes = sorted(abs(v) for v in values)
    rank = {m: (2 * magnitudes.index(m) + magnitudes.count(m) + 1) / 2 for m in magnitudes}
    ranks = [rank[abs(v)] for v in values]
    observed = sum(r for r, v in zip(ranks, values) if v > 0)
    sums = [sum(r for r, s in zip(ranks, signs) if s) for signs in itertools.product((0, 1), repeat=len(values))]
    lower = sum(s <= observed + 1e-9 for s in sums) / len(sums)
    upper = sum(s >= observed - 1e-9 for s in sums) / len(sums)
    return min(1.0, 2 * min(lower, upper))


class TestWilcoxon:
    def test_against_scipy_without_ties(self):
        x = [-1.2, -0.4, -0.9, -1.6, -0.2, 0.3, -0.7, -1.1, -0.5, -0.8]
        assert wilcoxon_signed_rank(x) == 0.005859375  # scipy.stats.wilcoxon(x, method="exact")

    @pytest.mark.parametrize(
        "differences",
        [[1, -1, 2, 2, -3, 3, 3, 4, 0, -5, 6], [0.5, 0.5, 0.5, -0.5], [1, 2, 3], [-2, 1, 0, 0, 3, -4, 4]],
    )
    def test_exact_with_ties_and_zeros(self, differences):
        # SciPy's "exact" mode ignores ties; the brute force counts every sign pattern
        assert wilcoxon_signed_rank(differences) == pytest.approx(_brute_force(differences))

    def test_floor_with_few_pairs(self):
        assert wilcoxon_signed_rank([-1.0] * 5) == 2 / 2**5
        assert wilcoxon_signed_rank([-1.0] * 10) == 2 / 2**10
        assert wilcoxon_signed_rank([0.0, 0.0]) == 1.0


class TestHolm:
    def test_step_down(self):
        assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
        assert holm([0.5, 0.001]) == pytest.approx([0.5, 0.002])
        adjusted = holm([0.2, math.nan, 0.01])
        assert adjusted[0] == pytest.approx(0.2) and math.isnan(adjusted[1]) and adjusted[2] == pytest.approx(0.02)
        assert holm([]) == []


class TestFamilies:
    """Issue 24: one family per scene without duplicates; the interval and bold agree."""

    @staticmethod
    def _methods():
        none = [10.0, 11.0, 9.5, 10.5, 10.2, 10.8, 9.9, 10.1]
        better = [v - 1.0 - 0.05 * k for k, v in enumerate(none)]
        same = [v + (0.1 if k % 2 else -0.1) for k, v in enumerate(none)]
        return {
            "none": {"seeds": list(range(8)), "test_mse": none},
            "stretch": {"seeds": list(range(8)), "test_mse": better},
            "inferred": {"seeds": list(range(8)), "test_mse": list(better)},
            "rot45": {"seeds": list(range(8)), "test_mse": same},
        }

    def test_duplicates_are_out_of_the_family(self):
        from event_transforms.tactile.stats import deltas_vs_none, duplicates

        methods = self._methods()
        dupes = duplicates(methods)
        assert dupes == {"inferred": "stretch"}
        deltas = deltas_vs_none(methods, "test_mse", exclude=tuple(dupes))
        assert set(deltas) == {"stretch", "rot45"} and deltas["stretch"]["family_size"] == 2

    def test_family_interval_decides_bold(self):
        from event_transforms.tactile.stats import deltas_vs_none, paired_t, significant

        deltas = deltas_vs_none(self._methods(), "test_mse", exclude=("inferred",))
        for delta in deltas.values():
            lo, hi = delta["ci_family"]
            wide = paired_t([0.0] * 8, [0.0] * 8)  # a no-spread pair has no interval width
            assert wide.ci == (0.0, 0.0)
            assert significant(delta) == (hi < 0 or lo > 0) == (delta["t_p_family"] <= 0.05)
            assert lo <= delta["ci95"][0] and hi >= delta["ci95"][1]  # wider than the unadjusted
        assert significant(deltas["stretch"]) and not significant(deltas["rot45"])

    def test_wilcoxon_floor(self):
        from event_transforms.tactile.stats import deltas_vs_none, wilcoxon_floor

        assert wilcoxon_floor(8, 12) == pytest.approx(12 * 2 / 256)
        deltas = deltas_vs_none(self._methods(), "test_mse")
        assert deltas["stretch"]["wilcoxon_floor"] == pytest.approx(3 * 2 / 256)

    def test_policy_rows_against_the_matched_row(self):
        from event_transforms.tactile.benchmark_scenes import get_scene
        from event_transforms.tactile.stats import summarize_scene

        methods = self._methods()
        runs = {}
        for name, m in {**methods, "resize": methods["rot45"] | {"test_mse": [v + 0.3 for v in methods["rot45"]["test_mse"]]}, "prior": methods["stretch"] | {
                "test_mse": [v + 0.01 for v in methods["stretch"]["test_mse"]]}}.items():
            runs[name] = [{"seed": s, "test_mse": v, "val_mse": v, "test_mse_paper_split": v, "val_mse_paper_split": v,
                           "best_step": 10, "holdout_mse": v, "steps": 20, "copies": 1, "train_items": 96,
                           "aug_s_once": 0.0, "aug_s_per_epoch": 0.0, "train_s": 1.0,
                           "test_phase_mse": {"grasp": v, "hold": v, "release": v}}
                          for s, v in zip(m["seeds"], m["test_mse"])]
        summary = summarize_scene(get_scene("paper"), runs, {}, {"train": 48, "val": 24, "test": 96})
        out = summary["methods"]
        assert out["inferred"]["duplicate_of"] == "stretch" and out["inferred"]["delta_vs_none"] is None
        assert out["prior"]["matched_row"] == "resize"
        vs = out["prior"]["delta_vs_matched"]
        assert vs["mean"] < 0 and vs["family_size"] == 1
        assert out["none"]["stopped_before_cap"] == 1.0


def test_a_verdict_from_models_still_falling_at_the_cap_is_not_resolved():
    """Honest at small scale (issue 33, item 8): when most members' hold-out MSE was still falling
    at the step cap, the Δ keeps its interval but prints no resolved verdict, and says why."""
    from event_transforms.tactile.report import _ci_text
    from event_transforms.tactile.benchmark_scenes import get_scene
    from event_transforms.tactile.stats import still_falling, summarize_scene

    def runs(test_mse, falling):
        history = {"steps": [10, 20, 30, 40], "mse": [4.0, 3.0, 2.5, 1.0 if falling else 2.45]}
        return [{"seed": s, "test_mse": v, "val_mse": v, "test_mse_paper_split": v, "val_mse_paper_split": v,
                 "best_step": 40, "holdout_mse": 1.0, "holdout_history": history, "steps": 40, "copies": 1,
                 "train_items": 6, "aug_s_once": 0.0, "aug_s_per_epoch": 0.0, "train_s": 1.0,
                 "test_phase_mse": {"grasp": v, "hold": v, "release": v}} for s, v in enumerate(test_mse)]

    none, better = [2.0, 2.1, 2.2, 2.05, 2.15], [1.0, 1.1, 1.2, 1.05, 1.15]
    settled = summarize_scene(get_scene("timing"), {"none": runs(none, False), "fs2": runs(better, False)}, {}, {})
    falling = summarize_scene(get_scene("timing"), {"none": runs(none, True), "fs2": runs(better, False)}, {}, {})
    assert settled["methods"]["none"]["converged"] and not falling["methods"]["none"]["converged"]
    assert settled["methods"]["fs2"]["delta_vs_none"]["significant"]
    delta = falling["methods"]["fs2"]["delta_vs_none"]
    assert not delta["significant"] and delta["not_converged"]
    assert _ci_text(delta).endswith("(not converged)") and "**" not in _ci_text(delta)
    assert not still_falling(None, 40)


class TestModeratedVariance:
    """Issue 33 item 5: each family's variances are moderated (Smyth 2004's empirical Bayes), so
    an interval's width does not turn on one row's 7-degree-of-freedom variance."""

    def test_digamma_and_trigamma_against_closed_forms_and_recurrences(self):
        from event_transforms.tactile.stats import digamma, trigamma

        gamma = 0.5772156649015329
        assert digamma(1.0) == pytest.approx(-gamma, abs=1e-12)
        assert digamma(0.5) == pytest.approx(-gamma - 2 * math.log(2), abs=1e-12)
        assert trigamma(1.0) == pytest.approx(math.pi ** 2 / 6, abs=1e-11)
        assert trigamma(0.5) == pytest.approx(math.pi ** 2 / 2, abs=1e-11)
        for x in (0.05, 0.7, 3.3, 12.0, 250.0):
            assert digamma(x + 1) == pytest.approx(digamma(x) + 1 / x, rel=1e-12, abs=1e-12)
            assert trigamma(x + 1) == pytest.approx(trigamma(x) - 1 / x ** 2, rel=1e-10, abs=1e-14)
        with pytest.raises(ValueError, match="x must be > 0"):
            digamma(0.0)
        with pytest.raises(ValueError, match="x must be > 0"):
            trigamma(-1.0)

    def test_variance_prior_recovers_the_prior_it_was_drawn_from(self):
        """Row variances σ² with 1/σ² ~ χ²(d₀) / (d₀ s₀²), sample variances s² ~ σ² χ²(d) / d: the
        moment estimates come back (4,000 rows)."""
        import random

        from event_transforms.tactile.stats import variance_prior

        rng = random.Random(0)
        d0, s0, d = 6.0, 2.5, 7
        chi2 = lambda k: 2.0 * rng.gammavariate(k / 2.0, 1.0)  # noqa: E731
        variances = [(d0 * s0 / chi2(d0)) * chi2(d) / d for _ in range(4000)]
        prior = variance_prior(variances, d)
        assert prior["rows"] == 4000
        assert prior["df"] == pytest.approx(d0, rel=0.15)
        assert prior["s2"] == pytest.approx(s0, rel=0.05)

    def test_variance_prior_edge_cases(self):
        from event_transforms.tactile.stats import variance_prior

        assert variance_prior([1.0], 7) is None
        assert variance_prior([1.0, 0.0, float("nan")], 7) is None  # zeros and NaN are left out
        same = variance_prior([2.0, 2.0, 2.0], 7)
        assert same["df"] == 14.0  # no scatter beyond sampling: the cap, (rows - 1) x df
        with pytest.raises(ValueError, match="df must be a positive int, got 0"):
            variance_prior([1.0, 2.0], 0)
        with pytest.raises(ValueError, match="df must be a positive int, got True"):
            variance_prior([1.0, 2.0], True)

    def test_the_moderated_interval_by_hand(self):
        from event_transforms.tactile.stats import paired_delta, student_t_quantile

        seeds = list(range(8))
        none = [2.0] * 8
        method = [1.0, 1.4, 0.8, 1.2, 1.1, 0.7, 1.3, 0.9]
        prior = {"df": 10.0, "s2": 0.5, "rows": 3}
        delta = paired_delta({"seeds": seeds, "x": none}, {"seeds": seeds, "x": method}, "x", 4, prior)
        diffs = [m - 2.0 for m in method]
        mean = sum(diffs) / 8
        s2 = sum((d - mean) ** 2 for d in diffs) / 7
        moderated = (10.0 * 0.5 + 7 * s2) / 17.0
        half = student_t_quantile(1 - 0.05 / 8, 17.0) * math.sqrt(moderated / 8)
        assert delta["ci_family"] == pytest.approx([mean - half, mean + half])
        assert delta["sd"] == pytest.approx(math.sqrt(moderated)) and delta["sd_raw"] == pytest.approx(math.sqrt(s2))
        assert delta["variance_prior"] == prior
        plain = paired_delta({"seeds": seeds, "x": none}, {"seeds": seeds, "x": method}, "x", 4)
        assert plain["sd"] == pytest.approx(math.sqrt(s2)) and plain["variance_prior"] is None

    METHODS = {"none": {"seeds": list(range(8)), "x": [2.0, 2.1, 1.9, 2.05, 2.0, 1.95, 2.1, 2.0]},
               "a": {"seeds": list(range(8)), "x": [1.0, 1.3, 0.8, 1.2, 1.1, 0.7, 1.3, 0.9]},
               "b": {"seeds": list(range(8)), "x": [2.2, 2.0, 2.4, 1.9, 2.3, 2.1, 1.8, 2.5]},
               "c": {"seeds": list(range(8)), "x": [2.0, 2.1, 1.9, 2.05, 2.0, 1.95, 2.1, 2.01]}}

    def test_rules_version_1_moderates_a_family_with_its_own_prior(self):
        from event_transforms.tactile.protocol.rules import RULES_V1
        from event_transforms.tactile.stats import deltas_vs_none, family_prior

        methods = self.METHODS
        out = deltas_vs_none(methods, "x", rules=RULES_V1)
        prior = family_prior(methods["none"], {k: v for k, v in methods.items() if k != "none"}, "x", rules=RULES_V1)
        assert all(d["variance_prior"] == prior for d in out.values())
        # every row's spread moves toward the family's: none is taken at its own 7 degrees of freedom
        for name in "abc":
            low, high = sorted((out[name]["sd_raw"], math.sqrt(prior["s2"])))
            assert low < out[name]["sd"] < high, name
            assert "borderline" in out[name] and len(out[name]["blocks"]) == 2  # version 1's block rule

    def test_rules_version_2_keeps_each_rows_own_variance(self):
        """Each row's own paired t at level 1 − 0.05/m, by hand; no prior, no blocks, no borderline."""
        from event_transforms.tactile.stats import deltas_vs_none, paired_t

        methods = self.METHODS
        out = deltas_vs_none(methods, "x")
        for name in "abc":
            delta = out[name]
            assert delta["variance_prior"] is None and delta["sd"] == pytest.approx(delta["sd_raw"])
            assert "borderline" not in delta and "blocks" not in delta
            test = paired_t(methods["none"]["x"], methods[name]["x"], level=1 - 0.05 / 3)
            assert delta["ci_family"] == pytest.approx(list(test.ci))
            assert delta["t_p_family"] == pytest.approx(min(1.0, 3 * test.t_p_value))
            assert delta["significant"] == (test.ci[1] < 0 or test.ci[0] > 0)

    def test_a_prior_from_fewer_rows_than_the_rules_allow_is_none(self):
        import dataclasses

        from event_transforms.tactile.protocol.rules import RULES_V1
        from event_transforms.tactile.stats import family_prior

        rows = {k: v for k, v in self.METHODS.items() if k != "none"}
        four = dataclasses.replace(RULES_V1, prior_min_rows=4)
        assert family_prior(self.METHODS["none"], rows, "x", rules=RULES_V1)["rows"] == 3
        assert family_prior(self.METHODS["none"], rows, "x", rules=four) is None


class TestConvergenceOfTheEnsemble:
    def test_holdout_drop_of_the_mean_curve(self):
        from event_transforms.tactile.stats import converged, holdout_drop

        flat = {"steps": [10, 20, 30, 40], "mse": [4.0, 2.0, 2.0, 2.0]}
        falling = {"steps": [10, 20, 30, 40], "mse": [4.0, 2.0, 2.0, 1.6]}
        # 1 of 2 members still falling by 20 %: the mean falls by 10 %, past the 5 % tolerance
        assert holdout_drop([flat, falling], 40) == pytest.approx(0.1)
        assert not converged(holdout_drop([flat, falling], 40))
        assert holdout_drop([flat, flat, flat, flat, falling], 40) == pytest.approx(0.04)
        assert converged(holdout_drop([flat, flat, flat, flat, falling], 40))
        assert holdout_drop([None, {}], 40) is None and converged(None)
        assert holdout_drop([{"steps": [40], "mse": [1.0]}], 40) is None  # no check in the first 3/4
        with pytest.raises(ValueError, match="share their check steps"):
            holdout_drop([flat, {"steps": [5, 20, 30, 40], "mse": [1, 1, 1, 1]}], 40)

    def test_half_the_members_falling_hard_is_not_converged(self):
        """The old rule (more than half the members still falling) called this converged."""
        from event_transforms.tactile.benchmark_scenes import get_scene
        from event_transforms.tactile.stats import summarize_scene

        def runs(values, falling):
            out = []
            for s, v in enumerate(values):
                last = 1.0 if (falling and s % 2) else 2.45
                out.append({"seed": s, "test_mse": v, "val_mse": v, "test_mse_paper_split": v,
                            "val_mse_paper_split": v, "best_step": 40, "holdout_mse": 1.0,
                            "holdout_history": {"steps": [10, 20, 30, 40], "mse": [4.0, 3.0, 2.5, last]},
                            "steps": 40, "copies": 1, "train_items": 6, "aug_s_once": 0.0, "aug_s_per_epoch": 0.0,
                            "train_s": 1.0, "test_phase_mse": {"grasp": v, "hold": v, "release": v}})
            return out

        none, better = [2.0, 2.1, 2.2, 2.05, 2.15, 2.0], [1.0, 1.1, 1.2, 1.05, 1.15, 1.0]
        out = summarize_scene(get_scene("timing"), {"none": runs(none, True), "fs2": runs(better, False)}, {}, {})
        assert out["methods"]["none"]["still_falling"] == 0.5
        assert out["methods"]["none"]["holdout_drop"] > 0.05 and not out["methods"]["none"]["converged"]
        assert out["methods"]["fs2"]["delta_vs_none"]["not_converged"]

    def test_only_the_side_behind_withholds_a_verdict(self):
        """``none`` still falling withholds "better" (it may catch up) but not "worse"."""
        from event_transforms.tactile.benchmark_scenes import get_scene
        from event_transforms.tactile.stats import behind_unconverged, summarize_scene

        def runs(values, falling):
            last = 1.0 if falling else 2.45
            return [{"seed": s, "test_mse": v, "val_mse": v, "test_mse_paper_split": v, "val_mse_paper_split": v,
                     "best_step": 40, "holdout_mse": 1.0,
                     "holdout_history": {"steps": [10, 20, 30, 40], "mse": [4.0, 3.0, 2.5, last]},
                     "steps": 40, "copies": 1, "train_items": 6, "aug_s_once": 0.0, "aug_s_per_epoch": 0.0,
                     "train_s": 1.0, "test_phase_mse": {"grasp": v, "hold": v, "release": v}} for s, v in enumerate(values)]

        none = [2.0, 2.1, 2.2, 2.05, 2.15, 2.0]
        worse, better = [v + 1.0 for v in none], [v - 1.0 for v in none]
        worse[0] += 0.01
        better[0] += 0.01
        out = summarize_scene(get_scene("timing"), {"none": runs(none, True), "fs2": runs(worse, False),
                                                     "tes2:0.5": runs(better, False)}, {}, {})
        assert out["methods"]["fs2"]["delta_vs_none"]["significant"]
        assert not out["methods"]["fs2"]["delta_vs_none"].get("not_converged")
        assert out["methods"]["tes2:0.5"]["delta_vs_none"]["not_converged"]
        assert behind_unconverged(0.0, True, False) and not behind_unconverged(0.0, True, True)
