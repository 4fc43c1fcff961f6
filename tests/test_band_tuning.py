"""Tuned channels of the spiking read-out (readout/band_tuning.py): placement from training
spectra, the channels' bands and steps, the decay code, and the spec's checks. No Brian2."""
import dataclasses

import numpy as np
import pytest

from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.readout.band_tuning import (
    Tuning,
    coarsest_dt_ms,
    fisher_ratio,
    place_channels,
    tune,
    tuned_bands,
)
from snn_antenna.readout.spiking import LOW_BAND
from snn_antenna.readout.spiking_decoders import TunedPlan, decay_code
from snn_antenna.sources import bench

RATE = 2000.0


def two_class_spectra(lines_hz=(120.0, 370.0), n=40, seed=0):
    """Log spectra (2 Hz bins) of two classes that differ only at ``lines_hz``."""
    rng = np.random.default_rng(seed)
    freq = np.arange(0.0, 1000.0, 2.0)
    spectra = rng.normal(0.0, 1.0, (2 * n, len(freq)))
    labels = np.repeat(["a", "b"], n)
    for f in lines_hz:
        spectra[labels == "b", np.argmin(np.abs(freq - f))] += 5.0
    return freq, spectra, labels


def test_fisher_ratio_known_answer():
    spectra = np.array([[0.0, 1.0], [2.0, 1.0], [10.0, 3.0], [12.0, 3.0]])
    # bin 0: class means 1 and 11 (variance 25), within-class variance 1 -> 25; bin 1: the
    # classes differ with no spread inside them -> variance of means over ~0
    ratio = fisher_ratio(spectra, ["x", "x", "y", "y"])
    assert ratio[0] == pytest.approx(25.0)
    assert ratio[1] > 1e6
    with pytest.raises(SpecError, match="labels"):
        fisher_ratio(spectra, ["x"] * 4)


def test_channels_go_where_the_classes_differ():
    freq, spectra, labels = two_class_spectra()
    tuning = Tuning(n_resonators=8, per_channel=2, quantile=0.99)
    centres, low, high = place_channels(freq, fisher_ratio(spectra, labels), tuning)
    assert len(centres) == 4
    # every channel sits within a few bins of one of the two lines, none in between
    near = np.min(np.abs(centres[:, None] - np.array([120.0, 370.0])[None]), axis=1)
    assert np.all(near <= 6.0), centres
    assert {bool(c < 245) for c in centres} == {True, False}      # both lines get channels
    assert np.all(low < centres) and np.all(centres < high)
    # in frequency order, no channel reaching past its neighbour's centre (a channel is at
    # least ±2 Hz wide, so close centres may share a little of their edges)
    assert np.all(np.diff(centres) > 0)
    assert np.all(low[1:] > centres[:-1]) and np.all(high[:-1] < centres[1:])


def test_a_rod_line_draws_the_channels_on_bench_contacts():
    """Wood (its rod rings at 334 Hz) against acrylic glass (123 Hz): the channels placed from
    their contacts' spectra bracket both rods' lines."""
    spec = bench.BenchSpec(materials=("wood", "acrylic_glass"), positions_cm=(15.0, 25.0, 35.0),
                           repetitions=6, duration_s=0.45, n_jobs=1)
    data = bench.generate(spec, log=lambda *_: None)
    labels = np.repeat(spec.materials, len(spec.positions_cm) * spec.repetitions)
    bands = tune(data["counts"].values, labels, RATE, spec.adc_bits, spec.full_scale_g,
                 Tuning(n_resonators=16, per_channel=2))
    passes = [(b.highpass_hz, b.lowpass_hz) for b in bands.values()]
    for line in (334.0, 123.0):
        assert any(lo - 5 <= line <= hi + 5 for lo, hi in passes), (line, passes)


def test_tuned_bands_split_the_resonators_over_capped_channels():
    freq, spectra, labels = two_class_spectra()
    score = fisher_ratio(spectra, labels)
    for n, channels, per in ((24, 12, 2), (48, 24, 2), (144, 24, 6)):
        tuning = Tuning(n_resonators=n)
        bands = tuned_bands(*place_channels(freq, score, tuning), tuning, RATE)
        assert len(bands) == channels and {b.n_neurons for b in bands.values()} == {per}
        for b in bands.values():
            assert b.filter_order == 8
            # the channel's resonators centred on it (they may reach past a narrow channel's
            # edges: a resonator fires most for input somewhat above its own frequency)
            centre = np.sqrt(b.band_hz[0] * b.band_hz[1])
            assert b.highpass_hz < centre < b.lowpass_hz
            # each channel's own step: the coarsest within the rod band's validated k·dt
            assert b.dt_ms == coarsest_dt_ms(b.band_hz[1], b.hz_per_k, tuning.max_k_dt)


def test_graded_gains_share_a_channel_and_its_resonators():
    freq, spectra, labels = two_class_spectra()
    tuning = Tuning(n_resonators=24, per_channel=6, max_channels=4, coder="analog",
                    coder_amplitude=1.0, gains=(20.0, 150.0, 1000.0))
    bands = tuned_bands(*place_channels(freq, fisher_ratio(spectra, labels), tuning), tuning,
                        RATE)
    assert len(bands) == 12 and {b.n_neurons for b in bands.values()} == {2}
    for j in range(4):
        trio = [bands[f"ch{j:02d}g{i}"] for i in range(3)]
        assert [b.coder_options["gain"] for b in trio] == [20.0, 150.0, 1000.0]
        # one channel: the same filters and resonators, only the coder's gain differs
        assert len({(b.highpass_hz, b.lowpass_hz, b.band_hz, b.dt_ms) for b in trio}) == 1


def test_a_bank_codes_bands_that_share_their_filters_as_each_band_alone():
    """The bank filters a channel once for all its gains: every column equals its band's
    own chain run alone."""
    from sklearn.pipeline import Pipeline

    from snn_antenna.readout.spiking import SpikingBank, align_events

    tuning = Tuning(n_resonators=6, per_channel=3, max_channels=2, coder="analog",
                    coder_amplitude=1.0, gains=(20.0, 150.0, 1000.0))
    bands = tuned_bands([120.0, 300.0], [115.0, 290.0], [125.0, 310.0], tuning, RATE)
    bank = SpikingBank(bands={**bands, "low": LOW_BAND}, duration_s=0.5)
    rng = np.random.default_rng(3)
    t = np.arange(1000) / RATE
    counts = 32768 + 40 * np.sin(2 * np.pi * 120 * t)[None, :, None] \
        + 30 * rng.standard_normal((3, 1000, 2))
    coded = bank.code(counts, RATE, 16, 18.0).reshape(1000, 3, len(bank.bands))
    main = align_events(counts, 16, 18.0)          # a 22 mg line at 120 Hz, 16 mg of noise
    for j, band in enumerate(bank.bands.values()):
        alone = Pipeline(band.chain(RATE, 16, 18.0).steps[2:]).fit_transform(main)
        assert np.array_equal(coded[:, :, j], alone), j
    # the gains differ: a loud line saturates the high gain's current, not the low one's
    assert np.abs(coded[:, :, 2]).max() == 1.0 > np.abs(coded[:, :, 0]).max()


def test_coarsest_step_known_answers():
    # k = f / 27.49; the rod band's validated k·dt is 420 / 27.49 × 0.005 = 0.0764
    assert coarsest_dt_ms(420.0, 27.49, 0.0764) == 0.005
    assert coarsest_dt_ms(126.0, 27.49, 0.0764) == 0.01
    assert coarsest_dt_ms(40.0, 27.49, 0.0764) == 0.05
    with pytest.raises(SpecError, match="max_k_dt"):
        coarsest_dt_ms(1e6, 1.0, 0.0764)


def test_decay_code_known_answer():
    binned = np.array([[[3, 1, 0], [0, 0, 7]]])          # one event, two neurons, 3 bins
    code = decay_code(binned)
    assert code.shape == (1, 4)
    assert np.allclose(code, [[np.log(2 / 4), np.log(1 / 2), 0.0, np.log(8.0)]])


def test_order_8_keeps_the_low_mode_out_of_a_narrow_rod_channel():
    """A 40 Hz low mode 30 times a 110 Hz rod line, band-passed 100-120 Hz: order 4 lets the
    low mode take zero crossings the line should own; order 8 does not."""
    t = np.arange(int(0.5 * RATE)) / RATE
    g = 0.6 * np.sin(2 * np.pi * 40 * t) + 0.02 * np.sin(2 * np.pi * 110 * t)
    counts = np.stack([g / 10.0 * 32767 + 32768, np.full_like(g, 32768)], axis=1)
    crossings = {}
    for order in (4, 8):
        band = dataclasses.replace(LOW_BAND, highpass_hz=100.0, lowpass_hz=120.0,
                                   threshold_g=0.0, filter_order=order)
        coded = band.chain(RATE, 16, 10.0).fit(counts).transform(counts)[len(t) // 2:]
        crossings[order] = int(np.sum(coded[1:] * coded[:-1] < 0))
    line = 2 * 110 * 0.25                                   # crossings of the line alone
    assert abs(crossings[8] - line) <= 0.05 * line, crossings
    assert abs(crossings[4] - line) > 0.1 * line, crossings


def test_tuned_plan_refuses_bad_settings_naming_the_field():
    with pytest.raises(SpecError, match="n_resonators"):
        Tuning(n_resonators=25)
    with pytest.raises(SpecError, match="gains.*analog"):
        Tuning(gains=(20.0, 150.0))               # the square-wave coder has no gain
    with pytest.raises(SpecError, match="per_channel.*gains"):
        Tuning(coder="analog", gains=(20.0, 150.0, 1000.0))    # 2 per channel, 3 gains
    with pytest.raises(SpecError, match="gain"):
        Tuning(coder="analog", per_channel=2, gains=(20.0, -1.0))
    with pytest.raises(SpecError, match="tuning.bogus"):
        TunedPlan(tuning={"bogus": 1})
    with pytest.raises(SpecError, match="curve"):
        TunedPlan(curve=[24, 25])
    with pytest.raises(SpecError, match="calibration_repetitions"):
        TunedPlan(calibration_repetitions=1)
    spec = specs.load("studies/baseline_comparison.toml",
                      ["spiking.tuned.tuning.quantile=1.5"])
    from snn_antenna.studies import baseline_comparison as study
    with pytest.raises(SpecError, match="spiking.tuned.tuning.quantile"):
        study.plan(spec)


# Brian2 at the channels' own steps over 1,024 contacts of 0.5 s, twice: a thorough check.
@pytest.mark.slow
def test_tuned_channels_read_materials_better_than_the_hand_set_rod_band():
    """The same 24 resonators, the same contacts and split: channels placed from calibration
    contacts of another seed against the hand-set rod band (90-420 Hz, one wide band-pass)."""
    import warnings

    from threadpoolctl import threadpool_limits

    from snn_antenna.engine.events import run_bank
    from snn_antenna.evaluation.bands import ROD_BAND
    from snn_antenna.evaluation.crossval import split_by_repetition
    from snn_antenna.readout.spiking import SpikingBank
    from sklearn.neural_network import MLPClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    spec = bench.BenchSpec(repetitions=8, n_jobs=2)
    data = bench.generate(spec, log=lambda *_: None)
    per = len(spec.positions_cm) * spec.repetitions
    labels = np.repeat(spec.materials, per)
    repetition = np.tile(np.arange(spec.repetitions), len(spec.materials) * len(spec.positions_cm))
    calibration = dataclasses.replace(spec, seed=1000, repetitions=3)
    cal = bench.generate(calibration, log=lambda *_: None)
    channels = tune(cal["counts"].values[:, :1000], np.repeat(spec.materials, 16 * 3), RATE,
                    spec.adc_bits, spec.full_scale_g, Tuning(n_resonators=24))
    edges = (0.075, 0.1, 0.15, 0.2, 0.3, 0.4)
    train, test = split_by_repetition(repetition, 0.3, 0)
    accuracy = {}
    for name, bands in (("tuned", channels), ("rod", {"rod": ROD_BAND})):
        bank = SpikingBank(bands=bands, duration_s=0.5, bin_edges_s=edges)
        f = run_bank(bank, data["counts"].values, RATE, spec.adc_bits, spec.full_scale_g,
                     progress=False)
        X = np.hstack([f.counts, f.latency_s, f.span_s,
                       f.binned_counts.reshape(len(labels), -1)]).astype(float)
        with threadpool_limits(1), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            clf = make_pipeline(StandardScaler(), MLPClassifier((51,), max_iter=300,
                                                                random_state=0))
            clf.fit(X[train], labels[train])
        accuracy[name] = float(np.mean(clf.predict(X[test]) == labels[test]))
    assert accuracy["tuned"] >= accuracy["rod"] + 0.10, accuracy
    assert accuracy["tuned"] >= 0.65, accuracy
