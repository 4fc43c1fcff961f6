"""Bands tuned from data: resonators spent where the material lives.

The hand-set rod band (90-420 Hz, log-spaced, one wide band-pass) spends most of its neurons
between the struck rods' lines and codes the sign of a wide band in which the strongest
component (the antenna's own modes) takes the zero crossings. A tuned bank instead reads
*channels*: narrow band-passes (Butterworth, order 8) placed where the training contacts'
spectra separate the materials, each coded by its own square-wave coder and read by a few
resonators tuned across it. The filter picks the line, the resonators read how long and how
strongly it rings (counts, latency, span, time bins).

Placement (``place_channels``) uses only the spectra and labels of training contacts (a
calibration set, never the test split): per frequency bin the Fisher ratio of the log
amplitude between materials; the bins in its top ``1 - quantile`` (dilated by two bins) are
where the material lives; channel centres are spread evenly in log frequency over those bins,
and each channel reaches halfway (geometrically) to its neighbours. ``tuned_bands`` turns
the channels into ``spiking.Band`` entries, each at the coarsest step (``DT_STEPS_MS``) whose
largest k·dt stays within the k·dt the rod band was validated at.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import bounds, calibration
from ..core.errors import SpecError, check, is_number
from ..networks import neurons
from ..networks.resonators import MIN_SAMPLES_PER_CYCLE
from ..preprocess import make_coder
from .spiking import Band, align_events

# The steps a band may take (ms), each dividing the bench's 0.5 ms input interval (the
# speed/accuracy study's list, ``evaluation.bands.DT_STEPS_MS``). None above 0.1 ms: a
# 200-resonator graded bank allowed 5x and 10x the validated k·dt, its low channels at 0.25
# and 0.5 ms, read the whole bench set's material at 0.979x and 0.872x the FFT-MLP's (5
# splits), 1 and 12 points below the same bank at 1x.
DT_STEPS_MS = (0.1, 0.05, 0.025, 0.02, 0.01, 0.005, 0.0025, 0.002, 0.001, 0.0005, 0.00025)


@dataclass
class Tuning:
    """How a tuned bank is made (``[spiking.tuned]`` of the baseline study).

    ``n_resonators`` in total, at least ``per_channel`` of them reading each channel, in at
    most ``max_channels`` channels (the compiled event engine runs the channels that share a
    step and method as one NeuronGroup, each channel its own coded input; 24 and 48 channels
    scored alike on 20 repetitions);
    channels inside ``range_hz``; a bin is the
    material's when its Fisher ratio is in the top ``1 - quantile`` of the range; each
    channel's coder codes above ``threshold_g``. ``template``: the ``Band`` fields every
    channel shares (coder amplitude, b, Hz per unit k, method); ``max_k_dt``: the largest
    k·dt (model ms per step) a channel's step may reach (the rod band's validated setting:
    rk2 at 0.005 ms up to 420 Hz, within 4 % of the exact reference; ``core.calibration``).
    """
    n_resonators: int = 24
    per_channel: int = 2
    max_channels: int = 24
    range_hz: tuple = (80.0, 450.0)
    quantile: float = 0.8
    threshold_g: float = 0.003
    coder_amplitude: float = 0.2
    hz_per_k: float = calibration.value("rod_hz_per_k")
    method: str = "rk2"
    max_k_dt: float = calibration.value("rod_max_k_dt")
    spread: float = 0.03      # the channel's resonators span centre × (1 ± spread)
    coder: str = "square"     # each channel's coder (``preprocess.CODERS``) and its options
    coder_options: dict = field(default_factory=dict)
    # Graded analog gains (per g): a channel's resonators split evenly among them, each share
    # reading the channel coded at its gain, so the channel's loudness is a population code
    # (a weak line drives the high-gain share; a loud one saturates it and drives the low-gain
    # share in proportion); empty: every resonator reads the coder of ``coder_options``
    gains: tuple = ()

    def __post_init__(self):
        bounds.declared(self)
        bounds.choice("method", self.method, neurons.METHODS)
        check(isinstance(self.per_channel, int) and self.per_channel >= 1, "per_channel",
              self.per_channel, "an integer >= 1")
        check(isinstance(self.max_channels, int) and self.max_channels >= 1, "max_channels",
              self.max_channels, "an integer >= 1")
        check(isinstance(self.n_resonators, int) and self.n_resonators >= self.per_channel
              and self.n_resonators % self.per_channel == 0
              and self.n_resonators % self.n_channels == 0, "n_resonators",
              self.n_resonators, f"a multiple of per_channel ({self.per_channel}) that "
                                 f"{self.max_channels} channels share evenly when it fills more")
        lo, hi = bounds.pair("range_hz", self.range_hz, strict=True, unit=" in Hz")
        check(lo > 0, "range_hz", self.range_hz, "[low, high] in Hz, 0 < low < high")
        check(is_number(self.quantile) and 0 <= self.quantile < 1, "quantile",
              self.quantile, "a fraction in [0, 1)")
        check(is_number(self.max_k_dt) and self.max_k_dt > 0, "max_k_dt", self.max_k_dt,
              "model ms per step > 0")
        check(is_number(self.spread) and 0 <= self.spread < 0.5, "spread", self.spread,
              "a fraction in [0, 0.5)")
        bounds.amplitude("threshold_g", self.threshold_g, lo=0.0)
        bounds.number("coder_amplitude", self.coder_amplitude, 0.0, bounds.MAX_AMPLITUDE,
                      lo_open=True)
        bounds.number("hz_per_k", self.hz_per_k, 0.0, bounds.MAX_RATE_HZ, lo_open=True)
        check(isinstance(self.coder_options, dict), "coder_options", self.coder_options,
              "a table of the coder's own parameters, e.g. {levels = 6}")
        check(isinstance(self.gains, (list, tuple)) and all(is_number(g) for g in self.gains),
              "gains", self.gains, "a list of analog gains per g (empty: coder_options' gain)")
        if self.gains:
            check(self.coder == "analog", "gains", list(self.gains),
                  f"graded gains of the analog coder only (coder is {self.coder!r})")
            check(self.resonators_per_channel % len(self.gains) == 0, "per_channel",
                  self.per_channel, f"resonators per channel a multiple of the "
                                    f"{len(self.gains)} gains, which share them evenly")
            for g in self.gains:
                make_coder(self.coder, self.coder_amplitude, self.threshold_g, gain=float(g))
        try:
            make_coder(self.coder, self.coder_amplitude, self.threshold_g,
                       **self.coder_options)
        except SpecError as exc:   # named as the tuning table spells it
            field_name = {"amplitude": "coder_amplitude", "threshold": "threshold_g"}.get(
                exc.field, exc.field if exc.field == "coder" else f"coder_options.{exc.field}")
            raise SpecError(field_name, exc.value, exc.accepted) from None

    @property
    def n_channels(self) -> int:
        return max(1, min(self.n_resonators // max(self.per_channel, 1), self.max_channels))

    @property
    def resonators_per_channel(self) -> int:
        return self.n_resonators // self.n_channels


def log_spectra(counts: np.ndarray, rate_hz: float, adc_bits: int, full_scale_g: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies, log amplitude spectra (events, bins)) of events (events, samples, 2
    axes of ADC counts), each on its own principal axis, Hann-windowed: what the robot
    recorded, nothing else."""
    g = align_events(counts, adc_bits, full_scale_g)          # (samples, events)
    window = np.hanning(len(g))[:, None]
    amplitude = np.abs(np.fft.rfft(g * window, axis=0)).T
    return np.fft.rfftfreq(len(g), 1.0 / rate_hz), np.log(amplitude + 1e-9)


def fisher_ratio(log_spectra: np.ndarray, labels) -> np.ndarray:
    """Per bin: variance of the class means over the mean within-class variance."""
    labels = np.asarray(labels)
    classes = np.unique(labels)
    check(len(classes) >= 2, "labels", list(classes), "at least two materials to separate")
    means = np.array([log_spectra[labels == c].mean(axis=0) for c in classes])
    within = np.array([log_spectra[labels == c].var(axis=0) for c in classes]).mean(axis=0)
    return means.var(axis=0) / np.maximum(within, 1e-12)


def place_channels(freq_hz: np.ndarray, score: np.ndarray, tuning: Tuning
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres, low edges, high edges) in Hz of ``tuning.n_channels`` channels, evenly in
    log frequency over the bins of ``range_hz`` whose ``score`` is in its top share."""
    lo, hi = (float(x) for x in tuning.range_hz)
    inside = (freq_hz >= lo) & (freq_hz <= hi)
    f, s = freq_hz[inside], score[inside]
    check(len(f) >= 2, "range_hz", tuning.range_hz, "a range holding at least two bins")
    material = s >= np.quantile(s, tuning.quantile)
    material = np.convolve(material.astype(float), np.ones(5), "same") > 0
    density = np.cumsum(material / f)
    density /= density[-1]
    n = tuning.n_channels
    centres = np.interp((np.arange(n) + 0.5) / n, density, f)
    mids = np.sqrt(centres[1:] * centres[:-1])
    low = np.r_[centres[0] / 1.03, mids]
    high = np.r_[mids, centres[-1] * 1.03]
    # at least ±2 Hz: a Butterworth band-pass narrower than that rings longer than a line
    return centres, np.minimum(low, centres - 2.0), np.maximum(high, centres + 2.0)


def coarsest_dt_ms(top_hz: float, hz_per_k: float, max_k_dt: float) -> float:
    """The largest step of ``DT_STEPS_MS`` keeping k·dt of a ``top_hz`` resonator within
    ``max_k_dt``."""
    bounds.number("hz_per_k", hz_per_k, 0.0, bounds.MAX_RATE_HZ, lo_open=True)
    k = bounds.number("top_hz", top_hz, 0.0, bounds.MAX_RATE_HZ, lo_open=True) / hz_per_k
    fits = [dt for dt in DT_STEPS_MS if k * dt <= max_k_dt * (1 + 1e-9)]
    check(bool(fits), "max_k_dt", max_k_dt,
          f"a k·dt allowing {DT_STEPS_MS[-1]:g} ms at {top_hz:g} Hz")
    return fits[0]


def tuned_bands(centres, low, high, tuning: Tuning, rate_hz: float) -> dict[str, Band]:
    """One ``Band`` per channel, named ``ch00``, ``ch01``… in frequency order (with graded
    ``gains``, one per channel and gain: ``ch00g0``, ``ch00g1``…, sharing the channel's
    filters); a channel's resonators stop at the highest frequency the rate carries
    (``MIN_SAMPLES_PER_CYCLE`` samples per cycle), so a channel centred at the top of
    ``range_hz`` never asks for more."""
    bands = {}
    top = rate_hz / MIN_SAMPLES_PER_CYCLE
    codings = [("", dict(tuning.coder_options))] if not tuning.gains else [
        (f"g{i}", {**tuning.coder_options, "gain": float(g)})
        for i, g in enumerate(tuning.gains)]
    per = tuning.resonators_per_channel // len(codings)
    for j, (c, lo, hi) in enumerate(zip(centres, low, high)):
        c = min(float(c), top)
        span = (c * (1 - tuning.spread), min(c * (1 + tuning.spread), top)) if per > 1 \
            else (c, c)
        for suffix, options in codings:
            bands[f"ch{j:02d}{suffix}"] = Band(
                n_neurons=per, band_hz=(float(span[0]), float(span[1])),
                spacing="log", coder_amplitude=tuning.coder_amplitude,
                threshold_g=tuning.threshold_g, lowpass_hz=float(min(hi, 0.45 * rate_hz)),
                highpass_hz=float(lo), hz_per_k=tuning.hz_per_k, method=tuning.method,
                dt_ms=coarsest_dt_ms(span[1], tuning.hz_per_k, tuning.max_k_dt),
                filter_order=8, coder=tuning.coder, coder_options=options)
    return bands


def tune(counts: np.ndarray, labels, rate_hz: float, adc_bits: int, full_scale_g: float,
         tuning: Tuning) -> dict[str, Band]:
    """Channels from labelled training contacts (``counts``: events, samples, 2 axes)."""
    freq, spectra = log_spectra(counts, rate_hz, adc_bits, full_scale_g)
    return tuned_bands(*place_channels(freq, fisher_ratio(spectra, labels), tuning), tuning,
                       rate_hz)

