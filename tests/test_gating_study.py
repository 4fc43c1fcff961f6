"""The gating threshold study end to end (quick profile, shrunk further): report and summary."""
import json
from pathlib import Path

import numpy as np
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


def test_the_threshold_sweep_is_a_resumable_store_reused_when_only_the_gate_changes(tmp_path):
    """The Th × speed sweep runs on the shared sweep engine: its counts land in a zarr store,
    a second run computes nothing, a changed gate reuses it, a changed sweep is refused."""
    from snn_antenna import spec as specs
    from snn_antenna.errors import SpecError
    from snn_antenna.studies.gating_threshold import (SWEEP_OUTPUTS, ThresholdSweep, build,
                                                      sweep_settings)
    from snn_antenna.sweep import Grid, run_sweep

    def sweep(*overrides):
        spec = specs.load(ROOT / "studies" / "gating_threshold.toml",
                          ["sweep.scene_s=5.0", "sweep.speeds_cm_s=[0.0, 27.0]", *overrides],
                          quick=True)
        build(spec)
        grid = Grid({"speed_cm_s": [27.0], "scene": [0.0], "threshold_g": [0.0, 0.3, 100.0]})
        return run_sweep(grid, ThresholdSweep(spec), tmp_path / "sweep.zarr", SWEEP_OUTPUTS,
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


def test_codings_scored_on_dask_workers_equal_those_scored_here():
    """Fig. 9 and the evaluation run on the study's Dask workers while this process trains the
    gate: the scores and rate maps must be those of running the same batches here."""
    from snn_antenna import spec as specs
    from snn_antenna.studies.gating_threshold import Codings, build, sweep_scene
    from snn_antenna.sweep import dask_client

    spec = specs.resolved(specs.load(ROOT / "studies" / "gating_threshold.toml",
                                     ["sweep.scene_s=3.0", "sweep.codings_per_run=3"],
                                     quick=True))
    parts = build(spec)
    items = []
    for speed in (0.0, 27.0):
        rec, x, coder = sweep_scene(parts, speed, 0)
        coded = coder.partial_transform(np.c_[x, x, x], threshold=np.array([[0.0, 0.3, 100.0]]))
        items += [(rec, coded[:, j]) for j in range(3)]
    here_scores, here_maps = Codings(spec).run(items)
    with dask_client(workers=2) as client:
        codings = Codings(spec, client)
        pending = codings.submit(items)          # two batches, returned before they finish
        assert len(pending) == 2
        there_scores, there_maps = codings.collect(pending)
    assert there_scores == here_scores
    assert all(a.equals(b) for a, b in zip(there_maps, here_maps))
    assert here_scores[3].fp > 0 and here_scores[5].tp == here_scores[5].fp == 0  # not vacuous
