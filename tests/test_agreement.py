"""Two runs of a study compared quantity by quantity (``report.agreement``) and the script
that prints it (``benchmarks/compare_runs.py``)."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

from hypothesis import given, strategies as st

from snn_antenna.report.agreement import agreement, compare_entry

ROOT = Path(__file__).resolve().parents[1]


def entry(quantity, value, interval=None, n=None):
    return {"quantity": quantity, "value": value, "interval": interval, "n": n}


def test_intervals_agree_when_they_overlap_and_differ_when_apart():
    assert compare_entry(entry("F1", 0.92, [0.90, 0.94], 8),
                         entry("F1", 0.95, [0.93, 0.97], 8))[0] == "agree"
    verdict, how = compare_entry(entry("F1", 0.92, [0.90, 0.94], 8),
                                 entry("F1", 0.97, [0.95, 0.99], 8))
    assert verdict == "differ" and "apart" in how and "n=8" in how


def test_a_deterministic_number_must_come_back_the_same():
    assert compare_entry(entry("err", 0.0378657), entry("err", 0.0378657))[0] == "agree"
    assert compare_entry(entry("err", 0.0378657), entry("err", 0.0379))[0] == "differ"
    assert compare_entry(entry("w", {"a": 1}), entry("w", {"a": 2}))[0] == "not comparable"


def test_a_quantity_of_one_run_only_is_said_never_counted():
    rows = agreement({"predicted": [entry("a", 1.0), entry("b", 2.0)]},
                     {"predicted": [entry("a", 1.0), entry("c", 3.0)]})
    assert [(r["quantity"], r["verdict"]) for r in rows] == [
        ("a", "agree"), ("b", "in one run only"), ("c", "in one run only")]


@given(st.floats(-1e6, 1e6), st.floats(0, 1e3), st.floats(0, 1e3), st.floats(-1e6, 1e6))
def test_overlap_is_symmetric(lo_a, width_a, width_b, lo_b):
    a = entry("x", lo_a, [lo_a, lo_a + width_a], 5)
    b = entry("x", lo_b, [lo_b, lo_b + width_b], 5)
    assert compare_entry(a, b)[0] == compare_entry(b, a)[0]


def test_the_script_exits_1_when_a_quantity_differs(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("compare_runs",
                                                  ROOT / "benchmarks" / "compare_runs.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    old, new, same = (tmp_path / n for n in ("old.json", "new", "same.json"))
    old.write_text(json.dumps({"predicted": [entry("F1", 0.9, [0.88, 0.92], 5)]}))
    new.mkdir()
    (new / "summary.json").write_text(json.dumps(
        {"predicted": [entry("F1", 0.8, [0.78, 0.82], 5)]}))
    same.write_text(old.read_text())
    assert script.main([str(old), str(new)]) == 1
    assert "differ" in capsys.readouterr().out
    assert script.main([str(old), str(same)]) == 0


def test_the_script_pairs_two_runs_per_seed_values_over_the_seeds_both_ran(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("compare_runs",
                                                  ROOT / "benchmarks" / "compare_runs.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    old, new = tmp_path / "old.json", tmp_path / "new.json"
    old.write_text(json.dumps({"f1_per_seed": {"gated": [0.80, 0.90, 0.70, 0.85, 0.75]}}))
    # the new run ran one seed more; each shared seed 0.02 to 0.04 better
    new.write_text(json.dumps({"f1_per_seed": {"gated": [0.83, 0.92, 0.74, 0.87, 0.78,
                                                         0.10]}}))
    assert script.main([str(old), str(new), "--paired", "f1_per_seed.gated"]) == 0
    out = capsys.readouterr().out
    assert "new − old +0.0280" in out and "n = 5" in out and "resolved above zero" in out
