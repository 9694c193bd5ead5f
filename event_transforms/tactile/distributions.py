"""Special functions for the paired statistics, in pure Python (no SciPy): Student's t
distribution (:func:`student_t_cdf`, :func:`student_t_quantile`, through the regularized
incomplete beta function) and the digamma and trigamma functions (:func:`digamma`,
:func:`trigamma`) that Smyth's variance prior (:func:`~event_transforms.tactile.stats.variance_prior`)
is estimated with. :mod:`~event_transforms.tactile.stats` re-exports them.
"""

from __future__ import annotations

import math

__all__ = ["student_t_cdf", "student_t_quantile", "digamma", "trigamma"]


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz's method)."""
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    result = d
    for m in range(1, 10_000):
        m2 = 2 * m
        for numerator in (
            m * (b - m) * x / ((a + m2 - 1.0) * (a + m2)),
            -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0)),
        ):
            d = 1.0 + numerator * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + numerator / c
            c = c if abs(c) > tiny else tiny
            result *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    return result


def _incomplete_beta(a: float, b: float, x: float) -> float:
    """The regularized incomplete beta function I_x(a, b)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _betacf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _betacf(b, a, 1.0 - x) / b


def student_t_cdf(t: float, df: float) -> float:
    """P(T <= t) for Student's t with ``df`` degrees of freedom.

    Example:
        >>> round(student_t_cdf(2.776445, 4), 6)
        0.975
    """
    if df <= 0:
        raise ValueError(f"df must be > 0, got {df!r}")
    if math.isinf(t):
        return 1.0 if t > 0 else 0.0
    tail = 0.5 * _incomplete_beta(df / 2.0, 0.5, df / (df + t * t))
    return 1.0 - tail if t > 0 else tail


def student_t_quantile(p: float, df: float) -> float:
    """The t with ``student_t_cdf(t, df) == p`` (bisection to machine precision).

    Example:
        >>> round(student_t_quantile(0.975, 9), 6)
        2.262157
    """
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must lie in (0, 1), got {p!r}")
    if p < 0.5:
        return -student_t_quantile(1.0 - p, df)
    low, high = 0.0, 1.0
    while student_t_cdf(high, df) < p:
        high *= 2.0
    for _ in range(200):
        mid = 0.5 * (low + high)
        if student_t_cdf(mid, df) < p:
            low = mid
        else:
            high = mid
        if high - low <= 1e-12 * max(1.0, high):
            break
    return 0.5 * (low + high)


def digamma(x: float) -> float:
    """ψ(x), the derivative of ln Γ(x), for x > 0 (recurrence to x ≥ 10, then the asymptotic series).

    Example:
        >>> round(digamma(1.0), 10)  # −γ, the Euler–Mascheroni constant
        -0.5772156649
    """
    if not x > 0:
        raise ValueError(f"x must be > 0, got {x!r}")
    result = 0.0
    while x < 10.0:
        result -= 1.0 / x
        x += 1.0
    inv2 = 1.0 / (x * x)
    return result + math.log(x) - 0.5 / x - inv2 * (1 / 12 - inv2 * (1 / 120 - inv2 * (1 / 252 - inv2 * (1 / 240 - inv2 / 132))))


def trigamma(x: float) -> float:
    """ψ'(x), the derivative of :func:`digamma`, for x > 0.

    Example:
        >>> round(trigamma(1.0), 10)  # π² / 6
        1.6449340668
    """
    if not x > 0:
        raise ValueError(f"x must be > 0, got {x!r}")
    result = 0.0
    while x < 10.0:
        result += 1.0 / (x * x)
        x += 1.0
    inv = 1.0 / x
    inv2 = inv * inv
    return result + inv + 0.5 * inv2 + inv * inv2 * (1 / 6 - inv2 * (1 / 30 - inv2 * (1 / 42 - inv2 / 30)))


def _trigamma_inverse(value: float) -> float:
    """The y > 0 with ``trigamma(y) == value`` (trigamma decreases from +∞ to 0: bisection in log y)."""
    low, high = 1e-8, 1e8
    for _ in range(200):
        mid = math.sqrt(low * high)
        if trigamma(mid) > value:
            low = mid
        else:
            high = mid
        if high / low < 1 + 1e-12:
            break
    return math.sqrt(low * high)
