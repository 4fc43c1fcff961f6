"""The model selection's stage: every candidate's grid point measured for its calibration
(its bench set, signal statistics and the calibration targets' read-out per seed), each
candidate's constant chosen on the calibration targets, the predicted read-outs measured at
that constant, the candidates compared on their predictions; the summary and report."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ...core.logfile import logged
from ...engine.batches import Batches
from ...engine.executor import executor
from ...evaluation import crossval as cv
from ...evaluation import signal as bench_signal
from ...evaluation.confusion import confusion
from ...readout import events
from ...readout.baselines import distance_baselines, material_baselines, two_material_baseline
from ...report.page import Report
from ..contract import Options, Plan
from .plan import Parts, point_workers
from .protocol import (
    CALIBRATION_TARGETS,
    PAPER_PAIR,
    PREDICTIONS,
    SCORES,
    calibrated_point,
    choose,
    confused_pairs,
    select,
)
from .report import QUICK_NOTE, write_report

# A grid point whose events the paper's processing skips more often than this is unreadable.
MAX_SKIPPED = 0.10


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick, fresh = plan.spec, plan.parts, options.quick, options.fresh
    out_dir, t0 = Path(out_dir), time.perf_counter()
    grid = [(c.physics, float(s)) for c in parts.selection.candidates for s in c.strengths]
    # every grid point is independent (its own bench set, seeded by the spec): one Batches
    # item each, on the Dask workers of --scheduler or stimulus.n_jobs local ones, else here
    workers = point_workers(parts, len(grid))
    with executor(workers, options.scheduler, log) as client:
        # on workers the points share the cores: each makes its bench set on one process
        # (n_jobs is not part of a bench set's key: the same data either way)
        if client is not None:
            parts = replace(parts, bench=replace(parts.bench, n_jobs=1))
        quiet = log if client is None else print
        # first every point's calibration quantities; a candidate's predictions are then
        # read at its calibrated point alone (the choice never sees them), submitted as soon
        # as the candidate's last point is in so that the workers stay busy
        calibrate = Batches(PointsWork(calibration, parts, fresh, quiet), per_run=1, client=client)
        predict = Batches(PointsWork(predictions, parts, fresh, quiet), per_run=1, client=client)
        pending = calibrate.submit(grid)
        points, predicting = [], []
        for i, ((physics, strength), run) in enumerate(zip(grid, pending), 1):
            log(f"[{i}/{len(grid)}] {physics} × {strength:g}")
            points += calibrate.collect([run])
            if i == len(grid) or grid[i][0] != physics:
                best = calibrated_point([p for p in points if p["physics"] == physics])
                if best is not None:
                    predicting.append((best, predict.submit([(physics, best["strength"])])))
        for best, run in predicting:
            log(f"predictions at {best['physics']} × {best['strength']:g}")
            best["per_seed"].update(predict.collect(run)[0])
    candidates = {c.physics: choose(c.physics, [p for p in points if p["physics"] == c.physics])
                  for c in parts.selection.candidates}
    decision = select(candidates)
    summary = {"grid": points, "candidates": candidates, "selection": decision,
               "calibration_targets": {k: {"paper": v[0], "tolerance": v[1], "what": v[2]}
                                       for k, v in CALIBRATION_TARGETS.items()},
               "predicted_quantities": {k: {"paper": v[0], "done_when": v[1],
                                            "larger_is_better": v[2], "what": v[3]}
                                        for k, v in PREDICTIONS.items()},
               "data": {"events_per_point": parts.bench.n_events,
                        "repetitions": parts.bench.repetitions,
                        "seeds": list(parts.evaluation.seeds)},
               "timing": {"total_s": time.perf_counter() - t0}}
    out_dir.mkdir(parents=True, exist_ok=True)
    report = Report(out_dir, "Model selection: the contact physics chosen by what it predicts",
                    quick=quick, quick_note=QUICK_NOTE)
    write_report(report, summary)
    summary = report.write(summary, spec, "none (no spiking part)")
    log(f"chosen: {decision['chosen']} ({decision['reason']})")
    log(f"report in {out_dir}/report.html ({summary['timing']['total_s']:.0f} s)")
    return summary


@dataclass(frozen=True)
class PointsWork:
    """``engine.batches.Batches`` work: grid points (mechanism, strength) → ``stage`` of each
    (``calibration`` or ``predictions``, module functions, so the work pickles to a worker)."""
    stage: Callable
    parts: Parts
    fresh: bool = False
    log: Callable = print

    def __call__(self, points: list) -> list:
        return [self.stage(self.parts, physics, strength, self.log, self.fresh)
                for physics, strength in points]


def measure(parts: Parts, physics: str, strength: float, log=print, fresh=False) -> dict:
    """One grid point with everything measured: its calibration quantities and, when it is
    readable, the predicted read-outs too (``run`` reads these at calibrated points only)."""
    point = calibration(parts, physics, strength, log, fresh)
    if "unreadable" not in point:
        point["per_seed"].update(predictions(parts, physics, strength, log, fresh))
    return point


def _features(parts: Parts, physics: str, strength: float, log, fresh):
    """The bench set of this mechanism and strength (cached on disk), its processed events
    and the share of them the paper's processing skipped."""
    spec = replace(parts.bench, physics=physics, physics_strength=strength)
    _, everything = bench_signal.load_features(spec, parts.processor, log, fresh)
    feats = everything.isel(event=np.flatnonzero(everything["skipped"].values == ""))
    return feats, events.skip_counts(everything), \
        1 - feats.sizes["event"] / everything.sizes["event"]


def calibration(parts: Parts, physics: str, strength: float, log=print, fresh=False) -> dict:
    """One grid point: the bench set of this mechanism and strength, its signal statistics
    and the calibration targets' read-out (the full-spectrum material MLP, whose confusions
    also give the paper's pair's rank), per seed."""
    feats, skipped, share = _features(parts, physics, strength, log, fresh)
    if share > MAX_SKIPPED:
        # The paper's processing read its contacts (an exponential decay, a clean onset): a
        # mechanism whose signal it cannot read is refuted by that, not scored.
        log(f"      unreadable: the paper's processing skipped {share:.0%} of the events")
        return {"physics": physics, "strength": strength, "skipped": skipped,
                "unreadable": f"the paper's processing skipped {share:.0%} of the events "
                              f"({', '.join(f'{k} {v}' for k, v in skipped.items() if v)})"}
    signal = bench_signal.signal_statistics(feats)
    ev = parts.evaluation
    material = material_baselines([], ev.material_mlp, ev.nmf_max_iter)
    results = cv.evaluate(feats, material, ev, log)
    materials = sorted(set(feats["material"].values.astype(str)))
    cm = confusion(results["mlp_spectrum_material"], len(materials))
    pairs = confused_pairs(cm, materials)
    rank = next(i for i, (pair, _) in enumerate(pairs, 1) if set(pair) == set(PAPER_PAIR))
    return {
        "physics": physics, "strength": strength, "events": int(feats.sizes["event"]),
        "skipped": skipped,
        "per_seed": _per_seed(results),
        "wood_aluminium_sites": float(signal.get("wood_aluminium_sites_differing", 0)),
        "wood_aluminium_sites_of": int(signal.get("wood_aluminium_sites", 0)),
        "brass_wood_rank": rank,
        "most_confused": [[*pair, rate] for pair, rate in pairs[:3]],
        "r2_low": signal["r2_low"], "r2_high": signal["r2_high"],
        "tau_low_cv_median": signal["tau_low_cv_median"],
    }


def predictions(parts: Parts, physics: str, strength: float, log=print, fresh=False) -> dict:
    """The predicted read-outs of a (readable) point, per seed: NMF-30, both distance MLPs
    and the 5-8-2 network, on the same bench set and splits as its calibration."""
    feats, _, _ = _features(parts, physics, strength, log, fresh)
    ev = parts.evaluation
    chosen = [b for b in material_baselines([30], ev.material_mlp, ev.nmf_max_iter)
              if b.name == "nmf_30"] + \
        [b for b in distance_baselines(feats.sizes["freq_hz"], ev.mlp)
         if b.name in ("mlp_spectrum", "mlp_parametric")] + [two_material_baseline(ev.mlp)]
    return _per_seed(cv.evaluate(feats, chosen, ev, log))


def _per_seed(results: dict) -> dict:
    """The study's per-seed numbers among ``results`` (``SCORES``)."""
    return {name: results[b].values(key).tolist()
            for name, (b, key) in SCORES.items() if b in results}
