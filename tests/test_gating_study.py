"""The gating threshold study end to end (quick profile, shrunk further): report and summary."""
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow   # ~1 min of CPU: the study's parts are covered by the tests below
def test_gating_study_labels_its_numbers_and_sizes_its_seeds_from_the_spread(tmp_path):
    """End to end on the quick profile: the built-in Fig. 9 numbers are listed as calibrated,
    never as predictions; the gate's F1 and its paired differences are predictions with
    interval and n, recomputable from the per-seed F1s; and a margin too fine for the pilot's
    spread makes the study run more seeds than the pilot, up to the budget."""
    from snn_antenna.report.stats import paired_difference

    out = tmp_path / "gating"
    status = main(["run", str(ROOT / "studies" / "gating_threshold.toml"), "--out", str(out),
                   "--quick", "--set", "sweep.scene_s=6.0",
                   "--set", "sweep.thresholds_g=[0.0, 0.1, 0.4, 100.0]",
                   "--set", "gate.epochs=2", "--set", "evaluation.pilot_seeds=2",
                   "--set", "evaluation.max_seeds=3", "--set", "evaluation.margin_f1=0.0001"])
    assert status == 0
    summary = json.loads((out / "summary.json").read_text())
    calibrated = {c["quantity"] for c in summary["calibrated"]}
    predicted = {p["quantity"]: p for p in summary["predicted"]}
    assert any("Th*(27" in q for q in calibrated) and not any("Th*(27" in q for q in predicted)
    assert any("2·Th*" in q for q in calibrated) and not any("2·Th*" in q for q in predicted)
    assert all(p["paper"] is None for p in predicted.values())   # nothing to reproduce here
    # More seeds than the pilot: the needed number exceeded the budget, so the budget ran.
    seeds = summary["seeds"]
    per_seed = summary["f1_per_seed"]
    gated, lookup = np.array(per_seed["gated"], float), np.array(per_seed["lookup"], float)
    assert seeds["pilot"] == 2 and seeds["needed"] >= 3 and seeds["used"] == 3 == len(gated)
    d = summary["differences"]["gated − lookup"]
    keep = np.isfinite(gated) & np.isfinite(lookup)
    if keep.sum() >= 2:
        expected = paired_difference(gated[keep], lookup[keep])
        assert d["n"] == expected.n and d["mean"] == pytest.approx(expected.mean)
        assert d["verdict"] == expected.verdict
        row = predicted["F1 gated − lookup table"]
        assert row["n"] == expected.n and row["interval"] == pytest.approx(
            [expected.low, expected.high])
    # each coder of [evaluation.coders] with the gate's Th, paired by seed with the square wave
    assert set(summary["coders"]) == {"delta", "analog"}
    for _label, row in summary["coders"].items():
        f1 = np.array(row["f1_per_seed"], float)
        keep = np.isfinite(f1) & np.isfinite(gated)
        assert len(f1) == len(gated) and row["minus_own_coder"]["n"] == keep.sum()
        if keep.sum() >= 2:
            assert row["minus_own_coder"]["mean"] == pytest.approx(
                paired_difference(f1[keep], gated[keep]).mean)
    assert summary["quick"] is True
    page = (out / "report.html").read_text()
    assert "the study&#x27;s coder" in page or "the study's coder" in page
    assert "quick-banner" in page and "Too small to compare" in page
    assert "Calibrated to" in page and "Predicted" in page
    for name in summary["figures"]:
        assert (out / name).is_file()


# These tests check the study's logic: on the numpy target they compile nothing (the
# compiled codings equal the runtime path's: tests/test_codings.py)
LOGIC_ONLY = "sweep.target=numpy"


def _quick_parts(*overrides):
    from snn_antenna.core import spec as specs
    from snn_antenna.studies.gating_threshold.plan import make_parts
    spec = specs.resolved(specs.load(ROOT / "studies" / "gating_threshold.toml",
                                     ["sweep.scene_s=6.0", LOGIC_ONLY, *overrides], quick=True))
    return spec, make_parts(spec)


def test_the_read_out_never_sees_the_ground_truth():
    """Replace a scene's labels (contacts, and the robot's true path) with garbage after
    generation, or lie about them three ways (contacts moved, deleted, invented): what the
    read-outs are given (the conditioned signal, coded with a per-sample Th from the speed
    command) is the same to the bit, and the study's batch path gives the same rate maps and
    detections; only the scores change. (The detector's only input is the coded column, so
    equal columns are equal detections: one Brian2 run checks the batch path.)"""
    from snn_antenna.engine.batches import ScoredCodings
    from snn_antenna.evaluation.scoring import score_with
    from test_blind import scrambles
    from snn_antenna.core.truth import Event, GroundTruth
    from snn_antenna.sources.scenes import SpeedProfile
    from snn_antenna.studies.gating_threshold.scenes import condition, make_scene

    spec, parts = _quick_parts("sweep.scene_s=5.0")
    scene, seed = make_scene(parts, SpeedProfile("ramp", points=[[0, 0.0], [5, 27.0]]), (11,))
    rec = scene.generate(seed)
    assert len(rec.truth.contacts) >= 2
    rng = np.random.default_rng(0)
    garbage = tuple(Event("contact", float(t), 1.0, float(d)) for t, d in
                    zip(rng.uniform(1, 4, 4), rng.uniform(15, 40, 4)))
    fake = replace(rec, truth=GroundTruth(garbage),
                   meta={**rec.meta, "robot_x_cm": rng.normal(size=rec.n_samples),
                         "pan_deg": rng.normal(size=rec.n_samples)})
    speed_th = 0.03 + 0.02 * rec.meta["speed_cm_s"]          # a Th from the speed command

    def coded(recording):
        x, coder = condition(parts, recording)
        return coder.partial_transform(x, threshold=speed_th)

    real = coded(rec)
    assert np.array_equal(coded(fake), real)
    lied = scrambles(rec.truth, rec.duration_s)                     # moved, deleted, invented
    for how in ("moved", "deleted", "invented"):
        assert np.array_equal(coded(replace(rec, truth=lied[how])), real), how
    # The study's batch path: the same coded column under true and garbage labels.
    codings = ScoredCodings(parts.readout, parts.sweep.codings_per_run)
    (s_real, s_fake), (m_real, m_fake) = codings.run([(rec, real), (fake, real)])
    assert m_real.equals(m_fake)
    detected = parts.readout.detector.detect(m_real)
    assert detected, "the scene's contacts should be detected: nothing to be blind about"
    assert s_real != s_fake    # the labels do reach the scoring, afterwards
    assert s_real == score_with(parts.readout, detected, rec.truth.contacts, rec.duration_s)


def test_preprocessing_is_fitted_on_the_calibration_drive_and_is_causal():
    """The chain is fitted on a separate drive without posts, never on a scored scene: the
    conditioned signal of a scene's first seconds does not depend on what comes later."""
    from snn_antenna.sources.scenes import SpeedProfile
    from snn_antenna.studies.gating_threshold.scenes import calibrated_chain, condition, make_scene

    _, parts = _quick_parts()
    scene, seed = make_scene(parts, SpeedProfile("constant", 27.0), (5,))
    rec = scene.generate(seed)
    assert rec.truth.contacts
    cut = int(2.0 * rec.rate_hz)
    first = condition(parts, rec)[0][:cut]
    later = rec.samples.copy()
    later[cut:] = later[cut:][::-1] * 2            # a different future (bigger contacts)
    assert np.array_equal(condition(parts, rec.with_samples(later))[0][:cut], first)
    align = calibrated_chain(parts).named_steps["align"]
    _, again = _quick_parts("calibration.seed=5")   # another calibration drive: same axis
    assert np.allclose(calibrated_chain(again).named_steps["align"].axis_, align.axis_,
                       atol=0.05)


def test_a_bad_coder_of_the_evaluation_is_refused_by_name():
    from snn_antenna.core.errors import SpecError
    from snn_antenna.core import spec as specs
    from snn_antenna.studies.gating_threshold import plan as build

    spec = specs.resolved(specs.load(ROOT / "studies" / "gating_threshold.toml", quick=True))
    spec["evaluation"]["coders"]["delta"]["coder_options"]["levels"] = 0
    with pytest.raises(SpecError) as err:
        build(spec)
    assert "coders.delta.levels" in err.value.field and err.value.value == 0
    spec["evaluation"]["coders"]["delta"] = {"coder": "sigma"}
    with pytest.raises(SpecError) as err:
        build(spec)
    assert "coders.delta.coder" in err.value.field


def test_evaluation_speeds_must_be_held_out_from_the_gate():
    from snn_antenna.core.errors import SpecError
    with pytest.raises(SpecError, match="evaluation.speeds_cm_s"):
        _quick_parts("gate.train_speeds_cm_s=[0.0, 27.0]", "evaluation.speeds_cm_s=[27.0]")
    with pytest.raises(SpecError, match="calibration.speed_cm_s"):
        _quick_parts("calibration.speed_cm_s=0.0")
    _, parts = _quick_parts("gate.train_speeds_cm_s=[0.0, 27.0]")
    assert parts.held_out_speeds.tolist() == [12.0]   # default: the untrained


def test_bad_speed_in_the_spec_fails_fast_with_one_line(tmp_path, capsys):
    status = main(["run", str(ROOT / "studies" / "gating_threshold.toml"), "--out",
                   str(tmp_path / "x"), "--quick", "--set", "sweep.speeds_cm_s=[0.0, -12.0]"])
    assert status == 2
    assert "speeds_cm_s" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_the_threshold_sweep_is_a_resumable_store_reused_when_only_the_gate_changes(tmp_path):
    """The Th × speed sweep runs on the shared sweep engine: its counts land in a zarr store,
    a second run computes nothing, a changed gate reuses it, a changed sweep is refused."""
    from snn_antenna.core import spec as specs
    from snn_antenna.engine.grid import Grid
    from snn_antenna.engine.sweep import run_sweep
    from snn_antenna.core.errors import SpecError
    from snn_antenna.evaluation.scoring import SCORE_OUTPUTS
    from snn_antenna.studies.gating_threshold.plan import make_parts, sweep_settings
    from snn_antenna.studies.gating_threshold.scenes import ThresholdSweep

    def sweep(*overrides):
        spec = specs.load(ROOT / "studies" / "gating_threshold.toml",
                          ["sweep.scene_s=5.0", "sweep.speeds_cm_s=[0.0, 27.0]", LOGIC_ONLY,
                           *overrides],
                          quick=True)
        make_parts(spec)
        # scene 4: a course whose shaking at 27 cm/s makes false positives at Th = 0
        grid = Grid({"speed_cm_s": [27.0], "scene": [4.0], "threshold_g": [0.0, 0.3, 100.0]})
        return run_sweep(grid, ThresholdSweep(spec), tmp_path / "sweep.zarr", SCORE_OUTPUTS,
                         settings=sweep_settings(spec), progress=False)

    first = sweep()
    data = first.data.squeeze()
    assert first.chunks_computed == [0]
    assert int(data.tp.sel(threshold_g=100.0)) == 0 == int(data.fp.sel(threshold_g=100.0))
    assert int(data.fp.sel(threshold_g=0.0)) > 0      # Th = 0: the shaking makes detections
    assert float(data.minutes[0]) == pytest.approx(4.0 / 60)   # 5 s scene, 1 s settling
    again = sweep("gate.epochs=5", "sweep.workers=2")
    assert again.chunks_computed == [] and again.data.equals(first.data)
    with pytest.raises(SpecError, match="fresh"):
        sweep("sweep.settle_s=0.5")


@pytest.mark.slow   # ~25 s: a Dask cluster of its own (test_sweep and test_event_engine keep
# the default suite's Dask checks)
def test_codings_scored_on_dask_workers_equal_those_scored_here():
    """Fig. 9 and the evaluation run on the study's Dask workers while this process trains the
    gate: the scores and rate maps must be those of running the same batches here."""
    from snn_antenna.core import spec as specs
    from snn_antenna.engine.batches import ScoredCodings
    from snn_antenna.engine.executor import dask_client
    from snn_antenna.studies.gating_threshold.plan import make_parts
    from snn_antenna.studies.gating_threshold.scenes import coded_at, sweep_scene

    spec = specs.resolved(specs.load(ROOT / "studies" / "gating_threshold.toml",
                                     ["sweep.scene_s=3.0", "sweep.codings_per_run=2"],
                                     quick=True))
    parts = make_parts(spec)
    # one scene (the driving one: a false positive at Th = 0), three codings in two batches
    rec, x, coder = sweep_scene(parts, 27.0, 1)
    items = [(rec, c) for c in coded_at(coder, x, [0.0, 0.3, 100.0])]
    here_scores, here_maps = ScoredCodings(parts.readout, 2).run(items)
    with dask_client(workers=2) as client:
        codings = ScoredCodings(parts.readout, 2, client)
        pending = codings.submit(items)          # two batches, returned before they finish
        assert len(pending.runs) == 2
        there_scores, there_maps = codings.collect(pending)
    assert there_scores == here_scores
    assert all(a.equals(b) for a, b in zip(there_maps, here_maps))
    assert here_scores[0].fp > 0 and here_scores[2].tp == here_scores[2].fp == 0  # not vacuous


def test_the_coder_table_names_the_studys_own_coder_from_its_preprocessing():
    from snn_antenna.core import spec as specs
    from snn_antenna.studies.gating_threshold.plan import make_parts
    from snn_antenna.studies.gating_threshold.report import coder_rows

    spec = specs.load(ROOT / "studies" / "gating_threshold.toml",
                      ['preprocess.coder="delta"'], quick=True)
    cell = {"mean": 0.5, "low": 0.4, "high": 0.6, "n": 2}
    rows = coder_rows({"f1": {"gated": cell}, "coders": {}}, make_parts(spec))
    assert rows[0]["coder"] == "delta (the study's)"
