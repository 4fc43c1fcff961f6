"""The gating study's stages (each prints a progress line): the Th × speed sweep and
Th*(speed) fitted on it, Fig. 9 in kind, the speed gate's training, and the evaluation on new
scenes (or held-out recorded drives) against fixed thresholds and the lookup table; the
summary."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ...core import spec as specs
from ...core.logfile import logged
from ...engine.batches import ScoredCodings
from ...engine.executor import executor
from ...engine.grid import Grid
from ...engine.sweep import run_sweep
from ...evaluation.scoring import SCORE_OUTPUTS, Score
from ...evaluation.thresholds import (
    F1_BOUNDS,
    GateRecall,
    LookupTable,
    MethodScores,
    ThStarFit,
    compare,
    difference,
    fit_th_star,
    fixed_method,
    interval,
)
from ...sources.scenes import SpeedProfile, ramp, random_steps
from ..contract import Options, Plan
from .plan import EVALUATION_SCENES, EVALUATION_STEPS, LOW_HIGH_CM_S, Parts, sweep_settings
from .recorded import RecordedSweep, evaluate_drives
from .recorded import summary_entry as recorded_entry
from .report import Fig9Row, Results, SeedPlan, human_summary, write_report
from .scenes import ThresholdSweep, coded_at, condition, make_scene, sweep_scene


def sweep(spec: dict, parts: Parts, out_dir: Path, fresh: bool, client, log):
    """Stage 1: the scored Th × speed grid (``sweep.zarr``) and Th*(speed) fitted on it."""
    sw, split = parts.sweep, parts.data
    thresholds, speeds = sw.thresholds_g, sw.speeds_cm_s
    units = {"speed_cm_s": "cm/s", "threshold_g": "g"}
    if split is None:
        log(f"[1/5] sweep: {len(speeds)} speeds x {len(thresholds)} thresholds x "
            f"{sw.n_scenes} scenes of {sw.scene_s:g} s "
            f"({len(speeds) * len(thresholds) * sw.n_scenes} codings, "
            f"{parts.array.n_neurons} resonators each)")
        grid = Grid({"speed_cm_s": speeds, "scene": np.arange(sw.n_scenes),
                     "threshold_g": thresholds}, units)
        evaluator, chunk = ThresholdSweep(specs.resolved(spec)), sw.codings_per_run
    else:
        # each training drive is coded once per Th and scored at every speed it logged: the
        # speeds are the grid's last axis, so a chunk holds every speed of its codings
        n = len(split.training)
        log(f"[1/5] sweep on {n} recorded training drive(s): {len(thresholds)} thresholds "
            f"({n * len(thresholds)} codings), scored at {len(speeds)} logged speeds")
        grid = Grid({"scene": np.arange(n), "threshold_g": thresholds, "speed_cm_s": speeds},
                    units)
        evaluator, chunk = RecordedSweep(specs.resolved(spec)), sw.codings_per_run * len(speeds)
    outcome = run_sweep(grid, evaluator, out_dir / "sweep.zarr", SCORE_OUTPUTS,
                        client=client, fresh=fresh, chunk_points=chunk,
                        settings=sweep_settings(spec, parts),
                        attrs={"description": "Th x speed sweep: detections scored per "
                                              "contact", "spec": specs.resolved(spec)})
    outcome.data = outcome.data.transpose("speed_cm_s", "scene", "threshold_g")
    log(f"      {len(outcome.chunks_computed)} chunk(s) computed, "
        f"{len(outcome.chunks_skipped)} already in {out_dir / 'sweep.zarr'}, "
        f"{outcome.wall_s:.0f} s")
    fit = fit_th_star(outcome.data)
    log("      best Th per speed: " + ", ".join(f"{v:g}: {t:.3g}"
                                                for v, t in zip(speeds, fit.best_th_g)))
    log("      Th*(speed), monotone: " + ", ".join(f"{v:g}: {t:.3g}"
                                                   for v, t in zip(speeds, fit.th_star_g)))
    return outcome, fit


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
        entries = [(slot, i, *scene) for slot in slots
                   for i, scene in enumerate(self.scenes[slot])]
        speed_cols = np.stack([rec.meta["speed_cm_s"] for _, _, rec, _, _ in entries], axis=1)
        gated_th = self.parts.gate.thresholds(speed_cols, self.parts.scene.rate_hz)
        lookup_th = self.recall.table(speed_cols)
        items, keys = [], []
        ev = self.parts.evaluation
        others = {label: ev.coder(label) for label in ev.coders}
        for k, (slot, i, rec, x, coder) in enumerate(entries):
            items += [(rec, coder.partial_transform(x, threshold=lookup_th[:, k])),
                      (rec, coder.partial_transform(x, threshold=gated_th[:, k]))]
            keys += [("lookup", slot, i), ("gated", slot, i)]
            for label, other in others.items():   # the same gate's Th, another coder
                items.append((rec, other.fit(x).partial_transform(x, threshold=gated_th[:, k])))
                keys.append((coder_method(label), slot, i))
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


def coder_method(label: str) -> str:
    """The method name of the gate's Th through coder ``label`` of ``evaluation.coders``."""
    return f"gated, {label} coder"


def compare_coders(scores: MethodScores, parts: Parts) -> dict:
    """Each coder of ``evaluation.coders`` with the gate's Th, on the same scenes as the
    study's own coder: F1 over seeds (interval, n) and its paired difference from it."""
    own = scores.per_seed("gated")
    out = {}
    for label, table in parts.evaluation.coders.items():
        f1 = scores.per_seed(coder_method(label))
        out[label] = {"coder": table.get("coder", "square"), "f1": interval(f1, F1_BOUNDS),
                      "f1_per_seed": [None if not np.isfinite(x) else float(x) for x in f1],
                      "minus_own_coder": difference(f1, own)}
    return out


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


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick = plan.spec, plan.parts, options.quick
    out_dir, t_start = Path(out_dir), time.perf_counter()
    # One Dask client (or none: ``sweep.workers = 1``) serves every Brian2 stage.
    with executor(parts.sweep.workers, options.scheduler, log) as client:
        outcome, fit = sweep(spec, parts, out_dir, options.fresh, client, log)
        codings = ScoredCodings(parts.readout, parts.sweep.codings_per_run, client)
        # The fixed thresholds worth evaluating: the grid around Th*'s range (outside it F1
        # only falls, see the sweep's curves) and the one chosen on the sweep.
        th = parts.sweep.thresholds_g
        lo, hi = fit.th_star_g.min() / 2, fit.th_star_g.max() * 2
        fixed_th = np.unique(np.r_[th[(th >= lo) & (th <= hi)], fit.sweep_fixed_th_g])
        if parts.data is None:
            fig9, scores, recall, seeds, example = generated_stages(parts, fit, fixed_th,
                                                                    codings, client, log)
        else:
            fig9, (scores, recall, seeds, example) = {}, recorded_stages(parts, fit, fixed_th,
                                                                         codings, log)
    results = Results(outcome, fit, fig9, recall, seeds,
                      {**compare(scores, fixed_th, fit.sweep_fixed_th_g),
                       "coders": compare_coders(scores, parts)}, example)
    summary = summarize(parts, results)
    if parts.data is not None:
        summary["recorded"] = recorded_entry(parts.data)
    summary["total_wall_s"] = time.perf_counter() - t_start
    write_report(out_dir, spec, parts, results, summary, quick)
    log(human_summary(summary, out_dir))
    return summary


def generated_stages(parts: Parts, fit: ThStarFit, fixed_th: np.ndarray, codings, client,
                     log):
    """Stages 2-5 on generated scenes: Fig. 9, the gate, the evaluation on new scenes."""
    where = "on the Dask workers" if client is not None else "after the gate"
    log(f"[2/5] Fig. 9 in kind: Th = 0, Th*, 2·Th* at low and high speed (runs {where})")
    fig9, fig9_runs = submit_fig9(parts, fit, codings)
    # the fixed-Th codings need no gate: the pilot's start now and run while the gate learns
    evaluation = Evaluation(parts, fixed_th, codings)
    evaluation.add_slots(range(parts.evaluation.pilot_seeds))
    evaluation.recall = recall = train_gate(parts, fit, log)
    categories = evaluation.scores.categories
    log(f"[4/5] evaluation on new scenes, pilot of {parts.evaluation.pilot_seeds} seed(s): "
        f"{len(categories)} scenes each ({', '.join(dict.fromkeys(categories))}); "
        f"{len(fixed_th)} fixed Th, the lookup table and the gate")
    collect_fig9(fig9, fig9_runs, codings)
    seeds = evaluate(evaluation, log)
    return fig9, evaluation.scores, recall, seeds, evaluation.example


def recorded_stages(parts: Parts, fit: ThStarFit, fixed_th: np.ndarray, codings, log):
    """Stages 2-5 on recorded drives: no Fig. 9 (its two numbers are the generator's
    calibration), the gate trained on the training drives' Th*, the evaluation on the
    held-out drives, one paired unit per drive."""
    log("[2/5] Fig. 9 left out: its numbers calibrate the generator, and no scene is generated")
    recall = train_gate(parts, fit, log)
    ev = parts.evaluation
    others = {coder_method(label): ev.coder(label) for label in ev.coders}
    scores, example = evaluate_drives(parts, fixed_th, recall, codings, others, log)
    n = len(parts.data.held_out)
    needed = scores.seeds_needed("gated", [fixed_method(scores.best_fixed(fixed_th)),
                                           "lookup"], ev.margin_f1)
    log(f"[5/5] resolving a difference of {ev.margin_f1:g} in F1 needs {needed} held-out "
        f"drive(s) at this spread; {n} recorded")
    return scores, recall, SeedPlan(n, needed, n, n, ev.margin_f1), example


def summarize(parts: Parts, r: Results) -> dict:
    ds, speeds, fit, outcome = r.outcome.data, r.fit.speeds_cm_s, r.fit, r.outcome
    i12, i27 = (int(np.argmin(np.abs(speeds - v))) for v in LOW_HIGH_CM_S)
    checks = {"calibration_checks": {
        "th_star_ratio_27_to_12": float(fit.th_star_g[i27] / fit.th_star_g[i12]),
        "tp_at_th_star_vs_double": {f"{v:g}": [row.scores[1].tp, row.scores[2].tp]
                                    for v, row in r.fig9.items()}}} if r.fig9 else {}
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
        **checks,
        "seeds": {"pilot": r.seeds.pilot, "needed": r.seeds.needed, "used": r.seeds.used,
                  "budget": r.seeds.budget, "margin_f1": r.seeds.margin_f1},
        **r.comparison,
        "sweep_chunks": {"computed": len(outcome.chunks_computed),
                         "reused": len(outcome.chunks_skipped), "workers": outcome.workers},
        "sweep_wall_s": outcome.wall_s,
    }


