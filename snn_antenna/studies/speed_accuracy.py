"""Speed vs accuracy: every integration knob measured against an exact reference.

For each scene (the array's tuning stimuli, the quickstart robot scene, a bench contact) the
resonator array runs in Brian2 for every integration method × dt (the main sweep), and for
a few settings across code targets × float precision × array size (the cost sweep). Each run
is timed and compared with the scene's reference (``snn_antenna.networks.reference``: solve_ivp with
exact threshold crossings and resets, piecewise between input switches): spike-time error,
spike-count error, rate-map error and, for contact scenes, decoded-distance error and
detection F1 of the quickstart read-out. The report shows the Pareto fronts (error vs wall
time), a recommendation per scene, and the stability map (method × k·dt × drive).

Configurations loop in this process: timing needs the machine to itself, and the knobs
(method, target, dtype) are build settings rather than the numeric axes of ``sweep.Grid``.
Each configuration is itself vectorised: all neurons (and, for tuning, all stimulus
frequencies) are one NeuronGroup.
"""
from __future__ import annotations

import dataclasses
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..readout import accuracy
from ..networks import neurons, reference
from .. import spec as specs
from ..errors import NumericalInstabilityError, check
from ..networks.resonators import ResonatorArray, rate_map
from ..preprocess import make_chain
from ..readout.contacts import ContactDetector, detector_from_spec
from ..report import (
    FLOAT32_CHECK,
    UNSTABLE_ON_PURPOSE,
    Calibrated,
    LogFile,
    Predicted,
    Report,
    fmt,
)
from ..signals import Recording
from ..sources.scenes import scene_from_spec
from ..sources.stimuli import RobotScene, square
from ..store import write_dataset

SECTIONS = ("network", "stimulus", "bench", "preprocess", "readout", "tuning", "sweep", "cost",
            "stability", "reference", "match")
SCENES = ("tuning", "quickstart", "bench")
TARGETS = ("numpy", "cython", "cpp_standalone")
DTYPES = ("float64", "float32")
COST = "cpu_s"   # what rankings use (see Run)
ERRORS = ("spike_time_error_ms", "spike_count_error", "rate_map_error", "distance_error_cm",
          "detection_f1")


@dataclasses.dataclass
class Tuning:
    """Square waves of the coder's amplitude at ``n_freqs`` log-spaced frequencies."""
    f_min_hz: float = 4.0
    f_max_hz: float = 45.0
    n_freqs: int = 12
    duration_s: float = 2.0
    amplitude: float = 0.15
    rate_hz: float = 1000.0


@dataclasses.dataclass
class Sweep:
    scenes: list = dataclasses.field(default_factory=lambda: list(SCENES))
    methods: list = dataclasses.field(default_factory=lambda: list(neurons.METHODS))
    dt_ms: list = dataclasses.field(default_factory=lambda: [0.005, 0.01, 0.025, 0.05, 0.1,
                                                            0.2, 0.5, 1.0])
    target: str = "cython"
    dtype: str = "float64"


@dataclasses.dataclass
class Cost:
    """Targets × dtypes × array sizes at ``settings`` (plus the quickstart recommendation)."""
    scene: str = "quickstart"
    settings: list = dataclasses.field(default_factory=lambda: [["euler", 0.1]])
    include_recommended: bool = True
    targets: list = dataclasses.field(default_factory=lambda: list(TARGETS))
    dtypes: list = dataclasses.field(default_factory=lambda: list(DTYPES))
    n_neurons: list = dataclasses.field(default_factory=lambda: [24, 2400])


@dataclasses.dataclass
class Stability:
    k_dt_min: float = 0.01
    k_dt_max: float = 50.0
    n_k_dt: int = 25
    drives: list = dataclasses.field(default_factory=lambda: [
        -50, -40, -30, -20, -10, -5, -1, -0.5, -0.15, 0, 0.15, 0.5, 1, 2, 5, 10, 20, 30, 40,
        50])
    model_ms: float = 400.0
    rate_tolerance: float = 0.05


@dataclasses.dataclass
class ReferenceSettings:
    rtol: float = reference.DEFAULT_RTOL
    atol: float = reference.DEFAULT_ATOL
    check_rtol: float = 1e-12   # the convergence check re-runs one scene at this tolerance
    check_scene: str = "bench"


@dataclasses.dataclass
class Match:
    """When a run's read-out counts as the reference's."""
    distance_cm: float = 0.1       # decoded distances within this
    detection_f1: float = 1.0      # contact windows identical
    rate_map_error: float = 0.05   # for the "rate map within" recommendation


@dataclasses.dataclass
class Run:
    """Spikes and cost of one configuration on one scene.

    ``cpu_s`` (this process and its children, e.g. a standalone binary) is what rankings
    use: on a shared machine wall time also measures everyone else's load.
    """
    spike_i: np.ndarray
    spike_t_ms: np.ndarray
    wall_s: float
    cpu_s: float
    compile_s: float = 0.0


class Timer:
    """Wall and CPU seconds (this process plus finished children) of a block."""

    def __enter__(self):
        self._wall, self._cpu = time.perf_counter(), _cpu_now()
        return self

    def __exit__(self, *exc):
        self.wall_s = time.perf_counter() - self._wall
        self.cpu_s = _cpu_now() - self._cpu
        return False


def _cpu_now() -> float:
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


# -- building -----------------------------------------------------------------------------
def build(spec: dict):
    """Check the whole spec and build every part before any simulation runs."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("network"):
        net = dict(specs.check_section(spec, "network", ResonatorArray))
        ResonatorArray(**net)
    scenes = {}
    for name, table_name in (("quickstart", "stimulus"), ("bench", "bench")):
        with specs.section(table_name):
            specs.check_section(spec, table_name, RobotScene, extra=["kind"])
            scene = scene_from_spec(spec.get(table_name, {}))
            scene.validate()
            scenes[name] = scene
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g"])
        for scene in scenes.values():
            make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
    detector, window_s = detector_from_spec(spec)
    parts = {}
    for name, cls in (("tuning", Tuning), ("sweep", Sweep), ("cost", Cost),
                      ("stability", Stability), ("reference", ReferenceSettings),
                      ("match", Match)):
        with specs.section(name):
            parts[name] = cls(**specs.check_section(spec, name, cls))
    _validate(parts, net, scenes)
    return net, scenes, pre, detector, window_s, parts


def _validate(parts: dict, net: dict, scenes: dict) -> None:
    sweep, cost, tun = parts["sweep"], parts["cost"], parts["tuning"]
    with specs.section("sweep"):
        for s in sweep.scenes:
            check(s in SCENES, "scenes", sweep.scenes, f"names from {list(SCENES)}")
        for m in sweep.methods:
            check(m in neurons.METHODS, "methods", sweep.methods,
                  f"names from {list(neurons.METHODS)}")
        check(len(sweep.dt_ms) >= 1 and all(isinstance(d, (int, float)) and 0 < d <= 1.0
                                            for d in sweep.dt_ms),
              "dt_ms", sweep.dt_ms, "steps in (0, 1] ms")
        check(sweep.target in ("numpy", "cython"), "target", sweep.target,
              "'numpy' or 'cython' (the runtime targets; the cost sweep covers standalone)")
        check(sweep.dtype in DTYPES, "dtype", sweep.dtype, f"one of {list(DTYPES)}")
    with specs.section("cost"):
        check(cost.scene in ("quickstart", "bench"), "scene", cost.scene,
              "'quickstart' or 'bench'")
        for t in cost.targets:
            check(t in TARGETS, "targets", cost.targets, f"names from {list(TARGETS)}")
        for d in cost.dtypes:
            check(d in DTYPES, "dtypes", cost.dtypes, f"names from {list(DTYPES)}")
        for n in cost.n_neurons:
            check(isinstance(n, int) and 1 <= n <= 100_000, "n_neurons", cost.n_neurons,
                  "integers in [1, 100000]")
        for s in cost.settings:
            check(isinstance(s, list) and len(s) == 2 and s[0] in neurons.METHODS
                  and isinstance(s[1], (int, float)) and 0 < s[1] <= 1, "settings",
                  cost.settings, "pairs [method, dt_ms] with dt_ms in (0, 1]")
    with specs.section("tuning"):
        check(0 < tun.f_min_hz < tun.f_max_hz < tun.rate_hz / 4, "f_max_hz", tun.f_max_hz,
              "0 < f_min_hz < f_max_hz < rate_hz / 4")
        check(isinstance(tun.n_freqs, int) and tun.n_freqs >= 2, "n_freqs", tun.n_freqs,
              "an integer >= 2")
    with specs.section("reference"):
        ref = parts["reference"]
        check(1e-14 <= ref.check_rtol < ref.rtol <= 1e-6, "check_rtol", ref.check_rtol,
              "a tolerance tighter than rtol (both in [1e-14, 1e-6])")
        check(ref.check_scene in SCENES, "check_scene", ref.check_scene, f"one of {SCENES}")
    for name, scene in scenes.items():
        ResonatorArray(**net).check_rate(scene.rate_hz)


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


# -- scenes ---------------------------------------------------------------------------------
class ArrayScene:
    """A coded recording read by the resonator array and the quickstart read-out."""

    def __init__(self, name, coded: Recording, net: dict, detector, window_s, match: Match):
        self.name, self.coded, self.net = name, coded, net
        self.detector, self.window_s, self.match = detector, window_s, match
        self.true = coded.contacts[0] if coded.contacts else None

    def array(self, method="euler", dt_ms=0.1, target="numpy", n_neurons=None):
        net = dict(self.net, method=method, dt_ms=dt_ms,
                   target=target if target != "cpp_standalone" else "numpy", force=True)
        if n_neurons is not None:
            net["n_neurons"] = n_neurons
        return ResonatorArray(**net)

    def run(self, method, dt_ms, target, n_neurons=None, warm_up=False) -> Run:
        array = self.array(method, dt_ms, target, n_neurons)
        coded = self.coded
        if warm_up:
            return _warm_up_array(array, coded)
        if target == "cpp_standalone":
            return _run_standalone(array, coded)
        with Timer() as timer:
            result = array.run(coded, window_s=self.window_s)
        return Run(result.spike_i, result.spike_t_s * 1000.0, timer.wall_s, timer.cpu_s)

    def reference(self, rtol, atol) -> Run:
        with Timer() as timer:
            result = reference.run_array(self.array(), self.coded, self.window_s, rtol, atol)
        return Run(result.spike_i, result.spike_t_s * 1000.0, timer.wall_s, timer.cpu_s)

    def readout(self, run: Run) -> dict:
        array = self.array()
        rates = rate_map(run.spike_i, run.spike_t_ms / 1000.0, array.neuron_hz,
                         self.coded.duration_s, self.window_s)
        detections = self.detector.detect(rates)
        decoded = None
        if self.true is not None:
            after = [d for d in detections if d.end_s > self.true.t_s]
            if after:
                decoded = min(after, key=lambda d: abs(d.onset_s - self.true.t_s)).distance_cm
        return {"rates": rates.values, "windows": self.detector.contact_windows(rates).values,
                "distance_cm": decoded, "n_neurons": array.n_neurons}

    def errors(self, run: Run, ref: Run, ref_readout: dict) -> dict:
        out = self.readout(run)
        n = out["n_neurons"]
        row = {
            "spike_time_error_ms": accuracy.spike_time_error_ms(
                run.spike_i, run.spike_t_ms, ref.spike_i, ref.spike_t_ms, n),
            "spike_count_error": accuracy.spike_count_error(
                np.bincount(run.spike_i, minlength=n), np.bincount(ref.spike_i, minlength=n)),
            "rate_map_error": accuracy.rate_map_error(out["rates"], ref_readout["rates"]),
            "detection_f1": accuracy.window_f1(out["windows"], ref_readout["windows"]),
            "distance_cm": out["distance_cm"],
        }
        d, d_ref = out["distance_cm"], ref_readout["distance_cm"]
        row["distance_error_cm"] = abs(d - d_ref) if d is not None and d_ref is not None \
            else None
        same_distance = (d is None and d_ref is None) or (
            row["distance_error_cm"] is not None
            and row["distance_error_cm"] <= self.match.distance_cm)
        row["readout_matches"] = bool(same_distance
                                      and row["detection_f1"] >= self.match.detection_f1)
        return row


class TuningScene:
    """Every neuron of the array driven by square waves at every stimulus frequency.

    One NeuronGroup of n_neurons × n_freqs neurons (2-D input, ``input_index``). The read-out
    is each neuron's preferred stimulus (the argmax of its tuning curve).
    """
    name = "tuning"

    def __init__(self, tun: Tuning, net: dict, match: Match):
        self.tun, self.net, self.match = tun, net, match
        self.freqs = np.geomspace(tun.f_min_hz, tun.f_max_hz, tun.n_freqs)
        self.current = np.column_stack([
            square(f, tun.duration_s, tun.rate_hz, tun.amplitude).samples for f in self.freqs])
        self.k = ResonatorArray(**dict(net, force=True)).k
        self.n_neurons = len(self.k) * len(self.freqs)
        self.k_of = np.repeat(self.k, len(self.freqs))
        self.input_of = np.tile(np.arange(len(self.freqs)), len(self.k))

    def run(self, method, dt_ms, target, n_neurons=None, warm_up=False) -> Run:
        check(target in ("numpy", "cython"), "target", target,
              "a runtime target for the tuning scene")
        with Timer() as timer:
            res = neurons.simulate("resonator", self.current, dt_ms, self.k_of, method,
                                   input_dt_ms=1000.0 / self.tun.rate_hz,
                                   input_index=self.input_of, target=target, force=True,
                                   b=self.net.get("b", 0.26), run_ms=5.0 if warm_up else None)
        return Run(res.spike_i, res.spike_t_ms, timer.wall_s, timer.cpu_s)

    def reference(self, rtol, atol) -> Run:
        with Timer() as timer:
            res = reference.simulate("resonator", self.current, self.k_of,
                                     input_dt_ms=1000.0 / self.tun.rate_hz,
                                     input_index=self.input_of, rtol=rtol, atol=atol,
                                     b=self.net.get("b", 0.26))
        return Run(res.spike_i, res.spike_t_ms, timer.wall_s, timer.cpu_s)

    def readout(self, run: Run) -> dict:
        counts = np.bincount(run.spike_i, minlength=self.n_neurons).reshape(
            len(self.k), len(self.freqs))
        rates = counts / self.tun.duration_s
        preferred = np.where(counts.max(axis=1) > 0, np.argmax(counts, axis=1), -1)
        return {"rates": rates, "preferred": preferred}

    def errors(self, run: Run, ref: Run, ref_readout: dict) -> dict:
        out = self.readout(run)
        return {
            "spike_time_error_ms": accuracy.spike_time_error_ms(
                run.spike_i, run.spike_t_ms, ref.spike_i, ref.spike_t_ms, self.n_neurons),
            "spike_count_error": accuracy.spike_count_error(out["rates"], ref_readout["rates"]),
            "rate_map_error": accuracy.rate_map_error(out["rates"], ref_readout["rates"]),
            "detection_f1": None, "distance_error_cm": None, "distance_cm": None,
            "readout_matches": bool(np.array_equal(out["preferred"],
                                                   ref_readout["preferred"])),
        }


def _warm_up_array(array: ResonatorArray, coded: Recording) -> Run:
    """Compile what ``array.run(coded)`` will run, on a few steps of the same input.

    Brian2 compiles the TimedArray's length and step ratio into the code, so the warm-up
    builds the very objects ``ResonatorArray.run`` builds (same input, same names).
    """
    import brian2 as b2

    with Timer() as timer:
        b2.start_scope()
        drive = b2.TimedArray(np.asarray(coded.samples, float), dt=b2.second / coded.rate_hz,
                              name="drive")
        group = array._build("drive(t)", "", {"drive": drive})
        spikes = b2.SpikeMonitor(group, name="spikes")
        guard = neurons.instability_guard(group, "resonator", array.dt_ms, array.method)
        b2.Network(group, spikes, guard).run(5 * b2.ms, namespace={})
    return Run(np.asarray(spikes.i[:], int), np.asarray(spikes.t_[:]) * 1000.0, timer.wall_s,
               timer.cpu_s)


def _run_standalone(array: ResonatorArray, coded: Recording) -> Run:
    """The array in Brian2's cpp_standalone mode: compile, then time the run alone.

    A NetworkOperation cannot run in standalone, so instability is checked on the final
    state (NaN is absorbing in this model: a NaN v never reaches threshold to be reset).
    """
    import brian2 as b2

    directory = tempfile.mkdtemp(prefix="snn_standalone_")
    b2.set_device("cpp_standalone", directory=directory, build_on_run=False)
    try:
        b2.start_scope()
        drive = b2.TimedArray(np.asarray(coded.samples, float), dt=b2.second / coded.rate_hz,
                              name="drive")
        group = array._build("drive(t)", "", {"drive": drive})
        spikes = b2.SpikeMonitor(group, name="spikes")
        b2.Network(group, spikes).run(coded.duration_s * b2.second, namespace={})
        t0 = time.perf_counter()
        b2.device.build(directory=directory, run=False)
        compile_s = time.perf_counter() - t0
        with Timer() as timer:
            b2.device.run()
        v, u = np.asarray(group.v[:]), np.asarray(group.u[:])
        spike_i, spike_t = np.asarray(spikes.i[:], int), np.asarray(spikes.t_[:]) * 1000.0
        bad = ~(np.isfinite(v) & np.isfinite(u))
        if bad.any():
            i = int(np.argmax(bad))
            raise NumericalInstabilityError(
                neuron=i, params={"k": float(array.k[i]), "b": array.b}, dt_ms=array.dt_ms,
                method=array.method, t_ms=coded.duration_s * 1000.0,
                safe_dt_ms=neurons.max_stable_dt_ms(array.k, array.method))
        return Run(spike_i, spike_t, timer.wall_s, timer.cpu_s, compile_s)
    finally:
        b2.device.reinit()
        b2.device.activate()
        b2.set_device("runtime")


# -- running -------------------------------------------------------------------------------
def prepare_scenes(net, robot_scenes, pre, detector, window_s, parts, seed, wanted, log):
    scenes = {}
    for name in wanted:
        if name == "tuning":
            scenes[name] = TuningScene(parts["tuning"], net, parts["match"])
            continue
        scene = robot_scenes[name]
        rec = scene.generate(seed)
        chain = make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
        chain.fit(rec.samples)
        coded = rec.with_samples(chain.transform(rec.samples), "coded")
        scenes[name] = ArrayScene(name, coded, net, detector, window_s, parts["match"])
        log(f"  {name}: {scene.duration_s:g} s at {scene.rate_hz:g} Hz, "
            f"{len(rec.contacts)} contact(s)")
    return scenes


def _size(scene) -> int:
    return scene.n_neurons if isinstance(scene, TuningScene) else scene.array().n_neurons


def measure(scene, ref: Run, ref_readout: dict, method, dt_ms, target, dtype, warmed: set,
            n_neurons=None) -> dict:
    """Run one configuration (warmed up first, so compiling is not timed) and score it."""
    default_n = _size(scene)
    row = {"scene": scene.name, "method": method, "dt_ms": float(dt_ms), "target": target,
           "dtype": dtype, "n_neurons": n_neurons or default_n}
    k_max = float(np.max(scene.k if isinstance(scene, TuningScene) else scene.array().k))
    row["k_dt"] = k_max * dt_ms
    row["beyond_stable_limit"] = row["k_dt"] > neurons.MAX_STABLE_K_DT[method]
    with float_precision(dtype):
        # dt is part of the generated code (the TimedArray's step ratio): a new dt compiles
        # anew, so every configuration warms up on a few steps before it is timed.
        key = (scene.name, method, dt_ms, target, dtype, n_neurons)
        t0 = time.perf_counter()
        try:
            if key not in warmed and target != "cpp_standalone":
                scene.run(method, dt_ms, target, n_neurons, warm_up=True)
                warmed.add(key)
            t0 = time.perf_counter()
            run = scene.run(method, dt_ms, target, n_neurons)
        except NumericalInstabilityError as exc:
            row.update(status="non-finite (raised NumericalInstabilityError)",
                       wall_s=time.perf_counter() - t0, cpu_s=None, compile_s=0.0,
                       error=str(exc),
                       readout_matches=False, **{e: None for e in ERRORS},
                       distance_cm=None, n_spikes=None)
            return row
    row.update(status="ok", wall_s=run.wall_s, cpu_s=run.cpu_s, compile_s=run.compile_s,
               n_spikes=int(len(run.spike_i)))
    if n_neurons is None:
        row.update(scene.errors(run, ref, ref_readout))
    else:  # a larger array has no reference here: its neurons are uncoupled, error per
        # neuron is the same as in the 24-neuron array; only cost is measured
        row.update({e: None for e in ERRORS}, distance_cm=None, readout_matches=None)
    return _check_finite(row, run)


def count_nonfinite(rows: list[dict]) -> dict:
    """Runs that raised NumericalInstabilityError, and runs that finished without it yet gave
    a non-finite spike time or score (``_check_finite``): both as measured."""
    return {"nonfinite_without_exception": sum(bool(r.get("nonfinite_without_exception"))
                                               for r in rows),
            "raised_instability": sum(r["status"].startswith("non-finite (raised")
                                      for r in rows)}


def _check_finite(row: dict, run: Run) -> dict:
    """A run that raised nothing but still produced a non-finite spike time or score is
    marked (and counted in the summary), its scores dropped: NaN never reaches a report."""
    bad = [name for name in ERRORS + ("distance_cm",)
           if row.get(name) is not None and not np.isfinite(row[name])]
    if not np.all(np.isfinite(run.spike_t_ms)):
        bad.append("spike times")
    row["nonfinite_without_exception"] = bool(bad)
    if bad:
        row.update(status=f"non-finite without exception ({', '.join(bad)})",
                   readout_matches=False, **{e: None for e in ERRORS}, distance_cm=None)
    return row


def pareto_front(rows: list[dict], error: str) -> list[dict]:
    """Rows not beaten on both wall time and ``error`` by another row."""
    ok = sorted((r for r in rows if r["status"] == "ok" and r.get(error) is not None),
                key=lambda r: (r[COST], r[error]))
    front, best = [], np.inf
    for r in ok:
        if r[error] < best:
            front.append(r)
            best = r[error]
    return front


def recommend(rows: list[dict], match: Match) -> list[dict]:
    """Per scene: the fastest run whose read-out matches the reference; the fastest whose
    rate map is within ``match.rate_map_error``; and the fastest setting at and below whose
    dt (same method) every run matches (robust to lucky coarse steps). Runs beyond their
    method's stability limit (forced in the sweep to show what happens) are never
    recommended."""
    out = []
    # Only settings a user gets without force=True: within the measured stability limit.
    rows = [r for r in rows if not r.get("beyond_stable_limit")]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene and r["status"] == "ok"]
        criteria = {
            "read-out matches the reference": lambda r: r["readout_matches"],
            f"rate map within {match.rate_map_error:.0%}":
                lambda r: r["rate_map_error"] <= match.rate_map_error,
        }
        for label, ok in criteria.items():
            passing = [r for r in mine if ok(r)]
            if passing:
                out.append(dict(criterion=label, **min(passing, key=lambda r: r[COST])))
        robust = []
        for method in dict.fromkeys(r["method"] for r in mine):
            runs = sorted((r for r in rows if r["scene"] == scene and r["method"] == method),
                          key=lambda r: r["dt_ms"])
            for r in runs:
                if r["status"] != "ok" or not r["readout_matches"]:
                    break
                robust.append(r)
        if robust:
            out.append(dict(criterion="read-out matches at this dt and every finer one",
                            **min(robust, key=lambda r: r[COST])))
    return out


class RunLog:
    """Finished configurations in ``OUT/runs.jsonl``: a re-run with the same spec skips them.

    Every row is appended as soon as it is measured, so an interrupted study resumes where
    it stopped (``--fresh`` starts over; a changed spec starts over by itself).
    """

    def __init__(self, path: Path, spec: dict, fresh: bool):
        import hashlib
        import json

        self.path, self._json = path, json
        self.key = hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()
                                  ).hexdigest()[:16]
        self.rows = {}
        if path.exists() and not fresh:
            lines = path.read_text().splitlines()
            if lines and json.loads(lines[0]).get("spec_key") == self.key:
                for line in lines[1:]:
                    try:
                        row = json.loads(line)
                    except ValueError:   # a line cut short by an interruption
                        continue
                    self.rows[self._id(row)] = row
        if not self.rows:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"spec_key": self.key}) + "\n")

    @staticmethod
    def _id(row) -> tuple:
        return (row["sweep"], row["scene"], row["method"], float(row["dt_ms"]), row["target"],
                row["dtype"], int(row["n_neurons"]))

    def get(self, **config):
        return self.rows.get(self._id(config))

    def add(self, row: dict) -> None:
        self.rows[self._id(row)] = row
        with open(self.path, "a") as f:
            f.write(self._json.dumps(row) + "\n")


def run(spec: dict, out_dir, quick: bool = False, fresh: bool = False, log=print) -> dict:
    built = build(spec)
    with LogFile(out_dir, log) as run_log:
        return _run(spec, Path(out_dir), quick, fresh, run_log, *built)


def _run(spec, out_dir, quick, fresh, log, net, robot_scenes, pre, detector, window_s, parts):
    seed = int(spec.get("seed", 0))
    sweep, cost, stab, refset, match = (parts[n] for n in ("sweep", "cost", "stability",
                                                            "reference", "match"))
    t_start = time.perf_counter()
    wanted = list(dict.fromkeys(sweep.scenes + [cost.scene]))
    log(f"[1/5] scenes ({', '.join(wanted)}, seed {seed})")
    scenes = prepare_scenes(net, robot_scenes, pre, detector, window_s, parts, seed, wanted,
                            log)

    log(f"[2/5] reference solutions (solve_ivp, rtol {refset.rtol:g})")
    refs, ref_readouts, ref_rows = {}, {}, []
    for name, scene in scenes.items():
        refs[name] = scene.reference(refset.rtol, refset.atol)
        ref_readouts[name] = scene.readout(refs[name])
        ref_rows.append({"scene": name, "wall_s": refs[name].wall_s, "cpu_s": refs[name].cpu_s,
                         "n_spikes": int(len(refs[name].spike_i)),
                         "distance_cm": ref_readouts[name].get("distance_cm")})
        log(f"  {name}: {len(refs[name].spike_i)} spikes in {refs[name].cpu_s:.1f} s CPU")
    check_name = refset.check_scene if refset.check_scene in scenes else next(iter(scenes))
    tight = scenes[check_name].reference(refset.check_rtol, refset.atol * 1e-3)
    convergence = _convergence(refs[check_name], tight, scenes[check_name])
    convergence.update(scene=check_name, rtol=refset.rtol, check_rtol=refset.check_rtol)
    log(f"  converged: spike times move by at most {convergence['max_shift_ms']:.2e} ms "
        f"at rtol {refset.check_rtol:g} ({check_name})")

    configs = [(name, m, dt) for name in sweep.scenes for m in sweep.methods
               for dt in sorted(sweep.dt_ms)]
    log(f"[3/5] main sweep: {len(configs)} runs ({sweep.target}, {sweep.dtype})")
    rows, warmed = [], set()
    done = RunLog(out_dir / "runs.jsonl", spec, fresh)
    with log.expected(UNSTABLE_ON_PURPOSE):   # coarse steps are forced past their limits
        for j, (name, method, dt) in enumerate(configs, 1):
            n = _size(scenes[name])
            row = done.get(sweep="main", scene=name, method=method, dt_ms=dt,
                           target=sweep.target, dtype=sweep.dtype, n_neurons=n)
            if row is None:
                row = measure(scenes[name], refs[name], ref_readouts[name], method, dt,
                              sweep.target, sweep.dtype, warmed)
                row["sweep"] = "main"
                done.add(row)
            rows.append(row)
            log(f"  [{j}/{len(configs)}] {_describe(row)}")

    recommendations = recommend(rows, match)
    settings = [tuple(s) for s in cost.settings]
    if cost.include_recommended:
        for r in recommendations:
            if r["scene"] == cost.scene and r["criterion"] == "read-out matches the reference":
                settings.append((r["method"], r["dt_ms"]))
    settings = list(dict.fromkeys((m, float(dt)) for m, dt in settings))
    cost_configs = [(m, dt, t, d, n) for m, dt in settings for t in cost.targets
                    for d in cost.dtypes for n in cost.n_neurons]
    log(f"[4/5] cost sweep on {cost.scene}: {len(cost_configs)} runs "
        f"(targets × dtypes × sizes at {settings})")
    default_n = _size(scenes[cost.scene])
    with log.expected(FLOAT32_CHECK):
        for j, (method, dt, target, dtype, n) in enumerate(cost_configs, 1):
            row = done.get(sweep="cost", scene=cost.scene, method=method, dt_ms=dt,
                           target=target, dtype=dtype, n_neurons=n)
            if row is None:
                row = measure(scenes[cost.scene], refs[cost.scene], ref_readouts[cost.scene],
                              method, dt, target, dtype, warmed,
                              n_neurons=n if n != default_n else None)
                row["sweep"] = "cost"
                done.add(row)
            rows.append(row)
            log(f"  [{j}/{len(cost_configs)}] {_describe(row)}")

    log(f"[5/5] stability map ({len(sweep.methods)} methods × {stab.n_k_dt} k·dt × "
        f"{len(stab.drives)} drives) and report")
    with log.expected(UNSTABLE_ON_PURPOSE):
        smap = accuracy.stability_map(
            sweep.methods, np.geomspace(stab.k_dt_min, stab.k_dt_max, stab.n_k_dt),
            np.asarray(stab.drives, float), b=net.get("b", 0.26), model_ms=stab.model_ms,
            rate_tolerance=stab.rate_tolerance)
    write_dataset(smap, out_dir / "stability_map.zarr")

    summary = _summarise(rows, ref_rows, recommendations, convergence, smap, scenes, net,
                         sweep, time.perf_counter() - t_start)
    _write_report(out_dir, spec, summary, rows, smap, sweep, quick, parts)
    log(_human(summary, out_dir))
    return summary


def _convergence(ref: Run, tight: Run, scene) -> dict:
    n = scene.n_neurons if isinstance(scene, TuningScene) else scene.array().n_neurons
    same_counts = np.array_equal(np.bincount(ref.spike_i, minlength=n),
                                 np.bincount(tight.spike_i, minlength=n))
    shift = 0.0
    if same_counts:
        for j in range(n):
            a, b = np.sort(ref.spike_t_ms[ref.spike_i == j]), \
                np.sort(tight.spike_t_ms[tight.spike_i == j])
            if len(a):
                shift = max(shift, float(np.max(np.abs(a - b))))
    else:
        shift = accuracy.spike_time_error_ms(ref.spike_i, ref.spike_t_ms, tight.spike_i,
                                             tight.spike_t_ms, n)
    return {"same_spike_counts": bool(same_counts), "max_shift_ms": shift,
            "wall_s_tight": tight.wall_s}


def _describe(row: dict) -> str:
    head = (f"{row['scene']} {row['method']} dt={row['dt_ms']:g} {row['target']} "
            f"{row['dtype']} n={row['n_neurons']}: ")
    if row["status"] != "ok":
        return head + row["status"]
    if row["rate_map_error"] is None:
        return head + f"{row['cpu_s']:.2f} s CPU"
    return head + (f"{row['cpu_s']:.2f} s CPU, spike-time err {row['spike_time_error_ms']:.3f} "
                   f"ms, rate-map err {row['rate_map_error']:.3f}, read-out "
                   f"{'matches' if row['readout_matches'] else 'differs'}")


# -- summary and report ---------------------------------------------------------------------
def _summarise(rows, ref_rows, recommendations, convergence, smap, scenes, net, sweep,
               total_s) -> dict:
    ref_cost = {r["scene"]: r[COST] for r in ref_rows}
    for r in recommendations:
        r["speedup_vs_reference"] = ref_cost[r["scene"]] / r[COST]
        finest = [x for x in rows if x["scene"] == r["scene"] and x["sweep"] == "main"
                  and x["status"] == "ok"]
        slowest = max(finest, key=lambda x: x[COST])
        r["speedup_vs_slowest_brian2"] = slowest[COST] / r[COST]
        r["slowest_brian2_setting"] = f"{slowest['method']} dt={slowest['dt_ms']:g}"
    default = {"method": net.get("method", "euler"), "dt_ms": float(net.get("dt_ms", 0.1))}
    default_rows = [r for r in rows if r["sweep"] == "main" and r["method"] == default["method"]
                    and abs(r["dt_ms"] - default["dt_ms"]) < 1e-12]
    quick_answer = None
    qs = [r for r in recommendations if r["scene"] == "quickstart"
          and r["criterion"] == "read-out matches the reference"]
    if qs:
        q = qs[0]
        quick_answer = {k: q[k] for k in ("method", "dt_ms", "target", "dtype", "wall_s", COST,
                                          "speedup_vs_reference", "speedup_vs_slowest_brian2",
                                          "slowest_brian2_setting", "distance_error_cm",
                                          "detection_f1")}
        quick_answer["reference_cpu_s"] = ref_cost["quickstart"]
    k_max = float(np.max(ResonatorArray(**dict(net, force=True)).k))
    limits = {m: {"shipped_max_stable_k_dt": neurons.MAX_STABLE_K_DT[m],
                  "measured_max_stable_k_dt": float(smap.max_stable_k_dt.sel(integrator=m)),
                  "measured_max_accurate_k_dt": float(smap.max_accurate_k_dt.sel(integrator=m)),
                  "max_dt_ms_for_band": neurons.MAX_STABLE_K_DT[m] / k_max}
              for m in smap.integrator.values}
    return {
        "rows": rows,
        "references": ref_rows,
        "reference_convergence": {**convergence, **_convergence_verdict(convergence, rows)},
        "recommendations": recommendations,
        "quickstart_fastest_matching": quick_answer,
        "shipped_default": dict(default, default_rows=[
            {k: r.get(k) for k in ("scene", "wall_s", COST, "rate_map_error", "readout_matches")}
            for r in default_rows]),
        "stability_limits": limits,
        **count_nonfinite(rows),
        "total_wall_s": total_s,
    }


def _convergence_verdict(convergence: dict, rows: list[dict]) -> dict:
    """How far below the Brian2 errors the reference's own uncertainty lies, as measured."""
    errors = [r for r in rows if r["sweep"] == "main" and r["status"] == "ok"
              and r.get("spike_time_error_ms") is not None]
    finest = min(errors, key=lambda r: r["spike_time_error_ms"], default=None)
    out = {"smallest_brian2_error_ms": finest["spike_time_error_ms"] if finest else None,
           "smallest_error_setting": (f"{finest['scene']} {finest['method']} "
                                      f"dt={finest['dt_ms']:g} ms") if finest else None}
    shift = convergence["max_shift_ms"]
    if finest and shift > 0:
        out["error_over_shift"] = finest["spike_time_error_ms"] / shift
    out["far_below"] = bool(convergence["same_spike_counts"] and finest is not None
                            and (shift == 0 or out["error_over_shift"] >= FAR_BELOW))
    return out


FAR_BELOW = 100.0   # "far below": the smallest Brian2 error is at least this many times larger


def _convergence_text(conv: dict) -> str:
    head = (f"Each scene's reference is solve_ivp (DOP853, rtol {conv['rtol']:g}) from input "
            f"switch to switch with exact threshold crossings and resets. Re-run at rtol "
            f"{conv['check_rtol']:g} on the {conv['scene']} scene, ")
    if not conv["same_spike_counts"]:
        return head + (f"some neurons fire a different number of spikes (spike-time "
                       f"difference {fmt(conv['max_shift_ms'])} ms): the reference is not "
                       f"converged at rtol {conv['rtol']:g}, and Brian2 errors of that size "
                       f"or smaller say nothing.")
    text = (head + f"every neuron fires the same number of spikes and spike times move by at "
            f"most {fmt(conv['max_shift_ms'])} ms. ")
    if conv["smallest_brian2_error_ms"] is None:
        return text + "No Brian2 run finished to compare that with."
    compare = (f"The smallest Brian2 spike-time error here is "
               f"{fmt(conv['smallest_brian2_error_ms'])} ms ({conv['smallest_error_setting']})")
    if conv["max_shift_ms"] == 0:
        return text + compare + ": the reference did not move at all."
    ratio = fmt(conv["error_over_shift"], digits=2)
    if conv["far_below"]:
        return text + compare + f", {ratio}× the reference's shift: the reference is " \
            "converged far below every Brian2 error reported here."
    return text + compare + f", only {ratio}× the reference's shift: errors near that size " \
        "are partly the reference's own, read them with that margin."


def quick_note(sweep: Sweep, parts: dict, scenes: dict) -> str:
    """What the quick profile leaves out, from the settings that ran."""
    missing = [m for m in neurons.METHODS if m not in sweep.methods]
    stab = parts["stability"]
    note = (f"quick profile: too small to choose a setting. Methods "
            f"{', '.join(sweep.methods)} at dt {fmt(sorted(sweep.dt_ms))} ms on the "
            f"{', '.join(sweep.scenes)} scene{'s' * (len(sweep.scenes) > 1)} "
            f"({sweep.target} target)")
    if missing:
        note += (f"; {', '.join(missing)} {'is' if len(missing) == 1 else 'are'} not in the "
                 f"quick sweep, so a recommendation here is only the best of these")
    return note + (f". The stability map has {stab.n_k_dt} k·dt steps × {len(stab.drives)} "
                   f"drives (the full map {Stability.n_k_dt} × {len(Stability().drives)}): "
                   f"its limits are grid points, not the shipped ones.")


def _provenance_rows(report: Report, summary: dict, net: dict) -> None:
    """The shipped stability limits are set from this map (calibrated); the integration
    errors are measured against the reference (predicted; the paper has none)."""
    for m, v in summary["stability_limits"].items():
        report.calibrated(Calibrated(
            f"largest stable k·dt, {m}", value=v["shipped_max_stable_k_dt"],
            target=v["measured_max_stable_k_dt"], unit="model ms per step",
            source="this run's stability map; the shipped value is the full profile's "
                   "largest finite grid point, rounded down",
            how="neurons.MAX_STABLE_K_DT (refuses a coarser dt unless force=True)"))
    d = summary["shipped_default"]
    for r in d["default_rows"]:
        if r.get("rate_map_error") is None:
            continue
        report.predicted(Predicted(
            f"rate-map error of the shipped default ({d['method']}, dt {d['dt_ms']:g} ms), "
            f"{r['scene']} scene", value=r["rate_map_error"], unit="relative",
            source="this run against the solve_ivp reference", n=1,
            note="one scene run with one seed (deterministic); the paper reports no "
                 "integration error"))


def _write_report(out_dir, spec, summary, rows, smap, sweep, quick, parts) -> None:
    report = Report(out_dir, "snn-antenna: speed vs accuracy of the resonator array",
                    quick=quick, quick_note=quick_note(sweep, parts, sweep.scenes))
    report.text(spec.get("description", ""))
    _provenance_rows(report, summary, {})
    conv = summary["reference_convergence"]
    report.heading("Reference")
    report.text(_convergence_text(conv))
    report.table([{k: r[k] for k in ("scene", "cpu_s", "wall_s", "n_spikes", "distance_cm")}
                  for r in summary["references"]], "Reference runs")
    q = summary["quickstart_fastest_matching"]
    report.heading("Recommendation")
    if quick:
        report.text("Quick profile: the settings below are the best of the few the quick "
                    "sweep ran (see the banner), not a recommendation for the toolkit.")
    if q:
        report.text(
            f"Quickstart scene: the fastest setting whose decoded distance and detection match "
            f"the reference is {q['method']} at dt = {q['dt_ms']:g} ms ({q['target']}, "
            f"{q['dtype']}): {fmt(q['cpu_s'], 's')} CPU ({fmt(q['wall_s'], 's')} wall), "
            f"{q['speedup_vs_reference']:.0f}× faster than the reference "
            f"({fmt(q['reference_cpu_s'], 's')} CPU) and "
            f"{q['speedup_vs_slowest_brian2']:.0f}× faster than the slowest Brian2 setting "
            f"({q['slowest_brian2_setting']}).")
    cols = ("scene", "criterion", "method", "dt_ms", "target", "dtype", "cpu_s", "wall_s",
            "speedup_vs_reference", "spike_time_error_ms", "spike_count_error",
            "rate_map_error", "distance_error_cm", "detection_f1")
    report.table([{c: r.get(c) for c in cols} for r in summary["recommendations"]],
                 "Recommended settings per scene, with their measured cost and error")
    d = summary["shipped_default"]
    report.table([dict(setting=f"{d['method']} dt={d['dt_ms']:g} ms", **r)
                  for r in d["default_rows"]], "The shipped default, as measured")
    report.heading("Pareto fronts")
    report.figure(_pareto_figure(rows), "pareto",
                  "Error against CPU time per scene (main sweep): colour is the method, the "
                  "marker's shape the step dt; the black line is the Pareto front. Runs that "
                  "raised NumericalInstabilityError are not drawn. CPU time, not wall time, "
                  "ranks runs: the machine is shared.")
    report.heading("Cost: targets, precision, array size")
    cost_cols = ("method", "dt_ms", "target", "dtype", "n_neurons", "cpu_s", "wall_s",
                 "compile_s", "rate_map_error", "readout_matches", "status")
    report.table([{c: r.get(c) for c in cost_cols} for r in rows if r["sweep"] == "cost"],
                 "Cost sweep (errors only where a reference of the same size exists)")
    report.heading("Stability map")
    report.figure(_stability_figure(smap), "stability_map",
                  "Constant drive I against k·dt, from the reset point: accurate (steady rate "
                  "within tolerance of the reference), inaccurate but finite, non-finite or "
                  "runaway (|v| or |u| above 1e6 at any step).")
    report.table([dict(method=m, **v) for m, v in summary["stability_limits"].items()],
                 "Stability limits (k·dt in model ms per step)")
    n_silent = summary["nonfinite_without_exception"]
    report.text(
        f"{summary['raised_instability']} run(s) raised NumericalInstabilityError (shown as "
        f"non-finite); {n_silent} run(s) finished without an exception yet produced a "
        f"non-finite spike time or score" + (" (listed below)." if n_silent else "."))
    report.heading("All runs")
    all_cols = ("sweep", "scene", "method", "dt_ms", "target", "dtype", "n_neurons", "cpu_s",
                "wall_s", "status") + ERRORS
    report.table([{c: r.get(c) for c in all_cols} for r in rows], "Every configuration")
    report.write(summary, spec, sweep.target)


def _pareto_figure(rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    main = [r for r in rows if r["sweep"] == "main"]
    scenes = list(dict.fromkeys(r["scene"] for r in main))
    errors = ("rate_map_error", "spike_time_error_ms")
    names = {"rate_map_error": "rate-map error (relative)",
             "spike_time_error_ms": "spike-time error (ms)"}
    fig, axes = plt.subplots(len(errors), len(scenes), figsize=(4.2 * len(scenes) + 1.6, 6.4),
                             squeeze=False, layout="constrained")
    colours = dict(zip(neurons.METHODS, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    steps = sorted({r["dt_ms"] for r in main})
    shapes = dict(zip(steps, "osD^vPX*hp"))
    methods = list(dict.fromkeys(r["method"] for r in main))
    for col, scene in enumerate(scenes):
        mine = [r for r in main if r["scene"] == scene and r["status"] == "ok"]
        for row, err in enumerate(errors):
            ax = axes[row][col]
            for r in mine:
                ax.scatter(r[COST], max(r[err], 1e-6), s=30, marker=shapes[r["dt_ms"]],
                           color=colours.get(r["method"]), edgecolor="k", linewidth=0.4,
                           alpha=0.85)
            front = pareto_front(mine, err)
            ax.plot([r[COST] for r in front], [max(r[err], 1e-6) for r in front],
                    color="k", lw=0.8, drawstyle="steps-post")
            _scale(ax.set_xscale, [r[COST] for r in mine])
            _scale(ax.set_yscale, [max(r[err], 1e-6) for r in mine])
            ax.set_xlabel("CPU time (s)")
            ax.set_ylabel(names[err])
            ax.set_title(f"{scene} scene", fontsize=10)
    handles = [Line2D([], [], ls="", marker="o", color=colours.get(m), label=m)
               for m in methods]
    handles += [Line2D([], [], ls="", marker=shapes[dt], color="grey", markeredgecolor="k",
                       label=f"dt {dt:g} ms") for dt in steps]
    fig.legend(handles=handles, loc="outside right center", fontsize=8, frameon=False)
    return fig


def _scale(set_scale, values) -> None:
    """Log only where the values span more than a decade: a narrow range reads best linear.
    Tick labels are plain numbers (0.03, not 3×10⁻²), few enough not to collide."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    axis = set_scale.__self__.xaxis if set_scale.__name__ == "set_xscale" \
        else set_scale.__self__.yaxis
    values = [v for v in values if v is not None and v > 0]
    if values and max(values) / min(values) > 10:
        set_scale("log")
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(FuncFormatter(
            lambda v, _: f"{v:g}" if v > 0 and round(v / 10 ** np.floor(np.log10(v))) in (2, 5)
            else ""))
    else:
        axis.set_major_locator(MaxNLocator(5))


def _stability_figure(smap):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    methods = list(smap.integrator.values)
    fig, axes = plt.subplots(1, len(methods), figsize=(3.3 * len(methods) + 0.8, 4.0),
                             sharey=True, squeeze=False, layout="constrained")
    colours = ["#4caf50", "#ffc107", "#d32f2f"]
    cmap = ListedColormap(colours)
    k_dt, drives = smap.k_dt.values, smap.I.values
    for ax, m in zip(axes[0], methods):
        ax.pcolormesh(np.arange(len(drives) + 1), np.arange(len(k_dt) + 1),
                      smap.status.sel(integrator=m).values, cmap=cmap, vmin=0, vmax=2,
                      edgecolors="white", linewidth=0.3)
        limit = float(smap.max_stable_k_dt.sel(integrator=m))
        ax.set_title(f"{m} (finite to k·dt {limit:.3g})", fontsize=9)
        _cell_ticks(ax.set_xticks, ax.set_xticklabels, drives, most=7)
        ax.set_xlabel("constant drive I")
        _cell_ticks(ax.set_yticks, ax.set_yticklabels, k_dt, most=13)
    axes[0][0].set_ylabel("k·dt (model ms per step)")
    fig.legend(handles=[Patch(color=c, label=t) for c, t in
                        zip(colours, ("accurate", "inaccurate but finite",
                                      "non-finite or runaway"))],
               loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    return fig


def _cell_ticks(set_ticks, set_labels, values, most: int) -> None:
    """A tick at the centre of every cell, or of every few cells when there are many."""
    step = max(1, int(np.ceil(len(values) / most)))
    idx = np.arange(0, len(values), step)
    set_ticks(idx + 0.5)
    set_labels([f"{values[i]:.3g}" for i in idx], fontsize=7)


def _human(s: dict, out_dir) -> str:
    lines = []
    q = s["quickstart_fastest_matching"]
    if q:
        lines.append(f"quickstart: fastest setting matching the reference read-out: "
                     f"{q['method']} dt={q['dt_ms']:g} ms ({q['target']}, {q['dtype']}), "
                     f"{q['cpu_s']:.2f} s CPU, {q['speedup_vs_reference']:.0f}x faster than the "
                     f"reference")
    for m, v in s["stability_limits"].items():
        lines.append(f"{m}: finite to k·dt {v['measured_max_stable_k_dt']:.3g} "
                     f"(shipped limit {v['shipped_max_stable_k_dt']:g})")
    lines.append(f"report in {out_dir}/report.html ({s['total_wall_s']:.0f} s)")
    return "\n".join(lines)
