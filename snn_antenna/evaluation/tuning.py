"""Tuning curves from a sweep of single resonators: spike rate against input frequency.

``derive`` reads every tuning curve of a rate grid (dims ``input_hz`` plus any of k, b, I,
...) for its peak, geometric centroid, band width (FWHM) and peak rate. ``summarise`` reads
them at one point of the other axes (``ReadPoint``, the nearest grid values): the calibration
k → preferred frequency against ``neurons.DRIVEN_HZ_PER_K`` (fitted through the origin: the
time-scale law says peak = hz_per_k · k), band width vs I and peak rate vs b. The figures
draw the curves and maps a tuning report shows.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import xarray as xr

from ..core import bounds
from ..report.figures import legend_outside
from ..networks import neurons

# The foundation's constant holds when the fitted centroid slope is within this (relative)
CALIBRATION_TOLERANCE = 0.05


@dataclass
class ReadPoint:
    """Where the tuning curves and the calibration are read (the nearest grid values)."""
    b: float = 0.26
    I: float = 0.15
    k: float = 1.0

    def __post_init__(self):
        bounds.declared(self)
        bounds.number("k", self.k, 0.0, lo_open=True)


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


def at(da: xr.DataArray, point: ReadPoint, keep: tuple[str, ...]) -> xr.DataArray:
    """Reduce every dim not in ``keep`` to the point's value (nearest) or its middle."""
    for dim in list(da.dims):
        if dim in keep:
            continue
        target = getattr(point, dim, None)
        da = da.sel({dim: target}, method="nearest") if target is not None \
            else da.isel({dim: da.sizes[dim] // 2})
    return da


def _finite_or_none(values) -> list:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def _slope_through_origin(k: np.ndarray, hz: np.ndarray) -> float | None:
    ok = np.isfinite(hz)
    return float(np.sum(k[ok] * hz[ok]) / np.sum(k[ok] ** 2)) if ok.any() else None


def calibration(maps: xr.Dataset, input_hz: np.ndarray,
                point: ReadPoint) -> tuple[dict, dict]:
    """Preferred frequency per k at ``point`` (the curve), and the fitted Hz per unit k
    (peaks and centroids) against ``neurons.DRIVEN_HZ_PER_K``, which the foundation defines
    as the tuning curve's geometric centroid."""
    peak = at(maps.peak_hz, point, ("k",))
    centroid = at(maps.centroid_hz, point, ("k",))
    k = peak.k.values
    slope = _slope_through_origin(k, peak.values)
    slope_c = _slope_through_origin(k, centroid.values)
    ok = np.isfinite(peak.values)
    ratio = peak.values[ok] / k[ok]
    driven = neurons.DRIVEN_HZ_PER_K
    curve = {"k": [float(x) for x in k], "peak_hz": _finite_or_none(peak.values),
             "centroid_hz": _finite_or_none(centroid.values)}
    return curve, {
        "hz_per_k_peak": slope, "hz_per_k_centroid": slope_c,
        "hz_per_k_peak_range": [float(ratio.min()), float(ratio.max())] if ok.any() else None,
        "foundation_driven_hz_per_k": driven,
        "relative_difference_peak": (slope / driven - 1) if slope else None,
        "relative_difference_centroid": (slope_c / driven - 1) if slope_c else None,
        "tolerance": CALIBRATION_TOLERANCE,
        "driven_hz_per_k_holds": bool(slope_c is not None
                                      and abs(slope_c / driven - 1) <= CALIBRATION_TOLERANCE),
        "input_hz_step": float(np.min(np.diff(input_hz))),
        "responding_k": int(ok.sum()),
    }


def summarise(maps: xr.Dataset, input_hz: np.ndarray, point: ReadPoint) -> dict:
    """The maps read at ``point``: the grid values used, the calibration (with a k axis),
    band width vs I (with an I axis) and peak rate vs b (with a b axis)."""
    summary: dict = {"reference": asdict(point)}
    summary["reference_used"] = {
        d: float(maps[d].sel({d: getattr(point, d)}, method="nearest"))
        for d in maps.dims if hasattr(point, d)}
    if "k" in maps.dims:
        summary["k_to_peak_hz"], summary["calibration"] = calibration(maps, input_hz, point)
    if "I" in maps.dims:
        width = at(maps.fwhm_hz, point, ("I",))
        summary["fwhm_vs_I"] = {"I": [float(x) for x in width.I.values],
                                "fwhm_hz": _finite_or_none(width.values),
                                "at_edge": [bool(x) for x in
                                            at(maps.fwhm_at_edge, point, ("I",)).values]}
    if "b" in maps.dims:
        rate = at(maps.peak_rate_hz, point, ("b",))
        summary["rate_vs_b"] = {"b": [float(x) for x in rate.b.values],
                                "peak_rate_hz": _finite_or_none(rate.values)}
    return summary


# -- figures ----------------------------------------------------------------------------------
AXIS_NAMES = {"k": "time scale k", "I": "input amplitude I", "b": "recovery b",
              "input_hz": "input frequency (Hz)", "a": "recovery rate a",
              "c": "reset c (mV)", "d": "reset step d"}


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def tuning_curves_figure(rate: xr.DataArray, point: ReadPoint):
    """Rate against input frequency: one curve per k (left) and per input amplitude I
    (right), the other axes at ``point``."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=False)
    f = rate.input_hz.values
    panels = ((axes[0], "k", plt.cm.viridis(np.linspace(0, 1, rate.sizes.get("k", 0))),
               "tuning curves vs k", dict(fontsize=6, ncol=2)),
              (axes[1], "I", plt.cm.plasma(np.linspace(0, 0.9, rate.sizes.get("I", 0))),
               f"tuning curves vs I (k≈{point.k:g})", dict(fontsize=7)))
    for ax, dim, colors, title, legend in panels:
        if dim not in rate.dims:
            continue
        curves = at(rate, point, (dim, "input_hz"))
        for color, value in zip(colors, curves[dim].values):
            ax.plot(f, curves.sel({dim: value}).values, color=color, lw=1,
                    label=f"{dim}={value:.3g}")
        ax.set_title(title)
        ax.legend(**legend)
    for ax in axes:
        _log_hz_axis(ax)
        ax.set_xlabel("input frequency (Hz)")
        ax.set_ylabel("spike rate (Hz)")
    return fig


def heatmaps_figure(rate: xr.DataArray, maps: xr.Dataset, point: ReadPoint,
                    hz_per_k_peak: float | None):
    """Rate over k × input frequency (with the Hz per unit k in use and the fitted one);
    band width over k × I and peak rate over k × b where the grid has those axes."""
    plt = _pyplot()
    panels = [("k", "input_hz", rate, "spike rate (Hz)")]
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
    axes = [named["rate"]] + [named[f"p{i}"] for i in range(1, len(panels))]
    for ax, (ydim, xdim, da, label) in zip(axes, panels):
        sub = at(da, point, (ydim, xdim)).transpose(ydim, xdim)
        values = np.ma.masked_invalid(sub.values.astype(float))
        if xdim == "input_hz":   # dense and log-spaced: a frequency axis
            mesh = ax.pcolormesh(sub[xdim].values, sub[ydim].values, values,
                                 shading="nearest", cmap="magma")
            _log_hz_axis(ax)
            kk = sub.k.values
            ax.plot(neurons.DRIVEN_HZ_PER_K * kk, kk, "c--", lw=1,
                    label=f"in use: {neurons.DRIVEN_HZ_PER_K:g} Hz × k")
            if hz_per_k_peak:
                ax.plot(hz_per_k_peak * kk, kk, ":", color="limegreen", lw=1.5,
                        label=f"peaks here: {hz_per_k_peak:.3g} Hz × k")
            legend_outside(ax, fontsize=8, loc="lower left", bbox_to_anchor=(0, 1.01),
                           ncols=2, frameon=False)
        else:                    # a few grid values: one labelled cell per value
            mesh = ax.pcolormesh(np.arange(sub.sizes[xdim] + 1), np.arange(sub.sizes[ydim] + 1),
                                 values, cmap="magma")
            for (yi, xi) in zip(*np.nonzero(np.ma.getmaskarray(values))):
                # a blank cell is a measurement too: say what it means
                ax.text(xi + 0.5, yi + 0.5, "no spike", ha="center", va="center",
                        fontsize=8, color="0.35")
            _value_ticks(ax.set_xticks, ax.set_xticklabels, sub[xdim].values)
            _value_ticks(ax.set_yticks, ax.set_yticklabels, sub[ydim].values)
        fig.colorbar(mesh, ax=ax, label=label)
        ax.set_xlabel(AXIS_NAMES.get(xdim, xdim))
        ax.set_ylabel(AXIS_NAMES.get(ydim, ydim))
    return fig


def _values(xs) -> list:
    return [np.nan if x is None else x for x in xs]


def maps_figure(summary: dict):
    """The read-outs of ``summarise`` as lines: k → preferred frequency (peak, centroid,
    the constant in use), band width vs I, peak rate vs b."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), layout="constrained")
    cal = summary.get("calibration")
    if cal and cal["hz_per_k_peak"] is not None:
        kp = summary["k_to_peak_hz"]
        k = np.array(kp["k"])
        axes[0].plot(k, _values(kp["peak_hz"]), "o-", label="peak")
        axes[0].plot(k, _values(kp["centroid_hz"]), "s--", label="centroid")
        axes[0].plot(k, neurons.DRIVEN_HZ_PER_K * k, "k:",
                     label=f"in use: {neurons.DRIVEN_HZ_PER_K:g} Hz × k")
        axes[0].set_xlabel(AXIS_NAMES["k"])
        axes[0].set_ylabel("preferred frequency (Hz)")
        axes[0].legend(fontsize=7)
    if "fwhm_vs_I" in summary:
        w = summary["fwhm_vs_I"]
        axes[1].plot(w["I"], _values(w["fwhm_hz"]), "o-")
        _grid_axis(axes[1], w["I"])
        axes[1].set_xlabel(AXIS_NAMES["I"])
        axes[1].set_ylabel("band width, FWHM (Hz)")
    if "rate_vs_b" in summary:
        r = summary["rate_vs_b"]
        axes[2].plot(r["b"], _values(r["peak_rate_hz"]), "o-")
        axes[2].set_xlabel(AXIS_NAMES["b"])
        axes[2].set_ylabel("peak spike rate (Hz)")
        _grid_axis(axes[2], r["b"])
        missing = [b for b, x in zip(r["b"], r["peak_rate_hz"]) if x is None]
        if missing:
            axes[2].set_title(f"no spike at b = {', '.join(f'{b:.4g}' for b in missing)}",
                              fontsize=8)
    return fig


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
