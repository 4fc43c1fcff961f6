"""readout.thresholds: Th* from a scored sweep, the lookup table, and paired comparisons."""
import numpy as np
import pytest
import xarray as xr

from snn_antenna.evaluation.scoring import Score
from snn_antenna.evaluation.thresholds import (
    LookupTable,
    MethodScores,
    compare,
    fit_th_star,
    fixed_method,
)


def sweep_counts(tp, fp, misses):
    """A speed × scene × threshold dataset of counts like the gating sweep's store."""
    dims = ("speed_cm_s", "scene", "threshold_g")
    coords = {"speed_cm_s": [0.0, 12.0, 27.0], "scene": [0, 1],
              "threshold_g": [0.0, 0.03, 0.1, 0.3, 1.0]}
    tp, fp, misses = (np.asarray(a, float) for a in (tp, fp, misses))
    return xr.Dataset({"tp": (dims, tp), "fp": (dims, fp), "misses": (dims, misses),
                       "latency_sum_s": (dims, 0.1 * tp), "minutes": (dims, np.ones_like(tp)),
                       "out_of_band_contacts": (dims, np.zeros_like(tp))}, coords=coords)


def test_th_star_rises_with_the_shaking_and_the_sweep_picks_one_fixed_th():
    # Per speed the false positives vanish at a higher Th; contacts are lost only at 1 g.
    fp_gone = {0.0: 1, 12.0: 2, 27.0: 3}        # index of the first Th without shaking
    tp = np.zeros((3, 2, 5))
    fp = np.zeros((3, 2, 5))
    for i, v in enumerate(fp_gone):
        fp[i, :, :fp_gone[v]] = 4
        tp[i, :, :4] = 3
    misses = 3 - tp
    ds = sweep_counts(tp, fp, misses)
    fit = fit_th_star(ds)
    assert np.all(np.diff(fit.th_star_g) >= 0) and fit.th_star_g[-1] > fit.th_star_g[0]
    assert fit.at([27.0]) == pytest.approx(fit.th_star_g[-1])
    assert "f1" in ds and ds.f1.sel(speed_cm_s=27.0, threshold_g=0.3) == pytest.approx(1.0)
    assert fit.sweep_fixed_th_g in ds.threshold_g.values


def test_the_lookup_table_interpolates_in_log_th():
    table = LookupTable(np.array([0.0, 20.0]), np.array([0.01, 1.0]))
    assert table(10.0) == pytest.approx(0.1) and table(np.array([0.0, 30.0])) == \
        pytest.approx([0.01, 1.0])


def test_comparisons_pair_methods_by_seed_slot_and_pick_the_oracle_in_hindsight():
    scores = MethodScores(["ramp", "steps"])
    per_slot_tp = {"gated": [3, 3, 2], "lookup": [3, 2, 2], fixed_method(0.1): [2, 2, 1],
                   fixed_method(0.3): [1, 1, 1]}
    for method, tps in per_slot_tp.items():
        for slot, tp in enumerate(tps):
            for scene in range(2):
                scores.add(method, slot, scene, Score(tp=tp, misses=3 - tp, minutes=0.5))
    f1 = scores.per_seed("gated")
    assert f1 == pytest.approx([1.0, 1.0, 2 * 4 / (2 * 4 + 2)])
    assert scores.per_seed("gated", "ramp") == pytest.approx([1.0, 1.0, 0.8])
    fixed = np.array([0.1, 0.3])
    assert scores.best_fixed(fixed) == 0.1
    result = compare(scores, fixed, 0.3)
    assert result["oracle_th_g"] == 0.1
    d = result["differences"]["gated − best fixed in hindsight"]
    assert d["n"] == 3 and d["mean"] == pytest.approx(np.mean(f1 - scores.per_seed("fixed:0.1")))
    assert [r["scenes"] for r in result["per_category"]] == ["ramp", "steps"]
    assert result["per_category"][0]["contacts scored"] == 9
    assert scores.seeds_needed("gated", ["lookup"], 0.5) >= 2


def test_a_bounded_interval_is_the_bootstrap_not_a_clipped_t():
    from snn_antenna.evaluation.thresholds import F1_BOUNDS, interval

    d = interval([0.95, 1.0, 1.0], F1_BOUNDS)
    # a t interval clipped at 1 would reach far below the lowest value (0.88 here)
    assert 0.95 - 1e-12 <= d["low"] <= d["mean"] <= d["high"] <= 1.0 and d["n"] == 3


def test_no_verdict_on_the_gate_from_too_few_seeds():
    from snn_antenna.evaluation.thresholds import difference, earns_its_place

    ahead = difference([0.9, 0.91], [0.5, 0.52])          # clearly ahead, but n = 2
    s = {"differences": {"gated − best fixed in hindsight": ahead, "gated − lookup": ahead}}
    earned, why = earns_its_place(s)
    assert not earned and "too small to resolve" in why and "n = 2" in why
    many = difference([0.9, 0.91, 0.92, 0.9, 0.93], [0.5, 0.52, 0.5, 0.51, 0.5])
    level = difference([0.9, 0.91, 0.92, 0.9, 0.93], [0.91, 0.9, 0.93, 0.9, 0.92])
    s = {"differences": {"gated − best fixed in hindsight": many, "gated − lookup": level}}
    assert earns_its_place(s)[0]
