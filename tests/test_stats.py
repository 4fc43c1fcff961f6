"""Claims across seeds: intervals from scipy.stats, and the report keeps calibrated apart."""
import json

import numpy as np
import pytest
from scipy import stats as sps

from snn_antenna.report import stats
from snn_antenna.core.errors import SpecError
from snn_antenna.report.page import Calibrated, Predicted, Report


def test_paired_difference_matches_scipy_paired_t():
    rng = np.random.default_rng(0)
    a = rng.normal(0.9, 0.03, 7)
    b = a - rng.normal(0.02, 0.03, 7)
    iv = stats.paired_difference(a, b)
    d = a - b
    low, high = sps.t.interval(0.95, 6, loc=d.mean(), scale=sps.sem(d))
    assert iv.n == 7
    assert iv.mean == pytest.approx(d.mean())
    assert (iv.low, iv.high) == pytest.approx((low, high))
    assert iv.p_value == pytest.approx(sps.ttest_rel(a, b).pvalue)


def test_interval_spanning_zero_is_not_resolved():
    # the gate's old headline: +0.035 ± 0.045 over 5 seeds
    diffs = np.array([0.10, 0.04, 0.03, -0.03, 0.035])
    iv = stats.mean_interval(diffs)
    assert iv.low < 0 < iv.high
    assert not iv.resolved and iv.verdict == "not resolved"
    assert "not resolved" in str(iv)
    clear = stats.mean_interval([0.05, 0.06, 0.055, 0.052, 0.058])
    assert clear.resolved and clear.verdict == "resolved above zero"


def test_no_verdict_below_the_documented_n():
    # gating's old "p = 0.024: resolved" on 2 seeds
    few = stats.paired_difference([0.91, 0.93], [0.80, 0.83])
    assert few.n < stats.MIN_N_TO_RESOLVE and few.low > 0
    assert not few.resolved and few.verdict.startswith("too small to resolve")
    assert not stats.mean_interval([0.05, 0.06, 0.055, 0.052]).resolved
    assert "MIN_N_TO_RESOLVE" in open("docs/reference.md").read() or \
        f"n ≥ {stats.MIN_N_TO_RESOLVE}" in open("docs/reference.md").read()


def test_a_positive_quantity_keeps_a_positive_interval():
    # the old "distance rmse 16 mm (95 % CI -107.8 to 140.1, n = 2)"
    rmse = [6.4, 25.9]
    assert stats.mean_interval(rmse).low < 0           # Student t runs below zero
    iv = stats.mean_interval(rmse, bounds=(0.0, np.inf))
    assert 0 <= iv.low <= iv.mean <= iv.high
    f1 = stats.mean_interval([0.97, 1.0, 0.99, 1.0, 0.98], bounds=(0.0, 1.0))
    assert 0 <= f1.low and f1.high <= 1
    assert stats.mean_interval(rmse, bounds=(0, np.inf)) == \
        stats.mean_interval(rmse, bounds=(0, np.inf))   # seeded: reruns agree
    with pytest.raises(SpecError, match="range"):
        stats.mean_interval([-1.0, 2.0], bounds=(0.0, np.inf))


def test_seeds_needed_is_exact_t_power():
    diffs = [0.1, -0.05, 0.08, -0.02, 0.06]
    sd = np.std(diffs, ddof=1)
    n = stats.seeds_needed(diffs, 0.05)
    assert stats.t_test_power(n, 0.05 / sd) >= 0.8 > stats.t_test_power(n - 1, 0.05 / sd)
    z = sps.norm.ppf(0.975) + sps.norm.ppf(0.8)
    assert n > np.ceil((z * sd / 0.05) ** 2)          # the normal approximation undercounts
    # the noncentral-t power agrees with simulated paired t-tests
    rng = np.random.default_rng(1)
    sims = rng.normal(0.05, sd, (20000, n))
    p = sps.ttest_1samp(sims, 0.0, axis=1).pvalue
    assert np.mean(p < 0.05) == pytest.approx(stats.t_test_power(n, 0.05 / sd), abs=0.015)


def test_seeds_needed_grows_with_spread_and_shrinks_with_margin():
    noisy, calm = [0.1, -0.05, 0.08, -0.02, 0.06], [0.03, 0.035, 0.032, 0.031, 0.034]
    assert stats.seeds_needed(noisy, 0.02) > stats.seeds_needed(calm, 0.02)
    assert stats.seeds_needed(noisy, 0.01) > stats.seeds_needed(noisy, 0.04)


def test_binomial_interval_is_wilson():
    low, high = stats.binomial_interval(23, 32)
    ci = sps.binomtest(23, 32).proportion_ci(0.95, method="wilson")
    assert (low, high) == pytest.approx((ci.low, ci.high))
    assert low < 23 / 32 < high


def test_bad_input_is_refused():
    with pytest.raises(SpecError, match="values"):
        stats.mean_interval([0.5])
    with pytest.raises(SpecError, match="b"):
        stats.paired_difference([1, 2, 3], [1, 2])


def test_report_keeps_calibrated_and_predicted_apart(tmp_path):
    rep = Report(tmp_path, "t", quick=True)
    rep.calibrated(Calibrated("low-mode precision", 6.2, 6.2, "mm", "docs/reference.md"))
    rep.predicted(Predicted("distance rmse", 2.1, "mm", paper=1.71, interval=(1.9, 2.3), n=5))
    with pytest.raises(ValueError, match="calibration target"):
        rep.predicted(Predicted("low-mode precision", 6.3, "mm", paper=6.2))
    summary = rep.write({}, {"seed": 1}, target="numpy")
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["quick"] is True
    assert [c["quantity"] for c in saved["calibrated"]] == ["low-mode precision"]
    assert [p["quantity"] for p in saved["predicted"]] == ["distance rmse"]
    page = (tmp_path / "report.html").read_text()
    assert page.index("Calibrated to") < page.index("Predicted")
    assert "quick profile" in page
    assert summary["predicted"][0]["n"] == 5
