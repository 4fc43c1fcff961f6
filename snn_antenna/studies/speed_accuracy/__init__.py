"""Speed vs accuracy: every integration knob measured against an exact reference.

For each scene (the array's tuning stimuli, the quickstart robot scene, a bench contact) the
resonator array runs in Brian2 for every integration method × dt (the main sweep), and for
a few settings across code targets × float precision × array size (the cost sweep). Each run
is timed and compared with the scene's reference (``networks.reference``): spike-time,
spike-count and rate-map error and, for contact scenes, decoded-distance error and detection
F1 of the quickstart read-out. The report shows the Pareto fronts (error vs CPU time), a
recommendation per scene, and the stability map (method × k·dt × drive).

Stages: workloads → references → main sweep → cost sweep → stability map → bench bands
(``evaluation.bands``: each band of the bench's spiking read-out before and at a setting inside
the accurate range, against the reference, with its cost) → the sweep engine's float precision
(``precision``: float32 against float64 on a tuning grid, with a rounding baseline) → report.
Settings
loop in this process (``engine.devices``): timing needs the machine to itself, and the knobs
(method, target, dtype) are build settings rather than the numeric axes of a sweep grid.
Finished runs are kept in ``OUT/runs.jsonl`` (``engine.runlog``): an interrupted run resumes.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...engine.devices import (
    DTYPES,
    RUNTIME_TARGETS,
    TARGETS,
    ArrayWorkload,
    Setting,
    TuningStimuli,
    TuningWorkload,
    reference_convergence,
    solve_reference,
)
from ...engine.runlog import Measurements, RunLog
from ...core.errors import check
from ...engine.cost import engine_of, stages_estimate
from ...core.logfile import FLOAT32_CHECK, UNSTABLE_ON_PURPOSE, LogFile
from ...networks import neurons, reference
from ...networks.resonators import ResonatorArray
from ...preprocess import make_chain
from ...evaluation import accuracy, tradeoff
from ...evaluation.accuracy import Match, StabilityGrid
from ...evaluation.bands import BENCH_BANDS, BandStudy
from ...evaluation.bands import run_study as run_band_study
from ...readout.contacts import detector_from_spec
from ...report.page import Report
from ...sources import recorded
from ...sources.scenes import scene_from_spec
from ...sources.stimuli import RobotScene
from ...core.store import write_dataset
from . import precision as engine_precision
from .precision import Precision
from ..contract import COMMON, Options, Plan, data_folder
from .report import human_summary, quick_note, write_report

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
    preprocess: dict
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
    with specs.section("network"):
        net = dict(specs.check_section(spec, "network", ResonatorArray))
        array = ResonatorArray(**net)
    robot_scenes = {}
    if spec.get("data") is not None:    # a recorded drive (its first) as the quickstart scene
        robot_scenes["quickstart"] = recorded.open_drives(spec["data"]).scene(0)
    for name, table_name in (("quickstart", "stimulus"), ("bench", "bench")):
        if name in robot_scenes:
            continue
        with specs.section(table_name):
            specs.check_section(spec, table_name, RobotScene, extra=["kind"])
            robot_scenes[name] = scene_from_spec(spec.get(table_name, {}))
            robot_scenes[name].validate()
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g"])
        for scene in robot_scenes.values():
            make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
    detector, window_s = detector_from_spec(spec)
    parts = {}
    for name, cls in (("tuning", TuningStimuli), ("sweep", Sweep), ("cost", Cost),
                      ("stability", StabilityGrid), ("reference", ReferenceSettings),
                      ("match", Match), ("bands", BandStudy), ("precision", Precision)):
        with specs.section(name):
            parts[name] = cls(**specs.check_section(spec, name, cls))
    with specs.section("tuning"):        # one neuron per array neuron and frequency
        bounds.integer("n_freqs", parts["tuning"].n_freqs, 2, 10_000)
    for scene in robot_scenes.values():
        array.check_rate(scene.rate_hz)
    return Plan("speed_accuracy", spec,
                Parts(net, robot_scenes, pre, detector, window_s, **parts), estimate)


def estimate(parts: Parts):
    """The main sweep (every scene at every method and dt), the cost sweep (its settings at
    every target, float type and array size), the stability map, the bench bands (their
    sample events at every method and step, and the tuning that recalibrates them) and the
    sweep engine's precision grid (per float type)."""
    array = ResonatorArray(**dict(parts.net, force=True))
    seconds = {"tuning": parts.tuning.duration_s,
               **{name: scene.duration_s for name, scene in parts.robot_scenes.items()}}
    size = {"tuning": array.n_neurons * parts.tuning.n_freqs}
    sweep, cost = parts.sweep, parts.cost
    main = [(seconds[s], float(dt), size.get(s, array.n_neurons), engine_of(sweep.target))
            for s in sweep.scenes for dt in sweep.dt_ms] * len(sweep.methods)
    # the recommendation is the fastest setting that matches: sized as the spec's settings
    settings = [tuple(s) for s in cost.settings] * (2 if cost.include_recommended else 1)
    costs = [(seconds[cost.scene], float(dt), n, engine_of(t)) for _, dt in settings
             for t in cost.targets for n in cost.n_neurons] * len(cost.dtypes)
    stab = parts.stability          # every neuron runs model_ms at the finest k·dt
    stability = [(stab.model_ms / stab.k_dt_min / 1000.0, 1.0, stab.n_k_dt * len(stab.drives),
                  "numpy")] * len(sweep.methods)
    bands = parts.bands
    events = len(bands.materials) * len(bands.positions_cm) * bands.repetitions
    band_runs = []
    for name in bands.bands:
        band = BENCH_BANDS[name]
        dt = band.dt_ms or min(sweep.dt_ms)
        band_runs += [(bands.duration_s, dt, band.n_neurons * events, engine_of(bands.target))
                      ] * (len(bands.methods) * (bands.coarser_steps + 2))
        if name in bands.calibrate:
            band_runs.append((bands.tuning_duration_s, dt, band.n_neurons * bands.n_freqs,
                              engine_of(bands.target)))
    precision = parts.precision
    points = precision.n_k * len(precision.amplitudes) * precision.n_freqs
    return stages_estimate("the method x dt sweep, the cost sweep, the stability map, the "
                           "bench bands and the precision grid", [
        ("sweep.dt_ms", sweep.dt_ms, main), ("cost.n_neurons", cost.n_neurons, costs),
        ("stability.model_ms", stab.model_ms, stability),
        ("bands.repetitions", bands.repetitions, band_runs),
        ("precision.n_k", precision.n_k,
         [(precision.duration_s, 0.1, points, "standalone")] * len(precision.dtypes))])


# -- stages ---------------------------------------------------------------------------------
def prepare_workloads(plan: Parts, seed: int, log) -> dict:
    """The tuning workload, and each robot scene generated and coded as the quickstart does."""
    workloads = {}
    for name in dict.fromkeys(plan.sweep.scenes + [plan.cost.scene]):
        if name == "tuning":
            workloads[name] = TuningWorkload(plan.tuning, plan.net, plan.match)
            continue
        scene = plan.robot_scenes[name]
        rec = scene.generate(seed)
        chain = make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **plan.preprocess)
        chain.fit(rec.samples)
        coded = rec.with_samples(chain.transform(rec.samples), "coded")
        workloads[name] = ArrayWorkload(name, coded, plan.net, plan.detector, plan.window_s,
                                        plan.match)
        log(f"  {name}: {scene.duration_s:g} s at {scene.rate_hz:g} Hz, "
            f"{len(rec.truth.contacts)} contact(s)")
    return workloads


def solve_references(plan: Parts, workloads: dict, log) -> tuple[dict, list, dict]:
    """Each workload's reference and read-out, and how far one moves at a tighter tolerance."""
    tol = plan.reference
    refs = {name: solve_reference(w, tol.rtol, tol.atol) for name, w in workloads.items()}
    rows = [{"scene": name, "wall_s": ref.run.wall_s, "cpu_s": ref.run.cpu_s,
             "n_spikes": int(len(ref.run.spike_i)),
             "distance_cm": getattr(ref.readout, "distance_cm", None)}
            for name, ref in refs.items()]
    for r in rows:
        log(f"  {r['scene']}: {r['n_spikes']} spikes in {r['cpu_s']:.1f} s CPU")
    name = tol.check_scene if tol.check_scene in workloads else next(iter(workloads))
    convergence = reference_convergence(workloads[name], refs[name], tol.check_rtol,
                                        tol.atol * tol.check_atol_factor)
    convergence.update(scene=name, rtol=tol.rtol, check_rtol=tol.check_rtol)
    log(f"  converged: spike times move by at most {convergence['max_shift_ms']:.2e} ms "
        f"at rtol {tol.check_rtol:g} ({name})")
    return refs, rows, convergence


def cost_pairs(plan: Parts, recommendations: list[dict], own_size: int) -> list:
    """The cost sweep's settings: the spec's (plus the quickstart recommendation) × targets ×
    dtypes × sizes; the workload's own size is scored against its reference."""
    cost = plan.cost
    settings = [tuple(s) for s in cost.settings]
    if cost.include_recommended:
        settings += [(r["method"], r["dt_ms"]) for r in recommendations
                     if r["scene"] == cost.scene and r["criterion"] == tradeoff.MATCHES]
    settings = list(dict.fromkeys((m, float(dt)) for m, dt in settings))
    return [(cost.scene, Setting(m, dt, t, d, n if n != own_size else None))
            for m, dt in settings for t in cost.targets for d in cost.dtypes
            for n in cost.n_neurons]


def summarise(plan: Parts, rows: list[dict], refs: tuple[list, dict], recommendations: list,
              smap) -> dict:
    ref_rows, convergence = refs
    ref_cost = {r["scene"]: r[tradeoff.COST] for r in ref_rows}
    tradeoff.add_speedups(recommendations, rows, ref_cost)
    quick = tradeoff.fastest_matching(recommendations, "quickstart")
    if quick is not None:
        quick = {k: quick[k] for k in (
            "method", "dt_ms", "target", "dtype", "wall_s", tradeoff.COST,
            "speedup_vs_reference", "speedup_vs_slowest_brian2", "slowest_brian2_setting",
            "distance_error_cm", "detection_f1")}
        quick["reference_cpu_s"] = ref_cost["quickstart"]
    default = {"method": plan.net.get("method", ResonatorArray.method),
               "dt_ms": float(plan.net.get("dt_ms", ResonatorArray.dt_ms))}
    default_rows = [{k: r.get(k) for k in ("scene", "wall_s", tradeoff.COST, "rate_map_error",
                                           "readout_matches")}
                    for r in tradeoff.main_rows_at(rows, default["method"], default["dt_ms"])]
    k_max = float(np.max(ResonatorArray(**dict(plan.net, force=True)).k))
    return {
        "rows": rows,
        "references": ref_rows,
        "reference_convergence": {**convergence,
                                  **tradeoff.convergence_verdict(convergence, rows)},
        "recommendations": recommendations,
        "quickstart_fastest_matching": quick,
        "shipped_default": dict(default, default_rows=default_rows),
        "stability_limits": accuracy.stability_limits(smap, k_max),
        **tradeoff.count_nonfinite(rows),
    }


def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, quick, seed = plan.spec, options.quick, plan.seed
    plan = plan.parts
    out_dir = Path(out_dir)
    runlog = RunLog(out_dir / "runs.jsonl", spec, options.fresh)   # a damaged log: said first
    with LogFile(out_dir, log) as log:
        t_start = time.perf_counter()
        sweep, stab = plan.sweep, plan.stability
        log(f"[1/7] scenes ({', '.join(dict.fromkeys(sweep.scenes + [plan.cost.scene]))}, "
            f"seed {seed})")
        workloads = prepare_workloads(plan, seed, log)
        log(f"[2/7] reference solutions (solve_ivp, rtol {plan.reference.rtol:g})")
        refs, ref_rows, convergence = solve_references(plan, workloads, log)
        runs = Measurements(workloads, refs, runlog, log)
        main = [(name, Setting(m, dt, sweep.target, sweep.dtype)) for name in sweep.scenes
                for m in sweep.methods for dt in sorted(sweep.dt_ms)]
        log(f"[3/7] main sweep: {len(main)} runs ({sweep.target}, {sweep.dtype})")
        with log.expected(UNSTABLE_ON_PURPOSE):   # coarse steps are forced past their limits
            rows = runs.sweep("main", main)
        recommendations = tradeoff.recommend(rows, plan.match)
        cost = cost_pairs(plan, recommendations, workloads[plan.cost.scene].n_neurons)
        log(f"[4/7] cost sweep on {plan.cost.scene}: {len(cost)} runs "
            f"(targets × dtypes × sizes)")
        with log.expected(FLOAT32_CHECK):
            rows += runs.sweep("cost", cost)
        log(f"[5/7] stability map ({len(sweep.methods)} methods × {stab.n_k_dt} k·dt × "
            f"{len(stab.drives)} drives)")
        with log.expected(UNSTABLE_ON_PURPOSE):
            smap = stab.map(sweep.methods, b=plan.net.get("b", ResonatorArray.b))
        write_dataset(smap, out_dir / "stability_map.zarr")
        log(f"[6/7] bench bands ({', '.join(plan.bands.bands)}) against the reference")
        bands = run_band_study(plan.bands, seed, log)
        # last: the compiled sweep engine holds Brian2's one standalone device from here on
        log(f"[7/7] sweep engine precision ({', '.join(plan.precision.dtypes) or 'none'}) "
            "against float64; report")
        precision = engine_precision.run(plan.precision, plan.match.rate_map_error, log)
        summary = summarise(plan, rows, (ref_rows, convergence), recommendations, smap)
        summary["bands"] = bands
        summary["precision"] = precision
        summary["total_wall_s"] = time.perf_counter() - t_start
        report = Report(out_dir, "snn-antenna: speed vs accuracy of the resonator array",
                        quick=quick, quick_note=quick_note(plan.sweep, plan.stability))
        report.text(spec.get("description", ""))
        drive = plan.robot_scenes["quickstart"]
        if getattr(drive, "recorded", False):
            summary["data"] = recorded.summary_entry(drive)
            report.table([{"what": w, "value": v} for w, v in recorded.provenance_rows(drive)],
                         "The quickstart scene is a recorded drive: where it came from")
        write_report(report, summary, smap)
        engine_precision.report_section(report, precision)
        report.write(summary, spec, sweep.target)
        log(human_summary(summary, out_dir))
    return summary
