"""Every study reads recorded data where it read generated data (``data = "DIR"``): the same
samples and labels reach it, and its report says where they came from."""
import json
from pathlib import Path

import numpy as np
import pytest

from data_helpers import (RATE, import_dir, import_quickstart_drive, ringing_counts,
                          write_labels, write_record)
from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.studies import baseline_comparison, quickstart, speed_accuracy
from snn_antenna.studies.contract import Options

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """The quickstart's quick scene, recorded as the board sends it, its contacts labelled."""
    tmp = tmp_path_factory.mktemp("drive")
    spec = specs.load(ROOT / "studies" / "quickstart.toml", [], quick=True)
    rec, data = import_quickstart_drive(tmp, spec)
    return spec, rec, data


def test_quickstart_reads_the_recorded_drive_sample_for_sample(drive):
    spec, generated, data = drive
    parts = quickstart.plan({**spec, "data": str(data)}).parts
    rec = parts.scene.generate(0)
    assert np.array_equal(rec.samples, generated.samples)
    assert rec.rate_hz == generated.rate_hz
    assert [(c.t_s, c.distance_cm, c.material) for c in rec.truth.contacts] == \
        [(c.t_s, c.distance_cm, c.material) for c in generated.truth.contacts]
    assert (parts.scene.adc_bits, parts.scene.full_scale_g) == (10, 18.0)


def test_speed_accuracy_takes_the_recorded_drive_as_its_quickstart_scene(drive):
    _, generated, data = drive
    spec = specs.load(ROOT / "studies" / "speed_accuracy.toml", [], quick=True)
    plan = speed_accuracy.plan({**spec, "data": str(data)}).parts
    assert np.array_equal(plan.robot_scenes["quickstart"].generate(0).samples,
                          generated.samples)


def test_a_study_refuses_a_data_set_of_the_other_kind_in_one_line(drive, tmp_path):
    spec, _, data = drive
    with pytest.raises(SpecError, match="imported bench recordings"):
        baseline_comparison.plan({**specs.load(ROOT / "studies" / "baseline_comparison.toml",
                                                [], quick=True), "data": str(data)})
    with pytest.raises(SpecError, match="data"):
        quickstart.plan({**spec, "data": str(tmp_path)})


def test_the_baseline_comparison_at_the_boards_rate_names_what_it_cannot_read(tmp_path):
    """The board samples at 1 kHz: a spectrum to 508 Hz is refused in one line naming the
    field, before any work."""
    onsets = [1.0, 2.5, 4.0]
    write_record(tmp_path / "recs" / "run1", ringing_counts(onsets, [10, 20, 30], 6.0))
    write_labels(tmp_path / "labels.csv", [("run1", t, d, "wood", 0)
                                          for t, d in zip(onsets, [10, 20, 30])])
    data = import_dir(tmp_path / "recs", tmp_path / "labels.csv", tmp_path / "data")
    spec = specs.load(ROOT / "studies" / "baseline_comparison.toml", [], quick=True)
    with pytest.raises(SpecError) as refused:
        baseline_comparison.plan({**spec, "data": str(data)})
    assert refused.value.field.startswith("events.")
    assert "500" in str(refused.value)
    spec = {**spec, "data": str(data), "events": {**spec["events"], "max_hz": 499.0},
            "evaluation": {**spec["evaluation"], "pipelines": ["distance", "material"]}}
    spec.pop("spiking")
    parts = baseline_comparison.plan(spec).parts
    assert parts.bench.recorded and parts.bench.n_events == 3 and parts.bench.rate_hz == RATE


@pytest.mark.slow
def test_quickstart_on_the_recorded_drive_scores_as_on_the_generated_scene(drive, tmp_path):
    spec, _, data = drive
    quiet, quick = (lambda *a: None), Options(quick=True)
    generated = quickstart.run(quickstart.plan(spec), tmp_path / "generated", quick, log=quiet)
    on_data = quickstart.run(quickstart.plan({**spec, "data": str(data)}), tmp_path / "recorded",
                             quick, log=quiet)
    for key in ("tp", "fp", "misses", "mean_abs_distance_error_cm"):
        assert on_data["score"][key] == generated["score"][key]
    shown = {c["quantity"] for c in on_data["calibrated"]}
    assert not any("generator" in q for q in shown) and any("generator" in q for q in
                                                             {c["quantity"] for c in
                                                              generated["calibrated"]})
    page = (tmp_path / "recorded" / "report.html").read_text()
    meta = json.loads((data / "import.json").read_text())
    assert meta["recordings"][0]["files"][0]["sha256"][:16] in page


# -- the gating threshold study on recorded drives ------------------------------------------------
def record_scene(path, rec) -> None:
    """A generated drive written as `record` keeps a drive: its counts, the speed command it
    started at and every change (as the live controls journal them)."""
    speed = np.asarray(rec.meta["speed_cm_s"], dtype=float)
    changes = [(int(i), float(speed[i])) for i in np.flatnonzero(np.diff(speed)) + 1]
    write_record(path, rec.samples, speed_cm_s=float(speed[0]), speed_changes=changes)


@pytest.fixture(scope="module")
def gating_drives(tmp_path_factory):
    """A calibration drive in the open and a drive along a course on a speed ramp, generated
    as the study generates its scenes, recorded and labelled."""
    from snn_antenna.sources.scenes import SpeedProfile, drive as open_drive, ramp
    from snn_antenna.studies.gating_threshold.spec import make_parts as build, make_scene

    tmp = tmp_path_factory.mktemp("gating")
    spec = specs.load(ROOT / "studies" / "gating_threshold.toml", [], quick=True)
    parts = build(spec)
    calibration = open_drive(parts.scene, SpeedProfile("constant", 15.0), 5.0, []).generate(7)
    v = parts.sweep.speeds_cm_s
    course, seed = make_scene(parts, ramp(float(v.min()), float(v.max()), parts.sweep.scene_s),
                              (9, 0))
    scored = course.generate(seed)
    assert scored.truth.contacts
    record_scene(tmp / "drives" / "calibration", calibration)
    record_scene(tmp / "drives" / "ramp", scored)
    write_labels(tmp / "labels.csv", [("ramp", c.t_s, c.distance_cm, c.material)
                                      for c in scored.truth.contacts],
                 ("recording", "contact_s", "distance_cm", "material"))
    return spec, scored, import_dir(tmp / "drives", tmp / "labels.csv", tmp / "data")


def test_the_gating_study_takes_recorded_drives_with_their_speed_log(gating_drives, tmp_path):
    from snn_antenna.studies.gating_threshold.spec import make_parts as build

    spec, scored, data = gating_drives
    parts = build({**spec, "data": str(data)})
    ramp = parts.data.recording(parts.data.names.index("ramp"))
    assert np.array_equal(ramp.samples, scored.samples)
    assert np.array_equal(ramp.meta["speed_cm_s"], np.asarray(scored.meta["speed_cm_s"],
                                                               dtype=np.float32))
    # a drive without its speed log cannot drive the gate: one line, before any work
    (tmp_path / "drives").mkdir()
    write_record(tmp_path / "drives" / "ramp", scored.samples)
    write_record(tmp_path / "drives" / "calibration", scored.samples[:2000])
    write_labels(tmp_path / "labels.csv", [("ramp", c.t_s, c.distance_cm, c.material)
                                           for c in scored.truth.contacts],
                 ("recording", "contact_s", "distance_cm", "material"))
    unlogged = import_dir(tmp_path / "drives", tmp_path / "labels.csv", tmp_path / "data")
    with pytest.raises(SpecError, match="speed command is logged"):
        build({**spec, "data": str(unlogged)})


@pytest.mark.slow
def test_the_gating_study_scores_the_gate_on_recorded_drives(gating_drives, tmp_path):
    from snn_antenna.studies import gating_threshold

    spec, scored, data = gating_drives
    s = gating_threshold.run(gating_threshold.plan({**spec, "data": str(data)}),
                             tmp_path / "out", Options(quick=True), log=lambda *a: None)
    rows = {r["method"]: r for r in s["recorded"]["rows"]}
    n = len(scored.truth.contacts)
    # every method scored on the same contacts (those after the settling time, in or out of
    # the array's band)
    counted = {r["tp"] + r["misses"] + r["out_of_band_contacts"] for r in rows.values()}
    assert len(counted) == 1 and 1 <= counted.pop() <= n
    page = (tmp_path / "out" / "report.html").read_text()
    meta = json.loads((data / "import.json").read_text())
    assert "The gate on recorded drives" in page
    assert meta["recordings"][0]["files"][0]["sha256"][:16] in page


def test_the_tuned_bank_is_refused_on_recorded_data_in_one_line(tmp_path):
    """Its channels are placed on generated calibration contacts of another seed, which a
    recording has not."""
    onsets = [1.0, 2.5, 4.0]
    write_record(tmp_path / "recs" / "run1", ringing_counts(onsets, [10, 20, 30], 6.0))
    write_labels(tmp_path / "labels.csv", [("run1", t, d, "wood", 0)
                                          for t, d in zip(onsets, [10, 20, 30])])
    data = import_dir(tmp_path / "recs", tmp_path / "labels.csv", tmp_path / "data")
    spec = specs.load(ROOT / "studies" / "baseline_comparison.toml", [], quick=True)
    bands = spec["spiking"]["bank"]["bands"]
    spec = {**spec, "data": str(data), "events": {**spec["events"], "max_hz": 499.0},
            "evaluation": {**spec["evaluation"], "pipelines": ["distance", "material"]},
            "spiking": {**spec["spiking"], "bank": {**spec["spiking"]["bank"],
                                                    "bands": {"low": bands["low"]}}}}
    with pytest.raises(SpecError) as refused:
        baseline_comparison.plan(spec)
    assert refused.value.field == "spiking.tuned"
    spec["spiking"].pop("tuned")
    assert baseline_comparison.plan(spec).parts.bank is not None
