"""The main job from the README: the quickstart scene, end to end, and the CLI's refusals."""
import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.preprocess import fit_warmup
from snn_antenna.core.truth import Event, GroundTruth
from snn_antenna.sources import antenna
from snn_antenna.sources.stimuli import RobotScene
from snn_antenna.studies import quickstart

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = ROOT / "studies" / "quickstart.toml"


def cli(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "snn_antenna.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_quickstart_command_writes_the_report(tmp_path):
    out = tmp_path / "qs"
    proc = cli("run", str(QUICKSTART), "--out", str(out), "--quick")
    assert proc.returncode == 0, proc.stderr
    assert "false positive" in proc.stdout and "decoded distance" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    for key in ("motion_dominant_hz", "contact_dominant_hz", "contact_detected_s", "distance_cm"):
        assert summary[key] is not None
    assert summary["quick"] is True
    assert summary["calibrated"] and summary["predicted"]
    assert {"tp", "fp", "misses", "fp_per_min", "latency_s"} <= set(summary["score"])
    prov = summary["provenance"]
    assert prov["seed"] == 1 and prov["brian2_target"] == "cython"
    assert prov["spec"]["network"]["n_neurons"] == 24  # the resolved spec, includes expanded
    assert prov["snn_antenna_version"] and prov["brian2_version"]
    assert len(prov["code_sha256"]) == 16 and "git_commit" in prov     # which code made it
    # the paper's 20.4 Hz per k is a reference for a prediction (tuning_sweep), never a target
    targets = [c["target"] for c in summary["calibrated"]]
    assert not any(isinstance(t, float) and abs(t - 7.0 / 0.3425) < 0.01 for t in targets)
    html = (out / "report.html").read_text()
    assert "Calibrated to" in html and "Predicted" in html
    assert "data:image/png;base64," in html and (out / "rate_map.png").stat().st_size > 10_000


def test_the_scene_keeps_driving_through_its_contacts():
    spec = specs.load(QUICKSTART)
    scene = quickstart.plan(spec).parts.scene
    assert len(scene.contacts) >= 1 and scene.duration_s - scene.contacts[-1].t_s > 5
    assert (scene.speed_profile() == scene.speed_cm_s).all()


def _garble(contacts, rng):
    """Ground truth replaced by nonsense: other times (in the warm-up, far from the true
    contacts), distances and materials."""
    return tuple(Event("contact", float(rng.uniform(0.2, 1.8)), float(rng.uniform(0.2, 1)),
                       float(rng.uniform(10, 35)), "brass") for _ in range(3))


def test_the_read_out_never_sees_the_ground_truth(tmp_path, monkeypatch):
    """A fresh seed, run twice: once as generated, once with the scene's contacts replaced by
    garbage after generation. Every detection is the same; only the score changes."""
    spec = specs.load(QUICKSTART, ["seed=29"], quick=True)
    honest = quickstart.run(quickstart.plan(spec), tmp_path / "honest", log=lambda *_: None)
    generate = RobotScene.generate
    rng = np.random.default_rng(0)

    def garbled(self, seed=0):
        rec = generate(self, seed)
        return replace(rec, truth=GroundTruth(_garble(rec.truth.events, rng)))

    monkeypatch.setattr(RobotScene, "generate", garbled)
    lied_to = quickstart.run(quickstart.plan(spec), tmp_path / "garbage",
                              log=lambda *_: None)
    assert honest["detections"], "the fresh seed should give at least one detection"
    assert lied_to["detections"] == honest["detections"]
    assert lied_to["motion_dominant_hz"] == honest["motion_dominant_hz"]
    assert lied_to["n_spikes"] == honest["n_spikes"]
    assert lied_to["score"] != honest["score"]    # the scoring did see the garbage


def test_the_chain_is_fitted_on_the_warm_up_only():
    """What comes after the warm-up (the contacts) cannot change the fitted chain."""
    spec = specs.load(QUICKSTART, ["seed=5"], quick=True)
    parts = quickstart.plan(spec).parts
    rec = parts.scene.generate(5)
    n = int(parts.warmup_s * rec.rate_hz)
    fit_warmup(parts.chain, rec.samples, rec.rate_hz, parts.warmup_s)
    axis = parts.chain.named_steps["align"].axis_.copy()
    later = rec.samples.copy()
    later[n:] = 512 + (rec.samples[n:, ::-1] - 512) * 3     # the other axis, louder
    fit_warmup(parts.chain, later, rec.rate_hz, parts.warmup_s)
    np.testing.assert_array_equal(parts.chain.named_steps["align"].axis_, axis)
    with pytest.raises(SpecError, match="warmup_s"):
        quickstart.plan(specs.load(QUICKSTART, ["preprocess.warmup_s=6.0"]))


# seed 1 in the default suite; seeds 2-4 (one quick run each) are the thorough check
@pytest.mark.parametrize("seed", [1] + [pytest.param(s, marks=pytest.mark.slow)
                                        for s in (2, 3, 4)])
def test_quickstart_meets_the_papers_fig10_in_kind(tmp_path, seed):
    spec = specs.load(QUICKSTART, [f"seed={seed}"], quick=True)
    s = quickstart.run(quickstart.plan(spec), tmp_path, log=lambda *_: None)
    # self-motion sits in the 7–8 Hz neurons (windows outside detections, read blind)
    assert 7.0 <= s["motion_dominant_hz"] <= 9.0
    # the contact found and nothing else, although the robot keeps driving (seeds 1-12 of
    # the full 16 s scene: 12 of 12 contacts, no false positive in 2.8 min of driving)
    assert s["score"]["tp"] == 1 and s["score"]["fp"] == 0 and s["score"]["misses"] == 0
    # on the paper's Fig. 10 contact (19 cm), activity moves to the neurons around the low
    # mode: the population centroid within 1.5 channels of it (over seeds 1-12 it sat +2.7 %
    # ± 2.8 % above the law, i.e. 0.4 ± 0.4 channels, the contact's own scatter included); the
    # single most active neuron within two, because a resonator fires once per cycle across a
    # plateau of its tuning curve and neighbours nearly tie.
    fig10 = next(c for c in s["score"]["contacts"] if c["true_distance_cm"] == 19.0)
    hz = np.geomspace(7, 30, 24)
    target = antenna.low_mode_hz(19.0)
    channel = np.log(hz[1] / hz[0])
    assert abs(np.log(fig10["frequency_hz"] / target)) <= 1.5 * channel
    assert abs(np.log(fig10["dominant_hz"] / target)) <= 2 * channel
    assert 0 <= fig10["latency_s"] <= 0.3
    assert abs(fig10["distance_cm"] - 19.0) <= 1.5


@pytest.mark.parametrize("extra,field", [
    (["--set", "network.n_neurons=0"], "network.n_neurons"),
    (["--set", "network.colour=3"], "network.colour"),
    (["--set", "stimulus.contacts.0.distance_cm=-2"], "distance_cm"),
    (["--set", "stimulus.contacts.0.distance_cm=55"], "distance_cm"),
    (["--set", "stimulus.rate_hz=100"], "rate_hz"),
    (["--set", "stimulus.contacts.0.material='granite'"], "material"),
    (["--set", "readout.windows=3"], "readout.windows"),
    (["--set", "banana=1"], "banana"),
])
def test_spec_errors_name_the_field_before_any_work(tmp_path, capsys, extra, field):
    from snn_antenna.cli import main

    assert main(["run", str(QUICKSTART), "--out", str(tmp_path / "x"), *extra]) == 2
    err = capsys.readouterr().err
    assert field in err and "Traceback" not in err, err
    assert not (tmp_path / "x").exists()  # refused before anything was written


def test_spec_error_from_the_command_line_is_one_line_without_traceback(tmp_path):
    proc = cli("run", str(QUICKSTART), "--out", str(tmp_path / "x"),
               "--set", "stimulus.contacts.0.distance_cm=-2")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "distance_cm" in proc.stderr


def test_missing_spec_file_is_a_clear_error(tmp_path):
    proc = cli("run", str(tmp_path / "nope.toml"))
    assert proc.returncode == 2 and "nope.toml" in proc.stderr
