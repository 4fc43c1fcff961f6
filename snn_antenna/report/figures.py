"""Figure parts every study draws the same way: the rate map and its colour scale.

``Report.figure`` saves a finished figure into the report folder; these draw on its axes.
"""
from __future__ import annotations

import numpy as np


def draw_rate_map(ax, rates, colorbar: bool | str = False, **mesh_kwargs):
    """Draw a rate map (the paper's frequency map, Fig. 10H) on ``ax``; returns the mesh.

    Neurons sit on a log-frequency axis, each cell spanning halfway to its neighbours, so a
    log-spaced array draws as equal rows labelled by frequency. ``colorbar=True`` adds the
    colour scale ("spike rate (Hz)"; a string replaces that label) beside ``ax``: a rate map
    without one cannot be read. ``mesh_kwargs`` (e.g. ``vmax``) go to ``pcolormesh``.
    """
    w = float(rates.attrs["window_s"])
    hz = rates.neuron_hz.values
    if len(hz) > 1:
        edges_hz = np.r_[hz[0] / np.sqrt(hz[1] / hz[0]), np.sqrt(hz[:-1] * hz[1:]),
                         hz[-1] * np.sqrt(hz[-1] / hz[-2])]
    else:
        edges_hz = np.array([hz[0] * 0.9, hz[0] * 1.1])
    edges_t = np.r_[rates.window_s.values, rates.window_s.values[-1] + w]
    mesh = ax.pcolormesh(edges_t, edges_hz, rates.values,
                         **{"cmap": "magma", "shading": "flat", **mesh_kwargs})
    ax.set_yscale("log")
    ticks = [f for f in (5, 7, 10, 15, 20, 30, 50, 100, 200, 500)
             if edges_hz[0] <= f <= edges_hz[-1]]
    ax.set_yticks(ticks)
    ax.set_yticklabels([str(f) for f in ticks])
    ax.minorticks_off()
    ax.set_ylabel("neuron (Hz)")
    if colorbar:
        rate_colorbar(ax, mesh, colorbar if isinstance(colorbar, str) else "spike rate (Hz)")
    return mesh


def rate_colorbar(ax, mesh, label_text: str = "spike rate (Hz)"):
    """The colour scale of a rate map (or any mesh) beside ``ax``, labelled with its unit."""
    bar = ax.figure.colorbar(mesh, ax=ax, pad=0.02, fraction=0.05)
    bar.set_label(label_text)
    return bar


def legend_outside(ax, **kwargs):
    """A legend beside the axes, never over the data (savefig's bbox_inches="tight" keeps it)."""
    return ax.legend(**{"loc": "upper left", "bbox_to_anchor": (1.01, 1), "borderaxespad": 0,
                        **kwargs})
