"""The speed/accuracy study's stages: workloads, references, the main sweep, the cost sweep,
the stability map, the bench bands and the sweep engine's precision; the summary."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ...core.logfile import FLOAT32_CHECK, UNSTABLE_ON_PURPOSE, LogFile
from ...core.store import write_dataset
from ...engine.devices import (
    ArrayWorkload,
    Setting,
    TuningWorkload,
    reference_convergence,
    solve_reference,
)
from ...engine.runlog import RunLog
from ...engine.settings_runs import drives_runs
from ...evaluation import accuracy, tradeoff
from ...evaluation.bands import run_study as run_band_study
from ...networks.resonators import ResonatorArray
from ...report.page import Report
from ..contract import Options, Plan
from . import cost_sweep, main_sweep
from . import precision as engine_precision
from .plan import Parts
from .report import human_summary, quick_note, write_report


def prepare_workloads(plan: Parts, seed: int, log) -> dict:
    """The tuning workload, and each robot scene generated and coded as the quickstart does."""
    workloads = {}
    for name in dict.fromkeys(plan.sweep.scenes + [plan.cost.scene]):
        if name == "tuning":
            workloads[name] = TuningWorkload(plan.tuning, plan.net, plan.match)
            continue
        scene = plan.robot_scenes[name]
        rec = scene.generate(seed)
        chain = plan.preprocess.chain(scene)
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
        n_main = len(sweep.scenes) * len(sweep.methods) * len(sweep.dt_ms)
        log(f"[3/7] main sweep: {n_main} settings in one compiled run ({sweep.dtype}); "
            f"their cost on {sweep.target}, timed on a sample")
        with log.expected(UNSTABLE_ON_PURPOSE):   # coarse steps are forced past their limits
            rows, main_sweep_done = main_sweep.run(plan, workloads, refs, runlog, log)
        recommendations = tradeoff.recommend(rows, plan.match)
        cost = cost_pairs(plan, recommendations, workloads[plan.cost.scene].n_neurons)
        log(f"[4/7] cost sweep on {plan.cost.scene}: {len(cost)} runs "
            f"(targets × dtypes × sizes; runtime targets timed on a sample)")
        with log.expected(FLOAT32_CHECK, UNSTABLE_ON_PURPOSE):
            cost_rows, cost_done = cost_sweep.run(cost, workloads, refs, runlog, log)
        rows += cost_rows
        log(f"[5/7] stability map ({len(sweep.methods)} methods × {stab.n_k_dt} k·dt × "
            f"{len(stab.drives)} drives, one compiled run)")
        with log.expected(UNSTABLE_ON_PURPOSE):
            smap = stab.map(sweep.methods, b=plan.net.get("b", ResonatorArray.b),
                            compiled=drives_runs)
        write_dataset(smap, out_dir / "stability_map.zarr")
        log(f"[6/7] bench bands ({', '.join(plan.bands.bands)}) against the reference")
        bands = run_band_study(plan.bands, seed, log, compiled=main_sweep.band_spikes,
                               compiled_tuning=main_sweep.tuning_spikes)
        # last: the compiled sweep engine holds Brian2's one standalone device from here on
        log(f"[7/7] sweep engine precision ({', '.join(plan.precision.dtypes) or 'none'}) "
            "against float64; report")
        precision = engine_precision.run(plan.precision, plan.match.rate_map_error, log)
        summary = summarise(plan, rows, (ref_rows, convergence), recommendations, smap)
        summary["main_sweep"] = main_sweep_done
        summary["cost_sweep"] = cost_done
        summary["bands"] = bands
        summary["precision"] = precision
        summary["total_wall_s"] = time.perf_counter() - t_start
        report = Report(out_dir, "snn-antenna: speed vs accuracy of the resonator array",
                        quick=quick, quick_note=quick_note(plan.sweep, plan.stability))
        report.text(spec.get("description", ""))
        drive = plan.robot_scenes["quickstart"]
        if (origin := drive.summary_entry()) is not None:
            summary["data"] = origin
        report.table([{"what": w, "value": v} for w, v in drive.provenance_rows()],
                     "Where the quickstart scene came from")
        write_report(report, summary, smap)
        engine_precision.report_section(report, precision)
        report.write(summary, spec, sweep.target)
        log(human_summary(summary, out_dir))
    return summary
