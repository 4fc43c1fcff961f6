"""Reports: every output folder holds report.html, summary.json and its figures as PNG.

``summary.json`` holds the numbers and the provenance (resolved spec, seed, package and
library versions, Brian2's code-generation target) so any figure can be regenerated. Files
are written atomically: a reader never sees half a report.
"""
from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import os
import platform
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np


def atomic_write(path: str | Path, data: bytes | str) -> None:
    """Write to a temporary file beside ``path`` and rename it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mode = "wb" if isinstance(data, bytes) else "w"
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _jsonable(obj: Any):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        value = float(obj)
        if not np.isfinite(value):
            raise ValueError(f"refusing to write a non-finite number ({value}) to summary.json")
        return value
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


def provenance(spec: dict, target: str | None = None) -> dict:
    import brian2
    import scipy
    import sklearn

    from . import __version__
    return {
        "spec": spec,
        "seed": spec.get("seed", 0),
        "snn_antenna_version": __version__,
        "brian2_version": brian2.__version__,
        "brian2_target": target or str(brian2.prefs.codegen.target),
        "numpy_version": np.__version__,
        "scipy_version": scipy.__version__,
        "sklearn_version": sklearn.__version__,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join(sys.argv),
    }


@dataclass
class Calibrated:
    """A number the generator or a default was *set* to match: never a result.

    ``value`` is what the model gives after calibration, ``target`` the number it was tuned
    to, ``source`` where the target comes from (a section of docs/reference.md), ``how`` the
    knob that was turned.
    """
    quantity: str
    value: Any
    target: Any
    unit: str = ""
    source: str = ""
    how: str = ""


@dataclass
class Predicted:
    """A number the model produced out of sample; only these are compared with the paper.

    ``paper`` is the paper's value for the same quantity (None when the paper has none),
    ``interval`` a confidence interval of ``value`` (or of a paired difference) over ``n``
    seeds or splits, ``note`` what a reader needs to weigh it (e.g. "not resolved").
    """
    quantity: str
    value: Any
    unit: str = ""
    paper: Any = None
    source: str = ""
    interval: tuple | None = None
    n: int | None = None
    note: str = ""


class Report:
    """Collect sections, tables and figures; ``write`` produces the folder.

    Every report lists what it was calibrated to apart from what it predicts
    (``calibrated`` / ``predicted``); a quantity may not be both. ``quick`` marks a run of
    the spec's small profile with a banner, with ``quick_note`` saying what is too small to
    compare.
    """

    def __init__(self, out_dir: str | Path, title: str, quick: bool = False,
                 quick_note: str = "quick profile: too small to compare with the paper"):
        self.out_dir = Path(out_dir)
        self.title = title
        self.quick = quick
        self.quick_note = quick_note
        self._parts: list[str] = []
        self.figures: list[str] = []
        self._calibrated: list[Calibrated] = []
        self._predicted: list[Predicted] = []

    def calibrated(self, *items: Calibrated) -> None:
        self._check_apart(items, self._predicted)
        self._calibrated.extend(items)

    def predicted(self, *items: Predicted) -> None:
        self._check_apart(items, self._calibrated)
        self._predicted.extend(items)

    @staticmethod
    def _check_apart(new, other) -> None:
        both = {i.quantity for i in new} & {o.quantity for o in other}
        if both:
            raise ValueError(f"{sorted(both)} listed as calibrated and as predicted: a "
                             "calibration target cannot be shown as a reproduction")

    def _provenance_sections(self) -> str:
        parts = []
        if self._calibrated:
            rows = [{"quantity": c.quantity, "model": c.value, "target": c.target,
                     "unit": c.unit, "source": c.source, "tuned by": c.how}
                    for c in self._calibrated]
            parts.append("<h2>Calibrated to</h2><p>The generator or a default was set to "
                         "match these numbers; they are inputs, not results.</p>"
                         + _table_html(rows))
        if self._predicted:
            rows = []
            for p in self._predicted:
                ci = p.interval
                rows.append({"quantity": p.quantity, "model": p.value, "unit": p.unit,
                             "95 % interval": (f"{_fmt(ci[0])} to {_fmt(ci[1])}"
                                               if ci is not None else ""),
                             "n": p.n, "paper": p.paper, "source": p.source, "note": p.note})
            parts.append("<h2>Predicted</h2><p>Produced out of sample; only these are "
                         "compared with the paper.</p>" + _table_html(rows))
        return "".join(parts)

    def text(self, paragraph: str) -> None:
        self._parts.append(f"<p>{html.escape(paragraph)}</p>")

    def heading(self, text: str) -> None:
        self._parts.append(f"<h2>{html.escape(text)}</h2>")

    def table(self, rows: list[dict], caption: str = "") -> None:
        if rows:
            self._parts.append(_table_html(rows, caption))

    def figure(self, fig, name: str, caption: str = "") -> Path:
        """Save a matplotlib figure as NAME.png and embed it in the page."""
        import matplotlib.pyplot as plt

        path = self.out_dir / f"{name}.png"
        self.out_dir.mkdir(parents=True, exist_ok=True)
        fig.savefig(path.with_suffix(".png.tmp"), dpi=110, bbox_inches="tight", format="png")
        os.replace(path.with_suffix(".png.tmp"), path)
        plt.close(fig)
        data = base64.b64encode(path.read_bytes()).decode()
        self._parts.append(f'<figure><img alt="{html.escape(name)}" '
                           f'src="data:image/png;base64,{data}"/>'
                           f"<figcaption>{html.escape(caption)}</figcaption></figure>")
        self.figures.append(path.name)
        return path

    def write(self, summary: dict, spec: dict, target: str | None = None) -> dict:
        summary = dict(summary)
        summary["provenance"] = provenance(spec, target)
        summary["figures"] = list(self.figures)
        summary["quick"] = bool(self.quick)
        summary["calibrated"] = [asdict(c) for c in self._calibrated]
        summary["predicted"] = [asdict(p) for p in self._predicted]
        payload = json.dumps(_jsonable(summary), indent=2, allow_nan=False)
        atomic_write(self.out_dir / "summary.json", payload)
        spec_html = html.escape(json.dumps(_jsonable(spec), indent=2))
        prov = summary["provenance"]
        banner = (f'<p class="quick-banner" style="background:#fff3cd;border:1px solid #e0b000;'
                  f'padding:.6em 1em"><strong>{html.escape(self.quick_note)}</strong></p>'
                  if self.quick else "")
        page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(self.title)}</title>
<style>body{{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto;padding:0 1em;
color:#222}} table{{border-collapse:collapse;margin:1em 0}} td,th{{border:1px solid #ccc;
padding:.25em .6em;text-align:right}} th{{background:#f3f3f3}} img{{max-width:100%}}
figcaption{{color:#555;font-size:.9em}} pre{{background:#f7f7f7;padding:1em;overflow:auto}}
</style></head><body>
<h1>{html.escape(self.title)}</h1>
{banner}{self._provenance_sections()}
{''.join(self._parts)}
<h2>Provenance</h2>
<p>snn-antenna {html.escape(prov['snn_antenna_version'])}, Brian2
{html.escape(prov['brian2_version'])} (target {html.escape(prov['brian2_target'])}),
seed {prov['seed']}, Python {html.escape(prov['python'])}, created {prov['created']}.</p>
<details><summary>Resolved spec</summary><pre>{spec_html}</pre></details>
</body></html>
"""
        atomic_write(self.out_dir / "report.html", page)
        return summary


def draw_rate_map(ax, rates):
    """Draw a rate map (the paper's frequency map, Fig. 10H) on ``ax``; returns the mesh.

    Neurons sit on a log-frequency axis, each cell spanning halfway to its neighbours, so a
    log-spaced array draws as equal rows labelled by frequency.
    """
    w = float(rates.attrs["window_s"])
    hz = rates.neuron_hz.values
    if len(hz) > 1:
        edges_hz = np.r_[hz[0] / np.sqrt(hz[1] / hz[0]), np.sqrt(hz[:-1] * hz[1:]),
                         hz[-1] * np.sqrt(hz[-1] / hz[-2])]
    else:
        edges_hz = np.array([hz[0] * 0.9, hz[0] * 1.1])
    edges_t = np.r_[rates.window_s.values, rates.window_s.values[-1] + w]
    mesh = ax.pcolormesh(edges_t, edges_hz, rates.values, cmap="magma", shading="flat")
    ax.set_yscale("log")
    ticks = [f for f in (5, 7, 10, 15, 20, 30, 50, 100, 200, 500) if edges_hz[0] <= f <= edges_hz[-1]]
    ax.set_yticks(ticks)
    ax.set_yticklabels([str(f) for f in ticks])
    ax.minorticks_off()
    ax.set_ylabel("neuron (Hz)")
    return mesh


def _table_html(rows: list[dict], caption: str = "") -> str:
    cols = list(dict.fromkeys(c for r in rows for c in r))
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in cols)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(r.get(c)))}</td>" for c in cols)
                   + "</tr>" for r in rows)
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    return f"<table>{cap}<tr>{head}</tr>{body}</table>"


def _fmt(value) -> str:
    if isinstance(value, (float, np.floating)):
        return f"{value:.4g}"
    return "" if value is None else str(value)
