"""Keep what you saw: the live page's "save view" button writes the view as a PNG (drawn by the
page itself) and the shown span's data beside it, ``view-<stream time>.npz``, which
:func:`load_view` reads back as an xarray Dataset: the rate map as the read-out takes it
(``ContactDetector.detect(ds.rates)``), the antenna's axes, the coded input with Th, and the
contacts, control changes and decisions of that moment.

Written by the view process into its own folder (``--view-save``), each file atomically.
"""
from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from ...core.errors import SpecError
from ...core.files import atomic_write, make_folder

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
MAX_PNG_BYTES = 20 << 20


def save_view(history, start_s: float, end_s: float, png: bytes) -> dict:
    """Write the PNG and the data of stream time [start_s, end_s] from ``history`` (the view
    process's ViewHistory); returns the two paths."""
    if history.config.save_dir is None:
        raise SpecError("view-save", None, "a folder to save views in (--view-save DIR)")
    if not (np.isfinite(start_s) and np.isfinite(end_s) and start_s < end_s):
        raise SpecError("span", f"{start_s}..{end_s}", "a shown span start < end (seconds)")
    if not png.startswith(PNG_MAGIC) or len(png) > MAX_PNG_BYTES:
        raise SpecError("png", f"{len(png)} bytes", f"a PNG image of at most "
                                                    f"{MAX_PNG_BYTES >> 20} MB")
    folder = make_folder(history.config.save_dir)
    stem = folder / f"view-{end_s:09.2f}s"
    n = 1
    while stem.with_suffix(".npz").exists() or stem.with_suffix(".png").exists():
        n += 1
        stem = folder / f"view-{end_s:09.2f}s-{n}"

    def span(rows: np.ndarray) -> np.ndarray:
        return rows[(rows[:, 0] >= start_s) & (rows[:, 0] <= end_s)] if len(rows) else rows

    windows = span(history.windows.rows)
    if len(windows):                    # one window length: those since the last change
        windows = windows[np.flatnonzero(windows[:, 1] == windows[-1, 1])]
    meta = {"start_s": start_s, "end_s": end_s, "t_s": history.t_s,
            "window_s": float(windows[-1, 1]) if len(windows) else history.window_s,
            "contacts": [c for c in history.contacts if start_s <= c["onset_s"] <= end_s],
            "controls": list(history.controls), "decided": history.decided,
            "th_g": history.th_g, "counts": history.counts}
    buffer = io.BytesIO()
    np.savez_compressed(buffer, xy=span(history.xy.rows), coded=span(history.coded.rows),
                        windows=windows, neuron_hz=history.neuron_hz,
                        meta=np.array(json.dumps(meta)))
    atomic_write(stem.with_suffix(".npz"), buffer.getvalue())
    atomic_write(stem.with_suffix(".png"), png)
    return {"png": str(stem.with_suffix(".png")), "data": str(stem.with_suffix(".npz"))}


def load_view(path):
    """A saved view (the ``.npz``, or its ``.png``'s stem) as an xarray Dataset: ``rates``
    (neuron_hz × window_s, spikes/s, ``attrs['window_s']``), ``x_g``/``y_g`` over ``t_s``,
    ``signal_g``/``th_g``/``coded`` over ``t_input_s``; attrs carry the span, contacts,
    control changes and the panels' decisions as they were."""
    import xarray as xr

    path = Path(path)
    path = path.with_suffix(".npz") if path.suffix != ".npz" else path
    accepted = "a view-*.npz written by the live page's save button"
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError) as exc:
        raise SpecError("view", str(path), f"{accepted} ({type(exc).__name__})") from None
    xy, coded, windows = arrays["xy"], arrays["coded"], arrays["windows"]
    neuron_hz = arrays["neuron_hz"]
    rates = xr.DataArray(windows[:, 2:].T.reshape(len(neuron_hz), len(windows)),
                         dims=("neuron_hz", "window_s"),
                         coords={"neuron_hz": neuron_hz, "window_s": windows[:, 0]},
                         attrs={"window_s": meta["window_s"], "units": "spikes/s"})
    return xr.Dataset(
        {"rates": rates,
         "x_g": ("t_s", xy[:, 1] if len(xy) else np.empty(0)),
         "y_g": ("t_s", xy[:, 2] if len(xy) else np.empty(0)),
         "signal_g": ("t_input_s", coded[:, 1] if len(coded) else np.empty(0)),
         "th_g": ("t_input_s", coded[:, 2] if len(coded) else np.empty(0)),
         "coded": ("t_input_s", coded[:, 3] if len(coded) else np.empty(0))},
        coords={"t_s": xy[:, 0] if len(xy) else np.empty(0),
                "t_input_s": coded[:, 0] if len(coded) else np.empty(0)},
        attrs={"start_s": meta["start_s"], "end_s": meta["end_s"],
               "window_s": meta["window_s"], "th_g_last": meta["th_g"],
               "contacts": json.dumps(meta["contacts"]),
               "controls": json.dumps(meta["controls"]),
               "decided": json.dumps(meta["decided"])})
