"""Antenna physics, waveforms and scenes: laws from the paper, labels, and refusals."""
import numpy as np
import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.core.signals import Recording
from snn_antenna.sources import antenna, stimuli


def peak_hz(x, rate_hz):
    spectrum = np.abs(np.fft.rfft(x - x.mean()))
    return np.fft.rfftfreq(len(x), 1 / rate_hz)[np.argmax(spectrum)]


def test_mode_laws_and_their_inverse():
    d = np.array([8.0, 19.0, 37.5])
    assert np.log10(antenna.low_mode_hz(d)) == pytest.approx(0.0268 * d + 0.69)
    assert np.log10(antenna.high_mode_hz(d)) == pytest.approx(0.0305 * d + 1.52)
    assert antenna.distance_from_low_hz(antenna.low_mode_hz(d)) == pytest.approx(d)


def test_decay_falls_with_distance_and_depends_on_material():
    d = np.linspace(8, 37.5, 16)
    for m in antenna.MATERIALS:
        tau_low, tau_high = antenna.decay_times_s(d, m)
        assert np.all(np.diff(tau_low) < 0) and np.all(np.diff(tau_high) < 0)
    assert np.all(antenna.decay_times_s(d, "aluminium")[0] > antenna.decay_times_s(d, "wood")[0])
    assert len(antenna.MATERIALS) == 8


def test_contact_ringing_rings_at_the_low_mode_and_decays():
    rng = np.random.default_rng(0)
    x = antenna.contact_ringing(19.0, "wood", 4000.0, 4000, rng, scatter=False)
    assert peak_hz(x, 4000.0) == pytest.approx(antenna.low_mode_hz(19.0), abs=1.0)
    tau = antenna.decay_times_s(19.0, "wood")[0]
    early, late = np.abs(x[:200]).max(), np.abs(x[int(3 * tau * 4000):][:200]).max()
    assert late < 0.1 * early


@pytest.mark.parametrize("distance", [-3.0, 0.0, 41.3, 80.0, float("nan")])
def test_distances_off_the_rod_are_refused(distance):
    with pytest.raises(SpecError, match="distance_cm"):
        antenna.low_mode_hz(distance)


def test_unknown_material_is_refused_with_the_list():
    with pytest.raises(SpecError, match="material.*aluminium"):
        antenna.decay_times_s(20.0, "granite")


def test_adc_quantises_and_clips_at_the_rails():
    adc = antenna.ADC(10, 18.0)
    assert adc.lsb_g == pytest.approx(36 / 1024)
    counts = adc.to_counts(np.array([0.0, 1.0, -100.0, 100.0]))
    assert counts.tolist() == [512, 512 + round(1 / adc.lsb_g), 0, 1023]
    assert np.abs(adc.to_g(adc.to_counts(np.linspace(-5, 5, 101))) -
                  np.linspace(-5, 5, 101)).max() <= adc.lsb_g / 2 + 1e-12


@pytest.mark.parametrize("make,expected", [
    (lambda: stimuli.sine(13.0, 2.0), 13.0),
    (lambda: stimuli.square(9.0, 2.0), 9.0),
    (lambda: stimuli.pulse_train(25.0, 2.0), 25.0),
])
def test_waveforms_carry_their_rate_and_frequency(make, expected):
    rec = make()
    assert rec.rate_hz == 1000.0 and rec.duration_s == pytest.approx(2.0)
    assert peak_hz(rec.samples, rec.rate_hz) == pytest.approx(expected, abs=0.6)


def test_chirp_silence_dc():
    c = stimuli.chirp(5, 50, 4.0).samples
    assert peak_hz(c[:1000], 1000) < peak_hz(c[-1000:], 1000)
    assert not stimuli.silence(1.0).samples.any()
    assert np.all(stimuli.dc(0.3, 1.0).samples == 0.3)


def test_waveform_above_nyquist_is_refused():
    with pytest.raises(SpecError, match="freq_hz.*Nyquist"):
        stimuli.sine(600.0, 1.0, rate_hz=1000.0)


def test_self_motion_rings_near_7_8_hz_and_grows_with_speed_squared():
    slow = stimuli.self_motion(12.0, 20.0, seed=1).samples
    fast = stimuli.self_motion(24.0, 20.0, seed=1).samples
    assert peak_hz(slow, 1000.0) == pytest.approx(7.8, abs=0.5)
    assert fast.std() / slow.std() == pytest.approx(4.0, rel=0.15)
    assert stimuli.self_motion(0.0, 5.0).samples.std() == 0.0


def test_robot_scene_labels_contacts_and_goes_quiet_after_stopping():
    scene = stimuli.RobotScene(contacts=[stimuli.Contact(2.0, 25.0, "brass")], duration_s=5.0)
    rec = scene.generate(seed=3)
    assert rec.samples.shape == (5000, 2) and rec.units == "counts"
    assert rec.samples.min() >= 0 and rec.samples.max() <= 1023
    (c,) = rec.truth.contacts
    assert (c.t_s, c.distance_cm, c.material, c.duration_s) == (2.0, 25.0, "brass", 1.0)
    g = antenna.ADC().to_g(rec.samples)
    moving, stopped = g[1000:2000].std(0).max(), g[4000:].std(0).max()
    assert stopped < 0.2 * moving  # after the stop only sensor noise and quantisation remain
    again = scene.generate(seed=3)
    assert np.array_equal(rec.samples, again.samples)  # seeded


@pytest.mark.parametrize("change,field", [
    ({"speed_cm_s": -1.0}, "speed_cm_s"),
    ({"speed_cm_s": float("inf")}, "speed_cm_s"),
    ({"rate_hz": 10.0}, "rate_hz"),
    ({"terrain": "ice"}, "terrain"),
    ({"contacts": [(9.0, 20.0)]}, "contacts[0].t_s"),
    ({"contacts": [(1.0, 50.0)]}, "distance_cm"),
])
def test_bad_scenes_are_refused_naming_the_field(change, field):
    with pytest.raises(SpecError, match=field.replace("[", r"\[").replace("]", r"\]")):
        made = {k: [stimuli.Contact(*c) for c in v] if k == "contacts" else v
                for k, v in change.items()}
        stimuli.RobotScene(duration_s=5.0, **made).generate()


def test_recordings_refuse_empty_and_non_finite_samples():
    with pytest.raises(SpecError, match="samples"):
        Recording(np.zeros(0), 1000.0)
    with pytest.raises(SpecError, match="non-finite"):
        Recording(np.array([1.0, np.inf]), 1000.0)
    with pytest.raises(SpecError, match="rate_hz"):
        Recording(np.zeros(3), 0.0)
