"""The gating study's plan: its spec's sections as dataclasses, checked before any work, and
the parts built from them (the array, the course, the preprocessing settings, the blind
read-out, the gate, the recorded drives' split); its cost at the seeds it is expected to
run."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError, check
from ...engine.cost import (
    Build,
    codings_engine,
    engine_of,
    gate_training_runs,
    max_workers,
    readout_seconds,
    stages_estimate,
    standalone_build,
)
from ...engine.codings import structure as compiled_structure
from ...networks.gate import SpeedGate
from ...networks.resonators import ResonatorArray
from ...preprocess import make_coder
from ...readout.contacts import detector_from_spec
from ...readout.detection import BlindReadOut
from ...sources import antenna
from ...sources.scenes import CourseLayout, CourseScene, SpeedProfile, drive, ramp
from ..contract import COMMON, Plan, data_folder
from ...networks.resonators import array_section, check_rates
from ...preprocess import Preprocessing, chain_section
from ..sections import scene_section
from .drives import RecordedSplit, split_drives

SECTIONS = ("network", "stimulus", "preprocess", "calibration", "readout", "course", "sweep",
            "gate", "evaluation", "data")
OPTIONS = (*COMMON, "fresh", "scheduler", "data")
LOW_HIGH_CM_S = (12.0, 27.0)  # the paper's two speeds (Fig. 9)
# Seed streams (first entry of every spawn key) and, within a scene's stream, its two draws.
SWEEP_SCENES, EVALUATION_SCENES, EVALUATION_STEPS = 0, 1, 2
COURSE_DRAW, NOISE_DRAW = 0, 1


# -- the spec ------------------------------------------------------------------------------
@dataclass
class SweepSettings:
    thresholds_g: list = (0.0, 0.1)
    speeds_cm_s: list = (0.0, 12.0)
    n_scenes: int = 3
    scene_s: float = 15.0
    settle_s: float = 1.0
    target: str | None = None
    codings_per_run: int = 200
    workers: int = 0          # Dask worker processes (0: one per core; 1: this process)

    def __post_init__(self):
        bounds.declared(self)
        th = self.thresholds_g = np.asarray(self.thresholds_g, dtype=float)
        check(th.ndim == 1 and len(th) >= 2 and np.all(np.isfinite(th)) and np.all(th >= 0)
              and np.all(np.diff(th) > 0), "thresholds_g", th.tolist(),
              "at least two increasing thresholds >= 0 g")
        v = self.speeds_cm_s = np.asarray(self.speeds_cm_s, dtype=float)
        if v.ndim != 1 or len(v) < 2 or not np.all(np.isfinite(v)) or np.any(v < 0):
            raise SpecError("speeds_cm_s", v.tolist(), "at least two finite speeds >= 0 cm/s")
        check(np.all(np.diff(v) > 0), "speeds_cm_s", v.tolist(), "increasing speeds")
        for name in ("n_scenes", "codings_per_run"):
            value = getattr(self, name)
            check(isinstance(value, int) and value >= 1, name, value, "an integer >= 1")
        check(0 <= self.settle_s < self.scene_s, "settle_s", self.settle_s,
              "a time in [0, scene_s) s")
        check(isinstance(self.workers, int) and self.workers >= 0, "workers", self.workers,
              "an integer >= 0 (0: one Dask worker per CPU core; 1: this process)")
        check(self.target in (None, "numpy", "cython", "standalone"), "target", self.target,
              "'standalone' (compiled once per worker, re-run per batch of codings), 'cython' "
              "or 'numpy'")


@dataclass
class EvaluationSettings:
    pilot_seeds: int = 5
    max_seeds: int = 20
    margin_f1: float = 0.02       # the F1 difference the comparison must resolve
    speeds_cm_s: list | None = None   # default: the swept speeds the gate is not trained on
    n_steps: int = 4              # random speed steps per scene
    other_terrain: str = "flat"
    # Which family of evaluation scenes: 0 gives the reported ones; any other integer draws
    # scenes never used for them (validation seeds, to tune settings on).
    scene_stream: int = 0
    # Coders evaluated beside the study's own (``[preprocess]``), each with the gate's Th on
    # the same scenes, paired by seed: label -> {coder, coder_amplitude, coder_options}.
    coders: dict = field(default_factory=dict)
    # With recorded drives (``data``): the share of the drives with labelled contacts held out
    # for the evaluation (split by drive, seeded); the others are the sweep's and the gate's.
    held_out_drives: float = 0.5

    def __post_init__(self):
        bounds.declared(self)
        check(isinstance(self.held_out_drives, (int, float)) and
              0 < self.held_out_drives < 1, "held_out_drives", self.held_out_drives,
              "a share in (0, 1) of the recorded drives held out for the evaluation")
        check(isinstance(self.scene_stream, int) and self.scene_stream >= 0, "scene_stream",
              self.scene_stream, "an integer >= 0")
        check(isinstance(self.coders, dict), "coders", self.coders,
              "a table of named coders, e.g. {delta = {coder = \"delta\"}}")
        for label in self.coders:
            self.coder(label)      # each coder's own checks, before any work
        for name in ("pilot_seeds", "max_seeds", "n_steps"):
            value = getattr(self, name)
            check(isinstance(value, int) and value >= 1, name, value, "an integer >= 1")
        check(self.max_seeds >= self.pilot_seeds, "max_seeds", self.max_seeds,
              f"at least pilot_seeds ({self.pilot_seeds})")
        check(np.isfinite(self.margin_f1) and 0 < self.margin_f1 < 1, "margin_f1",
              self.margin_f1, "an F1 difference in (0, 1) to resolve")
        antenna.terrain_noise_rms_g(0.0, self.other_terrain)   # refuses an unknown terrain

    def coder(self, label: str):
        """Coder ``label`` of ``coders``, checked (``preprocess.make_coder``); Th comes from
        the gate at each sample."""
        table = self.coders[label]
        keys = ("coder", "coder_amplitude", "coder_options")
        check(isinstance(table, dict) and set(table) <= set(keys), f"coders.{label}", table,
              f"a table of {', '.join(keys)}")
        options = table.get("coder_options", {})
        check(isinstance(options, dict), f"coders.{label}.coder_options", options,
              "a table of the coder's own parameters")
        try:
            return make_coder(table.get("coder", "square"), table.get("coder_amplitude", 0.15),
                              0.0, **options)
        except SpecError as exc:
            raise SpecError(f"coders.{label}.{exc.field}", exc.value, exc.accepted) from None

    def held_out(self, swept: np.ndarray, trained: np.ndarray) -> np.ndarray:
        """The speeds to evaluate: the spec's, or the swept ones the gate does not learn,
        failing those halfway between the trained ones."""
        if self.speeds_cm_s is not None:
            held = np.asarray(self.speeds_cm_s, dtype=float)
        else:
            held = swept[~np.isin(swept, trained)]
            if len(held) == 0:
                t = np.unique(trained)
                held = (t[:-1] + t[1:]) / 2 if len(t) > 1 else t + 1.0
        if held.ndim != 1 or len(held) < 1 or not np.all(np.isfinite(held)):
            raise SpecError("speeds_cm_s", self.speeds_cm_s, "a list of finite speeds")
        check(not np.any(np.isin(held, trained)), "speeds_cm_s", held.tolist(),
              f"speeds the gate is not trained on (trained: {trained.tolist()})")
        return held


@dataclass
class CalibrationSettings:
    """The drive the preprocessing is fitted on: in the open, never a scored scene."""
    speed_cm_s: float = 15.0
    duration_s: float = 5.0
    seed: int = 99991

    def __post_init__(self):
        bounds.declared(self)
        bounds.seed("seed", self.seed)
        check(np.isfinite(self.duration_s) and self.duration_s >= 1.0, "duration_s",
              self.duration_s, "a calibration drive of at least 1 s")
        check(isinstance(self.seed, int), "seed", self.seed, "an integer seed")
        check(float(self.speed_cm_s) > 0, "speed_cm_s", self.speed_cm_s,
              "a speed > 0 cm/s (standing still, the axes see only sensor noise to align on)")


@dataclass
class Parts:
    seed: int
    array: ResonatorArray
    scene: CourseScene
    preprocess: Preprocessing
    calibration: CalibrationSettings
    readout: BlindReadOut
    course: CourseLayout
    sweep: SweepSettings
    gate: SpeedGate
    train_speeds: np.ndarray
    evaluation: EvaluationSettings
    held_out_speeds: np.ndarray
    chain: object = None      # fitted on first use (``calibrated_chain``)
    data: RecordedSplit | None = None     # recorded drives in place of every scene


def _section(spec: dict, name: str, target, **kw):
    return target(**specs.check_section(spec, name, target, **kw))


def plan(spec: dict) -> Plan:
    """Check the whole spec and build every part before any simulation runs."""
    parts = make_parts(spec)
    data_folder(spec)
    return Plan("gating_threshold", spec, parts, estimate)


def make_parts(spec: dict) -> Parts:
    """Check the whole spec and build every part (a sweep's worker builds them again from the
    resolved spec: ``scenes.ThresholdSweep``)."""
    specs.check_top_level(spec, SECTIONS)
    array = array_section(spec)
    scene = scene_section(spec, course=True)
    pre, _ = chain_section(spec, [scene], gated=True)
    with specs.section("calibration"):
        cal = _section(spec, "calibration", CalibrationSettings)
        drive(scene, SpeedProfile("constant", float(cal.speed_cm_s)), 1.0, []).validate()
    detector, window_s = detector_from_spec(spec)
    with specs.section("course"):
        course = _section(spec, "course", CourseLayout)
    with specs.section("sweep"):
        sweep = _section(spec, "sweep", SweepSettings)
        bounds.positive_seconds("scene_s", sweep.scene_s)
        v = sweep.speeds_cm_s
        drive(scene, ramp(v.min(), v.max(), 1.0), 1.0, []).validate()
    with specs.section("gate"):
        table = dict(specs.check_section(spec, "gate", SpeedGate, extra=["train_speeds_cm_s"]))
        train = np.asarray(table.pop("train_speeds_cm_s", v[::2]), dtype=float)
        missing = sorted(set(train.tolist()) - set(v.tolist()))
        if missing:
            raise SpecError("train_speeds_cm_s", train.tolist(),
                            f"speeds of the sweep (not swept: {missing})")
        table["speed_range_cm_s"] = tuple(table.get("speed_range_cm_s",
                                                    (float(v.min()), float(v.max()))))
        table.setdefault("seed", int(spec.get("seed", 0)))
        gate = SpeedGate(**table)
        gate.check_speeds(v, "sweep.speeds_cm_s")
    with specs.section("evaluation"):
        ev = _section(spec, "evaluation", EvaluationSettings)
        held = gate.check_speeds(ev.held_out(v, train), "speeds_cm_s")
    check_rates(array, [scene])
    readout = BlindReadOut(array, detector, window_s, scene.rate_hz, sweep.settle_s,
                           sweep.target)
    seed = int(spec.get("seed", 0))
    return Parts(seed, array, scene, pre, cal, readout, course, sweep, gate, train, ev, held,
                 data=split_drives(spec, scene, sweep, ev.held_out_drives, seed))


def estimate(parts: Parts):
    """Every Brian2 run of the study: the sweep's codings, Fig. 9's, the gate's training and
    the evaluation at ``expected_seeds``, codings grouped as the study groups them and shared
    among its workers."""
    sw, array, ev = parts.sweep, parts.array, parts.evaluation
    workers = sw.workers or max_workers()
    engine = codings_engine(sw.target or array.target)

    def codings(n: int, seconds: float = sw.scene_s) -> list:
        # the compiled group always holds codings_per_run codings (a short run is padded);
        # its project is one per scene length (compiled once, or found compiled on disk)
        size = sw.codings_per_run if engine == "codings" else min(n, sw.codings_per_run)
        build = standalone_build(compiled_structure(
            array, round(seconds * parts.scene.rate_hz), parts.scene.rate_hz,
            sw.codings_per_run)) if engine == "codings" else Build("offline array",
                                                                   array.compiled())
        runs = [(seconds, array.dt_ms, size * array.n_neurons, engine,
                 build)] * -(-n // sw.codings_per_run)
        return runs[:-(-len(runs) // workers)] if workers > 1 else runs

    n_th, n_v = len(sw.thresholds_g), len(sw.speeds_cm_s)
    gate = ("gate", {"epochs": parts.gate.epochs, "present_s": parts.gate.present_s},
            gate_training_runs(parts.gate, len(parts.train_speeds), n_v))
    if parts.data is not None:       # recorded drives: coded once per Th, no Fig. 9
        split = parts.data
        longest = max(split.drives.dataset["n_samples"].values) / split.drives.rate_hz
        n_train, n_held = len(split.training), len(split.held_out)
        return stages_estimate("the threshold sweep on the training drives, the gate and the "
                               "evaluation on the held-out drives", [
            ("data", str(split.drives.path), codings(n_train * n_th, longest)), gate,
            ("data", str(split.drives.path),
             codings(n_held * (n_th + 2 + len(ev.coders)), longest))])
    profiles = len(parts.held_out_speeds) + 2 + (
        2 if ev.other_terrain != parts.scene.terrain else 0)
    scenes = expected_seeds(ev) * profiles
    recall = [(sw.scene_s, parts.gate.dt_ms, (parts.gate.n_speed_neurons + 2) * scenes,
               engine_of(parts.gate.target), Build("speed gate", parts.gate.compiled()))]
    windows = sw.scene_s / parts.readout.window_s   # each coding's rate map, read in Python
    n_sweep, n_fig9 = n_v * sw.n_scenes * n_th, len(LOW_HIGH_CM_S) * sw.n_scenes * 3
    # each scene coded at the fixed Th around Th*'s range, by the lookup table, the gate and
    # each other coder
    n_fixed = max(1, round(FIXED_TH_SHARE * n_th))
    n_evaluated = scenes * (n_fixed + 2 + len(ev.coders))
    return stages_estimate(f"the threshold sweep, Fig. 9, the gate and the evaluation (at "
                           f"{expected_seeds(ev)} seeds of its budget of {ev.max_seeds})", [
        ("sweep.n_scenes", sw.n_scenes, codings(n_sweep),
         readout_seconds(n_sweep, windows, workers)),
        ("sweep.n_scenes", sw.n_scenes, codings(n_fig9),
         readout_seconds(n_fig9, windows, workers)),
        gate,
        ("evaluation.max_seeds", ev.max_seeds, codings(n_evaluated) + recall,
         readout_seconds(n_evaluated, windows, workers))])


# The share of the sweep's thresholds the evaluation codes each scene at: those around the
# fitted Th*'s range (known only after the sweep); the full profile's run kept 15 of 23.
FIXED_TH_SHARE = 15 / 23


def expected_seeds(ev: EvaluationSettings) -> int:
    """The seeds an evaluation is expected to run: its pilot's, and ``MORE_SEEDS`` of that
    again (the pilot's spread decides, up to ``max_seeds``)."""
    return min(ev.max_seeds, ev.pilot_seeds + math.ceil(MORE_SEEDS * ev.pilot_seeds))


# The full profile's runs needed 8 seeds after a pilot of 5.
MORE_SEEDS = 0.6


def sweep_settings(spec: dict, parts: Parts | None = None) -> dict:
    """What makes two sweeps the same (the store's fingerprint): not the gate or evaluation
    settings, nor where it runs, so changing those reuses a finished sweep; with recorded
    drives, the data set's key and which drives trained."""
    resolved = specs.resolved(spec)
    settings = {k: resolved.get(k) for k in ("seed", "network", "stimulus", "preprocess",
                                             "readout", "course", "sweep")}
    settings["sweep"] = {k: v for k, v in (settings["sweep"] or {}).items() if k != "workers"}
    if parts is not None and parts.data is not None:
        split = parts.data
        settings["data"] = {"key": split.drives.provenance["key"], **split.roles()}
    return settings
