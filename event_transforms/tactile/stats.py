"""Paired statistics for comparing training methods over seeds (pure Python, no SciPy).

The protocol trains every method with the same seeds (same initial weights and data
order), so methods are compared pairwise, seed by seed:

- :func:`paired_t` — mean difference, sample standard deviation, the 95 % (or other)
  Student-t confidence interval of the mean difference, and the two-sided t-test p-value;
- :func:`wilcoxon_signed_rank` — the exact two-sided signed-rank p-value (zero differences
  dropped, tied magnitudes given their average rank, the null distribution counted exactly);
- :func:`holm` — Holm's step-down adjustment of a family of p-values;
- :func:`welch_interval` and :func:`correlation` — the unpaired interval and the correlation of
  the per-seed values, reported beside the paired interval to show what pairing bought;
- :func:`summarize_scene` — one scene's entry of a protocol's ``results.json``: per method
  the per-seed values and Δ vs ``none``; policy rows also Δ vs the scene's matched row.

**What the intervals cover, and the significance rule.** The rules are those of
:data:`~event_transforms.tactile.protocol.rules.RULES` (a version recorded by every result;
every function here that decides takes ``rules=`` to apply another version). Seeds vary the
initial weights, the batch order and the augmentation draws; on the simulated scenes each seed
also trains and is scored on its own data set (fresh per seed), so an interval covers training
randomness and new data sets from the simulator; on a folder of recordings (no new data) each
seed reads its own bootstrap resample, and an interval covers resamples of that one data set. One family per scene: its methods' Δ vs
``none``, a row that is bit-identical per seed to an earlier row (a *duplicate*, shown as
"= row X") excluded. The interval shown is the family-wise one, Bonferroni: the paired
t-interval at level 1 − α/m for a family of m (α = 0.05), with each row's own variance in rules
version 2 (its family-wise error measured at or below α by ``benchmarks/tactile/familywise_error.py``);
version 1 *moderated* it (:func:`variance_prior`, Smyth's empirical Bayes), which that Monte
Carlo measured above α with one noisy row. A Δ is significant (bold) exactly when that interval
excludes 0 (m × the t-test's p ≤ α) and the side behind converged (:func:`holdout_drop` of each
ensemble's mean hold-out curve); version 1 also asked its direction to hold in each half of the
seeds (:func:`replicated`, "borderline" otherwise), a rule that vetoed no verdict in that Monte
Carlo. Holm's p-values are kept in ``results.json`` beside them. The exact Wilcoxon p of n
pairs cannot go below 2 / 2**n, m times that after the family adjustment; where that floor is
above α the test cannot reach significance and the table says so.

With n pairs the exact signed-rank p-value cannot go below 2 / 2**n (0.0625 for 5 seeds,
0.002 for 10), whatever the data: a method can only be called significant by that test
with enough seeds.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .distributions import _trigamma_inverse, digamma, student_t_cdf, student_t_quantile, trigamma

if TYPE_CHECKING:
    from .protocol.rules import Rules
    from .benchmark_scenes import BenchmarkScene

__all__ = [
    "student_t_cdf",
    "student_t_quantile",
    "PairedTest",
    "paired_t",
    "wilcoxon_signed_rank",
    "holm",
    "still_falling",
    "holdout_drop",
    "converged",
    "ensemble_drop",
    "behind_unconverged",
    "digamma",
    "trigamma",
    "variance_prior",
    "family_prior",
    "seed_blocks",
    "replicated",
    "STILL_FALLING",
    "welch_interval",
    "correlation",
    "mean_sd",
    "significant",
    "wilcoxon_floor",
    "duplicates",
    "paired_delta",
    "deltas_vs_none",
    "scene_deltas",
    "summarize_scene",
    "current_rules",
]


@dataclass(frozen=True)
class PairedTest:
    """Mean of the paired differences ``b - a`` with its interval and tests.

    ``ci`` is ``None`` and the p-values NaN with fewer than two pairs (no spread to
    estimate); ``sd`` is then NaN too.
    """

    n: int
    mean: float
    sd: float
    ci: tuple[float, float] | None
    t_p_value: float
    wilcoxon_p_value: float


def paired_t(a: Sequence[float], b: Sequence[float], *, level: float = 0.95) -> PairedTest:
    """Paired comparison of ``b`` against ``a`` (e.g. a method's test MSE against ``none``'s).

    Example:
        >>> test = paired_t([10.0, 11.0, 9.5, 10.5, 10.2], [9.0, 10.1, 9.0, 9.4, 9.5])
        >>> round(test.mean, 2), [round(v, 3) for v in test.ci], round(test.t_p_value, 4)
        (-0.84, [-1.139, -0.541], 0.0015)
        >>> test.wilcoxon_p_value  # 5 pairs, all negative: the smallest possible value
        0.0625
    """
    if len(a) != len(b):
        raise ValueError(f"a and b must pair up, got {len(a)} and {len(b)} values")
    diffs = [float(y) - float(x) for x, y in zip(a, b)]
    n = len(diffs)
    if n == 0:
        raise ValueError("need at least one pair, got none")
    mean = sum(diffs) / n
    if n < 2:
        return PairedTest(n, mean, math.nan, None, math.nan, math.nan)
    sd = math.sqrt(sum((d - mean) ** 2 for d in diffs) / (n - 1))
    half = student_t_quantile(0.5 + level / 2.0, n - 1) * sd / math.sqrt(n)
    if sd == 0.0:
        p = 1.0 if mean == 0.0 else 0.0
    else:
        t = mean / (sd / math.sqrt(n))
        p = 2.0 * (1.0 - student_t_cdf(abs(t), n - 1))
    return PairedTest(n, mean, sd, (mean - half, mean + half), min(1.0, p), wilcoxon_signed_rank(diffs))


def variance_prior(variances: Sequence[float], df: int) -> dict[str, float] | None:
    """The scaled-χ² prior of a family's variances (Smyth 2004, *Linear models and empirical
    Bayes methods for assessing differential expression*, section 6.2): each row's sample
    variance s² (``df`` degrees of freedom) is taken as a draw around a common s₀² with prior
    degrees of freedom d₀, both estimated from the moments of log s².

    A row's moderated variance is then (d₀ s₀² + df s²) / (d₀ + df), with d₀ + df degrees of
    freedom (:func:`paired_delta`): 8 seeds give each row's variance only 7 degrees of freedom,
    so its interval's width moves a lot from run to run; the family's other rows steady it as
    far as their variances agree. d₀ is capped at the degrees of freedom the other rows hold,
    ``(rows - 1) × df``, reached when the variances scatter no more than sampling explains
    (full pooling). Rows with a variance of 0 or not finite are left out.

    Returns:
        ``{"df": d₀, "s2": s₀², "rows": the rows used}``, or ``None`` with fewer than 2 rows.

    Example:
        >>> prior = variance_prior([1.0, 1.2, 0.8, 1.1, 0.9], 7)  # no more scatter than sampling
        >>> prior["df"], round(prior["s2"], 3), prior["rows"]
        (28.0, 1.109, 5)
        >>> round(variance_prior([0.1, 1.0, 10.0, 100.0], 7)["df"], 2)  # far apart: little weight
        0.73
    """
    if isinstance(df, bool) or not isinstance(df, int) or df < 1:
        raise ValueError(f"df must be a positive int, got {df!r}")
    used = [float(v) for v in variances if v is not None and math.isfinite(float(v)) and float(v) > 0]
    rows = len(used)
    if rows < 2:
        return None
    half = df / 2.0
    logs = [math.log(v) - digamma(half) + math.log(half) for v in used]
    mean = statistics.fmean(logs)
    excess = statistics.variance(logs) - trigamma(half)
    cap = float((rows - 1) * df)
    d0 = cap if excess <= 0 else min(2.0 * _trigamma_inverse(excess), cap)
    s2 = math.exp(mean + digamma(d0 / 2.0) - math.log(d0 / 2.0))
    return {"df": d0, "s2": s2, "rows": rows}


def wilcoxon_signed_rank(differences: Sequence[float]) -> float:
    """Exact two-sided p-value of the Wilcoxon signed-rank test of ``differences``.

    Zero differences are dropped (Wilcoxon's convention); tied magnitudes share their
    average rank, and the null distribution of the positive rank sum is counted exactly
    over all 2**n sign patterns (by dynamic programming on doubled ranks). Returns 1.0
    when every difference is zero.

    Example:
        >>> wilcoxon_signed_rank([-1.2, -0.4, -0.9, -1.6, -0.2, 0.3, -0.7, -1.1, -0.5, -0.8])
        0.005859375
    """
    values = [float(d) for d in differences if float(d) != 0.0]
    n = len(values)
    if n == 0:
        return 1.0
    order = sorted(range(n), key=lambda i: abs(values[i]))
    doubled = [0] * n  # 2 × rank: integers even with average ranks of ties
    start = 0
    while start < n:
        stop = start
        while stop + 1 < n and abs(values[order[stop + 1]]) == abs(values[order[start]]):
            stop += 1
        for k in range(start, stop + 1):
            doubled[order[k]] = start + stop + 2  # (start + 1 + stop + 1) = 2 × average rank
        start = stop + 1
    observed = sum(r for r, v in zip(doubled, values) if v > 0)
    counts = [0] * (sum(doubled) + 1)
    counts[0] = 1
    for r in doubled:
        for s in range(len(counts) - 1, r - 1, -1):
            counts[s] += counts[s - r]
    total = 2**n
    lower = sum(counts[: observed + 1]) / total
    upper = sum(counts[observed:]) / total
    return min(1.0, 2.0 * min(lower, upper))


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values (same order as given; NaN stays NaN).

    Example:
        >>> holm([0.01, 0.04, 0.03])
        [0.03, 0.06, 0.06]
    """
    indexed = [(p, i) for i, p in enumerate(p_values) if not math.isnan(p)]
    indexed.sort()
    m = len(indexed)
    adjusted = [math.nan] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(indexed):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[i] = running
    return adjusted


def welch_interval(a: Sequence[float], b: Sequence[float], *, level: float = 0.95) -> tuple[float, float] | None:
    """The unpaired (Welch) ``level`` interval of ``mean(b) - mean(a)``, ignoring any pairing.

    Standard error ``sqrt(s_a²/n_a + s_b²/n_b)``, Welch–Satterthwaite degrees of freedom;
    ``None`` with fewer than two values on either side. Beside the paired interval it shows
    what the pairing buys: the two agree when paired runs share no noise.

    Example:
        >>> lo, hi = welch_interval([1.0, 2.0, 3.0], [2.0, 3.0, 4.0])
        >>> round(lo, 3), round(hi, 3)
        (-1.267, 3.267)
    """
    a, b = [float(v) for v in a], [float(v) for v in b]
    if len(a) < 2 or len(b) < 2:
        return None
    va, vb = statistics.variance(a) / len(a), statistics.variance(b) / len(b)
    mean = statistics.fmean(b) - statistics.fmean(a)
    se = math.sqrt(va + vb)
    if se == 0:
        return (mean, mean)
    df = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))
    half = student_t_quantile(0.5 + level / 2, df) * se
    return (mean - half, mean + half)


def correlation(a: Sequence[float], b: Sequence[float]) -> float:
    """Pearson's correlation of paired values (NaN with fewer than 3 pairs or no spread).

    Example:
        >>> round(correlation([1.0, 2.0, 3.0], [2.0, 4.1, 5.9]), 4)
        0.999
    """
    a, b = [float(v) for v in a], [float(v) for v in b]
    if len(a) != len(b):
        raise ValueError(f"a and b must have the same length, got {len(a)} and {len(b)}")
    if len(a) < 3:
        return math.nan
    ma, mb = statistics.fmean(a), statistics.fmean(b)
    sab = sum((x - ma) * (y - mb) for x, y in zip(a, b))
    saa, sbb = sum((x - ma) ** 2 for x in a), sum((y - mb) ** 2 for y in b)
    return sab / math.sqrt(saa * sbb) if saa > 0 and sbb > 0 else math.nan


# --------------------------------------------------------------------------- protocol summaries


def current_rules(rules: Rules | None = None) -> Rules:
    """``rules``, or the protocol's current :data:`~event_transforms.tactile.protocol.rules.RULES`.

    (Read when called: the protocol package imports this module.)

    Example:
        >>> current_rules().version
        '2'
    """
    if rules is not None:
        return rules
    from .protocol.rules import RULES

    return RULES


def significant(delta: dict[str, Any] | None, alpha: float | None = None) -> bool:
    """The family-wise interval (``ci_family``: the paired t-interval at level 1 − α/m)
    excludes 0 (equivalently: m × the t-test's p ≤ α) and the side behind had converged (no
    ``not_converged``); a Δ judged by rules version 1 must also not be ``borderline``
    (:func:`replicated`). Results without a family interval (older files) fall back to the
    unadjusted 95 % interval with the Holm-corrected p at ``alpha`` (default: the rules' α).
    """
    alpha = current_rules().alpha if alpha is None else alpha
    if not delta or delta.get("not_converged"):  # the models had not converged: no resolved verdict
        return False
    if delta.get("borderline"):  # rules version 1: excludes 0 over all seeds but not in each block alone
        return False
    ci = delta.get("ci_family")
    if ci is not None:
        return bool(ci[1] < 0 or ci[0] > 0)
    if not delta.get("ci95"):
        return False
    lo, hi = delta["ci95"]
    p = delta.get("t_p_holm")
    return bool((hi < 0 or lo > 0) and p is not None and not math.isnan(p) and p <= alpha)


#: The convergence tolerance of rules version 2 (``RULES.convergence_tolerance``; the functions
#: read the rules themselves, this name stays for readers of earlier releases).
STILL_FALLING = 0.05


def still_falling(history: dict[str, Any] | None, steps: int, *, tolerance: float | None = None,
                  rules: Rules | None = None) -> bool:
    """Whether a member's hold-out MSE was still falling at the step cap: its last check is more
    than ``tolerance`` (relative; default the rules' ``convergence_tolerance``) below its best
    check in the first three quarters (the rules' ``convergence_window``) of the run.
    A member without a history (no hold-out set) is not judged (``False``). Shown per member;
    the verdicts use the ensemble's mean curve (:func:`holdout_drop`).

    Example:
        >>> still_falling({"steps": [100, 200, 300, 400], "mse": [4.0, 3.0, 2.9, 2.0]}, 400)
        True
        >>> still_falling({"steps": [100, 200, 300, 400], "mse": [4.0, 3.0, 2.9, 2.85]}, 400)
        False
    """
    rules = current_rules(rules)
    tolerance = rules.convergence_tolerance if tolerance is None else tolerance
    if not history or not history.get("mse"):
        return False
    pairs = [(s_, m) for s_, m in zip(history["steps"], history["mse"]) if m is not None and math.isfinite(m)]
    early = [m for s_, m in pairs if s_ <= rules.convergence_window * steps]
    if not early or not pairs:
        return False
    return pairs[-1][1] < (1.0 - tolerance) * min(early)


def holdout_drop(histories: Sequence[dict[str, Any] | None], steps: int, *, rules: Rules | None = None) -> float | None:
    """How far an ensemble's mean hold-out MSE fell in the last quarter of its run: 1 − (the
    mean over members at the last check) / (the lowest mean at a check in the first three
    quarters, the rules' ``convergence_window``). Above the rules' ``convergence_tolerance`` the
    ensemble was still falling at the step cap: its models had not converged, and no Δ of theirs
    is printed as resolved.

    The mean curve is judged, not a count of members: with 8 members the share of members
    still falling moves by 1/8 when one member's curve crosses the tolerance, and a rule on
    it turned with the CPU's kernel set (4 of 8 members on one run, 6 of 8 on the rerun).
    ``None`` without histories (no hold-out set) or without a check in the first three quarters.

    Example:
        >>> hist = [{"steps": [100, 200, 300, 400], "mse": [4.0, 3.0, 2.9, 2.0]},
        ...         {"steps": [100, 200, 300, 400], "mse": [4.0, 3.0, 2.9, 3.0]}]
        >>> round(holdout_drop(hist, 400), 3)
        0.138
    """
    curves = [h for h in histories if h and h.get("mse")]
    if not curves:
        return None
    length = min(len(h["mse"]) for h in curves)
    checks = list(curves[0]["steps"][:length])
    if any(list(h["steps"][:length]) != checks for h in curves):
        raise ValueError("histories must share their check steps")
    mean = [statistics.fmean(float(h["mse"][i]) for h in curves) for i in range(length)]
    window = current_rules(rules).convergence_window
    early = [m for s_, m in zip(checks, mean) if s_ <= window * steps and math.isfinite(m)]
    if not early or not math.isfinite(mean[-1]) or min(early) <= 0:
        return None
    return 1.0 - mean[-1] / min(early)


def converged(drop: float | None, *, tolerance: float | None = None, rules: Rules | None = None) -> bool:
    """Whether an ensemble with this :func:`holdout_drop` had converged (``None``: not judged):
    the drop is at most ``tolerance`` (default the rules' ``convergence_tolerance``).

    Example:
        >>> converged(0.03), converged(0.12), converged(None)
        (True, False, True)
    """
    tolerance = current_rules(rules).convergence_tolerance if tolerance is None else tolerance
    return drop is None or drop <= tolerance


def ensemble_drop(runs: Sequence[dict[str, Any]], *, rules: Rules | None = None) -> float | None:
    """:func:`holdout_drop` of one ensemble's member records (``holdout_history``, ``steps``);
    ``None`` for no records.

    Example:
        >>> runs = [{"steps": 400, "holdout_history": {"steps": [100, 200, 300, 400], "mse": [4.0, 3.0, 3.0, 2.7]}}]
        >>> round(ensemble_drop(runs), 3), converged(ensemble_drop(runs)), ensemble_drop([])
        (0.1, False, None)
    """
    if not runs:
        return None
    return holdout_drop([r.get("holdout_history") for r in runs], runs[0]["steps"], rules=rules)


def behind_unconverged(mean: float, reference_converged: bool, method_converged: bool) -> bool:
    """Whether a Δ (method − reference) could close with more training: the side that is behind
    (the reference where the method is better, Δ < 0; the method where it is worse) had not
    converged. The side ahead still falling would only widen the gap, so its state does not
    withhold the verdict; each verdict turns on one ensemble's convergence, not two.

    Example:
        >>> behind_unconverged(-1.0, reference_converged=False, method_converged=True)  # none may catch up
        True
        >>> behind_unconverged(+1.0, reference_converged=False, method_converged=True)  # the gap only grows
        False
    """
    if mean < 0:
        return not reference_converged
    if mean > 0:
        return not method_converged
    return not (reference_converged and method_converged)


def wilcoxon_floor(n: int, family: int = 1) -> float:
    """The smallest family-adjusted exact Wilcoxon p of ``n`` pairs: min(1, m · 2 / 2**n).

    Example:
        >>> wilcoxon_floor(8, 12)
        0.09375
    """
    return min(1.0, family * 2.0 / 2.0**n) if n > 0 else 1.0


def duplicates(methods: dict[str, Any], key: str = "test_mse") -> dict[str, str]:
    """Rows bit-identical per seed to an earlier row: name -> the earlier row's name.

    Example:
        >>> duplicates({"none": {"seeds": [0, 1], "test_mse": [1.0, 2.0]},
        ...             "stretch": {"seeds": [0, 1], "test_mse": [0.5, 0.7]},
        ...             "inferred": {"seeds": [0, 1], "test_mse": [0.5, 0.7]}})
        {'inferred': 'stretch'}
    """
    seen: dict[tuple, str] = {}
    out = {}
    for name, method in methods.items():
        signature = (tuple(method["seeds"]), tuple(float(v) for v in method[key]))
        if signature in seen:
            out[name] = seen[signature]
        else:
            seen[signature] = name
    return out


def seed_blocks(first: Sequence[float], second: Sequence[float]) -> list[dict[str, Any]]:
    """The paired Δ (``second − first``) in two blocks of seeds, the first half and the rest
    (in the order given: by seed), each with its own unadjusted paired 95 % t-interval (rules
    version 1's block rule; version 2 has none).

    A block of fewer than 2 pairs has no interval (``ci95`` is ``None``).

    Example:
        >>> [b["mean"] for b in seed_blocks([1.0, 1.0, 1.0, 1.0], [0.0, 0.5, 0.2, 0.4])]
        [-0.75, -0.7]
    """
    pairs = list(zip(first, second))
    half = len(pairs) // 2
    out: list[dict[str, Any]] = []
    for block in (pairs[:half], pairs[half:]):
        if not block:
            out.append({"n": 0, "mean": math.nan, "ci95": None})
            continue
        test = paired_t([a for a, _ in block], [b for _, b in block])
        out.append({"n": test.n, "mean": test.mean, "ci95": list(test.ci) if test.ci is not None else None})
    return out


def replicated(mean: float, blocks: Sequence[dict[str, Any]]) -> bool:
    """Whether a Δ of sign ``mean`` shows in every block of seeds on its own: each block's mean
    Δ lies on the side of ``mean`` (:func:`seed_blocks`).

    Rules version 1's "perturbation the run makes itself": a verdict whose direction did not
    hold in each half of its seeds read "borderline". It is no perturbation: the halves are the
    same seeds, and once the family interval over all seeds excludes 0 the halves' means almost
    never disagree (``benchmarks/tactile/familywise_error.md``: it vetoed no verdict). Version 2 drops it
    (``rules.replication == "none"``); this function stays to recompute version-1 tables.

    Example:
        >>> replicated(-0.7, [{"mean": -0.6}, {"mean": -0.8}])
        True
        >>> replicated(-0.7, [{"mean": -1.5}, {"mean": 0.1}])
        False
    """
    if not blocks or mean == 0 or math.isnan(mean):
        return False
    return all(block.get("mean") is not None and not math.isnan(block["mean"]) and block["mean"] * mean > 0
               for block in blocks)


def _moderated(diffs: Sequence[float], level: float, prior: dict[str, float] | None) -> PairedTest:
    """:func:`paired_t` of the differences, with the moderated variance when ``prior`` is given:
    (d₀ s₀² + (n − 1) s²) / (d₀ + n − 1) on d₀ + n − 1 degrees of freedom (:func:`variance_prior`)."""
    zeros = [0.0] * len(diffs)
    plain = paired_t(zeros, diffs, level=level)
    if prior is None or plain.n < 2:
        return plain
    df = plain.n - 1
    total = prior["df"] + df
    sd = math.sqrt((prior["df"] * prior["s2"] + df * plain.sd ** 2) / total)
    se = sd / math.sqrt(plain.n)
    half = student_t_quantile(0.5 + level / 2.0, total) * se
    p = 2.0 * (1.0 - student_t_cdf(abs(plain.mean) / se, total)) if se > 0 else (1.0 if plain.mean == 0 else 0.0)
    return PairedTest(plain.n, plain.mean, sd, (plain.mean - half, plain.mean + half), min(1.0, p),
                      plain.wilcoxon_p_value)


def paired_delta(reference: dict[str, Any], method: dict[str, Any], key: str, family: int,
                 prior: dict[str, float] | None = None, *, rules: Rules | None = None) -> dict[str, Any] | None:
    """Δ of ``key`` (method − reference) paired by seed, with the family-wise interval at the
    rules' level 1 − α/``family`` (``ci_family``) and the unadjusted one (``ci95``).

    With ``prior`` (:func:`variance_prior` of the scene's family; rules version 1) the intervals
    and t p-values are moderated t (the row's variance shrunk toward the family's, on d₀ + n − 1
    degrees of freedom); ``sd_raw`` keeps the row's own standard deviation. With the rules'
    ``replication == "halves"`` (version 1) the Δ also records its two ``blocks`` of seeds and
    whether it is ``borderline``; version 2 records neither.

    Example:
        >>> none = {"seeds": [0, 1, 2, 3], "x": [2.0, 2.2, 2.1, 2.3]}
        >>> delta = paired_delta(none, {"seeds": [0, 1, 2, 3], "x": [1.0, 1.3, 1.1, 1.2]}, "x", 2)
        >>> round(delta["mean"], 2), [round(v, 2) for v in delta["ci_family"]], "borderline" in delta
        (-1.0, [-1.17, -0.83], False)
    """
    rules = current_rules(rules)
    base = dict(zip(reference["seeds"], reference[key]))
    pairs = [(base[s], v) for s, v in zip(method["seeds"], method[key]) if s in base]
    if not pairs:
        return None
    first, second = [a for a, _ in pairs], [b for _, b in pairs]
    diffs = [float(b) - float(a) for a, b in pairs]
    test = _moderated(diffs, rules.unadjusted_level, prior)
    wide = _moderated(diffs, rules.level(family), prior) if test.ci is not None else test
    welch = welch_interval(first, second, level=rules.unadjusted_level)
    family_ci = list(wide.ci) if wide.ci is not None else None
    replication: dict[str, Any] = {}
    if rules.replication == "halves":  # rules version 1: the seeds in two blocks, the direction in each
        blocks = seed_blocks(first, second)
        replication = {"blocks": blocks, "borderline": bool(
            family_ci is not None and (family_ci[1] < 0 or family_ci[0] > 0) and not replicated(test.mean, blocks))}
    return {
        "mean": test.mean,
        "ci95": list(test.ci) if test.ci is not None else None,
        "ci_family": family_ci,
        "sd": test.sd,
        "sd_raw": statistics.stdev(diffs) if len(diffs) > 1 else math.nan,
        "variance_prior": dict(prior) if prior is not None else None,
        **replication,
        "family_size": family,
        "p_value": test.wilcoxon_p_value,
        "t_p_value": test.t_p_value,
        "t_p_family": min(1.0, family * test.t_p_value) if not math.isnan(test.t_p_value) else math.nan,
        "p_family": min(1.0, family * test.wilcoxon_p_value) if not math.isnan(test.wilcoxon_p_value) else math.nan,
        "wilcoxon_floor": wilcoxon_floor(test.n, family),
        "n": test.n,
        "better_seeds": sum(b < a for a, b in pairs),
        "ci95_welch": list(welch) if welch is not None else None,
        "correlation": correlation(first, second),
    }


def family_prior(reference: dict[str, Any], methods: dict[str, Any], key: str, *,
                 rules: Rules | None = None) -> dict[str, float] | None:
    """:func:`variance_prior` of the paired Δ (each method − ``reference``, by seed) of
    ``methods``: the rows with the most common number of pairs, at least 2 pairs each; ``None``
    with fewer such rows than the rules' ``prior_min_rows``, or where the rules' variances are
    ``"raw"`` (version 2: no prior; pass ``rules=RULES_V1`` for version 1's).

    Example:
        >>> none = {"seeds": [0, 1, 2, 3], "x": [2.0, 2.2, 2.1, 2.3]}
        >>> rows = {"a": {"seeds": [0, 1, 2, 3], "x": [1.0, 1.3, 1.1, 1.2]},
        ...         "b": {"seeds": [0, 1, 2, 3], "x": [2.5, 2.6, 2.2, 2.9]}}
        >>> from event_transforms.tactile.protocol.rules import RULES_V1
        >>> family_prior(none, rows, "x", rules=RULES_V1)["rows"], family_prior(none, {"a": rows["a"]}, "x", rules=RULES_V1)
        (2, None)
        >>> family_prior(none, rows, "x") is None  # rules version 2: each row's own variance
        True
    """
    rules = current_rules(rules)
    if rules.variances == "raw" or rules.prior_min_rows is None:
        return None
    base = dict(zip(reference["seeds"], reference[key]))
    rows: list[list[float]] = []
    for method in methods.values():
        diffs = [float(v) - float(base[s]) for s, v in zip(method["seeds"], method[key]) if s in base]
        if len(diffs) >= 2:
            rows.append(diffs)
    if not rows:
        return None
    n = statistics.mode(len(r) for r in rows)
    prior = variance_prior([statistics.variance(r) for r in rows if len(r) == n], n - 1)
    return prior if prior is not None and prior["rows"] >= rules.prior_min_rows else None


def mean_sd(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (NaN for one value)."""
    values = [float(v) for v in values]
    return statistics.fmean(values), (statistics.stdev(values) if len(values) > 1 else math.nan)


def deltas_vs_none(methods: dict[str, Any], key: str, *, exclude: Sequence[str] = (),
                   rules: Rules | None = None) -> dict[str, dict[str, Any]]:
    """Δ of ``key`` vs ``none`` for every other method not in ``exclude`` (one family),
    paired seed by seed (:func:`paired_delta`): the paired t-interval unadjusted and
    family-wise (Bonferroni, the rules' level), the t and exact Wilcoxon p-values, raw,
    Holm-corrected and Bonferroni (``*_family``), the family's Wilcoxon floor; beside them the
    unpaired (Welch) interval and the correlation of the per-seed values, which say what the
    pairing bought.

    Under rules version 2 each row keeps its own variance; under version 1 (``rules=RULES_V1``)
    the variances are moderated with the family's own prior (:func:`family_prior`; every Δ keeps
    it as ``variance_prior``). ``methods`` maps a name to ``{"seeds": [...], key: [...]}``.

    Example:
        >>> methods = {"none": {"seeds": [0, 1, 2], "x": [2.0, 2.2, 2.1]},
        ...            "a": {"seeds": [0, 1, 2], "x": [1.0, 1.3, 1.1]}, "b": {"seeds": [0, 1, 2], "x": [2.1, 2.0, 2.4]}}
        >>> out = deltas_vs_none(methods, "x")
        >>> [round(v, 2) for v in out["a"]["ci_family"]], out["a"]["significant"], out["b"]["significant"]
        ([-1.17, -0.76], True, False)
    """
    rules = current_rules(rules)
    reference = methods.get("none")
    if reference is None:
        return {}
    family = [name for name in methods if name != "none" and name not in exclude]
    prior = family_prior(reference, {name: methods[name] for name in family}, key, rules=rules)
    out = {}
    for name in family:
        delta = paired_delta(reference, methods[name], key, len(family), prior, rules=rules)
        if delta is not None:
            out[name] = delta
    holm_w = holm([d["p_value"] for d in out.values()])
    holm_t = holm([d["t_p_value"] for d in out.values()])
    for (name, delta), pw, pt in zip(out.items(), holm_w, holm_t):
        delta["p_holm"], delta["t_p_holm"] = pw, pt
        delta["significant"] = significant(delta)
    return out


#: Policy rows compared with the scene's matched row too.
POLICY_ROWS = ("inferred", "prior", "everything")


def scene_deltas(methods: dict[str, Any], matched_methods: Sequence[str] = (), *,
                 rules: Rules | None = None) -> dict[str, dict[str, Any]]:
    """One scene's verdicts from its rows' per-seed values: per row the fields
    :func:`summarize_scene` records, ``duplicate_of`` (a row bit-identical per seed to an earlier
    one: no Δ of its own), ``delta_vs_none`` and ``delta_vs_none_paper_split`` (one family
    without the duplicates, :func:`deltas_vs_none`), and for the policy rows ``matched_row`` and
    ``delta_vs_matched`` (against ``matched`` where it ran, else the first of
    ``matched_methods`` that ran; the policy rows a family of their own). A Δ whose side behind
    had not converged (a row's ``converged``, default ``True``) is marked ``not_converged``.

    The table's verdicts are recomputed from the per-seed values with this function alone
    (:mod:`~event_transforms.tactile.protocol.recompute`). ``methods`` maps a name to
    ``{"seeds", "test_mse", "test_mse_paper_split", "converged"}`` and is not modified.

    Example:
        >>> rows = {"none": {"seeds": [0, 1, 2], "test_mse": [2.0, 2.2, 2.1]},
        ...         "fs1": {"seeds": [0, 1, 2], "test_mse": [1.0, 1.3, 1.1]},
        ...         "inferred": {"seeds": [0, 1, 2], "test_mse": [1.0, 1.3, 1.1]}}
        >>> out = scene_deltas(rows, ["fs1"])
        >>> round(out["fs1"]["delta_vs_none"]["mean"], 2), out["inferred"]["duplicate_of"], out["inferred"]["matched_row"]
        (-0.97, 'fs1', 'fs1')
    """
    rules = current_rules(rules)
    out: dict[str, dict[str, Any]] = {name: {"delta_vs_none": None, "delta_vs_none_paper_split": None}
                                      for name in methods}
    dupes = duplicates(methods)
    for name, original in dupes.items():
        out[name]["duplicate_of"] = original
    done = {name: bool(m.get("converged", True)) for name, m in methods.items()}
    for key, field_name in (("test_mse", "delta_vs_none"), ("test_mse_paper_split", "delta_vs_none_paper_split")):
        if not all(key in m for m in methods.values()):
            continue
        for name, delta in deltas_vs_none(methods, key, exclude=tuple(dupes), rules=rules).items():
            if behind_unconverged(delta["mean"], done.get("none", True), done[name]):  # more steps could close it
                delta["not_converged"] = True
                delta["significant"] = False
            out[name][field_name] = delta
    # the policy rows against the scene's matched row (the first matched method that ran)
    # (``matched``, every gap's matched augmentation, where the scene has two gaps or more)
    matched = next((m for m in ("matched", *matched_methods) if m in methods and m not in dupes), None)
    policies = [m for m in POLICY_ROWS if m in methods and m not in dupes and m != matched]
    matched_prior = (family_prior(methods[matched], {n: methods[n] for n in policies}, "test_mse", rules=rules)
                     if matched is not None else None)
    for name in policies:
        out[name]["matched_row"] = matched
        if matched is not None:
            vs = paired_delta(methods[matched], methods[name], "test_mse", len(policies), matched_prior, rules=rules)
            if vs is not None and behind_unconverged(vs["mean"], done[matched], done[name]):
                vs["not_converged"] = True
            out[name]["delta_vs_matched"] = vs
    for name in dupes:
        if name in POLICY_ROWS:
            out[name]["matched_row"] = matched
    return out


def summarize_scene(
    scene: BenchmarkScene, per_method: dict[str, list[dict[str, Any]]], baselines: dict[str, dict[str, float]],
    split_sizes: dict[str, int], *, rules: Rules | None = None,
) -> dict[str, Any]:
    """One scene's entry of ``results.json``: gaps, baselines, and per method the per-seed
    values and Δ vs ``none`` on test MSE (``delta_vs_none``) and on the paper's 6 + 6 split
    (``delta_vs_none_paper_split``), one family per scene without duplicate rows (a row
    bit-identical per seed to an earlier one gets ``duplicate_of`` and no Δ of its own);
    policy rows (``inferred``, ``prior``, ``everything``) also ``delta_vs_matched``, against
    the ``matched`` row where it ran (every gap's matched augmentation), else the scene's first
    matched method that ran (a family of their own). Judged by ``rules`` (default the protocol's
    current :data:`~event_transforms.tactile.protocol.rules.RULES`)."""
    rules = current_rules(rules)
    methods: dict[str, Any] = {}
    for name, runs in per_method.items():
        runs = sorted(runs, key=lambda r: r["seed"])
        methods[name] = {
            "seeds": [r["seed"] for r in runs],
            "test_mse": [r["test_mse"] for r in runs],
            "val_mse": [r["val_mse"] for r in runs],
            "test_mse_paper_split": [r["test_mse_paper_split"] for r in runs],
            "val_mse_paper_split": [r["val_mse_paper_split"] for r in runs],
            "best_step": [r.get("best_step") for r in runs],
            # members whose kept weights come from before the step cap (the stopping rule acted)
            "stopped_before_cap": statistics.fmean(
                1.0 if (r.get("best_step") is not None and r["best_step"] < r["steps"]) else 0.0 for r in runs
            ),
            "holdout_mse": [r.get("holdout_mse") for r in runs],
            # members whose hold-out MSE was still falling at the step cap (shown; not the rule)
            "still_falling": statistics.fmean(
                1.0 if still_falling(r.get("holdout_history"), r["steps"], rules=rules) else 0.0 for r in runs),
            # the ensemble's mean hold-out curve: its fall in the last quarter (the convergence rule)
            "holdout_drop": ensemble_drop(runs, rules=rules),
            "steps": runs[0]["steps"],
            "copies": runs[0]["copies"],
            "train_items": runs[0]["train_items"],
            "delta_vs_none": None,
            "delta_vs_none_paper_split": None,
            "aug_s_once": statistics.fmean(r["aug_s_once"] for r in runs),
            "aug_s_per_epoch": statistics.fmean(r["aug_s_per_epoch"] for r in runs),
            "train_s": statistics.fmean(r["train_s"] for r in runs),
            "test_phase_mse": {
                phase: statistics.fmean(r["test_phase_mse"][phase] for r in runs) for phase in ("grasp", "hold", "release")
            },
        }
    for name, m in methods.items():
        m["converged"] = converged(m["holdout_drop"], rules=rules)
    for name, fields in scene_deltas(methods, scene.matched_methods, rules=rules).items():
        methods[name].update(fields)
    return {
        "description": scene.description,
        "gaps": list(scene.gaps),
        "gap_sizes": {f: {k: [list(v) if isinstance(v, tuple) else v for v in pair] for k, pair in d.items()}
                      for f, d in scene.gap_sizes().items()},
        "matched_methods": list(scene.matched_methods),
        "split_sizes": dict(split_sizes),
        "baselines": baselines,
        "methods": methods,
    }
