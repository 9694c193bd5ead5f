"""The protocol's decision rules, in one place, with a version (DESIGN.md §14).

Every number and choice that turns per-seed values into a printed verdict lives in a
:class:`Rules`: the interval and its family-wise procedure, the level, how a row's variance is
estimated, the convergence rule and its tolerance, the budget check, the replication rule, what
"resolved" means and whether a cell can read "borderline". :mod:`~event_transforms.tactile.stats`,
:mod:`~event_transforms.tactile.report` and :mod:`~event_transforms.tactile.protocol.run` read
them from :data:`RULES`; every ``results.json`` records ``rules`` (:meth:`Rules.to_dict`) and
every report prints its version, and ``event-transforms compare`` says so when two runs were
judged by different versions.

A rule changed after looking at the numbers it judges is a new version: its table sits beside
the old one, never replacing it. The versions:

- ``"1"`` (:data:`RULES_V1`, the rules as of commit e4ced10): paired t-intervals at level
  1 − 0.05/m (Bonferroni over the scene's family of m rows), each row's variance *moderated*
  toward the family's (Smyth's empirical Bayes, the prior fitted from the family's own rows, as
  few as two, its degrees of freedom capped at (rows − 1) · df); resolved when that interval
  excludes 0, the side behind had converged, and the mean Δ of each half of the seeds lies on
  the same side ("borderline" otherwise). The moderated variances, the block rule and the
  mean-curve convergence rule were designed on the pair of kernel-set runs they were then judged
  on. Measured afterwards (``benchmarks/tactile/familywise_error.md``): the family-wise error reaches
  0.07 at level 0.05 with one noisy row, and the block rule vetoes almost no verdict.
- ``"2"`` (:data:`RULES`, from this release): each row's own paired t (its own variance, n − 1
  degrees of freedom), Bonferroni over the family; no block rule (the verdict rests on one block
  of seeds, and the report says so) and no "borderline"; convergence and the budget check as in
  version 1. Chosen by the Monte Carlo of ``benchmarks/tactile/familywise_error.py``: at or below 0.05
  within its error in every configuration (exact under normality), where the moderated t was not.

Example:
    >>> RULES.version, RULES.alpha, RULES.variances, RULES.replication
    ('2', 0.05, 'raw', 'none')
    >>> rules_for("1").variances
    'moderated'
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["Rules", "RULES", "RULES_V1", "RULES_VERSION", "HISTORY", "rules_for", "version_of"]


@dataclass(frozen=True)
class Rules:
    """One version of the protocol's decision rules.

    Attributes:
        version: the rules' version, recorded by every result.
        alpha: the family-wise level: a family's intervals are at level 1 − alpha/m.
        family_wise: the family-wise procedure of the intervals (``"bonferroni"``: each of the m
            rows' paired t-interval at level 1 − alpha/m; Holm's step-down p-values are kept
            beside them in ``results.json``, not used for a verdict).
        variances: ``"raw"`` (each row's own sample variance, n − 1 degrees of freedom) or
            ``"moderated"`` (Smyth's empirical-Bayes prior fitted from the family's rows).
        prior_min_rows: the fewest rows a moderated family's prior is fitted from (``None``
            with raw variances).
        unadjusted_level: the level of the unadjusted intervals shown beside (the scene tables'
            95 % columns, the seed blocks), never used for a verdict in a family.
        convergence_tolerance: an ensemble whose mean hold-out MSE fell by more than this share
            in the last part of its run had not converged; a Δ whose side behind had not
            converged is not resolved.
        convergence_window: the part of the run the "lowest mean before" is taken from (the
            first three quarters).
        budget_factor: the budget check retrains ``none`` and the headline at this many times
            the steps.
        replication: ``"none"`` (a verdict rests on its one block of seeds) or ``"halves"``
            (version 1: the mean Δ of each half of the seeds on the verdict's side, else
            "borderline").
        interval: the interval rule, in words.
        resolved: what a resolved (bold) cell means, in words.
        convergence: the convergence rule, in words.
        budget_check: the budget check, in words.
        borderline: what a "(borderline)" cell means, or ``None`` where no cell can read so.
        covers: what one block of seeds is, in words.
    """

    version: str
    alpha: float
    family_wise: str
    variances: str
    prior_min_rows: int | None
    unadjusted_level: float
    convergence_tolerance: float
    convergence_window: float
    budget_factor: int
    replication: str
    interval: str
    resolved: str
    convergence: str
    budget_check: str
    borderline: str | None
    covers: str

    def __post_init__(self) -> None:
        if self.family_wise != "bonferroni":
            raise ValueError(f"family_wise must be 'bonferroni', got {self.family_wise!r}")
        if self.variances not in ("raw", "moderated"):
            raise ValueError(f"variances must be 'raw' or 'moderated', got {self.variances!r}")
        if self.replication not in ("none", "halves"):
            raise ValueError(f"replication must be 'none' or 'halves', got {self.replication!r}")
        if (self.variances == "moderated") != (self.prior_min_rows is not None):
            raise ValueError(f"prior_min_rows must be set exactly with moderated variances, got "
                             f"{self.prior_min_rows!r} with variances={self.variances!r}")
        if self.budget_factor != 2:  # the report's "resolved at 2×" cells and the cost curve's last point
            raise ValueError(f"budget_factor must be 2 (the tables' 2× columns), got {self.budget_factor!r}")
        for name in ("alpha", "unadjusted_level", "convergence_tolerance", "convergence_window"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ValueError(f"{name} must lie in (0, 1), got {value!r}")

    @property
    def family_level(self) -> float:
        """The level of one row's interval in a family of one: ``1 − alpha``."""
        return 1.0 - self.alpha

    def level(self, family: int) -> float:
        """The level of each interval in a family of ``family`` rows: ``1 − alpha / m``.

        Example:
            >>> round(RULES.level(5), 3)
            0.99
        """
        return 1.0 - self.alpha / max(int(family), 1)

    def to_dict(self) -> dict[str, Any]:
        """The rules as ``results.json`` records them."""
        return asdict(self)

    def line(self) -> str:
        """One sentence for a report: the version and its rules in words.

        Example:
            >>> RULES.line()[:40]
            'Decision rules version 2 (event_transfor'
        """
        borderline = f" Borderline: {self.borderline}" if self.borderline else ""
        return (f"Decision rules version {self.version} (event_transforms/tactile/protocol/rules.py): "
                f"{self.interval} Resolved: {self.resolved} {self.convergence} {self.covers}{borderline}")


_CONVERGENCE = ("Convergence: an ensemble whose mean hold-out curve fell by more than 5 % in the last quarter "
                "of its run had not converged; a Δ is withheld only where the side behind had not.")
_BUDGET_V1 = ("The scene's pre-declared headline (its first matched method) and none again at twice the steps: "
              "robust when Δ keeps its sign and moves by less than its Bonferroni half-width; an unconverged "
              "headline is resolved at twice the steps when both ensembles converged there, the paired 95 % "
              "interval (a pre-declared family of one) excludes 0 and its direction holds in each half of the seeds.")

#: Version 1: the rules as of commit e4ced10 (moderated variances, the block rule, "borderline").
RULES_V1 = Rules(
    version="1", alpha=0.05, family_wise="bonferroni", variances="moderated", prior_min_rows=2,
    unadjusted_level=0.95, convergence_tolerance=0.05, convergence_window=0.75, budget_factor=2,
    replication="halves",
    interval=("Δ vs the reference with its paired t-interval at level 1 − 0.05/m (Bonferroni over the scene's "
              "family of m rows), each row's variance moderated toward the family's (Smyth's empirical-Bayes "
              "prior fitted from the family's own rows, as few as two, its degrees of freedom capped at "
              "(rows − 1) · df)."),
    resolved=("the family interval excludes 0, the side behind had converged, and the mean Δ of each half of the "
              "seeds lies on the same side."),
    convergence=_CONVERGENCE,
    budget_check=_BUDGET_V1,
    borderline="the family interval excludes 0 but one half of the seeds has its mean Δ on the other side.",
    covers=("The seeds are one block (training randomness and, with the bootstrap, resamples of one data set); "
            "its halves are the perturbation."),
)

#: Version 2 (from this release): raw paired t, Bonferroni, no block rule, no "borderline".
RULES = Rules(
    version="2", alpha=0.05, family_wise="bonferroni", variances="raw", prior_min_rows=None,
    unadjusted_level=0.95, convergence_tolerance=0.05, convergence_window=0.75, budget_factor=2,
    replication="none",
    interval=("Δ vs the reference with each row's own paired t-interval (its own variance over the seeds, n − 1 "
              "degrees of freedom) at level 1 − 0.05/m (Bonferroni over the scene's family of m rows; its "
              "family-wise error measured by Monte Carlo at or below 0.05 in benchmarks/tactile/familywise_error.md)."),
    resolved="the family interval excludes 0 and the side behind had converged.",
    convergence=_CONVERGENCE,
    budget_check=("The scene's pre-declared headline (its first matched method) and none again at twice the steps: "
                  "robust when Δ keeps its sign and moves by less than its Bonferroni half-width; an unconverged "
                  "headline is resolved at twice the steps when both ensembles converged there and the paired 95 % "
                  "interval (a pre-declared family of one) excludes 0."),
    borderline=None,
    covers=("Every verdict rests on one block of seeds, perturbed by nothing else the run makes: no second "
            "block of seeds or data replicates it."),
)

#: The version of the rules this code applies.
RULES_VERSION = RULES.version
#: Every version, by name.
HISTORY: dict[str, Rules] = {"1": RULES_V1, "2": RULES}


def rules_for(version: str) -> Rules:
    """The rules of ``version`` (a key of :data:`HISTORY`).

    Raises:
        ValueError: no such version.
    """
    if version not in HISTORY:
        raise ValueError(f"version must be one of {sorted(HISTORY)}, got {version!r}")
    return HISTORY[version]


def version_of(results: dict[str, Any]) -> str | None:
    """The rules' version a ``results.json`` dict records; ``None`` for files written before
    versions were recorded (judged by version 1, the rules of e4ced10, or earlier ones).

    Example:
        >>> version_of({"rules": RULES.to_dict()}), version_of({})
        ('2', None)
    """
    recorded = results.get("rules")
    if isinstance(recorded, dict) and "version" in recorded:
        return str(recorded["version"])
    return None
