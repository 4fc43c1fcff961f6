"""The model-selection study: each candidate contact mechanism moves the data the
way its physics says, and the study keeps its calibrations apart from its predictions."""
from __future__ import annotations

import importlib
import json
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.engine import rates
from snn_antenna.sources import antenna, bench
from snn_antenna.sources.contact_models import ContactPhysics
from snn_antenna.studies import model_selection as ms
from snn_antenna.studies.model_selection import cost as ms_cost
from snn_antenna.studies.model_selection import protocol
from snn_antenna.studies.contract import Options

RATE = 2000.0
SPEC = "studies/model_selection.toml"
# the per-point path: every read-out at one grid point (the package exports the study's run
# under the module's name)
MEASURE = importlib.import_module("snn_antenna.studies.model_selection.run").measure


def ringing(material, physics, distance_cm=30.0, n=2000):
    return antenna.contact_ringing(distance_cm, material, RATE, n, np.random.default_rng(0),
                                   scatter=False, physics=physics)


def high_share(x) -> float:
    """Energy above the paper's 55 Hz split relative to the energy below it."""
    spectrum = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(len(x), 1 / RATE)
    return float(spectrum[f > 55].sum() / spectrum[f <= 55].sum())


def low_peak_hz(x) -> float:
    """The low mode's frequency, read from a finely zero-padded spectrum below 40 Hz."""
    n = 2 ** 20
    spectrum, f = np.abs(np.fft.rfft(x, n)), np.fft.rfftfreq(n, 1 / RATE)
    below = f < 40
    return float(f[below][np.argmax(spectrum[below])])


def test_hertz_stiffer_rod_shorter_impact_more_high_mode():
    """Hertz: t_c ∝ (m²/E*²)^(1/5), so the stiff metal stops the tube sooner than the soft
    wood (1 GPa across the grain) and its short pulse excites the high mode more."""
    physics = ContactPhysics("hertz", 1000.0)
    metal, wood = antenna.MATERIALS["aluminium"], antenna.MATERIALS["wood"]
    mass = physics.effective_mass_kg()
    assert metal.impact_duration_s(mass) < wood.impact_duration_s(mass)
    assert high_share(ringing("aluminium", physics)) > 1.15 * high_share(ringing("wood", physics))
    # the longer the impact (more mass), the less high mode: the pulse spectrum's low-pass
    assert high_share(ringing("wood", physics)) < \
        0.8 * high_share(ringing("wood", ContactPhysics("hertz", 1.0)))


def test_boundary_soft_rod_lowers_the_mode_more():
    """A compliant contact (k_s = 3EI/L³: acrylic 2.9 kN/m, aluminium 62 kN/m) lowers the
    antenna's low mode below the clamped law, more on the soft rod."""
    physics = ContactPhysics("boundary", 3.0)
    clamped = float(antenna.low_mode_hz(20.0))
    soft = low_peak_hz(ringing("acrylic_glass", physics, 20.0, 8000))
    stiff = low_peak_hz(ringing("aluminium", physics, 20.0, 8000))
    assert soft < stiff <= clamped + 0.05    # peak-reading bias of a damped mode: ~0.02 Hz
    assert clamped - soft > 5 * (clamped - stiff)
    # the default (a rigid clamp) leaves the law alone
    assert low_peak_hz(ringing("acrylic_glass", ContactPhysics(), 20.0, 8000)) == \
        pytest.approx(clamped, abs=0.05)


def test_friction_high_mu_rod_loses_its_ring_sooner():
    """Coulomb friction removes μ-proportional amplitude per cycle (∝ f²: the high mode
    first): acrylic (μ 0.8) loses more of its high mode than POM (μ 0.2)."""
    def kept(material):
        return high_share(ringing(material, ContactPhysics("friction", 0.1))) / \
            high_share(ringing(material, ContactPhysics("friction", 0.01)))
    assert kept("acrylic_glass") < kept("pom") < 1.0
    # and the ring stops: no amplitude at all after the friction has eaten it
    x = ringing("acrylic_glass", ContactPhysics("friction", 1.0), 37.5)
    assert np.all(x[-200:] == 0.0)


def test_default_physics_is_the_current_model():
    """The default is 'current' at strength 1: the rod's line is there, as on main."""
    assert bench.BenchSpec().contact_physics == ContactPhysics("current", 1.0)
    with_line = ringing("aluminium", ContactPhysics())
    without = ringing("aluminium", ContactPhysics("hertz", 1.0))   # same mass, no line
    assert not np.allclose(with_line, without)


@pytest.mark.parametrize("field, value", [("physics", "magic"), ("physics", "hertz+hertz"),
                                          ("physics_strength", 0.0),
                                          ("physics_strength", float("nan"))])
def test_bad_physics_is_named(field, value):
    with pytest.raises(SpecError, match=field):
        bench.BenchSpec(**{field: value}).validate()


def _point(strength, accuracy, sites, nmf=0.5):
    return {"physics": "x", "strength": strength, "r2_low": 0.99,
            "per_seed": {"material_accuracy_spectrum": [accuracy, accuracy],
                         "nmf30_accuracy": [nmf, nmf], "two_material_accuracy": [0.6, 0.6],
                         "rmse_spectrum_mm": [3.0, 3.0], "rmse_two_peaks_mm": [4.0, 4.0]},
            "wood_aluminium_sites": sites, "brass_wood_rank": 5}


def test_calibration_uses_only_the_targets_and_loto_predicts_the_left_out():
    """The constant is chosen by the two targets alone (a better prediction elsewhere does
    not move it); leaving one target out picks by the other and predicts the left one."""
    points = [_point(1.0, 0.94, 2.0, nmf=0.99),     # best NMF-30, bad sites
              _point(2.0, 0.90, 12.0, nmf=0.10),    # worse accuracy, sites right
              _point(3.0, 0.60, 13.0, nmf=0.10)]
    c = protocol.choose("x", points)
    assert c["strength"] == 2.0
    assert c["loto"]["wood_aluminium_sites"]["strength"] == 1.0     # from accuracy alone
    assert c["loto"]["wood_aluminium_sites"]["predicted"] == 2.0
    assert c["loto"]["material_accuracy_spectrum"]["strength"] == 2.0
    unreadable = {"physics": "x", "strength": 9.0, "unreadable": "skipped 50 %"}
    assert protocol.choose("x", points + [unreadable])["strength"] == 2.0
    assert protocol.choose("x", [unreadable])["point"] is None


def test_a_candidate_that_misses_its_calibration_is_not_chosen_for_its_predictions():
    """Predictions choose only among candidates that reproduce their calibration targets:
    a mechanism that wrecks the fitted accuracy (0.2 for 0.942) but predicts NMF-30 perfectly
    is refused, and when nothing calibrates nothing is chosen."""
    good = protocol.choose("current", [_point(1.0, 0.94, 12.0, nmf=0.5)])
    wild = protocol.choose("hertz", [_point(1.0, 0.20, 12.0, nmf=0.99)])
    wild["physics"] = "hertz"
    assert good["calibrated"] and not wild["calibrated"]
    assert wild["n_met"] > good["n_met"]
    decision = protocol.select({"current": good, "hertz": wild})
    assert decision["chosen"] == "current" and decision["not_calibrated"] == ["hertz"]
    nothing = protocol.select({"hertz": wild})
    assert nothing["chosen"] is None and "calibration" in nothing["reason"]


def test_a_combination_keeps_the_rod_line_at_its_reference():
    """In ``current+X`` the strength is X's; the rod's line stays as calibrated alone."""
    assert ContactPhysics("current", 2.0).rod_coupling_scale() == 2.0
    assert ContactPhysics("current+hertz", 300.0).rod_coupling_scale() == 1.0
    assert ContactPhysics("current+hertz", 300.0).effective_mass_kg() == \
        pytest.approx(ContactPhysics("hertz", 300.0).effective_mass_kg())
    assert ContactPhysics("hertz", 300.0).rod_coupling_scale() == 0.0


def _trimmed_quick(tmp_path):
    spec = specs.load(SPEC, quick=True)
    spec["stimulus"]["cache_dir"] = str(tmp_path / "cache")
    spec["stimulus"]["n_jobs"] = 1          # here, not on Dask workers
    spec["stimulus"]["positions_cm"] = [8.0, 20.0, 37.5]
    spec["evaluation"]["seeds"] = [0, 1]
    spec["selection"]["candidates"] = [{"physics": "current", "strengths": [1.0]},
                                       {"physics": "boundary", "strengths": [3.0]}]
    return spec


@pytest.fixture(scope="module")
def trimmed_run(tmp_path_factory):
    """The trimmed quick study, run once here: (its plan, its summary, its folder). The
    boundary candidate has two grid values, so one point is not its calibrated one."""
    tmp_path = tmp_path_factory.mktemp("trimmed")
    spec = _trimmed_quick(tmp_path)
    spec["selection"]["candidates"] = [{"physics": "current", "strengths": [1.0]},
                                       {"physics": "boundary", "strengths": [1.0, 3.0]}]
    plan = ms.plan(spec)
    out = tmp_path / "out"
    return plan, ms.run(plan, out, Options(quick=True), log=lambda *a: None), out


def test_quick_study_keeps_calibrated_apart_from_predicted(trimmed_run):
    _, summary, out = trimmed_run
    saved = json.loads((out / "summary.json").read_text())
    assert (out / "report.html").exists() and (out / "model_selection.png").exists()
    calibrated = {c["quantity"] for c in saved["calibrated"]}
    predicted = {p["quantity"] for p in saved["predicted"]}
    assert not calibrated & predicted
    for name in ("current", "boundary"):
        assert calibrated == {f"{n}: {t[2]}" for n in ("current", "boundary")
                              for t in protocol.CALIBRATION_TARGETS.values()}
        for what in (p[3] for p in protocol.PREDICTIONS.values()):
            assert f"{name}: {what}" in predicted
        # the seeds' values are kept, with a verdict the statistics rules allow at n = 2
        nmf = next(p for p in saved["predicted"] if p["quantity"] == f"{name}: 8 materials, "
                   "NMF-30 accuracy")
        assert nmf["n"] == 2 and "too small to resolve" in nmf["note"]
        assert set(saved["candidates"][name]["loto"]) == set(protocol.CALIBRATION_TARGETS)
    # the outcome leads the page, above the calibrated and predicted tables
    page = (out / "report.html").read_text()
    assert page.index('class="lead"') < page.index("Calibrated to")
    assert "of 5" in page[page.index('class="lead"'):page.index("Calibrated to")]
    # too few contacts to meet the calibration: the quick run chooses nothing
    assert summary["selection"]["chosen"] in ("current", "boundary", None)
    assert saved["grid"][1]["physics"] == "boundary"


def test_spec_refuses_physics_in_the_stimulus(tmp_path):
    spec = _trimmed_quick(tmp_path)
    spec["stimulus"]["physics"] = "hertz"
    with pytest.raises(SpecError, match="stimulus.physics"):
        ms.plan(spec)
    spec = _trimmed_quick(tmp_path)
    spec["selection"]["candidates"] = [{"physics": "spring", "strengths": [1.0]}]
    with pytest.raises(SpecError, match="physics"):
        ms.plan(spec)


@pytest.mark.slow
def test_quick_profile_runs_end_to_end(tmp_path):
    spec = specs.load(SPEC, quick=True)
    spec["stimulus"]["cache_dir"] = str(tmp_path / "cache")
    summary = ms.run(ms.plan(spec), tmp_path / "out", Options(quick=True),
                     log=lambda *a: None)
    assert summary["candidates"]["friction"]["unreadable"] == [1.0]
    assert summary["selection"]["chosen"] in (*summary["candidates"], None)


@pytest.mark.slow
def test_grid_points_on_dask_workers_give_the_grid_measured_here(tmp_path):
    here = ms.run(ms.plan(_trimmed_quick(tmp_path)), tmp_path / "here", Options(quick=True),
                  log=lambda *a: None)
    spec = _trimmed_quick(tmp_path)
    spec["stimulus"]["n_jobs"] = 2      # two local Dask workers, a grid point each
    there = ms.run(ms.plan(spec), tmp_path / "there", Options(quick=True), log=lambda *a: None)
    assert there["grid"] == here["grid"]
    assert there["selection"] == here["selection"]


def _plain(x):
    """A summary's JSON form (numpy scalars as Python numbers)."""
    return json.loads(json.dumps(x, default=lambda o: o.item()))


def test_predictions_at_calibrated_points_are_those_of_measuring_every_point(trimmed_run):
    """The run reads the predicted read-outs at each candidate's calibrated point only: there
    they are what measuring every read-out at every point gives, the other points hold the
    same calibration quantities without them, and the choice is the one all numbers make."""
    plan, summary, _ = trimmed_run
    summary = _plain(summary)
    everything = [_plain(MEASURE(plan.parts, p["physics"], p["strength"],
                                        lambda *a: None)) for p in summary["grid"]]
    chosen = {(c["physics"], c["strength"]) for c in summary["candidates"].values()}
    assert len(chosen) == 2 and len(summary["grid"]) == 3
    for point, full in zip(summary["grid"], everything):
        if (point["physics"], point["strength"]) in chosen:
            assert point == full
        else:
            assert set(point["per_seed"]) == {"material_accuracy_spectrum"}
            assert set(full["per_seed"]) == set(protocol.SCORES)
            assert point == {**full, "per_seed": {k: full["per_seed"][k]
                                                  for k in point["per_seed"]}}
    candidates = {name: protocol.choose(name, [p for p in everything if p["physics"] == name])
                  for name in ("current", "boundary")}
    assert _plain(candidates) == summary["candidates"]
    assert _plain(protocol.select(candidates)) == summary["selection"]


def test_the_estimate_is_the_sum_of_the_plans_parts(monkeypatch):
    """Every grid point's bench set and calibration, each candidate's predictions, shared by
    the workers; the workers' start once; the parts named in the line --check prints."""
    monkeypatch.setattr(rates, "competing_load", lambda: 0.0)
    # no grid point's features on disk (a run on this machine may have left them)
    monkeypatch.setattr(ms_cost.signal, "features_path",
                        lambda *a: Path("/nonexistent/features.zarr"))
    monkeypatch.setattr(rates, "load_factor", lambda: (1.0, ""))
    parts = ms.plan(specs.load(SPEC)).parts
    points = sum(len(c.strengths) for c in parts.selection.candidates)
    candidates = len(parts.selection.candidates)
    cost = ms_cost.point_cost(parts)
    start = rates.rates()["python_s"]["study_start"].value
    work = points * (cost.bench + cost.calibration) + candidates * cost.predictions
    assert ms_cost.estimate(parts, 1).seconds == pytest.approx(work)
    two = ms_cost.estimate(parts, 2)
    assert two.seconds == pytest.approx(work / 2 + start)
    for part in ("21 grid points of 12,800 events on 2 worker(s)", "bench sets and features",
                 "calibration read-outs", "predicted read-outs at 7 calibrated points",
                 "workers' start"):
        assert part in two.describe()
    # the bench set's cost per event, the calibration's per training event and epoch
    more = ms.plan(specs.load(SPEC, ["stimulus.repetitions=200"])).parts
    assert ms_cost.point_cost(more).bench - ms_cost.POINT_S == \
        pytest.approx(2 * (cost.bench - ms_cost.POINT_S))
    assert ms_cost.point_cost(more).calibration == pytest.approx(2 * cost.calibration)
    # at a load of 3, each worker is one of 3 + 2 processes sharing the cores
    monkeypatch.setattr(rates, "competing_load", lambda: 3.0)
    assert ms_cost.estimate(parts, 2).seconds - start == pytest.approx(
        (work / 2) * rates.slowdown(4.0))


def test_a_point_whose_features_are_on_disk_costs_only_its_own_work(monkeypatch, tmp_path):
    """A re-run finds its grid points' bench sets and features cached: the estimate charges
    those points their own work, not the generation."""
    monkeypatch.setattr(rates, "competing_load", lambda: 0.0)
    monkeypatch.setattr(rates, "load_factor", lambda: (1.0, ""))
    parts = ms.plan(specs.load(SPEC)).parts
    points = sum(len(c.strengths) for c in parts.selection.candidates)
    cost = ms_cost.point_cost(parts)
    monkeypatch.setattr(ms_cost.signal, "features_path", lambda *a: tmp_path / "none.zarr")
    cold = ms_cost.estimate(parts, 1).seconds
    (tmp_path / "made.zarr").mkdir()
    monkeypatch.setattr(ms_cost.signal, "features_path", lambda *a: tmp_path / "made.zarr")
    warm = ms_cost.estimate(parts, 1).seconds
    assert cold - warm == pytest.approx(points * (cost.bench - ms_cost.POINT_S))
