"""Gating threshold: how the coder's Th must follow speed, and a spiking gate that learns it.

Every read-out is blind: the preprocessing chain is fitted once on a separate calibration
drive without posts (``calibrated_chain``), the coder's Th is fixed or comes from the speed
command only, and the array and detector see only the coded signal
(``scoring.BlindReadOut``); detections are scored against the labelled contacts afterwards.

Stages (each prints a progress line):

1. ``sweep``: Th × speed over seeded course scenes, every scene coded at every Th, all codings
   of a chunk as copies of the array in ONE Brian2 group (``ThresholdSweep``, on
   ``engine.sweep.run_sweep``: resumable, reused when only the gate or evaluation change);
   Th*(speed) is fitted on it (``thresholds.fit_th_star``).
2. ``fig9``: rate maps at 12 and 27 cm/s for Th = 0, Th* and 2·Th*. Both Fig. 9 numbers (the
   Th* ratio and the true positives lost by doubling Th*) were built into the generator by
   calibration: the report lists them under "Calibrated to", never as findings.
3. ``train_gate``: the speed gate (``networks.gate.SpeedGate``) learns Th* at a few speeds;
   its learning curve and recall at every swept speed (held-out ones too).
4. ``Evaluation``: new scenes per seed slot (held-out constant speeds, a ramp, random steps,
   and both on the other terrain); the gate's online Th against fixed thresholds around Th*'s
   range and the lookup table of the same trained Th*. A pilot's spread sets how many seeds
   resolve ``evaluation.margin_f1`` (``stats.seeds_needed``), up to ``evaluation.max_seeds``;
   every comparison is a paired difference with its 95 % CI (``thresholds.compare``).

Every Brian2 stage uses one Dask client (``sweep.workers``, ``--scheduler``; none with
``workers = 1``): Fig. 9 and the fixed-Th evaluation run on the workers while this process
trains the gate (``Codings`` over ``engine.batches.Batches``).

Seeds: every draw comes from ``numpy.random.SeedSequence(seed, spawn_key=(stream, ...))``, one
stream per sweep scene (shared by all speeds, so speeds are compared on the same courses) and
per evaluation scene (``evaluation.scene_stream`` picks another family of them: validation
scenes), so no two scenes share a seed whatever the counts.

Outputs: report.html, summary.json, figures, and ``sweep.zarr`` (the scored grid, dims
speed_cm_s × scene × threshold_g).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import spec as specs
from ..engine.batches import ScoredCodings
from ..engine.sweep import Grid, executor, run_sweep
from ..errors import SpecError, check
from ..networks.gate import SpeedGate
from ..networks.resonators import ResonatorArray
from ..preprocess import make_chain
from ..readout import threshold_figures as figures
from ..readout.contacts import detector_from_spec
from ..readout.scoring import SCORE_OUTPUTS, BlindReadOut, Score, score_columns, visible
from ..readout.thresholds import (GateRecall, LookupTable, MethodScores, ThStarFit, compare,
                                  describe_difference, describe_interval, fit_th_star,
                                  earns_its_place, f1_at, fixed_method, table_cell)
from ..report import Calibrated, Predicted, Report, draw_rate_map
from ..sources import antenna
from ..sources.scenes import (CourseLayout, CourseScene, SpeedProfile, course_drive, drive,
                              ramp, random_steps, scene_from_spec)

SECTIONS = ("network", "stimulus", "preprocess", "calibration", "readout", "course", "sweep",
            "gate", "evaluation")
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

    def __post_init__(self):
        check(isinstance(self.scene_stream, int) and self.scene_stream >= 0, "scene_stream",
              self.scene_stream, "an integer >= 0")
        for name in ("pilot_seeds", "max_seeds", "n_steps"):
            value = getattr(self, name)
            check(isinstance(value, int) and value >= 1, name, value, "an integer >= 1")
        check(self.max_seeds >= self.pilot_seeds, "max_seeds", self.max_seeds,
              f"at least pilot_seeds ({self.pilot_seeds})")
        check(np.isfinite(self.margin_f1) and 0 < self.margin_f1 < 1, "margin_f1",
              self.margin_f1, "an F1 difference in (0, 1) to resolve")
        antenna.terrain_noise_rms_g(0.0, self.other_terrain)   # refuses an unknown terrain

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
    preprocess: dict
    calibration: CalibrationSettings
    readout: BlindReadOut
    course: CourseLayout
    sweep: SweepSettings
    gate: SpeedGate
    train_speeds: np.ndarray
    evaluation: EvaluationSettings
    held_out_speeds: np.ndarray
    chain: object = None      # fitted on first use (``calibrated_chain``)


def _section(spec: dict, name: str, target, **kw):
    return target(**specs.check_section(spec, name, target, **kw))


def build(spec: dict) -> Parts:
    """Check the whole spec and build every part before any simulation runs."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("network"):
        array = _section(spec, "network", ResonatorArray)
    with specs.section("stimulus"):
        scene = scene_from_spec(spec.get("stimulus", {"kind": "course"}))
        if not isinstance(scene, CourseScene):
            raise SpecError("stimulus.kind", "robot", "'course' (scenes with obstacles)")
        scene.validate()
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g", "threshold"])
        make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
    with specs.section("calibration"):
        cal = _section(spec, "calibration", CalibrationSettings)
        drive(scene, SpeedProfile("constant", float(cal.speed_cm_s)), 1.0, []).validate()
    detector, window_s = detector_from_spec(spec)
    with specs.section("course"):
        course = _section(spec, "course", CourseLayout)
    with specs.section("sweep"):
        sweep = _section(spec, "sweep", SweepSettings)
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
    with specs.section("network"):
        array.check_rate(scene.rate_hz)
    readout = BlindReadOut(array, detector, window_s, scene.rate_hz, sweep.settle_s,
                           sweep.target)
    return Parts(int(spec.get("seed", 0)), array, scene, pre, cal, readout, course, sweep,
                 gate, train, ev, held)


def sweep_settings(spec: dict) -> dict:
    """What makes two sweeps the same (the store's fingerprint): not the gate or evaluation
    settings, nor where it runs, so changing those reuses a finished sweep."""
    resolved = specs.resolved(spec)
    settings = {k: resolved.get(k) for k in ("seed", "network", "stimulus", "preprocess",
                                             "readout", "course", "sweep")}
    settings["sweep"] = {k: v for k, v in (settings["sweep"] or {}).items() if k != "workers"}
    return settings


# -- scenes and the blind read-out ----------------------------------------------------------
def make_scene(parts: Parts, speed: SpeedProfile, key: tuple, terrain: str | None = None
               ) -> tuple[CourseScene, np.random.SeedSequence]:
    """A new course scene along ``speed`` and the seed of its recording, both from the
    stream ``key`` of the study's seed."""
    course_rng = np.random.default_rng(np.random.SeedSequence(parts.seed,
                                                              spawn_key=(*key, COURSE_DRAW)))
    scene = course_drive(parts.scene, speed, parts.sweep.scene_s, parts.course, course_rng,
                         terrain)
    return scene, np.random.SeedSequence(parts.seed, spawn_key=(*key, NOISE_DRAW))


def calibrated_chain(parts: Parts):
    """The preprocessing chain fitted on a separate calibration drive, never on a test scene:
    ``calibration.duration_s`` at ``calibration.speed_cm_s`` in the open (no posts, so no
    contact can leak in); the scenes are then transformed causally from their first sample."""
    if parts.chain is None:
        cal, scene = parts.calibration, parts.scene
        rec = drive(scene, SpeedProfile("constant", float(cal.speed_cm_s)), cal.duration_s,
                    []).generate(cal.seed)
        assert not rec.contacts   # an open-space drive: nothing to touch
        parts.chain = make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g,
                                 **parts.preprocess).fit(rec.samples)
    return parts.chain


def condition(parts: Parts, rec):
    """The recording's signal just before the coder (g, one channel) and the coder: only
    ``rec.samples`` is read."""
    chain = calibrated_chain(parts)
    x = rec.samples
    for _, step in chain.steps[:-1]:
        x = step.transform(x)
    return x, chain.named_steps["coder"]


def sweep_scene(parts: Parts, speed_cm_s: float, scene: int):
    """The sweep's course scene ``scene`` at a constant speed: recording, conditioned signal,
    coder. The same course and noise at every speed (speeds are compared on equal scenes)."""
    course, seed = make_scene(parts, SpeedProfile("constant", float(speed_cm_s)),
                              (SWEEP_SCENES, int(scene)))
    rec = course.generate(seed)
    return (rec, *condition(parts, rec))


def coded_at(coder, x: np.ndarray, thresholds) -> list[np.ndarray]:
    """``x`` coded at each of ``thresholds``: one column each."""
    th = np.asarray(thresholds, dtype=float)
    coded = coder.partial_transform(np.repeat(x[:, None], len(th), axis=1), threshold=th[None, :])
    return [coded[:, j] for j in range(len(th))]


@dataclass(frozen=True)
class ThresholdSweep:
    """The Th × speed sweep as a ``run_sweep`` evaluator over speed_cm_s × scene ×
    threshold_g: each (speed, scene) of a chunk is generated and conditioned once, coded at
    its thresholds, and the chunk's codings run as one Brian2 group. It holds the resolved
    spec, so it pickles; ``build`` re-checks it on the worker (milliseconds)."""
    spec: dict

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        parts = build(self.spec)
        items, order = [], []
        pairs = np.stack([points["speed_cm_s"], points["scene"]], axis=1)
        for v, scene in np.unique(pairs, axis=0):
            idx = np.flatnonzero((pairs[:, 0] == v) & (pairs[:, 1] == scene))
            rec, x, coder = sweep_scene(parts, v, scene)
            items += [(rec, c) for c in coded_at(coder, x, points["threshold_g"][idx])]
            order += list(idx)
        scores, _ = ScoredCodings(parts.readout, parts.sweep.codings_per_run).run(items)
        ordered = [None] * len(order)
        for i, sc in zip(order, scores):
            ordered[i] = sc
        return score_columns(ordered)


# -- stages --------------------------------------------------------------------------------
def sweep(spec: dict, parts: Parts, out_dir: Path, fresh: bool, client, log):
    """Stage 1: the scored Th × speed grid (``sweep.zarr``) and Th*(speed) fitted on it."""
    sw = parts.sweep
    thresholds, speeds = sw.thresholds_g, sw.speeds_cm_s
    log(f"[1/5] sweep: {len(speeds)} speeds x {len(thresholds)} thresholds x {sw.n_scenes} "
        f"scenes of {sw.scene_s:g} s ({len(speeds) * len(thresholds) * sw.n_scenes} codings, "
        f"{parts.array.n_neurons} resonators each)")
    grid = Grid({"speed_cm_s": speeds, "scene": np.arange(sw.n_scenes),
                 "threshold_g": thresholds}, {"speed_cm_s": "cm/s", "threshold_g": "g"})
    outcome = run_sweep(grid, ThresholdSweep(specs.resolved(spec)), out_dir / "sweep.zarr",
                        SCORE_OUTPUTS, client=client, fresh=fresh,
                        chunk_points=sw.codings_per_run, settings=sweep_settings(spec),
                        attrs={"description": "Th x speed sweep: detections scored per "
                                              "contact", "spec": specs.resolved(spec)})
    log(f"      {len(outcome.chunks_computed)} chunk(s) computed, "
        f"{len(outcome.chunks_skipped)} already in {out_dir / 'sweep.zarr'}, "
        f"{outcome.wall_s:.0f} s")
    fit = fit_th_star(outcome.data)
    log("      best Th per speed: " + ", ".join(f"{v:g}: {t:.3g}"
                                                for v, t in zip(speeds, fit.best_th_g)))
    log("      Th*(speed), monotone: " + ", ".join(f"{v:g}: {t:.3g}"
                                                   for v, t in zip(speeds, fit.th_star_g)))
    return outcome, fit


@dataclass
class Fig9Row:
    """One speed of Fig. 9: Th = 0, Th* and 2·Th*, pooled over the sweep's scenes."""
    thresholds: list
    rec: object                # the first scene's recording (drawn)
    scores: list | None = None
    maps: list | None = None   # the first scene's rate maps


def submit_fig9(parts: Parts, fit: ThStarFit, codings: ScoredCodings):
    """Stage 2: Fig. 9's codings, submitted (they run while the gate learns)."""
    speeds, rows, items = parts.sweep.speeds_cm_s, {}, []
    for v in LOW_HIGH_CM_S:
        iv = int(np.argmin(np.abs(speeds - v)))
        ts = [0.0, fit.th_star_g[iv], 2 * fit.th_star_g[iv]]
        for s in range(parts.sweep.n_scenes):
            rec, x, coder = sweep_scene(parts, speeds[iv], s)
            rows.setdefault(float(speeds[iv]), Fig9Row(ts, rec))
            items += [(rec, c) for c in coded_at(coder, x, ts)]
    return rows, codings.submit(items)


def collect_fig9(rows: dict, submitted, codings: ScoredCodings) -> None:
    scores, maps = codings.collect(submitted, "Fig. 9")
    per_row = 3 * (len(scores) // (3 * len(rows)))
    for r, row in enumerate(rows.values()):
        sc, mp = scores[r * per_row:(r + 1) * per_row], maps[r * per_row:(r + 1) * per_row]
        row.scores, row.maps = [sum(sc[j::3], Score()) for j in range(3)], mp[:3]


def train_gate(parts: Parts, fit: ThStarFit, log) -> GateRecall:
    """Stage 3: the speed gate learns Th* at the training speeds; its recall everywhere."""
    gate, train, speeds = parts.gate, parts.train_speeds, parts.sweep.speeds_cm_s
    train_th = fit.at(train)
    log(f"[3/5] training the speed gate in Brian2 on {len(train)} speeds "
        f"({gate.epochs} epochs, {gate.present_s:g} s per presentation)")
    gate.fit(train, train_th, test_speeds=speeds)
    recall = GateRecall(speeds, fit.th_star_g, gate.learning_curve_.isel(epoch=-1).values,
                        ~np.isin(speeds, train), gate.learning_curve_,
                        LookupTable(train, train_th))
    log("      recalled/Th*: " + ", ".join(f"{v:g}: {r:.2f}"
                                           for v, r in zip(speeds, recall.ratio)))
    return recall


class Evaluation:
    """Stage 4: gated vs lookup vs fixed Th on new scenes, one seed slot at a time.

    Each slot holds one scene of every profile (``profiles``); the fixed-Th codings need no
    gate, so ``add_slots`` submits them at once; ``add_adaptive`` adds the lookup's and the
    gate's, ``collect`` scores them into ``scores`` (a ``MethodScores``)."""

    def __init__(self, parts: Parts, fixed_th: np.ndarray, codings: ScoredCodings):
        self.parts, self.fixed_th, self.codings = parts, fixed_th, codings
        self.scores = MethodScores([cat for cat, *_ in self.profiles(0)])
        self.scenes, self.pending = {}, []   # slot -> [(rec, x, coder)]; (keys, submitted)
        self.example = None                  # a ramp scene's online Th and rate map
        self.recall: GateRecall | None = None

    def profiles(self, slot: int) -> list[tuple[str, str, SpeedProfile, str]]:
        """(category, name, speed profile, terrain) of each evaluation scene of a slot."""
        v, length = self.parts.sweep.speeds_cm_s, self.parts.sweep.scene_s
        lo, hi, terrain = float(v.min()), float(v.max()), self.parts.scene.terrain
        rng = np.random.default_rng(np.random.SeedSequence(
            self.parts.seed, spawn_key=(EVALUATION_STEPS, self.parts.evaluation.scene_stream,
                                        slot)))
        steps = random_steps(rng, lo, hi, length, self.parts.evaluation.n_steps)
        up, other = ramp(lo, hi, length), self.parts.evaluation.other_terrain
        out = [("held-out speeds", f"{x:g} cm/s", SpeedProfile("constant", float(x)), terrain)
               for x in self.parts.held_out_speeds]
        out += [("ramp", f"ramp {lo:g}→{hi:g} cm/s", up, terrain),
                ("steps", "random steps", steps, terrain)]
        if other != terrain:
            out += [(f"{other} ground", f"ramp, {other}", up, other),
                    (f"{other} ground", f"steps, {other}", steps, other)]
        return out

    def add_slots(self, slots) -> None:
        """Generate the slots' scenes and submit their fixed-Th codings."""
        items, keys = [], []
        for slot in slots:
            self.scenes[slot] = []
            for i, (_, _, profile, terrain) in enumerate(self.profiles(slot)):
                key = (EVALUATION_SCENES, self.parts.evaluation.scene_stream, slot, i)
                scene, seed = make_scene(self.parts, profile, key, terrain)
                rec = scene.generate(seed)
                x, coder = condition(self.parts, rec)
                self.scenes[slot].append((rec, x, coder))
                items += [(rec, c) for c in coded_at(coder, x, self.fixed_th)]
                keys += [(fixed_method(t), slot, i) for t in self.fixed_th]
        self.pending.append((keys, self.codings.submit(items)))

    def add_adaptive(self, slots) -> None:
        """Submit the lookup table's and the gate's codings (Th from the speed command)."""
        entries = [(slot, i, *scene) for slot in slots for i, scene in enumerate(self.scenes[slot])]
        speed_cols = np.stack([rec.meta["speed_cm_s"] for _, _, rec, _, _ in entries], axis=1)
        gated_th = self.parts.gate.thresholds(speed_cols, self.parts.scene.rate_hz)
        lookup_th = self.recall.table(speed_cols)
        items, keys = [], []
        for k, (slot, i, rec, x, coder) in enumerate(entries):
            items += [(rec, coder.partial_transform(x, threshold=lookup_th[:, k])),
                      (rec, coder.partial_transform(x, threshold=gated_th[:, k]))]
            keys += [("lookup", slot, i), ("gated", slot, i)]
            if self.example is None and self.scores.categories[i] == "ramp":
                self.example = {"rec": rec, "gated_th": gated_th[:, k],
                                "lookup_th": lookup_th[:, k], "key": keys[-1]}
        self.pending.append((keys, self.codings.submit(items)))

    def collect(self) -> None:
        for keys, submitted in self.pending:
            scores, maps = self.codings.collect(submitted, "evaluation")
            for key, sc, rates in zip(keys, scores, maps):
                self.scores.add(*key, sc)
                if self.example is not None and key == self.example["key"]:
                    self.example["map"] = rates
        self.pending = []


@dataclass
class SeedPlan:
    pilot: int
    needed: int
    used: int
    budget: int
    margin_f1: float


def evaluate(evaluation: Evaluation, log) -> SeedPlan:
    """Stages 4–5: the pilot's spread sets how many seeds run (up to the budget)."""
    ev = evaluation.parts.evaluation
    evaluation.add_adaptive(range(ev.pilot_seeds))
    evaluation.collect()
    scores = evaluation.scores
    others = [fixed_method(scores.best_fixed(evaluation.fixed_th)), "lookup"]
    needed = scores.seeds_needed("gated", others, ev.margin_f1)
    used = int(np.clip(needed, ev.pilot_seeds, ev.max_seeds))
    log(f"      the pilot's spread needs {needed} seed(s) to resolve a difference of "
        f"{ev.margin_f1:g} in F1; running {used} (budget: {ev.max_seeds})")
    if used > ev.pilot_seeds:
        more = range(ev.pilot_seeds, used)
        log(f"[5/5] evaluation, seeds {ev.pilot_seeds}..{used - 1}")
        evaluation.add_slots(more)
        evaluation.add_adaptive(more)
        evaluation.collect()
    else:
        log("[5/5] no further seeds needed")
    return SeedPlan(ev.pilot_seeds, needed, used, ev.max_seeds, ev.margin_f1)


@dataclass
class Results:
    """Every stage's output: what the summary and the report are made from."""
    outcome: object           # the sweep's ``SweepOutcome``; ``outcome.data`` is fitted
    fit: ThStarFit
    fig9: dict
    recall: GateRecall
    seeds: SeedPlan
    comparison: dict
    example: dict | None      # a ramp scene's online Th and rate map


def run(spec: dict, out_dir, quick: bool = False, fresh: bool = False,
        scheduler: str | None = None, log=print) -> dict:
    parts, out_dir, t_start = build(spec), Path(out_dir), time.perf_counter()
    # One Dask client (or none: ``sweep.workers = 1``) serves every Brian2 stage.
    with executor(parts.sweep.workers, scheduler, log) as client:
        outcome, fit = sweep(spec, parts, out_dir, fresh, client, log)
        codings = ScoredCodings(parts.readout, parts.sweep.codings_per_run, client)
        where = "on the Dask workers" if client is not None else "after the gate"
        log(f"[2/5] Fig. 9 in kind: Th = 0, Th*, 2·Th* at low and high speed (runs {where})")
        fig9, fig9_runs = submit_fig9(parts, fit, codings)
        # The fixed thresholds worth evaluating: the grid around Th*'s range (outside it F1
        # only falls, see the sweep's curves) and the one chosen on the sweep. Their codings
        # need no gate, so the pilot's start now and run while the gate learns.
        th = parts.sweep.thresholds_g
        lo, hi = fit.th_star_g.min() / 2, fit.th_star_g.max() * 2
        fixed_th = np.unique(np.r_[th[(th >= lo) & (th <= hi)], fit.sweep_fixed_th_g])
        evaluation = Evaluation(parts, fixed_th, codings)
        evaluation.add_slots(range(parts.evaluation.pilot_seeds))
        evaluation.recall = recall = train_gate(parts, fit, log)
        categories = evaluation.scores.categories
        log(f"[4/5] evaluation on new scenes, pilot of {parts.evaluation.pilot_seeds} seed(s): "
            f"{len(categories)} scenes each ({', '.join(dict.fromkeys(categories))}); "
            f"{len(fixed_th)} fixed Th, the lookup table and the gate")
        collect_fig9(fig9, fig9_runs, codings)
        seeds = evaluate(evaluation, log)
    results = Results(outcome, fit, fig9, recall, seeds,
                      compare(evaluation.scores, fixed_th, fit.sweep_fixed_th_g),
                      evaluation.example)
    summary = summarize(parts, results)
    summary["total_wall_s"] = time.perf_counter() - t_start
    write_report(out_dir, spec, parts, results, summary, quick)
    log(human_summary(summary, out_dir))
    return summary


def summarize(parts: Parts, r: Results) -> dict:
    ds, speeds, fit, outcome = r.outcome.data, r.fit.speeds_cm_s, r.fit, r.outcome
    i12, i27 = (int(np.argmin(np.abs(speeds - v))) for v in LOW_HIGH_CM_S)
    return {
        "th_star": {f"{v:g}": float(t) for v, t in zip(speeds, fit.th_star_g)},
        "best_th_per_speed": {f"{v:g}": float(t) for v, t in zip(speeds, fit.best_th_g)},
        "sweep_fixed_th_g": fit.sweep_fixed_th_g,
        "fp_per_min_at_th0_while_driving": float(ds.fp_per_min.isel(threshold_g=0)
                                                 .values[speeds > 0].mean()),
        "highest_th_misses_all": bool(ds.tp.isel(threshold_g=-1).sum() == 0),
        "recall_ratio": {f"{v:g}": float(x) for v, x in zip(speeds, r.recall.ratio)},
        "recall_error_factor_held_out": r.recall.error_factor(held_out=True),
        "recall_error_factor_trained": r.recall.error_factor(held_out=False),
        "train_speeds_cm_s": parts.train_speeds.tolist(),
        "gate_tau_read_s": parts.gate.tau_read_s,
        "calibration_checks": {
            "th_star_ratio_27_to_12": float(fit.th_star_g[i27] / fit.th_star_g[i12]),
            "tp_at_th_star_vs_double": {f"{v:g}": [row.scores[1].tp, row.scores[2].tp]
                                        for v, row in r.fig9.items()}},
        "seeds": {"pilot": r.seeds.pilot, "needed": r.seeds.needed, "used": r.seeds.used,
                  "budget": r.seeds.budget, "margin_f1": r.seeds.margin_f1},
        **r.comparison,
        "sweep_chunks": {"computed": len(outcome.chunks_computed),
                         "reused": len(outcome.chunks_skipped), "workers": outcome.workers},
        "sweep_wall_s": outcome.wall_s,
    }


# -- report --------------------------------------------------------------------------------
def human_summary(s: dict, out_dir) -> str:
    ok, why = earns_its_place(s)
    return "\n".join([
        "Th*: " + ", ".join(f"{v} cm/s {t:.3g} g" for v, t in s["th_star"].items()),
        *(f"F1 {label}: {describe_interval(v)}" for label, v in s["f1"].items()),
        *(f"{label}: {describe_difference(v)}" for label, v in s["differences"].items()),
        f"the gate {'earns' if ok else 'does not earn'} its place: {why}",
        f"report in {out_dir}/report.html ({s['total_wall_s']:.0f} s)"])


def quick_note(parts: Parts) -> str:
    sw = parts.sweep
    return (f"Quick profile: {len(sw.speeds_cm_s)} speeds × {len(sw.thresholds_g)} "
            f"thresholds × {sw.n_scenes} scene(s) of {sw.scene_s:g} s, gate trained "
            f"{parts.gate.epochs} epoch(s), {parts.evaluation.max_seeds} evaluation seed(s) at "
            "most. Too small to compare: Th* rests on a handful of contacts per speed on a "
            "coarse grid (it may sit at one threshold at every speed), the gate is barely "
            "trained, and the F1 intervals over so few seeds are wide or missing. Run the full "
            "profile for any number worth reading.")


def _ci(d):
    return None if d.get("low") is None else (d["low"], d["high"])


def _calibrated(s: dict, parts: Parts) -> list:
    checks, cal = s["calibration_checks"], parts.calibration
    tp = checks["tp_at_th_star_vs_double"]
    return [
        Calibrated("Th*(27 cm/s) / Th*(12 cm/s)", round(checks["th_star_ratio_27_to_12"], 2),
                   "> 5 (Fig. 9)", "", "docs/reference.md (Fig. 9)",
                   "self-motion grows with speed² (antenna.self_motion_rms_g, "
                   "SELF_MOTION_G_AT_12) so that this ratio lands near 5: built in, not found"),
        Calibrated("true positives at Th* → 2·Th* (12 and 27 cm/s)",
                   "; ".join(f"{v} cm/s: {a} → {b}" for v, (a, b) in tp.items()),
                   "doubling Th* loses contacts (Fig. 9)", "", "docs/reference.md (Fig. 9)",
                   "antenna.IMPACT_TRANSFER, chosen so that impacts sit between the self-motion "
                   "at 12 and at 27 cm/s: built in, not found"),
        Calibrated("preprocessing (PCA axis of the two accelerometer axes)", "fitted",
                   "a separate calibration drive", "", "this study's [calibration] section",
                   f"{cal.duration_s:g} s at {cal.speed_cm_s:g} cm/s in the open, no posts; "
                   "never fitted on a scene that is scored"),
        Calibrated("Th*(speed)", ", ".join(f"{v}: {t:.3g}" for v, t in s["th_star"].items()),
                   "best F1 per speed on the sweep's scenes", "g", "this study's sweep",
                   "the training data of the gate and the lookup table (monotone fit of each "
                   "speed's best Th); the evaluation uses other seeds")]


def _predicted(s: dict, parts: Parts) -> list:
    d_lu, d_fx, d_sw = (s["differences"][k] for k in (
        "gated − lookup", "gated − best fixed in hindsight", "gated − fixed from the sweep"))
    gated, lat, fpm = s["f1"]["gated"], s["latency_gated_s"], s["fp_per_min_gated"]
    terrain = parts.evaluation.other_terrain
    return [
        Predicted("F1 of the gate on new scenes (held-out speeds, ramps, steps, "
                  f"{terrain} ground)", gated["mean"], "", None, "evaluation", _ci(gated),
                  gated["n"], "F1 pooled per seed over its scenes; mean over seeds"),
        *(Predicted(f"F1 of the gate: {row['scenes']}", row["F1 gated"]["mean"], "", None,
                    "evaluation", _ci(row["F1 gated"]), row["F1 gated"]["n"],
                    f"{row['contacts scored']} contacts scored") for row in s["per_category"]),
        Predicted("latency of the gate's detections", lat["mean"], "s", None, "evaluation",
                  _ci(lat), lat["n"], "contact onset to the end of the first detected window"),
        Predicted("false positives per minute under the gate", fpm["mean"], "1/min", None,
                  "evaluation", _ci(fpm), fpm["n"]),
        Predicted("F1 gated − lookup table", d_lu["mean"], "", None, "evaluation", _ci(d_lu),
                  d_lu["n"], d_lu["verdict"]),
        Predicted("F1 gated − best fixed Th in hindsight", d_fx["mean"], "", None,
                  "evaluation", _ci(d_fx), d_fx["n"],
                  f"{d_fx['verdict']}; the fixed Th ({s['oracle_th_g']:g} g) is chosen on the "
                  "evaluation scenes themselves: an oracle"),
        Predicted("F1 gated − fixed Th chosen on the sweep", d_sw["mean"], "", None,
                  "evaluation", _ci(d_sw), d_sw["n"],
                  f"{d_sw['verdict']}; the Th ({s['sweep_fixed_th_g']:g} g) a user would "
                  "deploy without a gate"),
        Predicted("false positives per minute at Th = 0 while driving (sweep)",
                  s["fp_per_min_at_th0_while_driving"], "1/min", None, "sweep", None, None,
                  "pooled over the sweep's scenes; the paper shows spurious spikes, no rate"),
        Predicted("gate recall error factor on held-out speeds",
                  s["recall_error_factor_held_out"], "×", None, "gate", None,
                  int(np.sum(~np.isin(parts.sweep.speeds_cm_s, parts.train_speeds))),
                  "exp(mean |log(recalled / Th*)|) over the sweep's speeds the gate was not "
                  "trained on")]


def _headline(s: dict, parts: Parts) -> str:
    d, seeds, ev = s["differences"], s["seeds"], parts.evaluation
    return (
        f"On scenes with new seeds — constant speeds the gate was not trained on "
        f"({', '.join(f'{v:g}' for v in parts.held_out_speeds)} cm/s), ramps over the whole "
        f"speed range, random speed steps, and the ramp and the steps on {ev.other_terrain} "
        f"ground — the learned gate's F1 is {describe_interval(s['f1']['gated'])}. Against the "
        f"lookup table of the same trained Th*: {describe_difference(d['gated − lookup'])}. "
        f"Against the best single fixed Th in hindsight ({s['oracle_th_g']:g} g, chosen on "
        f"these very scenes: an oracle no robot has): "
        f"{describe_difference(d['gated − best fixed in hindsight'])}. Against the fixed Th a "
        f"user would deploy, chosen on the sweep ({s['sweep_fixed_th_g']:g} g): "
        f"{describe_difference(d['gated − fixed from the sweep'])}. Seeds: a pilot of "
        f"{seeds['pilot']} gave the spread; resolving a difference of {seeds['margin_f1']:g} in "
        f"F1 (α = 0.05, power 0.8) needs {seeds['needed']}, {seeds['used']} were run (budget "
        f"{seeds['budget']}).")


def write_report(out_dir: Path, spec: dict, parts: Parts, r: Results, s: dict,
                 quick: bool) -> None:
    ds = r.outcome.data
    rep = Report(out_dir, "snn-antenna: gating threshold and the learned speed gate",
                 quick=quick, quick_note=quick_note(parts))
    ok, why = earns_its_place(s)
    rep.calibrated(*_calibrated(s, parts))
    rep.predicted(*_predicted(s, parts))
    rep.text(spec.get("description", ""))
    rep.heading("Headline: the gate on new scenes")
    rep.text(_headline(s, parts))
    rep.text(f"Verdict: the gate {'earns' if ok else 'does not earn'} its place — {why}.")
    rep.text("The read-out never sees the ground truth: the preprocessing is fitted on a "
             "separate calibration drive, the gate and the lookup table read only the speed "
             "command, the resonator array and the detector read only the coded signal; every "
             "detection (true or false positive, duplicate, detection of an out-of-band "
             "contact) is scored against the labelled contacts afterwards.")
    rep.table([{"scenes": r["scenes"], "contacts scored": r["contacts scored"],
                **{k: table_cell(v) for k, v in r.items() if k not in ("scenes", "contacts scored")}}
               for r in s["per_category"]],
              "Per scene type: mean over seeds (95 % CI); differences paired by seed")
    rep.figure(figures.f1_per_category(s), "f1_per_category",
               "F1 per scene type, mean over seeds with 95 % CI (clipped to [0, 1]): the gate, "
               "the lookup table, the best fixed Th in hindsight and the fixed Th chosen on "
               "the sweep.")
    rep.figure(figures.f1_methods(s), "f1_methods",
               "F1 over all evaluation scenes for each fixed Th evaluated (mean over seeds, "
               "95 % CI), with the gate and the lookup table (line: mean, band: 95 % CI).")
    if r.example is not None and "map" in r.example:
        rep.figure(_fig_ramp(r.example, parts), "ramp_example",
                   "A ramp scene: speed command, the gate's online Th (and the lookup), and "
                   "the rate map under the gated Th; dashed lines: true contacts (cyan: in the "
                   "array's band, grey: outside it), green: detections.")
    rep.heading("Th × speed sweep (the gate's training data)")
    rep.figure(figures.f1_curves(ds), "f1_vs_threshold",
               "F1, false positives per minute and mean latency against Th, one line per speed "
               "(pooled over the sweep's scenes); dots mark Th*(speed), crosses each speed's "
               "own best Th before the monotone fit. Th = 0 is drawn at the left edge.")
    rep.table([_sweep_row(ds, v, b, t) for v, b, t in
               zip(ds.speed_cm_s.values, ds.best_th_g.values, ds.th_star_g.values)],
              "Th*(speed) from the sweep: each speed's best Th and their monotone fit")
    rep.heading("Fig. 9 in kind (calibrated: see above)")
    rep.figure(_fig9(r.fig9, parts), "fig9_rate_maps",
               "Rate maps of one scene at low and high speed for Th = 0, Th* and 2·Th*; "
               "dashed lines mark true contacts (cyan: in the array's band, grey: outside it), "
               "green lines detections.")
    rep.table([{"speed (cm/s)": v, "Th": lab, "Th (g)": th, **sc.as_dict()}
               for v, row in r.fig9.items()
               for lab, th, sc in zip(("0", "Th*", "2·Th*"), row.thresholds, row.scores)],
              "Detections pooled over the sweep's scenes")
    rep.heading("The speed gate (Brian2 associative memory)")
    rep.figure(figures.gate_recall(r.recall), "gate",
               "Left: learning curves, recall error factor exp(mean |log(recalled/Th*)|) on "
               "trained and held-out speeds. Right: Th* from the sweep, the gate's recall and "
               "the lookup table.")
    rep.write(s, spec, parts.array.target)


def _sweep_row(ds, v, best, th_star) -> dict:
    at_zero = ds.sel(speed_cm_s=v).isel(threshold_g=0)
    return {"speed (cm/s)": float(v), "best Th (g)": float(best), "Th* (g)": float(th_star),
            "F1 at Th*": f1_at(ds, v, th_star), "FP/min at Th = 0": float(at_zero.fp_per_min),
            # every scored contact is a hit or a miss, whatever the threshold
            "contacts scored": int((at_zero.tp + at_zero.misses).sum()),
            "out of the array's band": int(at_zero.out_of_band_contacts.sum())}


def _draw_map(ax, rates, rec, parts: Parts, title: str):
    """A rate map with the true contacts (cyan: in the array's band, grey: outside it) and
    the detections (green); returns the mesh for its colour bar."""
    mesh = draw_rate_map(ax, rates)
    for c in rec.contacts:
        ok = visible(c, parts.readout.detector, parts.array)
        ax.axvline(c.t_s, color="tab:cyan" if ok else "0.6", ls="--", lw=0.8)
    for d in parts.readout.detector.detect(rates):
        ax.axvline(d.onset_s, color="tab:green", lw=1.2)
    ax.set_title(title, fontsize=9)
    return mesh


def _fig9(fig9: dict, parts: Parts):
    fig, axes = figures.pyplot().subplots(len(fig9), 3, figsize=(15, 3.2 * len(fig9)),
                                          squeeze=False, sharex=True)
    for r, (v, row) in enumerate(fig9.items()):
        for c, (lab, th, rates) in enumerate(zip(("Th", "Th*", "2·Th*"), row.thresholds,
                                                 row.maps)):
            mesh = _draw_map(axes[r, c], rates, row.rec, parts, f"{v:g} cm/s, {lab} = {th:.3g} g")
            fig.colorbar(mesh, ax=axes[r, c], label="rate (Hz)", pad=0.01)
        axes[r, 0].set_ylabel("neuron (Hz)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def _fig_ramp(example: dict, parts: Parts):
    rec = example["rec"]
    # A narrow column holds the rate map's colour bar, so the three time axes stay aligned.
    fig, axes = figures.pyplot().subplots(3, 2, figsize=(11, 7.5), sharex="col", gridspec_kw={
        "height_ratios": [0.6, 0.8, 1.6], "width_ratios": [1, 0.02]})
    (a0, a1, a2), cax = axes[:, 0], axes[2, 1]
    axes[0, 1].set_visible(False)
    axes[1, 1].set_visible(False)
    a0.plot(rec.t_s, rec.meta["speed_cm_s"], color="k")
    a0.set_ylabel("speed (cm/s)")
    a1.plot(rec.t_s, example["gated_th"], color="tab:red", label="gate (online)")
    a1.plot(rec.t_s, example["lookup_th"], color="tab:blue", ls="--", label="lookup")
    figures.th_axis(a1, np.r_[example["gated_th"], example["lookup_th"]])
    a1.set_ylabel("Th (g)")
    a1.legend(fontsize=8)
    fig.colorbar(_draw_map(a2, example["map"], rec, parts, "gated"), cax=cax, label="rate (Hz)")
    a2.set_ylabel("neuron (Hz)")
    a2.set_xlabel("time (s)")
    fig.tight_layout()
    return fig
