"""Scene composition (only listed parts are built) and the closed exploration loop."""
import json
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import run_main

from snn_antenna.cli import main
from snn_antenna.core.errors import SpecError
from snn_antenna.networks import assembly
from snn_antenna.sources.scenes import OnlineAntenna

ROOT = Path(__file__).resolve().parents[1]
CPG_GATE_CONTROL = {"cpg", "cpg_ring", "speed_population", "readout", "plastic",
                    "control_contact", "control_motor", "control_sense", "control_act"}
# The gate learns in SpeedGate.fit: a built network recalls only.
LEARNING_ONLY = {"teacher", "teaching"}
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
    exploration = assembly.build(network_spec("exploration")).names()
    assert CPG_GATE_CONTROL <= exploration and not exploration & LEARNING_ONLY


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


SEED = ["--set", "seed=17"]


@pytest.fixture(scope="module")
def honest_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("exploration") / "exploration"
    run_main(["run", str(ROOT / "studies" / "exploration.toml"), "--out", str(out), "--quick",
              *SEED])
    return out, json.loads((out / "summary.json").read_text())


def test_the_closed_loop_stops_the_robot_at_a_post(honest_run):
    out, s = honest_run
    assert s["contact_t_s"] is not None, "the sweeping antenna should meet the first post"
    assert 0 <= s["stopped_after_contact_s"] <= STOP_WITHIN_S
    first = s["score"]["first_contact"]
    if first["within_array_band"]:
        assert abs(first["distance_error_cm"]) < 4.0
    else:   # rings above the top neuron: decoded at the array's edge, not scored
        assert s["score"]["out_of_band_contacts"] >= 1 and first["low_mode_hz"] > 30.0
    period = s["cpg_period_s"]
    assert abs(period["measured"] / period["spec"] - 1) < 0.05
    assert abs(s["pan_tilt_phase_deg"]["measured"] - 90.0) < 10.0
    assert 0 <= s["pan_range_deg"][0] and s["pan_range_deg"][1] <= 80
    assert -35 <= s["tilt_range_deg"][0] and s["tilt_range_deg"][1] <= 55
    assert s["calibrated"] and s["predicted"] and s["quick"] is True
    assert (out / "report.html").is_file() and (out / "exploration.png").is_file()


@pytest.mark.slow
def test_the_closed_loop_never_sees_the_ground_truth(honest_run, tmp_path, monkeypatch):
    """The same seed, run again with the world's contact record replaced by garbage after
    every step. The loop and its read-out (stop, detections, joint angles) are unchanged;
    only the score changes."""
    _, s = honest_run
    step = OnlineAntenna.step
    rng = np.random.default_rng(1)

    def step_then_lie(self, *args, **kwargs):
        samples = step(self, *args, **kwargs)
        self.contacts = [replace(c, t_s=float(rng.uniform(0.5, 3.5)),
                                 distance_cm=float(rng.uniform(9, 35)), material="brass")
                         for c in self.contacts]
        return samples

    monkeypatch.setattr(OnlineAntenna, "step", step_then_lie)
    garbage = tmp_path / "garbage"
    assert main(["run", str(ROOT / "studies" / "exploration.toml"), "--out", str(garbage),
                 "--quick", *SEED]) == 0
    g = json.loads((garbage / "summary.json").read_text())
    for key in ("detections", "stopped_at_s", "pan_range_deg", "tilt_range_deg",
                "cpg_period_s", "gate_th_g_while_driving"):
        assert g[key] == s[key], key
    assert g["contacts"] != s["contacts"] and g["score"] != s["score"]


def test_the_gate_trains_on_a_gating_runs_summary_or_refuses_it_clearly(tmp_path):
    from snn_antenna.core import spec as specs
    from snn_antenna.studies import exploration

    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"th_star": {"0": 0.03, "12": 0.13, "15": 0.2, "30": 0.56},
                                   "train_speeds_cm_s": [0.0, 12.0, 30.0]}))
    path = ROOT / "studies" / "exploration.toml"
    parts = exploration.plan(specs.load(path, [f'gate_training.from_summary="{summary}"'])).parts
    speeds, th = parts.gate_training
    assert speeds.tolist() == [0.0, 12.0, 30.0] and th.tolist() == [0.03, 0.13, 0.56]
    for bad in (tmp_path / "missing.json", ROOT / "pyproject.toml"):
        with pytest.raises(SpecError, match="from_summary"):
            exploration.plan(specs.load(path, [f'gate_training.from_summary="{bad}"']))
