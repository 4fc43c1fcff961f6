"""The tuning sweep's stages: every grid point's spike rate into ``results.zarr``
(resumable), the curves' maps derived from it, the report written."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from ...core import spec as specs
from ...core.logfile import LogFile
from ...core.provenance import provenance
from ...engine.evaluators import NeuronSweep
from ...engine.executor import executor
from ...engine.sweep import run_sweep
from ...evaluation import tuning
from ...networks import neurons
from ...report.page import Report
from ..contract import Options, Plan
from .plan import Parts
from .report import calibrated_and_predicted, quick_note, write_report


def sweep_grid(spec: dict, parts: Parts, out_dir: Path, fresh: bool, scheduler, log):
    """Every grid point's spike rate into ``OUT/results.zarr`` (chunks already there kept)."""
    neuron, grid = parts.neuron, parts.grid
    log(f"[1/3] sweeping {grid.describe()} ({neuron.engine}, dt {neuron.dt_ms:g} ms, "
        f"{neuron.duration_s:g} s per point) into {out_dir / 'results.zarr'}")
    attrs = {"spec": specs.resolved(spec),
             **{k: v for k, v in provenance(spec, neuron.engine).items() if k != "spec"}}
    attrs.pop("created", None)  # not part of what makes two runs the same sweep
    with executor(parts.settings.workers, scheduler, log) as client:
        outcome = run_sweep(grid, neuron, out_dir / "results.zarr", NeuronSweep.OUTPUTS,
                            client=client, chunk_points=parts.settings.chunk_points,
                            fresh=fresh, attrs=attrs, settings=dataclasses.asdict(neuron),
                            desc="chunks")
    log(f"      {len(outcome.chunks_computed)} chunk(s) computed, "
        f"{len(outcome.chunks_skipped)} already in the store, {outcome.wall_s:.1f} s")
    return outcome


def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick = plan.spec, plan.parts, options.quick
    out_dir = Path(out_dir)
    with LogFile(out_dir, log) as log:
        t0 = time.perf_counter()
        outcome = sweep_grid(spec, parts, out_dir, options.fresh, options.scheduler, log)
        log("[2/3] deriving peak frequency, band width and spike rate maps")
        data, neuron, grid = outcome.data, parts.neuron, parts.grid
        maps = tuning.derive(data.rate_hz)
        summary = tuning.summarise(maps, data.input_hz.values, parts.reference)
        summary.update({
            "grid": {d: [float(x) for x in data[d].values] for d in grid.dims},
            "points": grid.size,
            "chunks": outcome.chunks_total,
            "chunks_computed": len(outcome.chunks_computed),
            "chunks_skipped": len(outcome.chunks_skipped),
            "workers": outcome.workers,
            "neuron_steps": int(grid.size * round(neuron.duration_s * 1000 / neuron.dt_ms)),
            "sweep_wall_s": outcome.wall_s,
            "total_wall_s": time.perf_counter() - t0,
            "store": str(out_dir / "results.zarr"),
        })
        log("[3/3] writing the report")
        report = Report(out_dir, "snn-antenna tuning sweep: resonator tuning over k, b and I",
                        quick=quick, quick_note=quick_note(summary, neuron))
        report.text(spec.get("description", ""))
        calibrated_and_predicted(report, summary)
        write_report(report, data.rate_hz, maps, summary, parts.reference)
        summary = report.write(summary, spec, neuron.engine)
        cal = summary.get("calibration")
        if cal and cal["hz_per_k_peak"] is not None:
            verdict = "holds" if cal["driven_hz_per_k_holds"] else "does NOT hold"
            log(f"k → peak frequency: {cal['hz_per_k_peak']:.2f} Hz per unit k (centroid "
                f"{cal['hz_per_k_centroid']:.2f}); neurons.DRIVEN_HZ_PER_K = "
                f"{neurons.DRIVEN_HZ_PER_K:g} {verdict} (within {cal['tolerance'] * 100:.0f} %)")
        log(f"report in {out_dir}/report.html")
    return summary


