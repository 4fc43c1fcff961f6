"""Spiking read-out of contact events: tuning of the high band, batching, decoders."""
import dataclasses

import numpy as np
import pytest

from snn_antenna.engine.events import run_bank
from snn_antenna.networks import neurons
from snn_antenna.networks.neurons import spike_summary
from snn_antenna.readout.spiking import (
    HIGH_BAND,
    LOW_BAND,
    CentroidDistance,
    DominantNeuronDistance,
    SpikingBank,
)
from snn_antenna.core.signals import Recording
from snn_antenna.sources import bench
from snn_antenna.sources.stimuli import square

RATE = 2000.0


@pytest.fixture(scope="module")
def wood_events():
    """Wood at all 16 paper positions, 3 contacts each (48 events)."""
    return bench.generate(bench.BenchSpec(materials=("wood",), repetitions=3, duration_s=0.45),
                          log=lambda *_: None)


def test_each_high_band_neuron_peaks_within_one_channel_of_its_target():
    """Every neuron × every channel's square wave in one group, at the band's dt (0.1 ms)."""
    bank = SpikingBank(bands={"high": HIGH_BAND}, target="numpy")
    array = HIGH_BAND.array(bank.dt_ms, bank.method, "numpy")
    hz, n = array.neuron_hz, array.n_neurons
    current = np.stack([square(f, 0.3, RATE, HIGH_BAND.coder_amplitude).samples for f in hz],
                       axis=1)
    res = neurons.simulate("resonator", current, bank.dt_ms, k=np.repeat(array.k, n),
                           input_dt_ms=1000 / RATE, input_index=np.tile(np.arange(n), n))
    counts = np.bincount(res.spike_i, minlength=n * n).reshape(n, n)   # neuron × input
    assert counts.max(axis=1).min() > 0
    # the band's ends have no channel beyond them: judge them on the inner side only
    offset = np.argmax(counts, axis=1) - np.arange(n)
    assert np.all(np.abs(offset) <= 1), offset


def test_batched_coding_equals_the_chain_per_event(wood_events):
    counts = wood_events["counts"].values[:4]
    bank = SpikingBank(target="numpy")
    coded = bank.code(counts, RATE, 16, 10.0)
    for e in range(len(counts)):
        for j, band in enumerate(bank.bands.values()):
            ev = counts[e, :coded.shape[0]]
            chain = band.chain(RATE, 16, 10.0)
            assert np.array_equal(chain.fit(ev).transform(ev), coded[:, 2 * e + j])


def test_one_group_for_many_events_gives_the_spikes_of_one_run_per_event(wood_events):
    counts = wood_events["counts"].values[[0, 20, 45]]
    bank = SpikingBank(bands={"low": LOW_BAND}, duration_s=0.3, target="numpy")
    feats = run_bank(bank, counts, RATE, 16, 10.0, progress=False)
    coded = bank.code(counts, RATE, 16, 10.0)
    array = LOW_BAND.array(bank.dt_ms, bank.method, "numpy")
    for e in range(len(counts)):
        single = array.run(Recording(coded[:, e], RATE, units="coded"))
        assert np.array_equal(np.bincount(single.spike_i, minlength=array.n_neurons),
                              feats.counts[e])
    assert feats.neuron_steps == pytest.approx(3 * 24 * 0.3 / 1e-4)


def test_spiking_decoders_recover_distance_on_positions_not_trained_on():
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.neural_network import MLPRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    events = bench.generate(bench.BenchSpec(materials=("wood",), repetitions=6,
                                            duration_s=0.45), log=lambda *_: None)
    bank = SpikingBank(bands={"low": LOW_BAND}, duration_s=0.45, target="numpy")
    feats = run_bank(bank, events["counts"].values, RATE, 16, 10.0, progress=False)
    d = events["distance_cm"].values
    spread_mm = 10 * d.std()   # ≈ 92 mm: what always guessing the mean would give
    # the paper's map (no training) on every event
    law = DominantNeuronDistance(feats.neuron_hz).fit(feats.counts).predict(feats.counts)
    assert 10 * np.sqrt(np.mean((law - d) ** 2)) < 0.35 * spread_mm
    centroid = CentroidDistance(feats.neuron_hz).fit(feats.counts).predict(feats.counts)
    assert 10 * np.sqrt(np.mean((centroid - d) ** 2)) < 0.15 * spread_mm
    # an MLP on the spike counts, trained on every other position, tested on those between
    held_out = np.isin(events["position"].values, np.arange(1, 16, 2))
    mlp = TransformedTargetRegressor(make_pipeline(StandardScaler(), MLPRegressor(
        hidden_layer_sizes=(20, 5), alpha=1.0, max_iter=3000, random_state=0)),
        transformer=StandardScaler())
    mlp.fit(feats.counts[~held_out], d[~held_out])
    err = mlp.predict(feats.counts[held_out]) - d[held_out]
    assert 10 * np.sqrt(np.mean(err ** 2)) < 0.35 * spread_mm


def test_the_dominant_neuron_is_the_read_outs_one_rule():
    """Spike counts follow ``contacts.dominant_hz``: a plateau of tied neurons gives its
    centre (a plain argmax would give its lowest neuron), silence gives 0 Hz."""
    import xarray as xr

    from snn_antenna.readout.contacts import dominant_hz
    from snn_antenna.readout.spiking import SpikeFeatures

    hz = np.array([8.0, 10.0, 12.0, 14.0, 16.0])
    counts = np.array([[0, 5, 5, 5, 0], [0, 0, 0, 0, 0], [1, 2, 3, 2, 1]])
    feats = SpikeFeatures(counts, np.zeros_like(counts, float), np.zeros_like(counts, float),
                          hz, np.array(["low"] * 5), 0.5)
    assert feats.dominant_hz("low").tolist() == [12.0, 0.0, 12.0]
    rates = xr.DataArray(counts.astype(float), dims=("event", "neuron_hz"),
                         coords={"neuron_hz": hz})
    assert np.array_equal(feats.dominant_hz("low"), dominant_hz(rates).values)
    law = DominantNeuronDistance(hz).fit(counts).predict(counts)
    assert law[0] == law[2] and law[0] != law[1]


def test_spike_summary_known_answer():
    counts, first, span = spike_summary(np.array([1, 1, 1, 3]), np.array([0.1, 0.3, 0.2, 0.4]),
                                        4, 0.5)
    assert counts.tolist() == [0, 3, 0, 1]
    assert first.tolist() == [0.5, 0.1, 0.5, 0.4]
    assert span == pytest.approx([0.0, 0.2, 0.0, 0.0])


def test_binned_counts_known_answer():
    """Spikes per neuron before 0.1 s, in [0.1, 0.2), and from 0.2 s on (an edge belongs to
    the bin it opens)."""
    from snn_antenna.networks.neurons import binned_spike_counts
    binned = binned_spike_counts(np.array([0, 0, 0, 2, 2]),
                                 np.array([0.05, 0.1, 0.25, 0.2, 0.19]), 3, (0.1, 0.2))
    assert binned.tolist() == [[1, 1, 1], [0, 0, 0], [0, 1, 1]]


def test_bad_banks_are_refused():
    from snn_antenna.core.errors import SpecError
    on_the_banks_step = dataclasses.replace(HIGH_BAND, dt_ms=None, method=None)
    with pytest.raises(SpecError, match="bands.high.dt_ms"):
        SpikingBank(bands={"high": on_the_banks_step}, dt_ms=0.5)
    with pytest.raises(SpecError, match="bands.high.rate_hz"):
        SpikingBank(bands={"high": HIGH_BAND}).check_rate(1000.0)
    with pytest.raises(SpecError, match="^spacing = 'cubic'"):
        dataclasses.replace(LOW_BAND, spacing="cubic")
    with pytest.raises(SpecError, match="^bands.low.spacing = 'cubic'"):
        SpikingBank(bands={"low": {**dataclasses.asdict(LOW_BAND), "spacing": "cubic"}})
    with pytest.raises(SpecError, match="bin_edges_s"):
        SpikingBank(bands={"low": LOW_BAND}, bin_edges_s=(0.2, 0.1))
    with pytest.raises(SpecError, match="target"):
        SpikingBank(bands={"low": LOW_BAND}, target="cpp")
    # a band's own dt is checked against its own k, not the bank's dt
    with pytest.raises(SpecError, match="bands.high.dt_ms"):
        SpikingBank(bands={"high": dataclasses.replace(HIGH_BAND, dt_ms=0.5)}, dt_ms=0.05)
    with pytest.raises(SpecError, match="bands.low.method"):
        SpikingBank(bands={"low": {**dataclasses.asdict(LOW_BAND), "method": "heun"}})
    fine = SpikingBank(bands={"high": dataclasses.replace(HIGH_BAND, dt_ms=0.05, method="euler")},
                       dt_ms=0.5,
                       bin_edges_s=())
    assert fine.arrays()["high"].dt_ms == 0.05
