"""Reports: every output folder holds report.html, summary.json and its figures as PNG.

``summary.json`` holds the numbers and the provenance (spec, seed, versions, Brian2 target)
so any figure can be regenerated; files are written atomically. The page's header names the
command, commit, code hash, machine and date, so a copy mailed without its folder can still be
traced to what made it. Style: ``report.style``.
"""
from __future__ import annotations

import base64
import html
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..core.files import atomic_write
from ..core.provenance import machine, provenance
from .style import CSS as _CSS


def _jsonable(obj: Any):
    if hasattr(obj, "as_dict") and callable(obj.as_dict):   # stats.Interval and the like
        return _jsonable(obj.as_dict())
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

    Pass numbers, dicts and lists as they are: the report formats them (significant figures,
    nested rows, human column names beside the summary.json key). ``fmt`` does the same for
    numbers inside a sentence.
    """

    def __init__(self, out_dir: str | Path, title: str, quick: bool = False,
                 quick_note: str = "quick profile: too small to compare with the paper"):
        self.out_dir = Path(out_dir)
        self.title = title
        self.quick = quick
        self.quick_note = quick_note
        self._parts: list[str] = []
        self._lead: list[str] = []
        self.figures: list[str] = []
        self.figure_captions: dict[str, str] = {}     # file name -> caption, as the page shows it
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
            rows = [{"quantity": c.quantity, "value": c.value, "target": c.target,
                     "unit": c.unit, "source": c.source, "how": c.how}
                    for c in self._calibrated]
            parts.append("<h2>Calibrated to</h2><p>A model, a default or a fit to "
                         "the data named in each row's source was set to match these numbers; "
                         "they are inputs, not results.</p>"
                         + _table_html(rows, names=_CALIBRATED_NAMES))
        if self._predicted:
            rows = []
            for p in self._predicted:
                ci = p.interval
                interval = ""
                if ci is not None:
                    interval = f"{fmt(ci[0])} to {fmt(ci[1])}"
                    if p.n is not None:
                        interval += f" (n = {p.n})"
                rows.append({"quantity": p.quantity, "value": p.value, "unit": p.unit,
                             "interval": interval, "n": p.n, "paper": p.paper,
                             "source": p.source, "note": p.note})
            parts.append("<h2>Predicted</h2><p>Produced out of sample; only these are "
                         "compared with the paper.</p>"
                         + _table_html(rows, names=_PREDICTED_NAMES))
        return "".join(parts)

    def text(self, paragraph) -> None:
        self._parts.append(f"<p>{html.escape(fmt(paragraph))}</p>")

    def lead(self, paragraph) -> None:
        """The page's outcome in a sentence or two, shown above the calibrated and predicted
        tables: what a reader who reads nothing else should take away."""
        self._lead.append(f"<p class=\"lead\">{html.escape(fmt(paragraph))}</p>")

    def heading(self, text: str) -> None:
        self._parts.append(f"<h2>{html.escape(text)}</h2>")

    def table(self, rows: list[dict], caption: str = "") -> None:
        if rows:
            self._parts.append(_table_html(rows, caption))

    def figure(self, fig, name: str, caption: str = "") -> Path:
        """Save a matplotlib figure as NAME.png and embed it in the page."""
        import io

        import matplotlib.pyplot as plt

        path = self.out_dir / f"{name}.png"
        buffer = io.BytesIO()
        fig.savefig(buffer, dpi=110, bbox_inches="tight", format="png")
        plt.close(fig)
        atomic_write(path, buffer.getvalue())
        data = base64.b64encode(buffer.getvalue()).decode()
        self._parts.append(f'<figure><img alt="{html.escape(name)}" '
                           f'src="data:image/png;base64,{data}"/>'
                           f"<figcaption>{html.escape(fmt(caption))}</figcaption></figure>")
        self.figures.append(path.name)
        self.figure_captions[path.name] = fmt(caption)
        return path

    def _banner(self) -> str:
        if not self.quick:
            return ""
        note = self.quick_note
        if note.lower().startswith("quick profile:"):    # the banner's title says it already
            note = note.split(":", 1)[1].strip()
            note = note[:1].upper() + note[1:]
        return ('<div class="quick-banner" role="note"><strong>Quick profile</strong> '
                f"<span>{html.escape(note)}</span><small>This page was made with "
                "<code>--quick</code>: the spec's <code>[quick]</code> profile, a small run "
                "that checks the whole pipeline in seconds. Its numbers are not results; run "
                "the study without <code>--quick</code> for those.</small></div>")

    def write(self, summary: dict, spec: dict, target: str | None = None) -> dict:
        summary = dict(summary)
        summary["provenance"] = {**provenance(spec, target), "machine": machine()}
        summary["figures"] = list(self.figures)
        summary["figure_captions"] = dict(self.figure_captions)   # the results page's captions
        summary["quick"] = bool(self.quick)
        summary["calibrated"] = [asdict(c) for c in self._calibrated]
        summary["predicted"] = [asdict(p) for p in self._predicted]
        payload = json.dumps(_jsonable(summary), indent=2, allow_nan=False)
        atomic_write(self.out_dir / "summary.json", payload)
        spec_html = html.escape(json.dumps(_jsonable(spec), indent=2))
        prov = summary["provenance"]
        title = html.escape(self.title + (" (quick profile)" if self.quick else ""))
        page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>{_CSS}</style></head><body>
<h1>{html.escape(self.title)}</h1>
{_run_identity(prov)}
{self._banner()}{''.join(self._lead)}{self._provenance_sections()}
{''.join(self._parts)}
<h2>Provenance</h2>
<p>snn-antenna {html.escape(prov['snn_antenna_version'])}, Brian2
{html.escape(prov['brian2_version'])} (target {html.escape(prov['brian2_target'])}),
seed {prov['seed']}, Python {html.escape(prov['python'])}, created {prov['created']}.
<code>summary.json</code> beside this page holds the header's command, commit, code hash
and machine under <code>provenance</code>, and the calibrated and predicted rows under
<code>calibrated</code> and <code>predicted</code>, each number under the field shown below its
column's name. In the other tables a column whose name was made from a key shows that key
below the name.</p>
<details><summary>Resolved spec</summary><pre>{spec_html}</pre></details>
</body></html>
"""
        atomic_write(self.out_dir / "report.html", page)
        return summary


# The calibrated and predicted tables' column names, by the summary.json field each shows.
_CALIBRATED_NAMES = {"value": "model", "how": "tuned by"}
_PREDICTED_NAMES = {"value": "model", "interval": "95 % interval"}


def _run_identity(prov: dict) -> str:
    """The header a mailed copy is traced by: command, commit, code hash, machine, date."""
    created = str(prov.get("created", ""))
    date = created.replace("T", " ").replace("+00:00", " UTC")
    commit = prov.get("git_commit") or "none (not run from a git checkout)"
    rows = [("command", f"<code>{html.escape(shown_command(prov.get('command', '')))}</code>"),
            ("commit", f"<code>{html.escape(commit)}</code>"),
            ("code hash", f"<code>{html.escape(str(prov.get('code_sha256', '')))}</code> "
                          f"(snn-antenna {html.escape(str(prov.get('snn_antenna_version')))})"),
            ("machine", html.escape(str(prov.get("machine") or prov.get("platform", "")))),
            ("date", html.escape(date))]
    items = "".join(f"<dt>{name}</dt><dd>{value}</dd>" for name, value in rows)
    return f'<dl class="run-identity" aria-label="what made this page">{items}</dl>'


def shown_command(command: str) -> str:
    """The command as its user typed it: the program's name without the folder it was
    installed in (``/home/me/.venv/bin/snn-antenna run ...`` -> ``snn-antenna run ...``)."""
    program, _, rest = command.strip().partition(" ")
    name = os.path.basename(program)
    if name == "__main__.py" and os.path.basename(os.path.dirname(program)) == "snn_antenna":
        name = "python -m snn_antenna"
    return f"{name} {rest}".strip()


# -- formatting -------------------------------------------------------------------------------
# Units a key may end with (``distance_rmse_mm``), longest first; the rest is the name.
_UNITS = {("cm", "s"): "cm/s", ("mm", "s"): "mm/s", ("hz", "per", "k"): "Hz per unit k",
          ("mm",): "mm", ("cm",): "cm", ("m",): "m", ("ms",): "ms", ("us",): "µs",
          ("s",): "s", ("hz",): "Hz", ("khz",): "kHz", ("g",): "g", ("pct",): "%",
          ("percent",): "%", ("db",): "dB", ("mv",): "mV", ("deg",): "°", ("j",): "J",
          ("mb",): "MB", ("gb",): "GB"}
_WORDS = {"f1": "F1", "rmse": "RMSE", "mae": "MAE", "cpu": "CPU", "snn": "SNN", "svm": "SVM",
          "nmf": "NMF", "fwhm": "FWHM", "ci": "CI", "adc": "ADC", "id": "ID", "dt": "dt",
          "th": "Th", "hz": "Hz", "lda": "LDA", "pca": "PCA", "knn": "kNN", "ivp": "IVP",
          "pom": "POM", "pvc": "PVC", "fft": "FFT", "mlp": "MLP"}   # one spelling everywhere
_NAMES = {"cpu_s": "CPU time (s)", "wall_s": "wall time (s)", "compile_s": "compile time (s)",
          "k_dt": "k·dt", "n": "n", "p_value": "p value"}


def label(key) -> str:
    """A column name a reader understands: ``distance_rmse_mm`` -> "distance RMSE (mm)"."""
    key = str(key)
    if key in _NAMES:
        return _NAMES[key]
    if " " in key or "_" not in key:
        return _WORDS.get(key.lower(), key) if " " not in key else key
    words = key.split("_")
    unit = ""
    for suffix, name in sorted(_UNITS.items(), key=lambda kv: -len(kv[0])):
        if len(words) > len(suffix) and tuple(w.lower() for w in words[-len(suffix):]) == suffix:
            unit, words = name, words[:-len(suffix)]
            break
    text = " ".join(_WORDS.get(w.lower(), w) for w in words).replace("k dt", "k·dt")
    return f"{text} ({unit})" if unit else text


def unit_of(key) -> str:
    """The unit a key's name ends with ("" when none): ``rate_hz`` -> "Hz"."""
    text = label(key)
    return text[text.rfind("(") + 1:-1] if text.endswith(")") and "(" in text else ""


def by_speed(values: dict, show) -> str:
    """A speed → value mapping in one line, the one way reports write it:
    ``12 cm/s: 0.0669 g · 27 cm/s: 0.35 g`` (speeds in order, as numbers, not JSON keys)."""
    items = sorted((float(v), x) for v, x in values.items())
    return " · ".join(f"{v:g} cm/s: {show(x)}" for v, x in items)


def fmt(value, unit: str = "", digits: int = 4) -> str:
    """``value`` as a reader wants it in a sentence or a cell: numbers to ``digits``
    significant figures (plus ``unit``), dicts as "name = value" pairs, lists inline,
    intervals with their n. Never Python's repr of a dict or a float's 17 digits."""
    if unit and _is_number(value):
        value, unit = _larger_unit(float(value), unit)
    text = _fmt(value, digits)
    return f"{text} {unit}" if unit and text and _is_number(value) else text


def _larger_unit(value: float, unit: str) -> tuple[float, str]:   # 389946 µs -> 389.9 ms
    base, _, per = unit.partition("/")
    while base in _TIME_STEPS and abs(value) >= 1000:
        value, base = value / 1000, _TIME_STEPS[base]
    return value, base + ("/" + per if per else "")


def _is_number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) \
        and not isinstance(value, (bool, np.bool_))


def _fmt(value, digits: int = 4) -> str:
    if value is None:
        return "–"
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return _number(float(value), digits)
    if hasattr(value, "as_dict") and callable(value.as_dict):
        value = value.as_dict()
    if isinstance(value, dict):
        special = _summary_statistic(value, digits)
        if special is not None:
            return special
        return ", ".join(_pair(k, v, digits) for k, v in value.items())
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple, set)):
        items = list(value)
        shown = [_fmt(v, digits) for v in items[:_MAX_ITEMS]]
        more = f", … ({len(items)} values)" if len(items) > _MAX_ITEMS else ""
        if any(isinstance(v, (dict, list, tuple)) for v in items):
            return "; ".join(shown) + more
        return ", ".join(shown) + more
    return str(value)


_MAX_ITEMS = 12
_TIME_STEPS = {"ns": "µs", "µs": "ms", "ms": "s"}


def _pair(key, value, digits) -> str:
    unit = unit_of(key)
    name = label(key)
    if unit:
        name = name[:name.rfind("(")].rstrip()
        return f"{name} = {fmt(value, unit, digits)}"
    return f"{name} = {_fmt(value, digits)}"


def _number(x: float, digits: int) -> str:
    """``digits`` significant figures, trailing zeros dropped; powers of ten as ×10ⁿ."""
    if not np.isfinite(x):
        return "n/a"
    if x == 0:
        return "0"
    exponent = int(np.floor(np.log10(abs(x))))
    if -4 <= exponent < 6:
        decimals = digits - 1 - exponent
        if decimals < 0:     # 64245 to 2 figures: 64000
            return f"{round(x, decimals):.0f}"
        text = f"{round(x, decimals):.{decimals}f}"
        if "." in text:
            text = text.rstrip("0").rstrip(".")
        return "0" if text in ("-0", "") else text
    mantissa = f"{x / 10 ** exponent:.{digits - 1}f}".rstrip("0").rstrip(".")
    if mantissa in ("10", "-10"):      # rounding carried into the next power
        mantissa, exponent = mantissa[:-1], exponent + 1
    return f"{mantissa}×10{str(exponent).translate(_SUPERSCRIPT)}"


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _summary_statistic(d: dict, digits: int) -> str | None:
    """An interval (stats.Interval.as_dict) or a mean ± sd: with n beside it, always."""
    if {"mean", "low", "high"} <= set(d):
        n = d.get("n")
        level = d.get("level", 0.95)
        text = (f"{_fmt(d['mean'], digits)} ({_fmt(100 * level, 3)} % CI "
                f"{_fmt(d['low'], digits)} to {_fmt(d['high'], digits)}, "
                f"n = {_fmt(n)}")
        if d.get("verdict"):
            text += f"; {d['verdict']}"
        return text + ")"
    spread = next((k for k in ("std", "sd", "sem") if k in d), None)
    if "mean" in d and spread is not None:
        n = d.get("n", d.get("n_seeds"))
        rest = {k: v for k, v in d.items() if k not in ("mean", spread, "n", "n_seeds")}
        text = (f"{_fmt(d['mean'], digits)} ± {_fmt(d[spread], digits)} "
                f"({'sd' if spread != 'sem' else 'sem'}, "
                f"{'n = ' + _fmt(n) if n is not None else 'n not given'})")
        return text + ("; " + _fmt(rest, digits) if rest else "")
    return None


def _table_html(rows: list[dict], caption: str = "", names: dict | None = None) -> str:
    """Rows as a table every cell of which is visible on a 1,000 px page and on A4.

    Up to WIDE_COLUMNS columns fit with their text wrapped. A wider table with few rows is
    transposed (one row per quantity); one with many rows too is split into column groups,
    each repeating the first column so a reader knows which row a number belongs to.
    ``names``: a column's name for a key whose ``label`` is not what the column shows."""
    names = names or {}
    cols = list(dict.fromkeys(c for r in rows for c in r))
    cap = f"<caption>{html.escape(fmt(caption))}</caption>" if caption else ""
    if len(cols) <= WIDE_COLUMNS:
        return _plain_table(rows, cols, cap, names)
    if len(rows) < WIDE_COLUMNS:
        return _transposed_table(rows, cols, cap, names)
    first, rest = cols[0], cols[1:]
    step = WIDE_COLUMNS - 1
    groups = [rest[i:i + step] for i in range(0, len(rest), step)]
    return "".join(_plain_table(rows, [first] + g, cap if i == 0 else "", names)
                   for i, g in enumerate(groups))


def _plain_table(rows: list[dict], cols: list, cap: str, names: dict) -> str:
    numeric = {c for c in cols if all(r.get(c) is None or _is_number(r.get(c)) for r in rows)}
    head = "".join(_header_html(c, c in numeric, name=names.get(c)) for c in cols)
    body = "".join("<tr>" + "".join(_cell_html(r.get(c)) for c in cols) + "</tr>"
                   for r in rows)
    return (f'<div class="table-scroll"><table>{cap}<thead><tr>{head}</tr></thead>'
            f"<tbody>{body}</tbody></table></div>")


def _transposed_table(rows: list[dict], cols: list, cap: str, names: dict) -> str:
    head = "<th class=\"text\">quantity</th>" + "".join(
        f'<th class="num">{"row " + str(i + 1) if len(rows) > 1 else "value"}</th>'
        for i in range(len(rows)))
    body = "".join("<tr>" + _header_html(c, False, row=True, name=names.get(c))
                   + "".join(_cell_html(r.get(c)) for r in rows) + "</tr>" for c in cols)
    return (f'<div class="table-scroll"><table class="transposed">{cap}<thead><tr>{head}'
            f"</tr></thead><tbody>{body}</tbody></table></div>")


WIDE_COLUMNS = 8


def _header_html(key, numeric: bool, row: bool = False, name: str | None = None) -> str:
    name = name or label(key)
    key_html = f'<span class="key">{html.escape(str(key))}</span>' if name != str(key) else ""
    scope = ' scope="row"' if row else ""
    return (f'<th class="{"num" if numeric else "text"}"{scope}>'
            f"{html.escape(name)}{key_html}</th>")


def _cell_html(value) -> str:
    if hasattr(value, "as_dict") and callable(value.as_dict):
        value = value.as_dict()
    if isinstance(value, dict) and _summary_statistic(value, 4) is None and value:
        rows = "".join(f"<tr><th>{html.escape(label(k))}</th>{_cell_html(v)}</tr>"
                       for k, v in value.items())
        return f'<td class="text"><table class="nested">{rows}</table></td>'
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, dict) for v in value):
        return f'<td class="text">{_table_html(list(value))}</td>'
    text = html.escape(_fmt(value))
    kind = "num" if _is_number(value) else "text"
    return f'<td class="{kind}">{text}</td>'
