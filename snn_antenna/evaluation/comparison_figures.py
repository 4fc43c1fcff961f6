"""Figures of the read-out comparison on the bench data set (the paper's Figs. 2C, 4B, 5D,
6D, 7A, 7B) and its cost–accuracy Pareto plot, each from a ``comparison.Comparison``'s parts
or its summary; each returns a matplotlib figure.
"""
from __future__ import annotations

import numpy as np

from .comparison import cost_items, label
from .confusion import confusion
from .signal import PAPER_SIGNAL
from ..readout.band_tuning import log_spectra
from ..readout.spiking import recording_attrs
from ..readout.spiking_decoders import TRAINING_FREE
from ..report.figures import legend_outside

# Half-width (cm) of the horizontal jitter that separates the contacts of one site.
SITE_JITTER_CM = 0.3


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def frequency_laws(feats, cal, reference=PAPER_SIGNAL):
    """Peak frequency vs distance, both modes, our fit and ``reference``'s laws (dashed: the
    paper's, or the laws fitted on a lab's calibration contacts) (Fig. 2C)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    d = feats["distance_cm"].values
    dd = np.linspace(d.min(), d.max(), 50)
    for mode, colour in (("low", "tab:blue"), ("high", "tab:red")):
        f = feats["params"].sel(parameter=f"F_{mode}").values
        jitter = np.random.default_rng(0).uniform(-SITE_JITTER_CM, SITE_JITTER_CM, len(d))
        ax.scatter(d + jitter, f, s=2, alpha=0.25, color=colour, label=f"{mode} peak")
        s, i = cal[f"{mode}_law"]
        ax.plot(dd, 10 ** (s * dd + i), color=colour)
        ps, pi = reference[f"{mode}_law"]
        ax.plot(dd, 10 ** (ps * dd + pi), color="k", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("contact distance (cm)")
    ax.set_ylabel("peak frequency (Hz)")
    legend_outside(ax, markerscale=5)
    return fig


def decay_times(feats, materials=("wood", "aluminium")):
    """τ_low vs distance for ``materials`` (the paper's wood and aluminium), mean ± sd per
    site (Fig. 5D)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    m = feats["material"].values.astype(str)
    tau = feats["params"].sel(parameter="tau_low").values
    d = feats["distance_cm"].values
    colours = {"wood": "tab:brown", "aluminium": "tab:gray"}
    for name in materials:
        colour = colours.get(name)
        sel = m == name
        if not sel.any():
            continue
        sites = np.unique(d[sel])
        mean = [tau[sel & (d == s)].mean() for s in sites]
        sd = [tau[sel & (d == s)].std() for s in sites]
        ax.errorbar(sites, 1e3 * np.array(mean), 1e3 * np.array(sd), color=colour,
                    marker="o", ms=3, capsize=2, label=name)
    ax.set_xlabel("contact distance (cm)")
    ax.set_ylabel("τ_low (ms)")
    legend_outside(ax)
    return fig


def predicted_distance(results, names):
    """Small multiples, three to a row, so the page keeps its width (Fig. 4B)."""
    plt = _plt()
    cols = min(3, len(names))
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols, 2.8 * rows), sharex=True,
                             sharey=True, squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        r = results[name]
        f = r.folds[0]
        y = r.y[f.test_index]
        ax.scatter(y, f.prediction, s=2, alpha=0.3,
                   color="tab:red" if name.startswith("spiking_") else "tab:blue")
        ax.plot([8, 38], [8, 38], "k--", lw=0.8)
        ax.set_title(f"{label(name)}: {r.summary['rmse_mm']:.2f} mm", fontsize=8)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("true (cm)")
    for ax in axes[:, 0]:
        ax.set_ylabel("predicted (cm)")
    fig.tight_layout()
    return fig


def confusion_matrix(result, materials):
    """Rows normalised: the share of each true class predicted as each class (Fig. 6D)."""
    plt = _plt()
    cm = confusion(result, len(materials))
    frac = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
    fig, ax = plt.subplots(figsize=(6, 5))
    im = ax.imshow(frac, cmap="Blues", vmin=0, vmax=1)
    for i in range(len(materials)):
        for j in range(len(materials)):
            ax.text(j, i, f"{100 * frac[i, j]:.0f}", ha="center", va="center", fontsize=7,
                    color="w" if frac[i, j] > 0.5 else "k")
    ax.set_xticks(range(len(materials)), materials, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(materials)), materials, fontsize=8)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    fig.colorbar(im, label="fraction of true class")
    return fig


def nmf_basis(result, feats):
    """The first seed's NMF basis vectors as band-pass filters (Fig. 7A)."""
    plt = _plt()
    nmf = result.folds[0].estimator.steps[0][1]  # the NMFFilterBank
    freq = feats["freq_hz"].values
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for k, comp in enumerate(nmf.components_):
        ax.plot(freq, comp / comp.max(), lw=0.8, label=f"{k + 1}")
    ax.set_xscale("log")
    ax.set_xlim(2, freq.max())
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("weight (normalised)")
    legend_outside(ax, fontsize=6, ncol=3)
    return fig


def nmf_accuracy(summary):
    """Material accuracy vs NMF dimension, the full-spectrum MLP and the spiking read-outs
    at their number of resonators (Fig. 7B)."""
    plt = _plt()
    curve = summary["material_accuracy"]["nmf_curve"]
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    ax.errorbar([r["n"] for r in curve], [100 * r["accuracy"] for r in curve],
                [100 * r["accuracy_sd"] for r in curve], marker="o", capsize=3, label="NMF → MLP")
    full = summary["material_accuracy"].get("mlp_spectrum_material")
    if full:
        ax.axhline(100 * full["mean"], color="k", ls="--", label="full spectrum")
    spiking = (summary.get("spiking") or {}).get("against_fft", {})
    for name, row in spiking.items():
        if row.get("neurons"):
            ax.scatter(row["neurons"], 100 * row["accuracy"], color="tab:red", zorder=3)
            ax.annotate(label(name).replace("spiking MLP, ", ""), (row["neurons"],
                        100 * row["accuracy"]), fontsize=7, xytext=(4, -10),
                        textcoords="offset points", color="tab:red")
    if spiking:
        ax.scatter([], [], color="tab:red", label="spiking (x: resonators)")
    ax.set_xlabel("filters: NMF dimension, or resonators (spiking)")
    ax.set_ylabel(f"{len(summary['materials'])}-material accuracy (%)")
    legend_outside(ax)
    return fig


def pareto(summary):
    """Accuracy vs cost per event of every trained pipeline, with the Pareto front."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    cost = summary["cost_us_per_event"]
    number = {k: i + 1 for i, (k, _) in enumerate(cost_items(summary))}
    panels = ((axes[0], summary["distance_rmse_mm"], "distance rmse (mm)", False),
              (axes[1], {k: v for k, v in summary["material_accuracy"].items()
                         if k != "nmf_curve"} | {f"nmf_{r['n']}": {"mean": r["accuracy"]}
                                                 for r in summary["material_accuracy"]
                                                 ["nmf_curve"]},
               f"{len(summary['materials'])}-material accuracy", True))
    for ax, table, ylabel, higher in panels:
        pts = sorted((cost[k], v["mean"], k) for k, v in table.items()
                     if k in cost and k not in TRAINING_FREE)
        if not pts:
            continue
        # Pipelines sharing a front end share a cost: their labels alternate sides, in
        # order of the y value, so neighbours do not print over each other.
        for rank, (c, a, k) in enumerate(sorted(pts, key=lambda p: (round(p[0], -1), p[1]))):
            colour = "tab:red" if k.startswith(("spiking_", "coder_")) else "tab:blue"
            ax.scatter(c, a, color=colour, s=22, zorder=3)
            ax.annotate(str(number.get(k, "")), (c, a), fontsize=7,
                        xytext=(5, -3) if rank % 2 == 0 else (-15, -3),
                        textcoords="offset points", color=colour)
        front, best = [], None
        for c, a, _k in pts:
            if best is None or (a > best if higher else a < best):
                front.append((c, a))
                best = a
        ax.plot(*zip(*front), color="k", lw=0.8, drawstyle="steps-post")
        ax.set_xscale("log")
        ax.margins(x=0.12)   # room for the labels on the left of the cheapest points
        costs = [c for c, _, _ in pts]
        if max(costs) / min(costs) > 10:   # within one decade the minor ticks are the labels
            ax.xaxis.set_minor_formatter(plt.NullFormatter())
        ax.set_xlabel("cost per event (µs: features + decoder)")
        ax.set_ylabel(ylabel)
    axes[0].set_title("blue: FFT pipelines, red: spiking; numbers: cost table", fontsize=8)
    fig.tight_layout()
    return fig


def tuned_curve(summary):
    """The tuned spiking bank's material accuracy against its number of resonators, beside
    NMF with as many filters, on the same events and split; the full-spectrum MLP and the
    target bar (0.9 of it) dashed. Below: the bank's neuron-steps per event (what its cost
    grows with; wall times of the curve's runs include compiling) and the budget of 5 × the
    FFT pipeline's cost at the ns per neuron-step measured for the tuned bank in this run."""
    plt = _plt()
    curve = summary["spiking"]["tuned"]["curve"]
    n = [r["n"] for r in curve]
    fig, (ax, cost) = plt.subplots(2, 1, figsize=(7.5, 6.4), sharex=True)
    ax.plot(n, [100 * r["spiking"] for r in curve], "o-", color="tab:red",
            label="spiking, tuned channels")
    ax.plot(n, [100 * r["nmf"] for r in curve], "s-", color="tab:blue", label="NMF-n → MLP")
    fft = 100 * curve[0]["fft_mlp"]
    ax.axhline(fft, color="k", ls="--", label="full-spectrum MLP")
    ax.axhline(0.9 * fft, color="0.5", ls=":", label="0.9 × full spectrum")
    ax.set_ylabel(f"{len(summary['materials'])}-material accuracy (%)")
    cost.plot(n, [r["neuron_steps_per_event"] / 1e6 for r in curve], "o-", color="tab:red",
              label="tuned bank")
    measured = summary["feature_costs"].get("spiking_tuned") or {}
    if measured.get("ns_per_neuron_step"):
        fft_us = summary["feature_costs"]["fft"]["features_us_per_event"]
        budget = 5 * fft_us * 1e3 / measured["ns_per_neuron_step"] / 1e6
        cost.axhline(budget, color="0.5", ls=":", label=f"5 × FFT pipeline at "
                     f"{measured['ns_per_neuron_step']:.0f} ns/step")
    cost.set_xlabel("resonators (spiking) or NMF filters")
    cost.set_ylabel("neuron-steps per event (millions)")
    cost.set_xticks(n)
    cost.set_ylim(bottom=0)
    legend_outside(ax)
    legend_outside(cost)
    return fig


def bank_on_spectra(data, bank, max_hz: float):
    """Top: mean log amplitude spectrum of ``data``'s contacts per material over the window
    a bank reads (its ``duration_s``), up to ``max_hz``. Below: one row per band of the bank
    (a channel, or one gain of a graded channel): its pass band as a bar, its resonators'
    preferred frequencies as ticks."""
    plt = _plt()
    attrs = recording_attrs(data)
    n = int(round(bank.duration_s * attrs[0]))
    freq, spectra = log_spectra(data["counts"].values[:, :n], *attrs)
    labels = data["material"].values.astype(str)
    rows = len(bank.bands)
    fig, (ax, lanes) = plt.subplots(2, 1, sharex=True, figsize=(8, 4.5 + 0.06 * rows),
                                    gridspec_kw={"height_ratios": [3, 1 + 0.04 * rows]})
    keep = freq <= max_hz
    for i, m in enumerate(sorted(set(labels))):
        ax.plot(freq[keep], spectra[labels == m][:, keep].mean(axis=0), lw=0.8,
                color=f"C{i}", label=m)
    ax.set_ylabel("log amplitude")
    ax.legend(fontsize=7, ncol=4)
    for row, (name, array) in enumerate(bank.arrays().items()):
        band = bank.bands[name]
        lanes.plot([band.highpass_hz or 0.0, band.lowpass_hz], [row, row], color="0.75",
                   lw=3, solid_capstyle="butt")
        lanes.plot(array.neuron_hz, np.full(len(array.neuron_hz), row), "|", color="k",
                   ms=6)
    lanes.set_ylim(rows - 0.5, -0.5)
    lanes.set_yticks([])
    lanes.set_ylabel(f"{rows} bands")
    lanes.set_xlabel("frequency (Hz)")
    fig.tight_layout()
    return fig
