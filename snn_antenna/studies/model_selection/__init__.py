"""Model selection: which contact mechanism, chosen by what it predicts.

For every candidate (``[selection] candidates``: a mechanism of ``sources/contact_models.py``
or a ``+`` combination, with a small grid of its one free constant), the study generates a
bench set at each grid value, processes its events as the paper did and runs the paper's
read-outs on the same splits by repetition for several seeds. Two numbers of the paper are
calibration targets (``CALIBRATION_TARGETS``): the constant is the grid value that meets them
best. Everything else is predicted and never enters that choice (``PREDICTIONS``).
Leave-one-target-out: the constant is chosen again from one target alone, and the left-out
target becomes a prediction. Among the candidates that meet their calibration targets (within
their tolerances), the one whose predictions meet most of the acceptance criteria (then: falls
least short of them) is the one the study chooses; none, when nothing calibrates.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError, check, is_number
from ...evaluation import crossval as cv
from ...evaluation import signal as bench_signal
from ...evaluation.confusion import confusion
from ...core.logfile import logged
from ...engine.cost import bench_seconds, stages_estimate
from ...readout import events
from ...readout.baselines import distance_baselines, material_baselines, two_material_baseline
from ...report.page import Report
from ...sources import bench
from ...sources.contact_models import ContactPhysics
from .protocol import (
    CALIBRATION_TARGETS,
    PAPER_PAIR,
    PREDICTIONS,
    SCORES,
    choose,
    confused_pairs,
    select,
)
from ..contract import COMMON, Options, Plan, cache_folder
from .report import write_report

SECTIONS = ("stimulus", "events", "evaluation", "selection")
OPTIONS = (*COMMON, "fresh")
# A grid point whose events the paper's processing skips more often than this is unreadable.
MAX_SKIPPED = 0.10

QUICK_NOTE = ("Quick profile: a handful of contacts per material and site, two seeds, short "
              "training and one or two grid values per candidate. It checks the pipeline; "
              "its accuracies and rmse are not results and choose nothing.")


@dataclass
class Candidate:
    physics: str
    strengths: list

    def __post_init__(self):
        bounds.declared(self)
        check(isinstance(self.strengths, list) and len(self.strengths) >= 1
              and all(is_number(s) for s in self.strengths), "selection.candidates.strengths",
              self.strengths, "a non-empty list of factors on the mechanism's constant")
        for s in self.strengths:
            ContactPhysics(self.physics, float(s))    # names a bad mechanism or strength


@dataclass
class Selection:
    """``[selection]``: the candidates and their grids."""
    candidates: list = field(default_factory=list)

    def __post_init__(self):
        check(isinstance(self.candidates, list) and len(self.candidates) >= 1 and
              all(isinstance(c, dict) and set(c) == {"physics", "strengths"}
                  for c in self.candidates), "selection.candidates", self.candidates,
              "a non-empty list of {physics = NAME, strengths = [factors]} tables")
        self.candidates = [c if isinstance(c, Candidate) else Candidate(**c)
                           for c in self.candidates]
        names = [c.physics for c in self.candidates]
        check(len(set(names)) == len(names), "selection.candidates", names,
              "distinct mechanisms")


@dataclass
class StudySpec:
    bench: bench.BenchSpec
    processor: events.EventProcessor
    evaluation: cv.Evaluation
    selection: Selection


def plan(spec: dict) -> Plan:
    """Check the whole spec before any long work; build its parts."""
    specs.check_top_level(spec, SECTIONS)
    for key in ("physics", "physics_strength"):
        if key in spec.get("stimulus", {}):
            raise SpecError(f"stimulus.{key}", spec["stimulus"][key],
                            "no value here: [selection] sets the mechanism for every run")
    with specs.section("stimulus"):
        bench_spec = bench.spec_from_table(spec.get("stimulus", {}), int(spec.get("seed", 0)))
        bench_spec.validate()
        cache_folder("cache_dir", bench_spec.cache_dir)
    check({"wood", "aluminium", *PAPER_PAIR} <= set(bench_spec.materials),
          "stimulus.materials", list(bench_spec.materials),
          "a list holding wood, aluminium and brass (the targets and the paper's pair)")
    with specs.section("events"):
        table = specs.check_section(spec, "events", events.EventProcessor, exclude=["rate_hz"])
        processor = events.EventProcessor(rate_hz=bench_spec.rate_hz, **table)
    with specs.section("evaluation"):
        evaluation = cv.Evaluation(**specs.check_section(spec, "evaluation", cv.Evaluation))
    with specs.section("selection"):
        selection = Selection(**specs.check_section(spec, "selection", Selection))
    return Plan("model_selection", spec,
                StudySpec(bench_spec, processor, evaluation, selection), estimate)


def estimate(parts: StudySpec):
    """A bench set per grid point (every candidate's strengths), its events processed and
    read out (no Brian2)."""
    points = sum(len(c.strengths) for c in parts.selection.candidates)
    return stages_estimate("the candidates' bench sets and read-outs", [
        ("stimulus.repetitions", parts.bench.repetitions, [],
         points * bench_seconds(parts.bench.n_events, parts.bench.n_jobs))])


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick, fresh = plan.spec, plan.parts, options.quick, options.fresh
    out_dir, t0 = Path(out_dir), time.perf_counter()
    grid = [(c.physics, float(s)) for c in parts.selection.candidates for s in c.strengths]
    points = []
    for i, (physics, strength) in enumerate(grid, 1):
        log(f"[{i}/{len(grid)}] {physics} × {strength:g}")
        points.append(measure(parts, physics, strength, log, fresh))
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


def measure(parts: StudySpec, physics: str, strength: float, log=print, fresh=False) -> dict:
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
