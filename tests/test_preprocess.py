"""Preprocessing: offline and streaming forms agree exactly; each stage does its job."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.base import clone

from snn_antenna import preprocess as pp
from snn_antenna.core.errors import SpecError
from snn_antenna.sources.stimuli import Contact, RobotScene

SCENE = RobotScene(duration_s=4.0, contacts=[Contact(2.0, 19.0)]).generate(seed=5)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(1, 900), min_size=1, max_size=12))
def test_streaming_equals_offline_for_any_chunking(sizes):
    chain = pp.fit_warmup(pp.make_chain(SCENE.rate_hz, threshold=0.05), SCENE.samples,
                          SCENE.rate_hz, warmup_s=1.5)
    offline = chain.transform(SCENE.samples)
    pp.reset(chain)
    cuts = np.cumsum(sizes)
    cuts = cuts[cuts < SCENE.n_samples]
    streamed = np.concatenate([pp.partial_transform(chain, c)
                               for c in np.split(SCENE.samples, cuts)])
    np.testing.assert_array_equal(offline, streamed)


def test_a_warm_up_fit_sees_only_the_warm_up():
    # Everything after the warm-up (here: the contact at 2 s) is replaced; the fitted chain,
    # and so the coded signal up to any time, must not change.
    n = int(1.5 * SCENE.rate_hz)
    other = SCENE.samples.copy()
    other[n:] = other[n:, ::-1] * 2
    a = pp.fit_warmup(pp.make_chain(SCENE.rate_hz), SCENE.samples, SCENE.rate_hz, 1.5)
    b = pp.fit_warmup(pp.make_chain(SCENE.rate_hz), other, SCENE.rate_hz, 1.5)
    np.testing.assert_array_equal(a.named_steps["align"].axis_, b.named_steps["align"].axis_)
    np.testing.assert_array_equal(a.transform(SCENE.samples)[:n], b.transform(other)[:n])
    for bad in (0.0, 0.005, 4.5, float("nan")):
        with pytest.raises(SpecError, match="warmup_s"):
            pp.fit_warmup(pp.make_chain(SCENE.rate_hz), SCENE.samples, SCENE.rate_hz, bad)


def test_pca_recovers_the_oscillation_axis():
    rng = np.random.default_rng(0)
    s = np.sin(np.linspace(0, 60, 3000))
    theta = np.deg2rad(35)
    X = np.c_[s * np.cos(theta), s * np.sin(theta)] + rng.normal(0, 0.01, (3000, 2)) + [3, -1]
    align = pp.PCAAlign().fit(X)
    assert abs(align.axis_ @ [np.cos(theta), np.sin(theta)]) == pytest.approx(1, abs=1e-3)
    assert align.explained_variance_ratio_ > 0.99
    y = align.transform(X)
    assert abs(np.corrcoef(y, s)[0, 1]) > 0.99


def test_lowpass_keeps_the_band_and_removes_high_frequencies():
    t = np.arange(4000) / 1000
    lp = pp.LowPass(1000.0, 30.0).fit(t)
    slow, fast = (lp.transform(np.sin(2 * np.pi * 10 * t)),
                  lp.transform(np.sin(2 * np.pi * 120 * t)))
    assert slow[1000:].std() == pytest.approx(np.sqrt(0.5), rel=0.05)
    assert fast[1000:].std() < 0.01


def test_a_filter_is_designed_once_per_setting_and_passes_its_own_band():
    from scipy.signal import butter

    t = np.arange(4000) / 1000
    hp = pp.HighPass(1000.0, 100.0, order=8).fit(t)
    designed = pp.butter_sos.cache_info().misses
    again = pp.HighPass(1000.0, 100.0, order=8).fit(t)
    assert pp.butter_sos.cache_info().misses == designed                # not designed again
    again.sos_[0, 0] = 7.0                                              # each its own copy
    assert hp.sos_[0, 0] != 7.0
    assert np.array_equal(hp.sos_, butter(8, 100.0, btype="highpass", fs=1000.0,
                                          output="sos"))
    assert not np.array_equal(pp.LowPass(1000.0, 100.0, order=8).fit(t).sos_, hp.sos_)
    slow = hp.transform(np.sin(2 * np.pi * 20 * t))
    fast = hp.transform(np.sin(2 * np.pi * 300 * t))
    assert slow[1000:].std() < 0.01 and fast[1000:].std() == pytest.approx(np.sqrt(0.5), rel=0.05)


def test_centre_removes_offsets_without_a_start_transient():
    x = np.full(3000, 4.0) + np.sin(np.linspace(0, 100, 3000))
    y = pp.Centre(1000.0, 1.0).fit(x).transform(x)
    assert abs(y[0]) < 1e-12 and abs(y[2000:].mean()) < 0.1 and np.abs(y).max() < 1.2


@pytest.mark.parametrize("offset_g", [0.05, -0.03])
def test_a_band_pass_chain_leaves_no_standing_offset_from_its_first_sample(offset_g):
    """A window that starts off its mean (the high-pass passes the step): the band-passed,
    coded signal keeps no offset once the step has rung out; centred after the high-pass, it
    kept minus the high-pass's first output for the whole window."""
    rate = 2000.0
    t = np.arange(1000) / rate
    g = offset_g * (t < 0.01) + 0.002 * np.sin(2 * np.pi * 200.0 * t)
    counts = np.stack([g, 0.0 * g], axis=1) / 18.0 * 2 ** 15 + 2 ** 15
    chain = pp.make_chain(rate, 16, 18.0, lowpass_hz=260.0, lowpass_order=8,
                          highpass_hz=150.0, coder="analog", coder_amplitude=1.0,
                          coder_gain=100.0)
    assert "centre" not in chain.named_steps
    y = chain.fit_transform(counts)
    late = y[int(0.2 * rate):]
    assert abs(late.mean()) < 0.02 * np.abs(late).max()
    # the low-pass-only chain is centred as before
    assert "centre" in pp.make_chain(rate, 16, 18.0).named_steps


def test_coder_codes_sign_and_silences_sub_threshold_samples():
    coder = pp.SquareWaveCoder(amplitude=0.2, threshold=0.5).fit([0.0])
    out = coder.transform(np.array([-2.0, -0.4, 0.0, 0.3, 0.6, 9.0]))
    assert out.tolist() == [-0.2, 0.0, 0.0, 0.0, 0.2, 0.2]
    per_sample = coder.partial_transform(np.array([1.0, 1.0]), threshold=np.array([0.5, 2.0]))
    assert per_sample.tolist() == [0.2, 0.0]
    huge = pp.SquareWaveCoder(threshold=1e9).fit([0.0]).transform(np.array([5.0, -5.0]))
    assert not huge.any()  # a threshold above the signal codes silence, not an error


def test_transformers_are_scikit_learn_estimators():
    chain = pp.make_chain(1000.0)
    twin = clone(chain)
    assert twin.get_params()["coder__amplitude"] == 0.15
    twin.set_params(coder__threshold=0.3)
    assert twin.named_steps["coder"].threshold == 0.3


@pytest.mark.parametrize("step,field", [
    (pp.LowPass(1000.0, 600.0), "cutoff_hz"),
    (pp.LowPass(-1.0, 30.0), "rate_hz"),
    (pp.Centre(1000.0, 0.0), "tau_s"),
    (pp.SquareWaveCoder(threshold=-1.0), "threshold"),
    (pp.SquareWaveCoder(amplitude=float("nan")), "amplitude"),
])
def test_bad_parameters_are_refused_in_fit(step, field):
    with pytest.raises(SpecError, match=field):
        step.fit(np.zeros(10))


def test_bad_data_is_refused():
    with pytest.raises(SpecError, match="non-finite"):
        pp.LowPass().fit(np.array([0.0, np.nan]))
    with pytest.raises(SpecError, match="two or more axes"):
        pp.PCAAlign().fit(np.zeros(10))
    with pytest.raises(SpecError, match="fit"):
        pp.Centre().transform(np.zeros(3))
