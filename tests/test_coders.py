"""The coders as interchangeable last stages of the chain: offline == streaming, bounds, and
what each keeps of the signal."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.core.errors import SpecError
from snn_antenna.preprocess import (
    CODER_OPTIONS,
    CODERS,
    AnalogCoder,
    LevelCoder,
    SquareWaveCoder,
    make_chain,
    make_coder,
    partial_transform,
    reset,
)

RATE = 1000.0


def _counts(seed: int, n: int = 1500) -> np.ndarray:
    """Two axes of ADC counts: a decaying 20 Hz ring on noise, around mid-scale."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    ring = 60 * np.exp(-t / 0.3) * np.sin(2 * np.pi * 20 * t)
    return 512 + np.column_stack([ring, 0.5 * ring]) + rng.normal(0, 3, (n, 2))


CHAINS = {
    "square": dict(coder="square", threshold=0.02),
    "delta": dict(coder="delta", threshold=0.01, coder_step_g=0.02, coder_levels=5,
                  coder_ratio=1.5),
    "analog": dict(coder="analog", threshold=0.0, coder_gain=3.0, coder_amplitude=0.4),
}


@pytest.mark.parametrize("name", sorted(CHAINS))
@settings(max_examples=15, deadline=None)
@given(cuts=st.lists(st.integers(1, 1499), max_size=6), seed=st.integers(0, 50))
def test_offline_equals_streaming(name, cuts, seed):
    counts = _counts(seed)
    chain = make_chain(RATE, **CHAINS[name]).fit(counts[:300])
    offline = chain.transform(counts)
    reset(chain)
    edges = [0, *sorted(set(cuts)), len(counts)]
    streamed = np.concatenate([partial_transform(chain, counts[a:b])
                               for a, b in zip(edges[:-1], edges[1:]) if b > a])
    if name == "analog":
        # the current is the low-passed signal itself, and the filter run chunk by chunk
        # (sosfilt with its carried state) may round differently from one whole run in the
        # last bit; the thresholding coders hide that, this one passes it on
        np.testing.assert_allclose(streamed, offline, rtol=1e-9, atol=1e-12)
    else:
        np.testing.assert_array_equal(streamed, offline)
    assert np.any(offline != 0)                      # the ring is coded, not silence


def test_one_level_is_the_square_wave():
    x = np.sin(np.linspace(0, 30, 400)) * np.exp(-np.linspace(0, 4, 400))
    square = SquareWaveCoder(0.2, 0.05).fit(x).transform(x)
    level = LevelCoder(0.2, 0.05, step_g=0.1, levels=1).fit(x).transform(x)
    np.testing.assert_array_equal(level, square)


def test_levels_keep_the_amplitude_the_square_wave_drops():
    """Two rings of different amplitude: one square wave, different staircases and currents."""
    t = np.arange(400) / RATE
    ring = np.sin(2 * np.pi * 30 * t)
    weak, strong = 0.05 * ring, 0.4 * ring
    sq = SquareWaveCoder(0.2, 0.01).fit(weak)
    np.testing.assert_array_equal(np.abs(sq.transform(weak)).max(),
                                  np.abs(sq.transform(strong)).max())
    for coder in (LevelCoder(0.2, 0.01, step_g=0.05, levels=6, ratio=1.0),
                  AnalogCoder(1.0, 0.0, gain=2.0)):
        coder.fit(weak)
        assert np.abs(coder.transform(strong)).max() > 2 * np.abs(coder.transform(weak)).max()
    # the level edges: threshold + step · (1 + r + … ), here 0.01 + 0.05·(0, 1, 3, 7)
    edges = LevelCoder(0.4, 0.01, step_g=0.05, levels=4, ratio=2.0).fit(weak)
    np.testing.assert_allclose(edges.edges_above_threshold_, [0.0, 0.05, 0.15, 0.35])
    np.testing.assert_allclose(edges.transform(np.array([0.005, 0.02, 0.1, -0.2, 0.5])),
                               [0.0, 0.1, 0.2, -0.3, 0.4])


def test_analog_saturates_and_keeps_the_sign():
    c = AnalogCoder(0.3, 0.1, gain=2.0).fit(np.zeros(3))
    np.testing.assert_allclose(c.transform(np.array([0.05, 0.2, -0.2, 5.0, -5.0])),
                               [0.0, 0.2, -0.2, 0.3, -0.3])


@pytest.mark.parametrize("name", sorted(CODERS))
def test_gate_threshold_per_sample(name):
    """Every coder takes the speed gate's Th per sample, as the live path gives it."""
    coder = make_coder(name, 0.2, 0.0).fit(np.zeros(3))
    x = np.full(4, 0.05)
    out = coder.partial_transform(x, threshold=np.array([0.0, 0.01, 0.1, 1.0]))
    assert out[0] > 0 and out[1] > 0 and out[2] == 0 and out[3] == 0


# -- bounds ---------------------------------------------------------------------------------
BAD = {
    "coder_step_g": st.one_of(st.floats(max_value=0.0), st.just(float("nan")),
                              st.just(float("inf")), st.text(max_size=3)),
    "coder_levels": st.one_of(st.integers(max_value=0), st.integers(min_value=65),
                              st.floats(1, 5), st.booleans()),
    "coder_ratio": st.one_of(st.floats(max_value=0.999), st.floats(min_value=10.001,
                                                                   allow_infinity=False),
                             st.just(float("nan"))),
    "coder_gain": st.one_of(st.floats(max_value=0.0), st.floats(min_value=1e4 * 1.001,
                                                                allow_infinity=False)),
}
OWNER = {"coder_step_g": "delta", "coder_levels": "delta", "coder_ratio": "delta",
         "coder_gain": "analog"}


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_out_of_range_parameters_are_refused_by_name(data):
    key = data.draw(st.sampled_from(sorted(BAD)))
    value = data.draw(BAD[key])
    with pytest.raises(SpecError) as err:
        make_chain(RATE, coder=OWNER[key], **{key: value})
    assert err.value.field == key


@settings(max_examples=40, deadline=None)
@given(step=st.floats(1e-6, 10.0), levels=st.integers(1, 64), ratio=st.floats(1.0, 10.0),
       gain=st.floats(1e-3, 1e4), th=st.floats(0.0, 5.0),
       x=st.lists(st.floats(-50, 50), min_size=1, max_size=20))
def test_in_range_parameters_code_within_the_amplitude(step, levels, ratio, gain, th, x):
    x = np.asarray(x)
    for chain in (make_chain(RATE, coder="delta", threshold=th, coder_step_g=step,
                             coder_levels=levels, coder_ratio=ratio),
                  make_chain(RATE, coder="analog", threshold=th, coder_gain=gain)):
        coder = chain.named_steps["coder"].fit(x)
        out = coder.transform(x)
        assert np.all(np.isfinite(out)) and np.all(np.abs(out) <= coder.amplitude * (1 + 1e-12))
        assert np.all(out[np.abs(x) <= th] == 0)


def test_unknown_coder_and_misplaced_option_are_refused():
    with pytest.raises(SpecError) as err:
        make_chain(RATE, coder="sigma-delta")
    assert err.value.field == "coder" and "'square'" in err.value.accepted
    with pytest.raises(SpecError) as err:       # a delta option given to the square wave
        make_chain(RATE, coder_levels=4)
    assert err.value.field == "coder_levels" and "'delta'" in err.value.accepted
    assert set(CODER_OPTIONS) == set(CODERS)


@settings(max_examples=30, deadline=None)
@given(low=st.floats(1.0, 499.0), above=st.floats(0.0, 400.0))
def test_highpass_at_or_above_the_lowpass_is_refused(low, above):
    with pytest.raises(SpecError) as err:
        make_chain(RATE, lowpass_hz=low, highpass_hz=min(low + above, 499.9))
    assert err.value.field == "highpass_hz" and "lowpass_hz" in err.value.accepted
    make_chain(RATE, lowpass_hz=low, highpass_hz=low / 2)      # a band-pass is fine


# -- the live path takes the coder from the spec ----------------------------------------------
LIVE_CODERS = {"delta": ["preprocess.coder=\"delta\"", "preprocess.coder_levels=4",
                         "preprocess.coder_step_g=0.05", "preprocess.coder_amplitude=0.3"],
               "analog": ["preprocess.coder=\"analog\"", "preprocess.coder_gain=1.5",
                          "preprocess.coder_amplitude=0.3"]}


@pytest.mark.parametrize("name", sorted(LIVE_CODERS))
def test_live_chain_takes_the_coder_from_the_spec(name):
    """The live chain's last stage is the spec's coder, and codes a contact as one."""
    from pathlib import Path

    from snn_antenna.bridge.online.pipeline import build_online
    from snn_antenna.preprocess import CalibratedChain
    from snn_antenna.sources.stimuli import Contact, RobotScene

    network = Path(__file__).resolve().parents[1] / "networks" / "live.toml"
    parts = build_online(network, ["preprocess.threshold=0.05", *LIVE_CODERS[name]])
    assert isinstance(parts.chain.named_steps["coder"], CODERS[name])
    counts = RobotScene(duration_s=3.0, contacts=[Contact(2.0, 19.0)]).generate(seed=1).samples
    coded = CalibratedChain(parts.chain, 1000).push(counts.astype(float))
    assert len(np.unique(coded)) > 3 and np.abs(coded).max() <= 0.3


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LIVE_CODERS))
def test_live_path_runs_each_coder(tmp_path, name):
    """networks/live.toml replayed with another coder: the chain's last stage is that coder,
    the live coded stream equals the chain's offline coding, and contacts come out."""
    from pathlib import Path

    from snn_antenna.bridge.online.pipeline import build_online, run_online
    from snn_antenna.preprocess import CalibratedChain
    from snn_antenna.bridge.wire.recorder import record_counts
    from snn_antenna.bridge.wire.replay import ReplaySource
    from snn_antenna.sources.stimuli import Contact, RobotScene

    network = Path(__file__).resolve().parents[1] / "networks" / "live.toml"
    overrides = ["preprocess.threshold=0.05", *LIVE_CODERS[name]]
    parts = build_online(network, overrides)
    assert isinstance(parts.chain.named_steps["coder"], CODERS[name])
    counts = RobotScene(duration_s=4.0, contacts=[Contact(2.0, 19.0)]).generate(seed=1).samples
    offline = CalibratedChain(parts.chain, 1000).push(counts.astype(float))
    assert len(np.unique(offline)) > 3           # a staircase or a current, not ±amplitude
    live = run_online(ReplaySource(record_counts(tmp_path / "rec", counts)).start(),
                      build_online(network, overrides), no_data_timeout_s=60)
    assert live["samples"] == len(counts)
    assert len(live["contacts"]) >= 1
