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
