"""Statistics for claims across seeds or splits: every comparison carries its interval and n.

Built on ``scipy.stats`` (no hand-rolled tests). A difference whose confidence interval spans
zero is reported as "not resolved", never as a lead; with fewer than ``MIN_N_TO_RESOLVE``
values there is no verdict at all ("too small to resolve"): a t interval over 2-4 seeds leans
wholly on normality and has almost no power. A bounded quantity (an rmse, an F1, a rate) gets
a bootstrap interval of its mean, which stays inside the values seen and so inside the range.
The rules are in docs/reference.md ("Statistics rules").
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from ..core import bounds
from ..core.errors import check

MIN_N_TO_RESOLVE = 5      # fewest seeds or splits a "resolved" verdict may rest on
BOOTSTRAP_RESAMPLES = 4000


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
        """True when the interval excludes zero and n is large enough to say so."""
        return self.n >= MIN_N_TO_RESOLVE and (self.low > 0 or self.high < 0)

    @property
    def verdict(self) -> str:
        if self.n < MIN_N_TO_RESOLVE:
            return f"too small to resolve (n = {self.n} < {MIN_N_TO_RESOLVE})"
        if not self.resolved:
            return "not resolved"
        return "resolved above zero" if self.low > 0 else "resolved below zero"

    def as_dict(self) -> dict:
        return {**asdict(self), "resolved": self.resolved, "verdict": self.verdict}

    def __str__(self) -> str:
        return (f"{self.mean:+.3g} ({self.level:.0%} CI {self.low:+.3g} to {self.high:+.3g}, "
                f"n = {self.n}; {self.verdict})")


def mean_interval(values, level: float = 0.95, bounds: tuple | None = None) -> Interval:
    """Mean and confidence interval of independent values (seeds or splits).

    Unbounded (a paired difference): Student t. ``bounds`` (low, high) mark a quantity that
    cannot leave that range (an rmse ≥ 0, an F1 in [0, 1]): its interval is a percentile
    bootstrap of the mean, seeded so a rerun gives the same numbers, which never leaves the
    range of the values and so never the quantity's."""
    x = np.asarray(values, dtype=float).ravel()
    check(x.size >= 2, "values", x.size, "at least 2 values for an interval")
    check(bool(np.all(np.isfinite(x))), "values", "non-finite", "finite values")
    if bounds is not None:
        lo, hi = bounds
        check(bool(np.all((x >= lo) & (x <= hi))), "values", f"{x.min():g} to {x.max():g}",
              f"values inside the quantity's range {lo:g} to {hi:g}")
    mean = float(x.mean())
    sem = float(stats.sem(x))
    if sem == 0.0:
        return Interval(mean, mean, mean, int(x.size), level,
                        None if mean != 0 else 1.0)
    p = float(stats.ttest_1samp(x, 0.0).pvalue)
    if bounds is not None:
        boot = stats.bootstrap((x,), np.mean, confidence_level=level, method="percentile",
                               n_resamples=BOOTSTRAP_RESAMPLES,
                               random_state=np.random.default_rng(0))
        ci = boot.confidence_interval
        return Interval(mean, float(ci.low), float(ci.high), int(x.size), level, p)
    low, high = stats.t.interval(level, x.size - 1, loc=mean, scale=sem)
    return Interval(mean, float(low), float(high), int(x.size), level, p)


def paired_difference(a, b, level: float = 0.95) -> Interval:
    """a − b paired by seed: mean, t interval, n and the paired t-test's p (scipy.stats)."""
    a = np.asarray(a, dtype=float).ravel()
    b = np.asarray(b, dtype=float).ravel()
    check(a.shape == b.shape, "b", b.shape, f"the same number of paired values as a {a.shape}")
    return mean_interval(a - b, level)


def seeds_needed(differences, margin: float, level: float = 0.95, power: float = 0.8) -> int:
    """Seeds needed to resolve a paired difference of size ``margin`` given the measured spread.

    Exact power of the two-sided paired t-test (scipy's noncentral t): the smallest n, at
    least ``MIN_N_TO_RESOLVE``, whose power to detect ``margin`` reaches ``power``. The
    normal approximation undercounts at small n, exactly where seeds are few.
    """
    d = np.asarray(differences, dtype=float).ravel()
    check(margin > 0, "margin", margin, "a positive difference to resolve")
    sd = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    if sd == 0.0:
        return MIN_N_TO_RESOLVE
    n = MIN_N_TO_RESOLVE
    while n < 100_000 and t_test_power(n, margin / sd, level) < power:
        n += 1
    return n


def t_test_power(n: int, effect: float, level: float = 0.95) -> float:
    """Power of a two-sided one-sample (paired) t-test on n values for effect = δ/σ."""
    bounds.number("n", n, 2.0, bounds.MAX_COUNT)
    bounds.number("effect", effect, -bounds.MAX_MAGNITUDE, bounds.MAX_MAGNITUDE)
    bounds.number("level", level, 0.0, 1.0, lo_open=True, hi_open=True)
    df = n - 1
    crit = stats.t.ppf(1 - (1 - level) / 2, df)
    nc = effect * np.sqrt(n)
    return float(stats.nct.sf(crit, df, nc) + stats.nct.cdf(-crit, df, nc))


def binomial_interval(successes: int, trials: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson interval of a proportion (accuracy over independent events)."""
    trials = bounds.number("trials", trials, 1.0, bounds.MAX_COUNT)
    bounds.number("successes", successes, 0.0, trials, unit=" (at most trials)")
    bounds.number("level", level, 0.0, 1.0, lo_open=True, hi_open=True)
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(level, method="wilson")
    return float(ci.low), float(ci.high)


def poisson_interval(count: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson count (e.g. false positives in a run), from
    scipy's chi² quantiles."""
    bounds.number("count", count, 0.0, bounds.MAX_COUNT)
    alpha = 1 - bounds.number("level", level, 0.0, 1.0, lo_open=True, hi_open=True)
    low = stats.chi2.ppf(alpha / 2, 2 * count) / 2 if count else 0.0
    return float(low), float(stats.chi2.ppf(1 - alpha / 2, 2 * count + 2) / 2)
