"""Timing the resonator array on Brian2's devices: runtime (numpy, cython) and cpp_standalone.

A timed run must not time compiling: ``warm_up_array`` compiles what ``ResonatorArray.run``
will run on a few steps first, and ``run_standalone`` times the standalone binary apart from
its build. ``Timer`` measures wall and CPU seconds (this process plus finished children, so a
standalone binary counts); ``float_precision`` sets Brian2's float type for the groups built
inside it. ``Run`` is what a timed run returns: its spikes and its cost.

Two workloads put the array through its paces, each with its exact reference
(``networks.reference``) and its read-out: ``ArrayWorkload`` (a coded recording read by the
array and the quickstart read-out) and ``TuningWorkload`` (every neuron at every square-wave
frequency, one group). ``measure`` runs one ``Setting`` of a workload, warmed up, timed and
scored against the reference.

The sweep engine's standalone project (``engine.sweep``) is compiled once and re-run per
chunk with new parameters; here each configuration is built, compiled and run once, since the
build settings themselves are what is measured (``engine.settings_runs.array_standalone``
keeps such a build on disk instead).
"""
from __future__ import annotations

import os
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..core import bounds
from ..core.errors import NumericalInstabilityError, check
from ..networks import neurons, reference
from ..networks.resonators import ResonatorArray, held_samples
from ..evaluation import accuracy
from ..evaluation.accuracy import Match, SpikeTrains
from ..evaluation.tradeoff import ERRORS, RAISED, check_finite
from ..core.signals import Recording
from ..sources.stimuli import square

WARM_UP_MS = 5.0   # a few steps run every line of the compiled code; their spikes are unused
RUNTIME_TARGETS = ("numpy", "cython")
TARGETS = RUNTIME_TARGETS + ("cpp_standalone",)
DTYPES = ("float64", "float32")


@dataclass
class Run(SpikeTrains):
    """Spikes and cost of one timed run (``compile_s``: a standalone build, timed apart)."""
    wall_s: float = 0.0
    cpu_s: float = 0.0
    compile_s: float = 0.0


def cpu_seconds() -> float:
    """User and system CPU seconds of this process and its finished children."""
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


class Timer:
    """Wall and CPU seconds (this process plus finished children) of a block."""

    def __enter__(self):
        self._wall, self._cpu = time.perf_counter(), cpu_seconds()
        return self

    def __exit__(self, *exc):
        self.wall_s = time.perf_counter() - self._wall
        self.cpu_s = cpu_seconds() - self._cpu
        return False

    def run(self, spike_i, spike_t_ms, compile_s: float = 0.0) -> Run:
        return Run(np.asarray(spike_i, int), np.asarray(spike_t_ms, float), self.wall_s,
                   self.cpu_s, compile_s)


@contextmanager
def float_precision(dtype: str):
    """Brian2's default float type for groups built inside (restored afterwards)."""
    import brian2 as b2

    before = b2.prefs.core.default_float_dtype
    b2.prefs.core.default_float_dtype = np.float32 if dtype == "float32" else np.float64
    try:
        yield
    finally:
        b2.prefs.core.default_float_dtype = before


def _offline_group(array: ResonatorArray, coded: Recording):
    """The group and spike monitor ``ResonatorArray.run`` builds for ``coded``, same names:
    Brian2 compiles the TimedArray's (padded) length and step ratio into the code, so only the
    very same objects share its compiled code."""
    import brian2 as b2

    b2.start_scope()
    drive = b2.TimedArray(held_samples(np.asarray(coded.samples, float)),
                          dt=b2.second / coded.rate_hz, name="drive")
    group = array.build_group("drive(t)", "", {"drive": drive})
    return group, b2.SpikeMonitor(group, name="spikes")


def warm_up_array(array: ResonatorArray, coded: Recording, run_ms: float = WARM_UP_MS) -> Run:
    """Compile what ``array.run(coded)`` will run, on its first ``run_ms`` (the same network
    and code as the whole run, stopped early: also a timed sample of it)."""
    import brian2 as b2

    with Timer() as timer:
        group, spikes = _offline_group(array, coded)
        guard = neurons.instability_guard(group, "resonator", array.dt_ms, array.method)
        b2.Network(group, spikes, guard).run(run_ms * b2.ms, namespace={})
        guard.function()
    return timer.run(spikes.i[:], np.asarray(spikes.t_[:]) * 1000.0)


def run_array(array: ResonatorArray, coded: Recording, window_s: float) -> Run:
    """``array.run(coded)`` on a runtime target, timed."""
    with Timer() as timer:
        result = array.run(coded, window_s=window_s)
    return timer.run(result.spike_i, result.spike_t_s * 1000.0)


def bounded_make() -> None:
    """Compile with as many jobs as this process has cores. Brian2's default, ``make -j``,
    starts every code object's compiler at once: a bank of 50 bands meant ~80 g++ processes
    on 2 cores (load average 80, minutes of thrashing, every other job on the machine held up)."""
    from brian2 import prefs

    prefs.devices.cpp_standalone.extra_make_args_unix = [f"-j{len(os.sched_getaffinity(0))}"]


def run_standalone(array: ResonatorArray, coded: Recording) -> Run:
    """The array in Brian2's cpp_standalone mode: compile, then time the run alone.

    A NetworkOperation cannot run in standalone, so instability is checked on the final
    state (NaN is absorbing in this model: a NaN v never reaches threshold to be reset).
    """
    import brian2 as b2

    directory = tempfile.mkdtemp(prefix="snn_standalone_")
    bounded_make()
    b2.set_device("cpp_standalone", directory=directory, build_on_run=False)
    # Brian2 keeps one cpp_standalone device per process, and a compiled project of this
    # process (``engine.standalone.project``: the settings runs, the sweeps) may have built and
    # run on it: start it afresh (that project is rebuilt from its folder when next asked for)
    b2.device.reinit()
    b2.device.activate(directory=directory, build_on_run=False)
    try:
        group, spikes = _offline_group(array, coded)
        b2.Network(group, spikes).run(coded.duration_s * b2.second, namespace={})
        t0 = time.perf_counter()
        b2.device.build(directory=directory, run=False)
        compile_s = time.perf_counter() - t0
        with Timer() as timer:
            b2.device.run()
        _check_final_state(array, group, coded.duration_s)
        return timer.run(spikes.i[:], np.asarray(spikes.t_[:]) * 1000.0, compile_s)
    finally:
        b2.device.reinit()
        b2.device.activate()
        b2.set_device("runtime")


def _check_final_state(array: ResonatorArray, group, duration_s: float) -> None:
    v, u = np.asarray(group.v[:]), np.asarray(group.u[:])
    bad = ~(np.isfinite(v) & np.isfinite(u))
    if bad.any():
        i = int(np.argmax(bad))
        raise NumericalInstabilityError(
            neuron=i, params={"k": float(array.k[i]), "b": array.b}, dt_ms=array.dt_ms,
            method=array.method, t_ms=duration_s * 1000.0,
            safe_dt_ms=neurons.max_stable_dt_ms(array.k, array.method))


# -- workloads ------------------------------------------------------------------------------
class ArrayWorkload:
    """A coded recording read by the resonator array and the quickstart read-out."""

    def __init__(self, name: str, coded: Recording, net: dict, detector, window_s: float,
                 match: Match):
        self.name, self.coded, self.net = name, coded, net
        self.detector, self.window_s, self.match = detector, window_s, match
        self.true = coded.truth.contacts[0] if coded.truth.contacts else None
        self.n_neurons = self.array().n_neurons
        self.k_max = float(np.max(self.array().k))

    def array(self, method="euler", dt_ms=0.1, target="numpy", n_neurons=None):
        """The array at these settings (forced: coarse steps are measured on purpose)."""
        net = dict(self.net, method=method, dt_ms=dt_ms, force=True,
                   target=target if target in RUNTIME_TARGETS else "numpy")
        if n_neurons is not None:
            net["n_neurons"] = n_neurons
        return ResonatorArray(**net)

    def run(self, setting: Setting, warm_up: bool = False, run_ms: float | None = None) -> Run:
        """The whole run, or (``warm_up``) its first ``WARM_UP_MS``, or its first ``run_ms``
        (runtime targets): the same compiled code each time."""
        array = self.array(setting.method, setting.dt_ms, setting.target, setting.n_neurons)
        if warm_up or run_ms is not None:
            return warm_up_array(array, self.coded, WARM_UP_MS if run_ms is None else run_ms)
        if setting.target == "cpp_standalone":
            return run_standalone(array, self.coded)
        return run_array(array, self.coded, self.window_s)

    def reference(self, rtol: float, atol: float) -> Run:
        with Timer() as timer:
            result = reference.run_array(self.array(), self.coded, self.window_s, rtol, atol)
        return timer.run(result.spike_i, result.spike_t_s * 1000.0)

    def readout(self, run: SpikeTrains) -> accuracy.ArrayReadout:
        return accuracy.array_readout(run, self.array().neuron_hz, self.coded.duration_s,
                                      self.window_s, self.detector, self.true)

    def errors(self, run: SpikeTrains, ref: SpikeTrains, ref_readout) -> dict:
        return accuracy.compare_array(run, ref, self.readout(run), ref_readout,
                                      self.n_neurons, self.match)


@dataclass
class TuningStimuli:
    """Square waves of the coder's amplitude at ``n_freqs`` log-spaced frequencies."""
    f_min_hz: float = 4.0
    f_max_hz: float = 45.0
    n_freqs: int = 12
    duration_s: float = 2.0
    amplitude: float = 0.15
    rate_hz: float = 1000.0

    def __post_init__(self):
        bounds.declared(self)
        bounds.positive_seconds("duration_s", self.duration_s)
        bounds.amplitude("amplitude", self.amplitude)
        check(0 < self.f_min_hz < self.f_max_hz < self.rate_hz / 4, "f_max_hz", self.f_max_hz,
              "0 < f_min_hz < f_max_hz < rate_hz / 4")
        check(isinstance(self.n_freqs, int) and self.n_freqs >= 2, "n_freqs", self.n_freqs,
              "an integer >= 2")

    @property
    def freqs_hz(self) -> np.ndarray:
        return np.geomspace(self.f_min_hz, self.f_max_hz, self.n_freqs)


class TuningWorkload:
    """Every neuron of the array driven by square waves at every stimulus frequency.

    One NeuronGroup of n_neurons × n_freqs neurons (2-D input, ``input_index``). The read-out
    is each neuron's preferred stimulus (the argmax of its tuning curve).
    """
    name = "tuning"

    def __init__(self, stimuli: TuningStimuli, net: dict, match: Match):
        self.stimuli, self.net, self.match = stimuli, net, match
        self.freqs = stimuli.freqs_hz
        self.current = np.column_stack([
            square(f, stimuli.duration_s, stimuli.rate_hz, stimuli.amplitude).samples
            for f in self.freqs])
        self.k = ResonatorArray(**dict(net, force=True)).k
        self.k_max = float(np.max(self.k))
        self.n_neurons = len(self.k) * len(self.freqs)
        self.k_of = np.repeat(self.k, len(self.freqs))
        self.input_of = np.tile(np.arange(len(self.freqs)), len(self.k))
        self.b = net.get("b", ResonatorArray.b)

    def run(self, setting: Setting, warm_up: bool = False, run_ms: float | None = None) -> Run:
        check(setting.target in RUNTIME_TARGETS, "target", setting.target,
              "a runtime target for the tuning workload")
        if warm_up:
            run_ms = WARM_UP_MS
        with Timer() as timer:
            res = neurons.simulate("resonator", self.current, setting.dt_ms, self.k_of,
                                   setting.method, input_dt_ms=1000.0 / self.stimuli.rate_hz,
                                   input_index=self.input_of, target=setting.target,
                                   force=True, b=self.b, run_ms=run_ms)
        return timer.run(res.spike_i, res.spike_t_ms)

    def reference(self, rtol: float, atol: float) -> Run:
        with Timer() as timer:
            res = reference.simulate("resonator", self.current, self.k_of,
                                     input_dt_ms=1000.0 / self.stimuli.rate_hz,
                                     input_index=self.input_of, rtol=rtol, atol=atol, b=self.b)
        return timer.run(res.spike_i, res.spike_t_ms)

    def readout(self, run: SpikeTrains) -> accuracy.TuningReadout:
        return accuracy.tuning_readout(run, len(self.k), len(self.freqs),
                                       self.stimuli.duration_s)

    def errors(self, run: SpikeTrains, ref: SpikeTrains, ref_readout) -> dict:
        return accuracy.compare_tuning(run, ref, self.readout(run), ref_readout)


# -- measuring one setting ------------------------------------------------------------------
@dataclass(frozen=True)
class Setting:
    """How one run is built: integrator, step, code target, float type and array size
    (None: the workload's own size, the one its reference exists for)."""
    method: str
    dt_ms: float
    target: str
    dtype: str = "float64"
    n_neurons: int | None = None

    def __post_init__(self):
        bounds.declared(self)
        bounds.choice("method", self.method, neurons.METHODS)
        bounds.choice("target", self.target, TARGETS)
        bounds.choice("dtype", self.dtype, DTYPES)
        bounds.dt_ms("dt_ms", self.dt_ms)
        if self.n_neurons is not None:
            bounds.positive_integer("n_neurons", self.n_neurons)


@dataclass
class Reference:
    """A workload's reference run and its read-out."""
    run: Run
    readout: accuracy.ArrayReadout | accuracy.TuningReadout


def measure(workload, ref: Reference, setting: Setting, warmed: set) -> dict:
    """Run one setting (warmed up first, so compiling is not timed) and score it.

    ``warmed`` remembers the (workload, setting) pairs already compiled. A larger array than
    the workload's has no reference: its neurons are uncoupled, so the error per neuron is
    that of the workload's array; only its cost is measured.
    """
    row = {"scene": workload.name, "method": setting.method, "dt_ms": float(setting.dt_ms),
           "target": setting.target, "dtype": setting.dtype,
           "n_neurons": setting.n_neurons or workload.n_neurons,
           "k_dt": workload.k_max * setting.dt_ms}
    row["beyond_stable_limit"] = row["k_dt"] > neurons.MAX_STABLE_K_DT[setting.method]
    with float_precision(setting.dtype):
        # dt is part of the generated code (the TimedArray's step ratio): a new dt compiles
        # anew, so every setting warms up on a few steps before it is timed.
        t0 = time.perf_counter()
        try:
            if (workload.name, setting) not in warmed and setting.target != "cpp_standalone":
                workload.run(setting, warm_up=True)
                warmed.add((workload.name, setting))
            t0 = time.perf_counter()
            run = workload.run(setting)
        except NumericalInstabilityError as exc:
            row.update(status=RAISED, wall_s=time.perf_counter() - t0, cpu_s=None,
                       compile_s=0.0, error=str(exc), readout_matches=False,
                       **{e: None for e in ERRORS}, distance_cm=None, n_spikes=None)
            return row
    row.update(status="ok", wall_s=run.wall_s, cpu_s=run.cpu_s, compile_s=run.compile_s,
               n_spikes=int(len(run.spike_i)))
    if setting.n_neurons is None:
        row.update(workload.errors(run, ref.run, ref.readout))
    else:
        row.update({e: None for e in ERRORS}, distance_cm=None, readout_matches=None)
    return check_finite(row, run)


def solve_reference(workload, rtol: float, atol: float) -> Reference:
    run = workload.reference(rtol, atol)
    return Reference(run, workload.readout(run))


def reference_convergence(workload, ref: Reference, rtol: float, atol: float) -> dict:
    """How far ``ref`` moves when solved again at the tighter ``rtol``, ``atol``
    (``accuracy.reference_shift``), and what the tighter solve cost."""
    tight = workload.reference(rtol, atol)
    return dict(accuracy.reference_shift(ref.run, tight, workload.n_neurons),
                wall_s_tight=tight.wall_s)
