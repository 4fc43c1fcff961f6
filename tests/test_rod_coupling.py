"""The calibration of ``antenna.ROD_COUPLING`` (``studies.baseline_comparison.coupling``,
``benchmarks/calibrate_rod_coupling.py``): the root finder on a known accuracy curve, its
refusals, and the command's options. The measurement itself (a whole bench set per coupling)
is the command's, not the suite's."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.sources import antenna
from snn_antenna.studies import baseline_comparison as study
from snn_antenna.studies.baseline_comparison import coupling

ROOT = Path(__file__).resolve().parents[1]


def known_curve(monkeypatch, calls: list):
    """Per-split accuracies that rise with the coupling: 0.9 + coupling, with a spread
    across five splits that averages out."""
    def fake(parts, c, log=print):
        calls.append(c)
        return 0.9 + c + np.array([-0.002, -0.001, 0.0, 0.001, 0.002])
    monkeypatch.setattr(coupling, "accuracy", fake)


def test_the_root_is_where_the_mean_accuracy_meets_the_target(monkeypatch):
    calls = []
    known_curve(monkeypatch, calls)
    root, points = coupling.calibrate(None, (0.01, 0.05), target=0.942, xtol=1e-6,
                                      log=lambda *_: None)
    assert root == pytest.approx(0.042, abs=1e-5)
    assert calls[:2] == [0.01, 0.05] and set(points) == set(calls)   # each measured once
    rows = coupling.curve_rows(points)
    assert [r["coupling"] for r in rows] == sorted(points)
    assert all(r["n"] == 5 and r["interval"][0] <= r["accuracy"] <= r["interval"][1]
               for r in rows)


def test_a_bracket_the_accuracy_does_not_cross_is_refused(monkeypatch):
    calls = []
    known_curve(monkeypatch, calls)
    with pytest.raises(SpecError, match="bracket") as err:
        coupling.calibrate(None, (0.045, 0.06), target=0.942, log=lambda *_: None)
    assert "94.50 and 96.00 %" in str(err.value) and len(calls) == 2


def test_a_coupling_is_checked_before_any_bench_set_is_made():
    parts = study.plan(specs.load(ROOT / "studies" / "baseline_comparison.toml")).parts
    with pytest.raises(SpecError, match="coupling"):
        coupling.accuracy(parts, 0.0)
    from dataclasses import replace
    other = replace(parts, bench=replace(parts.bench, physics="boundary"))
    with pytest.raises(SpecError, match="stimulus.physics"):
        coupling.accuracy(other, antenna.ROD_COUPLING)


def test_the_command_takes_its_options(monkeypatch, capsys):
    path = ROOT / "benchmarks" / "calibrate_rod_coupling.py"
    spec = importlib.util.spec_from_file_location("calibrate_rod_coupling", path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "calibrate_rod_coupling", module)
    spec.loader.exec_module(module)
    with pytest.raises(SystemExit) as done:
        module.main(["--help"])
    assert done.value.code == 0
    usage = capsys.readouterr().out
    assert all(o in usage for o in ("--bracket", "--curve", "--target", "--set", "--out"))



def test_the_line_through_noisy_couplings_meets_the_target_where_the_trend_does():
    rng = np.random.default_rng(0)
    xs = np.linspace(0.016, 0.022, 7)
    points = {float(c): 0.9 + c + rng.normal(0, 0.003, 5) for c in xs}
    points[0.05] = np.full(5, 0.5)                    # outside the fit's range: left out
    root, slope = coupling.fitted_root(points, 0.919, (0.015, 0.023))
    assert root == pytest.approx(0.019, abs=0.003) and slope > 0
    with pytest.raises(SpecError, match="3 measured couplings"):
        coupling.fitted_root(points, 0.919, (0.016, 0.0171))
    falling = {c: 1.0 - a for c, a in points.items()}
    with pytest.raises(SpecError, match="rises"):
        coupling.fitted_root(falling, 0.08, (0.015, 0.023))


def test_the_constant_names_the_command_that_calibrates_it():
    source = (ROOT / "snn_antenna" / "sources" / "antenna.py").read_text()
    comment = source[:source.index("\nROD_COUPLING = ")].rsplit("\n\n", 1)[-1]
    assert "benchmarks/calibrate_rod_coupling.py" in comment
