"""The gating threshold study end to end (quick profile, shrunk further): report and summary."""
import json
from pathlib import Path

import pytest

from snn_antenna.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow   # ~30 s of CPU: the study's parts are covered by tests/test_gate.py
def test_gating_study_writes_report_summary_and_store(tmp_path):
    out = tmp_path / "gating"
    status = main(["run", str(ROOT / "studies" / "gating_threshold.toml"), "--out", str(out),
                   "--quick", "--set", "sweep.scene_s=6.0",
                   "--set", "sweep.thresholds_g=[0.0, 0.1, 0.4, 100.0]",
                   "--set", "gate.epochs=2", "--set", "evaluation.n_ramps=0"])
    assert status == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["th_star"]) == {"0", "12", "27"}
    assert all(t in (0.1, 0.4, 100.0) for t in summary["best_th_per_speed"].values())
    assert all(0.1 <= t <= 100.0 for t in summary["th_star"].values())
    for key in ("f1_gated", "f1_best_fixed", "f1_lookup", "f1_sweep_fixed"):
        assert 0 <= summary[key]["mean"] <= 1 and summary[key]["std"] >= 0
    # The best fixed Th is the best in hindsight: no fixed Th did better on the same scenes.
    assert summary["f1_best_fixed"]["mean"] >= summary["f1_sweep_fixed"]["mean"]
    th = list(summary["th_star"].values())
    assert th == sorted(th)                     # Th*(speed) never falls with speed
    # A threshold far above the signal simply detects nothing (scored, no error).
    assert summary["paper_in_kind"]["highest_th_misses_all"] is True
    assert summary["provenance"]["spec"]["study"] == "gating_threshold"
    assert (out / "report.html").stat().st_size > 10_000 and (out / "sweep.zarr").is_dir()
    for name in summary["figures"]:
        assert (out / name).is_file()


def test_bad_speed_in_the_spec_fails_fast_with_one_line(tmp_path, capsys):
    status = main(["run", str(ROOT / "studies" / "gating_threshold.toml"), "--out",
                   str(tmp_path / "x"), "--quick", "--set", "sweep.speeds_cm_s=[0.0, -12.0]"])
    assert status == 2
    assert "speeds_cm_s" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
