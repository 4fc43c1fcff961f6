"""The speed/accuracy study end to end (quick profile) and its spec checks."""
import json

import pytest

from snn_antenna.core import spec as specs
from snn_antenna.engine.runlog import RUN_IDENTITY, RunLog
from snn_antenna.core.errors import SpecError
from snn_antenna.networks import neurons
from snn_antenna.evaluation import tradeoff
from snn_antenna.studies import runner
from snn_antenna.studies.contract import Options
from snn_antenna.studies import speed_accuracy as study
from snn_antenna.studies.speed_accuracy import report as study_report

SPEC = "studies/speed_accuracy.toml"


# The default suite's run: every stage but the bands' 0.001-0.002 ms runs and the compiled
# sweep engine's precision stage (two compiles), on the bench scene alone, two methods at
# dt 0.2 and 0.5 ms and one array size in both float types (~40 s before, when it ran the
# whole quick main sweep on both scenes). The slow run is the whole quick profile: the tuning
# scene, izhikevich, the bands (+75 s) and float32 on the sweep engine.
DEFAULT_SUITE = ["bands.bands=[]", "precision.dtypes=[]", "sweep.scenes=['bench']",
                 "sweep.methods=['euler', 'rk2']", "sweep.dt_ms=[0.2, 0.5]",
                 "reference.check_scene='bench'", "cost.n_neurons=[24]"]


@pytest.mark.parametrize("overrides", [
    DEFAULT_SUITE,
    pytest.param([], marks=pytest.mark.slow),
])
def test_quick_study_writes_rows_fronts_recommendations_and_the_stability_map(tmp_path,
                                                                              overrides):
    spec = specs.load(SPEC, overrides, quick=True)
    study_module = runner("speed_accuracy")
    summary = study_module.run(study_module.plan(spec), tmp_path, Options(quick=True),
                               log=lambda *a: None)
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
    cost = [r for r in rows if r["sweep"] == "cost"]
    assert {r["n_neurons"] for r in cost} == set(spec["cost"]["n_neurons"])
    assert {r["dtype"] for r in cost} == set(spec["cost"]["dtypes"])   # float32 is an axis
    # runtime costs are timed on a sample of the run, and the sample fires as the compiled
    # run that scored the setting did over the same window
    for r in cost + main:
        if r["status"] == "ok" and r["target"] != "cpp_standalone":
            assert "timed" in r["cost_from"] and r["cpu_s"] > 0, r
    done = stored["main_sweep"]
    assert done["timed_samples"] > 0 and done["samples_agree"] == done["timed_samples"]
    own = {r["n_neurons"] for r in main if r["scene"] == spec["cost"]["scene"]}
    for r in cost:     # only the array's own size has a reference to score against
        scored = r["n_neurons"] in own and r["status"] == "ok"
        assert (r["rate_map_error"] is not None) == scored, r
    assert summary["rows"] == rows
    precision = stored["precision"]
    if not spec["precision"]["dtypes"]:
        assert precision is None
        return
    by_dtype = {r["dtype"]: r for r in precision["rows"]}
    assert set(by_dtype) == set(spec["precision"]["dtypes"])
    assert by_dtype["float64"]["spike_count_error"] == 0      # float64 is the comparison
    for r in precision["rows"] + [precision["baseline"]]:
        assert r["ns_per_neuron_step"] > 0 and 0 <= r["same_count_share"] <= 1
    r32 = by_dtype["float32"]
    assert r32["within_tolerance"] == (r32["spike_count_error"] <= precision["tolerance"])
    assert "Sweep engine: float precision" in (tmp_path / "report.html").read_text()


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
        study.plan(spec)
    assert info.value.field == field


def test_the_run_log_resumes_the_same_spec_and_starts_over_for_another(tmp_path):
    path = tmp_path / "runs.jsonl"
    row = dict(sweep="main", scene="bench", method="euler", dt_ms=0.1, target="numpy",
               dtype="float64", n_neurons=24, cpu_s=1.0)
    RunLog(path, {"seed": 1}).add(row)
    with open(path, "a") as f:
        f.write('{"sweep": "main", "sce')          # a line cut short by an interruption
    again = RunLog(path, {"seed": 1})
    assert again.get(**{k: row[k] for k in RUN_IDENTITY}) == row
    assert again.get(**dict({k: row[k] for k in RUN_IDENTITY}, dt_ms=0.5)) is None
    assert RunLog(path, {"seed": 2}).rows == {}
    assert RunLog(path, {"seed": 2}, fresh=True).rows == {}


def test_the_reference_verdict_says_what_was_measured():
    rows = [dict(sweep="main", scene="bench", method="euler", dt_ms=0.1, status="ok",
                 spike_time_error_ms=e) for e in (0.6, 2.0)]
    base = dict(same_spike_counts=True, scene="bench", rtol=1e-10, check_rtol=1e-12)

    def text(**shift):
        conv = dict(base, **shift)
        return study_report.convergence_text(dict(conv,
                                                  **tradeoff.convergence_verdict(conv, rows)))

    assert "converged far below" in text(max_shift_ms=1e-5)
    near = text(max_shift_ms=0.1)
    assert "far below" not in near and "only 6×" in near
    assert "not converged" in text(same_spike_counts=False, max_shift_ms=3.0)


def test_the_quick_banner_names_the_methods_the_quick_sweep_leaves_out():
    spec = specs.load(SPEC, quick=True)
    plan = study.plan(spec).parts
    note = study_report.quick_note(plan.sweep, plan.stability)
    missing = [m for m in neurons.METHODS if m not in plan.sweep.methods]
    assert missing and all(m in note for m in missing)
    assert note.startswith("quick profile")
