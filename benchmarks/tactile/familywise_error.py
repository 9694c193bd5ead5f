"""The family-wise error of the protocol's intervals, measured by Monte Carlo under Δ = 0.

A scene's family is its rows' Δ vs one reference (``none``, or the matched row for the policy
rows), paired by seed: every row and the reference get a per-seed value, and the protocol's
Δ of a row is row − reference seed by seed (:func:`event_transforms.tactile.stats.deltas_vs_none`),
so the rows' Δ share the reference's noise and are correlated. A row is *declared* when its
family-wise interval excludes 0. With every true Δ equal to 0, the family-wise error is the
share of families in which at least one row is declared; a procedure at level 0.05 keeps it at
or below 0.05.

Configurations (8 seeds; the per-seed values normal, each row with its own spread):

- ``homogeneous``: every row and the reference with standard deviation 1;
- ``one row 4×``: one row with 4× the spread of the others;
- ``graded 1–4×``: the rows' spreads spaced geometrically from 1 to 4;
- ``reference 3×``: the reference with 3× the rows' spread (the rows' Δ strongly correlated);

each for families of 2–8 rows. Procedures:

- ``rules 1`` (as of e4ced10): Bonferroni over the family with Smyth's moderated variances, the
  prior fitted from the family's own rows (as few as two), its degrees of freedom capped at
  (rows − 1) · df; with and without the block rule (each half of the seeds on the same side);
- ``rules 2`` (:mod:`event_transforms.tactile.protocol.rules`): each row's own paired t,
  Bonferroni over the family (level 1 − 0.05/m). Under the complete null Holm's step-down rejects
  something exactly when Bonferroni does (its first step is Bonferroni's test), so the two share
  this error;
- ``moderated, prior from ≥ 4 rows``: the rules-1 procedure where the family has at least four
  rows, the raw t below (the other fix the issue names), for comparison.

Beside the error, the power: the share of families of ``homogeneous`` rows in which one row with
a true Δ of 2 (1.41 standard deviations of its per-seed Δ) is declared, the others null.

    python -m benchmarks.tactile.familywise_error [--families 20000] [--seed 0] [--quick] [--no-write]

It writes ``benchmarks/tactile/familywise_error.md``. Numpy only; vectorised over families.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from event_transforms.tactile.protocol.rules import RULES, RULES_VERSION
from event_transforms.tactile.stats import student_t_quantile

__all__ = [
    "KINDS", "ROWS", "spreads", "simulate", "declared_v1", "declared_raw", "declared_min_rows", "error_rates", "main",
]

ROOT = Path(__file__).resolve().parents[2]
OUTPUT = ROOT / "benchmarks" / "tactile" / "familywise_error.md"
#: The families' kinds (the rows' spreads) and sizes measured.
KINDS = ("homogeneous", "one row 4×", "graded 1–4×", "reference 3×")
ROWS = tuple(range(2, 9))
SEEDS = 8
ALPHA = 0.05


def spreads(kind: str, rows: int) -> tuple[float, np.ndarray]:
    """The reference's and the rows' standard deviations of a family of ``rows`` rows.

    Example:
        >>> spreads("one row 4×", 3)
        (1.0, array([4., 1., 1.]))
    """
    if kind == "homogeneous":
        return 1.0, np.ones(rows)
    if kind == "one row 4×":
        return 1.0, np.array([4.0] + [1.0] * (rows - 1))
    if kind == "graded 1–4×":
        return 1.0, np.geomspace(1.0, 4.0, rows)
    if kind == "reference 3×":
        return 3.0, np.ones(rows)
    raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")


def simulate(kind: str, rows: int, families: int, rng: np.random.Generator, *, seeds: int = SEEDS,
             shift: Sequence[float] | None = None) -> np.ndarray:
    """The per-seed Δ (row − reference) of ``families`` families: shape ``(families, rows, seeds)``.

    Every row and the reference draw their own per-seed values (normal, the kind's spreads);
    a seed effect shared by every method of the seed cancels in the Δ and is left out.
    ``shift`` adds a true Δ per row (default 0: the null).
    """
    ref_sd, row_sd = spreads(kind, rows)
    reference = rng.standard_normal((families, 1, seeds)) * ref_sd
    values = rng.standard_normal((families, rows, seeds)) * row_sd[None, :, None]
    if shift is not None:
        values = values + np.asarray(shift, dtype=float)[None, :, None]
    return values - reference


def _raw_t(deltas: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = deltas.shape[-1]
    mean = deltas.mean(axis=-1)
    var = deltas.var(axis=-1, ddof=1)
    return mean, var, np.full(mean.shape, float(n - 1))


def declared_raw(deltas: np.ndarray, *, alpha: float = ALPHA) -> np.ndarray:
    """Rules 2: each row's paired t-interval at level 1 − α/m excludes 0 (m rows in the family).

    Returns booleans of shape ``(families, rows)``.
    """
    families, rows, n = deltas.shape
    mean, var, _ = _raw_t(deltas)
    quantile = student_t_quantile(1.0 - alpha / (2.0 * rows), n - 1)
    return np.abs(mean) > quantile * np.sqrt(var / n)


# ---------------------------------------------------------------- rules 1, vectorised (the code of e4ced10)

def _digamma(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float)
    result = np.zeros_like(x)
    for _ in range(12):  # recurrence to x ≥ 10 (every x here is ≥ 0.5)
        small = x < 10.0
        result = result - np.where(small, 1.0 / x, 0.0)
        x = np.where(small, x + 1.0, x)
    inv2 = 1.0 / (x * x)
    return result + np.log(x) - 0.5 / x - inv2 * (1 / 12 - inv2 * (1 / 120 - inv2 * (1 / 252 - inv2 * (
        1 / 240 - inv2 / 132))))


def _trigamma(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float)
    result = np.zeros_like(x)
    for _ in range(12):
        small = x < 10.0
        result = result + np.where(small, 1.0 / (x * x), 0.0)
        x = np.where(small, x + 1.0, x)
    inv = 1.0 / x
    inv2 = inv * inv
    return result + inv + 0.5 * inv2 + inv * inv2 * (1 / 6 - inv2 * (1 / 30 - inv2 * (1 / 42 - inv2 / 30)))


def _trigamma_inverse(value: np.ndarray) -> np.ndarray:
    low, high = np.full(value.shape, 1e-8), np.full(value.shape, 1e8)
    for _ in range(100):  # bisection in log y, as stats._trigamma_inverse
        mid = np.sqrt(low * high)
        above = _trigamma(mid) > value
        low, high = np.where(above, mid, low), np.where(above, high, mid)
    return np.sqrt(low * high)


def _prior(var: np.ndarray, df: int) -> tuple[np.ndarray, np.ndarray]:
    """stats.variance_prior of each family's row variances (axis 1): (d₀, s₀²), vectorised."""
    rows = var.shape[1]
    half = df / 2.0
    logs = np.log(var) - _digamma(np.array(half)) + math.log(half)
    mean = logs.mean(axis=1)
    excess = logs.var(axis=1, ddof=1) - _trigamma(np.array(half))
    cap = float((rows - 1) * df)
    fitted = 2.0 * _trigamma_inverse(np.where(excess > 0, excess, 1.0))
    d0 = np.where(excess <= 0, cap, np.minimum(fitted, cap))
    s2 = np.exp(mean + _digamma(d0 / 2.0) - np.log(d0 / 2.0))
    return d0, s2


class _Quantiles:
    """Student-t quantiles q(1 − α/(2m), df) for non-integer df, tabulated in 1/df and interpolated
    (the moderated t's degrees of freedom d₀ + n − 1 vary from family to family)."""

    def __init__(self, alpha: float, low: float, high: float, points: int = 400) -> None:
        self.alpha = alpha
        self.grid = np.linspace(1.0 / high, 1.0 / low, points)  # increasing 1/df
        self.tables: dict[int, np.ndarray] = {}

    def __call__(self, rows: int, df: np.ndarray) -> np.ndarray:
        if rows not in self.tables:
            level = 1.0 - self.alpha / (2.0 * rows)
            self.tables[rows] = np.array([student_t_quantile(level, 1.0 / g) for g in self.grid])
        return np.interp(1.0 / df, self.grid, self.tables[rows])


_QUANTILES = _Quantiles(ALPHA, SEEDS - 1.0, (max(ROWS) - 1) * (SEEDS - 1.0) + SEEDS - 1.0 + 1.0)


def declared_v1(deltas: np.ndarray, *, alpha: float = ALPHA, min_rows: int = 2,
                blocks: bool = False) -> np.ndarray:
    """Rules 1: each row's moderated t-interval at level 1 − α/m excludes 0, the variance prior
    fitted from the family's rows (:func:`event_transforms.tactile.stats.variance_prior`; only
    where the family has at least ``min_rows`` rows, else each row's own variance); with
    ``blocks`` the Δ's direction must also hold in each half of the seeds (the rules-1 block rule).

    Returns booleans of shape ``(families, rows)``.
    """
    if alpha != ALPHA:
        raise ValueError(f"alpha must be {ALPHA} (the tabulated quantiles), got {alpha!r}")
    families, rows, n = deltas.shape
    mean, var, df = _raw_t(deltas)
    if rows >= min_rows:
        d0, s2 = _prior(var, n - 1)
        var = (d0[:, None] * s2[:, None] + (n - 1) * var) / (d0[:, None] + n - 1)
        df = np.broadcast_to((d0 + n - 1)[:, None], mean.shape)
    out = np.abs(mean) > _QUANTILES(rows, df) * np.sqrt(var / n)
    if blocks:
        half = n // 2
        first, second = deltas[..., :half].mean(axis=-1), deltas[..., half:].mean(axis=-1)
        out &= (first * mean > 0) & (second * mean > 0)
    return out


def declared_min_rows(deltas: np.ndarray, *, min_rows: int = 4) -> np.ndarray:
    """The moderated t with a prior fitted only from families of at least ``min_rows`` rows."""
    return declared_v1(deltas, min_rows=min_rows)


#: The procedures measured: name -> declared(deltas).
PROCEDURES = {
    "rules 1: moderated (prior from ≥ 2 rows), Bonferroni": declared_v1,
    "rules 1 with the block rule": lambda d: declared_v1(d, blocks=True),
    "moderated, prior from ≥ 4 rows, Bonferroni": declared_min_rows,
    f"rules {RULES_VERSION}: raw paired t, Bonferroni": declared_raw,
}


def error_rates(kind: str, rows: int, families: int, rng: np.random.Generator,
                procedures: dict | None = None) -> dict[str, tuple[float, float]]:
    """Per procedure the family-wise error under Δ = 0 and its Monte Carlo standard error.

    Example:
        >>> rates = error_rates("homogeneous", 3, 2000, np.random.default_rng(0),
        ...                     {"raw": declared_raw})
        >>> error, se = rates["raw"]
        >>> error <= 0.05 + 2 * se, round(se, 4)
        (True, 0.0045)
    """
    deltas = simulate(kind, rows, families, rng)
    out = {}
    for name, declared in (procedures or PROCEDURES).items():
        error = float(declared(deltas).any(axis=1).mean())
        out[name] = (error, math.sqrt(max(error * (1 - error), 1e-12) / families))
    return out


def power(rows: int, families: int, rng: np.random.Generator, shift: float = 2.0,
          procedures: dict | None = None) -> dict[str, float]:
    """Per procedure the share of homogeneous families whose first row (true Δ ``shift``) is declared."""
    deltas = simulate("homogeneous", rows, families, rng, shift=[shift] + [0.0] * (rows - 1))
    return {name: float(declared(deltas)[:, 0].mean()) for name, declared in (procedures or PROCEDURES).items()}


def _cell(error: float, se: float) -> str:
    mark = " ✗" if error > ALPHA + 2 * se else ""
    return f"{error:.3f} ± {se:.3f}{mark}"


def run(families: int, seed: int) -> str:
    """The result page (markdown)."""
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    names = list(PROCEDURES)
    lines = [
        "# The family-wise error of the protocol's intervals (Monte Carlo under Δ = 0)",
        "",
        f"Written by `python -m benchmarks.tactile.familywise_error --families {families} --seed {seed}` "
        f"(numpy {np.__version__}). Each cell: the share of {families:,} simulated families with every true Δ "
        f"equal to 0 in which at least one row's family-wise interval excludes 0 (level {ALPHA}), ± its Monte "
        f"Carlo standard error; ✗ marks an error above {ALPHA} by more than two standard errors. {SEEDS} seeds; "
        "each row and the shared reference draw their own per-seed values (normal), and a row's Δ is row − "
        "reference seed by seed, as `stats.deltas_vs_none` computes it, so the rows' Δ are correlated. The "
        "protocol's rules are version "
        f"{RULES_VERSION} (`event_transforms/tactile/protocol/rules.py`): {RULES.interval.rstrip('.')}.",
        "",
    ]
    worst = {name: 0.0 for name in names}
    above = {(kind, name): 0 for kind in KINDS for name in names}  # configurations above 0.05 + 2 s.e.
    for kind in KINDS:
        lines += [f"## {kind}", "", "| rows | " + " | ".join(names) + " |", "|---:|" + "---:|" * len(names)]
        for rows in ROWS:
            rates = error_rates(kind, rows, families, rng)
            for name in names:
                worst[name] = max(worst[name], rates[name][0])
                above[kind, name] += rates[name][0] > ALPHA + 2 * rates[name][1]
            lines.append(f"| {rows} | " + " | ".join(_cell(*rates[name]) for name in names) + " |")
        lines.append("")
    lines += ["## Power: one row with a true Δ of 2 in a homogeneous family (1.41 sd of its per-seed Δ)", "",
              "| rows | " + " | ".join(names) + " |", "|---:|" + "---:|" * len(names)]
    shares = {}
    for rows in (2, 4, 6, 8):
        shares[rows] = power(rows, families, rng)
        lines.append(f"| {rows} | " + " | ".join(f"{shares[rows][name]:.3f}" for name in names) + " |")
    v1, blocks, four, v2 = names
    v2_above = sum(above[kind, v2] for kind in KINDS)
    v2_text = ("at or below 0.05 within two Monte Carlo standard errors in every configuration" if v2_above == 0
               else f"above 0.05 by more than two standard errors in {v2_above} configuration(s)")
    lines += [
        "",
        "## What was chosen, and why",
        "",
        "Largest error over the configurations: " + "; ".join(f"{name} {worst[name]:.3f}" for name in names) + ".",
        "",
        f"- **Rules 1 is above its level.** The moderated variances reach {worst[v1]:.3f} (above 0.05 by more than "
        f"two standard errors in {sum(above[kind, v1] for kind in KINDS)} of {len(KINDS) * len(ROWS)} "
        "configurations): a noisy row is shrunk toward quiet ones, and homogeneous families are above 0.05 too "
        f"({above['homogeneous', v1]} of {len(ROWS)} sizes), most likely because the rows' variances share the "
        "reference's noise (every Δ is row − the same reference): they are not independent, and pooling them as if "
        "they were overstates the prior's degrees of freedom. Fitting the prior only from four rows or more does not help where it applies "
        f"({worst[four]:.3f}); below four rows it is the raw t.",
        f"- **The block rule changes nothing.** With it the largest error is {worst[blocks]:.3f} against "
        f"{worst[v1]:.3f} without, and the power {shares[8][blocks]:.3f} against {shares[8][v1]:.3f} (8 rows): once "
        "the interval over all seeds excludes 0, the two halves' means almost never disagree. Rules 2 drops it; "
        "a verdict rests on one block of seeds.",
        f"- **Rules 2: each row's own paired t, Bonferroni.** Exact under normality (each row's test has level "
        f"α/m whatever the correlation, so the family's error is at most α): largest measured error "
        f"{worst[v2]:.3f}, {v2_text}; conservative where the rows' Δ are "
        "strongly correlated (`reference 3×`). Under the complete null Holm's step-down has the same error (its "
        "first step is Bonferroni's test); its p-values stay in `results.json`, and the intervals are Bonferroni's "
        "so that a bold cell is exactly an interval that excludes 0.",
        f"- **The price is power.** One real Δ of 1.41 sd in a family of 8 is declared {shares[8][v2]:.0%} of the "
        f"time by rules 2 against {shares[8][v1]:.0%} by rules 1: rules 1 borrowed degrees of freedom from the family's other rows, "
        "where both its power and its excess error came from. More seeds, not a looser rule, buy it back.",
        "",
        f"Computed in {time.perf_counter() - start:.0f} s.",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--families", type=int, default=20_000, help="families per configuration (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="the generator's seed (default %(default)s)")
    parser.add_argument("--quick", action="store_true", help="500 families per configuration (a smoke test)")
    parser.add_argument("--no-write", action="store_true", help="print only; do not write the page")
    parser.add_argument("--output", type=Path, default=OUTPUT, help="the page to write (default %(default)s)")
    args = parser.parse_args(argv)
    page = run(500 if args.quick else args.families, args.seed)
    print(page)
    if not args.no_write and not args.quick:
        args.output.write_text(page + "\n")
    return page


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
