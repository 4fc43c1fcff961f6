"""Where a spiking bank's input chain loses the material: one read-out at every step.

A tuned bank reads narrow channels (``readout.band_tuning``): each event's two axes go to g,
onto their principal axis (PCA 2→1), through the channel's Butterworth band-pass, the centring
and the coder (``SpikingBank.code``). A classifier on what the signal carries *after* a step
bounds what any read-out downstream of it can reach; the drop from one step to the next is
what that step discards. So every step is read the same way (``channel_features``): per
channel of the bank and per time bin of ``bank.bin_edges_s``, the log mean power of the
channel's signal and the share of samples where it changes sign (how fast it oscillates).

Before the chain's own band-pass a signal has no channels yet: there each channel is cut out
by an ideal (zero-phase, brick-wall FFT) band-pass over the bank's window, the best a filter
of that band could keep; from the band-pass on, the chain's own channel signals are read.

Steps (``STAGES``), each on the first ``bank.duration_s`` of every event (what the bank sees):

- ``spectrum_2_axes`` / ``spectrum_main_axis``: the window's log amplitude spectrum (Hann,
  up to ``max_hz``) of both axes, or of the principal axis: no channels, no time bins.
- ``ideal_2_axes`` / ``ideal_main_axis``: the channels by ideal band-pass, both axes or the
  principal axis (what PCA 2→1 keeps, in the bank's channels and time bins).
- ``band_pass``: the chain's Butterworth band-pass of each channel (its leakage and ringing).
- ``centred``: after the chain's centring.
- ``coded``: after the coder (its threshold's dead zone and its saturation).
- ``coded_statistics``: the coded input read as ``readout.spiking.coded_features`` reads it
  (half-cycle onsets, mean |current|, changes): the baseline comparison's "ceiling" of a coder.
- ``centred_2_axes`` / ``coded_2_axes``: both axes, each through every channel's chain (a
  bank per axis), read like ``centred`` and ``coded``.
"""
from __future__ import annotations

import numpy as np

from ..core.errors import check
from ..report import labels
from ..readout.spiking import SpikingBank, align_events, coded_features
from ..sources.antenna import ADC

STAGES = ("spectrum_2_axes", "spectrum_main_axis", "ideal_2_axes", "ideal_main_axis",
          "band_pass", "centred", "coded", "coded_statistics", "centred_2_axes",
          "coded_2_axes")
STAGE_TEXT = labels.STAGE_TEXT    # each stage in words, shared with the results page
# A power floor (g², or the coded current's unit squared): the log of a silent channel
# stays finite and far below any signal the sensor's noise (10 mg) leaves.
POWER_FLOOR = 1e-12


def bin_cuts(bank: SpikingBank, rate_hz: float, n_samples: int) -> list[int]:
    """Sample indices where the bank's time bins start, and the window's end."""
    return [0, *(int(round(e * rate_hz)) for e in bank.bin_edges_s
                 if 0 < e * rate_hz < n_samples), n_samples]


def channel_features(signals: np.ndarray, cuts: list[int]) -> np.ndarray:
    """Per event (rows): for each channel and time bin, log mean power and the share of
    samples whose sign differs from the previous sample's. ``signals``: (samples, events,
    channels)."""
    x = np.asarray(signals, dtype=float)
    sign = np.sign(x)
    crossing = np.zeros_like(x)
    crossing[1:] = (sign[1:] != sign[:-1]) & (sign[1:] != 0)
    widths = np.diff(cuts)[:, None, None]
    power = np.add.reduceat(x * x, cuts[:-1], axis=0) / widths
    rate = np.add.reduceat(crossing, cuts[:-1], axis=0) / widths
    per_bin = np.stack([np.log(power + POWER_FLOOR), rate], axis=-1)  # bins, events, ch, 2
    return per_bin.transpose(1, 2, 0, 3).reshape(x.shape[1], -1)


def ideal_channels(x: np.ndarray, rate_hz: float, edges_hz: np.ndarray) -> np.ndarray:
    """(samples, events) → (samples, events, channels): each channel's band ``[lo, hi]`` of
    ``edges_hz`` (channels, 2) kept by a brick-wall mask on the window's FFT."""
    spectrum = np.fft.rfft(x, axis=0)
    freq = np.fft.rfftfreq(len(x), 1.0 / rate_hz)
    masks = (freq[:, None] >= edges_hz[:, 0]) & (freq[:, None] <= edges_hz[:, 1])
    return np.fft.irfft(spectrum[:, :, None] * masks[:, None, :], n=len(x), axis=0)


def window_spectrum(x: np.ndarray, rate_hz: float, max_hz: float) -> np.ndarray:
    """(samples, events) → (events, bins up to ``max_hz``): log amplitude, Hann window."""
    amplitude = np.abs(np.fft.rfft(x * np.hanning(len(x))[:, None], axis=0))
    freq = np.fft.rfftfreq(len(x), 1.0 / rate_hz)
    return np.log(amplitude[freq <= max_hz] + 1e-9).T


def chain_stages(bank: SpikingBank, x: np.ndarray, rate_hz: float, adc_bits: int,
                 full_scale_g: float) -> dict[str, np.ndarray]:
    """(samples, events) of one axis in g → each channel's signal after the chain's
    band-pass, centring (a chain without a high-pass is centred; ``make_chain``) and coder:
    name → (samples, events, channels). The chain's own stages (``Band.chain`` after its g
    conversion and alignment), run in order."""
    out: dict[str, list] = {"band_pass": [], "centred": [], "coded": []}
    for band in bank.bands.values():
        stages = dict(band.chain(rate_hz, adc_bits, full_scale_g).steps[2:])
        y = x
        for name in ("lowpass", "highpass"):
            if name in stages:
                y = stages[name].fit(y).transform(y)
        out["band_pass"].append(y)
        if "centre" in stages:
            y = stages["centre"].fit(y).transform(y)
        out["centred"].append(y)
        out["coded"].append(stages["coder"].fit(y).transform(y))
    return {k: np.stack(v, axis=2) for k, v in out.items()}


def stage_features(bank: SpikingBank, counts: np.ndarray, rate_hz: float, adc_bits: int,
                   full_scale_g: float, max_hz: float = 508.0,
                   stages=STAGES) -> dict[str, np.ndarray]:
    """Every stage's feature rows (``STAGES``) for events ``counts`` (events, samples, 2 axes
    of ADC counts), ``bank.batch_events`` events at a time."""
    unknown = sorted(set(stages) - set(STAGES))
    check(not unknown, "stages", unknown, f"names out of {list(STAGES)}")
    n_samples = min(counts.shape[1], int(round(bank.duration_s * rate_hz)))
    cuts = bin_cuts(bank, rate_hz, n_samples)
    edges = np.array([[b.highpass_hz or 0.0, b.lowpass_hz] for b in bank.bands.values()])
    rows: dict[str, list] = {s: [] for s in stages}
    adc = ADC(adc_bits, full_scale_g)
    for start in range(0, len(counts), bank.batch_events):
        chunk = counts[start:start + bank.batch_events, :n_samples]
        g = adc.to_g(np.asarray(chunk, dtype=float))                  # events, samples, 2
        axes = [(g[:, :, a] - g[:, :, a].mean(axis=1, keepdims=True)).T for a in (0, 1)]
        main = align_events(chunk, adc_bits, full_scale_g)            # samples, events
        made: dict[str, np.ndarray] = {}
        if "spectrum_2_axes" in stages:
            made["spectrum_2_axes"] = np.hstack([window_spectrum(a, rate_hz, max_hz)
                                                 for a in axes])
        if "spectrum_main_axis" in stages:
            made["spectrum_main_axis"] = window_spectrum(main, rate_hz, max_hz)
        if "ideal_2_axes" in stages:
            made["ideal_2_axes"] = np.hstack([channel_features(
                ideal_channels(a, rate_hz, edges), cuts) for a in axes])
        if "ideal_main_axis" in stages:
            made["ideal_main_axis"] = channel_features(ideal_channels(main, rate_hz, edges),
                                                       cuts)
        if {"band_pass", "centred", "coded"} & set(stages):
            chain = chain_stages(bank, main, rate_hz, adc_bits, full_scale_g)
            for name in ("band_pass", "centred", "coded"):
                if name in stages:
                    made[name] = channel_features(chain[name], cuts)
        if "coded_statistics" in stages:
            made["coded_statistics"] = coded_features(bank, chunk, rate_hz, adc_bits,
                                                      full_scale_g)
        if {"centred_2_axes", "coded_2_axes"} & set(stages):
            both = [chain_stages(bank, a, rate_hz, adc_bits, full_scale_g) for a in axes]
            for name in ("centred", "coded"):
                if f"{name}_2_axes" in stages:
                    made[f"{name}_2_axes"] = np.hstack([channel_features(c[name], cuts)
                                                        for c in both])
        for name in stages:
            rows[name].append(made[name])
    return {name: np.concatenate(r).astype(np.float32) for name, r in rows.items()}
