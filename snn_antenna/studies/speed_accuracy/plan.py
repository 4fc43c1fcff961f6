"""The speed/accuracy study's plan: the array's table, the robot scenes (the quickstart's
generated or recorded, the bench contact), the preprocessing settings, the detector and
every sweep's settings, checked before any simulation; its cost."""
from __future__ import annotations

import dataclasses
import math

from ...core import bounds
from ...core import spec as specs
from ...core.errors import check
from ...engine import rates
from ...engine.cost import engine_of, stages_estimate
from ...engine.devices import DTYPES, RUNTIME_TARGETS, TARGETS, TuningStimuli
from ...engine.devices import WARM_UP_MS as DEVICE_WARM_UP_MS
from ...evaluation.accuracy import Match, StabilityGrid
from ...evaluation.bands import (BENCH_BANDS, CHOSEN, COST_SAMPLE_SHARE, SMALL_SIGNAL_EULER,
                                 WARM_UP_MS, BandStudy, accurate_dt_ms, candidate_steps)
from ...networks import neurons, reference
from ...networks.resonators import ResonatorArray
from ...readout.contacts import detector_from_spec
from ..contract import COMMON, Plan, data_folder
from ...networks.resonators import array_section, check_rates, network_table
from ...preprocess import Preprocessing, chain_section
from ..sections import scene_section, source_section
from . import timing
from .precision import Precision

SECTIONS = ("network", "stimulus", "bench", "preprocess", "readout", "tuning", "sweep", "cost",
            "stability", "reference", "match", "bands", "precision", "data")
OPTIONS = (*COMMON, "fresh", "data")
SCENES = ("tuning", "quickstart", "bench")


def _names_from(values, known, field: str) -> None:
    for v in values:
        check(v in known, field, values, f"names from {list(known)}")


@dataclasses.dataclass
class Sweep:
    """The main sweep: every method × dt on every scene, at one target and float type."""
    scenes: list = dataclasses.field(default_factory=lambda: list(SCENES))
    methods: list = dataclasses.field(default_factory=lambda: list(neurons.METHODS))
    dt_ms: list = dataclasses.field(default_factory=lambda: [0.005, 0.01, 0.025, 0.05, 0.1,
                                                            0.2, 0.5, 1.0])
    target: str = "cython"
    dtype: str = "float64"

    def __post_init__(self):
        bounds.declared(self)
        _names_from(self.scenes, SCENES, "scenes")
        _names_from(self.methods, neurons.METHODS, "methods")
        check(len(self.dt_ms) >= 1 and all(isinstance(d, (int, float)) and 0 < d <= 1.0
                                           for d in self.dt_ms),
              "dt_ms", self.dt_ms, "steps in (0, 1] ms")
        check(self.target in RUNTIME_TARGETS, "target", self.target,
              "'numpy' or 'cython' (the runtime targets; the cost sweep covers standalone)")
        check(self.dtype in DTYPES, "dtype", self.dtype, f"one of {list(DTYPES)}")


@dataclasses.dataclass
class Cost:
    """Targets × dtypes × array sizes at ``settings`` (plus the quickstart recommendation)."""
    scene: str = "quickstart"
    settings: list = dataclasses.field(default_factory=lambda: [["euler", 0.1]])
    include_recommended: bool = True
    targets: list = dataclasses.field(default_factory=lambda: list(TARGETS))
    dtypes: list = dataclasses.field(default_factory=lambda: list(DTYPES))
    n_neurons: list = dataclasses.field(default_factory=lambda: [24, 2400])

    def __post_init__(self):
        bounds.declared(self)
        check(self.scene in ("quickstart", "bench"), "scene", self.scene,
              "'quickstart' or 'bench'")
        _names_from(self.targets, TARGETS, "targets")
        _names_from(self.dtypes, DTYPES, "dtypes")
        for n in self.n_neurons:
            check(isinstance(n, int) and 1 <= n <= 100_000, "n_neurons", self.n_neurons,
                  "integers in [1, 100000]")
        for s in self.settings:
            check(isinstance(s, list) and len(s) == 2 and s[0] in neurons.METHODS
                  and isinstance(s[1], (int, float)) and 0 < s[1] <= 1, "settings",
                  self.settings, "pairs [method, dt_ms] with dt_ms in (0, 1]")


@dataclasses.dataclass
class ReferenceSettings:
    rtol: float = reference.DEFAULT_RTOL
    atol: float = reference.DEFAULT_ATOL
    check_rtol: float = 1e-12   # the convergence check re-runs one scene at this tolerance
    check_scene: str = "bench"
    # ... and at this fraction of atol (tightened with rtol, so atol does not cap the check)
    check_atol_factor: float = 1e-3

    def __post_init__(self):
        bounds.declared(self)
        bounds.number("atol", self.atol, 0.0)
        bounds.number("check_atol_factor", self.check_atol_factor, 0.0)
        check(1e-14 <= self.check_rtol < self.rtol <= 1e-6, "check_rtol", self.check_rtol,
              "a tolerance tighter than rtol (both in [1e-14, 1e-6])")
        check(self.check_scene in SCENES, "check_scene", self.check_scene, f"one of {SCENES}")


@dataclasses.dataclass
class Parts:
    """Every part of the study, built and checked from the spec before any simulation."""
    net: dict
    robot_scenes: dict
    preprocess: Preprocessing
    detector: object
    window_s: float
    tuning: TuningStimuli
    sweep: Sweep
    cost: Cost
    stability: StabilityGrid
    reference: ReferenceSettings
    match: Match
    bands: BandStudy
    precision: Precision


def plan(spec: dict) -> Plan:
    """Check the whole spec and build every part before any simulation runs."""
    specs.check_top_level(spec, SECTIONS)
    data_folder(spec)
    net = network_table(spec)
    array = array_section(spec)
    robot_scenes = {"quickstart": source_section(spec), "bench": scene_section(spec, "bench")}
    pre, _ = chain_section(spec, robot_scenes.values())
    detector, window_s = detector_from_spec(spec)
    parts = {}
    for name, cls in (("tuning", TuningStimuli), ("sweep", Sweep), ("cost", Cost),
                      ("stability", StabilityGrid), ("reference", ReferenceSettings),
                      ("match", Match), ("bands", BandStudy), ("precision", Precision)):
        with specs.section(name):
            parts[name] = cls(**specs.check_section(spec, name, cls))
    with specs.section("tuning"):        # one neuron per array neuron and frequency
        bounds.integer("n_freqs", parts["tuning"].n_freqs, 2, 10_000)
    check_rates(array, robot_scenes.values())
    return Plan("speed_accuracy", spec,
                Parts(net, robot_scenes, pre, detector, window_s, **parts), estimate)


# CPU seconds of the exact reference (solve_ivp, rtol 1e-10, ``networks.reference``) per
# neuron, simulated second and Hz of the neuron's preferred frequency: its steps follow the
# oscillation. The full profile's log (AMD EPYC 2 cores, load 2): 16.6 s for the tuning scene
# (288 neurons x 2 s, mean 15.9 Hz), 9.2 s for the quickstart scene (24 x 16 s), 4.2 s for
# the low band's sample events (24 x 8 x 0.5 s, mean 22 Hz), 39 s and 73 s for the high and
# rod bands' (twice 24 x 8 x 0.5 s, mean 190 and 218 Hz): 1.0e-3 to 1.8e-3; the highest.
REFERENCE_S_PER_NEURON_S_HZ = 1.8e-3
REFERENCE_LOAD = 2.0    # the load it was measured at (``rates.measured_at``)


def _mean_hz(band_hz) -> float:
    """The mean preferred frequency of neurons spaced evenly in log frequency over
    ``band_hz``."""
    lo, hi = (float(f) for f in band_hz)
    return lo if hi <= lo else (hi - lo) / math.log(hi / lo)


def _sampled(seconds: float, dt_ms: float, n: int, engine: str) -> list:
    """A runtime setting timed on a sample (``timing.timed_sample``): a warm-up, its first
    ``WARM_UP_MS`` and its first ``timing.SAMPLE_S`` (at most the scene)."""
    sample = timing.sample_seconds(seconds)
    return [(DEVICE_WARM_UP_MS / 1000, dt_ms, n, engine)] * 2 + [(sample, dt_ms, n, engine)]


def estimate(parts: Parts):
    """The references (solve_ivp), the main sweep (every scene at every method and dt in one
    compiled run, and a timed sample per scene and method on its target), the cost sweep
    (its settings at every target, float type and array size: runtime targets on a timed
    sample, standalone whole, own-size errors from one compiled run per float type), the
    stability map (one compiled run), the bench bands (their sample events at every method
    and step, and the tuning that recalibrates them) and the sweep engine's precision grid
    (per float type)."""
    array = ResonatorArray(**dict(parts.net, force=True))
    seconds = {"tuning": parts.tuning.duration_s,
               **{name: scene.duration_s for name, scene in parts.robot_scenes.items()}}
    size = {"tuning": array.n_neurons * parts.tuning.n_freqs}
    sweep, cost = parts.sweep, parts.cost
    scenes = list(dict.fromkeys(sweep.scenes + [cost.scene]))
    neuron_s = sum(size.get(s, array.n_neurons) * seconds[s] for s in scenes)
    check_scene = parts.reference.check_scene
    check_scene = check_scene if check_scene in scenes else scenes[0]
    # the convergence check: the check scene again, tighter (about twice the work)
    neuron_s += 2 * size.get(check_scene, array.n_neurons) * seconds[check_scene]
    references = neuron_s * _mean_hz(array.band_hz) * REFERENCE_S_PER_NEURON_S_HZ
    # the main sweep: one compiled run, a group per method and dt holding every scene's
    # neurons for the longest scene (engine.settings_runs); then per scene and method one
    # timed sample on the sweep's target, at its finest step (main_sweep)
    longest = max(seconds[s] for s in sweep.scenes)
    neurons_all = sum(size.get(s, array.n_neurons) for s in sweep.scenes)
    main = [(longest, float(dt), neurons_all, "codings") for dt in sweep.dt_ms
            ] * len(sweep.methods)
    for s in sweep.scenes:
        main += _sampled(seconds[s], float(min(sweep.dt_ms)), size.get(s, array.n_neurons),
                         engine_of(sweep.target)) * len(sweep.methods)
    # the recommendation is the fastest setting that matches: sized as the spec's settings
    settings = [tuple(s) for s in cost.settings] * (2 if cost.include_recommended else 1)
    costs = []
    for _, dt in settings:
        for t in cost.targets:
            for n in cost.n_neurons:
                if t == "cpp_standalone":   # the whole scene, its binary kept on disk
                    costs.append((seconds[cost.scene], float(dt), n, "standalone"))
                else:
                    costs += _sampled(seconds[cost.scene], float(dt), n, engine_of(t))
    costs *= len(cost.dtypes)
    if set(cost.targets) - {"cpp_standalone"}:   # own-size errors: a compiled run per dtype
        costs += [(seconds[cost.scene], float(dt), array.n_neurons, "codings")
                  for _, dt in settings] * len(cost.dtypes)
    stab = parts.stability          # every neuron runs model_ms at the finest k·dt
    stability = [(stab.model_ms / stab.k_dt_min / 1000.0, 1.0,
                  stab.n_k_dt * len(stab.drives) * len(sweep.methods), "codings")]
    bands = parts.bands
    events = len(bands.materials) * len(bands.positions_cm) * bands.repetitions
    band_runs, band_references = [], 0.0
    for name in bands.bands:
        band = BENCH_BANDS[name]
        calibrated = name in bands.calibrate
        # the exact reference of the sample events (again at the recalibrated Hz per k)
        band_references += ((2 if calibrated else 1) * events * band.n_neurons
                            * bands.duration_s * _mean_hz(band.band_hz)
                            * REFERENCE_S_PER_NEURON_S_HZ)
        # the small-signal setting, then every method at its candidate steps (at the band's
        # own Hz per k: a recalibration moves them little): one compiled run of them all
        # over the sample events (at two Hz per k); then the small-signal setting and each
        # method at its finest candidate timed on the target (a warm-up, its first
        # WARM_UP_MS and its first share of the window) on a group of at least cost_events
        # events, the coarser steps costed by steps (main_sweep.band_spikes,
        # evaluation.bands.sampled_cost)
        group = band.n_neurons * max(events, bands.cost_events)
        per_method = [candidate_steps(band, method, None, bands.coarser_steps)
                      for method in bands.methods]
        steps = [SMALL_SIGNAL_EULER.dt_ms] + [step for mine in per_method for step in mine]
        band_runs += [(bands.duration_s, step, 2 * band.n_neurons * events, "codings")
                      for step in steps]
        sample = min(max(bands.duration_s * COST_SAMPLE_SHARE, 2 * WARM_UP_MS / 1000),
                     bands.duration_s)
        timed = [SMALL_SIGNAL_EULER.dt_ms] + [mine[0] for mine in per_method]
        band_runs += [(window, step, group, engine_of(bands.target)) for step in timed
                      for window in (WARM_UP_MS / 1000, WARM_UP_MS / 1000, sample)]
        if calibrated:
            # the driven tuning at the small-signal setting on the target, then compiled at
            # rk4's accurate step and at the chosen one (sized as the shipped choice)
            tuned = band.n_neurons * bands.n_freqs
            fine = accurate_dt_ms(band, "rk4")
            chosen = CHOSEN[name].dt_ms if name in CHOSEN else fine
            band_runs += [(bands.tuning_duration_s, SMALL_SIGNAL_EULER.dt_ms, tuned,
                           engine_of(bands.target)),
                          (bands.tuning_duration_s, fine, tuned, "codings"),
                          (bands.tuning_duration_s, chosen, tuned, "codings")]
    precision = parts.precision
    points = precision.n_k * len(precision.amplitudes) * precision.n_freqs
    references = rates.measured_at(references, REFERENCE_LOAD)
    band_references = rates.measured_at(band_references, REFERENCE_LOAD)
    return stages_estimate("the references, the method x dt sweep, the cost sweep, the "
                           "stability map, the bench bands and the precision grid", [
        ("reference.rtol", parts.reference.rtol, [], references),
        ("sweep.dt_ms", sweep.dt_ms, main), ("cost.n_neurons", cost.n_neurons, costs),
        ("stability.model_ms", stab.model_ms, stability),
        ("bands.repetitions", bands.repetitions, band_runs, band_references),
        ("precision.n_k", precision.n_k,
         [(precision.duration_s, 0.1, points, "standalone")] * len(precision.dtypes))])
