"""Spiking read-out of contact events: what a bank of resonators is and what it reads.

Each event goes through the real preprocessing chain (``preprocess.make_chain``: counts → g,
PCA alignment, low-pass, centring, square-wave coder; ``SpikingBank.code``) and drives a bank
of resonators (``networks.resonators.ResonatorArray`` sets their tuning). Running a bank over a
data set is the sweep engine's work (``engine.events``: a chunk of events × a band's neurons is ONE
NeuronGroup, compiled once per process in cpp_standalone and re-run with each chunk's coded
inputs), so Brian2 runs once per chunk and band, never once per event.

Two bands (``Band``):

- ``low``: the paper's array (its 7–30 Hz widened to the bench's 8–50 Hz low mode), input
  low-passed below the band's top; the dominant neuron's frequency (``contacts.dominant_hz``)
  gives the distance through the inverse low-mode law (the paper's Fig. 10E).
- ``high``: resonators over the high mode (55–500 Hz: k up to ~20, so dt ≤ 0.4 ms for
  ``euler``), input band-passed to 50–900 Hz. A resonator keeps firing while its mode rings
  above the coder's threshold, so how long each fires carries the decay time, which is where
  the material shows.

- ``rod`` (a physics-motivated third bank; ``stimuli/bench.toml`` and the baseline study):
  resonators over the struck rods' own bending modes (Euler–Bernoulli from each material's
  E, ρ and the 12 mm × 15 cm rod: 107–377 Hz, ``antenna.Material.rod_mode_hz``), input
  band-passed around them with a low threshold, because the rod's line is weak (a few % of
  the impact) but outlasts the antenna's own high mode (τ_high ≤ 60 ms; a metal rod rings for
  0.5–1.2 s, wood and plastics for 50–105 ms).

Features per event and neuron: spike count, first-spike latency, firing span (last − first
spike) and the counts in time bins (``SpikingBank.bin_edges_s``): how each channel's firing
decays, a spike-based spectrogram; after ~0.2 s the antenna's own high mode has died and what
still drives the high-frequency resonators is the rod. Each in ``SpikeFeatures`` with the
neurons' preferred frequencies.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.pipeline import Pipeline

from ..core import bounds
from ..core import calibration
from ..core.errors import SpecError, check, is_number
from ..networks import neurons
from ..networks.resonators import ResonatorArray
from ..preprocess import CODERS, make_chain, make_coder
from ..sources import antenna
from ..sources.antenna import ADC
from .contacts import centroid_hz, dominant_hz, preferred_hz
from ..networks.assembly import build, configure
from ..networks.control import MaterialUnit


@dataclass
class Band:
    """One resonator bank and the input chain that feeds it (keys of ``[spiking.bands.*]``)."""
    n_neurons: int = 24
    band_hz: tuple = (8.0, 55.0)
    spacing: str = "log"
    b: float = 0.26
    coder_amplitude: float = 0.15
    threshold_g: float = 0.05
    lowpass_hz: float = 60.0
    highpass_hz: float | None = None
    hz_per_k: float = neurons.DRIVEN_HZ_PER_K
    dt_ms: float | None = None   # this band's own time step (None: the bank's)
    method: str | None = None    # this band's own integration method (None: the bank's)
    # Order of the chain's Butterworth low- and high-pass: a narrow band-pass around weak
    # rod lines needs 8, or the strong antenna modes beside it leak through and take the
    # square-wave coder's zero crossings (order 4 passes ~4 % of a low mode at 40 Hz below a
    # 92 Hz high-pass, more than the rod line itself)
    filter_order: int = 4
    # The last stage of the band's chain (``preprocess.CODERS``: "square", "delta",
    # "analog"), coding above ``threshold_g`` up to ``coder_amplitude``; ``coder_options``:
    # the coder's own parameters (``preprocess.CODER_OPTIONS``, e.g. {levels = 6}).
    coder: str = "square"
    coder_options: dict = field(default_factory=dict)

    def __post_init__(self):
        bounds.declared(self)
        bounds.choice("spacing", self.spacing, ("log", "linear"))
        if self.method is not None:
            bounds.choice("method", self.method, neurons.METHODS)
        bounds.choice("coder", self.coder, tuple(CODERS))
        bounds.positive_integer("n_neurons", self.n_neurons)
        for name in ("coder_amplitude", "lowpass_hz", "hz_per_k"):
            bounds.number(name, getattr(self, name), 0.0, lo_open=True)
        bounds.number("threshold_g", self.threshold_g, 0.0, unit=" g")
        if self.highpass_hz is not None:
            bounds.number("highpass_hz", self.highpass_hz, 0.0, lo_open=True, unit=" Hz")
        if self.dt_ms is not None:
            bounds.dt_ms("dt_ms", self.dt_ms)
        bounds.integer("filter_order", self.filter_order, 1, 8)

    def check_coder(self) -> None:
        """The coder's name and parameters, refused before any work."""
        make_coder(self.coder, self.coder_amplitude, self.threshold_g, **self.coder_options)

    def array(self, dt_ms: float, method: str, target: str) -> ResonatorArray:
        """The band's resonators at its own dt and method, or else ``dt_ms`` and ``method``."""
        return ResonatorArray(self.n_neurons, tuple(self.band_hz), self.spacing, self.b,
                              dt_ms if self.dt_ms is None else self.dt_ms,
                              method if self.method is None else self.method, target,
                              self.hz_per_k)

    def chain(self, rate_hz: float, adc_bits: int, full_scale_g: float):
        return make_chain(rate_hz, adc_bits, full_scale_g, lowpass_hz=self.lowpass_hz,
                          lowpass_order=self.filter_order, coder_amplitude=self.coder_amplitude,
                          threshold=self.threshold_g, highpass_hz=self.highpass_hz,
                          coder=self.coder, **{f"coder_{k}": v
                                               for k, v in self.coder_options.items()})


LOW_BAND = Band()
# The high band (55-500 Hz: k up to ~20) integrates at its own step: at the bank's euler
# 0.1 ms (k·dt up to 2 model-ms) its rate map is 4.7 times the exact reference's. rk4 at
# 0.005 ms is the cheapest setting found within 5 % of the reference on bench events, and
# its Hz per unit k comes from a driven tuning sweep at an accurate step (the speed/accuracy
# study's "bands" section, ``evaluation.bands``, measures both). Its input is band-passed
# (50-900 Hz): the square-wave coder codes only the sign, so with the low mode still in the
# signal the high mode would show only near the low mode's zero crossings.
HIGH_BAND_HZ_PER_K = calibration.value("high_band_hz_per_k")
HIGH_BAND = Band(n_neurons=24, band_hz=(55.0, 500.0), lowpass_hz=900.0, highpass_hz=50.0,
                 threshold_g=0.02, hz_per_k=HIGH_BAND_HZ_PER_K, dt_ms=0.005, method="rk4")


@dataclass
class SpikeFeatures:
    """Per event × neuron: spike counts, first-spike latency (s) and firing span (s).

    ``neuron_hz`` holds each neuron's preferred frequency, ``band`` its band's name. A neuron
    that never fires has latency = the run's duration and span 0.
    """
    counts: np.ndarray
    latency_s: np.ndarray
    span_s: np.ndarray
    neuron_hz: np.ndarray
    band: np.ndarray
    duration_s: float
    wall_s: float = 0.0
    neuron_steps: float = 0.0
    binned_counts: np.ndarray | None = None  # (events, neurons, bins of bin_edges_s)

    def matrix(self) -> np.ndarray:
        """One row per event: counts, latencies and spans of every neuron (decoder input)."""
        return np.hstack([self.counts, self.latency_s, self.span_s]).astype(float)

    def select(self, bands) -> SpikeFeatures:
        keep = np.isin(self.band, list(bands))
        return SpikeFeatures(self.counts[:, keep], self.latency_s[:, keep], self.span_s[:, keep],
                             self.neuron_hz[keep], self.band[keep], self.duration_s,
                             self.wall_s, self.neuron_steps,
                             None if self.binned_counts is None
                             else self.binned_counts[:, keep])

    def dominant_hz(self, band: str = "low") -> np.ndarray:
        """Preferred frequency of each event's dominant neuron in ``band`` (0: silent), by
        ``contacts.dominant_hz``'s rule (ties go to the plateau's centre)."""
        sub = self.select([band])
        return dominant_of_counts(sub.counts, sub.neuron_hz)

    def to_dataset(self, event, bin_edges_s) -> xr.Dataset:
        """The features as a data set (event × neuron), as ``cached_features`` stores them."""
        return xr.Dataset(
            {"counts": (("event", "neuron"), self.counts.astype(np.int32)),
             "latency_s": (("event", "neuron"), self.latency_s),
             "span_s": (("event", "neuron"), self.span_s),
             "binned_counts": (("event", "neuron", "time_bin"),
                               self.binned_counts.astype(np.int32))},
            coords={"event": np.asarray(event), "neuron_hz": ("neuron", self.neuron_hz),
                    "band": ("neuron", self.band.astype(str)),
                    "bin_start_s": ("time_bin", [0.0, *bin_edges_s])},
            attrs={"simulation_wall_s": self.wall_s, "neuron_steps": self.neuron_steps})


def dominant_of_counts(counts, neuron_hz) -> np.ndarray:
    """Dominant neuron's preferred frequency per row of spike ``counts`` (events × neurons
    tuned to ``neuron_hz``): ``contacts.dominant_hz`` on them, 0 where all stayed silent."""
    rates = xr.DataArray(np.asarray(counts, dtype=float), dims=("event", "neuron_hz"),
                         coords={"neuron_hz": np.asarray(neuron_hz, dtype=float)})
    return dominant_hz(rates).values


# Where a bank's events run: Brian2 cpp_standalone through the sweep engine (compiled once
# per process, re-run per chunk with new inputs), or a runtime target (one NeuronGroup per
# band and chunk through ``neurons.simulate``); ``engine.events`` runs both.
TARGETS = ("standalone", "cython", "numpy")


@dataclass
class SpikingBank:
    """Resonator bands read out per contact event, many events per Brian2 run.

    Each band is its own NeuronGroup at its own ``dt_ms`` and ``method`` (a band's fields,
    default the bank's). ``batch_events`` events make one chunk of the sweep engine
    (``engine.events.run_bank`` runs a bank over a data set).
    """
    bands: dict = field(default_factory=lambda: {"low": LOW_BAND, "high": HIGH_BAND})
    duration_s: float = 0.5
    dt_ms: float = 0.1
    method: str = "euler"
    target: str = "standalone"  # one of TARGETS
    batch_events: int = 400
    # Inner edges (s from the start of each event's recording, which holds the bench's 50 ms
    # lead-in) of the time bins whose spike counts trace each channel's decay: 50 ms after
    # the impact, then 150 ms (the antenna's high mode, τ_high ≤ 60 ms, is below 8 % by
    # then while a struck metal rod still rings), then 250 ms.
    bin_edges_s: tuple = (0.1, 0.2, 0.3)

    def __post_init__(self):
        bounds.declared(self)
        check(isinstance(self.bands, dict) and len(self.bands) >= 1, "bands", self.bands,
              "a table of named bands, e.g. {low = {...}, high = {...}}")
        made = {}
        for name, band in self.bands.items():
            try:
                made[name] = band if isinstance(band, Band) else Band(**band)
            except SpecError as exc:
                raise SpecError(f"bands.{name}.{exc.field}", exc.value, exc.accepted) from None
        self.bands = made
        check(self.target in TARGETS, "target", self.target,
              "'standalone' (compiled C++, re-run per chunk), 'cython' or 'numpy'")
        for name, band in self.bands.items():
            try:
                check(band.dt_ms is None or is_number(band.dt_ms), "dt_ms", band.dt_ms,
                      "a step in ms, or none for the bank's dt_ms")
                band.array(self.dt_ms, self.method, self.runtime_target)
                band.check_coder()
            except SpecError as exc:
                raise SpecError(f"bands.{name}.{exc.field}", exc.value, exc.accepted) from None
        check(np.isfinite(self.duration_s) and self.duration_s > 0, "duration_s",
              self.duration_s, "a run length > 0 s per event")
        check(isinstance(self.batch_events, int) and self.batch_events >= 1, "batch_events",
              self.batch_events, "an integer >= 1 (events per Brian2 run)")
        edges = np.asarray(self.bin_edges_s, dtype=float)
        # Edges past duration_s are allowed (their bins stay empty), so one bank spec serves
        # short read-out windows (the control layer's 0.15 s) as well as whole events.
        check(edges.ndim == 1 and np.all(np.isfinite(edges)) and np.all(np.diff(edges) > 0)
              and (len(edges) == 0 or edges[0] > 0), "bin_edges_s", self.bin_edges_s,
              "increasing times > 0 s")
        self.bin_edges_s = tuple(float(e) for e in edges)

    @property
    def runtime_target(self) -> str:
        """The Brian2 runtime target of the bank's ``ResonatorArray`` objects."""
        return "cython" if self.target == "standalone" else self.target

    def arrays(self) -> dict[str, ResonatorArray]:
        """Each band's resonators, at the band's own dt and method."""
        return {name: band.array(self.dt_ms, self.method, self.runtime_target)
                for name, band in self.bands.items()}

    def check_rate(self, rate_hz: float) -> None:
        for name, band in self.bands.items():
            try:
                band.array(self.dt_ms, self.method, self.runtime_target).check_rate(rate_hz)
                check(band.lowpass_hz < rate_hz / 2, "lowpass_hz", band.lowpass_hz,
                      f"a cut-off below Nyquist ({rate_hz / 2:g} Hz)")
            except SpecError as exc:
                raise SpecError(f"bands.{name}.{exc.field}", exc.value, exc.accepted) from None

    @property
    def neuron_hz(self) -> np.ndarray:
        return np.concatenate([a.neuron_hz for a in self.arrays().values()])

    @property
    def n_neurons(self) -> int:
        return sum(b.n_neurons for b in self.bands.values())

    def description(self) -> dict:
        """What a report says of the bank: its size, bands, Brian2 target and time step."""
        return {"neurons_per_event": self.n_neurons,
                "bands": {k: asdict(v) for k, v in self.bands.items()},
                "target": self.target, "dt_ms": self.dt_ms, "method": self.method,
                "duration_s": self.duration_s}

    def code(self, counts: np.ndarray, rate_hz: float, adc_bits: int, full_scale_g: float
             ) -> np.ndarray:
        """Coded inputs (n_samples, n_events × n_bands), column e·n_bands + j for event e
        through band j's chain (``inputs(...).coded()``)."""
        return self.inputs(counts, rate_hz, adc_bits, full_scale_g).coded()

    def inputs(self, counts: np.ndarray, rate_hz: float, adc_bits: int, full_scale_g: float
               ) -> BankInputs:
        """The bands' input currents as the columns they share and each band's gain and clip
        on them (``BankInputs``). Each event is aligned on its own principal axis (what
        ``PCAAlign`` fitted on that event gives); the chain's later stages run on all events
        at once as columns (they filter along time only). Bands whose chains differ only in
        an analog coder's gain (a channel's graded gains) share one column: the filtered
        signal's dead zone (``AnalogCoder.dead_zone``), which each band's gain scales and
        its amplitude clips; any other coder's output is its band's own column, unscaled."""
        n_samples = min(counts.shape[1], int(round(self.duration_s * rate_hz)))
        main = align_events(counts[:, :n_samples], adc_bits, full_scale_g)   # (samples, events)
        columns, keys, column, gain, clip = [], {}, [], [], []
        for band, x in zip(self.bands.values(),
                           band_filtered(self.bands, main, rate_hz, adc_bits, full_scale_g)):
            coder = band.chain(rate_hz, adc_bits, full_scale_g).steps[-1][1].fit(x)
            analog = isinstance(coder, CODERS["analog"])
            params = {k: v for k, v in coder.get_params().items() if not analog or k not in
                      ("gain", "amplitude")}
            # band_filtered hands bands with the same filters one and the same array
            key = (id(x), type(coder).__name__, repr(sorted(params.items())))
            if not analog or key not in keys:
                keys[key] = len(columns)
                columns.append(coder.dead_zone(x) if analog else coder.transform(x))
            column.append(keys[key])
            # a coder's own output passes unclipped: twice its amplitude is never reached
            gain.append(coder.gain if analog else 1.0)
            clip.append(coder.amplitude * (1.0 if analog else 2.0))
        return BankInputs(tuple(columns), np.array(column), np.array(gain), np.array(clip))


@dataclass(frozen=True)
class BankInputs:
    """A bank's input currents for a chunk of events: ``columns``, each (samples, events),
    and, per band, the ``column`` it reads, the ``gain`` that scales it and the ``clip``
    level that bounds it: band j's current is clip(gain[j] · columns[column[j]], −clip[j],
    clip[j]), which the compiled engine computes per neuron as it reads its sample, so a
    channel's graded gains send one column, not one each."""
    columns: tuple
    column: np.ndarray
    gain: np.ndarray
    clip: np.ndarray

    def coded(self) -> np.ndarray:
        """Each band's current (samples, events × bands), column e·n_bands + j for event e
        through band j."""
        c = np.clip(self.gain * np.stack(self.columns, axis=2)[:, :, self.column], -self.clip,
                    self.clip)
        return c.reshape(len(c), -1)


def band_filtered(bands: dict, main: np.ndarray, rate_hz: float, adc_bits: int,
                  full_scale_g: float) -> list[np.ndarray]:
    """Each band's signal after its chain's filters and centring, before its coder, from the
    events' main axes ``main`` (samples, events; ``align_events``). One pass: these stages
    learn nothing from the samples (their fit checks the parameters; a pipeline's fit runs
    every stage but the last, so fit-then-transform would filter twice); bands whose filters
    are the same (a channel's graded gains, which differ only in their coder) share it."""
    out, done = [], {}
    for band in bands.values():
        key = (band.lowpass_hz, band.highpass_hz, band.filter_order)  # what the filters take
        if key not in done:
            done[key] = Pipeline(band.chain(rate_hz, adc_bits, full_scale_g).steps[2:-1]
                                 ).fit_transform(main)
        out.append(done[key])
    return out


def coded_features(bank: SpikingBank, counts: np.ndarray, rate_hz: float, adc_bits: int,
                   full_scale_g: float) -> np.ndarray:
    """What a bank's coded input carries before any resonator, per event (rows): for each
    channel and time bin (``bank.bin_edges_s``), the half-cycles the coded current starts
    (samples entering a sign it did not hold), its mean |current| over the coder's
    amplitude, and its changes of value (a level-crossing coder's events). The same three
    numbers for every coder, so a classifier on them bounds what any read-out of the coded
    input can reach without neurons. Coded ``bank.batch_events`` events at a time."""
    n_samples = min(counts.shape[1], int(round(bank.duration_s * rate_hz)))
    cuts = [0, *(int(round(e * rate_hz)) for e in bank.bin_edges_s
                 if 0 < e * rate_hz < n_samples), n_samples]
    amplitude = np.array([b.coder_amplitude for b in bank.bands.values()])
    rows = []
    for start in range(0, len(counts), bank.batch_events):
        chunk = counts[start:start + bank.batch_events]
        c = bank.code(chunk, rate_hz, adc_bits, full_scale_g).reshape(
            n_samples, len(chunk), len(amplitude)) / amplitude
        sign = np.sign(c)
        onset = np.zeros_like(c)
        onset[1:] = (sign[1:] != sign[:-1]) & (sign[1:] != 0)
        change = np.zeros_like(c)
        change[1:] = c[1:] != c[:-1]
        per_bin = [np.add.reduceat(x, cuts[:-1], axis=0) / np.diff(cuts)[:, None, None]
                   for x in (onset, np.abs(c), change)]       # (bins, events, channels)
        rows.append(np.stack(per_bin, axis=-1).transpose(1, 2, 0, 3).reshape(len(chunk), -1))
    return np.concatenate(rows).astype(np.float32)


def align_events(counts: np.ndarray, adc_bits: int, full_scale_g: float) -> np.ndarray:
    """Events (events, samples, 2 axes of counts) → main axis in g, shape (samples, events).

    The batched form of ``preprocess.CountsToG`` + ``PCAAlign`` fitted per event: mean removed,
    projected on the covariance's top eigenvector, its largest component made positive.
    """
    # axes × samples contiguous per event: the means and the 2 × 2 covariances reduce along
    # memory, 3-4× faster than on the (events, samples, axes) layout
    g = ADC(adc_bits, full_scale_g).to_g(np.ascontiguousarray(np.swapaxes(counts, 1, 2)))
    centred = g - g.mean(axis=2, keepdims=True)
    cov = np.matmul(centred, np.swapaxes(centred, 1, 2))
    _, vectors = np.linalg.eigh(cov)
    axis = vectors[:, :, -1]
    axis *= np.sign(axis[np.arange(len(axis)), np.argmax(np.abs(axis), axis=1)])[:, None]
    return (centred[:, 0] * axis[:, :1] + centred[:, 1] * axis[:, 1:]).T


class DominantNeuronDistance(RegressorMixin, BaseEstimator):
    """The paper's decoder (Fig. 10E) as an estimator: the dominant neuron's preferred
    frequency (``contacts.dominant_hz``) → distance through the inverse low-mode law. Nothing
    is learnt; ``fit`` only checks the input width. X holds spike counts of neurons tuned to
    ``neuron_hz``; an event where all stayed silent gets the middle of the calibrated range.
    ``law``: (slope per cm, intercept, distance for a silent event) of a law
    ``log10 F = slope d + intercept`` fitted for another antenna (a lab's, from its labels:
    ``evaluation.antenna_fit``); None: this project's antenna's."""

    def __init__(self, neuron_hz=None, law=None):
        self.neuron_hz = neuron_hz
        self.law = law

    def fit(self, X, y=None):
        preferred_hz("neuron_hz", self.neuron_hz)
        check(self.law is None or (len(self.law) == 3 and all(is_number(v) for v in self.law)
                                   and self.law[0] != 0), "law", self.law,
              "None or (slope per cm ≠ 0, intercept, distance in cm for a silent event)")
        check(np.ndim(X) == 2 and np.shape(X)[1] == len(self.neuron_hz), "X",
              f"shape {np.shape(X)}", "one column of spike counts per neuron of neuron_hz")
        self.n_features_in_ = np.shape(X)[1]
        return self

    def predict(self, X):
        return _distance_from_hz(dominant_of_counts(X, self.neuron_hz), self.law)


class CentroidDistance(DominantNeuronDistance):
    """Like ``DominantNeuronDistance`` but from the rate-weighted geometric centroid of the
    neurons' preferred frequencies (``readout.centroid_hz``), the quantity the resonators'
    k is tuned to (``neurons.DRIVEN_HZ_PER_K``); the most active neuron alone sits about a
    channel below the ringing frequency, because a resonator fires most for input somewhat
    above its centroid. ``around``: the centroid of the neurons within this factor (> 1) of
    each event's most driven neuron only, so neurons that a far component (another mode, an
    overtone) drives do not pull it; None: of every neuron. The most driven neuron is the
    one that fired on the largest share of its own cycles (its count over its preferred
    frequency): a resonator fires at most once per input cycle, so a high one that a weak
    harmonic drives can outnumber in spikes the low ones the mode itself drives."""

    def __init__(self, neuron_hz=None, law=None, around=None):
        super().__init__(neuron_hz, law)
        self.around = around

    def fit(self, X, y=None):
        check(self.around is None or (is_number(self.around) and self.around > 1), "around",
              self.around, "None or a factor > 1 around the dominant neuron")
        return super().fit(X, y)

    def predict(self, X):
        X = np.asarray(X, dtype=float)
        hz = np.asarray(self.neuron_hz, dtype=float)
        if self.around is not None:
            dominant = hz[np.argmax(X / hz[None, :], axis=1)][:, None]
            X = np.where((hz[None, :] <= dominant * self.around)
                         & (hz[None, :] >= dominant / self.around), X, 0.0)
        rates = xr.DataArray(X, dims=("event", "neuron_hz"), coords={"neuron_hz": hz})
        return _distance_from_hz(centroid_hz(rates).values, self.law)


def _distance_from_hz(f: np.ndarray, law=None) -> np.ndarray:
    """Inverse low-mode law (``law``: see ``DominantNeuronDistance``); 0 Hz (silent) → the
    middle of the calibrated range."""
    if law is not None:
        slope, intercept, silent_cm = law
        out = np.full(len(f), float(silent_cm))
        out[f > 0] = (np.log10(f[f > 0]) - intercept) / slope
        return out
    out = np.full(len(f), float(np.mean(antenna.CALIBRATED_RANGE_CM)))
    out[f > 0] = antenna.distance_from_low_hz(f[f > 0])
    return out


def window_features(network: dict, coded: np.ndarray, rate_hz: float) -> np.ndarray:
    """What the network's ``MaterialUnit`` reads (``network``: a network spec table with a
    ``material`` part), for coded events (samples, events) played back to back through the
    network's own resonator array, one window each: rows of ``MaterialUnit.window_features``.
    Fitting on these, not on ``spiking.SpikingBank``'s offline runs, keeps training and use
    on the same Brian2 code path and the same feature definition."""
    import brian2 as b2

    # the network's material part (its configured unit, found by type: "material" here is a
    # part of the network, not the bench label a read-out must never look up)
    unit = next((p for p in configure(network).values() if isinstance(p, MaterialUnit)), None)
    check(unit is not None, "network.parts", network.get("parts"),
          "a network with a 'material' part (whose read-out these features feed)")
    n_samples, n_events = coded.shape
    window_s = n_samples / rate_hz
    check(np.isclose(window_s, unit.window_s), "network.material.window_s", unit.window_s,
          f"the coded events' length ({n_samples} samples at {rate_hz:g} Hz = {window_s:g} s)")
    resonators_only = {"parts": ["resonators"], "inputs": ["antenna"],
                       "resonators": network.get("resonators", {})}
    asm = build(resonators_only)
    group = asm.objects["resonators"]
    feed = b2.TimedArray(np.ascontiguousarray(coded.T.ravel()), dt=b2.second / rate_hz)
    group.run_regularly("I_ext = coded_input(t)", dt=b2.second / rate_hz)
    monitor = b2.SpikeMonitor(group)
    asm.network.add(monitor)
    asm.network.run(n_events * window_s * b2.second, namespace={"coded_input": feed})
    return unit.window_features(np.asarray(monitor.i[:]), np.asarray(monitor.t_[:]),
                                len(group), n_events)


def recording_attrs(data: xr.Dataset) -> tuple[float, int, float]:
    """(rate_hz, adc_bits, full_scale_g) of a bench data set, as ``SpikingBank.code`` takes."""
    return (float(data.attrs["rate_hz"]), int(data.attrs["adc_bits"]),
            float(data.attrs["full_scale_g"]))
