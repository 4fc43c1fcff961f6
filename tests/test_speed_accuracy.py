"""The speed/accuracy study end to end (quick profile) and its spec checks."""
import json

import numpy as np
import pytest

from snn_antenna import spec as specs
from snn_antenna.errors import SpecError
from snn_antenna.studies import runner
from snn_antenna.studies import speed_accuracy as study

SPEC = "studies/speed_accuracy.toml"


def test_quick_study_writes_rows_fronts_recommendations_and_the_stability_map(tmp_path):
    spec = specs.load(SPEC, quick=True)
    summary = runner("speed_accuracy").run(spec, tmp_path, quick=True, log=lambda *a: None)
    for name in ("report.html", "summary.json", "pareto.png", "stability_map.png"):
        assert (tmp_path / name).is_file(), name
    assert (tmp_path / "stability_map.zarr").is_dir()
    stored = json.loads((tmp_path / "summary.json").read_text())   # no NaN can be written
    rows = stored["rows"]
    quick = spec["sweep"]
    main = [r for r in rows if r["sweep"] == "main"]
    assert len(main) == len(quick["scenes"]) * len(quick["methods"]) * len(quick["dt_ms"])
    for r in rows:
        assert {"method", "dt_ms", "target", "dtype", "wall_s", "cpu_s", "status",
                "spike_time_error_ms", "spike_count_error", "rate_map_error",
                "distance_error_cm", "detection_f1"} <= set(r)
        assert r["status"] == "ok" or r["status"].startswith("non-finite")
        if r["status"] == "ok" and r["rate_map_error"] is not None:
            assert r["rate_map_error"] >= 0 and r["spike_time_error_ms"] >= 0
    bench = [r for r in main if r["scene"] == "bench"]
    assert all(r["detection_f1"] is not None for r in bench)
    # finer steps are closer to the reference, method by method
    for m in quick["methods"]:
        fine, coarse = sorted((r for r in bench if r["method"] == m), key=lambda r: r["dt_ms"])
        assert fine["spike_time_error_ms"] < coarse["spike_time_error_ms"]
    assert stored["reference_convergence"]["max_shift_ms"] < 1e-3
    assert {r["scene"] for r in stored["recommendations"]} <= set(quick["scenes"])
    assert set(stored["stability_limits"]) == set(quick["methods"])
    sizes = {r["n_neurons"] for r in rows if r["sweep"] == "cost"}
    assert sizes == set(spec["cost"]["n_neurons"])
    assert summary["rows"] == rows


@pytest.mark.parametrize("override, field", [
    ("sweep.methods=['heun']", "sweep.methods"),
    ("sweep.dt_ms=[0.1, 2.0]", "sweep.dt_ms"),
    ("cost.targets=['gpu']", "cost.targets"),
    ("sweep.colour='red'", "sweep.colour"),
    ("reference.check_rtol=1e-6", "reference.check_rtol"),
])
def test_bad_specs_are_refused_before_any_work(override, field):
    spec = specs.load(SPEC, [override], quick=True)
    with pytest.raises(SpecError) as info:
        study.build(spec)
    assert info.value.field == field


def test_pareto_front_and_recommendation_pick_the_cheapest_sufficient_runs():
    rows = [dict(scene="s", method="euler", dt_ms=dt, status="ok", cpu_s=c, rate_map_error=e,
                 readout_matches=m)
            for dt, c, e, m in ((0.01, 10.0, 0.01, True), (0.1, 1.0, 0.04, True),
                                (0.5, 0.5, 0.2, False), (1.0, 0.6, 0.3, True))]
    front = study.pareto_front(rows, "rate_map_error")
    assert [r["dt_ms"] for r in front] == [0.5, 0.1, 0.01]
    forced = dict(rows[2], dt_ms=0.7, cpu_s=0.1, readout_matches=True, rate_map_error=0.0,
                  beyond_stable_limit=True)
    recs = {r["criterion"]: r["dt_ms"] for r in study.recommend(rows + [forced], study.Match())}
    assert recs["read-out matches the reference"] == 1.0        # cheapest that matches
    assert recs["rate map within 5%"] == 0.1
    assert recs["read-out matches at this dt and every finer one"] == 0.1   # 0.5 breaks it


def _row(status="ok", **errors):
    return dict(sweep="main", scene="bench", method="euler", dt_ms=0.1, status=status,
                **{e: errors.get(e, 0.1) for e in study.ERRORS}, distance_cm=25.0)


def test_a_run_with_a_non_finite_value_but_no_exception_is_marked_and_counted():
    finite = study.Run(np.array([0, 1]), np.array([1.0, 2.0]), 0.1, 0.1)
    silent = study.Run(np.array([0, 1]), np.array([1.0, np.nan]), 0.1, 0.1)
    ok = study._check_finite(_row(), finite)
    assert ok["status"] == "ok" and ok["nonfinite_without_exception"] is False
    bad = study._check_finite(_row(), silent)
    assert bad["nonfinite_without_exception"] is True and "spike times" in bad["status"]
    score = study._check_finite(_row(rate_map_error=float("inf")), finite)
    assert score["rate_map_error"] is None and "rate_map_error" in score["status"]
    raised = _row(status="non-finite (raised NumericalInstabilityError)")
    counts = study.count_nonfinite([ok, bad, score, raised])
    assert counts == {"nonfinite_without_exception": 2, "raised_instability": 1}


def test_the_reference_verdict_says_what_was_measured():
    rows = [_row(spike_time_error_ms=0.6), _row(spike_time_error_ms=2.0)]
    base = dict(same_spike_counts=True, scene="bench", rtol=1e-10, check_rtol=1e-12)
    far = dict(base, max_shift_ms=1e-5)
    far.update(study._convergence_verdict(far, rows))
    assert far["far_below"] and "converged far below" in study._convergence_text(far)
    near = dict(base, max_shift_ms=0.1)
    near.update(study._convergence_verdict(near, rows))
    text = study._convergence_text(near)
    assert not near["far_below"] and "far below" not in text and "only 6×" in text
    moved = dict(base, same_spike_counts=False, max_shift_ms=3.0)
    moved.update(study._convergence_verdict(moved, rows))
    assert "not converged" in study._convergence_text(moved)


def test_the_quick_banner_names_the_methods_the_quick_sweep_leaves_out():
    spec = specs.load(SPEC, quick=True)
    *_, parts = study.build(spec)
    note = study.quick_note(parts["sweep"], parts, parts["sweep"].scenes)
    missing = [m for m in study.neurons.METHODS if m not in parts["sweep"].methods]
    assert missing and all(m in note for m in missing)
    assert note.startswith("quick profile")
