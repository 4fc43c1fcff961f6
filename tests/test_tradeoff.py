"""Ranking runs by cost and error: Pareto front, recommendations, non-finite bookkeeping and
the reference's own convergence, on hand-made rows."""
import numpy as np
import pytest

from snn_antenna.engine.devices import Run
from snn_antenna.evaluation import accuracy, tradeoff
from snn_antenna.evaluation.accuracy import Match, SpikeTrains


def test_pareto_front_and_recommendation_pick_the_cheapest_sufficient_runs():
    rows = [dict(scene="s", method="euler", dt_ms=dt, status="ok", cpu_s=c, rate_map_error=e,
                 readout_matches=m)
            for dt, c, e, m in ((0.01, 10.0, 0.01, True), (0.1, 1.0, 0.04, True),
                                (0.5, 0.5, 0.2, False), (1.0, 0.6, 0.3, True))]
    front = tradeoff.pareto_front(rows, "rate_map_error")
    assert [r["dt_ms"] for r in front] == [0.5, 0.1, 0.01]
    forced = dict(rows[2], dt_ms=0.7, cpu_s=0.1, readout_matches=True, rate_map_error=0.0,
                  beyond_stable_limit=True)
    recs = {r["criterion"]: r["dt_ms"] for r in tradeoff.recommend(rows + [forced], Match())}
    assert recs[tradeoff.MATCHES] == 1.0        # cheapest that matches
    assert recs["rate map within 5%"] == 0.1
    assert recs[tradeoff.ROBUST] == 0.1         # 0.5 breaks it


def _row(status="ok", **errors):
    return dict(sweep="main", scene="bench", method="euler", dt_ms=0.1, status=status,
                **{e: errors.get(e, 0.1) for e in tradeoff.ERRORS}, distance_cm=25.0)


def test_a_run_with_a_non_finite_value_but_no_exception_is_marked_and_counted():
    finite = Run(np.array([0, 1]), np.array([1.0, 2.0]), 0.1, 0.1)
    silent = Run(np.array([0, 1]), np.array([1.0, np.nan]), 0.1, 0.1)
    ok = tradeoff.check_finite(_row(), finite)
    assert ok["status"] == "ok" and ok["nonfinite_without_exception"] is False
    bad = tradeoff.check_finite(_row(), silent)
    assert bad["nonfinite_without_exception"] is True and "spike times" in bad["status"]
    score = tradeoff.check_finite(_row(rate_map_error=float("inf")), finite)
    assert score["rate_map_error"] is None and "rate_map_error" in score["status"]
    raised = _row(status=tradeoff.RAISED)
    counts = tradeoff.count_nonfinite([ok, bad, score, raised])
    assert counts == {"nonfinite_without_exception": 2, "raised_instability": 1}


def test_the_convergence_verdict_compares_the_smallest_error_with_the_shift():
    rows = [_row(spike_time_error_ms=0.6), _row(spike_time_error_ms=2.0)]
    far = tradeoff.convergence_verdict(dict(same_spike_counts=True, max_shift_ms=1e-5), rows)
    assert far["far_below"] and far["error_over_shift"] == pytest.approx(6e4)
    assert far["smallest_error_setting"] == "bench euler dt=0.1 ms"
    near = tradeoff.convergence_verdict(dict(same_spike_counts=True, max_shift_ms=0.1), rows)
    assert not near["far_below"] and near["error_over_shift"] == pytest.approx(6.0)
    moved = tradeoff.convergence_verdict(dict(same_spike_counts=False, max_shift_ms=1e-5), rows)
    assert not moved["far_below"]


def test_reference_shift_is_the_largest_move_or_the_error_when_counts_differ():
    ref = SpikeTrains(np.array([0, 0, 1]), np.array([1.0, 5.0, 2.0]))
    moved = SpikeTrains(np.array([0, 0, 1]), np.array([1.0, 5.25, 2.5]))
    assert accuracy.reference_shift(ref, moved, 2) == {"same_spike_counts": True,
                                                      "max_shift_ms": 0.5}
    fewer = SpikeTrains(np.array([0, 1]), np.array([1.0, 2.0]))
    shift = accuracy.reference_shift(ref, fewer, 2)
    assert not shift["same_spike_counts"] and shift["max_shift_ms"] > 0.5


def test_a_tuning_read_out_matches_when_every_neuron_prefers_the_same_stimulus():
    ref = SpikeTrains(np.array([1, 1, 2]), np.array([1.0, 2.0, 3.0]))   # 2 neurons × 2 freqs
    ref_out = accuracy.tuning_readout(ref, 2, 2, duration_s=1.0)
    assert ref_out.preferred.tolist() == [1, 0]
    silent = accuracy.tuning_readout(SpikeTrains(np.array([], int), np.array([])), 2, 2, 1.0)
    assert silent.preferred.tolist() == [-1, -1]
    row = accuracy.compare_tuning(ref, ref, ref_out, ref_out)
    assert row["readout_matches"] and row["rate_map_error"] == 0.0
    shifted = SpikeTrains(np.array([0, 0, 0, 2]), np.array([1.0, 2.0, 3.0, 3.0]))
    row = accuracy.compare_tuning(shifted, ref, accuracy.tuning_readout(shifted, 2, 2, 1.0),
                                  ref_out)
    assert not row["readout_matches"] and row["rate_map_error"] > 0
