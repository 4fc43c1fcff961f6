"""The scripts in benchmarks/ run. Default suite: each imports, builds its options, and calls
the package's functions as their signatures read. Slow: each one's smallest mode runs end to
end on tiny inputs and prints or writes what it promises, its JSON a source the results page
takes."""
import ast
import importlib.util
import inspect
import re
import sys
from pathlib import Path

import pytest

from snn_antenna.report import regenerate, results

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"


def script(name: str, monkeypatch):
    """``benchmarks/NAME.py`` as a module: the folder holds scripts, not a package, and a
    script imports its neighbours by name (as when it runs from there)."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, name, module)
    spec.loader.exec_module(module)
    return module


def cited(json_path: Path, tmp_path: Path) -> dict:
    """A benchmark's ``--json`` output through the results page: accepted as a source (it
    carries its command), rendered, and every number on the page read back from it."""
    record = results._bench_record(json_path)
    page = results.make_page([], [json_path], tmp_path / "page" / "results.md")
    assert results.check_page(page, page.parent / "results") == []
    assert "#run-" in page.read_text()
    return record


def array_ran(out: str, tmp_path: Path) -> None:
    record = cited(tmp_path / "bench.json", tmp_path)
    rows = record["implementations"]
    assert record["neurons"] == 4 and len(rows) == 4
    assert all(row["wall_s"] > 0 for row in rows.values())
    spikes = [row["spikes"] for row in rows.values() if row["spikes"] is not None]
    assert spikes[0] > 0 and len(set(spikes[:2])) == 1    # numpy and cython: the same spikes


def bands_ran(out: str, tmp_path: Path) -> None:
    record = cited(tmp_path / "bench.json", tmp_path)
    assert [r["role"] for r in record["settings"]] == [
        "bank's own", "shipped", "map-accurate euler", "map-accurate rk4"]
    assert record["settings"][0]["cost_of_own_setting"] == 1.0
    assert all(r["band"] == "high" and r["cpu_ms_per_event"] > 0 for r in record["settings"])
    rows = [line for line in out.splitlines() if line.startswith("  ") and ": " in line]
    assert [row.split(":")[0].strip() for row in rows] == [
        "bank's own", "shipped", "map-accurate euler", "map-accurate rk4"]
    assert rows[0].split()[-1] == "1.0x"                # the cost ratio to the bank's own
    assert all(float(row.split()[-1].rstrip("x")) > 0 for row in rows)
    assert "high band" in out


def stage_ceilings_ran(out: str, tmp_path: Path) -> None:
    record = cited(tmp_path / "bench.json", tmp_path)
    assert [r["stage"] for r in record["stages"]] == ["band_pass", "coded"]
    for row in record["stages"]:
        assert 0 < row["accuracy_pct"]["mean"] <= 100 and row["accuracy_pct"]["n"] == 1
        assert row["features"] == 2 * len(record["bank"]["channel_low_hz"]) * (
            1 + len(record["bank"]["bin_edges_s"]))   # power and sign changes per bin
    assert "band_pass |" in out and "coded |" in out


def coders_ran(out: str, tmp_path: Path) -> None:
    record = cited(tmp_path / "bench.json", tmp_path)
    assert record["name"] == "bench_coders_cost_only"     # a section beside the full run's
    assert "fft" in record["costs"] and len(record["costs"]) > 1
    assert all(c["features_us_per_event"] > 0 for c in record["costs"].values())
    assert "× FFT" in out


def events_ran(out: str, tmp_path: Path) -> None:
    record = cited(tmp_path / "bench.json", tmp_path)
    assert record["fft_pipeline"]["us_per_event"] > 0
    assert [row["resonators"] for row in record["tuned_banks"]] == [24]
    assert record["one_run_per_contact"]["contacts"] >= 1


def stream_ran(out: str, tmp_path: Path) -> None:
    factor = re.search(r"throughput \(compute-only real-time factor\): ([\d.]+)x", out)
    assert factor and float(factor.group(1)) > 0, out
    for line in ("throughput (compute-only real-time factor)", "live at 1 kHz",
                 "sample-to-rate-map latency", "contacts (fast run)"):
        assert line in out, line


def studies_ran(out: str, tmp_path: Path) -> None:
    record = cited(tmp_path / "bench.json", tmp_path)
    (row,) = record["rows"]
    assert row["study"] == "quickstart" and row["profile"] == "quick"
    assert row["estimate_s"] > 0 and row["measured_s"] > 0
    assert row["measured_over_estimate"] == pytest.approx(row["measured_s"] / row["estimate_s"])
    assert "rates: " in out and "within x1.5 of the estimate" in out
    # what the estimate's seconds pay for, summing to it
    assert sum(row["estimate_parts_s"].values()) == pytest.approx(row["estimate_s"])
    assert "the process's start and its report" in row["estimate_parts_s"]


def lab_readouts_ran(out: str, tmp_path: Path) -> None:
    rows = [line.split() for line in out.splitlines() if line.endswith(("meets", "MISSES"))]
    tasks = {row[1] for row in rows}
    assert tasks == {"material", "distance"}, out
    assert any(row[0] == "mlp_parametric_material" for row in rows), out
    record = cited(tmp_path / "bench.json", tmp_path)     # the same rows, by task
    assert len(record["material_accuracy"]) + len(record["distance_rmse_mm"]) == len(rows)
    assert record["material_accuracy"]["mlp_parametric_material"]["mark"] in ("meets", "misses")


def sweep_ran(out: str, tmp_path: Path) -> None:
    record = cited(tmp_path / "bench.json", tmp_path)
    (grid,) = record["per_grid"].values()
    for engine in ("standalone", "standalone32", "floor64", "floor32", "cython", "numpy",
                   "numba", "naive"):
        assert grid[engine] > 0, engine
    assert record["scaling"] == []


# each script's smallest real mode (JSON into the test's folder as bench.json) and what it
# promises; every script in benchmarks/ has one
SMALL_RUNS = {
    "bench_array": (["--seconds", "1", "--neurons", "4", "--python-seconds", "0.05",
                     "--json", "bench.json"], array_ran),
    "bench_bands": (["--bands", "high", "--cost-events", "1", "--materials", "wood",
                     "--seconds", "0.1", "--json", "bench.json"], bands_ran),
    "bench_coders": (["--cost-only", "--repetitions", "1", "--out", "bench.json",
                      "--set", "spiking.tuned.calibration_repetitions=2",
                      "--set", "spiking.tuned.coder_sizes=[24]",
                      "--set", "spiking.tuned.cost_repeats=1",
                      "--set", "spiking.cost_sample_events=8"], coders_ran),
    "bench_events": (["--cost-only", "--cost-events", "4", "--sizes", "24",
                      "--json", "bench.json"], events_ran),
    "bench_lab_readouts": (["--rate", "1000", "--work", "lab", "--set", "evaluation.seeds=[0]",
                            "--set", "evaluation.nmf_dims=[3]", "--set", "spiking.workers=1",
                            "--json", "bench.json"],
                           lab_readouts_ran),
    "bench_stage_ceilings": (["--repetitions", "2", "--stages", "band_pass", "coded",
                              "--set", "evaluation.seeds=[0]",
                              "--set", "spiking.tuned.calibration_repetitions=2",
                              "--out", "bench.json"], stage_ceilings_ran),
    "bench_stream": (["--seconds", "1", "--baseline", "none"], stream_ran),
    "bench_studies": (["--studies", "quickstart", "--json", "bench.json"], studies_ran),
    "bench_sweep": (["--sizes", "40", "--duration-s", "0.05", "--repeat", "1",
                     "--runtime-max", "40", "--naive-sample", "1", "--workers",
                     "--json", "bench.json"], sweep_ran),
}


def test_every_benchmark_has_a_small_run():
    assert sorted(SMALL_RUNS) == sorted(p.stem for p in BENCHMARKS.glob("bench_*.py"))


@pytest.mark.parametrize("name", sorted(SMALL_RUNS))
def test_a_benchmark_imports_and_takes_its_small_run_options(name, monkeypatch, capsys):
    """Its imports resolve and its parser builds and knows every option of its small run and
    of its results page command (``regenerate.PAGE_BENCHMARKS``)."""
    module = script(name, monkeypatch)
    with pytest.raises(SystemExit) as done:
        module.main(["--help"])
    assert done.value.code == 0
    usage = capsys.readouterr().out
    page = regenerate.PAGE_BENCHMARKS[name].split()
    options = [arg for arg in SMALL_RUNS[name][0] + page if arg.startswith("--")]
    assert all(option in usage for option in options), (options, usage)


def package_calls(module):
    """(line, callee, call) for each call in the script's source of a function or class of
    the package it reaches by a name of its own (``calibration_bands(...)``,
    ``bands.measure(...)``)."""
    for node in ast.walk(ast.parse(Path(module.__file__).read_text())):
        if not isinstance(node, ast.Call):
            continue
        path, func = [], node.func
        while isinstance(func, ast.Attribute):
            path.insert(0, func.attr)
            func = func.value
        if not isinstance(func, ast.Name) or func.id not in vars(module):
            continue
        callee = vars(module)[func.id]
        for attr in path:
            callee = getattr(callee, attr, None)
        home = getattr(callee, "__module__", None) or ""
        if callable(callee) and home.split(".")[0] == "snn_antenna":
            yield node.lineno, callee, node


@pytest.mark.parametrize("name", sorted(SMALL_RUNS))
def test_a_benchmark_calls_the_package_as_its_signatures_read(name, monkeypatch):
    """Each call of the package's functions in the script binds to the function's signature
    (the arguments' number and keywords), without running the benchmark."""
    module = script(name, monkeypatch)
    checked = 0
    for line, callee, call in package_calls(module):
        if any(isinstance(a, ast.Starred) for a in call.args) or any(
                k.arg is None for k in call.keywords):
            continue                                # *args or **kwargs: not known here
        try:
            signature = inspect.signature(callee)
        except ValueError:                          # an exception class: no signature of its own
            continue
        try:
            signature.bind(*call.args, **{k.arg: k for k in call.keywords})
        except TypeError as exc:
            pytest.fail(f"benchmarks/{name}.py:{line}: {callee.__qualname__}: {exc}")
        checked += 1
    assert checked, f"{name} calls nothing of the package by name"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SMALL_RUNS))
def test_a_benchmark_runs_its_small_mode_end_to_end(name, monkeypatch, capsys, tmp_path):
    """The script's own ``main`` on tiny inputs, in a folder of its own (caches too)."""
    module = script(name, monkeypatch)
    monkeypatch.chdir(tmp_path)
    argv, promised = SMALL_RUNS[name]
    ended = module.main(argv)
    assert ended == 0 or isinstance(ended, dict), ended   # bench_coders returns its table
    promised(capsys.readouterr().out, tmp_path)             # each asserts what its script promises
