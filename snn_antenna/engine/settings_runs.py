"""Scenes × integration steps on the compiled engine: one run per method for a whole grid.

    results = settings_spikes(drives, "rk2", [0.1, 0.5], "float64")
    results[("bench", 0.1)]   # a devices.Run, or the NumericalInstabilityError it raised

The speed/accuracy study scores every method × dt on every scene against an exact reference.
On the runtime targets each (scene, method, dt) is a Brian2 run of its own: built, compiled
(a new dt is new code) and stepped with Python between the steps. Here one cpp_standalone
project per method and float type holds every step of the grid as its own NeuronGroup (its
own clock), and every group holds every scene's neurons, each reading its scene's input
column of one TimedArray (``drive(t, input_index)``); one run of the binary steps them all.
The project is compiled once per structure (``engine.standalone.project``, kept on disk) and
takes the scenes' inputs, tuning and resting states as run arguments.

The model is the runtime path's: the same equations, Brian2's threshold, reset and state
updater, spikes from a SpikeMonitor, each neuron starting from the state its runtime run
starts from (``SceneDrive.v0``/``u0``). A scene shorter than the run holds its last input
sample after its end (as ``resonators.held_samples`` pads) and its spikes after its end are
dropped, so each scene's spikes are its runtime run's up to the compiler's rounding.

Blow-ups: every neuron checks its |v| and |u| each ``check_ms`` until its scene ends (a model
variable, no Python during the run); a scene whose neuron left the finite range gets the
``NumericalInstabilityError`` its runtime run would have raised, the others their spikes.

``SettingsRuns`` is the ``engine.batches.Batches`` work: one method per item, so the methods'
projects run on the Dask workers side by side.
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..core.errors import NumericalInstabilityError, check
from ..networks import neurons
from ..networks.resonators import held_samples
from .devices import ArrayWorkload, Run, Timer, TuningWorkload, float_precision
from .standalone import project, run_project, vectorising_flags

CHECK_EVERY_MS = 10.0


@dataclass(frozen=True, eq=False)
class SceneDrive:
    """One scene as the array's neurons see it: input columns ``current`` (samples, columns)
    at ``rate_hz``, and per neuron its ``k``, input column and starting state."""
    name: str
    current: np.ndarray
    rate_hz: float
    k: np.ndarray
    input_index: np.ndarray
    v0: np.ndarray
    u0: np.ndarray
    b: float

    def __post_init__(self):
        current = np.asarray(self.current, float)
        check(current.ndim == 2 and current.shape[0] >= 1 and current.shape[1] >= 1,
              "current", current.shape, "(samples, columns), at least one of each")
        n = len(self.k)
        for name in ("input_index", "v0", "u0"):
            check(np.shape(getattr(self, name)) == (n,), name, np.shape(getattr(self, name)),
                  f"one value per neuron ({n})")
        check(np.all((self.input_index >= 0) & (self.input_index < current.shape[1])),
              "input_index", self.input_index, f"columns in [0, {current.shape[1]})")

    @property
    def n_neurons(self) -> int:
        return len(self.k)

    @property
    def n_samples(self) -> int:
        return int(np.shape(self.current)[0])

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.rate_hz


def scene_drive(workload) -> SceneDrive:
    """A speed/accuracy workload (``engine.devices``) as its runtime run drives the array:
    a coded scene's one column with every neuron at rest for zero input (as
    ``ResonatorArray.build_group`` starts them); the tuning stimuli's columns with each
    neuron at rest for its column's first sample (as ``neurons.simulate`` starts)."""
    if isinstance(workload, ArrayWorkload):
        array = workload.array()
        v0, u0 = neurons.resting_state("resonator", array.b)
        n = array.n_neurons
        return SceneDrive(workload.name, np.asarray(workload.coded.samples, float)[:, None],
                          float(workload.coded.rate_hz), np.asarray(array.k, float),
                          np.zeros(n, int), np.full(n, v0), np.full(n, u0), float(array.b))
    check(isinstance(workload, TuningWorkload), "workload", type(workload).__name__,
          "an ArrayWorkload or a TuningWorkload")
    first = workload.current[0][workload.input_of]
    v_rest, u_rest = neurons.resting_state("resonator", workload.b, first)
    return SceneDrive(workload.name, workload.current, float(workload.stimuli.rate_hz),
                      np.asarray(workload.k_of, float), np.asarray(workload.input_of),
                      v_rest, u_rest, float(workload.b))


def check_interval_ms(drives) -> float:
    """``CHECK_EVERY_MS``, or a divisor of it at which every scene's end is checked."""
    ends_ms = [d.duration_s * 1000.0 for d in drives]
    for every in (CHECK_EVERY_MS, 5.0, 2.0, 1.0, 0.5, 0.1):
        if all(abs(e / every - round(e / every)) < 1e-9 for e in ends_ms):
            return every
    raise ValueError(f"scene lengths {ends_ms} ms are not whole multiples of 0.1 ms")


def _structure(drives, settings, dtype: str, check_ms: float) -> tuple:
    """What the compiled project depends on; inputs, tuning and states are run arguments."""
    return ("settings", neurons.PRESETS["resonator"].quadratic, tuple(settings), dtype,
            max(d.n_samples for d in drives),
            float(drives[0].rate_hz), tuple(d.n_neurons for d in drives),
            sum(int(np.shape(d.current)[1]) for d in drives), check_ms)


def _build(drives, settings, check_ms: float) -> dict:
    import brian2 as b2

    n = sum(d.n_neurons for d in drives)
    columns = sum(int(np.shape(d.current)[1]) for d in drives)
    n_samples = max(d.n_samples for d in drives)
    drive = b2.TimedArray(np.zeros((n_samples, columns)), dt=b2.second / drives[0].rate_hz,
                          name="drive")
    preset = neurons.PRESETS["resonator"]
    guard = (f"unstable = unstable or (t <= stop_t and not (abs(v) < "
             f"{neurons.RUNAWAY_LIMIT!r} and abs(u) < {neurons.RUNAWAY_LIMIT!r}))")
    net, groups, monitors = b2.Network(), [], []
    for g, (method, dt_ms) in enumerate(settings):
        group = b2.NeuronGroup(
            n, neurons.equations("resonator", "drive(t, input_index)",
                                 "input_index : integer (constant)\nunstable : boolean\n"
                                 "stop_t : second (constant)"),
            threshold=neurons.THRESHOLD, reset=neurons.reset(),
            method=neurons.brian_method(method), namespace={"drive": drive},
            dt=float(dt_ms) * b2.ms, name=f"step_{g}")
        group.a, group.c, group.d = preset.a, preset.c, preset.d
        group.run_regularly(guard, dt=check_ms * b2.ms, name=f"guard_{g}")
        spikes = b2.SpikeMonitor(group, name=f"spikes_{g}")
        net.add(group, spikes)
        groups.append(group)
        monitors.append(spikes)
    net.run(n_samples / drives[0].rate_hz * b2.second, namespace={})
    return {"groups": groups, "spikes": monitors, "drive": drive}


def _inputs(drives) -> np.ndarray:
    """Every scene's columns side by side, each held at its last sample to the longest."""
    n_samples = max(d.n_samples for d in drives)
    parts = []
    for d in drives:
        current = np.asarray(d.current, float)
        pad = np.repeat(current[-1:], n_samples - len(current), axis=0)
        parts.append(np.concatenate([current, pad]))
    return np.ascontiguousarray(np.concatenate(parts, axis=1))


def settings_spikes(drives: list[SceneDrive], methods, dts, dtype: str = "float64",
                    pairs=None) -> dict:
    """{(scene name, method, dt): Run or NumericalInstabilityError} for every scene of
    ``drives`` with every method of ``methods`` at every step of ``dts`` (or at each
    (method, dt) of ``pairs`` instead): one run of a compiled project. Each Run's cost is
    the whole run's, shared out over its (scene, method, dt) triples by neuron-steps."""
    check(len(drives) >= 1 and len({d.rate_hz for d in drives}) == 1, "drives",
          [d.rate_hz for d in drives], "scenes at one input rate")
    settings = list(dict.fromkeys(
        (m, float(dt)) for m, dt in (pairs if pairs is not None else
                                     [(m, dt) for m in methods for dt in dts])))
    from brian2 import second

    check_ms = check_interval_ms(drives)
    with float_precision(dtype), vectorising_flags("float64"):
        proj = project(_structure(drives, settings, dtype, check_ms),
                       lambda: _build(drives, settings, check_ms))
    starts = np.cumsum([0] + [d.n_neurons for d in drives])
    col_starts = np.cumsum([0] + [int(np.shape(d.current)[1]) for d in drives])
    per = {name: np.concatenate([np.asarray(getattr(d, name), float) for d in drives])
           for name in ("k", "v0", "u0")}
    index = np.concatenate([np.asarray(d.input_index) + c for d, c in zip(drives, col_starts)])
    stop = np.repeat([d.duration_s for d in drives], [d.n_neurons for d in drives])
    b = np.repeat([float(d.b) for d in drives], [d.n_neurons for d in drives])
    run_args = {proj["drive"]: _inputs(drives)}
    for group in proj["groups"]:
        run_args.update({group.k: per["k"], group.b: b, group.v: per["v0"], group.u: per["u0"],
                         group.input_index: index.astype(np.int32),
                         group.stop_t: stop * second})
    with Timer() as timer:
        run_project(proj, run_args)
    longest = max(d.duration_s for d in drives)
    work = {(d.name, m, dt): d.n_neurons * d.duration_s / dt for d in drives
            for m, dt in settings}
    total = sum(work.values())
    out = {}
    for g, (method, dt) in enumerate(settings):
        group, monitor = proj["groups"][g], proj["spikes"][g]
        flagged = np.asarray(group.unstable[:], bool)
        v, u = np.asarray(group.v_[:]), np.asarray(group.u_[:])
        finite = np.isfinite(v) & np.isfinite(u)
        spike_i = np.asarray(monitor.i[:], dtype=np.int64)
        spike_t_ms = np.asarray(monitor.t_[:], dtype=float) * 1000.0
        for j, d in enumerate(drives):
            lo, hi = starts[j], starts[j + 1]
            bad = flagged[lo:hi] | (~finite[lo:hi] if d.duration_s >= longest else False)
            if np.any(bad):
                i = int(np.argmax(bad))
                k = float(per["k"][lo + i])
                out[(d.name, method, dt)] = NumericalInstabilityError(
                    neuron=i, params={"k": k, "b": float(d.b)}, dt_ms=dt, method=method,
                    t_ms=1000.0 * d.duration_s, safe_dt_ms=neurons.max_stable_dt_ms(k, method))
                continue
            # the steps of the scene's own run: t = step · dt < its duration
            n_steps = int(round(d.duration_s * 1000.0 / dt))
            keep = (spike_i >= lo) & (spike_i < hi) & \
                (np.rint(spike_t_ms / dt) < n_steps)
            share = work[(d.name, method, dt)] / total
            out[(d.name, method, dt)] = Run(spike_i[keep] - lo, spike_t_ms[keep],
                                    timer.wall_s * share, timer.cpu_s * share)
    return out


@dataclass(frozen=True)
class SettingsRuns:
    """``engine.batches.Batches`` work: the items are methods, each item's result its
    triples of ``settings_spikes(drives, items, dts, dtype)`` (one compiled run per batch of
    methods)."""
    drives: tuple
    dts: tuple
    dtype: str = "float64"

    def __call__(self, methods: list) -> list:
        both = settings_spikes(list(self.drives), methods, self.dts, self.dtype)
        return [{key: r for key, r in both.items() if key[1] == m} for m in methods]


def neuron_steps(drives, n_methods: int, dts) -> float:
    """Neuron-steps of one run of ``n_methods`` methods: every scene at every step, each
    group stepped for the longest scene."""
    longest = max(x.duration_s for x in drives)
    return n_methods * sum(d.n_neurons * math.ceil(longest * 1000.0 / dt)
                           for d in drives for dt in dts)


# -- the stability map's constant drives ----------------------------------------------------
@contextmanager
def ieee_flags():
    """Brian2's compiler flags without ``-ffast-math``, for projects built inside: the
    arithmetic in the order the equations give it, as the runtime targets compute it. The
    stability map's near-threshold cells are decided by the last bits of a 40,000-step run:
    with fast-math's reordering, 3 of the full map's 2,000 cells changed class against the
    numpy runs and two methods' accurate limits moved by a grid point; without it, one
    cell beyond rk2's stable limit differs and every limit is the numpy map's."""
    from brian2 import prefs

    before = list(prefs.codegen.cpp.extra_compile_args_gcc)
    prefs.codegen.cpp.extra_compile_args_gcc = [
        f for f in before if f not in ("-ffast-math", "-fno-finite-math-only")]
    try:
        yield
    finally:
        prefs.codegen.cpp.extra_compile_args_gcc = before


def _build_drives(methods, n: int, n_drives: int, steps: int, preset: str) -> dict:
    """``accuracy.run_drives``' group once per method, in one network: the same equations,
    threshold, reset, state updater and runaway latch (after every step)."""
    import brian2 as b2

    p = neurons.PRESETS[preset]
    drive = b2.TimedArray(np.zeros((1, n_drives)), dt=steps * b2.ms, name="drive")
    limit = neurons.RUNAWAY_LIMIT
    net, groups, monitors = b2.Network(), [], []
    for g, method in enumerate(methods):
        group = b2.NeuronGroup(
            n, neurons.equations(p, "drive(t, input_index)",
                                 "input_index : integer (constant)\nblown : boolean"),
            threshold=neurons.THRESHOLD, reset=neurons.reset(),
            method=neurons.brian_method(method), namespace={"drive": drive},
            dt=1 * b2.ms, name=f"method_{g}")
        group.a, group.c, group.d = p.a, p.c, p.d
        group.run_regularly(f"blown = blown or not (abs(v) < {limit!r} and abs(u) < {limit!r})",
                            when="after_groups", name=f"latch_{g}")
        spikes = b2.SpikeMonitor(group, name=f"spikes_{g}")
        net.add(group, spikes)
        groups.append(group)
        monitors.append(spikes)
    net.run(steps * b2.ms, namespace={})
    return {"groups": groups, "spikes": monitors, "drive": drive}


def drives_runs(methods, k_dt, drives, steps: int, *, preset: str = "resonator",
                b: float | None = None) -> dict:
    """``accuracy.run_drives`` for every method of ``methods`` in one run of a compiled
    project: {method: (runaway, spike_i, spike_t_ms, k_of, drive_of)}, each method's group
    every (k·dt, drive) pair as one neuron, ``steps`` steps of 1 ms from the reset point.
    The grid's values are run arguments, so another grid of the same size reuses the
    binary."""
    k_dt, drives = np.asarray(k_dt, float), np.asarray(drives, float)
    check(np.all(k_dt > 0) and np.all(np.isfinite(k_dt)), "k_dt", k_dt, "values > 0")
    check(np.all(np.isfinite(drives)), "drives", drives, "finite currents")
    check(isinstance(steps, int) and steps >= 1, "steps", steps, "an integer >= 1")
    methods = list(methods)
    check(len(methods) >= 1 and all(m in neurons.METHODS for m in methods), "methods",
          methods, f"names from {list(neurons.METHODS)}")
    p = neurons.PRESETS[preset]
    b = p.b if b is None else b
    kk, ii = np.meshgrid(k_dt, np.arange(len(drives)), indexing="ij")
    kk, ii = kk.ravel(), ii.ravel()
    structure = ("drives", preset, p.quadratic, (p.a, p.c, p.d), tuple(methods), kk.size,
                 len(drives), steps)
    with float_precision("float64"), ieee_flags():
        proj = project(structure, lambda: _build_drives(methods, kk.size, len(drives), steps,
                                                        preset))
    run_args = {proj["drive"]: drives[None, :]}
    for group in proj["groups"]:
        run_args.update({group.k: kk, group.b: np.full(kk.size, float(b)),
                         group.v: np.full(kk.size, float(p.c)),
                         group.u: np.full(kk.size, float(b) * p.c),
                         group.input_index: ii.astype(np.int32),
                         group.blown: np.zeros(kk.size, bool)})
    with np.errstate(all="ignore"):
        run_project(proj, run_args)
    out = {}
    for method, group, spikes in zip(methods, proj["groups"], proj["spikes"]):
        out[method] = (np.asarray(group.blown[:], bool), np.asarray(spikes.i[:], int),
                       np.asarray(spikes.t_[:], float) * 1000.0, kk, drives[ii])
    return out


# -- the array on cpp_standalone, its build kept ----------------------------------------------
def array_standalone(array, coded) -> Run:
    """``devices.run_standalone`` with its project kept on disk by what it compiles
    (``standalone.project``: the array's size, method, step, float type, the input's length
    and rate, the compiler's flags): the input, tuning and resting state are run arguments,
    so another run of the same configuration (the next run of a study) runs the binary
    without compiling. The binary's run is timed; ``compile_s`` is what this call spent
    building (near zero when kept). Instability is checked on the final state (NaN is
    absorbing in this model)."""
    import brian2 as b2

    held = held_samples(np.asarray(coded.samples, float))
    structure = ("array", neurons.PRESETS["resonator"].quadratic, array.method,
                 float(array.dt_ms), array.n_neurons, len(held), float(coded.rate_hz),
                 str(np.dtype(b2.prefs.core.default_float_dtype)))

    def build():
        b2.start_scope()
        drive = b2.TimedArray(held, dt=b2.second / coded.rate_hz, name="drive")
        group = array.build_group("drive(t)", "", {"drive": drive})
        spikes = b2.SpikeMonitor(group, name="spikes")
        b2.Network(group, spikes).run(coded.duration_s * b2.second, namespace={})
        return {"group": group, "spikes": spikes, "drive": drive}

    with Timer() as build_timer:
        proj = project(structure, build)
    group, n = proj["group"], array.n_neurons
    v0, u0 = neurons.resting_state("resonator", array.b)
    run_args = {proj["drive"]: held, group.k: np.asarray(array.k, float),
                group.b: np.full(n, float(array.b)), group.v: np.full(n, v0),
                group.u: np.full(n, u0), group.spike_count: np.zeros(n, np.int32)}
    with Timer() as timer:
        run_project(proj, run_args)
    v, u = np.asarray(group.v[:]), np.asarray(group.u[:])
    bad = ~(np.isfinite(v) & np.isfinite(u))
    if bad.any():
        i = int(np.argmax(bad))
        raise NumericalInstabilityError(
            neuron=i, params={"k": float(array.k[i]), "b": float(array.b)}, dt_ms=array.dt_ms,
            method=array.method, t_ms=coded.duration_s * 1000.0,
            safe_dt_ms=neurons.max_stable_dt_ms(array.k, array.method))
    spikes = proj["spikes"]
    return timer.run(spikes.i[:], np.asarray(spikes.t_[:]) * 1000.0, build_timer.wall_s)
