"""The resonator array: offline and streaming agree; rate maps and read-out."""
import tomllib
from pathlib import Path
from types import SimpleNamespace

import brian2 as b2
import numpy as np
import pytest
from brian2.codegen.runtime.cython_rt import CythonCodeObject

from snn_antenna.core.errors import SpecError
from snn_antenna.networks.resonators import (
    ChunkFeed,
    ResonatorArray,
    StreamPort,
    held_samples,
    rate_map,
)
from snn_antenna.readout.contacts import ContactDetector, centroid_hz, dominant_hz
from snn_antenna.core.signals import Recording
from snn_antenna.sources import stimuli

ROOT = Path(__file__).resolve().parents[1]


def coded_test_input():
    """Two seconds at 8 Hz then one at 16 Hz, coded as the coder would (±0.15)."""
    a = stimuli.square(8.0, 2.0, amplitude=0.15).samples
    b = stimuli.square(16.0, 1.0, amplitude=0.15).samples
    return Recording(np.r_[a, b], 1000.0, units="coded")


def test_streaming_gives_the_same_spikes_as_offline():
    array = ResonatorArray(target="numpy", n_neurons=12)
    coded = coded_test_input()
    offline = array.run(coded, window_s=0.1).rate_map
    windows = []
    chunks = np.array_split(coded.samples, [7, 333, 1500, 2999])
    stats = array.stream(ChunkFeed(chunks, lambda t, counts: windows.append(counts)),
                         coded.rate_hz, window_s=0.1)
    streamed = np.stack(windows, axis=1) / 0.1
    assert stats.samples == coded.n_samples and stats.windows == 30
    np.testing.assert_array_equal(streamed, offline.values)
    assert offline.values.sum() > 20


def live_array() -> ResonatorArray:
    """The array the live pipeline ships (networks/live.toml), as it runs there."""
    with open(ROOT / "networks" / "live.toml", "rb") as f:
        return ResonatorArray(**tomllib.load(f))


def test_streaming_gives_the_same_spikes_as_offline_at_the_live_setting():
    """Every spike, to the input sample: 1 ms windows (one sample per block) and the live
    100 ms windows (blocks of 25); chunks of any length; a last, partial block."""
    array = live_array()
    rng = np.random.default_rng(1)
    t = np.arange(6_037) / 1000.0
    freq = np.where(t < 3.0, 8.0, 17.0)               # self-motion, then a "contact"
    x = 0.15 * np.sign(np.sin(2 * np.pi * np.cumsum(freq) / 1000.0))
    x[rng.random(len(x)) < 0.03] = 0.0                 # below the coder's threshold now and then
    coded = Recording(x, 1000.0, units="coded")
    cuts = np.sort(rng.choice(np.arange(1, len(x)), 25, replace=False))
    for window_s in (0.001, 0.1):
        offline = array.run(coded, window_s=window_s).rate_map.values * window_s
        feed = ChunkFeed(np.split(x, cuts))
        stats = array.stream(feed, 1000.0, window_s=window_s)
        windows = [counts for _, counts in feed.windows]
        assert stats.samples == len(x) and stats.windows == offline.shape[1]
        np.testing.assert_array_equal(np.stack(windows, axis=1), offline)
    assert offline.sum() > 100 and offline[array.neuron_hz > 12].sum() > 10


def test_recordings_of_one_power_of_two_share_one_compiled_input():
    """The offline input is padded to a power of two with its last value: the compiled code
    that reads it (Brian2 writes the TimedArray's length into it) is the same for 5,000 and
    8,192 samples, so a new recording length compiles nothing new on a warm machine."""
    x = np.arange(5_000, dtype=float)
    held = held_samples(x)
    assert len(held) == 8_192 and np.array_equal(held[:5_000], x)
    assert (held[5_000:] == x[-1]).all()
    assert len(held_samples(x[:4_096])) == 4_096
    assert len(held_samples(x[:1])) == 1

    reader = SimpleNamespace(clock=SimpleNamespace(dt_=1e-4))   # a group stepping at 0.1 ms

    def reading_code(n):
        drive = b2.TimedArray(held_samples(np.zeros(n)), dt=b2.ms, name="drive")
        return drive.implementations[CythonCodeObject].get_code(reader)

    assert reading_code(5_000) == reading_code(8_192) != reading_code(8_193)


def test_a_spike_on_a_window_edge_counts_in_the_window_it_starts():
    """53 * 0.1 > 5.3 in floating point: binning by edges put a spike at 5.3 s in [5.2, 5.3)."""
    rates = rate_map(np.array([0, 0]), np.array([5.3, 0.2]), [8.0], 6.0, 0.1)
    assert rates.sel(window_s=5.3, method="nearest").item() == 10.0
    assert rates.sel(window_s=0.2, method="nearest").item() == 10.0 and rates.sum() == 20.0


def test_streaming_needs_a_step_that_divides_the_sample_interval():
    with pytest.raises(SpecError, match="dt_ms.*divides the sample interval"):
        ResonatorArray(target="numpy", dt_ms=0.3).stream(ChunkFeed([np.zeros(10)]), 1000.0)


def test_the_stream_calls_out_of_the_network_only_through_its_port():
    """A StreamPort (fill and window) is what the stream takes: a bare iterator of chunks is
    refused, naming what is accepted."""
    with pytest.raises(SpecError, match="port = 'list_iterator' .*StreamPort"):
        ResonatorArray(target="numpy").stream(iter([np.zeros(10)]), 1000.0)
    assert isinstance(ChunkFeed([]), StreamPort)


def test_rate_map_is_labelled_and_read_out_follows_the_input_frequency():
    array = ResonatorArray(target="numpy")
    rates = array.run(coded_test_input(), window_s=0.25).rate_map
    assert rates.dims == ("neuron_hz", "window_s")
    assert rates.neuron_hz.attrs["units"] == "Hz" and rates.attrs["units"] == "Hz"
    early = float(centroid_hz(rates.sel(window_s=slice(0.5, 1.99)).sum("window_s")))
    late = float(centroid_hz(rates.sel(window_s=slice(2.0, 3.0)).sum("window_s")))
    assert early == pytest.approx(8.0, rel=0.07) and late == pytest.approx(16.0, rel=0.07)
    dom = dominant_hz(rates)
    assert np.all(dom.sel(window_s=slice(2.25, 3.0)) > 12)


def test_contact_detector_finds_the_shift_above_the_motion_band():
    hz = np.geomspace(7, 30, 24)
    # 30 windows: motion activity in the 7–8 Hz neurons, then a contact at 16 Hz (windows 20–24)
    spikes_i, spikes_t = [], []
    for w in range(30):
        neuron = 1 if w < 20 or w >= 25 else int(np.argmin(np.abs(hz - 16)))
        spikes_i += [neuron] * 3
        spikes_t += [w * 0.1 + 0.01, w * 0.1 + 0.04, w * 0.1 + 0.07]
    rates = rate_map(np.array(spikes_i), np.array(spikes_t), hz, 3.0, 0.1)
    (contact,) = ContactDetector().detect(rates)
    assert contact.onset_s == pytest.approx(2.0) and contact.end_s == pytest.approx(2.5)
    assert contact.frequency_hz == pytest.approx(hz[np.argmin(np.abs(hz - 16))])


@pytest.mark.parametrize("kwargs,field", [
    ({"n_neurons": 0}, "n_neurons"),
    ({"band_hz": (30.0, 7.0)}, "band_hz"),
    ({"spacing": "mel"}, "spacing"),
    ({"dt_ms": 1.0, "band_hz": (7.0, 500.0), "method": "rk4"}, "dt_ms"),
])
def test_bad_arrays_are_refused(kwargs, field):
    with pytest.raises(SpecError, match=field):
        ResonatorArray(**kwargs)


def test_input_sampled_too_slowly_for_the_band_is_refused():
    with pytest.raises(SpecError, match="rate_hz.*at least 120"):
        ResonatorArray(target="numpy").run(Recording(np.zeros(100), 100.0))


def test_a_column_of_a_larger_array_runs_on_the_compiled_target():
    """A strided view (a column slice) used to make Brian2's cython TimedArray refuse it."""
    columns = np.stack([coded_test_input().samples] * 2, axis=1)
    view = Recording(columns[:, 1], 1000.0, units="coded")
    assert not view.samples.flags.c_contiguous
    result = ResonatorArray(target="cython", n_neurons=4).run(view)
    assert result.spike_i.size > 0
