"""The sweep engine's float precision: what float32 saves and what it changes.

The compiled sweep engine (``NeuronSweep``, engine ``"standalone"``) runs one tuning grid
(k × drive amplitude × square-wave frequency, as ``benchmarks/bench_sweep.py`` and the
tuning sweep use it) in each float type of ``dtypes``; each run is timed (a second run:
the one-off compile is left out) and its spike counts are compared with float64's. A
rounding baseline says how much of that is precision at all: the same grid in float64 on
Brian2's numpy target (other arithmetic order, no fast-math) against the compiled float64.
Points near a bifurcation change their count for any rounding change, so float32 is
judged by its spike-count error (``accuracy.spike_count_error``: Σ|Δcount| / Σcount, the
grid's rate map's relative L1 error) against the study's rate-map tolerance
(``[match] rate_map_error``), with the baseline beside it.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ...core import bounds
from ...engine.devices import DTYPES
from ...engine.evaluators import NeuronSweep
from ...engine.grid import Grid
from ...core.errors import check
from ...evaluation import accuracy
from ...report.page import fmt


@dataclasses.dataclass
class Precision:
    """The grid and the float types of the precision stage."""
    dtypes: list = dataclasses.field(default_factory=lambda: list(DTYPES))
    n_k: int = 25                       # k log-spaced over [0.25, 2.5]
    amplitudes: list = dataclasses.field(default_factory=lambda: [0.15, 0.5])
    n_freqs: int = 40                   # input_hz over [2, 60]
    duration_s: float = 1.0

    def __post_init__(self):
        bounds.declared(self)
        check(all(d in DTYPES for d in self.dtypes), "dtypes", self.dtypes,
              f"names from {list(DTYPES)} (none: the stage is left out)")
        check(isinstance(self.n_k, int) and 1 <= self.n_k <= 1000, "n_k", self.n_k,
              "an integer in [1, 1000]")
        check(isinstance(self.n_freqs, int) and 2 <= self.n_freqs <= 1000, "n_freqs",
              self.n_freqs, "an integer in [2, 1000]")
        check(len(self.amplitudes) >= 1 and all(isinstance(a, (int, float)) and a >= 0
                                                for a in self.amplitudes),
              "amplitudes", self.amplitudes, "amplitudes >= 0")
        check(isinstance(self.duration_s, (int, float)) and 0.1 <= self.duration_s <= 10,
              "duration_s", self.duration_s, "a duration in [0.1, 10] s")

    def grid(self) -> Grid:
        return Grid({"k": {"start": 0.25, "stop": 2.5, "num": self.n_k, "scale": "log"},
                     "I": [float(a) for a in self.amplitudes],
                     "input_hz": {"start": 2, "stop": 60, "num": self.n_freqs}})


def _timed_counts(sweep: NeuronSweep, grid: Grid, warm: bool) -> tuple[np.ndarray, float]:
    evaluate = sweep.for_grid(grid, (grid.size,))
    points = grid.points()
    if warm:
        evaluate(points)   # compiles (standalone): paid once, not per run
    t0 = time.perf_counter()
    counts = evaluate(points)["spike_count"]
    return np.asarray(counts, np.int64), time.perf_counter() - t0


def _compare(counts, ref) -> dict:
    diff = np.abs(counts - ref)
    return {"spike_count_error": accuracy.spike_count_error(counts, ref),
            "same_count_share": float(np.mean(diff == 0)), "max_count_diff": int(diff.max())}


def run(precision: Precision, tolerance: float, log) -> dict:
    """Rows per float type (time, errors against float64) and the rounding baseline; None
    when ``dtypes`` is empty."""
    if not precision.dtypes:
        return None
    grid = precision.grid()
    base = NeuronSweep(duration_s=precision.duration_s,
                       settle_s=min(0.25, precision.duration_s / 4))
    steps = precision.duration_s * 1000 / base.dt_ms
    ref, _ = _timed_counts(base, grid, warm=True)
    rows = []
    for dtype in precision.dtypes:
        counts, seconds = _timed_counts(dataclasses.replace(base, dtype=dtype), grid, True)
        row = {"dtype": dtype, "engine": "standalone", "n_points": grid.size,
               "wall_s": seconds, "ns_per_neuron_step": seconds / (grid.size * steps) * 1e9,
               **_compare(counts, ref)}
        row["within_tolerance"] = row["spike_count_error"] <= tolerance
        rows.append(row)
        log(f"  {dtype}: {row['ns_per_neuron_step']:.2f} ns per neuron-step, spike-count "
            f"error {row['spike_count_error']:.2e} against float64 "
            f"({row['same_count_share']:.1%} of points the same)")
    runtime, seconds = _timed_counts(dataclasses.replace(base, engine="numpy"), grid, False)
    baseline = {"dtype": "float64", "engine": "numpy", "n_points": grid.size,
                "wall_s": seconds, "ns_per_neuron_step": seconds / (grid.size * steps) * 1e9,
                **_compare(runtime, ref)}
    log(f"  rounding baseline (float64, numpy target): spike-count error "
        f"{baseline['spike_count_error']:.2e} ({baseline['same_count_share']:.1%} the same)")
    return {"rows": rows, "baseline": baseline, "tolerance": tolerance,
            "grid": {d: len(grid.axes[d]) for d in grid.dims},
            "duration_s": precision.duration_s}


def report_section(report, result: dict | None) -> None:
    if result is None:
        return
    report.heading("Sweep engine: float precision")
    by_dtype = {r["dtype"]: r for r in result["rows"]}
    text = (f"The compiled sweep engine on a {' × '.join(map(str, result['grid'].values()))} "
            f"grid (k × amplitude × frequency, {fmt(result['duration_s'])} s at dt 0.1 ms), "
            f"in each float type, against its float64 counts. ")
    if "float32" in by_dtype and "float64" in by_dtype:
        r32, r64 = by_dtype["float32"], by_dtype["float64"]
        text += (f"float32 runs at {fmt(r64['wall_s'] / r32['wall_s'], digits=2)}× float64's "
                 f"speed with a spike-count error of {fmt(r32['spike_count_error'])} "
                 f"({'within' if r32['within_tolerance'] else 'OUTSIDE'} the study's rate-map "
                 f"tolerance {fmt(result['tolerance'])}); ")
    b = result["baseline"]
    text += (f"float64 on the numpy target, another arithmetic order in the same precision, "
             f"differs from the compiled float64 by {fmt(b['spike_count_error'])} "
             f"({fmt(100 * b['same_count_share'])} % of points the same): points near a "
             f"bifurcation change their count for any rounding change.")
    report.text(text)
    report.table(result["rows"] + [b], "Sweep engine by float type (errors against float64)")
