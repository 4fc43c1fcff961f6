"""Known answers for each physical ingredient of a bench contact (``antenna.Material``)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from snn_antenna.sources import antenna

RATE = 2000.0


def test_rod_mode_follows_euler_bernoulli_from_E_rho_and_geometry():
    """f₁ of a clamped–free solid rod from I and A directly (not via the code's d/4)."""
    d, length = antenna.ROD_DIAMETER_M, antenna.ROD_FREE_LENGTH_M
    inertia, area = np.pi * d ** 4 / 64, np.pi * d ** 2 / 4
    for name, m in antenna.MATERIALS.items():
        e, rho = m.youngs_gpa * 1e9, m.density_kg_m3
        expected = 1.8751 ** 2 / (2 * np.pi * length ** 2) * np.sqrt(e * inertia / (rho * area))
        assert m.rod_mode_hz() == pytest.approx(expected, rel=1e-4), name
        assert m.rod_mode_hz(2) / m.rod_mode_hz() == pytest.approx((4.6941 / 1.8751) ** 2,
                                                                 rel=1e-4)
    # a textbook number: 12 mm aluminium, 15 cm free, E 69 GPa, ρ 2700 → 377 Hz
    assert antenna.MATERIALS["aluminium"].rod_mode_hz() == pytest.approx(377.2, abs=0.5)
    # aluminium and steel share √(E/ρ) (the classic coincidence), so share their mode
    al, st = antenna.MATERIALS["aluminium"], antenna.MATERIALS["stainless_steel"]
    assert abs(al.rod_mode_hz() / st.rod_mode_hz() - 1) < 0.03


def test_the_rods_mode_is_in_the_recorded_ringing(monkeypatch):
    """What the rod adds to a contact is a line at its own mode, on every material."""
    for name, m in antenna.MATERIALS.items():
        # sampled finely, so the sampled peak is the peak (at 2 kHz a 334 Hz sine has six)
        with_rod = antenna.contact_ringing(20.0, name, 20_000.0, 20_000,
                                           np.random.default_rng(0), scatter=False)
        monkeypatch.setattr(antenna, "ROD_COUPLING", 0.0)
        without = antenna.contact_ringing(20.0, name, 20_000.0, 20_000,
                                          np.random.default_rng(0), scatter=False)
        monkeypatch.undo()
        added = with_rod - without
        f = np.fft.rfftfreq(len(added), 1 / 20_000.0)
        assert f[np.argmax(np.abs(np.fft.rfft(added)))] == pytest.approx(m.rod_mode_hz(),
                                                                        abs=1.0), name
        # amplitude: ROD_COUPLING's share of the 2 g impact, scaled by f₁/ρ and the pulse
        expected = 2.0 * m.rod_ringing() * antenna.pulse_excitation(
            m.rod_mode_hz(), m.contact_duration_s)
        expected *= np.exp(-1 / (4 * m.rod_mode_hz() * m.rod_tau_s()))   # first crest
        assert np.abs(added).max() == pytest.approx(expected, rel=0.02), name


def hertz_duration_by_integration(mass, radius, e_star, speed):
    """Contact time of m x'' = −(4/3) E* √R x^{3/2}, from x = 0 at speed v until x = 0."""
    k = 4 / 3 * e_star * np.sqrt(radius)

    def rhs(t, y):
        return [y[1], -k / mass * max(y[0], 0.0) ** 1.5]

    def leaves(t, y):
        return y[0]
    leaves.terminal, leaves.direction = True, -1
    sol = solve_ivp(rhs, (0, 1e-2), [1e-12, speed], events=leaves, rtol=1e-10, atol=1e-16,
                    max_step=1e-7)
    return float(sol.t_events[0][0])


def test_contact_duration_matches_hertz_by_integration():
    for name in ("aluminium", "wood", "pvc"):
        m = antenna.MATERIALS[name]
        radius = np.sqrt(antenna.TUBE_RADIUS_M * antenna.ROD_DIAMETER_M / 2)
        t = hertz_duration_by_integration(antenna.TUBE_EFFECTIVE_MASS_KG, radius,
                                          m.contact_modulus_gpa * 1e9,
                                          antenna.IMPACT_SPEED_M_S)
        assert m.contact_duration_s == pytest.approx(t, rel=0.01), name
    # softer contact, longer impact: wood (across the grain) > plastics > metals
    d = {n: antenna.MATERIALS[n].contact_duration_s for n in ("wood", "pvc", "aluminium")}
    assert d["wood"] > d["pvc"] > d["aluminium"]


def test_pulse_excitation_is_the_half_sine_spectrum():
    tc = 0.4e-3
    fine = 1e6
    t = np.arange(int(0.05 * fine)) / fine
    pulse = np.where(t < tc, np.sin(np.pi * t / tc), 0.0)
    spectrum = np.abs(np.fft.rfft(pulse))
    f = np.fft.rfftfreq(len(t), 1 / fine)
    for freq in (0.0, 460.0, 1250.0, 2500.0, 4000.0):
        i = int(round(freq / f[1]))
        assert antenna.pulse_excitation(f[i], tc) == pytest.approx(
            spectrum[i] / spectrum[0], abs=2e-3)


def test_contact_loss_adds_pi_f_eta_share_to_the_decay_rate():
    d = np.array([8.0, 20.0, 37.5])
    for name, m in antenna.MATERIALS.items():
        share = antenna.ANTENNA_CONTACT_STIFFNESS_N_M / (
            antenna.ANTENNA_CONTACT_STIFFNESS_N_M + 3 * m.youngs_gpa * 1e9
            * np.pi * antenna.ROD_DIAMETER_M ** 4 / 64 / antenna.ROD_FREE_LENGTH_M ** 3)
        tau_low, tau_high = antenna.decay_times_s(d, name)
        x = (d - 8.0) / 29.5
        own_low, own_high = 0.30 - 0.20 * x, 0.060 - 0.045 * x
        assert 1 / tau_low - 1 / own_low == pytest.approx(
            np.pi * antenna.low_mode_hz(d) * m.loss * share, rel=1e-6)
        assert 1 / tau_high - 1 / own_high == pytest.approx(
            np.pi * antenna.high_mode_hz(d) * m.loss * share, rel=1e-6)
    # soft lossy rods take most: acrylic < wood < aluminium in τ_low at every distance
    tl = {n: antenna.decay_times_s(d, n)[0] for n in ("acrylic_glass", "wood", "aluminium")}
    assert np.all(tl["acrylic_glass"] < tl["wood"]) and np.all(tl["wood"] < tl["aluminium"])


def test_rod_decay_from_loss_factor_and_the_resting_antenna():
    for _name, m in antenna.MATERIALS.items():
        share = m._antenna_share()
        eta = m.loss + antenna.TUBE_LOSS * share
        assert m.rod_tau_s() == pytest.approx(1 / (np.pi * m.rod_mode_hz() * eta), rel=1e-9)
    # the envelope of the recorded rod line decays with that τ (wood: 75 ms)
    m = antenna.MATERIALS["wood"]
    x = antenna.contact_ringing(20.0, "wood", RATE, 2000, np.random.default_rng(0),
                                scatter=False)
    from scipy.signal import butter, hilbert, sosfiltfilt
    band = sosfiltfilt(butter(4, [m.rod_mode_hz() - 25, m.rod_mode_hz() + 25], "bandpass",
                              fs=RATE, output="sos"), x)
    env = np.abs(hilbert(band))
    t = np.arange(len(x)) / RATE
    sel = (t > 0.05) & (t < 0.2)
    slope = np.polyfit(t[sel], np.log(env[sel]), 1)[0]
    assert -1 / slope == pytest.approx(m.rod_tau_s(), rel=0.1)
