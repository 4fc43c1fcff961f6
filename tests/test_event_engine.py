"""Contact events on the sweep engine (``engine.events``): compiled standalone = runtime path,
bands at their own dt, resumable store, Dask, blow-ups named."""
import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from snn_antenna.engine.events import EventSweep, event_sweep, run_bank
from snn_antenna.engine.sweep import run_sweep
from snn_antenna.core.errors import NumericalInstabilityError
from snn_antenna.readout.spiking import HIGH_BAND, LOW_BAND, SpikingBank
from snn_antenna.sources import bench

RATE, BITS, FULL_SCALE = 2000.0, 16, 10.0
# the high band at its own, finer dt; 8 events per chunk, so 12 events make a full chunk and
# a short one (padded in the compiled project)
BANK = SpikingBank(bands={"low": LOW_BAND,
                          "high": dataclasses.replace(HIGH_BAND, dt_ms=0.05, method="euler")},
                   duration_s=0.2, batch_events=8, target="standalone")


@pytest.fixture(scope="module")
def events():
    data = bench.generate(bench.BenchSpec(materials=("wood", "aluminium"), repetitions=1,
                                          positions_cm=(10.0, 16.0, 22.0, 28.0, 34.0, 36.0),
                                          duration_s=0.2), log=lambda *_: None)
    return data["counts"].values


@pytest.fixture(scope="module")
def standalone(events):
    # one compile (~20-40 s on a fresh machine; reused from the disk cache afterwards)
    return run_bank(BANK, events, RATE, BITS, FULL_SCALE, progress=False)


def test_compiled_engine_gives_the_runtime_paths_spike_counts(events, standalone):
    """The same events through cpp_standalone and the cython runtime (neurons.simulate with
    a 2-D input): equal spike counts for every neuron. Spike times may differ by one step
    (the compilers order floating-point operations differently), never counts here."""
    runtime = run_bank(dataclasses.replace(BANK, target="cython"), events, RATE, BITS,
                       FULL_SCALE, progress=False)
    assert standalone.counts.shape == (12, 48)
    assert standalone.counts.sum() > 100 and (standalone.counts == 0).any()
    assert np.array_equal(standalone.counts, runtime.counts)
    assert np.abs(standalone.latency_s - runtime.latency_s).max() <= 0.05e-3 + 1e-12
    assert np.array_equal(standalone.binned_counts.sum(axis=2), standalone.counts)
    assert list(standalone.band) == ["low"] * 24 + ["high"] * 24
    # each band integrates at its own dt: the high band takes twice the steps
    assert standalone.neuron_steps == pytest.approx(12 * 24 * 0.2 * (1e4 + 2e4))


def test_a_block_in_memory_gives_the_stored_runs_features(events, standalone):
    """What the cost measurement times (``EventSweep.block``: one run, no store) is what a
    data set's run stores, event for event."""
    sweep = event_sweep(dataclasses.replace(BANK, batch_events=12), events, RATE, BITS,
                        FULL_SCALE)
    block = sweep.block()
    assert np.array_equal(block["count"].reshape(12, -1), standalone.counts)
    assert np.array_equal(block["latency_s"].reshape(12, -1), standalone.latency_s)
    assert sweep.neuron_steps == standalone.neuron_steps


def test_an_interrupted_run_resumes_without_redoing_finished_chunks(events, standalone,
                                                                    tmp_path, monkeypatch):
    sweep = EventSweep(BANK, np.ascontiguousarray(events[:, :400]), RATE, BITS, FULL_SCALE)
    # The same evaluator, interrupted in its second chunk: a stand-in evaluator of another
    # module would be other code computing the first chunk, which a resume rightly refuses.
    computes = EventSweep.__call__

    def stops_after_first_chunk(self, points):
        if points["event"].min() >= BANK.batch_events:
            raise RuntimeError("interrupted")
        return computes(self, points)

    store = tmp_path / "events.zarr"
    kw = dict(chunk_points=BANK.batch_events * BANK.n_neurons, settings=sweep.settings(),
              progress=False)
    with monkeypatch.context() as patched:
        patched.setattr(EventSweep, "__call__", stops_after_first_chunk)
        with pytest.raises(RuntimeError, match="interrupted"):
            run_sweep(sweep.grid(), sweep, store, sweep.outputs(), **kw)
    outcome = run_sweep(sweep.grid(), sweep, store, sweep.outputs(), **kw)
    assert outcome.chunks_skipped == [0] and outcome.chunks_computed == [1]
    assert np.array_equal(sweep.features(outcome.data).counts, standalone.counts)


def test_dask_workers_give_the_single_process_features(events, tmp_path):
    from snn_antenna.engine.executor import dask_client

    bank = dataclasses.replace(BANK, bands={"low": LOW_BAND}, target="numpy")
    here = run_bank(bank, events, RATE, BITS, FULL_SCALE, progress=False)
    with dask_client(workers=1) as client:
        there = run_bank(bank, events, RATE, BITS, FULL_SCALE, client=client,
                         store_path=tmp_path / "dask.zarr", progress=False)
    assert np.array_equal(here.counts, there.counts)
    assert np.array_equal(here.binned_counts, there.binned_counts)


def test_a_blown_up_neuron_is_named_after_the_compiled_run():
    sweep = EventSweep(BANK, np.zeros((1, 400, 2), np.uint16), RATE, BITS, FULL_SCALE)
    array = BANK.arrays()["high"]
    n = 3 * array.n_neurons
    fine = SimpleNamespace(v=np.full(n, -60.0), u=np.full(n, -15.0), unstable=np.zeros(n, bool))
    sweep._check_stable(fine, [BANK.arrays()["low"], array], [1], n)
    for field, value in (("v", np.nan), ("u", 1e7), ("unstable", True)):
        group = SimpleNamespace(**vars(fine))
        setattr(group, field, getattr(fine, field).copy())
        getattr(group, field)[30] = value
        with pytest.raises(NumericalInstabilityError, match="neuron 30") as info:
            sweep._check_stable(group, [BANK.arrays()["low"], array], [1], n)
        assert info.value.params["k"] == pytest.approx(array.k[30 - 24])
        assert info.value.dt_ms == 0.05
