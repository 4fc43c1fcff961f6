"""Cost against error: ranking measured runs of one model at many integration settings.

A run is a row (dict) with its setting (``scene``, ``method``, ``dt_ms``, ...), its ``status``
("ok" or why not), its cost (``cpu_s``, ``wall_s``) and its errors against the reference
(``ERRORS``, from ``accuracy.compare_array`` / ``compare_tuning``). From such rows:
``pareto_front`` (runs no other run beats on both cost and an error), ``recommend`` (the
cheapest run that meets each criterion), ``add_speedups``, and the bookkeeping of runs that
went non-finite (``check_finite``, ``count_nonfinite``).
"""
from __future__ import annotations

import numpy as np

from ..networks import neurons
from .accuracy import Match, SpikeTrains

# What rankings use: this process's and its children's CPU seconds. On a shared machine wall
# time also measures everyone else's load.
COST = "cpu_s"
ERRORS = ("spike_time_error_ms", "spike_count_error", "rate_map_error", "distance_error_cm",
          "detection_f1")
MATCHES = "read-out matches the reference"
ROBUST = "read-out matches at this dt and every finer one"
# "far below": the smallest Brian2 error is at least this many times the reference's shift
FAR_BELOW = 100.0


def pareto_front(rows: list[dict], error: str) -> list[dict]:
    """Rows not beaten on both cost and ``error`` by another row, cheapest first."""
    ok = sorted((r for r in rows if r["status"] == "ok" and r.get(error) is not None),
                key=lambda r: (r[COST], r[error]))
    front, best = [], np.inf
    for r in ok:
        if r[error] < best:
            front.append(r)
            best = r[error]
    return front


def recommend(rows: list[dict], match: Match) -> list[dict]:
    """Per scene: the cheapest run whose read-out matches the reference; the cheapest whose
    rate map is within ``match.rate_map_error``; and the cheapest setting at and below whose
    dt (same method) every run matches (robust to lucky coarse steps). Runs beyond their
    method's stability limit (forced in a sweep to show what happens) are never
    recommended: a user gets only settings within it without force=True."""
    out = []
    rows = [r for r in rows if not r.get("beyond_stable_limit")]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene and r["status"] == "ok"]
        criteria = {
            MATCHES: lambda r: r["readout_matches"],
            f"rate map within {match.rate_map_error:.0%}":
                lambda r: r["rate_map_error"] <= match.rate_map_error,
        }
        for label, ok in criteria.items():
            passing = [r for r in mine if ok(r)]
            if passing:
                out.append(dict(criterion=label, **min(passing, key=lambda r: r[COST])))
        robust = _robust_runs([r for r in rows if r["scene"] == scene],
                              dict.fromkeys(r["method"] for r in mine))
        if robust:
            out.append(dict(criterion=ROBUST, **min(robust, key=lambda r: r[COST])))
    return out


def _robust_runs(rows: list[dict], methods) -> list[dict]:
    """Per method, the runs from the finest dt up to the first that fails or differs."""
    robust = []
    for method in methods:
        for r in sorted((r for r in rows if r["method"] == method), key=lambda r: r["dt_ms"]):
            if r["status"] != "ok" or not r["readout_matches"]:
                break
            robust.append(r)
    return robust


def add_speedups(recommendations: list[dict], rows: list[dict], reference_cost: dict) -> None:
    """Each recommendation's speed-up over its scene's reference (``reference_cost[scene]``)
    and over the slowest finished run of its scene in the main sweep."""
    for r in recommendations:
        r["speedup_vs_reference"] = reference_cost[r["scene"]] / r[COST]
        finished = [x for x in rows if x["scene"] == r["scene"] and x["sweep"] == "main"
                    and x["status"] == "ok"]
        slowest = max(finished, key=lambda x: x[COST])
        r["speedup_vs_slowest_brian2"] = slowest[COST] / r[COST]
        r["slowest_brian2_setting"] = f"{slowest['method']} dt={slowest['dt_ms']:g}"


def fastest_matching(recommendations: list[dict], scene: str) -> dict | None:
    """The cheapest run of ``scene`` whose read-out matches the reference, if any."""
    return next((r for r in recommendations
                 if r["scene"] == scene and r["criterion"] == MATCHES), None)


def main_rows_at(rows: list[dict], method: str, dt_ms: float) -> list[dict]:
    """The main sweep's runs at one setting (every scene)."""
    return [r for r in rows if r["sweep"] == "main" and r["method"] == method
            and abs(r["dt_ms"] - dt_ms) < 1e-12]


def check_finite(row: dict, spikes: SpikeTrains) -> dict:
    """A run that raised nothing but still produced a non-finite spike time or score is
    marked (``nonfinite_without_exception``), its scores dropped: NaN never reaches a
    report."""
    bad = [name for name in ERRORS + ("distance_cm",)
           if row.get(name) is not None and not np.isfinite(row[name])]
    if not np.all(np.isfinite(spikes.spike_t_ms)):
        bad.append("spike times")
    row["nonfinite_without_exception"] = bool(bad)
    if bad:
        row.update(status=f"non-finite without exception ({', '.join(bad)})",
                   readout_matches=False, **{e: None for e in ERRORS}, distance_cm=None)
    return row


RAISED = "non-finite (raised NumericalInstabilityError)"


def count_nonfinite(rows: list[dict]) -> dict:
    """Runs that raised NumericalInstabilityError, and runs that finished without it yet gave
    a non-finite spike time or score (``check_finite``): both as measured."""
    return {"nonfinite_without_exception": sum(bool(r.get("nonfinite_without_exception"))
                                               for r in rows),
            "raised_instability": sum(r["status"] == RAISED for r in rows)}


def convergence_verdict(shift: dict, rows: list[dict]) -> dict:
    """How far below the Brian2 errors (main sweep) the reference's own shift
    (``accuracy.reference_shift``) lies, as measured."""
    errors = [r for r in rows if r["sweep"] == "main" and r["status"] == "ok"
              and r.get("spike_time_error_ms") is not None]
    finest = min(errors, key=lambda r: r["spike_time_error_ms"], default=None)
    out = {"smallest_brian2_error_ms": finest["spike_time_error_ms"] if finest else None,
           "smallest_error_setting": (f"{finest['scene']} {finest['method']} "
                                      f"dt={finest['dt_ms']:g} ms") if finest else None}
    moved = shift["max_shift_ms"]
    if finest and moved > 0:
        out["error_over_shift"] = finest["spike_time_error_ms"] / moved
    out["far_below"] = bool(shift["same_spike_counts"] and finest is not None
                            and (moved == 0 or out["error_over_shift"] >= FAR_BELOW))
    return out


def describe(row: dict) -> str:
    """One line for a progress log: the setting, then its cost and errors or why it failed."""
    head = (f"{row['scene']} {row['method']} dt={row['dt_ms']:g} {row['target']} "
            f"{row['dtype']} n={row['n_neurons']}: ")
    if row["status"] != "ok":
        return head + row["status"]
    if row["rate_map_error"] is None:
        return head + f"{row['cpu_s']:.2f} s CPU"
    return head + (f"{row['cpu_s']:.2f} s CPU, spike-time err {row['spike_time_error_ms']:.3f} "
                   f"ms, rate-map err {row['rate_map_error']:.3f}, read-out "
                   f"{'matches' if row['readout_matches'] else 'differs'}")


SMALLEST_DRAWN = 1e-6   # a zero error is drawn here on the log axes


def pareto_figure(rows: list[dict]):
    """Error against cost per scene (main sweep): colour is the method, the marker's shape
    the step dt, the black line the Pareto front."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    main = [r for r in rows if r["sweep"] == "main"]
    scenes = list(dict.fromkeys(r["scene"] for r in main))
    names = {"rate_map_error": "rate-map error (relative)",
             "spike_time_error_ms": "spike-time error (ms)"}
    fig, axes = plt.subplots(len(names), len(scenes), figsize=(4.2 * len(scenes) + 1.6, 6.4),
                             squeeze=False, layout="constrained")
    colours = dict(zip(neurons.METHODS, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    steps = sorted({r["dt_ms"] for r in main})
    shapes = dict(zip(steps, "osD^vPX*hp"))
    for col, scene in enumerate(scenes):
        mine = [r for r in main if r["scene"] == scene and r["status"] == "ok"]
        for row, (err, label) in enumerate(names.items()):
            ax = axes[row][col]
            for r in mine:
                ax.scatter(r[COST], max(r[err], SMALLEST_DRAWN), s=30,
                           marker=shapes[r["dt_ms"]], color=colours.get(r["method"]),
                           edgecolor="k", linewidth=0.4, alpha=0.85)
            front = pareto_front(mine, err)
            ax.plot([r[COST] for r in front], [max(r[err], SMALLEST_DRAWN) for r in front],
                    color="k", lw=0.8, drawstyle="steps-post")
            _scale(ax.set_xscale, [r[COST] for r in mine])
            _scale(ax.set_yscale, [max(r[err], SMALLEST_DRAWN) for r in mine])
            ax.set_xlabel("CPU time (s)")
            ax.set_ylabel(label)
            ax.set_title(f"{scene} scene", fontsize=10)
    handles = [Line2D([], [], ls="", marker="o", color=colours.get(m), label=m)
               for m in dict.fromkeys(r["method"] for r in main)]
    handles += [Line2D([], [], ls="", marker=shapes[dt], color="grey", markeredgecolor="k",
                       label=f"dt {dt:g} ms") for dt in steps]
    fig.legend(handles=handles, loc="outside right center", fontsize=8, frameon=False)
    return fig


def _scale(set_scale, values) -> None:
    """Log only where the values span more than a decade: a narrow range reads best linear.
    Tick labels are plain numbers (0.03, not 3×10⁻²), few enough not to collide."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    axis = set_scale.__self__.xaxis if set_scale.__name__ == "set_xscale" \
        else set_scale.__self__.yaxis
    values = [v for v in values if v is not None and v > 0]
    if values and max(values) / min(values) > 10:
        set_scale("log")
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(FuncFormatter(
            lambda v, _: f"{v:g}" if v > 0 and round(v / 10 ** np.floor(np.log10(v))) in (2, 5)
            else ""))
    else:
        axis.set_major_locator(MaxNLocator(5))
