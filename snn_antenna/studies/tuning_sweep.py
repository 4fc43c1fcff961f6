"""Tuning sweep: spike count vs input frequency over grids of k, b and input amplitude I.

Every grid point is one resonator driven by the square-wave coder's output for a pure tone
(±I at ``input_hz``); all points of a chunk are neurons of one Brian2 NeuronGroup, chunks run
on Dask workers and land in ``OUT/results.zarr`` (resumable). From the tuning curves:

- peak frequency vs k: the calibration curve k → preferred frequency (``k_to_peak_hz``),
  checked against ``neurons.DRIVEN_HZ_PER_K`` (the foundation's constant);
- band width (FWHM of the tuning curve) vs I: the input amplitude sets the band (Fig. 8G);
- spike rate vs b: b sets the rate (Fig. 8H).
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import xarray as xr

from ..networks import neurons
from .. import spec as specs
from ..errors import check
from ..report import Calibrated, LogFile, Predicted, Report, fmt, provenance
from ..engine.sweep import NEURON_AXES, Grid, NeuronSweep, executor, run_sweep

SECTIONS = ("neuron", "axes", "sweep", "reference")


@dataclasses.dataclass
class SweepSettings:
    chunk_points: int = 4096
    workers: int = 0  # 0: one worker process per CPU core; 1: run in this process


@dataclasses.dataclass
class Reference:
    """Where the tuning curves and the calibration are read (the nearest grid values)."""
    b: float = 0.26
    I: float = 0.15
    k: float = 1.0


def build(spec: dict):
    """Check the whole spec (the grid included) before any simulation runs."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("neuron"):
        neuron = NeuronSweep(**specs.check_section(spec, "neuron", NeuronSweep,
                                                   exclude=["group_size"]))
    grid = Grid.from_spec(spec.get("axes", {}), NEURON_AXES)
    check("input_hz" in grid.axes and len(grid.axes["input_hz"]) >= 3, "axes.input_hz",
          list(grid.axes.get("input_hz", [])),
          "an axis of at least 3 input frequencies (the tuning curve)")
    with specs.section("sweep"):
        settings = SweepSettings(**specs.check_section(spec, "sweep", SweepSettings))
        check(isinstance(settings.workers, int) and settings.workers >= 0, "workers",
              settings.workers, "an integer >= 0 (0: one per CPU core)")
    with specs.section("reference"):
        reference = Reference(**specs.check_section(spec, "reference", Reference))
    neuron.for_grid(grid, grid.block_shape(settings.chunk_points))  # refuse a bad grid now
    return neuron, grid, settings, reference


def run(spec: dict, out_dir, quick: bool = False, fresh: bool = False,
        scheduler: str | None = None, log=print) -> dict:
    neuron, grid, settings, reference = build(spec)
    out_dir = Path(out_dir)
    with LogFile(out_dir, log) as run_log:
        return _run(spec, out_dir, quick, fresh, scheduler, run_log, neuron, grid, settings,
                    reference)


def _run(spec, out_dir, quick, fresh, scheduler, log, neuron, grid, settings, reference):
    t0 = time.perf_counter()
    log(f"[1/3] sweeping {grid.describe()} ({neuron.engine}, dt {neuron.dt_ms:g} ms, "
        f"{neuron.duration_s:g} s per point) into {out_dir / 'results.zarr'}")
    attrs = {"spec": specs.resolved(spec),
             **{k: v for k, v in provenance(spec, neuron.engine).items() if k != "spec"}}
    attrs.pop("created", None)  # not part of what makes two runs the same sweep
    common = dict(chunk_points=settings.chunk_points, fresh=fresh, attrs=attrs,
                  settings=dataclasses.asdict(neuron), desc="chunks")
    store = out_dir / "results.zarr"
    with executor(settings.workers, scheduler, log) as client:
        outcome = run_sweep(grid, neuron, store, NeuronSweep.OUTPUTS, client=client, **common)
    log(f"      {len(outcome.chunks_computed)} chunk(s) computed, "
        f"{len(outcome.chunks_skipped)} already in the store, {outcome.wall_s:.1f} s")
    log("[2/3] deriving peak frequency, band width and spike rate maps")
    data = outcome.data
    maps = derive(data.rate_hz)
    summary = summarise(maps, data, neuron, reference)
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
        "store": str(store),
    })
    log("[3/3] writing the report")
    report = Report(out_dir, "snn-antenna tuning sweep: resonator tuning over k, b and I",
                    quick=quick, quick_note=quick_note(summary, neuron))
    report.text(spec.get("description", ""))
    _provenance_rows(report, summary)
    _write_report(report, data, maps, summary, reference)
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
        interval=tuple(cal["hz_per_k_peak_range"]) if cal["hz_per_k_peak_range"] else None,
        n=cal["responding_k"],
        note=(f"range of peak/k over the {cal['responding_k']} k values that fired (not a "
              f"confidence interval); the paper codes with amplitude 0.085 in its scaling, "
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


# -- derived maps -----------------------------------------------------------------------------
def derive(rate: xr.DataArray) -> xr.Dataset:
    """Per tuning curve (every point of the other axes): peak, centroid, FWHM, peak rate.

    Curves without a single spike have no peak: those entries are NaN here and ``null`` in
    summary.json, never a number.
    """
    f = rate.input_hz.values
    curves = rate.transpose(..., "input_hz")
    values = curves.values.reshape(-1, len(f))
    out = {name: np.full(len(values), np.nan) for name in
           ("peak_hz", "centroid_hz", "fwhm_hz", "peak_rate_hz")}
    edge = np.zeros(len(values), bool)
    for j, c in enumerate(values):
        top = c.max()
        if top <= 0:
            continue
        at_top = np.flatnonzero(c == top)
        out["peak_hz"][j] = float(np.exp(np.mean(np.log(f[at_top]))))
        out["centroid_hz"][j] = float(np.exp(np.sum(c * np.log(f)) / np.sum(c)))
        out["peak_rate_hz"][j] = top
        out["fwhm_hz"][j], edge[j] = fwhm(f, c, int(at_top[len(at_top) // 2]))
    dims = curves.dims[:-1]
    shape = curves.shape[:-1]
    coords = {d: rate[d] for d in dims}
    data = {name: (dims, arr.reshape(shape)) for name, arr in out.items()}
    data["fwhm_at_edge"] = (dims, edge.reshape(shape))
    ds = xr.Dataset(data, coords=coords)
    for name, units in (("peak_hz", "Hz"), ("centroid_hz", "Hz"), ("fwhm_hz", "Hz"),
                        ("peak_rate_hz", "Hz")):
        ds[name].attrs["units"] = units
    return ds


def fwhm(f: np.ndarray, c: np.ndarray, peak: int) -> tuple[float, bool]:
    """Width (Hz) of the contiguous band around ``peak`` where c ≥ max/2, the crossings
    interpolated linearly; True when the band reaches the end of the frequency axis."""
    half = c[peak] / 2.0
    lo = peak
    while lo > 0 and c[lo - 1] >= half:
        lo -= 1
    hi = peak
    while hi < len(c) - 1 and c[hi + 1] >= half:
        hi += 1
    at_edge = lo == 0 or hi == len(c) - 1
    f_lo = f[lo] if lo == 0 else np.interp(half, [c[lo - 1], c[lo]], [f[lo - 1], f[lo]])
    f_hi = f[hi] if hi == len(c) - 1 else np.interp(half, [c[hi + 1], c[hi]], [f[hi + 1], f[hi]])
    return float(f_hi - f_lo), bool(at_edge)


def _at(da: xr.DataArray, reference: Reference, keep: tuple[str, ...]) -> xr.DataArray:
    """Reduce every dim not in ``keep`` to the reference value (nearest) or its middle."""
    for dim in list(da.dims):
        if dim in keep:
            continue
        target = getattr(reference, dim, None)
        da = da.sel({dim: target}, method="nearest") if target is not None \
            else da.isel({dim: da.sizes[dim] // 2})
    return da


def _finite_or_none(values) -> list:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=float)]


CALIBRATION_TOLERANCE = 0.05


def summarise(maps: xr.Dataset, data: xr.Dataset, neuron: NeuronSweep,
              reference: Reference) -> dict:
    summary: dict = {"reference": dataclasses.asdict(reference)}
    used = {d: float(maps[d].sel({d: getattr(reference, d)}, method="nearest"))
            for d in maps.dims if hasattr(reference, d)}
    summary["reference_used"] = used
    if "k" in maps.dims:
        peak = _at(maps.peak_hz, reference, ("k",))
        centroid = _at(maps.centroid_hz, reference, ("k",))
        k = peak.k.values
        summary["k_to_peak_hz"] = {"k": [float(x) for x in k],
                                   "peak_hz": _finite_or_none(peak.values),
                                   "centroid_hz": _finite_or_none(centroid.values)}
        ok = np.isfinite(peak.values)
        okc = np.isfinite(centroid.values)
        # least squares through the origin: the time-scale law says peak = hz_per_k · k
        slope = float(np.sum(k[ok] * peak.values[ok]) / np.sum(k[ok] ** 2)) if ok.any() \
            else None
        slope_c = float(np.sum(k[okc] * centroid.values[okc]) / np.sum(k[okc] ** 2)) \
            if okc.any() else None
        ratio = peak.values[ok] / k[ok]
        summary["calibration"] = {
            "hz_per_k_peak": slope, "hz_per_k_centroid": slope_c,
            "hz_per_k_peak_range": [float(ratio.min()), float(ratio.max())] if ok.any() else None,
            "foundation_driven_hz_per_k": neurons.DRIVEN_HZ_PER_K,
            "relative_difference_peak": (slope / neurons.DRIVEN_HZ_PER_K - 1) if slope else None,
            "relative_difference_centroid":
                (slope_c / neurons.DRIVEN_HZ_PER_K - 1) if slope_c else None,
            "tolerance": CALIBRATION_TOLERANCE,
            # the foundation defines its constant as the tuning curve's geometric centroid
            "driven_hz_per_k_holds": bool(
                slope_c is not None
                and abs(slope_c / neurons.DRIVEN_HZ_PER_K - 1) <= CALIBRATION_TOLERANCE),
            "input_hz_step": float(np.min(np.diff(data.input_hz.values))),
            "responding_k": int(ok.sum()),
        }
    if "I" in maps.dims:
        width = _at(maps.fwhm_hz, reference, ("I",))
        summary["fwhm_vs_I"] = {"I": [float(x) for x in width.I.values],
                                "fwhm_hz": _finite_or_none(width.values),
                                "at_edge": [bool(x) for x in
                                            _at(maps.fwhm_at_edge, reference, ("I",)).values]}
    if "b" in maps.dims:
        rate = _at(maps.peak_rate_hz, reference, ("b",))
        summary["rate_vs_b"] = {"b": [float(x) for x in rate.b.values],
                                "peak_rate_hz": _finite_or_none(rate.values)}
    return summary


# -- report -----------------------------------------------------------------------------------
def _write_report(report: Report, data: xr.Dataset, maps: xr.Dataset, summary: dict,
                  reference: Reference) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cal = summary.get("calibration")
    if cal and cal["hz_per_k_peak"] is None:
        cal = None  # no k gave a single spike
    if cal:
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

    # tuning curves
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=False)
    f = data.input_hz.values
    if "k" in data.rate_hz.dims:
        curves = _at(data.rate_hz, reference, ("k", "input_hz"))
        colors = plt.cm.viridis(np.linspace(0, 1, curves.sizes["k"]))
        for color, kk in zip(colors, curves.k.values):
            axes[0].plot(f, curves.sel(k=kk).values, color=color, lw=1, label=f"k={kk:.3g}")
        axes[0].set_title("tuning curves vs k")
        axes[0].legend(fontsize=6, ncol=2)
    if "I" in data.rate_hz.dims:
        curves = _at(data.rate_hz, reference, ("I", "input_hz"))
        colors = plt.cm.plasma(np.linspace(0, 0.9, curves.sizes["I"]))
        for color, ii in zip(colors, curves.I.values):
            axes[1].plot(f, curves.sel(I=ii).values, color=color, lw=1, label=f"I={ii:.3g}")
        axes[1].set_title(f"tuning curves vs I (k≈{reference.k:g})")
        axes[1].legend(fontsize=7)
    for ax in axes:
        _log_hz_axis(ax)
        ax.set_xlabel("input frequency (Hz)")
        ax.set_ylabel("spike rate (Hz)")
    report.figure(fig, "tuning_curves",
                  "Spike rate (after the settling time) against the input frequency of the "
                  "square-wave coder's output. Left: one curve per k at the reference b and I. "
                  "Right: one curve per input amplitude I: the amplitude sets the band width "
                  "(the paper's Fig. 8G).")

    # heatmaps
    panels = [("k", "input_hz", data.rate_hz, "spike rate (Hz)")]
    if "k" in maps.dims and "I" in maps.dims:
        panels.append(("k", "I", maps.fwhm_hz, "band width, FWHM (Hz)"))
    if "k" in maps.dims and "b" in maps.dims:
        panels.append(("k", "b", maps.peak_rate_hz, "peak spike rate (Hz)"))
    panels = [p for p in panels if all(d in p[2].dims for d in p[:2])]
    # the dense k × frequency map across the page, the small ones below it: each readable at
    # the page's width
    layout = [["rate"] * 2] + ([[f"p{i}" for i in range(1, len(panels))]
                                + ["."] * (3 - len(panels))] if len(panels) > 1 else [])
    fig, named = plt.subplot_mosaic(layout, figsize=(10, 4 + 3.6 * (len(panels) > 1)),
                                    layout="constrained",
                                    height_ratios=[1.1, 1][:len(layout)])
    axes = [[named["rate"]] + [named[f"p{i}"] for i in range(1, len(panels))]]
    for ax, (ydim, xdim, da, label) in zip(axes[0], panels):
        sub = _at(da, reference, (ydim, xdim)).transpose(ydim, xdim)
        values = np.ma.masked_invalid(sub.values.astype(float))
        if xdim == "input_hz":   # dense and log-spaced: a frequency axis
            mesh = ax.pcolormesh(sub[xdim].values, sub[ydim].values, values,
                                 shading="nearest", cmap="magma")
            _log_hz_axis(ax)
            kk = sub.k.values
            ax.plot(neurons.DRIVEN_HZ_PER_K * kk, kk, "c--", lw=1,
                    label=f"in use: {neurons.DRIVEN_HZ_PER_K:g} Hz × k")
            if cal and cal["hz_per_k_peak"]:
                ax.plot(cal["hz_per_k_peak"] * kk, kk, "w:", lw=1.2,
                        label=f"peaks here: {cal['hz_per_k_peak']:.3g} Hz × k")
            ax.legend(fontsize=7, loc="lower right")
        else:                    # a few grid values: one labelled cell per value
            mesh = ax.pcolormesh(np.arange(sub.sizes[xdim] + 1), np.arange(sub.sizes[ydim] + 1),
                                 values, cmap="magma")
            _value_ticks(ax.set_xticks, ax.set_xticklabels, sub[xdim].values)
            _value_ticks(ax.set_yticks, ax.set_yticklabels, sub[ydim].values)
        fig.colorbar(mesh, ax=ax, label=label)
        ax.set_xlabel(AXIS_NAMES.get(xdim, xdim))
        ax.set_ylabel(AXIS_NAMES.get(ydim, ydim))
    report.figure(fig, "heatmaps",
                  "Left: spike rate over k and input frequency (reference b, I) with the "
                  "frequency per unit k the array uses and the one fitted to these peaks. "
                  "Middle: band width (FWHM) of each tuning curve over k and I. Right: peak "
                  "spike rate over k and b (the paper's Fig. 8H). Blank cells: the neuron "
                  "never fired.")

    # derived maps as lines
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), layout="constrained")
    if cal:
        kp = summary["k_to_peak_hz"]
        k = np.array(kp["k"])
        axes[0].plot(k, [np.nan if p is None else p for p in kp["peak_hz"]], "o-", label="peak")
        axes[0].plot(k, [np.nan if p is None else p for p in kp["centroid_hz"]], "s--",
                     label="centroid")
        axes[0].plot(k, neurons.DRIVEN_HZ_PER_K * k, "k:",
                     label=f"in use: {neurons.DRIVEN_HZ_PER_K:g} Hz × k")
        axes[0].set_xlabel(AXIS_NAMES["k"])
        axes[0].set_ylabel("preferred frequency (Hz)")
        axes[0].legend(fontsize=7)
    if "fwhm_vs_I" in summary:
        w = summary["fwhm_vs_I"]
        axes[1].plot(w["I"], [np.nan if x is None else x for x in w["fwhm_hz"]], "o-")
        _grid_axis(axes[1], w["I"])
        axes[1].set_xlabel(AXIS_NAMES["I"])
        axes[1].set_ylabel("band width, FWHM (Hz)")
    if "rate_vs_b" in summary:
        r = summary["rate_vs_b"]
        axes[2].plot(r["b"], [np.nan if x is None else x for x in r["peak_rate_hz"]], "o-")
        axes[2].set_xlabel(AXIS_NAMES["b"])
        axes[2].set_ylabel("peak spike rate (Hz)")
        _grid_axis(axes[2], r["b"])
        missing = [b for b, x in zip(r["b"], r["peak_rate_hz"]) if x is None]
        if missing:
            axes[2].set_title(f"no spike at b = {fmt(missing)}", fontsize=8)
    report.figure(fig, "maps",
                  f"Calibration k → preferred frequency; band width vs I; peak rate vs b "
                  f"(at {fmt(summary['reference_used'])}; a b without a point never fired).")


AXIS_NAMES = {"k": "time scale k", "I": "input amplitude I", "b": "recovery b",
              "input_hz": "input frequency (Hz)", "a": "recovery rate a",
              "c": "reset c (mV)", "d": "reset step d"}


def _grid_axis(ax, values) -> None:
    """The x axis spans the grid's values (a curve with one finite point would otherwise
    get a range of its own), ticked at them when there are few."""
    lo, hi = min(values), max(values)
    pad = 0.08 * (hi - lo) if hi > lo else 0.05 * abs(hi) or 0.05
    ax.set_xlim(lo - pad, hi + pad)
    if len(values) <= 8:
        ax.set_xticks(values)
        ax.set_xticklabels([f"{v:.3g}" for v in values])


def _value_ticks(set_ticks, set_labels, values, most: int = 12) -> None:
    """A tick at the centre of each cell (every few cells when there are many)."""
    step = max(1, int(np.ceil(len(values) / most)))
    idx = np.arange(0, len(values), step)
    set_ticks(idx + 0.5)
    set_labels([f"{values[i]:.3g}" for i in idx])


def _log_hz_axis(ax) -> None:
    from matplotlib.ticker import NullFormatter

    ax.set_xscale("log")
    ticks = [2, 5, 10, 20, 40, 60]
    ax.set_xticks(ticks)
    ax.set_xticklabels([str(t) for t in ticks])
    ax.xaxis.set_minor_formatter(NullFormatter())
