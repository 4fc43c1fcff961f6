"""The fused event engine (``engine.events``, target ``standalone``: bands sharing a dt in one
group, input read once per sample, features accumulated in the update) against the runtime
path (``neurons.simulate`` on cython, the reference), feature by feature."""
import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.engine.events import EventSweep, run_bank
from snn_antenna.engine.standalone import tick_substeps
from snn_antenna.readout.band_tuning import Tuning, tuned_bands
from snn_antenna.readout.spiking import HIGH_BAND, LOW_BAND, Band, BankInputs, SpikingBank
from snn_antenna.sources import bench

RATE, BITS, FULL_SCALE = 2000.0, 16, 10.0
# the baseline study's rod band (rk2 at 0.005 ms) and a tuned channel at the same step (one
# group: each neuron reads its own channel's column); an edge off the input's sample
# boundaries (0.0752 s = sample 150.4), so the passes that take the edges' counts come more
# often than once a sample, and edges every 2.5 ms after it, so that some spikes fall in the
# step just before an edge (which bin takes them is the edges' rule)
ROD = Band(n_neurons=4, band_hz=(90.0, 420.0), coder_amplitude=0.2, threshold_g=0.006,
           lowpass_hz=500.0, highpass_hz=80.0, hz_per_k=27.49, method="rk2", dt_ms=0.005)
CHANNELS = tuned_bands([330.0], [300.0], [360.0],
                       Tuning(n_resonators=2, per_channel=2, max_channels=1), RATE)
# a channel read at three analog gains: one input column, each neuron scaling and clipping it
GRADED = {f"graded_{name}": band for name, band in tuned_bands(
    [120.0], [110.0], [130.0], Tuning(n_resonators=3, per_channel=3, max_channels=1,
                                      coder="analog", coder_amplitude=1.0, threshold_g=0.002,
                                      gains=(20.0, 150.0, 1000.0)), RATE).items()}
# the high band at rk4, whose last stage reads the next input sample at a sample's last step
HIGH = dataclasses.replace(HIGH_BAND, n_neurons=6)
# (one chunk of 0.15 s: the runtime path's cost is per step; test_event_engine.py pads a chunk)
BANK = SpikingBank(bands={"low": LOW_BAND, "high": HIGH, "rod": ROD, **CHANNELS, **GRADED},
                   duration_s=0.15, batch_events=12, target="standalone",
                   bin_edges_s=(0.0752, *np.arange(0.08, 0.15, 0.0025)))


@pytest.fixture(scope="module")
def both():
    data = bench.generate(bench.BenchSpec(materials=("wood", "aluminium"), repetitions=1,
                                          positions_cm=(10.0, 16.0, 22.0, 28.0, 34.0, 36.0),
                                          duration_s=0.2), log=lambda *_: None)
    events = data["counts"].values
    # one compile (~20-40 s on a fresh machine; reused from the disk cache afterwards)
    fused = run_bank(BANK, events, RATE, BITS, FULL_SCALE, progress=False)
    runtime = run_bank(dataclasses.replace(BANK, target="cython"), events, RATE, BITS,
                       FULL_SCALE, progress=False)
    return fused, runtime


def agree(a, b) -> np.ndarray:
    """Per (event, neuron): every feature equal."""
    return ((a.counts == b.counts) & (a.latency_s == b.latency_s) & (a.span_s == b.span_s)
            & (a.binned_counts == b.binned_counts).all(axis=2))


@pytest.mark.parametrize("band, spikes", [("low", 60), ("high", 50)])
def test_low_and_high_band_give_the_runtime_paths_features_spike_for_spike(both, band, spikes):
    fused, runtime = (f.select([band]) for f in both)
    assert fused.counts.sum() > spikes and (fused.binned_counts[:, :, 1:] > 0).any()
    assert agree(fused, runtime).all()


def test_rod_and_tuned_channels_give_the_runtime_paths_features(both):
    """First spikes and the early bins equal everywhere, every feature equal for most
    neurons (docs/materials.md, "The fused event engine", gives the counts). A channel at the
    coder's low threshold (3-6 mg) fires for whatever side of its
    threshold the state lands on, so the compilers' different rounding of the same rk2
    expression parts a few neurons' trains after some tens of spikes: the unfused compiled
    engine without fusion differs from the runtime path as much on these events
    (6 counts and 25 spans of 96 neurons; the fused engine 7 and 24)."""
    fused, runtime = (f.select(["rod", *CHANNELS]) for f in both)
    assert fused.counts.shape == (12, 6) and fused.counts.sum() > 500
    assert (fused.binned_counts.sum(axis=2) == fused.counts).all()
    assert np.array_equal(fused.latency_s, runtime.latency_s)
    assert np.array_equal(fused.binned_counts[:, :, :2], runtime.binned_counts[:, :, :2])
    assert (fused.counts == runtime.counts).mean() >= 0.9
    assert abs(fused.counts.sum() / runtime.counts.sum() - 1) < 0.01
    assert agree(fused, runtime).mean() >= 0.6


def test_graded_gains_read_one_column_as_each_band_its_own(both):
    """The compiled engine sends a channel's graded gains one column and scales and clips it
    per neuron: every feature equals that of each band's coded current sent as its own
    column; against the runtime path, as for the rod band above (the compilers' rounding of
    rk2 parts a train after some tens of spikes), first spikes and early bins equal."""
    events = both[0].counts.shape[0]
    counts = bench.generate(bench.BenchSpec(materials=("wood",), repetitions=1,
                                            positions_cm=(10.0, 34.0), duration_s=0.2),
                            log=lambda *_: None)["counts"].values[:, :300]
    sweep = EventSweep(BANK, np.ascontiguousarray(counts), RATE, BITS, FULL_SCALE)
    inputs = BANK.inputs(counts, RATE, BITS, FULL_SCALE)
    assert len(inputs.columns) == len(BANK.bands) - 2
    n = len(BANK.bands)
    coded = inputs.coded().reshape(300, len(counts), n)
    own = BankInputs(tuple(coded[:, :, j] for j in range(n)), np.arange(n), np.ones(n),
                     np.full(n, 1e9))
    shared, alone = sweep._standalone(inputs), sweep._standalone(own)
    for j in range(n):
        assert all(np.array_equal(a, b) for a, b in zip(shared[j], alone[j])), j
    fused, runtime = (f.select(list(GRADED)) for f in both)
    assert fused.counts.shape == (events, 3) and (fused.counts > 0).all()
    assert (fused.counts[:, 2] >= fused.counts[:, 0]).all()   # the loudest gain fires most
    assert np.array_equal(fused.latency_s, runtime.latency_s)
    assert np.array_equal(fused.binned_counts[:, :, :2], runtime.binned_counts[:, :, :2])


@settings(max_examples=200, deadline=None)
@given(st.sampled_from([0.1, 0.05, 0.025, 0.02, 0.01, 0.005, 0.0025, 0.03]),
       st.sampled_from([1000.0, 2000.0, 3000.0]), st.integers(1, 3000),
       st.lists(st.integers(0, 10**6), max_size=3), st.one_of(st.none(), st.integers(1, 50)))
def test_a_tick_divides_the_sample_the_run_and_every_boundary(dt_ms, rate_hz, samples,
                                                             boundaries, at_most):
    sample_ms = 1000.0 / rate_hz
    s = tick_substeps(sample_ms, dt_ms, samples * sample_ms, at_most, boundaries)
    per_sample = sample_ms / dt_ms
    assert s >= 1 and (at_most is None or s <= at_most)
    if abs(per_sample - round(per_sample)) > 1e-6:
        assert s == 1
    else:
        assert round(per_sample) % s == 0 and all(b % s == 0 for b in boundaries)
