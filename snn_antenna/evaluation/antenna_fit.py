"""A lab's own antenna, fitted from the labels of its calibration contacts.

A recorded data set comes from an antenna that is not this project's: its first mode may fall
with distance where the paper's rises, its modes' ranges may overlap, and its materials may
differ in nothing but decay. Nothing of the generator's antenna is assumed; what the read-outs
need is fitted on the contacts of the calibration repetitions (held out of every split), with
their labels, and reported as calibrated with that source:

- the frequency law: per labelled distance, the two most prominent peaks of the median
  (peak-scaled) spectrum of its calibration windows are its low and high mode; a line through
  log10 of the low one against distance is the law (``log10 F = slope d + intercept``), which
  the training-free decoders invert;
- the mode split: the low mode is searched below ``split_hz`` (the highest low mode × the
  square root of the smallest high / low ratio), the high mode above ``split_ratio`` × the
  low peak (that square root): the geometric middle between the modes at every distance,
  where one fixed frequency between them may not exist;
- the decay-fit window: among a few settings of the window's end, the edges and the floor of
  the extreme points and an envelope fit for a mode under three of them (``WINDOW_KEYS``),
  the one that fits a decay to the most calibration contacts, then with the least spread of
  τ_low within a material and distance;
- the bands of the hand-set bank (low: the low mode's range; high: the high mode's; rod:
  both) and the tuned bank's range: the modes' ranges widened by ``MARGIN``;
- the hand-set bands' thresholds (``fit_band_thresholds``): a typed threshold within a band's
  quiet level (its rms before the trigger) raised to ``BAND_NOISE_MULTIPLE`` × that level;
- the tuned bank's coder levels (``fit_coder``): its channels placed on the calibration
  contacts as the study places them, each contact's main axis through every channel's
  filters; the threshold is ``NOISE_MULTIPLE`` × the median channel's rms over the
  pre-trigger samples (what the coder sees before a contact: the sensor's noise, the ADC's
  steps, the filters' start, the tails of earlier contacts), and the analog gain (or the
  level coder's step) brings the ``PEAK_QUANTILE`` quantile of the channels' peaks after
  the trigger to the coder's amplitude (its top level), so the ringing's decay stays within
  the coder's range instead of holding it at its ceiling; a sign or level coder
  (``QUANTISED_CODERS``) takes ``BAND_NOISE_MULTIPLE`` × that rms as its threshold instead,
  when the peak quantile lies at least twice as high;
- the rate centroid's neighbourhood (``centroid_around``, from the calibration contacts'
  spikes): of ``CENTROID_AROUND``, the factor around each contact's most driven low-band
  resonator (spikes per cycle) whose centroid reads their distances best through the fitted
  law (resonators an overtone or the other mode drives otherwise pull the centroid off the
  low mode);
- the dominant resonator's bias (``dominant_bias``, from the calibration contacts' spikes):
  the most active resonator sits below the ringing (a resonator fires most for input
  somewhat above its own frequency), by a factor the law's intercept takes up, the median
  over the calibration contacts of log10 of their dominant resonator's frequency against
  the law's at their labelled distance;
- the spiking distance MLPs' L2 penalty (``distance_alpha``, from the calibration contacts'
  spikes): of ``DISTANCE_ALPHAS``, the one whose MLP reads the calibration contacts'
  distances best, each repetition read by the MLP trained on the others (a few dozen
  training contacts and a hundred or more inputs: the typed penalty leaves the fit to
  whichever inputs happen to match the few labels).

Only the calibration contacts' labels (and recordings) are fitted on; every scored contact is
read as a robot has it (its counts), and its labels serve the scoring alone.
"""
from __future__ import annotations

import copy
import itertools
import warnings
from dataclasses import asdict, dataclass, fields, replace

import numpy as np
from scipy import stats
from scipy.signal import find_peaks
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from ..core.errors import SpecError, check
from ..readout.band_tuning import Tuning, tune
from ..readout.baselines import DISTANCE_HIDDEN, Mlp, regressor_pipeline, sized_for
from ..readout.events import EventProcessor, SkippedEvent, main_axis_g
from ..readout.spiking import (CentroidDistance, SpikingBank, align_events, band_filtered,
                               dominant_of_counts)
from ..readout.spiking_decoders import TunedPlan

MARGIN = 1.25                 # a fitted band reaches this factor beyond the modes' range
# the decay-fit windows tried (``readout.events.EventProcessor``'s fields of the same names)
EDGE_SIGMAS = (0.0, 2.0)
EXTREME_MIN_FRACTIONS = (0.05, 0.1)
END_FRACTIONS = (0.1, 0.03)
ENVELOPE_FALLBACK = (False, True)
WINDOW_KEYS = ("edge_sigmas", "extreme_min_fraction", "envelope_fallback", "end_fraction")
# the tuned bank's coder levels (``fit_coder``): the threshold over the channels' quiet rms,
# and the quantile of the channels' peaks the coder's range reaches. The quiet rms is the
# sensor's noise and the filters' start: a channel's filters start at rest on the window's
# first sample, which lies off the window's mean (the ringing after the trigger sets it), and
# that step rings down through the samples before the trigger. On the lab rod's calibration
# contacts (``tests/lab_antenna.py``) the channels' median quiet rms is 5.6 mg, their noise
# alone (the same samples less their mean, run end to end through the filters) 1.4 mg: one
# quiet rms lies about four times above the noise, and the analog coder codes the ringing
# down to there. (A threshold of 3 or 5 times the noise alone, with the sign and level coders
# and the hand-set bands at 5 times it, read the material no better on the lab rod at 1 and
# 2 kHz, quick and full, and on the other rod's sessions of seeds 33 and 34, with the gain at
# the median peak: ``benchmarks/bench_lab_readouts.py``.)
NOISE_MULTIPLE = 1.0
# The analog gain (the level coder's top level) brings this quantile of the channels' peaks
# to the coder's amplitude: all but the loudest 5 % of a channel's contacts ring within the
# coder's range, so their amplitude and its decay reach the resonators rather than the
# coder's ceiling. On the lab rod's full profile the median peak (0.5) held the tuned bank's
# rate at 0.89 and its latency code at 0.80 (0.75: 0.91, 0.88; 0.9: 0.95, 0.88); 0.95 reads
# 0.95 and 0.92; the largest peak (1.0), one contact's, leaves the others in a small part of
# the range (rate 0.85). Quick at 1 and 2 kHz the rate and latency code meet at 0.9 and 0.95
# alike, not at 0.5 (latency) or 1.0 (rate).
PEAK_QUANTILE = 0.95
# a hand-set band's threshold within its quiet level (below its rms before the trigger) is
# raised to this multiple of that rms, above the rare noise peaks over a window; so is the
# threshold of a sign or level coder on the tuned channels (``QUANTISED_CODERS``): a coder
# that keeps only the signal's sign or a few levels codes the noise as fully as the ringing
# at the analog coder's threshold, so its firing ends on the noise's late peaks rather than
# with the ringing (on the lab rod's six lowest channels, the median contact's last sample
# beyond one quiet rms lies 160-190 ms after the trigger for rubber, at the window's end
# for aluminium; beyond 5 quiet rms, 28 mg, 60-140 ms and 280-450 ms)
BAND_NOISE_MULTIPLE = 5.0
QUANTISED_CODERS = ("square", "delta")
# the rate centroid's neighbourhoods tried (``readout.spiking.CentroidDistance.around``)
CENTROID_AROUND = (None, 3.0, 2.0, 1.5, 1.25)
# the spiking distance MLPs' L2 penalties tried (``readout.baselines.Mlp.alpha``)
DISTANCE_ALPHAS = (1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0)


@dataclass(frozen=True)
class FittedAntenna:
    """What the calibration contacts' labels gave (see the module's docstring)."""
    low_law: tuple[float, float]           # log10 F_low = slope * d + intercept (d in cm)
    high_law: tuple[float, float]
    r2_low: float
    distances_cm: tuple[float, ...]
    low_hz: tuple[float, ...]              # per distance: the low mode's peak
    high_hz: tuple[float, ...]
    split_hz: float
    split_ratio: float
    edge_sigmas: float
    extreme_min_fraction: float
    envelope_fallback: bool
    end_fraction: float
    fitted_fraction: float                 # calibration contacts with a decay fit
    low_identified_fraction: float         # whose low peak lies nearest its distance's
    n_contacts: int
    repetitions: tuple[int, ...]
    source: str
    coder_noise_g: float | None = None     # the tuned channels' median pre-trigger rms
    coder_peak_g: float | None = None      # the PEAK_QUANTILE of their peaks after it

    @property
    def low_range_hz(self) -> tuple[float, float]:
        return min(self.low_hz), max(self.low_hz)

    @property
    def high_range_hz(self) -> tuple[float, float]:
        return min(self.high_hz), max(self.high_hz)

    @property
    def range_cm(self) -> tuple[float, float]:
        return min(self.distances_cm), max(self.distances_cm)

    def distance_cm(self, low_hz) -> np.ndarray:
        """The law inverted: the distance whose low mode rings at ``low_hz``."""
        return (np.log10(np.asarray(low_hz, dtype=float)) - self.low_law[1]) / self.low_law[0]

    def silent_cm(self, silent: np.ndarray, distance_cm: np.ndarray) -> tuple[float, str]:
        """Where a contact that leaves the low band silent was struck, read from the
        calibration contacts (``silent``: which of them left it silent, ``distance_cm``: their
        labels): their mean distance, or the middle of the fitted range when none was silent;
        and the line saying so. A short decay at a low mode rings less than a resonator's
        period, so silence marks the far, slow end of a rod whose mode falls with distance;
        the middle of the range would put those contacts half the rod away."""
        silent = np.asarray(silent, dtype=bool)
        if not silent.any():
            middle = float(np.mean(self.range_cm))
            return middle, (f"fitted: a silent low band reads {middle:g} cm (the middle of "
                            f"the range: none of {len(silent)} calibration contacts silent)")
        at = float(np.mean(np.asarray(distance_cm, dtype=float)[silent]))
        return at, (f"fitted: a silent low band reads {at:g} cm (the mean distance of the "
                    f"{int(silent.sum())} of {len(silent)} calibration contacts it stayed "
                    "silent for)")

    def processor(self, like: EventProcessor) -> EventProcessor:
        """``like`` with the fitted mode split and decay-fit window."""
        return replace(like, split_hz=self.split_hz, split_ratio=self.split_ratio,
                       **{k: getattr(self, k) for k in WINDOW_KEYS})

    def applied(self, spec: dict) -> tuple[dict, list[str]]:
        """The study spec with the fitted values in place of the typed ones, and one line for
        the law and one per value replaced (what it was, what it is)."""
        spec = copy.deepcopy(spec)
        notes = [f"fitted: the low-mode law log10 F = {self.low_law[0]:.4f} d + "
                 f"{self.low_law[1]:.3f} (d in cm, r² {self.r2_low:.4f}), on the labels of "
                 f"{self.n_contacts} contacts of repetitions {list(self.repetitions)}"]
        ev = spec.setdefault("events", {})
        for key in ("split_hz", "split_ratio", *WINDOW_KEYS):
            value = getattr(self, key)
            value = value if isinstance(value, bool) else round(float(value), 6)
            notes.append(f"fitted: events.{key} {ev.get(key, '(default)')} → "
                         + (str(value).lower() if isinstance(value, bool) else f"{value:g}"))
            ev[key] = value
        lo_low, hi_low = self.low_range_hz
        lo_high, hi_high = self.high_range_hz
        spans = {"low": (lo_low, hi_low), "high": (lo_high, hi_high),
                 "rod": (min(lo_low, lo_high), max(hi_low, hi_high))}
        spiking = spec.get("spiking") if isinstance(spec.get("spiking"), dict) else {}
        bands = (spiking.get("bank") or {}).get("bands") or {}
        for name, band in bands.items():
            if name in spans and isinstance(band, dict):
                notes.append(_fit_band(band, f"spiking.bank.bands.{name}", *spans[name]))
        tuning = (spiking.get("tuned") or {}).get("tuning")
        if isinstance(tuning, dict):
            lo, hi = _widened(*spans["rod"])
            notes.append(f"fitted: spiking.tuned.tuning.range_hz {tuning.get('range_hz')} → "
                         f"[{lo:g}, {hi:g}] (both modes' range)")
            tuning["range_hz"] = [lo, hi]
        return spec, notes

    def description(self) -> dict:
        """What ``summary.json`` keeps (every fitted value with its source)."""
        out = asdict(self)
        out["law"] = "log10 F_low = slope * distance_cm + intercept"
        return out

    @classmethod
    def rows_of(cls, description: dict) -> list[tuple[str, str, str, str]]:
        """``rows`` of a fit kept in a summary (``description``)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: tuple(v) if isinstance(v, list) else v
                      for k, v in description.items() if k in names}).rows()

    def rows(self) -> list[tuple[str, str, str, str]]:
        """(quantity, fitted value, unit, how) of every fitted value, for a report."""
        lo_low, hi_low = self.low_range_hz
        lo_high, hi_high = self.high_range_hz
        return [
            ("low-mode law (slope per cm, intercept)",
             f"{self.low_law[0]:.4f}, {self.low_law[1]:.3f}", "",
             f"log10 F_low against distance at {len(self.distances_cm)} distances, "
             f"r² {self.r2_low:.4f}"),
            ("high-mode law (slope per cm, intercept)",
             f"{self.high_law[0]:.4f}, {self.high_law[1]:.3f}", "", "as the low mode's"),
            ("low mode over the distances", f"{lo_low:.0f}–{hi_low:.0f}", "Hz",
             "the most prominent lower peak of each distance's median spectrum"),
            ("high mode over the distances", f"{lo_high:.0f}–{hi_high:.0f}", "Hz",
             "the most prominent higher peak"),
            ("mode split: low mode below", f"{self.split_hz:.1f}", "Hz",
             "the highest low mode × √(smallest high / low ratio)"),
            ("mode split: high mode above, × the low peak", f"{self.split_ratio:.3f}", "",
             "√(smallest high / low ratio)"),
            ("decay-fit window: edges left out (σ_t)", f"{self.edge_sigmas:g}", "",
             f"of {list(EDGE_SIGMAS)}: the most contacts fitted, then the least spread of "
             "τ_low within a material and distance"),
            ("decay-fit window: floor of the extreme points", f"{self.extreme_min_fraction:g}",
             "of the largest", f"of {list(EXTREME_MIN_FRACTIONS)}, as above"),
            ("decay-fit window: a mode under 3 extreme points fitted on its envelope",
             "yes" if self.envelope_fallback else "no", "", "of no, yes, as above"),
            ("window's end: local maxima below this fraction of the largest",
             f"{self.end_fraction:g}", "", f"of {list(END_FRACTIONS)}, as above"),
            ("calibration contacts with a decay fit", f"{100 * self.fitted_fraction:.1f}", "%",
             "with the fitted split and window"),
            ("calibration contacts whose low peak is their distance's",
             f"{100 * self.low_identified_fraction:.1f}", "%",
             "nearest (in log frequency) to the low mode of their own distance")] + ([] if (
            self.coder_noise_g is None or self.coder_peak_g is None) else [
            ("tuned channels' rms before the trigger (median channel)",
             f"{1e3 * self.coder_noise_g:.2f}", "mg",
             f"the coder's threshold: {NOISE_MULTIPLE:g} × this"),
            (f"tuned channels' peak after the trigger (quantile {PEAK_QUANTILE:g})",
             f"{1e3 * self.coder_peak_g:.1f}", "mg",
             "reaches the coder's amplitude (analog gain; the level coder's top level)")])


def _widened(lo: float, hi: float) -> tuple[float, float]:
    return round(lo / MARGIN, 1), round(hi * MARGIN, 1)


def _fit_band(band: dict, label: str, lo: float, hi: float) -> str:
    """The band table over [lo, hi] widened, its filters' cut-offs moved with its edges in
    the same proportion as the typed band's; the line saying so."""
    new_lo, new_hi = _widened(lo, hi)
    old = band.get("band_hz")
    if isinstance(old, (list, tuple)) and len(old) == 2 and all(
            isinstance(v, (int, float)) and v > 0 for v in old):
        for cut, edge, new_edge in (("lowpass_hz", old[1], new_hi),
                                    ("highpass_hz", old[0], new_lo)):
            if isinstance(band.get(cut), (int, float)) and band[cut] > 0:
                band[cut] = round(band[cut] * new_edge / edge, 1)
    band["band_hz"] = [new_lo, new_hi]
    return f"fitted: {label}.band_hz {old} → [{new_lo:g}, {new_hi:g}] Hz"


def fit(data, calibration: np.ndarray, processor: EventProcessor, source: str
        ) -> FittedAntenna:
    """The antenna's law, mode split and decay-fit window from the contacts of ``data`` (a
    bench data set) selected by the mask ``calibration``, read with ``processor``'s window
    (``source``: where they came from, for the report)."""
    data = data.isel(event=np.flatnonzero(calibration))
    bits, full_scale = int(data.attrs["adc_bits"]), float(data.attrs["full_scale_g"])
    distance = data["distance_cm"].values.astype(float)
    material = data["material"].values.astype(str)
    reps = tuple(sorted(set(int(r) for r in data["repetition"].values)))
    where = f"the calibration contacts (repetitions {list(reps)} of {source})"
    signals, segments, kept = [], [], []
    for i, counts in enumerate(data["counts"].values):
        if np.any(counts <= 0) or np.any(counts >= 2 ** bits - 1):
            continue                       # clipped: its spectrum is the clip's
        x = main_axis_g(counts, bits, full_scale)
        try:
            onset, end = processor.window(x)
        except SkippedEvent:
            continue
        signals.append(x)
        segments.append(x[onset:end] - x[onset:end].mean())
        kept.append(i)
    kept = np.asarray(kept, dtype=int)
    sites = sorted(set(distance[kept]))
    if len(sites) < 2:
        raise SpecError("data", source, f"calibration contacts at two distances or more, "
                                        f"each with an onset ({where} hold {len(sites)})")
    freqs = processor.freq_hz
    spectra = np.asarray([processor.spectrum(s) for s in segments])
    spectra /= np.maximum(spectra.max(axis=1, keepdims=True), 1e-30)
    low, high = [], []
    for d in sites:
        median = np.median(spectra[distance[kept] == d], axis=0)
        peaks, props = find_peaks(median, prominence=0.05)
        peaks, prom = peaks[freqs[peaks] >= processor.min_hz], props["prominences"][
            freqs[peaks] >= processor.min_hz]
        if len(peaks) < 2:
            raise SpecError("data", source, f"contacts ringing in two modes at every distance "
                                            f"({where}: {len(peaks)} peak at {d:g} cm)")
        two = sorted(freqs[peaks[np.argsort(prom)[-2:]]])
        low.append(float(two[0]))
        high.append(float(two[1]))
    low, high, d = np.asarray(low), np.asarray(high), np.asarray(sites)
    low_fit, high_fit = stats.linregress(d, np.log10(low)), stats.linregress(d, np.log10(high))
    if not (np.isfinite(low_fit.slope) and low_fit.slope != 0 and np.all(high > low)):
        raise SpecError("data", source, f"contacts whose low mode moves with distance, below "
                                        f"their high mode ({where}: low modes {low.tolist()} "
                                        f"Hz, high {high.tolist()} Hz at {d.tolist()} cm)")
    ratio = float(np.sqrt(np.min(high / low)))
    split_hz = min(float(low.max()) * ratio, 0.99 * processor.max_hz)
    base = replace(processor, split_hz=split_hz, split_ratio=ratio)
    window, fitted, identified = _decay_window(base, signals, distance[kept], material[kept],
                                               d, low, len(data["event"]))
    return FittedAntenna(
        low_law=(float(low_fit.slope), float(low_fit.intercept)),
        high_law=(float(high_fit.slope), float(high_fit.intercept)),
        r2_low=float(low_fit.rvalue ** 2), distances_cm=tuple(map(float, d)),
        low_hz=tuple(map(float, low)), high_hz=tuple(map(float, high)), split_hz=split_hz,
        split_ratio=ratio, **dict(zip(WINDOW_KEYS, window)), fitted_fraction=fitted,
        low_identified_fraction=identified,
        n_contacts=int(data.sizes["event"]), repetitions=reps, source=where)


def _decay_window(base: EventProcessor, signals, distance, material, sites, low_hz,
                  n_contacts: int) -> tuple[tuple, float, float]:
    """The values of ``WINDOW_KEYS`` that fit a decay to the most calibration
    segments, then with the least median spread (CV) of τ_low within a material and distance;
    with the fraction fitted and the fraction whose low peak is their own distance's."""
    best = None
    for window in itertools.product(EDGE_SIGMAS, EXTREME_MIN_FRACTIONS, ENVELOPE_FALLBACK,
                                    END_FRACTIONS):
        p = replace(base, **dict(zip(WINDOW_KEYS, window)))
        tau, f_low = np.full(len(signals), np.nan), np.full(len(signals), np.nan)
        for i, x in enumerate(signals):
            try:
                onset, end = p.window(x)
                par = p.parametric(x[onset:end] - x[onset:end].mean())
            except SkippedEvent:
                continue
            tau[i], f_low[i] = par["tau_low"], par["F_low"]
        ok = np.isfinite(tau)
        cvs = [np.std(tau[g], ddof=1) / np.mean(tau[g])
               for g in (ok & (material == m) & (distance == d)
                         for m in set(material) for d in set(distance)) if g.sum() >= 2]
        score = (int(ok.sum()), -float(np.median(cvs)) if cvs else 0.0)
        if best is None or score > best[0]:
            nearest = sites[np.argmin(np.abs(np.log10(f_low[ok])[:, None]
                                             - np.log10(low_hz)[None, :]), axis=1)]
            best = (score, window, float(np.mean(nearest == distance[ok]))
                    if ok.any() else 0.0)
    (n_fitted, _), window, identified = best
    return window, n_fitted / n_contacts, identified


def fit_coder(antenna: FittedAntenna, data, calibration: np.ndarray, spec: dict,
              at_rate: dict | None = None) -> tuple[FittedAntenna, dict, list[str]]:
    """The tuned bank's coder levels from the contacts of ``data`` selected by
    ``calibration`` (see the module's docstring): ``antenna`` with the channels' quiet rms and
    peak quantile, ``spec`` (already fitted by ``FittedAntenna.applied``) with the threshold,
    analog gain and level step of ``[spiking.tuned]`` and of every coder compared in their
    place, and one line per value replaced. The channels are placed as ``at_rate`` (``spec``
    fitted to the data's rate; None: ``spec``) places them. A spec without a tuned bank comes
    back as is."""
    spiking = spec.get("spiking") if isinstance(spec.get("spiking"), dict) else {}
    if not isinstance(spiking.get("tuned"), dict) or not spiking["tuned"]:
        return antenna, spec, []
    spec = copy.deepcopy(spec)
    tuned = spec["spiking"]["tuned"]
    plan = TunedPlan(**(at_rate or spec)["spiking"]["tuned"])
    rate, bits = float(data.attrs["rate_hz"]), int(data.attrs["adc_bits"])
    full_scale = float(data.attrs["full_scale_g"])
    data = data.isel(event=np.flatnonzero(calibration))
    materials = data["material"].values.astype(str)
    if len(set(materials)) < 2:     # no channels to place: the split checks refuse such sets
        return antenna, spec, []
    counts = data["counts"].values[:, :int(round(plan.duration_s * rate))]
    bands = tune(counts, materials, rate, bits, full_scale, plan.base)
    quiet, peaks = channel_levels(counts, bands, rate, bits, full_scale,
                                  int(round(float(data.attrs["pre_trigger_s"]) * rate)))
    noise, peak = float(np.median(quiet)), float(np.quantile(peaks, PEAK_QUANTILE))
    threshold = NOISE_MULTIPLE * noise
    where = antenna.source
    if not peak > 2 * threshold:
        raise SpecError("data", where, f"calibration contacts whose tuned channels ring above "
                                       f"their quiet level (the channels' peak quantile "
                                       f"{PEAK_QUANTILE:g} is {1e3 * peak:.2f} mg, their "
                                       f"threshold {1e3 * threshold:.2f} mg)")
    why = {"threshold_g": f"{NOISE_MULTIPLE:g} × the tuned channels' median rms before the "
                          f"trigger, {1e3 * noise:.2f} mg, on {where}",
           "gain": f"the channels' peak quantile {PEAK_QUANTILE:g} after the trigger, "
                   f"{1e3 * peak:.1f} mg, reaches the coder's amplitude, on {where}",
           "step_g": f"the channels' peak quantile {PEAK_QUANTILE:g} after the trigger, "
                     f"{1e3 * peak:.1f} mg, reaches the top level, on {where}",
           "quantised": f"{BAND_NOISE_MULTIPLE:g} × the tuned channels' median rms before the "
                        f"trigger, {1e3 * noise:.2f} mg, as a hand-set band's square wave: a "
                        f"sign or level coder at that rms codes the channel's noise after the "
                        f"ringing, on {where}"}
    notes = []

    def fitted(table: dict, label: str, inherited: Tuning):
        coder = table.get("coder", inherited.coder)
        amplitude = float(table.get("coder_amplitude", inherited.coder_amplitude))
        level, reason = threshold, why["threshold_g"]
        # a coder's range from its threshold to the channels' peak at least a factor of 2
        # wide, as ``fit_coder`` asks of the analog coder's; narrower: the analog coder's
        # threshold
        quantised = coder in QUANTISED_CODERS and peak > 2 * BAND_NOISE_MULTIPLE * noise
        if quantised:
            level, reason = BAND_NOISE_MULTIPLE * noise, why["quantised"]
        if "threshold_g" in table or table is tuned["tuning"] or quantised:
            notes.append(f"fitted: {label}.threshold_g {table.get('threshold_g', '(default)')}"
                         f" → {level:.6g} ({reason})")
            table["threshold_g"] = round(level, 6)
        options = table.get("coder_options")
        if not isinstance(options, dict):
            return
        key, value = None, None
        if coder == "analog":
            key, value = "gain", amplitude / (peak - level)
        elif coder == "delta":
            levels = int(options.get("levels", 4))
            ratio = float(options.get("ratio", 2.0))
            top = (levels - 1 if ratio == 1.0 else (ratio ** (levels - 1) - 1) / (ratio - 1))
            if top > 0:
                key, value = "step_g", (peak - level) / top
        if key:
            notes.append(f"fitted: {label}.coder_options.{key} {options.get(key, '(default)')}"
                         f" → {value:.6g} ({why[key]})")
            options[key] = round(value, 6)

    tuned.setdefault("tuning", {})
    fitted(tuned["tuning"], "spiking.tuned.tuning", plan.base)
    for label, table in (tuned.get("coders") or {}).items():
        if isinstance(table, dict):
            fitted(table, f"spiking.tuned.coders.{label}", plan.base)
    TunedPlan(**tuned)              # the fitted levels within the coders' own bounds
    return replace(antenna, coder_noise_g=noise, coder_peak_g=peak), spec, notes


def fit_band_thresholds(data, calibration: np.ndarray, spec: dict, bank: SpikingBank,
                        source: str) -> tuple[dict, list[str]]:
    """``spec`` with the threshold of each hand-set band (``[spiking.bank.bands.NAME]``, as
    ``bank`` holds them at the data's rate) whose typed threshold lies within the band's quiet
    level (below its rms before the trigger on the contacts of ``data`` selected by
    ``calibration``) raised to ``BAND_NOISE_MULTIPLE`` × that rms; and one line per value
    replaced. The square-wave coder codes every sample beyond its threshold, so a threshold
    within the quiet level keeps it coding noise after the ringing has gone, and the firing
    spans carry no decay; a typed threshold above the quiet level stays as typed."""
    rate, bits = float(data.attrs["rate_hz"]), int(data.attrs["adc_bits"])
    full_scale = float(data.attrs["full_scale_g"])
    data = data.isel(event=np.flatnonzero(calibration))
    counts = data["counts"].values[:, :int(round(bank.duration_s * rate))]
    quiet, _ = channel_levels(counts, bank.bands, rate, bits, full_scale,
                              int(round(float(data.attrs["pre_trigger_s"]) * rate)))
    spec = copy.deepcopy(spec)
    notes = []
    for (name, band), rms in zip(bank.bands.items(), quiet):
        table = spec["spiking"]["bank"]["bands"].get(name)
        floor = BAND_NOISE_MULTIPLE * rms
        if isinstance(table, dict) and band.threshold_g < rms:
            notes.append(f"fitted: spiking.bank.bands.{name}.threshold_g {band.threshold_g:g} → "
                         f"{floor:.6g} ({BAND_NOISE_MULTIPLE:g} × the band's rms before the "
                         f"trigger, {1e3 * rms:.2f} mg, which the typed one lies within, on "
                         f"{source})")
            table["threshold_g"] = round(floor, 6)
    return spec, notes


def channel_levels(counts: np.ndarray, bands: dict, rate_hz: float, adc_bits: int,
                   full_scale_g: float, pre_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """(each band's rms over the first ``pre_samples`` samples, every contact's and band's
    largest |value| after them) of the contacts ``counts`` (events, samples, 2 axes) through
    each band's filters, as the bank filters them before its coder (``SpikingBank.code``)."""
    check(0 < pre_samples < counts.shape[1], "data.pre_trigger_s", pre_samples,
          "samples before the trigger, fewer than the window's")
    main = align_events(counts, adc_bits, full_scale_g)       # (samples, events)
    quiet, peaks = [], []
    for filtered in band_filtered(bands, main, rate_hz, adc_bits, full_scale_g):
        quiet.append(float(np.sqrt(np.mean(filtered[:pre_samples] ** 2))))
        peaks.append(np.abs(filtered[pre_samples:]).max(axis=0))
    return np.asarray(quiet), np.concatenate(peaks)


def centroid_around(counts: np.ndarray, neuron_hz, distance_cm, law: tuple
                    ) -> tuple[float | None, str]:
    """(the factor of ``CENTROID_AROUND`` whose rate centroid reads the distances
    ``distance_cm`` of the calibration contacts with the least rmse from their low band's
    spike ``counts`` (contacts × resonators tuned to ``neuron_hz``) through ``law``
    (``readout.spiking.DominantNeuronDistance``), the wider on a tie; the line saying so)."""
    distance_cm = np.asarray(distance_cm, dtype=float)
    rmse = {}
    for around in CENTROID_AROUND:
        reader = CentroidDistance(neuron_hz, law, around).fit(counts)
        rmse[around] = float(np.sqrt(np.mean((reader.predict(counts) - distance_cm) ** 2)))
    best = min(CENTROID_AROUND, key=lambda a: rmse[a])       # min keeps the first on a tie
    tried = ", ".join(f"{'all' if a is None else f'×{a:g}'} {10 * r:.1f} mm"
                      for a, r in rmse.items())
    return best, ("fitted: the rate centroid over the low-band resonators "
                  + ("all" if best is None else f"within ×{best:g} of the most driven one")
                  + f" (the least rmse on the {len(distance_cm)} calibration contacts: "
                  + tried + ")")


def dominant_bias(counts: np.ndarray, neuron_hz, distance_cm, law: tuple
                  ) -> tuple[tuple, str]:
    """(``law`` with its intercept moved by the dominant resonator's bias, the line saying
    so): the median over the calibration contacts that drive the low band (``counts``:
    contacts × resonators tuned to ``neuron_hz``) of log10 of their dominant resonator's
    frequency (``readout.spiking.dominant_of_counts``) less the law's log10 F at their
    labelled distance ``distance_cm``; ``law`` is (slope, intercept, silent distance) as
    ``readout.spiking.DominantNeuronDistance`` takes it. No driven contact: ``law`` as is."""
    hz = dominant_of_counts(counts, neuron_hz)
    driven = hz > 0
    slope, intercept, silent_cm = law
    if not driven.any():
        return law, ("fitted: the dominant resonator read through the law as it is (none of "
                     f"the {len(hz)} calibration contacts drove the low band)")
    distance_cm = np.asarray(distance_cm, dtype=float)[driven]
    bias = float(np.median(np.log10(hz[driven]) - (slope * distance_cm + intercept)))
    return (slope, intercept + bias, silent_cm), (
        f"fitted: the dominant resonator's bias, its frequency × {10 ** bias:.3f} of the law's "
        f"at the labelled distance (the median over the {int(driven.sum())} calibration "
        "contacts that drove the low band), taken into the law it reads through")


def distance_alpha(X: np.ndarray, distance_cm, repetition, mlp: Mlp, hidden=DISTANCE_HIDDEN,
                   label: str = "the spiking distance MLP") -> tuple[float, str]:
    """(the L2 penalty of ``DISTANCE_ALPHAS`` whose MLP (``mlp`` with that ``alpha``, layers
    ``hidden``, as ``readout.baselines.regressor_pipeline`` builds it for this many contacts)
    reads the calibration contacts' distances ``distance_cm`` from their inputs ``X`` with
    the least rmse, each repetition of ``repetition`` read by the MLP trained on the others,
    the smaller on a tie; the line saying so, naming ``label``). Fewer than two repetitions:
    ``mlp``'s own penalty."""
    X = np.asarray(X, dtype=float)
    distance_cm = np.asarray(distance_cm, dtype=float)
    repetition = np.asarray(repetition)
    folds = sorted(set(repetition.tolist()))
    if len(folds) < 2:
        return mlp.alpha, (f"fitted: {label}'s L2 penalty as typed ({mlp.alpha:g}: the "
                           "calibration contacts hold one repetition, none to read out)")
    rmse = {}
    for alpha in DISTANCE_ALPHAS:
        errors = []
        for r in folds:
            train, test = repetition != r, repetition == r
            model = sized_for(regressor_pipeline(replace(mlp, alpha=alpha), hidden, 0),
                              int(train.sum()))
            # one BLAS thread: a few dozen rows gain nothing from more, and lose to their
            # start-up on a busy machine
            with warnings.catch_warnings(), threadpool_limits(1):
                warnings.simplefilter("ignore", ConvergenceWarning)
                model.fit(X[train], distance_cm[train])
            errors.append((model.predict(X[test]) - distance_cm[test]) ** 2)
        rmse[alpha] = float(np.sqrt(np.mean(np.concatenate(errors))))
    best = min(DISTANCE_ALPHAS, key=lambda a: rmse[a])       # min keeps the first on a tie
    tried = ", ".join(f"{a:g} {10 * r:.1f} mm" for a, r in rmse.items())
    return best, (f"fitted: {label}'s L2 penalty {best:g} (the least rmse on the "
                  f"{len(distance_cm)} calibration contacts, each of their {len(folds)} "
                  f"repetitions read by the MLP trained on the others: {tried})")


__all__ = ["FittedAntenna", "fit", "fit_coder", "fit_band_thresholds", "centroid_around",
           "channel_levels", "dominant_bias", "distance_alpha", "BAND_NOISE_MULTIPLE",
           "CENTROID_AROUND", "DISTANCE_ALPHAS", "MARGIN", "NOISE_MULTIPLE", "PEAK_QUANTILE",
           "QUANTISED_CODERS"]
