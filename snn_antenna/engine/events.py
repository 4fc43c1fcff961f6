"""Contact events on the sweep engine: resonator banks over coded events (``EventSweep``).

    features = run_bank(bank, counts, rate_hz, adc_bits, full_scale_g, client=client)

The grid is event × neuron (every neuron of every band of a ``SpikingBank``); a chunk is
``bank.batch_events`` whole events. On a worker, ``EventSweep`` codes its chunk's events
(``SpikingBank.code``) and runs each band as its own NeuronGroup at the band's dt and method,
each neuron reading its event's column of the band's 2-D input:

- ``"standalone"`` (``bank.target``): Brian2 cpp_standalone, one project per process,
  compiled once and re-run per chunk with the chunk's coded inputs, the bands' tuning and the
  neurons' resting state through ``run_args`` (``engine.standalone``); a short last chunk is
  padded with copies of its first event instead of recompiling. Bands that share a dt and a
  method are one group (each neuron reads its own band's column), stepped by the sweep
  engine's ``FusedUpdater``: the input read once per clock tick, a few model steps per tick,
  threshold and reset branch-free, and the features accumulated as model variables in the
  same pass (no SpikeMonitor);
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
import math
import os
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from ..core.errors import NumericalInstabilityError, check
from ..networks import neurons
from ..readout.events import extraction_cost
from ..readout.spiking import SpikeFeatures, SpikingBank, recording_attrs
from ..core.store import Output
from .event_features import band_features, fused_features, spike_time_s
from .grid import Grid
from .standalone import (
    SPIKED,
    FusedUpdater,
    _functions,
    fused_reset,
    project,
    run_project,
    tick_substeps,
    vectorising_flags,
)
from .sweep import run_sweep
from ..core.files import remove_entry
from ..sources import bench

CHECK_EVERY_MS = 10.0
# Model steps per call of the fused update at most. Unrolled substeps of one neuron are one
# long dependency chain, which the core cannot overlap with the next neurons' (a run of the
# tuned 24-resonator bank over 400 events took 1.3 s of CPU at 1 substep per call, 1.0 s at
# 2, 1.3 s at 5 and 1.9 s at 10 with the input read inside the update; 2026-11-26, 2 cores,
# shared); the input and the bin edges' counts are read once per input sample regardless.
MAX_TICK_SUBSTEPS = 2
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

    def for_grid(self, grid: Grid, block_shape) -> EventSweep:
        check(grid.dims == ("event", "neuron") and block_shape[1] == self.bank.n_neurons,
              "axes", list(grid.dims), "event × neuron, every neuron of the bank in a chunk")
        check(block_shape[0] == min(self.bank.batch_events, grid.shape[0]), "chunk_points",
              int(np.prod(block_shape)), "batch_events × neurons (one chunk = one run)")
        return self

    @property
    def bytes_per_point(self) -> int:
        """Memory a chunk holds per point: the coded inputs of its events, 8 bytes a sample
        (at most one column per band: ``SpikingBank.inputs``)."""
        return int(8 * self.n_samples * len(self.bank.bands) / self.bank.n_neurons) + 64

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        n = self.bank.n_neurons
        events = points["event"].reshape(-1, n)[:, 0].astype(int)
        inputs = self.bank.inputs(self.counts[events], self.rate_hz, self.adc_bits,
                                  self.full_scale_g)
        n_bands = len(self.bank.bands)
        t0 = time.perf_counter()
        if self.bank.target == "standalone":
            parts = self._standalone(inputs)
        else:
            coded = inputs.coded()
            parts = [band_features(*self._runtime(array,
                                                  np.ascontiguousarray(coded[:, j::n_bands])),
                                   len(events), array.n_neurons, self.duration_s,
                                   self.bank.bin_edges_s)
                     for j, array in enumerate(self.arrays)]
        brian2_s = time.perf_counter() - t0
        counts, latency, span, binned = (np.concatenate([p[k] for p in parts], axis=1)
                                         for k in range(4))
        out = {"count": counts.ravel(), "latency_s": latency.ravel(), "span_s": span.ravel(),
               "brian2_s": np.full(counts.size, brian2_s / counts.size)}
        for b in range(binned.shape[2]):
            out[f"bin_{b}"] = binned[:, :, b].ravel()
        return out

    @cached_property
    def arrays(self) -> list:
        """The bank's bands as resonator arrays (``SpikingBank.arrays``), in band order."""
        return list(self.bank.arrays().values())

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.rate_hz

    def _runtime(self, array, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = columns.shape[1]
        res = neurons.simulate(
            "resonator", columns, array.dt_ms, k=np.tile(array.k, m), method=array.method,
            input_dt_ms=1000.0 / self.rate_hz, input_index=np.repeat(np.arange(m),
                                                                     array.n_neurons),
            target=self.bank.target, b=np.full(m * array.n_neurons, array.b))
        return res.spike_i, res.spike_t_ms

    # -- the compiled path ---------------------------------------------------------------
    def _layout(self) -> list[tuple[float, str, tuple[int, ...]]]:
        """The compiled project's groups: (dt_ms, method, the bands it holds), one per step
        and method. A group's neurons are ordered event, band, the band's neuron."""
        groups: dict = {}
        for j, array in enumerate(self.arrays):
            groups.setdefault((float(array.dt_ms), array.method), []).append(j)
        return [(dt, method, tuple(bands)) for (dt, method), bands in groups.items()]

    def _edge_steps(self, dt_ms: float) -> list[int]:
        """Per edge of ``bin_edges_s``: the first model step at dt ``dt_ms`` whose spike
        falls in the bin after it (``band_features``' rule on the runtime path's times)."""
        out = []
        for edge in self.bank.bin_edges_s:
            n = max(0, int(edge / (dt_ms * 1e-3)) - 2)
            while spike_time_s(n, dt_ms) < edge:
                n += 1
            out.append(n)
        return out

    def _run_edges(self, dt_ms: float) -> list[int]:
        """The steps of ``_edge_steps`` that fall within the run."""
        n_steps = round(self.duration_s * 1000.0 / dt_ms)
        return [e for e in self._edge_steps(dt_ms) if e < n_steps]

    def _substeps(self, dt_ms: float, at_most: int | None = None) -> int:
        """Model steps at dt ``dt_ms`` between the passes that read the input
        (``at_most=None``): a divisor of the input sample's steps; or, ``at_most`` given, per
        call of the fused update: a divisor of the former at which every bin edge falls on
        a call."""
        run_ms = self.duration_s * 1000.0
        if at_most is None:
            return tick_substeps(1000.0 / self.rate_hz, dt_ms, run_ms)
        return tick_substeps(1000.0 / self.rate_hz, dt_ms, run_ms, at_most,
                             self._run_edges(dt_ms))

    def _edge_every(self, dt_ms: float) -> int:
        """Model steps between the passes that take the bin edges' counts: every edge within
        the run falls on one (their greatest common divisor), a few passes per run where
        the input is read once per sample. 0: no edge within the run, no pass."""
        return math.gcd(*self._run_edges(dt_ms))

    def _standalone(self, inputs) -> list[tuple[np.ndarray, ...]]:
        """Every band's (counts, latency, span, binned), each (events, band neurons[, bins]),
        for the chunk's ``inputs`` (``SpikingBank.inputs``): one run of the compiled
        project, padded to ``batch_events`` events."""
        size = self.bank.batch_events
        arrays = self.arrays
        layout = self._layout()
        column = tuple(int(c) for c in inputs.column)
        with vectorising_flags("float64"):
            proj = project(self._structure(layout, column),
                           lambda: self._build(arrays, layout, column))
        n_samples, m = inputs.columns[0].shape
        run_args = {}
        for g, (_, _, bands) in enumerate(layout):
            group = proj["groups"][g]
            used = _group_columns(column, bands)
            cols = np.empty((n_samples, size, len(used)))   # the drive's layout: e·n + i
            for i, c in enumerate(used):
                cols[:, :m, i] = inputs.columns[c]
            # a short chunk: padded with copies of its first event
            cols[:, m:] = cols[:, :1]
            cols = cols.reshape(n_samples, -1)

            def per_neuron(values, bands=bands):
                return np.tile(np.concatenate([np.full(arrays[j].n_neurons, values[j])
                                               for j in bands]), size)
            k = np.tile(np.concatenate([arrays[j].k for j in bands]), size)
            b = per_neuron([a.b for a in arrays])
            gain, clip = per_neuron(inputs.gain), per_neuron(inputs.clip)
            # at rest for each event's first input sample, as neurons.simulate starts
            first = np.clip(gain * cols[0][_input_columns(arrays, bands, size, column)],
                            -clip, clip)
            v, u = neurons.resting_state("resonator", b, first)
            run_args.update({proj["drives"][g]: cols, group.k: k, group.b: b,
                             group.input_gain: gain, group.input_clip: clip,
                             group.v: v, group.u: u})
        run_project(proj, run_args)
        parts = {}
        for g, (dt_ms, _, bands) in enumerate(layout):
            group = proj["groups"][g]
            widths = [arrays[j].n_neurons for j in bands]
            n = m * sum(widths)

            def read(name, group=group, n=n, widths=widths):
                return np.asarray(getattr(group, name)[:])[:n].reshape(m, sum(widths))

            self._check_stable(group, arrays, bands, n)
            features = fused_features(
                read("spike_count"), read("first_step"), read("last_step"),
                [read(f"before_{e}") for e in range(len(self.bank.bin_edges_s))],
                self._edge_steps(dt_ms), round(self.duration_s * 1000.0 / dt_ms), dt_ms,
                self.duration_s)
            ends = np.cumsum(widths)[:-1]
            for j, split in zip(bands, zip(*(np.split(f, ends, axis=1) for f in features))):
                parts[j] = split
        return [parts[j] for j in range(len(arrays))]

    def _structure(self, layout, column: tuple) -> tuple:
        """What the compiled project depends on (``column``: each band's input column,
        ``SpikingBank.inputs``); everything else is a run argument."""
        arrays = self.arrays
        return ("events", neurons.PRESETS["resonator"].quadratic, self.n_samples,
                float(self.rate_hz), self.bank.batch_events, self.bank.bin_edges_s,
                tuple((dt, method, self._substeps(dt), self._substeps(dt, MAX_TICK_SUBSTEPS),
                       self._edge_every(dt), tuple(arrays[j].n_neurons for j in bands),
                       tuple(column[j] for j in bands))
                      for dt, method, bands in layout))

    def _build(self, arrays, layout, column: tuple) -> dict:
        import brian2 as b2

        size, input_dt = self.bank.batch_events, (1000.0 / self.rate_hz) * b2.ms
        preset = neurons.PRESETS["resonator"]
        n_edges = len(self.bank.bin_edges_s)
        objects = {"groups": [], "drives": []}
        net = b2.Network()
        for g, (dt_ms, method, bands) in enumerate(layout):
            columns = _input_columns(arrays, bands, size, column)
            substeps = self._substeps(dt_ms, MAX_TICK_SUBSTEPS)
            every = self._substeps(dt_ms)   # steps between input passes
            edge_every = self._edge_every(dt_ms)
            drive = b2.TimedArray(
                np.zeros((self.n_samples, size * len(_group_columns(column, bands)))),
                dt=input_dt, name=f"drive_{g}")
            # Passes of their own before the fused update: once per input sample, the
            # sample, scaled and clipped per neuron (``BankInputs``); at the bin edges, each
            # edge's count so far (the spikes before the edge, once the tick starting at it
            # has begun). In the update's loop, the TimedArray's bounds checks (branches) and
            # the edges' tests (a scalar boolean) would keep the compiler from vectorising it.
            tick = "\n".join([*_next_sample(g, method),
                              f"I_held = {_scaled(f'drive_{g}(t, input_index)')}"])
            edges = "\n".join(
                f"before_{e} = where(t_in_timesteps*{substeps} <= {step}, spike_count, "
                f"before_{e})" for e, step in enumerate(self._edge_steps(dt_ms)))
            variables = "\n".join(
                ["I_held : 1", "input_index : integer (constant)", "unstable : boolean",
                 "input_gain : 1 (constant)", "input_clip : 1 (constant)",
                 *RECORDED, *(f"before_{e} : 1" for e in range(n_edges)),
                 *(("I_next : 1", "next_sample_t : second (shared)") if method == "rk4" else ())])
            # a, c and d stay per-neuron arrays, though one value: declared shared, Brian2
            # pulls their products out of the loop in another order, the last bit of a step
            # moves, and a train of a hundred spikes parts from the runtime path's
            group = b2.NeuronGroup(
                len(columns), neurons.equations("resonator", HELD_INPUT[method == "rk4"],
                                                variables),
                method=FusedUpdater(method, substeps, "", fused_reset(*ON_SPIKE)
                                    .replace("SUBSTEPS", str(substeps))),
                dt=substeps * dt_ms * b2.ms, name=f"band_{g}",
                namespace={f"drive_{g}": drive, "dt_sub": dt_ms * b2.ms,
                           "input_rate": self.rate_hz * b2.Hz, **_functions()})
            group.input_index = columns
            group.a, group.c, group.d = preset.a, preset.c, preset.d
            group.run_regularly(tick, dt=every * dt_ms * b2.ms, when="start", name=f"tick_{g}")
            if edge_every:
                group.run_regularly(edges, dt=edge_every * dt_ms * b2.ms, when="start",
                                    name=f"edges_{g}")
            group.run_regularly(GUARD, dt=CHECK_EVERY_MS * b2.ms, name=f"guard_{g}")
            net.add(group)
            objects["groups"].append(group)
            objects["drives"].append(drive)
        net.run(self.n_samples * input_dt, namespace={})
        return objects

    def _check_stable(self, group, arrays, bands, n: int) -> None:
        """``NumericalInstabilityError`` for the first of the group's ``n`` neurons (holding
        ``bands`` of ``arrays``) whose |v| or |u| left the finite range during the run."""
        v, u = np.asarray(group.v[:])[:n], np.asarray(group.u[:])[:n]
        bad = np.asarray(group.unstable[:])[:n] | ~np.isfinite(v) | ~np.isfinite(u) \
            | (np.abs(v) >= neurons.RUNAWAY_LIMIT) | (np.abs(u) >= neurons.RUNAWAY_LIMIT)
        if bad.any():
            i = int(np.argmax(bad))
            per_event = [(j, r) for j in bands for r in range(arrays[j].n_neurons)]
            j, r = per_event[i % len(per_event)]
            array = arrays[j]
            k = float(array.k[r])
            raise NumericalInstabilityError(
                neuron=i, params={"k": k, "b": float(array.b)}, dt_ms=array.dt_ms,
                method=array.method, t_ms=1000.0 * self.duration_s,
                safe_dt_ms=neurons.max_stable_dt_ms(k, array.method))

    @property
    def neuron_steps(self) -> float:
        """Model steps of every neuron over every event."""
        return sum(len(self.counts) * a.n_neurons * self.n_samples * (1000.0 / self.rate_hz)
                   / a.dt_ms for a in self.arrays)

    def block(self) -> dict[str, np.ndarray]:
        """The features of every event in one run, in this process, no store: one chunk's
        work (the bank's ``batch_events`` holding them all)."""
        n = self.bank.n_neurons
        return self({"event": np.repeat(np.arange(len(self.counts)), n),
                     "neuron": np.tile(np.arange(n), len(self.counts))})

    def features(self, data) -> SpikeFeatures:
        """The store's results (event × neuron) as ``SpikeFeatures``."""
        n_bins = len(self.bank.bin_edges_s) + 1
        steps = self.neuron_steps
        names = np.concatenate([[name] * a.n_neurons
                                for name, a in zip(self.bank.bands, self.arrays)])
        return SpikeFeatures(
            data["count"].values.astype(np.int64), data["latency_s"].values,
            data["span_s"].values, self.bank.neuron_hz, names,
            min(self.n_samples / self.rate_hz, self.bank.duration_s),
            float(data["brian2_s"].values.sum()), steps,
            np.stack([data[f"bin_{b}"].values for b in range(n_bins)], axis=2))


# What the fused group records per neuron, updated in every model step (``fused_reset``'s
# statements, ``SPIKED`` its threshold test; SUBSTEPS: the group's substeps per tick): the
# step index, the spike count, the step of the last spike, and the step of the first spike
# (``first_step`` follows step + 1 until the first spike, then holds). Floats: an integer
# would be converted to and from floating point in the vectorised loop; whole numbers are
# exact in them up to 2**53.
RECORDED = ("spike_count : 1", "first_step : 1", "last_step : 1")
ON_SPIKE = ("_step = 1.0*(t_in_timesteps*SUBSTEPS + substep)",
            f"spike_count = where({SPIKED}, spike_count + 1, spike_count)",
            f"last_step = where({SPIKED}, _step, last_step)",
            "first_step = where(spike_count > 0, first_step, _step + 1)")


# The fused group's input: the sample held over the tick, as the coder holds it. rk4's last
# stage looks at t + dt, where the runtime path's TimedArray gives the next sample at a
# sample's last step: for rk4 the tick pass also reads that one (I_next) and the stages
# after the sample's end take it. The select is arithmetic (w is 0 or 1: exact either way):
# a scalar boolean in the loop would keep it from vectorising.
HELD_INPUT = ("held_input(I_held)",
              "held_input(I_held*(1 - int(t > next_sample_t - 0.25*dt_sub)) "
              "+ I_next*int(t > next_sample_t - 0.25*dt_sub))")


def _next_sample(g: int, method: str) -> tuple[str, ...]:
    """The tick pass's statements reading the next input sample (rk4 only: ``HELD_INPUT``)."""
    if method != "rk4":
        return ()
    return ("next_sample_t = (floor(t*input_rate + 1e-6) + 1)/input_rate",
            f"I_next = {_scaled(f'drive_{g}(next_sample_t, input_index)')}")


def _scaled(sample: str) -> str:
    """A neuron's current from its column's ``sample``: scaled by its band's gain and
    clipped at its band's level (``BankInputs``)."""
    return f"clip(input_gain*{sample}, -input_clip, input_clip)"


def _group_columns(column: tuple, bands) -> list[int]:
    """The bank's input columns (``BankInputs.column``: each band's) that ``bands`` read, in
    the order a group's drive holds them per event."""
    return sorted({column[j] for j in bands})


def _input_columns(arrays, bands, events: int, column: tuple) -> np.ndarray:
    """Each neuron's input column in a group holding ``bands`` of ``arrays`` for ``events``
    events, ``column`` giving each band's column of the bank's inputs: neuron (event e,
    band j, its neuron r) reads the group's column e · n + (band j's among the n the group
    reads)."""
    used = _group_columns(column, bands)
    local = [used.index(column[j]) for j in bands]
    within = np.repeat(local, [arrays[j].n_neurons for j in bands])
    return (np.arange(events)[:, None] * len(used) + within[None, :]).ravel()


def event_sweep(bank: SpikingBank, counts: np.ndarray, rate_hz: float, adc_bits: int,
                full_scale_g: float) -> EventSweep:
    """``bank`` over events ``counts`` (events, samples, 2 axes of ADC counts) cut to its
    window, the recording's rate checked against its bands."""
    bank.check_rate(rate_hz)
    n_samples = min(counts.shape[1], int(round(bank.duration_s * rate_hz)))
    return EventSweep(bank, np.ascontiguousarray(counts[:, :n_samples]), float(rate_hz),
                      int(adc_bits), float(full_scale_g))


def run_bank(bank: SpikingBank, counts: np.ndarray, rate_hz: float, adc_bits: int,
             full_scale_g: float, *, client=None, store_path=None, fresh: bool = False,
             progress: bool = True) -> SpikeFeatures:
    """Spiking features of events ``counts`` (events, samples, 2 axes of ADC counts): the
    sweep engine over event × neuron, in this process or on ``client``'s Dask workers, into
    the zarr store ``store_path`` (resumable; default: a temporary one)."""
    sweep = event_sweep(bank, counts, rate_hz, adc_bits, full_scale_g)
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
    events spread over the data set, as one block in memory (``EventSweep.block``: as the
    FFT pipeline's ``extraction_cost`` times its features, from the ADC counts, without the
    store a data set's run writes) of exactly that many events in this process (a larger
    chunk would pad the run with copies and charge them to the sample), after a warm-up run
    on two of them (code generation, compiling)."""
    ids = np.linspace(0, data.sizes["event"] - 1, n_events).astype(int)
    sample = data["counts"].values[ids]
    attrs = recording_attrs(data)
    one = replace(bank, batch_events=n_events)   # the warm-up's run: the same project
    event_sweep(one, sample[:2], *attrs).block()
    sweep = event_sweep(one, sample, *attrs)
    t0 = time.perf_counter()
    out = sweep.block()
    total = time.perf_counter() - t0
    simulation_s = float(out["brian2_s"].sum())
    return {"features_us_per_event": 1e6 * total / n_events,
            "simulation_us_per_event": 1e6 * simulation_s / n_events,
            "neuron_steps_per_event": sweep.neuron_steps / n_events,
            "ns_per_neuron_step": 1e9 * simulation_s / sweep.neuron_steps,
            "events_measured": n_events, "target": bank.target}


def best_costs(data, processor, sample_ids, banks: dict, repeats: int, log) -> dict:
    """Wall time per event of the FFT pipeline's features (``processor``) and of each bank of
    ``banks`` (name → bank), on the events ``sample_ids``, taken in turn ``repeats`` times in
    this process: each the best of its runs (the least disturbed by other work on the
    machine)."""
    ids = np.asarray(sample_ids)
    best: dict = {}
    for _ in range(repeats):
        runs = {"fft": extraction_cost(data, processor, ids)}
        runs.update({k: run_cost(data, bank, len(ids)) for k, bank in banks.items()})
        for k, c in runs.items():
            if k not in best or c["features_us_per_event"] < best[k]["features_us_per_event"]:
                best[k] = {**c, "best_of": repeats}
    log("      cost per event (best of " + f"{repeats}): " + ", ".join(
        f"{k} {c['features_us_per_event']:.0f} µs" for k, c in best.items()))
    return best
