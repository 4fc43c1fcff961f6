"""Event processing on signals with known answers, and bad data refused or counted."""
import numpy as np
import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.readout import events

RATE = 2000.0


def two_modes(f_low=12.0, tau_low=0.2, f_high=150.0, tau_high=0.03, lead_s=0.05,
              duration_s=1.0, noise_g=0.005, seed=0):
    t = np.arange(int(duration_s * RATE)) / RATE
    x = 2.0 * np.exp(-t / tau_low) * np.cos(2 * np.pi * f_low * t)
    x += 0.8 * np.exp(-t / tau_high) * np.cos(2 * np.pi * f_high * t + 1.0)
    x = np.r_[np.zeros(int(lead_s * RATE)), x]
    return x + np.random.default_rng(seed).normal(0, noise_g, len(x))


@pytest.mark.parametrize("f_low,tau_low,f_high,tau_high", [
    (12.0, 0.2, 150.0, 0.03), (9.0, 0.3, 70.0, 0.05), (30.0, 0.12, 300.0, 0.02)])
def test_two_mode_oscillation_recovered(f_low, tau_low, f_high, tau_high):
    """Frequencies within one bin of the window's FFT (the paper's resolution), τ within 10 %
    (low) and 15 % (high), onset exactly where the impact starts."""
    proc = events.EventProcessor(rate_hz=RATE)
    x = two_modes(f_low, tau_low, f_high, tau_high)
    onset, end = proc.window(x)
    assert onset == int(0.05 * RATE)
    bin_hz = RATE / (end - onset)
    spectrum, p = proc.features(x)
    assert abs(p["F_low"] - f_low) <= bin_hz
    assert abs(p["F_high"] - f_high) <= bin_hz
    assert p["tau_low"] == pytest.approx(tau_low, rel=0.10)
    assert p["tau_high"] == pytest.approx(tau_high, rel=0.15)
    assert p["A_low"] == pytest.approx(2.0, rel=0.25)
    assert spectrum.shape == (509,)
    assert proc.freq_hz[np.argmax(spectrum)] == pytest.approx(f_low, abs=1.0)


def test_window_ends_where_maxima_fall_below_ten_percent():
    proc = events.EventProcessor(rate_hz=RATE)
    tau = 0.15
    x = two_modes(20.0, tau, 200.0, 0.01, noise_g=0.0)
    onset, end = proc.window(x)
    # Single dominant mode: |x| falls to 10 % after τ ln 10, give or take a half period.
    assert (end - onset) / RATE == pytest.approx(tau * np.log(10), abs=1 / 20.0)


def counts_of(x_g, bits=16, full_scale=10.0):
    lsb = 2 * full_scale / 2 ** bits
    xy = np.column_stack([x_g * np.cos(0.5), x_g * np.sin(0.5) + 1.0])
    return np.clip(np.round(2 ** (bits - 1) + xy / lsb), 0, 2 ** bits - 1).astype(np.int64)


def test_bad_events_are_counted_by_reason_and_nan_refused():
    proc = events.EventProcessor(rate_hz=RATE)
    good = counts_of(two_modes())
    quiet = counts_of(np.random.default_rng(1).normal(0, 0.005, len(good) // 1))
    clipped = counts_of(two_modes() * 20)
    spectra, params, skip = events.process_block(np.stack([good, quiet, clipped]), proc, 16, 10.0)
    reasons = [""] + list(events.SKIP_REASONS)
    assert [reasons[c] for c in skip] == ["", "no_onset", "clipped"]
    assert params[0, 0] == pytest.approx(12.0, abs=3.0) and not params[1:].any()
    bad = np.stack([good]).astype(float)
    bad[0, 500, 0] = np.nan
    with pytest.raises(SpecError, match="non-finite"):
        events.process_block(bad, proc, 16, 10.0)


def test_processor_settings_are_checked():
    with pytest.raises(SpecError, match="split_hz"):
        events.EventProcessor(rate_hz=RATE, split_hz=600.0)
    with pytest.raises(SpecError, match="end_fraction"):
        events.EventProcessor(rate_hz=RATE, end_fraction=1.5)


def tau_low_spread(proc, f_low, tau_low, n=40):
    """Relative bias and CV of τ_low over contacts that differ only in phase and noise."""
    rng = np.random.default_rng(7)
    taus = []
    for _i in range(n):
        t = np.arange(int(RATE)) / RATE
        x = 2.0 * np.exp(-t / tau_low) * np.cos(2 * np.pi * f_low * t + rng.normal(0, 0.2))
        x += 0.9 * np.exp(-t / (tau_low / 5)) * np.cos(2 * np.pi * 7.5 * f_low * t
                                                 + rng.uniform(0, 6))
        x = np.r_[np.zeros(100), x] + rng.normal(0, 0.01, 100 + len(t))
        taus.append(proc.features(x)[1]["tau_low"])
    taus = np.array(taus)
    return taus.mean() / tau_low - 1, taus.std(ddof=1) / taus.mean()


@pytest.mark.parametrize("f_low,tau_low", [(8.0, 0.30), (20.0, 0.21), (45.0, 0.11)])
def test_tau_low_is_as_precise_as_the_papers(f_low, tau_low):
    """The paper's CV of τ_low (< 1 %) needs the fit itself well below 1 %: on decays with
    one known τ, the extraction's own CV < 0.75 % (0.3–0.4 % from 20 Hz up; the 8 Hz mode
    gives the fewest extreme points) and bias < 1 %."""
    bias, cv = tau_low_spread(events.EventProcessor(rate_hz=RATE), f_low, tau_low)
    assert abs(bias) < 0.01 and cv < 0.0075, (bias, cv)


def test_extreme_points_at_the_window_edges_spoil_the_fit():
    """Why the edges are left out: with every extreme point and the narrower band, the same
    decays scatter by more than the paper's whole CV of τ_low."""
    naive = events.EventProcessor(rate_hz=RATE, edge_sigmas=0.0, band_fraction_low=0.15)
    bias, cv = tau_low_spread(naive, 20.0, 0.21)
    assert cv > 0.01 or abs(bias) > 0.03, (bias, cv)
