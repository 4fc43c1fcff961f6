"""Tuning sweep: spike count vs input frequency over grids of k, b and input amplitude I.

Every grid point is one resonator driven by the square-wave coder's output for a pure tone
(±I at ``input_hz``); all points of a chunk are neurons of one Brian2 NeuronGroup, chunks run
on Dask workers and land in ``OUT/results.zarr`` (resumable). From the tuning curves
(``evaluation.tuning``):

- peak frequency vs k: the calibration curve k → preferred frequency (``k_to_peak_hz``),
  checked against ``neurons.DRIVEN_HZ_PER_K`` (the foundation's constant);
- band width (FWHM of the tuning curve) vs I: the input amplitude sets the band (Fig. 8G);
- spike rate vs b: b sets the rate (Fig. 8H).

Stages: sweep the grid → derive the curves' maps → report.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..core import bounds
from ..core import spec as specs
from ..engine.cost import check_memory, estimate as sweep_estimate
from ..engine.evaluators import NEURON_AXES, NeuronSweep
from ..engine.executor import executor
from ..engine.grid import Grid
from ..engine.sweep import run_sweep
from ..core.errors import check
from ..core.logfile import LogFile
from ..networks import neurons
from ..evaluation import tuning
from ..evaluation.tuning import ReadPoint
from ..core.provenance import provenance
from ..report.page import Calibrated, Predicted, Report, fmt
from .contract import COMMON, Options, Plan

SECTIONS = ("neuron", "axes", "sweep", "reference")
OPTIONS = (*COMMON, "fresh", "scheduler")


@dataclasses.dataclass
class SweepSettings:
    chunk_points: int = 4096
    workers: int = 0  # 0: one worker process per CPU core; 1: run in this process

    def __post_init__(self):
        bounds.declared(self)
        bounds.positive_integer("chunk_points", self.chunk_points)
        bounds.integer("workers", self.workers, 0)
        check(isinstance(self.workers, int) and self.workers >= 0, "workers", self.workers,
              "an integer >= 0 (0: one per CPU core)")


class Parts(NamedTuple):
    """The checked spec: the neuron model, the grid, how to sweep it, where to read it."""
    neuron: NeuronSweep
    grid: Grid
    settings: SweepSettings
    reference: ReadPoint


def plan(spec: dict) -> Plan:
    """Check the whole spec (the grid included) before any simulation runs; a grid whose
    results or chunks cannot fit in memory is refused here, before a worker starts."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("neuron"):
        neuron = NeuronSweep(**specs.check_section(spec, "neuron", NeuronSweep,
                                                   exclude=["group_size", "shared"]))
    with specs.section("axes"):
        grid = Grid.from_spec(spec.get("axes", {}), NEURON_AXES)
    check("input_hz" in grid.axes and len(grid.axes["input_hz"]) >= 3, "axes.input_hz",
          list(grid.axes.get("input_hz", [])),
          "an axis of at least 3 input frequencies (the tuning curve)")
    with specs.section("sweep"):
        settings = SweepSettings(**specs.check_section(spec, "sweep", SweepSettings))
    with specs.section("reference"):
        point = ReadPoint(**specs.check_section(spec, "reference", ReadPoint))
    block = grid.block_shape(settings.chunk_points)
    neuron.for_grid(grid, block)                    # refuse a bad grid now
    check_memory(grid, NeuronSweep.OUTPUTS, int(np.prod(block)), neuron.bytes_per_point)
    return Plan("tuning_sweep", spec, Parts(neuron, grid, settings, point), estimate)


def estimate(parts: Parts):
    """The sweep's points, neuron-steps, time and memory, from the grid's shape alone."""
    return sweep_estimate(parts.grid, parts.neuron, parts.settings.chunk_points,
                          parts.settings.workers)


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
        _provenance_rows(report, summary)
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


def quick_note(summary: dict, neuron: NeuronSweep) -> str:
    """What the quick profile's grid is too small for, from the grid that ran."""
    grid = summary["grid"]
    sizes = " × ".join(f"{len(v)} {name}" for name, v in
                       (("k", grid.get("k", [])), ("b", grid.get("b", [])),
                        ("I", grid.get("I", [])), ("frequencies", grid.get("input_hz", [])))
                       if v)
    step = summary.get("calibration", {}).get("input_hz_step")
    return (f"quick profile: too small to compare with the paper. A grid of {sizes}, "
            f"{neuron.duration_s:g} s per point ({neuron.engine}); frequency steps of "
            f"{fmt(step)} Hz limit the slope to a few per cent, and a b or I with one or two "
            "values draws no trend.")


PAPER_HZ_PER_K = 7.0 / 0.3425   # the paper's 7 Hz neuron has k = 0.3425 (docs/reference.md)


def _range_text(pair) -> str:
    return f"{fmt(pair[0])} to {fmt(pair[1])} Hz" if pair else "(none)"


def _provenance_rows(report: Report, summary: dict) -> None:
    """What the sweep calibrates (the foundation's constant) apart from what it predicts."""
    cal = summary.get("calibration")
    if not cal or cal["hz_per_k_centroid"] is None:
        return
    used = fmt(summary["reference_used"])
    report.calibrated(Calibrated(
        "preferred frequency per unit k (tuning-curve centroid)",
        value=neurons.DRIVEN_HZ_PER_K, target=cal["hz_per_k_centroid"], unit="Hz",
        source=f"the centroid this sweep measures at {used}; the constant was set "
               "from the full profile's grid",
        how="neurons.DRIVEN_HZ_PER_K, the constant the array uses to place its neurons"))
    report.predicted(Predicted(
        "preferred frequency per unit k (tuning-curve peak)", value=cal["hz_per_k_peak"],
        unit="Hz", paper=PAPER_HZ_PER_K,
        source="paper: the 7 Hz neuron has k = 0.3425 (docs/reference.md)",
        # the spread of peak/k over k is a range, not a confidence interval: it goes in the
        # note, never in the table's "95 % interval" column
        n=cal["responding_k"],
        note=(f"peak/k ranges {_range_text(cal['hz_per_k_peak_range'])} over the "
              f"{cal['responding_k']} k values that fired; the paper codes with amplitude "
              f"0.085 in its scaling, "
              f"this sweep at {used}; the grid's frequency step is "
              f"{fmt(cal['input_hz_step'])} Hz")))
    if "fwhm_vs_I" in summary:
        w = summary["fwhm_vs_I"]
        report.predicted(Predicted(
            "band width (FWHM) at each input amplitude I",
            value={f"I = {fmt(i)}": f for i, f in zip(w["I"], w["fwhm_hz"])}, unit="Hz",
            source="the paper's Fig. 8G: the amplitude sets the band's width (no number)",
            note="widens with I as in the paper" if _increasing(w["fwhm_hz"])
            else "does not widen monotonically with I here"))


def _increasing(values) -> bool:
    v = [x for x in values if x is not None]
    return len(v) >= 2 and all(b > a for a, b in zip(v, v[1:]))



# -- report -----------------------------------------------------------------------------------
def _calibration_section(report: Report, summary: dict) -> None:
    cal = summary.get("calibration")
    if not cal or cal["hz_per_k_peak"] is None:
        return   # no k gave a single spike
    report.heading("Calibration: k → preferred frequency")
    report.text(
        f"Least-squares slope through the origin: {cal['hz_per_k_peak']:.3g} Hz per unit k "
        f"from the tuning curves' peaks, {cal['hz_per_k_centroid']:.3g} from their "
        f"geometric centroids; the array places its neurons with "
        f"{cal['foundation_driven_hz_per_k']:g} Hz per unit k (neurons.DRIVEN_HZ_PER_K, "
        f"defined as the centroid), which "
        f"{'holds' if cal['driven_hz_per_k_holds'] else 'does not hold'} within "
        f"{cal['tolerance'] * 100:.0f} %. Frequency step of the grid: "
        f"{cal['input_hz_step']:.3g} Hz.")
    kp = summary["k_to_peak_hz"]
    report.table([{"k": k, "peak_hz": p, "centroid_hz": c,
                   "peak/k (Hz per unit k)": (p / k if p else None)}
                  for k, p, c in zip(kp["k"], kp["peak_hz"], kp["centroid_hz"])],
                 f"Preferred frequency per k at {fmt(summary['reference_used'])}")


def write_report(report: Report, rate, maps, summary: dict, point: ReadPoint) -> None:
    _calibration_section(report, summary)
    report.figure(tuning.tuning_curves_figure(rate, point), "tuning_curves",
                  "Spike rate (after the settling time) against the input frequency of the "
                  "square-wave coder's output. Left: one curve per k at the reference b and I. "
                  "Right: one curve per input amplitude I: the amplitude sets the band width "
                  "(the paper's Fig. 8G).")
    cal = summary.get("calibration") or {}
    report.figure(tuning.heatmaps_figure(rate, maps, point, cal.get("hz_per_k_peak")),
                  "heatmaps",
                  "Left: spike rate over k and input frequency (reference b, I) with the "
                  "frequency per unit k the array uses and the one fitted to these peaks. "
                  "Middle: band width (FWHM) of each tuning curve over k and I. Right: peak "
                  "spike rate over k and b (the paper's Fig. 8H). Blank cells: the neuron "
                  "never fired.")
    report.figure(tuning.maps_figure(summary), "maps",
                  f"Calibration k → preferred frequency; band width vs I; peak rate vs b "
                  f"(at {fmt(summary['reference_used'])}; a b without a point never fired).")
