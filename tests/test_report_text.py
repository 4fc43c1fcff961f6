"""Report prose comes from the run, not from the full profile's description."""

from snn_antenna.sources.stimuli import Contact, RobotScene
from snn_antenna.studies.quickstart.report import scene_text

DESCRIPTION = ("A robot drives at 12 cm/s and keeps driving; at 5.5 s its antenna touches an "
               "obstacle 19 cm along the rod (the paper's Fig. 10), then it drives on for "
               "9.5 s. Self-motion drives the 7-8 Hz resonators.")


def test_quickstart_tells_the_scene_it_ran():
    quick = RobotScene(speed_cm_s=12.0, duration_s=7.0, contacts=[Contact(3.0, 19.0, "wood")])
    text = scene_text(quick, DESCRIPTION)
    assert "for 7 s" in text and "drives on for 4 s" in text and "9.5 s" not in text
    assert text.endswith("Self-motion drives the 7-8 Hz resonators.")


def test_max_accurate_k_dt_ignores_drives_the_finest_step_already_misses():
    import numpy as np

    from snn_antenna.evaluation.accuracy import ACCURATE, INACCURATE, _largest_accurate

    k_dt = np.array([0.01, 0.1, 0.5, 1.0])
    status = np.full((4, 3), ACCURATE)
    status[:, 2] = INACCURATE          # a near-threshold drive: wrong at every step
    status[3, 0] = INACCURATE          # the first drive goes wrong at k·dt = 1
    assert _largest_accurate(k_dt, status) == 0.5
    status[0, :] = INACCURATE
    assert _largest_accurate(k_dt, status) == 0.0


def test_one_spelling_per_material_and_times_in_a_readable_unit():
    from snn_antenna.report.page import fmt, label

    assert label("pom") == "POM" and label("pvc") == "PVC" and fmt({"pvc": 0.9}) == "PVC = 0.9"
    assert fmt(389946.0, "µs/event") == "389.9 ms/event" and fmt(12.5, "µs") == "12.5 µs"
    assert fmt(2500.0, "ms") == "2.5 s"


def test_the_band_advice_is_words_not_code():
    from snn_antenna.evaluation.bands import apply_line

    text = apply_line("high", {"dt_ms": 0.05, "method": "exponential_euler", "hz_per_k": 20.44})
    assert text == "high band: step 0.05 ms, exponential_euler integration, 20.44 Hz per unit k"
    assert "=" not in text and "Band(" not in text


def test_speed_to_value_mappings_are_written_one_way():
    from snn_antenna.report.page import by_speed

    line = by_speed({"27.0": 0.35, "12": 0.0669, "0": 0.03}, lambda t: f"{t:.3g} g")
    assert line == "0 cm/s: 0.03 g · 12 cm/s: 0.0669 g · 27 cm/s: 0.35 g"


def test_speed_accuracy_lists_only_the_shipped_limits_its_map_supports(tmp_path):
    from snn_antenna.report.page import Report
    from snn_antenna.studies.speed_accuracy.report import calibrated_and_predicted

    summary = {"stability_limits": {
        "euler": {"shipped_max_stable_k_dt": 0.5, "measured_max_stable_k_dt": 0.6},
        "izhikevich": {"shipped_max_stable_k_dt": 1.4, "measured_max_stable_k_dt": 0.5}},
        "shipped_default": {"method": "euler", "dt_ms": 0.1, "default_rows": []}}
    quick = Report(tmp_path, "t", quick=True)
    calibrated_and_predicted(quick, summary)
    assert [c.quantity for c in quick._calibrated] == ["largest stable k·dt, euler"]
    assert any("izhikevich" in part and "not checked" in part for part in quick._parts)
    full = Report(tmp_path, "t")
    calibrated_and_predicted(full, summary)        # a full map below the shipped value: said
    izh = [c for c in full._calibrated if "izhikevich" in c.quantity][0]
    assert "NOT supported" in izh.how


def test_tuning_puts_the_spread_of_peak_per_k_in_words_not_in_the_interval_column(tmp_path):
    from snn_antenna.report.page import Report
    from snn_antenna.studies.tuning_sweep.report import calibrated_and_predicted

    summary = {"reference_used": {"k": 1.0}, "calibration": {
        "hz_per_k_centroid": 20.7, "hz_per_k_peak": 23.9, "hz_per_k_peak_range": [22.0, 24.0],
        "responding_k": 4, "input_hz_step": 1.0}}
    report = Report(tmp_path, "t", quick=True)
    calibrated_and_predicted(report, summary)
    peak = report._predicted[0]
    assert peak.interval is None and "22 to 24 Hz" in peak.note
