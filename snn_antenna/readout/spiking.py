"""Spiking read-out of contact events: resonator banks over many events in one NeuronGroup.

Each event goes through the real preprocessing chain (``preprocess.make_chain``: counts → g,
PCA alignment, low-pass, centring, square-wave coder) and drives a bank of resonators
(``network.ResonatorArray`` sets their tuning). For a whole data set, a batch of events ×
neurons is ONE Brian2 NeuronGroup through ``neurons.simulate``: the coded events are the
columns of a 2-D input and each neuron reads its event's column (``input_index``), so Brian2
runs once per batch, never once per event.

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

import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.pipeline import Pipeline

from ..errors import SpecError, check
from ..networks import neurons
from ..networks.neurons import binned_spike_counts, spike_summary
from ..networks.resonators import ResonatorArray
from ..preprocess import make_chain
from ..sources import antenna
from ..sources.antenna import ADC
from .contacts import centroid_hz, dominant_hz


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

    def array(self, dt_ms: float, method: str, target: str) -> ResonatorArray:
        return ResonatorArray(self.n_neurons, tuple(self.band_hz), self.spacing, self.b, dt_ms,
                              method, target, self.hz_per_k)

    def chain(self, rate_hz: float, adc_bits: int, full_scale_g: float):
        return make_chain(rate_hz, adc_bits, full_scale_g, lowpass_hz=self.lowpass_hz,
                          coder_amplitude=self.coder_amplitude, threshold=self.threshold_g,
                          highpass_hz=self.highpass_hz)


LOW_BAND = Band()
# The high band is tuned with the small-signal resonance (24.5 Hz per unit k): measured at
# dt 0.1 ms with 0.5 s square waves, each neuron's largest spike count then falls within one
# channel of its target (with the driven 20.4 Hz per k it fell 1-2 channels above).
# Its input is band-passed (50–900 Hz): the square-wave coder codes only the sign, so with the
# low mode still in the signal the high mode would show only near the low mode's zero crossings.
HIGH_BAND = Band(n_neurons=24, band_hz=(55.0, 500.0), lowpass_hz=900.0, highpass_hz=50.0,
                 threshold_g=0.02, hz_per_k=neurons.LINEAR_HZ_PER_K)


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

    def select(self, bands) -> "SpikeFeatures":
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


@dataclass
class SpikingBank:
    """Resonator bands read out per contact event, many events per Brian2 run."""
    bands: dict = field(default_factory=lambda: {"low": LOW_BAND, "high": HIGH_BAND})
    duration_s: float = 0.5
    dt_ms: float = 0.1
    method: str = "euler"
    target: str = "numpy"
    batch_events: int = 400
    # Inner edges (s from the start of each event's recording, which holds the bench's 50 ms
    # lead-in) of the time bins whose spike counts trace each channel's decay: 50 ms after
    # the impact, then 150 ms (the antenna's high mode, τ_high ≤ 60 ms, is below 8 % by
    # then while a struck metal rod still rings), then 250 ms.
    bin_edges_s: tuple = (0.1, 0.2, 0.3)

    def __post_init__(self):
        check(isinstance(self.bands, dict) and len(self.bands) >= 1, "bands", self.bands,
              "a table of named bands, e.g. {low = {...}, high = {...}}")
        self.bands = {name: b if isinstance(b, Band) else Band(**b)
                      for name, b in self.bands.items()}
        for name, band in self.bands.items():
            try:
                band.array(self.dt_ms, self.method, self.target)
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

    def check_rate(self, rate_hz: float) -> None:
        for name, band in self.bands.items():
            try:
                band.array(self.dt_ms, self.method, self.target).check_rate(rate_hz)
                check(band.lowpass_hz < rate_hz / 2, "lowpass_hz", band.lowpass_hz,
                      f"a cut-off below Nyquist ({rate_hz / 2:g} Hz)")
            except SpecError as exc:
                raise SpecError(f"bands.{name}.{exc.field}", exc.value, exc.accepted) from None

    @property
    def neuron_hz(self) -> np.ndarray:
        return np.concatenate([b.array(self.dt_ms, self.method, self.target).neuron_hz
                               for b in self.bands.values()])

    @property
    def n_neurons(self) -> int:
        return sum(b.n_neurons for b in self.bands.values())

    def description(self) -> dict:
        """What a report says of the bank: its size, bands, Brian2 target and time step."""
        return {"neurons_per_event": self.n_neurons,
                "bands": {k: asdict(v) for k, v in self.bands.items()},
                "target": self.target, "dt_ms": self.dt_ms, "duration_s": self.duration_s}

    def code(self, counts: np.ndarray, rate_hz: float, adc_bits: int, full_scale_g: float
             ) -> np.ndarray:
        """Coded inputs (n_samples, n_events × n_bands), column e·n_bands + j for event e
        through band j's chain. Each event is aligned on its own principal axis (what
        ``PCAAlign`` fitted on that event gives); the chain's later stages run on all events
        at once as columns (they filter along time only)."""
        n_samples = min(counts.shape[1], int(round(self.duration_s * rate_hz)))
        main = align_events(counts[:, :n_samples], adc_bits, full_scale_g)   # (samples, events)
        coded = []
        for band in self.bands.values():
            chain = band.chain(rate_hz, adc_bits, full_scale_g)
            after_align = Pipeline(chain.steps[2:])
            coded.append(after_align.fit(main).transform(main))
        return np.stack(coded, axis=2).reshape(n_samples, -1)

    def run(self, counts: np.ndarray, rate_hz: float, adc_bits: int, full_scale_g: float,
            progress: bool = True) -> SpikeFeatures:
        """Spiking features of events ``counts`` (events, samples, 2 axes of ADC counts)."""
        from tqdm.auto import tqdm

        self.check_rate(rate_hz)
        arrays = [b.array(self.dt_ms, self.method, self.target) for b in self.bands.values()]
        k = np.concatenate([a.k for a in arrays])
        b_values = np.concatenate([np.full(a.n_neurons, a.b) for a in arrays])
        band_of = np.concatenate([np.full(a.n_neurons, j) for j, a in enumerate(arrays)])
        per_event = len(k)
        n = len(counts)
        names = np.array(list(self.bands))
        feats = {key: np.zeros((n, per_event)) for key in ("counts", "latency", "span")}
        feats["binned"] = np.zeros((n, per_event, len(self.bin_edges_s) + 1))
        wall, steps = 0.0, 0.0
        bar = tqdm(total=n, desc="spiking", unit="event", disable=not progress, leave=False)
        for lo in range(0, n, self.batch_events):
            batch = counts[lo:lo + self.batch_events]
            current = self.code(batch, rate_hz, adc_bits, full_scale_g)
            m = len(batch)
            # neuron (event e, bank neuron j) reads column e * n_bands + band_of[j]
            index = (np.arange(m)[:, None] * len(arrays) + band_of[None, :]).ravel()
            t0 = time.perf_counter()
            result = neurons.simulate(
                "resonator", current, self.dt_ms, k=np.tile(k, m), method=self.method,
                input_dt_ms=1000.0 / rate_hz, input_index=index, target=self.target,
                b=np.tile(b_values, m))
            wall += time.perf_counter() - t0
            steps += m * per_event * current.shape[0] * (1000.0 / rate_hz) / self.dt_ms
            c, lat, span = spike_summary(result.spike_i, result.spike_t_ms / 1000.0,
                                         m * per_event, current.shape[0] / rate_hz)
            feats["counts"][lo:lo + m] = c.reshape(m, per_event)
            feats["latency"][lo:lo + m] = lat.reshape(m, per_event)
            feats["span"][lo:lo + m] = span.reshape(m, per_event)
            feats["binned"][lo:lo + m] = binned_spike_counts(
                result.spike_i, result.spike_t_ms / 1000.0, m * per_event,
                self.bin_edges_s).reshape(m, per_event, -1)
            bar.update(m)
        bar.close()
        return SpikeFeatures(feats["counts"], feats["latency"], feats["span"],
                             np.concatenate([a.neuron_hz for a in arrays]), names[band_of],
                             min(counts.shape[1] / rate_hz, self.duration_s), wall, steps,
                             feats["binned"])


def align_events(counts: np.ndarray, adc_bits: int, full_scale_g: float) -> np.ndarray:
    """Events (events, samples, 2 axes of counts) → main axis in g, shape (samples, events).

    The batched form of ``preprocess.CountsToG`` + ``PCAAlign`` fitted per event: mean removed,
    projected on the covariance's top eigenvector, its largest component made positive.
    """
    g = ADC(adc_bits, full_scale_g).to_g(counts)
    centred = g - g.mean(axis=1, keepdims=True)
    cov = np.einsum("esi,esj->eij", centred, centred)
    _, vectors = np.linalg.eigh(cov)
    axis = vectors[:, :, -1]
    axis *= np.sign(axis[np.arange(len(axis)), np.argmax(np.abs(axis), axis=1)])[:, None]
    return np.einsum("esi,ei->se", centred, axis)


class DominantNeuronDistance(RegressorMixin, BaseEstimator):
    """The paper's decoder (Fig. 10E) as an estimator: the dominant neuron's preferred
    frequency (``contacts.dominant_hz``) → distance through the inverse low-mode law. Nothing
    is learnt; ``fit`` only checks the input width. X holds spike counts of neurons tuned to
    ``neuron_hz``; an event where all stayed silent gets the middle of the calibrated range."""

    def __init__(self, neuron_hz=None):
        self.neuron_hz = neuron_hz

    def fit(self, X, y=None):
        check(self.neuron_hz is not None and np.shape(X)[1] == len(self.neuron_hz), "X",
              f"shape {np.shape(X)}", "one column of spike counts per neuron of neuron_hz")
        self.n_features_in_ = np.shape(X)[1]
        return self

    def predict(self, X):
        return _distance_from_hz(dominant_of_counts(X, self.neuron_hz))


class CentroidDistance(DominantNeuronDistance):
    """Like ``DominantNeuronDistance`` but from the rate-weighted geometric centroid of the
    neurons' preferred frequencies (``readout.centroid_hz``), the quantity the resonators'
    k is tuned to (``neurons.DRIVEN_HZ_PER_K``); the most active neuron alone sits about a
    channel below the ringing frequency, because a resonator fires most for input somewhat
    above its centroid."""

    def predict(self, X):
        rates = xr.DataArray(np.asarray(X, dtype=float), dims=("event", "neuron_hz"),
                             coords={"neuron_hz": np.asarray(self.neuron_hz, dtype=float)})
        return _distance_from_hz(centroid_hz(rates).values)


def _distance_from_hz(f: np.ndarray) -> np.ndarray:
    """Inverse low-mode law; 0 Hz (silent) → the middle of the calibrated range."""
    out = np.full(len(f), float(np.mean(antenna.CALIBRATED_RANGE_CM)))
    out[f > 0] = antenna.distance_from_low_hz(f[f > 0])
    return out


def window_features(network: dict, coded: np.ndarray, rate_hz: float) -> np.ndarray:
    """Spike features of the network's own resonator array (``network``: a network spec
    table) for coded events (samples, events) played back to back, one window each:
    rows as ``SpikeFeatures.matrix()`` (counts, latencies, spans), what ``MaterialUnit``
    reads in the network. Fitting on these, not on ``spiking.SpikingBank``'s offline runs,
    keeps training and use on the same Brian2 code path."""
    import brian2 as b2

    from ..networks.assembly import build

    resonators_only = {"parts": ["resonators"], "inputs": ["antenna"],
                       "resonators": network.get("resonators", {})}
    asm = build(resonators_only)
    group = asm.objects["resonators"]
    n_samples, n_events = coded.shape
    window_s = n_samples / rate_hz
    feed = b2.TimedArray(np.ascontiguousarray(coded.T.ravel()), dt=b2.second / rate_hz)
    group.run_regularly("I_ext = coded_input(t)", dt=b2.second / rate_hz)
    monitor = b2.SpikeMonitor(group)
    asm.network.add(monitor)
    asm.network.run(n_events * window_s * b2.second, namespace={"coded_input": feed})
    i, t = np.asarray(monitor.i[:]), np.asarray(monitor.t_[:])
    event = np.minimum((t // window_s).astype(int), n_events - 1)
    n = len(group)
    counts, latency, span = spike_summary(event * n + i, t - event * window_s, n * n_events,
                                          window_s)
    return np.hstack([x.reshape(n_events, n) for x in (counts, latency, span)]).astype(float)


# -- whole bench data sets: cached features and measured cost ------------------------------
def cached_features(data: xr.Dataset, bank: SpikingBank, bench_spec, log=print,
                    fresh: bool = False) -> xr.Dataset:
    """Spiking features of every event of a bench data set (``bench_spec`` made it), cached
    on disk, keyed by the data set, the bank and the source of the code that simulates."""
    import sys

    from .. import preprocess
    from ..sources import bench

    key = bench.source_hash({"bench": bench_spec.key(), "bank": _bank_fields(bank)},
                            sys.modules[__name__], neurons, preprocess)
    path = Path(bench_spec.cache_dir) / f"spiking-{key}.zarr"

    def compute():
        f = bank.run(data["counts"].values, *recording_attrs(data))
        log(f"      {data.sizes['event']} events: {f.neuron_steps:.3g} neuron-steps in "
            f"{f.wall_s:.1f} s of simulation")
        return f.to_dataset(data["event"].values, bank.bin_edges_s)
    return bench.cached(path, compute, log, fresh)


def _bank_fields(bank: SpikingBank) -> dict:
    d = asdict(bank)
    d["bands"] = {k: {kk: (list(vv) if isinstance(vv, tuple) else vv) for kk, vv in v.items()}
                  for k, v in d["bands"].items()}
    return d


def recording_attrs(data: xr.Dataset) -> tuple[float, int, float]:
    """(rate_hz, adc_bits, full_scale_g) of a bench data set, as ``SpikingBank.run`` takes."""
    return (float(data.attrs["rate_hz"]), int(data.attrs["adc_bits"]),
            float(data.attrs["full_scale_g"]))


def run_cost(data: xr.Dataset, bank: SpikingBank, n_events: int) -> dict:
    """Wall time (coding + Brian2) and neuron-steps per event, measured now on ``n_events``
    events spread over the data set, in one batch (after a warm-up run on two of them:
    code generation, compiling)."""
    ids = np.linspace(0, data.sizes["event"] - 1, n_events).astype(int)
    sample = data["counts"].values[ids]
    one = replace(bank, batch_events=max(bank.batch_events, n_events))
    attrs = recording_attrs(data)
    one.run(sample[:2], *attrs, progress=False)
    t0 = time.perf_counter()
    f = one.run(sample, *attrs, progress=False)
    total = time.perf_counter() - t0
    return {"features_us_per_event": 1e6 * total / n_events,
            "simulation_us_per_event": 1e6 * f.wall_s / n_events,
            "neuron_steps_per_event": f.neuron_steps / n_events,
            "ns_per_neuron_step": 1e9 * f.wall_s / f.neuron_steps,
            "events_measured": n_events, "target": bank.target}
