"""Gating threshold: how the coder's Th must follow speed, and a spiking gate that learns it.

Stages (each prints a progress line):

1. Sweep Th × speed over seeded course scenes: every scene is coded at every Th and all
   codings of one speed run as copies of the resonator array in ONE Brian2 NeuronGroup
   (``gating.run_codings``); detections are scored per contact (``gating.score``).
   Each speed's best Th maximises F1 over the pooled scenes of that speed, smoothed over
   neighbouring thresholds (``choose_th_star``); Th*(speed) is their monotone fit
   (``monotone_th_star``): the shaking that Th must hide only grows with speed, and a few
   contacts per speed make a single speed's argmax noisy.
2. Fig. 9 in kind: rate maps at 12 and 27 cm/s for Th = 0, Th* and 2·Th*, and the true
   positives lost by doubling Th*.
3. Train the speed gate (``gate.SpeedGate``, Brian2 associative memory) on Th* at a few
   speeds; record its learning curve and its recall at every swept speed (held-out ones too).
4. On new scenes (new seeds, constant speeds and ramps 0→30 cm/s) compare detection F1 of the
   gate's online Th (recalled from each scene's speed at every sample) against every fixed Th
   and a lookup table of the trained Th* (interpolated in log Th). Two single thresholds are
   reported: the best in hindsight (the fixed Th with the highest F1 on the evaluation scenes
   themselves, an oracle no robot has) and the one a user would deploy (the Th of highest F1
   over all speeds of the sweep).

Every Brian2 stage uses the same Dask client (``sweep.workers``, ``--scheduler``; none with
``workers = 1``): after the sweep, Fig. 9 and the fixed-Th evaluation start on the workers
while this process trains the gate (``Codings``), then the lookup and gated codings follow.

Outputs: report.html, summary.json, figures, and ``sweep.zarr`` (the scored grid, one
xarray Dataset with dims speed_cm_s × scene × threshold_g, written chunk by chunk by
``sweep.run_sweep``: on a local Dask cluster or ``--scheduler``, resumed after an interruption,
reused when only the gate or evaluation settings change; ``--fresh`` starts over).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from .. import spec as specs
from ..errors import SpecError, check
from ..gate import SpeedGate
from ..gating import Score, run_codings, score
from ..network import ResonatorArray
from ..preprocess import make_chain
from ..readout import ContactDetector
from ..report import Report, draw_rate_map
from ..scenes import CourseScene, SpeedProfile, random_course, scene_from_spec
from ..store import Output
from ..sweep import Grid, executor, prepare_workers, run_sweep

SECTIONS = ("network", "stimulus", "preprocess", "readout", "course", "sweep", "gate",
            "evaluation")
LOW_HIGH_CM_S = (12.0, 27.0)  # the paper's two speeds (Fig. 9)


def _sweep_settings(thresholds_g=(0.0, 0.1), speeds_cm_s=(0.0, 12.0), n_scenes=3,
                    scene_s=15.0, settle_s=1.0, target=None, codings_per_run=200, workers=0):
    return locals()


def _evaluation_settings(n_scenes=3, n_ramps=2, seed_offset=1000):
    return locals()


def _course_settings(spacing_cm=45.0, lateral_cm=(8.0, 30.0), materials=("wood",),
                     first_reach_cm=(12.0, 28.0), first_angle_deg=(20.0, 60.0)):
    return locals()


def build(spec: dict) -> dict:
    """Check the whole spec and build every part before any simulation runs."""
    specs.check_top_level(spec, SECTIONS)
    parts = {"seed": int(spec.get("seed", 0))}
    with specs.section("network"):
        parts["array"] = ResonatorArray(**specs.check_section(spec, "network", ResonatorArray))
    with specs.section("stimulus"):
        scene = scene_from_spec(spec.get("stimulus", {"kind": "course"}))
        if not isinstance(scene, CourseScene):
            raise SpecError("stimulus.kind", "robot", "'course' (scenes with obstacles)")
        scene.validate()
        parts["scene"] = scene
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g", "threshold"])
        parts["chain_args"] = (scene.rate_hz, scene.adc_bits, scene.full_scale_g, pre)
        make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
    with specs.section("readout"):
        read = dict(specs.check_section(spec, "readout", ContactDetector, extra=["window_s"]))
        parts["window_s"] = float(read.pop("window_s", 0.1))
        parts["detector"] = ContactDetector(**{k: tuple(v) if isinstance(v, list) else v
                                               for k, v in read.items()})
    with specs.section("course"):
        parts["course"] = {**_course_settings(),
                           **specs.check_section(spec, "course", _course_settings)}
    with specs.section("sweep"):
        sweep = {**_sweep_settings(), **specs.check_section(spec, "sweep", _sweep_settings)}
        th = np.asarray(sweep["thresholds_g"], dtype=float)
        check(th.ndim == 1 and len(th) >= 2 and np.all(np.isfinite(th)) and np.all(th >= 0)
              and np.all(np.diff(th) > 0), "thresholds_g", sweep["thresholds_g"],
              "at least two increasing thresholds >= 0 g")
        v = np.asarray(sweep["speeds_cm_s"], dtype=float)
        if v.ndim != 1 or len(v) < 2 or not np.all(np.isfinite(v)) or np.any(v < 0):
            raise SpecError("speeds_cm_s", sweep["speeds_cm_s"],
                            "at least two finite speeds >= 0 cm/s")
        check(np.all(np.diff(v) > 0), "speeds_cm_s", sweep["speeds_cm_s"], "increasing speeds")
        replace(scene, speed=SpeedProfile("ramp", points=[[0, float(v.min())],
                                                          [1, float(v.max())]])).validate()
        check(isinstance(sweep["n_scenes"], int) and sweep["n_scenes"] >= 1, "n_scenes",
              sweep["n_scenes"], "an integer >= 1")
        check(0 <= sweep["settle_s"] < sweep["scene_s"], "settle_s", sweep["settle_s"],
              "a time in [0, scene_s) s")
        check(isinstance(sweep["codings_per_run"], int) and sweep["codings_per_run"] >= 1,
              "codings_per_run", sweep["codings_per_run"], "an integer >= 1")
        check(isinstance(sweep["workers"], int) and sweep["workers"] >= 0, "workers",
              sweep["workers"], "an integer >= 0 (0: one Dask worker per CPU core; 1: this "
              "process)")
        sweep["thresholds_g"], sweep["speeds_cm_s"] = th, v
        parts["sweep"] = sweep
    with specs.section("gate"):
        table = dict(specs.check_section(spec, "gate", SpeedGate, extra=["train_speeds_cm_s"]))
        train = np.asarray(table.pop("train_speeds_cm_s", v[::2]), dtype=float)
        missing = sorted(set(train.tolist()) - set(v.tolist()))
        if missing:
            raise SpecError("train_speeds_cm_s", train.tolist(),
                            f"speeds of the sweep (not swept: {missing})")
        if "speed_range_cm_s" not in table:
            table["speed_range_cm_s"] = (float(v.min()), float(v.max()))
        table["speed_range_cm_s"] = tuple(table["speed_range_cm_s"])
        table.setdefault("seed", int(spec.get("seed", 0)))
        parts["gate"] = SpeedGate(**table)
        parts["gate"].check_speeds(v, "sweep.speeds_cm_s")
        parts["train_speeds"] = train
    with specs.section("evaluation"):
        parts["evaluation"] = {**_evaluation_settings(),
                               **specs.check_section(spec, "evaluation", _evaluation_settings)}
    with specs.section("network"):
        parts["array"].check_rate(scene.rate_hz)
    return parts


# -- scenes -------------------------------------------------------------------------------
def make_scene(parts: dict, speed: SpeedProfile, seed: int) -> CourseScene:
    sweep = parts["sweep"]
    rng = np.random.default_rng([seed, 7])
    top = float(np.max(speed.at(np.linspace(0, sweep["scene_s"], 50))))
    course = {k: tuple(v) if isinstance(v, list) else v for k, v in parts["course"].items()}
    obstacles = random_course(rng, top * sweep["scene_s"] + 80.0, **course)
    return replace(parts["scene"], duration_s=float(sweep["scene_s"]), speed=speed,
                   speed_cm_s=float(speed.at(0.0)), obstacles=obstacles, contacts=[],
                   stop_after_contact_s=None)


def conditioned(parts: dict, scene: CourseScene, seed: int):
    """The scene's recording and its signal just before the coder (g, one channel)."""
    rate_hz, bits, fs, pre = parts["chain_args"]
    rec = scene.generate(seed)
    chain = make_chain(rate_hz, bits, fs, **pre).fit(rec.samples)
    x = rec.samples
    for _, step in chain.steps[:-1]:
        x = step.transform(x)
    return rec, x, chain.named_steps["coder"]


def score_codings(parts: dict, coded: np.ndarray, labels: list) -> tuple[list, list]:
    """Columns of ``coded`` as copies of the array in ONE Brian2 group, each column's
    detections scored against its scene's ``(contacts, duration_s)`` in ``labels``.
    Returns (Score, rate map) per column."""
    detector, window_s = parts["detector"], parts["window_s"]
    maps = run_codings(parts["array"], coded, parts["scene"].rate_hz, window_s,
                       target=parts["sweep"]["target"])
    scores = [score(detector.detect(rates), contacts, duration_s, detector, parts["array"],
                    window_s, parts["sweep"]["settle_s"])
              for rates, (contacts, duration_s) in zip(maps, labels)]
    return scores, maps


def _score_batch(spec: dict, coded: np.ndarray, labels: list) -> tuple[list, list]:
    """``score_codings`` on a Dask worker: the parts are rebuilt there from the spec."""
    return score_codings(build(spec), coded, labels)


class Codings:
    """Coded columns → (Score, rate map) each, ``sweep.codings_per_run`` columns per Brian2
    group (fewer, larger runs: Brian2's cost per step hardly grows with the group's size).

    ``submit(items)`` takes [(recording, coded column)] and returns at once: with a Dask
    client the batches start on the study's workers, so this process can do other work
    meanwhile (the study trains the gate while the workers run Fig. 9 and the fixed-Th
    evaluation); without one they are deferred. ``collect`` waits for them (or runs them
    here) and returns scores and maps in the items' order.
    """

    def __init__(self, spec: dict, client=None):
        self.spec, self.parts, self.client = spec, build(spec), client
        if client is not None:
            prepare_workers(client)

    def submit(self, items: list) -> list:
        per_run = self.parts["sweep"]["codings_per_run"]
        pending = []
        for i in range(0, len(items), per_run):
            batch = items[i:i + per_run]
            coded = np.stack([c for _, c in batch], axis=1)
            labels = [(rec.contacts, rec.duration_s) for rec, _ in batch]
            pending.append(partial(score_codings, self.parts, coded, labels)
                           if self.client is None else
                           self.client.submit(_score_batch, self.spec, coded, labels,
                                              pure=False))
        return pending

    def collect(self, pending: list, desc: str | None = None) -> tuple[list, list]:
        from tqdm import tqdm

        scores, maps = [], []
        for handle in tqdm(pending, desc=desc, unit="run",
                           disable=desc is None or len(pending) < 2):
            batch_scores, batch_maps = handle() if isinstance(handle, partial) else \
                handle.result()
            scores += batch_scores
            maps += batch_maps
        return scores, maps

    def run(self, items: list, desc: str | None = None) -> tuple[list, list]:
        return self.collect(self.submit(items), desc)


SWEEP_OUTPUTS = {
    "tp": Output("i4", "1", "contacts detected (true positives)"),
    "fp": Output("i4", "1", "detections away from any contact (false positives)"),
    "misses": Output("i4", "1", "scored contacts without a detection"),
    "duplicates": Output("i4", "1", "further detections within a detected contact"),
    "unscored_contacts": Output("i4", "1", "contacts outside the array's band"),
    "latency_sum_s": Output("f8", "s", "summed latency of the true positives"),
    "minutes": Output("f8", "min", "scored time"),
}


def sweep_scene(parts: dict, speed_cm_s: float, scene: int):
    """The sweep's seeded course scene ``scene`` at a constant speed, conditioned."""
    seed = parts["seed"] * 1000 + int(scene)
    return conditioned(parts, make_scene(parts, SpeedProfile("constant", float(speed_cm_s)),
                                         seed), seed)


@dataclass(frozen=True)
class ThresholdSweep:
    """The Th × speed sweep as a ``sweep.run_sweep`` evaluator (so it runs on Dask workers,
    resumes after an interruption and lands in a zarr store like every sweep).

    Points over ``speed_cm_s`` × ``scene`` × ``threshold_g``: each (speed, scene) of a chunk is
    generated and conditioned once and coded at each of its thresholds, and all codings of the
    chunk run as copies of the array in one Brian2 group (``Codings``). It holds the
    resolved spec, so it pickles; ``build`` re-checks it on the worker (milliseconds).
    """
    spec: dict

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        codings = Codings(self.spec)   # builds (re-checks) the parts here, on the worker
        parts = codings.parts
        n = len(points["threshold_g"])
        items, order = [], []
        pairs = np.stack([points["speed_cm_s"], points["scene"]], axis=1)
        for v, scene in np.unique(pairs, axis=0):
            idx = np.flatnonzero((pairs[:, 0] == v) & (pairs[:, 1] == scene))
            rec, x, coder = sweep_scene(parts, v, scene)
            coded = coder.partial_transform(np.repeat(x[:, None], len(idx), axis=1),
                                            threshold=points["threshold_g"][idx][None, :])
            items += [(rec, coded[:, j]) for j in range(len(idx))]
            order += list(idx)
        scores, _ = codings.run(items)
        out = {name: np.zeros(n, dtype=o.dtype) for name, o in SWEEP_OUTPUTS.items()}
        for i, sc in zip(order, scores):
            for name in ("tp", "fp", "misses", "duplicates", "unscored_contacts", "minutes"):
                out[name][i] = getattr(sc, name)
            out["latency_sum_s"][i] = float(np.sum(sc.latencies_s))
        return out


def sweep_settings(spec: dict) -> dict:
    """What makes two sweeps the same (the store's fingerprint): not the gate or evaluation
    settings, nor where it runs, so changing those reuses a finished sweep."""
    resolved = specs.resolved(spec)
    settings = {k: resolved.get(k) for k in ("seed", "network", "stimulus", "preprocess",
                                             "readout", "course", "sweep")}
    settings["sweep"] = {k: v for k, v in (settings["sweep"] or {}).items() if k != "workers"}
    return settings


def pooled_f1(scores) -> float:
    total = sum(scores, Score())
    return total.f1 if total.f1 is not None else 0.0


def choose_th_star(thresholds: np.ndarray, f1: np.ndarray) -> float:
    """The Th > 0 of best F1, smoothed over neighbouring thresholds.

    A few contacts per speed make F1 at one Th noisy; averaging each Th's F1 with its two
    neighbours on the (log-spaced) grid picks the middle of a robust plateau rather than a
    lucky point at its edge. Ties: the geometric centre of the tied thresholds.
    """
    candidates = np.flatnonzero(thresholds > 0)
    smooth = np.array([np.mean(f1[max(i - 1, candidates[0]):i + 2]) for i in candidates])
    tied = thresholds[candidates][smooth >= smooth.max() - 1e-9]
    centre = np.exp(np.mean(np.log(tied)))
    return float(tied[np.argmin(np.abs(np.log(tied) - np.log(centre)))])


def monotone_th_star(speeds: np.ndarray, best_th: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Th*(speed): the non-decreasing fit (in log Th) of each speed's best threshold.

    The self-motion Th must hide grows with speed, so a speed whose argmax falls below a slower
    speed's is noise of a few contacts; isotonic regression pools such neighbours, weighted by
    how many contacts each speed scored.
    """
    from sklearn.isotonic import IsotonicRegression

    fit = IsotonicRegression(increasing=True).fit(speeds, np.log(best_th),
                                                  sample_weight=np.maximum(weights, 1))
    return np.exp(fit.predict(speeds))


# -- the study ----------------------------------------------------------------------------
def run(spec: dict, out_dir, quick: bool = False, fresh: bool = False,
        scheduler: str | None = None, log=print) -> dict:
    parts = build(spec)
    # One Dask client (or none: ``sweep.workers = 1``) serves every Brian2 stage.
    with executor(parts["sweep"]["workers"], scheduler, log) as client:
        return _run(spec, parts, Path(out_dir), quick, fresh, client, log)


def _run(spec: dict, parts: dict, out_dir: Path, quick: bool, fresh: bool, client,
         log) -> dict:
    seed = parts["seed"]
    sweep, gate, ev = parts["sweep"], parts["gate"], parts["evaluation"]
    thresholds, speeds = sweep["thresholds_g"], sweep["speeds_cm_s"]
    t_start = time.perf_counter()
    n_sc = sweep["n_scenes"]

    # 1. the sweep ---------------------------------------------------------------------------
    log(f"[1/4] sweep: {len(speeds)} speeds x {len(thresholds)} thresholds x {n_sc} scenes of "
        f"{sweep['scene_s']:g} s ({len(speeds) * len(thresholds) * n_sc} codings, "
        f"{parts['array'].n_neurons} resonators each)")
    grid = Grid({"speed_cm_s": speeds, "scene": np.arange(n_sc),
                 "threshold_g": thresholds}, {"speed_cm_s": "cm/s", "threshold_g": "g"})
    outcome = run_sweep(grid, ThresholdSweep(specs.resolved(spec)), out_dir / "sweep.zarr",
                        SWEEP_OUTPUTS, client=client, fresh=fresh,
                        chunk_points=sweep["codings_per_run"], settings=sweep_settings(spec),
                        attrs={"description": "Th x speed sweep: detections scored per "
                                              "contact", "spec": specs.resolved(spec)})
    log(f"      {len(outcome.chunks_computed)} chunk(s) computed, "
        f"{len(outcome.chunks_skipped)} already in {out_dir / 'sweep.zarr'}, "
        f"{outcome.wall_s:.0f} s")
    ds = outcome.data
    pooled = ds.sum("scene")
    f1 = (2 * pooled.tp / (2 * pooled.tp + pooled.fp + pooled.misses)).fillna(0.0)
    ds["f1"] = f1
    ds["fp_per_min"] = pooled.fp / pooled.minutes
    ds["latency_s"] = (pooled.latency_sum_s / pooled.tp.where(pooled.tp > 0))
    per_speed_best = np.array([choose_th_star(thresholds, f1.isel(speed_cm_s=i).values)
                               for i in range(len(speeds))])
    scored = (pooled.tp + pooled.misses).max("threshold_g").values
    th_star = monotone_th_star(speeds, per_speed_best, scored)
    ds["best_th_g"] = ("speed_cm_s", per_speed_best,
                       {"long_name": "argmax of smoothed F1 per speed"})
    ds["th_star_g"] = ("speed_cm_s", th_star, {"long_name": "monotone fit of best_th_g"})
    # The single Th a user would deploy without a gate: best F1 over every speed of the sweep,
    # chosen as each speed's best is.
    overall = ds[["tp", "fp", "misses"]].sum(("speed_cm_s", "scene"))
    sweep_fixed_th = choose_th_star(thresholds, (2 * overall.tp / (
        2 * overall.tp + overall.fp + overall.misses)).fillna(0.0).values)
    log("      best Th per speed: " + ", ".join(f"{v:g}: {t:.3g}"
                                                for v, t in zip(speeds, per_speed_best)))
    log("      Th*(speed), monotone: " + ", ".join(f"{v:g}: {t:.3g}"
                                                   for v, t in zip(speeds, th_star)))
    codings = Codings(specs.resolved(spec), client)
    where = "on the Dask workers" if client is not None else "after the gate"

    # 2. Fig. 9 in kind: Th = 0, Th*, 2 Th* at the paper's two speeds -----------------------------
    log(f"[2/4] Fig. 9 in kind: Th = 0, Th*, 2·Th* at low and high speed (runs {where})")
    fig9, items = {}, []
    for v in LOW_HIGH_CM_S:
        iv = int(np.argmin(np.abs(speeds - v)))
        ts = [0.0, th_star[iv], 2 * th_star[iv]]
        fig9[float(speeds[iv])] = {"thresholds": ts}
        for s in range(n_sc):
            rec, x, coder = sweep_scene(parts, speeds[iv], s)
            fig9[float(speeds[iv])].setdefault("rec", rec)
            coded = coder.partial_transform(np.repeat(x[:, None], 3, axis=1),
                                            threshold=np.array(ts)[None, :])
            items += [(rec, coded[:, j]) for j in range(3)]
    fig9_runs = codings.submit(items)

    # New scenes for the evaluation (new seeds: constant speeds and ramps); the fixed-Th codings
    # need no gate, so they start now and run while the gate learns.
    methods = [f"fixed:{t:g}" for t in thresholds] + ["lookup", "gated"]
    eval_profiles = [(f"{v:g} cm/s", SpeedProfile("constant", float(v))) for v in speeds]
    eval_profiles += [(f"ramp {i}", SpeedProfile("ramp", points=[
        [0.0, float(speeds.min())], [float(sweep["scene_s"]), float(speeds.max())]]))
        for i in range(ev["n_ramps"])]
    scenes = []   # (profile index, seed slot, recording, conditioned signal, coder)
    for ip, (name, profile) in enumerate(eval_profiles):
        slots = range(ev["n_scenes"]) if profile.kind == "constant" else \
            [(ip - len(speeds)) % max(ev["n_scenes"], 1)]
        for s in slots:
            sd = ev["seed_offset"] + seed * 1000 + ip * 10 + s
            scenes.append((ip, s, *conditioned(parts, make_scene(parts, profile, sd), sd)))
    items = []
    for ip, s, rec, x, coder in scenes:
        coded = coder.partial_transform(np.repeat(x[:, None], len(thresholds), axis=1),
                                        threshold=thresholds[None, :])
        items += [(rec, coded[:, j]) for j in range(len(thresholds))]
    fixed_runs = codings.submit(items)
    del items

    # 3. the gate ---------------------------------------------------------------------------------
    train = parts["train_speeds"]
    train_th = np.array([th_star[int(np.flatnonzero(speeds == v)[0])] for v in train])
    log(f"[3/4] training the speed gate in Brian2 on {len(train)} speeds "
        f"({gate.epochs} epochs, {gate.present_s:g} s per presentation)")
    gate.fit(train, train_th, test_speeds=speeds)
    recalled = gate.learning_curve_.isel(epoch=-1).values
    held_out = ~np.isin(speeds, train)
    ratio = recalled / th_star
    log("      recalled/Th*: " + ", ".join(f"{v:g}: {r:.2f}" for v, r in zip(speeds, ratio)))

    # 4. gated vs fixed vs lookup on the new scenes -----------------------------------------------
    log(f"[4/4] evaluation on new scenes: {ev['n_scenes']} per speed + {ev['n_ramps']} ramps "
        f"0→{speeds.max():g} cm/s, fixed Th (all {len(thresholds)}), lookup and gated")
    log(f"      the gate recalls Th online along {len(scenes)} scenes' speed")
    speed_cols = np.stack([rec.meta["speed_cm_s"] for _, _, rec, _, _ in scenes], axis=1)
    gated_th = gate.thresholds(speed_cols, scenes[0][2].rate_hz)
    lookup_th = np.exp(np.interp(speed_cols, train, np.log(train_th)))
    items = []
    for k, (ip, s, rec, x, coder) in enumerate(scenes):
        items += [(rec, coder.partial_transform(x, threshold=lookup_th[:, k])),
                  (rec, coder.partial_transform(x, threshold=gated_th[:, k]))]
    adaptive_runs = codings.submit(items)
    del items
    scores, maps = codings.collect(fig9_runs, "Fig. 9")
    for r, e in enumerate(fig9.values()):
        block = slice(r * 3 * n_sc, (r + 1) * 3 * n_sc)
        sc, mp = scores[block], maps[block]
        e["scores"] = [sum(sc[j::3], Score()) for j in range(3)]
        e["maps"] = mp[:3]
    fixed_scores, _ = codings.collect(fixed_runs, "evaluation, fixed Th")
    adaptive_scores, adaptive_maps = codings.collect(adaptive_runs, "evaluation, lookup and gated")
    n_th = len(thresholds)
    eval_scores, example = {}, None   # (profile index, seed slot, method) -> Score
    for k, (ip, s, rec, _, _) in enumerate(scenes):
        for j, t in enumerate(thresholds):
            eval_scores[(ip, s, f"fixed:{t:g}")] = fixed_scores[k * n_th + j]
        eval_scores[(ip, s, "lookup")] = adaptive_scores[2 * k]
        eval_scores[(ip, s, "gated")] = adaptive_scores[2 * k + 1]
        if eval_profiles[ip][1].kind == "ramp" and example is None:
            example = {"rec": rec, "gated_th": gated_th[:, k], "lookup_th": lookup_th[:, k],
                       "map": adaptive_maps[2 * k + 1]}
    n_slots = max(ev["n_scenes"], 1)

    def f1_per_seed(method, profiles=range(len(eval_profiles))):
        return np.array([pooled_f1([eval_scores[(ip, s, method)] for ip in profiles
                                    if (ip, s, method) in eval_scores])
                         for s in range(n_slots)])

    per_method = {m: f1_per_seed(m) for m in methods}
    fixed_means = np.array([per_method[f"fixed:{t:g}"].mean() for t in thresholds])
    oracle_th = float(thresholds[int(np.argmax(fixed_means))])
    stats = lambda a: {"mean": float(np.mean(a)), "std": float(np.std(a, ddof=1))
                       if len(a) > 1 else 0.0, "per_seed": [float(x) for x in a]}
    f1_gated, f1_lookup = stats(per_method["gated"]), stats(per_method["lookup"])
    f1_fixed = {**stats(per_method[f"fixed:{oracle_th:g}"]), "threshold_g": oracle_th}
    f1_deployed = {**stats(per_method[f"fixed:{sweep_fixed_th:g}"]),
                   "threshold_g": sweep_fixed_th}
    compared = {"gated": "gated", "lookup": "lookup",
                f"best fixed {oracle_th:g} g": f"fixed:{oracle_th:g}",
                f"sweep's fixed {sweep_fixed_th:g} g": f"fixed:{sweep_fixed_th:g}",
                "Th = 0": f"fixed:{thresholds[0]:g}"}
    per_speed = []
    for ip, (name, _) in enumerate(eval_profiles):
        row = {"scenes": name}
        for label, method in compared.items():
            total = sum((eval_scores[k] for k in eval_scores
                         if k[0] == ip and k[2] == method), Score())
            row[f"F1 {label}"] = total.f1
            if method == "gated":
                row["FP/min gated"] = total.fp_per_min
                row["latency gated (s)"] = total.latency_s
                row["contacts scored"] = total.tp + total.misses
        per_speed.append(row)
    diff = per_method["gated"] - per_method[f"fixed:{oracle_th:g}"]
    diff_deployed = per_method["gated"] - per_method[f"fixed:{sweep_fixed_th:g}"]

    # -- paper-in-kind checks -------------------------------------------------------------------
    driving = speeds > 0
    fp0 = float(ds.fp_per_min.sel(threshold_g=thresholds[0]).values[driving].mean())
    i12, i27 = (int(np.argmin(np.abs(speeds - v))) for v in LOW_HIGH_CM_S)
    in_kind = {
        "fp_per_min_at_th0_while_driving": fp0,
        "th_star_ratio_27_to_12": float(th_star[i27] / th_star[i12]),
        "tp_at_th_star_vs_double": {f"{v:g}": [fig9[v]["scores"][1].tp,
                                               fig9[v]["scores"][2].tp] for v in fig9},
        "highest_th_misses_all": bool(ds.tp.sel(threshold_g=thresholds[-1]).sum() == 0),
    }
    summary = {
        "th_star": {f"{v:g}": float(t) for v, t in zip(speeds, th_star)},
        "f1_gated": f1_gated,
        "f1_best_fixed": f1_fixed,
        "f1_lookup": f1_lookup,
        "gated_minus_best_fixed": stats(diff),
        "f1_sweep_fixed": f1_deployed,
        "gated_minus_sweep_fixed": stats(diff_deployed),
        "best_th_per_speed": {f"{v:g}": float(t) for v, t in zip(speeds, per_speed_best)},
        "recall_ratio": {f"{v:g}": float(r) for v, r in zip(speeds, ratio)},
        "recall_error_factor_held_out": float(np.exp(np.mean(np.abs(np.log(ratio[held_out])))))
        if held_out.any() else None,
        "recall_error_factor_trained": float(np.exp(np.mean(np.abs(np.log(ratio[~held_out]))))),
        "train_speeds_cm_s": train.tolist(),
        "paper_in_kind": in_kind,
        "per_speed": per_speed,
        "quick": quick,
        "sweep_chunks": {"computed": len(outcome.chunks_computed),
                         "reused": len(outcome.chunks_skipped), "workers": outcome.workers},
        "sweep_wall_s": outcome.wall_s,
        "total_wall_s": time.perf_counter() - t_start,
    }
    _write_report(out_dir, spec, parts, ds, th_star, fig9, gate, train, train_th, held_out,
                  recalled, per_speed, summary, example, fixed_means, thresholds)
    log(human_summary(summary, out_dir))
    return summary


def human_summary(s: dict, out_dir) -> str:
    g, f, lk = s["f1_gated"], s["f1_best_fixed"], s["f1_lookup"]
    d = s["gated_minus_best_fixed"]
    sf, dd = s["f1_sweep_fixed"], s["gated_minus_sweep_fixed"]
    return "\n".join([
        "Th*: " + ", ".join(f"{v} cm/s {t:.3g} g" for v, t in s["th_star"].items()),
        f"F1 gated {g['mean']:.3f} ± {g['std']:.3f}, lookup {lk['mean']:.3f} ± {lk['std']:.3f}",
        f"best fixed in hindsight (Th = {f['threshold_g']:g} g) {f['mean']:.3f} ± "
        f"{f['std']:.3f}: gated − fixed {d['mean']:+.3f} ± {d['std']:.3f}",
        f"fixed Th chosen on the sweep ({sf['threshold_g']:g} g) {sf['mean']:.3f} ± "
        f"{sf['std']:.3f}: gated − fixed {dd['mean']:+.3f} ± {dd['std']:.3f}",
        f"report in {out_dir}/report.html ({s['total_wall_s']:.0f} s)"])


# -- report -------------------------------------------------------------------------------
def _write_report(out_dir, spec, parts, ds, th_star, fig9, gate, train, train_th, held_out,
                  recalled, per_speed, summary, example, fixed_means, thresholds):
    rep = Report(out_dir, "snn-antenna: gating threshold and the learned speed gate")
    rep.text(spec.get("description", ""))
    d = summary["gated_minus_best_fixed"]
    g, f = summary["f1_gated"], summary["f1_best_fixed"]
    sf, dd = summary["f1_sweep_fixed"], summary["gated_minus_sweep_fixed"]
    verdict = "above" if d["mean"] > 0 else "equal to" if d["mean"] == 0 else "below"
    rep.text(f"On scenes not used for training, the learned gate's F1 is {g['mean']:.3f} ± "
             f"{g['std']:.3f} (mean ± sd over {len(g['per_seed'])} seeds), {verdict} the best "
             f"single fixed threshold in hindsight ({f['threshold_g']:g} g: {f['mean']:.3f} ± "
             f"{f['std']:.3f}) by {d['mean']:+.3f} ± {d['std']:.3f} (paired by seed), and "
             f"{dd['mean']:+.3f} ± {dd['std']:.3f} against the fixed threshold a user would pick "
             f"from the sweep ({sf['threshold_g']:g} g: {sf['mean']:.3f} ± {sf['std']:.3f}); "
             f"the lookup table of Th* reaches {summary['f1_lookup']['mean']:.3f} ± "
             f"{summary['f1_lookup']['std']:.3f}.")
    rep.heading("Th × speed sweep")
    rep.figure(_fig_f1_curves(ds, th_star), "f1_vs_threshold",
               "F1, false positives per minute and mean latency against Th, one line per speed "
               "(pooled over the sweep's scenes); dots mark Th*(speed), crosses each speed's "
               "own best Th before the monotone fit.")
    rep.table([{"speed (cm/s)": float(v), "best Th (g)": float(b), "Th* (g)": float(t),
                "F1 at Th*": f1_at(ds, v, t),
                "FP/min at Th = 0": float(ds.fp_per_min.sel(speed_cm_s=v).isel(threshold_g=0)),
                # every scored contact is a hit or a miss, whatever the threshold
                "contacts scored": int((ds.tp + ds.misses).sel(speed_cm_s=v)
                                       .isel(threshold_g=0).sum()),
                "out of the array's band": int(ds.unscored_contacts.sel(speed_cm_s=v)
                                               .isel(threshold_g=0).sum())}
               for v, b, t in zip(ds.speed_cm_s.values, ds.best_th_g.values, th_star)],
              "Th*(speed) from the sweep: each speed's best Th and their monotone fit")
    rep.heading("Fig. 9 in kind")
    rep.figure(_fig9(fig9, parts), "fig9_rate_maps",
               "Rate maps of one scene at low and high speed for Th = 0, Th* and 2·Th*; "
               "dashed lines mark true contacts (cyan: scored, grey: outside the array's "
               "band), green lines detections.")
    rep.table([{"speed (cm/s)": v, "Th": lab, "Th (g)": th, **sc.as_dict()}
               for v, e in fig9.items()
               for lab, th, sc in zip(("0", "Th*", "2·Th*"), e["thresholds"], e["scores"])],
              "Detections pooled over the sweep's scenes")
    rep.heading("The speed gate (Brian2 associative memory)")
    rep.figure(_fig_gate(gate, ds, th_star, train, train_th, held_out, recalled), "gate",
               "Left: learning curves, recall error factor exp(mean |log(recalled/Th*)|) on "
               "trained and held-out speeds. Right: Th* from the sweep, the gate's recall and "
               "the lookup table.")
    rep.heading("Gated vs fixed vs lookup on new scenes")
    rep.figure(_fig_compare(fixed_means, thresholds, summary), "f1_methods",
               "Pooled F1 over all evaluation scenes (mean over seeds) for every fixed Th, "
               "with the gate and the lookup table as horizontal lines.")
    rep.figure(_fig_per_speed(per_speed), "f1_per_speed",
               "F1 per evaluation scene type (pooled over seeds): the gate, the lookup table, "
               "the best fixed Th in hindsight, the sweep's fixed Th and Th = 0.")
    rep.table(per_speed, "F1 per speed on the evaluation scenes")
    if example is not None:
        rep.figure(_fig_ramp(example, parts), "ramp_example",
                   "A ramp scene 0→30 cm/s: speed, the gate's online Th (and the lookup), "
                   "and the rate map under the gated Th.")
    rep.write(summary, spec, parts["array"].target)


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def f1_at(ds, speed, th) -> float:
    """Sweep F1 at ``speed`` for a Th between grid points (interpolated in log Th)."""
    grid = ds.threshold_g.values
    f1 = ds.f1.sel(speed_cm_s=speed).values
    positive = grid > 0
    return float(np.interp(np.log(th), np.log(grid[positive]), f1[positive]))


def _fig_per_speed(per_speed):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4))
    names = [r["scenes"] for r in per_speed]
    styles = {"gated": ("tab:red", "o-"), "lookup": ("tab:blue", "s--")}
    for key in (k for k in per_speed[0] if k.startswith("F1 ")):
        label = key[3:]
        color, style = styles.get(label, (None, ".:"))
        ax.plot(range(len(names)), [np.nan if r[key] is None else r[key] for r in per_speed],
                style, color=color, label=label)
    ax.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("F1")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _fig_f1_curves(ds, th_star):
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    th = ds.threshold_g.values
    x = np.where(th > 0, th, th[th > 0].min() / 2)
    cmap = plt.get_cmap("viridis")
    speeds = ds.speed_cm_s.values
    for i, v in enumerate(speeds):
        c = cmap(i / max(len(speeds) - 1, 1))
        axes[0].plot(x, ds.f1.isel(speed_cm_s=i), color=c, label=f"{v:g}")
        axes[0].plot(th_star[i], f1_at(ds, v, th_star[i]), "o", color=c)
        best = float(ds.best_th_g.values[i])
        axes[0].plot(best, f1_at(ds, v, best), "x", color=c)
        axes[1].plot(x, ds.fp_per_min.isel(speed_cm_s=i), color=c)
        axes[2].plot(x, ds.latency_s.isel(speed_cm_s=i), color=c)
    for ax, lab in zip(axes, ("F1", "false positives / min", "latency (s)")):
        ax.set_xscale("log")
        ax.set_xlabel("Th (g; leftmost point: Th = 0)")
        ax.set_ylabel(lab)
    axes[0].legend(title="cm/s", fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def _draw_map(ax, rates, rec, detections, parts, title):
    draw_rate_map(ax, rates)
    from ..gating import visible
    for c in rec.contacts:
        ok = visible(c, parts["detector"], parts["array"])
        ax.axvline(c.t_s, color="tab:cyan" if ok else "0.6", ls="--", lw=0.8)
    for d in detections:
        ax.axvline(d.onset_s, color="tab:green", lw=1.2)
    ax.set_title(title, fontsize=9)


def _fig9(fig9, parts):
    plt = _plt()
    fig, axes = plt.subplots(len(fig9), 3, figsize=(13, 3.2 * len(fig9)), squeeze=False,
                             sharex=True)
    for r, (v, e) in enumerate(fig9.items()):
        for c, (lab, th, rates) in enumerate(zip(("Th", "Th*", "2·Th*"), e["thresholds"],
                                                 e["maps"])):
            det = parts["detector"].detect(rates)
            _draw_map(axes[r, c], rates, e["rec"], det, parts,
                      f"{v:g} cm/s, {lab} = {th:.3g} g")
        axes[r, 0].set_ylabel("neuron (Hz)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def _fig_gate(gate, ds, th_star, train, train_th, held_out, recalled):
    plt = _plt()
    fig, (a0, a1) = plt.subplots(1, 2, figsize=(12, 4))
    lc = gate.learning_curve_
    err = np.abs(np.log(lc.values / th_star[None, :]))
    a0.plot(lc.epoch, np.exp(err[:, ~held_out].mean(1)), "o-", label="trained speeds")
    if held_out.any():
        a0.plot(lc.epoch, np.exp(err[:, held_out].mean(1)), "s-", label="held-out speeds")
    a0.set_yscale("log")
    a0.set_xlabel("epoch")
    a0.set_ylabel("recall error factor")
    a0.legend()
    v = ds.speed_cm_s.values
    a1.plot(v, th_star, "k.-", label="Th* (sweep)")
    a1.plot(v[~held_out], recalled[~held_out], "o", color="tab:blue", label="gate, trained")
    a1.plot(v[held_out], recalled[held_out], "s", color="tab:orange", label="gate, held out")
    fine = np.linspace(v.min(), v.max(), 100)
    a1.plot(fine, np.exp(np.interp(fine, train, np.log(train_th))), color="0.6", lw=1,
            label="lookup (interpolated)")
    a1.set_yscale("log")
    a1.set_xlabel("speed (cm/s)")
    a1.set_ylabel("Th (g)")
    a1.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _fig_compare(fixed_means, thresholds, summary):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.where(thresholds > 0, thresholds, thresholds[thresholds > 0].min() / 2)
    ax.plot(x, fixed_means, "k.-", label="fixed Th")
    ax.axhline(summary["f1_gated"]["mean"], color="tab:red", label="learned gate")
    ax.axhline(summary["f1_lookup"]["mean"], color="tab:blue", ls="--", label="lookup table")
    ax.set_xscale("log")
    ax.set_xlabel("fixed Th (g; leftmost point: Th = 0)")
    ax.set_ylabel("F1 over all speeds")
    ax.legend()
    fig.tight_layout()
    return fig


def _fig_ramp(example, parts):
    plt = _plt()
    rec = example["rec"]
    fig, (a0, a1, a2) = plt.subplots(3, 1, figsize=(10, 7), sharex=True,
                                     gridspec_kw={"height_ratios": [0.6, 0.8, 1.6]})
    t = rec.t_s
    a0.plot(t, rec.meta["speed_cm_s"], color="k")
    a0.set_ylabel("speed (cm/s)")
    a1.plot(t, example["gated_th"], color="tab:red", label="gate (online)")
    a1.plot(t, example["lookup_th"], color="tab:blue", ls="--", label="lookup")
    a1.set_yscale("log")
    a1.set_ylabel("Th (g)")
    a1.legend(fontsize=8)
    rates = example["map"]
    _draw_map(a2, rates, rec, parts["detector"].detect(rates), parts, "gated")
    a2.set_ylabel("neuron (Hz)")
    a2.set_xlabel("time (s)")
    fig.tight_layout()
    return fig
