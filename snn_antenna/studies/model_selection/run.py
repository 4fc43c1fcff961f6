"""The model selection's stage: every candidate's grid point measured (its bench set, signal
statistics and the paper's read-outs per seed), each candidate's constant chosen on the
calibration targets, the candidates compared on their predictions; the summary and report."""
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
from .plan import Parts
from .protocol import (
    CALIBRATION_TARGETS,
    PAPER_PAIR,
    PREDICTIONS,
    SCORES,
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
    workers = max(1, min(parts.bench.n_jobs, len(grid)))
    with executor(workers, options.scheduler, log) as client:
        work = MeasurePoints(parts, fresh, log if client is None else print)
        batches = Batches(work, per_run=1, client=client)
        pending = batches.submit(grid)
        points = []
        for i, ((physics, strength), run) in enumerate(zip(grid, pending), 1):
            log(f"[{i}/{len(grid)}] {physics} × {strength:g}")
            points += batches.collect([run])
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
class MeasurePoints:
    """``engine.batches.Batches`` work: grid points (mechanism, strength) → ``measure``."""
    parts: Parts
    fresh: bool = False
    log: Callable = print

    def __call__(self, points: list) -> list:
        return [measure(self.parts, physics, strength, self.log, self.fresh)
                for physics, strength in points]


def measure(parts: Parts, physics: str, strength: float, log=print, fresh=False) -> dict:
    """One grid point: the bench set of this mechanism and strength, its signal statistics
    and the paper's read-outs, per seed."""
    spec = replace(parts.bench, physics=physics, physics_strength=strength)
    _, everything = bench_signal.load_features(spec, parts.processor, log, fresh)
    feats = everything.isel(event=np.flatnonzero(everything["skipped"].values == ""))
    skipped = events.skip_counts(everything)
    share = 1 - feats.sizes["event"] / everything.sizes["event"]
    if share > MAX_SKIPPED:
        # The paper's processing read its contacts (an exponential decay, a clean onset): a
        # mechanism whose signal it cannot read is refuted by that, not scored.
        log(f"      unreadable: the paper's processing skipped {share:.0%} of the events")
        return {"physics": physics, "strength": strength, "skipped": skipped,
                "unreadable": f"the paper's processing skipped {share:.0%} of the events "
                              f"({', '.join(f'{k} {v}' for k, v in skipped.items() if v)})"}
    signal = bench_signal.signal_statistics(feats)
    ev = parts.evaluation
    n_bins = feats.sizes["freq_hz"]
    chosen = [b for b in material_baselines([30], ev.material_mlp, ev.nmf_max_iter)] + \
        [b for b in distance_baselines(n_bins, ev.mlp)
         if b.name in ("mlp_spectrum", "mlp_parametric")] + [two_material_baseline(ev.mlp)]
    results = cv.evaluate(feats, chosen, ev, log)
    materials = sorted(set(feats["material"].values.astype(str)))
    cm = confusion(results["mlp_spectrum_material"], len(materials))
    pairs = confused_pairs(cm, materials)
    rank = next(i for i, (pair, _) in enumerate(pairs, 1) if set(pair) == set(PAPER_PAIR))
    return {
        "physics": physics, "strength": strength, "events": int(feats.sizes["event"]),
        "skipped": skipped,
        "per_seed": {name: results[b].values(key).tolist()
                     for name, (b, key) in SCORES.items()},
        "wood_aluminium_sites": float(signal.get("wood_aluminium_sites_differing", 0)),
        "wood_aluminium_sites_of": int(signal.get("wood_aluminium_sites", 0)),
        "brass_wood_rank": rank,
        "most_confused": [[*pair, rate] for pair, rate in pairs[:3]],
        "r2_low": signal["r2_low"], "r2_high": signal["r2_high"],
        "tau_low_cv_median": signal["tau_low_cv_median"],
    }
