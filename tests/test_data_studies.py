"""Every study reads recorded data where it read generated data (``data = "DIR"``): the same
samples and labels reach it, and its report says where they came from."""
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from data_helpers import (import_dir, import_gating_drives, import_quickstart_drive,
                          write_labels, write_record)
from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.sources.source import Scene
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


def test_a_scene_answers_the_same_questions_generated_or_recorded(drive):
    """Both kinds answer every question of ``source.Scene``; only the answers differ: where
    the data came from (rows, summary entry) and what the generator was set to match."""
    spec, _, data = drive
    generated = quickstart.plan(spec).parts.scene
    on_data = quickstart.plan({**spec, "data": str(data)}).parts.scene
    assert isinstance(generated, Scene) and isinstance(on_data, Scene)
    assert generated.provenance_rows() == [] and generated.summary_entry() is None
    meta = json.loads((data / "import.json").read_text())
    assert on_data.summary_entry()["key"] == meta["key"]
    assert dict(on_data.provenance_rows())["labels"].endswith(f"{meta['labels']['sha256']})")
    assert on_data.calibrated() == []
    assert any("generator" in c.quantity for c in generated.calibrated())
    assert "recorded drive" in on_data.describe()
    assert f"{generated.speed_cm_s:g} cm/s" in generated.describe()
    assert (on_data.rate_hz, on_data.duration_s) == (generated.rate_hz, generated.duration_s)


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


# -- the gating threshold study on recorded drives -------------------------------------------
GATING_QUICK = ["sweep.scene_s=4.0"]      # 4 s drives: the split and its checks, in seconds


@pytest.fixture(scope="module")
def gating_drives(tmp_path_factory):
    """Two course drives at each of the quick profile's speeds and one in the open, generated
    as the study generates its scenes, recorded with their speed log, labelled, imported."""
    tmp = tmp_path_factory.mktemp("gating")
    spec = specs.load(ROOT / "studies" / "gating_threshold.toml", GATING_QUICK, quick=True)
    data, recs = import_gating_drives(tmp, spec, calibration_s=2.0)
    return spec, recs, data


def test_the_gating_study_splits_recorded_drives_by_drive_within_each_speed(gating_drives):
    """Every scored drive is either a training or a held-out drive, never both; the training
    drives cover every swept speed; the open drive fits the chain; the seed draws the split."""
    from snn_antenna.studies.gating_threshold.plan import make_parts as build

    spec, recs, data = gating_drives
    splits = {}
    for seed in range(6):
        split = build({**spec, "seed": seed, "data": str(data)}).data
        roles = split.roles()
        train, held = set(roles["training drives"]), set(roles["held-out drives"])
        assert roles["calibration drive"] == "open"
        assert not train & held and train | held == set(recs) - {"open"}
        assert {n.split("_")[0] for n in train} == {n.split("_")[0] for n in held} \
            == {"v0", "v12", "v27"}
        splits[seed] = tuple(sorted(held))
    assert len(set(splits.values())) > 1
    again = build({**spec, "seed": 3, "data": str(data)}).data
    assert tuple(again.roles()["held-out drives"]) == splits[3]
    ramp = again.recording(again.drives.names.index("v27_1"))
    assert np.array_equal(ramp.samples, recs["v27_1"].samples)
    assert np.all(ramp.meta["speed_cm_s"] == 27.0)


def test_the_gating_study_refuses_recorded_drives_it_cannot_split_in_one_line(gating_drives,
                                                                               tmp_path):
    from snn_antenna.studies.gating_threshold.plan import make_parts as build

    spec, recs, data = gating_drives
    on_data = {**spec, "data": str(data)}
    with pytest.raises(SpecError) as refused:         # a speed no drive ran at
        build({**on_data, "sweep": {**spec["sweep"], "speeds_cm_s": [0.0, 12.0, 27.0, 30.0]}})
    assert refused.value.field == "sweep.speeds_cm_s" and "[30.0]" in str(refused.value)
    with pytest.raises(SpecError) as refused:         # a share that holds out nothing
        build({**on_data, "evaluation": {**spec["evaluation"], "held_out_drives": 0.2}})
    assert refused.value.field == "evaluation.held_out_drives"
    # one scored drive: nothing to hold out; a drive without its speed log: no gate input
    for name, logged in (("v27_0", True), ("v12_0", False)):
        folder = tmp_path / name
        for drive in ("open", name):
            write_record(folder / "drives" / drive, recs[drive].samples,
                         speed_cm_s=float(recs[drive].meta["speed_cm_s"][0]) if logged
                         else None)
        write_labels(folder / "labels.csv", [(name, c.t_s, c.distance_cm, c.material)
                                             for c in recs[name].truth.contacts],
                     ("recording", "contact_s", "distance_cm", "material"))
        if not logged:
            write_record(folder / "drives" / "v12_1", recs["v12_1"].samples)
        small = import_dir(folder / "drives", folder / "labels.csv", folder / "data")
        with pytest.raises(SpecError, match="at least two drives|speed command is logged"):
            build({**spec, "data": str(small)})


def test_check_refuses_a_speed_the_recorded_drives_lack_in_one_line(gating_drives, capsys):
    from snn_antenna.cli import main

    _, _, data = gating_drives
    args = ["run", str(ROOT / "studies" / "gating_threshold.toml"), "--quick", "--check",
            "--data", str(data), "--set", "sweep.speeds_cm_s=[0.0, 12.0, 27.0, 30.0]"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sweep.speeds_cm_s" in err and "[30.0]" in err
    assert main(args[:-2]) == 0


@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(), st.text(),
                 st.booleans(), st.none()))
def test_a_held_out_share_outside_0_to_1_is_refused_in_one_line(value):
    from snn_antenna.studies.gating_threshold.plan import EvaluationSettings

    valid = (isinstance(value, (int, float)) and not isinstance(value, bool)
             and 0 < value < 1)
    if valid:
        assert EvaluationSettings(held_out_drives=value).held_out_drives == value
        return
    with pytest.raises(SpecError) as refused:
        EvaluationSettings(held_out_drives=value)
    assert refused.value.field == "held_out_drives" and "\n" not in str(refused.value)


def test_a_recorded_drive_is_scored_at_the_speed_it_was_touched_at():
    """One drive at 0 then 27 cm/s: the contact and the detection on it count at the speed of
    the touch, a false positive at the speed of its onset, the minutes at each speed from
    the log."""
    from snn_antenna.core.signals import Recording
    from snn_antenna.core.truth import Event, GroundTruth
    from snn_antenna.readout.contacts import ContactEstimate
    from snn_antenna.studies.gating_threshold.recorded import score_by_speed
    from snn_antenna.studies.gating_threshold.plan import make_parts as build

    parts = build(specs.load(ROOT / "studies" / "gating_threshold.toml", [], quick=True))
    speed = np.r_[np.zeros(6000), np.full(4000, 27.0)]
    rec = Recording(np.zeros((10_000, 2)), 1000.0, GroundTruth((
        Event("contact", 2.0, 1.0, 20.0, "wood"), Event("contact", 5.95, 1.0, 20.0, "wood"),
        Event("contact", 8.0, 1.0, 20.0, "wood"))), meta={"speed_cm_s": speed})
    hit = ContactEstimate(2.0, 2.3, 12.0, 20.0)        # on the first contact (0 cm/s)
    late = ContactEstimate(6.0, 6.4, 12.0, 20.0)       # onset at 27 cm/s, on the 0 cm/s touch
    false = ContactEstimate(7.0, 7.2, 12.0, 20.0)      # on nothing, at 27 cm/s
    at0, at12, at27 = score_by_speed(parts.readout, [hit, late, false], rec, [0.0, 12.0, 27.0])
    assert (at0.tp, at0.fp, at0.misses) == (2, 0, 0)
    assert (at27.tp, at27.fp, at27.misses) == (0, 1, 1)
    assert (at12.tp, at12.fp, at12.misses, at12.minutes) == (0, 0, 0, 0.0)
    assert at0.minutes == pytest.approx(5.0 / 60) and at27.minutes == pytest.approx(4.0 / 60)


@pytest.mark.slow
def test_the_gating_study_on_recorded_drives_trains_and_scores_on_recordings_only(tmp_path):
    """The whole quick study on recorded drives: the sweep holds only the training drives,
    the evaluation only the held-out ones, the report names the recordings and their hashes
    and lists no generator constant; a second run gives the same numbers."""
    from snn_antenna.studies import gating_threshold

    spec = specs.load(ROOT / "studies" / "gating_threshold.toml", [], quick=True)
    data, recs = import_gating_drives(tmp_path, spec)
    plan = gating_threshold.plan({**spec, "data": str(data)})
    quiet = lambda *a: None                                              # noqa: E731
    first = gating_threshold.run(plan, tmp_path / "one", Options(quick=True), log=quiet)
    second = gating_threshold.run(gating_threshold.plan({**spec, "data": str(data)}),
                                  tmp_path / "two", Options(quick=True), log=quiet)
    rec = first["recorded"]
    assert len(rec["training drives"]) == 3 == len(rec["held-out drives"])
    assert first["f1"]["gated"]["n"] <= 3
    for key in ("th_star", "f1", "differences"):
        assert first[key] == second[key]
    assert "calibration_checks" not in first
    written = json.loads((tmp_path / "one" / "summary.json").read_text())
    assert [c["source"] for c in written["calibrated"]] == [str(data.resolve())] * 2
    assert all("antenna." not in c["how"] and "SELF_MOTION" not in c["how"]
               for c in written["calibrated"])
    page = (tmp_path / "one" / "report.html").read_text()
    meta = json.loads((data / "import.json").read_text())
    assert all(r["files"][0]["sha256"][:16] in page for r in meta["recordings"])
    assert "Fig. 9 in kind" not in page and "The recorded drives" in page
