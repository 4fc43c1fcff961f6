"""What a model selection costs, from its plan's parts: every grid point's bench set, its
events' features and its calibration read-out, and each candidate's predicted read-outs at
its calibrated point, shared among the workers, at the machine's load.

Each part is CPU seconds on one core of this machine, per unit of the work it does, measured
with ``time.process_time`` in one process (AMD EPYC, Zen 5, 2 cores; the ``current`` model at
strength 1; 3 seeds, the full profile's evaluation): the bench set and its features at 20
repetitions (2,560 events), the read-outs' fits on the full bench set (12,799 events). A
process among ``load`` others gets its share of the cores (``rates.slowdown``), so the wall
time is the CPU time shared among the workers times that slowdown.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from ...engine import rates
from ...engine.cost import JobEstimate, stages_estimate, study_overhead_s
from ...evaluation import signal
from ...readout.baselines import NMFFilterBank

# one contact event generated (``sources.bench.generate``) and processed (its window,
# spectrum and decay fits: ``readout.events.process``)
GENERATE_EVENT_S = 4.3e-4
FEATURES_EVENT_S = 1.13e-3
# a grid point's own work beside its events: its caches written and read, its signal
# statistics, the read-outs' set-up
POINT_S = 1.0
# one training event through one epoch of an MLP on these inputs (scikit-learn, mini-batches
# of 64, one BLAS thread): the 8-material MLP on the spectrum (6.6e-6: 10.7 s for 3 x 60
# epochs of 8,959 events), the same after NMF-30 (its 30 filter outputs), the distance MLP on
# the spectrum and the MLPs on the parametric features
EPOCH_EVENT_S = {"spectrum_material": 6.6e-6, "nmf_material": 2.9e-6,
                 "spectrum_distance": 5.3e-6, "params": 2.5e-6}
# one spectrum through one coordinate-descent iteration of NMF-30 (``NMFFilterBank``: 3.2 s
# for 400 iterations on 3,000 spectra)
NMF_ROW_ITERATION_S = 2.7e-6
# epochs after which scikit-learn's tol stopped the distance MLPs and the 5-8-2 network on
# the full bench set (means over the 3 seeds; the budget, mlp_max_iter, can stop them sooner)
STOP_EPOCHS = {"mlp_spectrum": 30, "mlp_parametric": 40, "mlp_5_8_2": 130}


@dataclass(frozen=True)
class PointCost:
    """CPU seconds of one grid point's parts and of one candidate's predictions."""
    bench: float          # the bench set and its features
    calibration: float    # the material MLP on every seed's split
    predictions: float    # NMF-30, the distance MLPs and the 5-8-2 network, every split


def train_events(events: int, repetitions: int, test_fraction: float) -> int:
    """Events in a split's training side (whole repetitions, as ``crossval``'s split)."""
    n_test = min(repetitions - 1, max(1, int(round(test_fraction * repetitions))))
    return events * (repetitions - n_test) // max(1, repetitions)


def point_cost(parts) -> PointCost:
    bench, ev = parts.bench, parts.evaluation
    events, seeds = bench.n_events, len(ev.seeds)
    train = train_events(events, bench.repetitions, ev.test_fraction)
    pair = train * 2 // max(1, len(bench.materials))      # the 5-8-2 network's two materials
    nmf_rows = min(train, NMFFilterBank().max_fit_samples)
    mlp = ev.mlp_max_iter
    predictions = seeds * (
        nmf_rows * ev.nmf_max_iter * NMF_ROW_ITERATION_S
        + train * ev.material_max_iter * EPOCH_EVENT_S["nmf_material"]
        + train * min(mlp, STOP_EPOCHS["mlp_spectrum"]) * EPOCH_EVENT_S["spectrum_distance"]
        + train * min(mlp, STOP_EPOCHS["mlp_parametric"]) * EPOCH_EVENT_S["params"]
        + pair * min(mlp, STOP_EPOCHS["mlp_5_8_2"]) * EPOCH_EVENT_S["params"])
    return PointCost(
        bench=POINT_S + events * (GENERATE_EVENT_S + FEATURES_EVENT_S),
        calibration=seeds * train * ev.material_max_iter * EPOCH_EVENT_S["spectrum_material"],
        predictions=predictions)


def cached_features(parts, physics: str, strength: float) -> bool:
    """Whether the features of this grid point's bench set are cached (``signal``)."""
    spec = replace(parts.bench, physics=physics, physics_strength=strength)
    return signal.features_path(spec, parts.processor).exists()


def _slowdown(workers: int) -> float:
    """Wall seconds per CPU second of each of ``workers`` processes started among the
    machine's load now."""
    return rates.slowdown(rates.competing_load() + workers - 1)


def wall_factor(workers: int) -> float:
    """``_slowdown``, divided by the factor ``Plan.estimate`` applies from the rates' probe
    to now: that factor is for the probe's rates, and these parts carry no probe's load."""
    factor, _ = rates.load_factor()
    return _slowdown(workers) / factor


def estimate(parts, workers: int) -> JobEstimate:
    """The run's wall time from its parts: every point's bench set and calibration, each
    candidate's predictions (one calibrated point each), shared among ``workers``; their
    start (a worker imports what the study's process does) when there is more than one."""
    cost = point_cost(parts)
    points = sum(len(c.strengths) for c in parts.selection.candidates)
    candidates = len(parts.selection.candidates)
    per_cpu = wall_factor(workers) / workers
    # a point whose bench set's features are on disk reads them (its own work alone)
    made = sum(cached_features(parts, c.physics, s) for c in parts.selection.candidates
               for s in c.strengths)
    stages = [("stimulus.repetitions", parts.bench.repetitions, [],
               ((points - made) * cost.bench + made * POINT_S) * per_cpu),
              ("evaluation.material_max_iter", parts.evaluation.material_max_iter, [],
               points * cost.calibration * per_cpu),
              ("evaluation.nmf_max_iter", parts.evaluation.nmf_max_iter, [],
               candidates * cost.predictions * per_cpu)]
    if workers > 1:
        stages.append(("stimulus.n_jobs", workers, [],
                       rates.rates()["python_s"]["study_start"].value))
    # the parts as they will take: Plan.estimate multiplies by the probe's load factor and
    # adds the study's start and report
    factor, _ = rates.load_factor()
    seconds = [s[3] * factor for s in stages]
    what = (f"{points} grid points of {parts.bench.n_events:,} events on {workers} "
            f"worker(s), each ×{_slowdown(workers):.2g} slower at load "
            f"{rates.competing_load():.1f} (not niced): bench sets and features "
            f"{_short(seconds[0])}, "
            f"calibration read-outs {_short(seconds[1])}, predicted read-outs at {candidates} "
            f"calibrated points {_short(seconds[2])}"
            + (f", workers' start {_short(seconds[3])}" if workers > 1 else "")
            + f", the study's start and report {_short(study_overhead_s() * factor)} "
              f"(CPU per point {cost.bench + cost.calibration:.3g} s, per prediction "
              f"{cost.predictions:.3g} s); in all")
    return stages_estimate(what, stages)


def _short(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"
