"""Scene composition (only listed parts are built) and the closed exploration loop."""
import json
import tomllib
from pathlib import Path

import pytest

from snn_antenna import assembly
from snn_antenna.cli import main
from snn_antenna.errors import SpecError

ROOT = Path(__file__).resolve().parents[1]
CPG_GATE_CONTROL = {"cpg", "cpg_ring", "speed_population", "readout", "plastic", "teacher",
                    "teaching", "control_contact", "control_motor", "control_sense",
                    "control_act"}
STOP_WITHIN_S = 0.5   # the robot stops within this time of touching a post


def network_spec(name):
    with open(ROOT / "networks" / f"{name}.toml", "rb") as f:
        table = tomllib.load(f)
    for part in ("resonators", "gate", "cpg"):
        if part in table:
            table[part]["target"] = "numpy"
    return table


def test_a_bench_scene_builds_only_the_resonator_array():
    names = assembly.build(network_spec("bench")).names()
    assert "resonators" in names and not names & CPG_GATE_CONTROL
    robot = assembly.build(network_spec("robot")).names()
    assert {"speed_population", "readout", "plastic"} <= robot
    assert not robot & {"cpg", "cpg_ring", "control_contact", "control_motor"}
    assert CPG_GATE_CONTROL <= assembly.build(network_spec("exploration")).names()


@pytest.mark.parametrize("parts,inputs,needs", [
    (["control"], ["antenna", "speed_command"], "resonators"),
    (["resonators", "gate"], ["antenna"], "speed_command"),
    (["resonators", "cpg"], ["antenna"], "speed_command"),
    (["resonators"], [], "antenna"),
])
def test_a_part_with_missing_inputs_is_refused(parts, inputs, needs):
    with pytest.raises(SpecError, match=f"needs {needs}"):
        assembly.build({"parts": parts, "inputs": inputs})


def test_unknown_parts_and_settings_are_refused():
    with pytest.raises(SpecError, match="network.parts"):
        assembly.build({"parts": ["resonators", "hippocampus"], "inputs": ["antenna"]})
    with pytest.raises(SpecError, match="network.cpg.colour"):
        assembly.build({"parts": ["cpg"], "inputs": ["speed_command"], "cpg": {"colour": 1}})


def test_the_closed_loop_stops_the_robot_at_a_post(tmp_path):
    out = tmp_path / "exploration"
    assert main(["run", str(ROOT / "studies" / "exploration.toml"), "--out", str(out),
                 "--quick"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["contact_t_s"] is not None, "the sweeping antenna should meet the first post"
    assert 0 <= s["stopped_after_contact_s"] <= STOP_WITHIN_S
    true, decoded = s["contact_distance_cm"]["true"], s["contact_distance_cm"]["decoded"]
    assert abs(decoded - true) < 4.0
    period = s["cpg_period_s"]
    assert abs(period["measured"] / period["spec"] - 1) < 0.05
    assert abs(s["pan_tilt_phase_deg"]["measured"] - 90.0) < 10.0
    assert 0 <= s["pan_range_deg"][0] and s["pan_range_deg"][1] <= 80
    assert -35 <= s["tilt_range_deg"][0] and s["tilt_range_deg"][1] <= 55
    assert (out / "report.html").is_file() and (out / "exploration.png").is_file()


def test_the_gate_trains_on_a_gating_runs_summary_or_refuses_it_clearly(tmp_path):
    from snn_antenna import spec as specs
    from snn_antenna.studies import exploration

    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"th_star": {"0": 0.03, "12": 0.13, "15": 0.2, "30": 0.56},
                                   "train_speeds_cm_s": [0.0, 12.0, 30.0]}))
    path = ROOT / "studies" / "exploration.toml"
    parts = exploration.build(specs.load(path, [f'gate_training.from_summary="{summary}"']))
    speeds, th = parts["gate_training"]
    assert speeds.tolist() == [0.0, 12.0, 30.0] and th.tolist() == [0.03, 0.13, 0.56]
    for bad in (tmp_path / "missing.json", ROOT / "pyproject.toml"):
        with pytest.raises(SpecError, match="from_summary"):
            exploration.build(specs.load(path, [f'gate_training.from_summary="{bad}"']))
