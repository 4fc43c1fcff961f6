"""Figures of a Th × speed study: F1 curves of the sweep, the gate's recall, F1 per method.

Plain matplotlib over ``evaluation.thresholds``' results (a fitted sweep dataset, a
``GateRecall``, the ``compare`` dict); the figures that draw rate maps stay with the report.
"""
from __future__ import annotations

import numpy as np

from .thresholds import GateRecall, f1_at
from ..report.figures import legend_outside


def pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def th_axis(ax, values, axis: str = "y") -> None:
    """Th on a log axis only where it spans a decade or more, with plain tick labels
    (0.03, not 3×10⁻²); a narrower range stays linear."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    if len(v) == 0 or v.max() / v.min() < 10:
        return
    (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
    target = ax.yaxis if axis == "y" else ax.xaxis
    target.set_major_locator(LogLocator(base=10, subs=(1.0, 3.0)))
    target.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    target.set_minor_formatter(NullFormatter())


def _errorbar(ax, x, intervals, **kw):
    mean = np.array([np.nan if d["mean"] is None else d["mean"] for d in intervals])
    low = np.array([m if d.get("low") is None else d["low"] for m, d in zip(mean, intervals)])
    high = np.array([m if d.get("high") is None else d["high"] for m, d in zip(mean, intervals)])
    # yerr as one (2, n) array: a list of two length-1 arrays is read as scalars (deprecated)
    ax.errorbar(x, mean, yerr=np.array([mean - low, high - mean]), capsize=3, **kw)


def f1_per_category(comparison: dict):
    plt = pyplot()
    rows = comparison["per_category"]
    fig, ax = plt.subplots(figsize=(9, 4))
    labels = [k[3:] for k in rows[0] if k.startswith("F1 ")]
    styles = {"gated": ("tab:red", "o"), "lookup": ("tab:blue", "s")}
    width = 0.8 / len(labels)
    for j, label in enumerate(labels):
        color, marker = styles.get(label, (None, "^"))
        x = np.arange(len(rows)) + (j - (len(labels) - 1) / 2) * width
        _errorbar(ax, x, [r[f"F1 {label}"] for r in rows], fmt=marker, color=color,
                  label=label)
    ax.set_xticks(range(len(rows)), [r["scenes"] for r in rows])
    ax.set_ylabel("F1 (mean over seeds, 95 % CI)")
    ax.set_ylim(-0.02, 1.02)
    legend_outside(ax, fontsize=8)
    fig.tight_layout()
    return fig


def f1_curves(ds):
    """F1, FP/min and latency against Th per speed, from a ``fit_th_star``-ed sweep."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), sharex=True)
    th = ds.threshold_g.values
    x = np.where(th > 0, th, th[th > 0].min() / 2)
    cmap = plt.get_cmap("viridis")
    speeds = ds.speed_cm_s.values
    for i, v in enumerate(speeds):
        c = cmap(i / max(len(speeds) - 1, 1))
        axes[0].plot(x, ds.f1.isel(speed_cm_s=i), color=c, label=f"{v:g}")
        star = float(ds.th_star_g.values[i])
        axes[0].plot(star, f1_at(ds, v, star), "o", color=c)
        best = float(ds.best_th_g.values[i])
        axes[0].plot(best, f1_at(ds, v, best), "x", color=c)
        axes[1].plot(x, ds.fp_per_min.isel(speed_cm_s=i), color=c)
        axes[2].plot(x, ds.latency_s.isel(speed_cm_s=i), color=c)
    for ax, lab in zip(axes, ("F1", "false positives / min", "latency (s)")):
        th_axis(ax, x, "x")
        ax.set_xlabel("Th (g; leftmost point: Th = 0)")
        ax.set_ylabel(lab)
        ax.tick_params(axis="x", labelrotation=45)
    legend_outside(axes[-1], handles=axes[0].get_legend_handles_labels()[0], title="cm/s",
                   fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def gate_recall(recall: GateRecall):
    plt = pyplot()
    fig, (a0, a1) = plt.subplots(1, 2, figsize=(12, 4))
    lc, held_out, th_star = recall.learning_curve, recall.held_out, recall.th_star_g
    err = np.abs(np.log(lc.values / th_star[None, :]))
    a0.plot(lc.epoch, np.exp(err[:, ~held_out].mean(1)), "o-", label="trained speeds")
    if held_out.any():
        a0.plot(lc.epoch, np.exp(err[:, held_out].mean(1)), "s-", label="held-out speeds")
    th_axis(a0, np.exp(err.mean(1)))
    a0.set_xlabel("epoch")
    a0.set_ylabel("recall error factor (×)")
    a0.legend()   # the right-hand panel sits where an outside legend would go
    v, recalled = recall.speeds_cm_s, recall.recalled_g
    a1.plot(v, th_star, "k.-", label="Th* (sweep)")
    a1.plot(v[~held_out], recalled[~held_out], "o", color="tab:blue", label="gate, trained")
    a1.plot(v[held_out], recalled[held_out], "s", color="tab:orange", label="gate, held out")
    fine = np.linspace(v.min(), v.max(), 100)
    a1.plot(fine, recall.table(fine), color="0.6", lw=1, label="lookup (interpolated)")
    th_axis(a1, np.r_[th_star, recalled])
    a1.set_xlabel("speed (cm/s)")
    a1.set_ylabel("Th (g)")
    legend_outside(a1, fontsize=8)
    fig.tight_layout()
    return fig


def f1_methods(comparison: dict):
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    curve = comparison["fixed_curve"]
    th = np.array([c["threshold_g"] for c in curve])
    _errorbar(ax, th, curve, fmt="k.-", label="fixed Th")
    for label, color, ls in (("gated", "tab:red", "-"), ("lookup", "tab:blue", "--")):
        d = comparison["f1"][label]
        ax.axhline(d["mean"], color=color, ls=ls, label=f"{label} (mean)")
        if d.get("low") is not None:
            ax.axhspan(d["low"], d["high"], color=color, alpha=0.12)
    th_axis(ax, th, "x")
    ax.set_ylim(max(-0.02, ax.get_ylim()[0]), min(1.02, ax.get_ylim()[1]))
    ax.set_xlabel("fixed Th (g)")
    ax.set_ylabel("F1 over all evaluation scenes")
    legend_outside(ax, fontsize=8)
    fig.tight_layout()
    return fig
