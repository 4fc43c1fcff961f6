"""Contact events on the sweep engine: resonator banks over coded events (``EventSweep``).

    features = run_bank(bank, counts, rate_hz, adc_bits, full_scale_g, client=client)

The grid is event × neuron (every neuron of every band of a ``SpikingBank``); a chunk is
``bank.batch_events`` whole events. On a worker, ``EventSweep`` codes its chunk's events
(``SpikingBank.code``) and runs each band as its own NeuronGroup at the band's dt and method,
each neuron reading its event's column of the band's 2-D input:

- ``"standalone"`` (``bank.target``): Brian2 cpp_standalone, one project per process holding
  one group per band, compiled once and re-run per chunk with the chunk's coded inputs, the
  bands' tuning and the neurons' resting state through ``run_args`` (``engine.standalone``);
  a short last chunk is padded with copies of its first event instead of recompiling;
- ``"cython"`` / ``"numpy"``: the same groups through ``neurons.simulate`` (runtime).

Per point (event, neuron): spike count, first-spike latency, firing span, spikes per time bin
(``SpikingBank.bin_edges_s``) and the chunk's Brian2 seconds shared out over its points. The
results land in a resumable zarr store (``engine.sweep.run_sweep``, on Dask when given a
client) and come back as ``SpikeFeatures``. ``cached_features`` keeps a bench data set's
features on disk (an interrupted run resumes); ``run_cost`` times a sample of events.

Blow-ups: the runtime targets stop within 10 ms (``neurons.instability_guard``); the compiled
project flags a neuron whose |v| or |u| left the finite range at any 10 ms check (a variable
of the model, no Python during the run) and ``NumericalInstabilityError`` is raised after it.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import NumericalInstabilityError, check
from ..networks import neurons
from ..networks.neurons import binned_spike_counts, spike_summary
from ..readout.spiking import SpikeFeatures, SpikingBank, recording_attrs
from ..store import Output
from .grid import Grid
from .standalone import project, run_project
from .sweep import run_sweep

CHECK_EVERY_MS = 10.0
GUARD = (f"unstable = unstable or not (abs(v) < {neurons.RUNAWAY_LIMIT!r} and "
         f"abs(u) < {neurons.RUNAWAY_LIMIT!r})")


@dataclass(frozen=True, repr=False)
class EventSweep:
    """Spiking features of ``bank`` over events ``counts`` (events, samples, 2 axes of ADC
    counts, cut to the bank's window), one grid point per (event, neuron)."""
    bank: SpikingBank
    counts: np.ndarray
    rate_hz: float
    adc_bits: int
    full_scale_g: float

    def __repr__(self) -> str:
        return f"EventSweep({len(self.counts)} events, {self.settings()['bank']})"

    def settings(self) -> dict:
        """What the results depend on (the store's fingerprint): the bank and the data."""
        bank = asdict(self.bank)
        return {"bank": json.loads(json.dumps(bank, default=list)),
                "data": hashlib.sha1(np.ascontiguousarray(self.counts).tobytes()).hexdigest(),
                "recording": [self.rate_hz, self.adc_bits, self.full_scale_g]}

    @property
    def n_samples(self) -> int:
        return self.counts.shape[1]

    def outputs(self) -> dict[str, Output]:
        out = {"count": Output("i4", "1", "spikes in the event's window"),
               "latency_s": Output("f8", "s", "first spike (the window's length if none)"),
               "span_s": Output("f8", "s", "last spike - first spike"),
               "brian2_s": Output("f8", "s", "the chunk's Brian2 time over its points")}
        for b in range(len(self.bank.bin_edges_s) + 1):
            out[f"bin_{b}"] = Output("i4", "1", f"spikes in time bin {b} (bin_edges_s)")
        return out

    def grid(self) -> Grid:
        return Grid({"event": np.arange(len(self.counts)),
                     "neuron": np.arange(self.bank.n_neurons)})

    def for_grid(self, grid: Grid, block_shape) -> "EventSweep":
        check(grid.dims == ("event", "neuron") and block_shape[1] == self.bank.n_neurons,
              "axes", list(grid.dims), "event × neuron, every neuron of the bank in a chunk")
        check(block_shape[0] == min(self.bank.batch_events, grid.shape[0]), "chunk_points",
              int(np.prod(block_shape)), "batch_events × neurons (one chunk = one run)")
        return self

    @property
    def bytes_per_point(self) -> int:
        """Memory a chunk holds per point: the coded inputs of its events, 8 bytes a sample."""
        return int(8 * self.n_samples * len(self.bank.bands) / self.bank.n_neurons) + 64

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        n = self.bank.n_neurons
        events = points["event"].reshape(-1, n)[:, 0].astype(int)
        coded = self.bank.code(self.counts[events], self.rate_hz, self.adc_bits,
                               self.full_scale_g)
        n_bands = len(self.bank.bands)
        t0 = time.perf_counter()
        columns = [np.ascontiguousarray(coded[:, j::n_bands]) for j in range(n_bands)]
        if self.bank.target == "standalone":
            spikes = self._standalone(columns)
        else:
            spikes = [self._runtime(array, cols) for array, cols in
                      zip(self.bank.arrays().values(), columns)]
        brian2_s = time.perf_counter() - t0
        parts = [band_features(i, t_ms, len(events), array.n_neurons,
                               self.n_samples / self.rate_hz, self.bank.bin_edges_s)
                 for (i, t_ms), array in zip(spikes, self.bank.arrays().values())]
        counts, latency, span, binned = (np.concatenate([p[k] for p in parts], axis=1)
                                         for k in range(4))
        out = {"count": counts.ravel(), "latency_s": latency.ravel(), "span_s": span.ravel(),
               "brian2_s": np.full(counts.size, brian2_s / counts.size)}
        for b in range(binned.shape[2]):
            out[f"bin_{b}"] = binned[:, :, b].ravel()
        return out

    def _runtime(self, array, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = columns.shape[1]
        res = neurons.simulate(
            "resonator", columns, array.dt_ms, k=np.tile(array.k, m), method=array.method,
            input_dt_ms=1000.0 / self.rate_hz, input_index=np.repeat(np.arange(m),
                                                                     array.n_neurons),
            target=self.bank.target, b=np.full(m * array.n_neurons, array.b))
        return res.spike_i, res.spike_t_ms

    def _standalone(self, columns: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Every band's spikes (neuron, ms) for the chunk's coded ``columns``: one run of the
        compiled project, padded to ``batch_events`` events."""
        size = self.bank.batch_events
        m = columns[0].shape[1]
        arrays = list(self.bank.arrays().values())
        proj = project(self._structure(arrays), lambda: self._build(arrays))
        run_args = {}
        for j, (array, cols) in enumerate(zip(arrays, columns)):
            cols = np.hstack([cols, np.repeat(cols[:, :1], size - m, axis=1)])
            group = proj["groups"][j]
            k = np.tile(array.k, size)
            b = np.full(k.size, array.b)
            # at rest for each event's first input sample, as neurons.simulate starts
            levels, which = np.unique(cols[0], return_inverse=True)
            rest = np.array([neurons.resting_state("resonator", array.b, float(I0))
                             for I0 in levels])[np.repeat(which.ravel(), array.n_neurons)]
            run_args.update({proj["drives"][j]: cols, group.k: k, group.b: b,
                             group.v: np.ascontiguousarray(rest[:, 0]),
                             group.u: np.ascontiguousarray(rest[:, 1])})
        run_project(proj, run_args)
        out = []
        for j, array in enumerate(arrays):
            self._check_stable(proj["groups"][j], array, m * array.n_neurons)
            monitor = proj["monitors"][j]
            i, t = np.asarray(monitor.i[:], dtype=int), np.asarray(monitor.t_[:])
            keep = i < m * array.n_neurons
            # the runtime path's spike times: monitor.t / ms, the same division
            out.append((i[keep], t[keep] / 0.001))
        return out

    def _structure(self, arrays) -> tuple:
        """What the compiled project depends on; everything else is a run argument."""
        return ("events", neurons.PRESETS["resonator"].quadratic, self.n_samples,
                float(self.rate_hz), self.bank.batch_events,
                tuple((a.n_neurons, float(a.dt_ms), a.method) for a in arrays))

    def _build(self, arrays) -> dict:
        import brian2 as b2

        size, input_dt = self.bank.batch_events, (1000.0 / self.rate_hz) * b2.ms
        preset = neurons.PRESETS["resonator"]
        objects = {"groups": [], "drives": [], "monitors": []}
        net = b2.Network()
        for j, array in enumerate(arrays):
            n = size * array.n_neurons
            drive = b2.TimedArray(np.zeros((self.n_samples, size)), dt=input_dt,
                                  name=f"drive_{j}")
            group = b2.NeuronGroup(
                n, neurons.equations("resonator", f"drive_{j}(t, input_index)",
                                     "input_index : integer (constant)\nunstable : boolean"),
                threshold=neurons.THRESHOLD, reset=neurons.reset(),
                method=neurons.brian_method(array.method), dt=array.dt_ms * b2.ms,
                name=f"band_{j}", namespace={f"drive_{j}": drive})
            group.input_index = np.arange(n) // array.n_neurons
            group.a, group.c, group.d = preset.a, preset.c, preset.d
            group.run_regularly(GUARD, dt=CHECK_EVERY_MS * b2.ms, name=f"guard_{j}")
            monitor = b2.SpikeMonitor(group, name=f"spikes_{j}")
            net.add(group, monitor)
            for key, obj in (("groups", group), ("drives", drive), ("monitors", monitor)):
                objects[key].append(obj)
        net.run(self.n_samples * input_dt, namespace={})
        return objects

    def _check_stable(self, group, array, n: int) -> None:
        v, u = np.asarray(group.v[:])[:n], np.asarray(group.u[:])[:n]
        bad = np.asarray(group.unstable[:])[:n] | ~np.isfinite(v) | ~np.isfinite(u) \
            | (np.abs(v) >= neurons.RUNAWAY_LIMIT) | (np.abs(u) >= neurons.RUNAWAY_LIMIT)
        if bad.any():
            i = int(np.argmax(bad))
            k = float(array.k[i % array.n_neurons])
            raise NumericalInstabilityError(
                neuron=i, params={"k": k, "b": float(array.b)}, dt_ms=array.dt_ms,
                method=array.method, t_ms=1000.0 * self.n_samples / self.rate_hz,
                safe_dt_ms=neurons.max_stable_dt_ms(k, array.method))

    def features(self, data) -> SpikeFeatures:
        """The store's results (event × neuron) as ``SpikeFeatures``."""
        arrays = self.bank.arrays()
        n_bins = len(self.bank.bin_edges_s) + 1
        steps = sum(len(self.counts) * a.n_neurons * self.n_samples * (1000.0 / self.rate_hz)
                    / a.dt_ms for a in arrays.values())
        names = np.concatenate([[name] * a.n_neurons for name, a in arrays.items()])
        return SpikeFeatures(
            data["count"].values.astype(np.int64), data["latency_s"].values,
            data["span_s"].values, self.bank.neuron_hz, names,
            min(self.n_samples / self.rate_hz, self.bank.duration_s),
            float(data["brian2_s"].values.sum()), steps,
            np.stack([data[f"bin_{b}"].values for b in range(n_bins)], axis=2))


def band_features(spike_i, spike_t_ms, n_events: int, n_neurons: int, duration_s: float,
                  bin_edges_s) -> tuple[np.ndarray, ...]:
    """(counts, latency, span, binned) of one band's group, each (events, band neurons[,
    bins]): neuron e·n_neurons + j is neuron j of event e."""
    t_s = np.asarray(spike_t_ms) / 1000.0
    total = n_events * n_neurons
    counts, latency, span = spike_summary(spike_i, t_s, total, duration_s)
    binned = binned_spike_counts(spike_i, t_s, total, bin_edges_s)
    return (counts.reshape(n_events, n_neurons), latency.reshape(n_events, n_neurons),
            span.reshape(n_events, n_neurons), binned.reshape(n_events, n_neurons, -1))


def run_bank(bank: SpikingBank, counts: np.ndarray, rate_hz: float, adc_bits: int,
             full_scale_g: float, *, client=None, store_path=None, fresh: bool = False,
             progress: bool = True) -> SpikeFeatures:
    """Spiking features of events ``counts`` (events, samples, 2 axes of ADC counts): the
    sweep engine over event × neuron, in this process or on ``client``'s Dask workers, into
    the zarr store ``store_path`` (resumable; default: a temporary one)."""
    bank.check_rate(rate_hz)
    n_samples = min(counts.shape[1], int(round(bank.duration_s * rate_hz)))
    sweep = EventSweep(bank, np.ascontiguousarray(counts[:, :n_samples]), float(rate_hz),
                       int(adc_bits), float(full_scale_g))
    # a temporary store in memory where the machine has one: its files are written, read
    # back and removed within the call (on a disk, removing them took ~0.15 s a call)
    shm = "/dev/shm" if store_path is None and os.path.isdir("/dev/shm") else None
    with tempfile.TemporaryDirectory(prefix="snn_antenna_events_", dir=shm) as tmp:
        path = Path(tmp) / "events.zarr" if store_path is None else Path(store_path)
        outcome = run_sweep(sweep.grid(), sweep, path, sweep.outputs(), client=client,
                            chunk_points=bank.batch_events * bank.n_neurons, fresh=fresh,
                            settings=sweep.settings(), progress=progress, desc="spiking")
        return sweep.features(outcome.data)


# -- whole bench data sets: cached features and measured cost ------------------------------
def cached_features(data, bank: SpikingBank, bench_spec, log=print, fresh: bool = False,
                    client=None):
    """Spiking features of every event of a bench data set (``bench_spec`` made it), cached
    on disk, keyed by the data set, the bank and this module's code with its imports
    (``bench.cache_key``).
    The run itself goes through a sweep store beside the cache, so an interrupted one
    resumes."""
    from ..files import remove_entry
    from ..sources import bench

    key = bench.cache_key({"bench": bench_spec.key(), "bank": _bank_fields(bank)}, __name__)
    path = Path(bench_spec.cache_dir) / f"spiking-{key}.zarr"
    store = path.with_name(f"spiking-{key}.sweep.zarr")

    def compute():
        f = run_bank(bank, data["counts"].values, *recording_attrs(data), client=client,
                     store_path=store, fresh=fresh)
        log(f"      {data.sizes['event']} events: {f.neuron_steps:.3g} neuron-steps in "
            f"{f.wall_s:.1f} s of simulation")
        return f.to_dataset(data["event"].values, bank.bin_edges_s)
    out = bench.cached(path, compute, __name__, log, fresh)
    remove_entry(store)
    return out


def _bank_fields(bank: SpikingBank) -> dict:
    d = asdict(bank)
    d["bands"] = {k: {kk: (list(vv) if isinstance(vv, tuple) else vv) for kk, vv in v.items()}
                  for k, v in d["bands"].items()}
    return d


def run_cost(data, bank: SpikingBank, n_events: int) -> dict:
    """Wall time (coding + Brian2) and neuron-steps per event, measured now on ``n_events``
    events spread over the data set, in one chunk in this process (after a warm-up run on
    two of them: code generation, compiling)."""
    ids = np.linspace(0, data.sizes["event"] - 1, n_events).astype(int)
    sample = data["counts"].values[ids]
    one = replace(bank, batch_events=max(bank.batch_events, n_events))
    attrs = recording_attrs(data)
    run_bank(one, sample[:2], *attrs, progress=False)
    t0 = time.perf_counter()
    f = run_bank(one, sample, *attrs, progress=False)
    total = time.perf_counter() - t0
    return {"features_us_per_event": 1e6 * total / n_events,
            "simulation_us_per_event": 1e6 * f.wall_s / n_events,
            "neuron_steps_per_event": f.neuron_steps / n_events,
            "ns_per_neuron_step": 1e9 * f.wall_s / f.neuron_steps,
            "events_measured": n_events, "target": bank.target}
