"""Coded scenes on the compiled engine (``engine.codings``), the blind read-out's dispatch to
it (``engine.batches.DetectColumns``), and the rates every estimate multiplies by
(``engine.rates``, ``engine.cost``)."""
import json

import numpy as np
import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.engine import batches, cost, rates
from snn_antenna.engine.batches import DetectColumns
from snn_antenna.networks.resonators import ResonatorArray
from snn_antenna.readout.contacts import ContactDetector
from snn_antenna.readout.detection import BlindReadOut, run_codings

RATE = 1000.0


def coded_columns(n_samples: int, columns: int) -> np.ndarray:
    t = np.arange(n_samples) / RATE
    hz = np.linspace(6.0, 28.0, columns)
    return 0.15 * np.sign(np.sin(2 * np.pi * t[:, None] * hz[None, :]))


@pytest.mark.slow
def test_compiled_codings_give_the_runtime_paths_rate_maps():
    """Five codings in runs of three (a full run and a padded short one) against the cython
    runtime path: the same model, so the same spikes up to the compilers' rounding (a spike
    may move by a step, across a window's edge)."""
    from snn_antenna.engine.codings import compiled_rate_maps

    array = ResonatorArray(n_neurons=6, method="rk2", dt_ms=0.1)
    coded = coded_columns(400, 5)
    runtime = run_codings(array, coded, RATE, 0.1, "cython")
    compiled = compiled_rate_maps(array, coded, RATE, 0.1, per_run=3)
    assert len(compiled) == 5
    totals = [float(m.values.sum()) for m in runtime]
    assert sum(totals) > 0 and min(totals) < max(totals)   # the codings differ
    for r, c in zip(runtime, compiled):
        assert c.dims == r.dims and np.allclose(c.neuron_hz, r.neuron_hz)
        assert abs(float(c.values.sum()) - float(r.values.sum())) <= 0.02 * float(
            r.values.sum()) + 10.0
        assert np.mean(c.values == r.values) >= 0.95


def readout(target):
    return BlindReadOut(ResonatorArray(n_neurons=4), ContactDetector(), 0.1, RATE, 0.0,
                        target)


def test_a_standalone_read_out_runs_on_the_compiled_engine_in_runs_of_its_size(monkeypatch):
    calls = []

    def compiled(array, coded, rate_hz, window_s, per_run):
        calls.append((coded.shape, per_run))
        return [runtime_map] * coded.shape[1]

    runtime_map = run_codings(ResonatorArray(n_neurons=4), coded_columns(300, 1), RATE, 0.1,
                              "numpy")[0]
    monkeypatch.setattr(batches, "compiled_rate_maps", compiled)
    out = DetectColumns(readout("standalone"), per_run=7)(list(coded_columns(300, 2).T))
    assert calls == [((300, 2), 7)] and len(out) == 2
    assert out[0][1] is runtime_map                  # (detections, rate map) per column
    calls.clear()
    DetectColumns(readout("numpy"), per_run=7)(list(coded_columns(300, 2).T))
    assert calls == []                               # a runtime target: BlindReadOut.detect


def test_the_gating_sweep_refuses_a_target_it_cannot_run():
    from snn_antenna.studies.gating_threshold.plan import SweepSettings

    with pytest.raises(SpecError, match="target"):
        SweepSettings(target="cpp_standalone")
    assert SweepSettings(target="standalone").target == "standalone"


def test_estimates_take_the_stored_probe_of_this_code_and_say_so(tmp_path, monkeypatch):
    monkeypatch.setenv("SNN_ANTENNA_CACHE", str(tmp_path))
    runs = [(10.0, 0.1, 4800, "codings")]
    table = cost.job_estimate("codings", runs)
    assert "engine/rates.py TABLE" in table.describe()
    path = tmp_path / "rates" / f"{rates.probe_key()}.json"
    path.parent.mkdir()
    stored = {"neuron_steps_per_s": {"codings": rates.TABLE["neuron_steps_per_s"]["codings"]
                                     / 10},
              "steps_per_s": {"codings": -1.0},         # refused: kept from the table
              "compile_s": {"codings": float("nan")}}
    path.write_text(json.dumps({"rates": stored, "when": "2026-01-01 00:00 UTC"}))
    probed = cost.job_estimate("codings", runs)
    assert "probe of 2026-01-01" in probed.describe()
    now = rates.rates()
    assert now["steps_per_s"]["codings"].value == rates.TABLE["steps_per_s"]["codings"]
    assert now["compile_s"]["codings"].value == rates.TABLE["compile_s"]["codings"]
    neurons = 10.0 * 1e4 * 4800 / rates.TABLE["neuron_steps_per_s"]["codings"]
    assert probed.seconds - table.seconds == pytest.approx(9 * neurons)
    # a probe stored under another key (other code, another machine) is never read
    path.rename(path.with_name("0123456789abcdef.json"))
    assert cost.job_estimate("codings", runs).seconds == pytest.approx(table.seconds)


def test_an_estimate_follows_the_load_from_its_probes_to_now(tmp_path, monkeypatch):
    monkeypatch.setenv("SNN_ANTENNA_CACHE", str(tmp_path))
    monkeypatch.setattr(rates.os, "cpu_count", lambda: 2)
    power = rates.SLOWDOWN_POWER
    assert rates.slowdown(0.5) == 1.0 and rates.slowdown(5.0) == pytest.approx(3.0 ** power)
    # no probe: from the load the table was measured at
    monkeypatch.setattr(rates, "competing_load", lambda: rates.TABLE_LOAD)
    factor, note = rates.load_factor()
    assert factor == pytest.approx(1.0) and f"table at {rates.TABLE_LOAD:.1f}" in note
    path = tmp_path / "rates" / f"{rates.probe_key()}.json"
    path.parent.mkdir()
    path.write_text(json.dumps({"rates": {}, "when": "2026-01-01 00:00 UTC",
                                "load_average": 3.0}))
    monkeypatch.setattr(rates, "competing_load", lambda: 7.0)
    factor, note = rates.load_factor()
    assert factor == pytest.approx((4.0 / 2.0) ** power) and "probe at 3.0" in note
    from snn_antenna.core import spec as specs
    from snn_antenna.studies import runner

    spec = specs.load("studies/tuning_sweep.toml", [], quick=True)
    busy = runner("tuning_sweep").plan(spec).estimate()
    monkeypatch.setattr(rates, "competing_load", lambda: 3.0)
    calm = runner("tuning_sweep").plan(spec).estimate()
    assert busy.seconds == pytest.approx(2 ** power * calm.seconds)
    assert f"×{2 ** power:.2f}" in busy.rate.source


def test_the_competing_load_is_the_cpu_in_use_or_the_queue_of_a_saturated_machine(monkeypatch):
    """The cores busy while watched (not the load average, which counts idle kernel
    threads and trails a finished run); a saturated machine's queue (the load average);
    niced work left out unless the kernel groups by session."""
    monkeypatch.setattr(rates.os, "getloadavg", lambda: (6.0, 0.0, 0.0))
    monkeypatch.setattr(rates.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(rates.time, "sleep", lambda s: None)
    monkeypatch.setattr(rates, "_autogroups", lambda: False)

    def watch(*splits):
        ticks = iter(splits)
        monkeypatch.setattr(rates, "_cpu_times", lambda: next(ticks))
        rates._watched.clear()
        return rates.competing_load()

    start = (100.0, 100.0, 100.0)
    # a quarter of the CPU time busy at nice 0: half a core, whatever the load average
    assert watch(start, (125.0, 100.0, 175.0)) == pytest.approx(0.5)
    assert watch(start, (100.0, 100.0, 200.0)) == pytest.approx(0.0)       # idle
    # saturated by ordinary work: the queue the load average counts
    assert watch(start, (200.0, 100.0, 100.0)) == pytest.approx(6.0)
    # saturated by niced work: it yields to an ordinary process
    assert watch(start, (100.0, 200.0, 100.0)) == pytest.approx(0.0)
    assert watch(start, (150.0, 150.0, 100.0)) == pytest.approx(3.0)
    # where the kernel shares the CPU by session first, niced work competes in full
    monkeypatch.setattr(rates, "_autogroups", lambda: True)
    assert watch(start, (100.0, 200.0, 100.0)) == pytest.approx(6.0)
    assert watch(None) == pytest.approx(6.0)                              # no /proc/stat
    # one estimate asks several times within a watch: the machine is watched once
    assert rates.competing_load() == pytest.approx(6.0)
    # the real /proc/stat of this machine: between idle and its queue
    monkeypatch.undo()
    rates._watched.clear()
    assert 0.0 <= rates.competing_load() <= max(rates.os.getloadavg()[0],
                                                 rates.os.cpu_count()) + 1.0
