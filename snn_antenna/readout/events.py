"""Contact-event processing as in the paper: window, amplitude spectrum, parametric features.

For each contact (Patanè et al. 2012, "Materials and methods"):

1. align the two axes to the main one (PCA) and convert to g;
2. onset where |x| first exceeds a threshold; end where the local maxima of |x| fall below
   10 % of the largest; keep the window between, subtract its mean;
3. amplitude spectrum |FFT| of the window on a fixed grid (``n_fft`` points, bins up to
   ``max_hz``; 1 Hz bins and 509 of them by default, as the paper's 509 components);
4. parametric features: split the window's own FFT at 55 Hz; in each part the peak
   frequency F (the most prominent bin, no interpolation, as the paper); the component
   reconstructed from the FFT around that peak only (a Gaussian weight of width
   ``band_fraction_low`` / ``band_fraction_high`` × F); its local extreme points (at least
   ``extreme_min_interval_ms`` apart, from the largest on while above ``extreme_min_fraction``
   of it), rectified and log-transformed; a linear fit gives amplitude A and decay time τ.

Precision of τ (the paper: CV of τ_low below 1 %). A Gaussian weight of width σ_f in
frequency is a Gaussian smoothing of width σ_t = 1 / (2π σ_f) in time, so the reconstructed
component is pulled down within a few σ_t of the window's abrupt start (the impact) and end
(the 10 % cut): extreme points there bias the slope by an amount that changes with each
window's length and phase. On synthetic two-mode decays with a known τ (no scatter in the
signal), that alone gave a CV of 2–3.5 % and biases up to −10 % (``tests/test_events.py``).
Two changes, both inside the paper's method, bring it to ~0.4 %: extreme points closer than
``edge_sigmas`` × σ_t to either end are left out of the fit, and the low mode's weight is
twice as wide (0.3 F: σ_t ≈ half a period; the high mode, ≥ 7× higher, stays far outside it),
while the high mode keeps 0.15 F (the rod's own mode can sit within 30 % of it). Each
extreme's height is refined by a parabola through it and its two neighbours (at 2 kHz a
15 Hz peak is sampled 130 times per period; at 400 Hz only five).

Events that cannot be processed are not dropped silently: ``process`` marks each with a reason
(``no_onset``, ``clipped``, ``no_decay_fit``) and counts them; NaN samples are refused.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..core import bounds
from ..core.errors import check
from ..core.signals import validate_samples
from ..core.parallel import parallel_map

PARAMETERS = ("F_low", "A_low", "tau_low", "F_high", "A_high", "tau_high")
SKIP_REASONS = ("no_onset", "clipped", "no_decay_fit")


class SkippedEvent(Exception):
    """An event that cannot be processed; ``reason`` is one of SKIP_REASONS."""

    def __init__(self, reason: str):
        self.reason = reason
        super().__init__(reason)


@dataclass
class EventProcessor:
    """The paper's event processing for signals sampled at ``rate_hz`` (g, main axis)."""
    rate_hz: float = 2000.0
    onset_threshold_g: float = 0.2
    end_fraction: float = 0.1
    n_fft: int | None = None           # default: one second of samples (1 Hz bins)
    max_hz: float = 508.0
    min_hz: float = 2.0                # below: drift, not ringing
    split_hz: float = 55.0
    # the high mode searched above split_ratio × the low peak (None: above split_hz): an
    # antenna whose modes' ranges overlap over its distances (a lab's rod, fitted from its
    # labels: evaluation.antenna_fit) has no one frequency between them
    split_ratio: float | None = None
    band_fraction_low: float = 0.3     # Gaussian weight around the peak: σ / its frequency
    band_fraction_high: float = 0.15
    edge_sigmas: float = 2.0           # extreme points this many σ_t from the window's ends
                                       # are left out of the decay fit (see the docstring)
    extreme_min_interval_ms: float = 3.0
    extreme_min_fraction: float = 0.1
    # a mode too short-lived for three extreme points (a low-Q ring: under a period above
    # the floor) fitted on its envelope instead (the analytic signal's magnitude, from its
    # largest on while above the floor); off: skipped as no_decay_fit
    envelope_fallback: bool = False

    def __post_init__(self):
        bounds.declared(self)
        check(np.isfinite(self.rate_hz) and self.rate_hz > 0, "rate_hz", self.rate_hz,
              "a sample rate > 0 Hz")
        check(np.isfinite(self.onset_threshold_g) and self.onset_threshold_g > 0,
              "onset_threshold_g", self.onset_threshold_g, "a threshold > 0 g")
        check(0 < self.end_fraction < 1, "end_fraction", self.end_fraction, "a fraction in (0, 1)")
        check(0 < self.min_hz < self.split_hz < self.max_hz <= self.rate_hz / 2, "split_hz",
              (self.min_hz, self.split_hz, self.max_hz),
              f"0 < min_hz < split_hz < max_hz <= {self.rate_hz / 2:g} Hz (Nyquist)")
        check(self.split_ratio is None or (np.isfinite(self.split_ratio)
                                           and self.split_ratio > 1), "split_ratio",
              self.split_ratio, "a ratio > 1 of the high mode's lowest to the low peak, or "
              "None")
        check(isinstance(self.envelope_fallback, bool), "envelope_fallback",
              self.envelope_fallback, "true or false")
        check(self.n_fft is None or (isinstance(self.n_fft, int) and self.n_fft >= 16),
              "n_fft", self.n_fft, "an integer number of FFT points >= 16, or None")
        for name in ("band_fraction_low", "band_fraction_high"):
            value = getattr(self, name)
            check(0 < value < 1, name, value, "a fraction in (0, 1)")
        check(np.isfinite(self.edge_sigmas) and 0 <= self.edge_sigmas <= 5, "edge_sigmas",
              self.edge_sigmas, "a number of smoothing widths in [0, 5]")
        bounds.number("extreme_min_interval_ms", self.extreme_min_interval_ms, 0.0, 1e6,
                      unit=" ms")
        bounds.number("extreme_min_fraction", self.extreme_min_fraction, 0.0, 1.0)

    @property
    def fft_points(self) -> int:
        return self.n_fft or int(round(self.rate_hz))

    @property
    def freq_hz(self) -> np.ndarray:
        """Centre frequencies of the spectrum's bins."""
        f = np.fft.rfftfreq(self.fft_points, 1.0 / self.rate_hz)
        return f[f <= self.max_hz + 1e-9]

    # -- steps ------------------------------------------------------------------------------
    def window(self, x: np.ndarray) -> tuple[int, int]:
        """(onset, end) sample indices of the contact in main-axis signal ``x`` (g)."""
        from scipy.signal import find_peaks

        ax = np.abs(x)
        above = np.flatnonzero(ax > self.onset_threshold_g)
        if len(above) == 0:
            raise SkippedEvent("no_onset")
        onset = int(above[0])
        peaks, _ = find_peaks(ax[onset:])
        if len(peaks) == 0:
            return onset, len(x)
        heights = ax[onset:][peaks]
        # The end is the last local maximum still above the fraction of the largest: the
        # second mode adds small maxima near the zero crossings of the first, so "the first
        # maximum below" would end most windows after a few cycles.
        loud = np.flatnonzero(heights >= self.end_fraction * heights.max())
        return onset, onset + int(peaks[loud[-1]]) + 1

    def spectrum(self, segment: np.ndarray) -> np.ndarray:
        """Amplitude spectrum (g·s) of a mean-removed segment on the fixed grid."""
        n = self.fft_points
        spec = np.abs(np.fft.rfft(segment[:n], n)) / self.rate_hz
        return spec[:len(self.freq_hz)]

    def parametric(self, segment: np.ndarray) -> dict[str, float]:
        """F, A, τ of the low (< split_hz) and high (>= split_hz, or >= split_ratio × the
        low peak) mode of a segment."""
        n = len(segment)
        window_amplitude = np.abs(np.fft.rfft(segment))
        window_f = np.fft.rfftfreq(n, 1.0 / self.rate_hz)
        # Reconstruction from the FFT with a smooth (Gaussian) weight around the peak and
        # zero padding: a brick-wall band rings in time and wraps around, which scattered the
        # decay fits several-fold more (measured while building this).
        padded_n = 4 * n
        coeffs = np.fft.rfft(segment, padded_n)
        freqs = np.fft.rfftfreq(padded_n, 1.0 / self.rate_hz)
        out = {}
        for name, lo, hi, fraction in (
                ("low", self.min_hz, self.split_hz, self.band_fraction_low),
                ("high", self.split_hz, self.max_hz, self.band_fraction_high)):
            if name == "high" and self.split_ratio is not None:
                lo = self.split_ratio * out["F_low"]
            f_peak = _peak_frequency(window_amplitude, window_f, lo, hi)
            sigma_hz = fraction * f_peak
            weight = np.exp(-0.5 * ((freqs - f_peak) / sigma_hz) ** 2)
            component = np.fft.irfft(coeffs * weight, padded_n)[:n]
            edge = int(self.edge_sigmas * self.rate_hz / (2 * np.pi * sigma_hz))
            amp, tau = self._decay_fit(component, f_peak, edge)
            out[f"F_{name}"], out[f"A_{name}"], out[f"tau_{name}"] = f_peak, amp, tau
        return out

    def _decay_fit(self, component: np.ndarray, f_hz: float, edge: int = 0
                   ) -> tuple[float, float]:
        from scipy.signal import find_peaks

        rect = np.abs(component)
        n = len(rect)
        # Extreme points are half a period apart; the minimum interval keeps noise wiggles out.
        spacing = max(self.extreme_min_interval_ms * 1e-3, 0.4 / f_hz) * self.rate_hz
        peaks, _ = find_peaks(rect, distance=max(1, int(spacing)))
        if len(peaks) == 0:
            raise SkippedEvent("no_decay_fit")
        # Away from the window's ends, where the band's smoothing pulls the component down;
        # a mode too short-lived for three such points keeps them all.
        inner = self._decay_run(rect, peaks[(peaks >= edge) & (peaks < n - edge)])
        peaks = inner if len(inner) >= 3 else self._decay_run(rect, peaks)
        if len(peaks) < 3:
            if self.envelope_fallback:
                return self._envelope_fit(component)
            raise SkippedEvent("no_decay_fit")
        # Each extreme's height and time from a parabola through it and its neighbours.
        before, at, after = rect[peaks - 1], rect[peaks], rect[np.minimum(peaks + 1, n - 1)]
        curvature = before - 2 * at + after
        shift = np.where(curvature < 0, 0.5 * (before - after) / np.where(
            curvature < 0, curvature, -1.0), 0.0)
        shift = np.clip(shift, -0.5, 0.5)
        height = at - 0.25 * (before - after) * shift
        t = (peaks + shift) / self.rate_hz
        slope, intercept = np.polyfit(t, np.log(height), 1)
        if not slope < 0:
            raise SkippedEvent("no_decay_fit")
        return float(np.exp(intercept)), float(-1.0 / slope)

    def _envelope_fit(self, component: np.ndarray) -> tuple[float, float]:
        """(A, τ) from a line through log of the component's envelope, from its largest on
        while above ``extreme_min_fraction`` of it (at least 3 samples)."""
        from scipy.signal import hilbert

        envelope = np.abs(hilbert(component))
        envelope = envelope[int(np.argmax(envelope)):]
        below = np.flatnonzero(envelope < self.extreme_min_fraction * envelope[0])
        envelope = envelope[:below[0]] if len(below) else envelope
        if len(envelope) < 3 or not envelope[0] > 0:
            raise SkippedEvent("no_decay_fit")
        slope, intercept = np.polyfit(np.arange(len(envelope)) / self.rate_hz,
                                      np.log(envelope), 1)
        if not slope < 0:
            raise SkippedEvent("no_decay_fit")
        return float(np.exp(intercept)), float(-1.0 / slope)

    def _decay_run(self, rect: np.ndarray, peaks: np.ndarray) -> np.ndarray:
        """The extreme points of the decay: from the largest on, and only the contiguous run
        above the minimum (later points are the other mode's leakage through the band; the
        impact's sharp start is broadband), not this decay."""
        if len(peaks) == 0:
            return peaks
        peaks = peaks[int(np.argmax(rect[peaks])):]
        below = np.flatnonzero(rect[peaks] < self.extreme_min_fraction * rect.max())
        return peaks[:below[0]] if len(below) else peaks

    # -- whole events -----------------------------------------------------------------------
    def features(self, x: np.ndarray) -> tuple[np.ndarray, dict[str, float]]:
        """Spectrum and parametric features of one main-axis signal (g)."""
        x = np.asarray(validate_samples(x, "x"), dtype=float)
        onset, end = self.window(x)
        segment = x[onset:end] - x[onset:end].mean()
        return self.spectrum(segment), self.parametric(segment)


def _peak_frequency(amplitude: np.ndarray, freqs: np.ndarray, lo: float, hi: float) -> float:
    """Frequency of the most prominent spectral peak in [lo, hi), at the FFT's own resolution.

    The most prominent local maximum, not the largest bin: near the split the skirt of the
    other mode (with its truncation ripples) can exceed a weak mode's peak. No interpolation
    between bins, as the paper's peak search: its bin width (1 / window length, 1.5–4 Hz
    here) is a large part of the spread of the low peak.
    """
    from scipy.signal import find_peaks

    peaks, props = find_peaks(amplitude, prominence=0)
    inside = (freqs[peaks] >= lo) & (freqs[peaks] < hi)
    if not inside.any():
        raise SkippedEvent("no_decay_fit")
    return float(freqs[peaks[inside][np.argmax(props["prominences"][inside])]])


def main_axis_g(counts: np.ndarray, adc_bits: int, full_scale_g: float) -> np.ndarray:
    """Two axes of ADC counts → the main axis in g (PCA over the event, mean removed).

    The axis's sign is arbitrary per event; neither the spectrum nor the rectified decay
    depends on it.
    """
    # lazy: scikit-learn loads with a chain, not with the command line
    from ..preprocess import CountsToG, PCAAlign

    g = CountsToG(adc_bits, full_scale_g).fit(counts).transform(counts)
    return PCAAlign().fit(g).transform(g)


def process_block(counts: np.ndarray, processor: EventProcessor, adc_bits: int,
                  full_scale_g: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Features of events ``counts`` (events, samples, 2): spectra, parameters, skip codes.

    Skip code 0 is a processed event, i + 1 the i-th entry of SKIP_REASONS; skipped events
    get zero features (never read: callers select valid events by the code).
    """
    validate_samples(counts.reshape(-1, counts.shape[-1]), "counts")
    n_bins = len(processor.freq_hz)
    spectra = np.zeros((len(counts), n_bins), dtype=np.float32)
    params = np.zeros((len(counts), len(PARAMETERS)))
    skip = np.zeros(len(counts), dtype=np.int8)
    rail = 2 ** adc_bits - 1
    for i, ev in enumerate(counts):
        try:
            if np.any(ev <= 0) or np.any(ev >= rail):
                raise SkippedEvent("clipped")
            spec, par = processor.features(main_axis_g(ev, adc_bits, full_scale_g))
        except SkippedEvent as exc:
            skip[i] = 1 + SKIP_REASONS.index(exc.reason)
            continue
        spectra[i] = spec
        params[i] = [par[p] for p in PARAMETERS]
    return spectra, params, skip


def process(ds: xr.Dataset, processor: EventProcessor, n_jobs: int = 1, block: int = 200,
            log=print) -> xr.Dataset:
    """Features of every event of a bench data set: ``spectrum`` (event, freq_hz),
    ``params`` (event, parameter) and ``skipped`` (event: '' or the reason)."""
    check(float(ds.attrs["rate_hz"]) == processor.rate_hz, "processor.rate_hz",
          processor.rate_hz, f"the data set's rate, {ds.attrs['rate_hz']} Hz")
    counts = ds["counts"].values
    n = len(counts)
    log(f"events: extracting windows, spectra and decay fits of {n} events "
        f"on {n_jobs} process(es)")
    parts = parallel_map(process_block,
                         [(counts[i:i + block], processor, int(ds.attrs["adc_bits"]),
                           float(ds.attrs["full_scale_g"])) for i in range(0, n, block)],
                         n_jobs, "features")
    spectra = np.concatenate([p[0] for p in parts])
    params = np.concatenate([p[1] for p in parts])
    codes = np.concatenate([p[2] for p in parts])
    reasons = np.array([""] + list(SKIP_REASONS))[codes]
    out = xr.Dataset(
        {"spectrum": (("event", "freq_hz"), spectra, {"units": "g s"}),
         "params": (("event", "parameter"), params),
         "skipped": ("event", reasons)},
        coords={"freq_hz": processor.freq_hz, "parameter": list(PARAMETERS),
                "event": ds["event"].values},   # the values only: a coordinate DataArray
                                                # would bring the labels along
        attrs=dict(ds.attrs))
    counts_by_reason = skip_counts(out)
    if sum(counts_by_reason.values()):
        log(f"events: skipped {counts_by_reason}")
    return out


def skip_counts(features: xr.Dataset) -> dict[str, int]:
    reasons = features["skipped"].values
    return {r: int(np.sum(reasons == r)) for r in SKIP_REASONS}


def extraction_cost(data: xr.Dataset, processor: EventProcessor, event_ids) -> dict:
    """Wall time per event of the feature extraction, measured now on events ``event_ids``
    of a bench data set (after a warm-up on two of them: imports, caches)."""
    ids = np.asarray(event_ids)
    args = (processor, int(data.attrs["adc_bits"]), float(data.attrs["full_scale_g"]))
    process_block(data["counts"].values[ids[:2]], *args)
    t0 = time.perf_counter()
    process_block(data["counts"].values[ids], *args)
    return {"features_us_per_event": 1e6 * (time.perf_counter() - t0) / len(ids)}
