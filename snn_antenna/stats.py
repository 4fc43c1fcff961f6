"""Statistics for claims across seeds or splits: every comparison carries its interval and n.

Built on ``scipy.stats`` (no hand-rolled tests). A difference whose confidence interval spans
zero is reported as "not resolved", never as a lead.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from .errors import check


@dataclass(frozen=True)
class Interval:
    """Mean of ``n`` values with a two-sided ``level`` confidence interval (Student t)."""
    mean: float
    low: float
    high: float
    n: int
    level: float = 0.95
    p_value: float | None = None   # two-sided, against a mean of zero (paired differences)

    @property
    def resolved(self) -> bool:
        """True when the interval excludes zero."""
        return self.low > 0 or self.high < 0

    @property
    def verdict(self) -> str:
        if not self.resolved:
            return "not resolved"
        return "resolved above zero" if self.low > 0 else "resolved below zero"

    def as_dict(self) -> dict:
        return {**asdict(self), "resolved": self.resolved, "verdict": self.verdict}

    def __str__(self) -> str:
        return (f"{self.mean:+.3g} ({self.level:.0%} CI {self.low:+.3g} to {self.high:+.3g}, "
                f"n = {self.n}; {self.verdict})")


def mean_interval(values, level: float = 0.95) -> Interval:
    """Mean and t confidence interval of independent values (seeds or splits)."""
    x = np.asarray(values, dtype=float).ravel()
    check(x.size >= 2, "values", x.size, "at least 2 values for an interval")
    check(bool(np.all(np.isfinite(x))), "values", "non-finite", "finite values")
    mean = float(x.mean())
    sem = float(stats.sem(x))
    if sem == 0.0:
        return Interval(mean, mean, mean, int(x.size), level,
                        None if mean != 0 else 1.0)
    low, high = stats.t.interval(level, x.size - 1, loc=mean, scale=sem)
    p = float(stats.ttest_1samp(x, 0.0).pvalue)
    return Interval(mean, float(low), float(high), int(x.size), level, p)


def paired_difference(a, b, level: float = 0.95) -> Interval:
    """a − b paired by seed: mean, t interval, n and the paired t-test's p (scipy.stats)."""
    a = np.asarray(a, dtype=float).ravel()
    b = np.asarray(b, dtype=float).ravel()
    check(a.shape == b.shape, "b", b.shape, f"the same number of paired values as a {a.shape}")
    return mean_interval(a - b, level)


def seeds_needed(differences, margin: float, level: float = 0.95, power: float = 0.8) -> int:
    """Seeds needed to resolve a paired difference of size ``margin`` given the measured spread.

    Normal approximation n = ((z_{1-α/2} + z_power) σ / margin)², at least 3.
    """
    d = np.asarray(differences, dtype=float).ravel()
    check(margin > 0, "margin", margin, "a positive difference to resolve")
    sd = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    z = stats.norm.ppf(1 - (1 - level) / 2) + stats.norm.ppf(power)
    return max(3, int(np.ceil((z * sd / margin) ** 2)))


def binomial_interval(successes: int, trials: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson interval of a proportion (accuracy over independent events)."""
    check(trials > 0, "trials", trials, "at least one trial")
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(level, method="wilson")
    return float(ci.low), float(ci.high)


def poisson_interval(count: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson count (e.g. false positives in a run), from
    scipy's chi² quantiles."""
    alpha = 1 - level
    low = stats.chi2.ppf(alpha / 2, 2 * count) / 2 if count else 0.0
    return float(low), float(stats.chi2.ppf(1 - alpha / 2, 2 * count + 2) / 2)
