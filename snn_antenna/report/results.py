"""The results page: every measured number of the documentation, regenerated from its sources.

    snn-antenna results out/quickstart out/gating ... --bench out/bench_array.json \\
        --bench-output out/bench_coders.json "python benchmarks/bench_coders.py" \\
        --out docs/results.md
    python -m snn_antenna.report.results record-bench out/bench_array.json -- \\
        python benchmarks/bench_array.py --seconds 2

The page is built from the ``summary.json`` of the study runs it is given and from the output
of benchmarks; nothing on it is typed by hand. A benchmark's output is either

- a benchmark's own JSON (``--json PATH`` of the benchmarks in ``benchmarks/``): its measured
  values and a ``provenance`` block (:func:`machine_provenance`, written by the benchmark);
- a record of ``record-bench``: what the benchmark printed, with its provenance, and with
  ``--data FILE`` the JSON the benchmark wrote as well;
- ``--bench-output FILE COMMAND``: a benchmark's JSON or printed text that carries no
  provenance, with the command that made it. The page then records this machine and this
  checkout's commit at the time the page is made, and says so (``provenance_added``).

Each source is copied beside the page (``docs/results/NAME.json``, with its provenance; NAME is
the benchmark script's, or the name its output carries for a mode that stands beside the
default run, such as ``bench_coders_cost_only``), so the page cites files that stay with it,
and the page is a pure function of those files: running the command again on them gives the
same page. The page's folder is an output folder like a run's (``outputs.output_folder``), shared
with the documentation's other pages: its manifest, kept under version control beside the page,
names the page and ``results/`` by their content, so the command rewrites them on any checkout
and nothing else; a page or source edited by hand is refused, never overwritten.

Every number on the page is a link to its run's source block (command, commit, machine) whose
title is the JSON Pointer (RFC 6901) of the value in the cited file, for example
``[0.8519](#run-gating_threshold "/f1/gated/mean")``; :func:`check_page` reads each one back
from its file and fails on any that differs. A benchmark's values are shown the same way
(tables of linked numbers); printed output without values is shown as it was printed, and
:func:`check_page` compares it with the record character by character.
"""

from __future__ import annotations

import json
import os
import platform
import re
import stat
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from ..core.bounds import out_path
from ..core.commands import LIST, POSITIONALS, SWITCH, Command, Option
from ..core.errors import SpecError
from ..core.files import atomic_write, walk
from ..core.outputs import output_folder
from ..core.provenance import code_identity, file_digest
from . import guides
from .regenerate import regenerate
from .labels import readout_label

#: the study summaries' own lists of what was calibrated and what is predicted
ROW_LISTS = ("calibrated", "predicted")

#: further values a study's summary holds that the page shows as tables, per study:
#: (title, pointer of a mapping whose entries are the table's rows, columns)
EXTRA_TABLES: dict[str, list[tuple[str, str, tuple[str, ...]]]] = {
    "baseline_comparison": [
        (
            "8-material accuracy per read-out (the bench table and the spiking read-outs)",
            "/material_accuracy",
            ("mean", "sd", "n_seeds"),
        ),
        ("Distance rmse per read-out (mm)", "/distance_rmse_mm", ("mean", "sd", "n_seeds")),
        (
            "Spiking read-outs against the full-spectrum MLP on the same splits",
            "/spiking/against_fft",
            ("neurons", "accuracy", "fraction_interval"),
        ),
        (
            "The tuned bank by size, first split (accuracy, cost per contact in µs)",
            "/spiking/tuned/curve",
            ("n", "channels", "spiking", "nmf", "fft_mlp", "wall_us_per_event"),
        ),
    ],
    "speed_accuracy": [
        (
            "Recommended settings (each criterion and scene)",
            "/recommendations",
            (
                "criterion",
                "scene",
                "method",
                "dt_ms",
                "target",
                "dtype",
                "cpu_s",
                "rate_map_error",
                "spike_time_error_ms",
                "speedup_vs_reference",
            ),
        ),
        (
            "Largest stable and accurate k·dt per method (stability map)",
            "/stability_limits",
            ("shipped_max_stable_k_dt", "measured_max_stable_k_dt", "measured_max_accurate_k_dt"),
        ),
        (
            "float32 against float64 on a tuning grid (the precision stage)",
            "/precision/rows",
            (
                "dtype",
                "engine",
                "n_points",
                "ns_per_neuron_step",
                "spike_count_error",
                "same_count_share",
                "max_count_diff",
                "within_tolerance",
            ),
        ),
    ],
    "gating_threshold": [
        ("F1 on new scenes, mean over seeds", "/f1", ("mean", "low", "high", "n")),
        (
            "Paired differences of F1 by seed",
            "/differences",
            ("mean", "low", "high", "n", "p_value", "verdict"),
        ),
    ],
}

_LINK = re.compile(r'\[([^\]]*)\]\(#run-([\w.-]+) "([^"]*)"\)')


def fmt(value) -> str:
    """A number as every report shows it (``report.page.fmt``: four significant figures)."""
    from .page import fmt as page_fmt  # numpy and the page only when a page is made

    return page_fmt(value)


# -- JSON Pointer ---------------------------------------------------------------------------


def pointer(*keys) -> str:
    """The JSON Pointer of ``keys`` (``~`` and ``/`` escaped as RFC 6901 says)."""
    return "".join("/" + str(k).replace("~", "~0").replace("/", "~1") for k in keys)


def resolve(document: Any, ptr: str) -> Any:
    """The value at JSON Pointer ``ptr`` in ``document``."""
    value = document
    for token in ptr.split("/")[1:]:
        token = token.replace("~1", "/").replace("~0", "~")
        value = value[int(token)] if isinstance(value, list) else value[token]
    return value


# -- the page -------------------------------------------------------------------------------


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _cell(value: Any, run: str, ptr: str) -> str:
    """A value as the page shows it: each number a link to its source, text as text."""
    if _is_number(value):
        return f'[{fmt(value)}](#run-{run} "{ptr}")'
    if value is None:
        return "–"
    if isinstance(value, dict):
        return ", ".join(
            f"{_text(k)}: {_cell(v, run, ptr + pointer(k))}" for k, v in value.items()
        )
    if isinstance(value, list):
        return ", ".join(_cell(v, run, ptr + pointer(i)) for i, v in enumerate(value))
    if isinstance(value, bool):
        return "yes" if value else "no"
    return _text(value)


def _text(value: Any) -> str:
    """Text inside a Markdown table cell."""
    return str(value).replace("|", "\\|").replace("\n", " ")


def _label(key) -> str:
    """A row's or a column's key as a reader names it (``labels.readout_label``:
    ``coder_square_24_bins`` -> "square coder, 24 resonators: rate in time bins")."""
    return _text(readout_label(key))


def _labels_of(document: Any) -> set[str]:
    """Every key of ``document`` (at any depth) as the page labels it: the text a table's
    row and column names may show."""
    found: set[str] = set()
    todo = [document]
    while todo:
        value = todo.pop()
        if isinstance(value, dict):
            found |= {_label(k).replace("\\|", "|").strip(" ,:;()[]–") for k in value}
            todo += list(value.values())
        elif isinstance(value, list):
            todo += value
    return found


def _table(header: tuple[str, ...], rows: list[list[str]]) -> list[str]:
    return [
        "| " + " | ".join(header) + " |",
        "|" + " --- |" * len(header),
        *("| " + " | ".join(row) + " |" for row in rows),
        "",
    ]


def _row_list(summary: dict, run: str, key: str) -> list[str]:
    rows = []
    for i, row in enumerate(summary.get(key) or []):
        here = pointer(key, i)
        compare = "target" if key == "calibrated" else "paper"
        value = _cell(row.get("value"), run, here + "/value")
        if row.get("interval"):
            value += " (" + _cell(row["interval"], run, here + "/interval") + ")"
        rows.append(
            [
                _text(row.get("quantity", "")),
                value,
                _cell(row.get("n"), run, here + "/n") if row.get("n") is not None else "",
                _cell(row.get(compare), run, here + "/" + compare),
                _text(row.get("unit") or ""),
            ]
        )
    if not rows:
        return []
    title = "Calibrated to" if key == "calibrated" else "Predicted"
    compare = "target" if key == "calibrated" else "paper"
    return [
        f"**{title}**",
        "",
        *_table(("quantity", "value (interval)", "n", compare, "unit"), rows),
    ]


def _extra_tables(summary: dict, run: str, study: str) -> list[str]:
    lines = []
    for title, ptr, columns in EXTRA_TABLES.get(study, []):
        try:
            entries = resolve(summary, ptr)
        except (KeyError, IndexError, ValueError, TypeError):
            continue
        if isinstance(entries, (dict, list)) and entries:
            lines += _rows_table(title, entries, run, ptr, columns)
    return lines


def _source(run: str, file: str, prov: dict, extra: str = "") -> list[str]:
    commit = prov.get("git_commit") or "not a git checkout"
    return [
        f"(run-{run})=",
        "",
        f"- command: `{prov.get('command', '')}`",
        f"- commit: `{commit}` (snn-antenna {prov.get('snn_antenna_version', '?')}, "
        f"code hash `{prov.get('code_sha256', '?')}`)",
        f"- machine: {prov.get('platform', '?')}, Python {prov.get('python', '?')}"
        + (
            f", Brian2 {prov['brian2_version']} ({prov.get('brian2_target')})"
            if prov.get("brian2_version")
            else ""
        )
        + extra,
        f"- made: {prov.get('created', '?')}; source: `{file}`",
        "",
    ]


def study_section(summary: dict, run: str, file: str) -> list[str]:
    """The page's section of one study run."""
    prov = summary.get("provenance", {})
    study = prov.get("spec", {}).get("study", run)
    lines = [f"## {study.replace('_', ' ').capitalize()}", ""]
    if summary.get("quick"):
        lines += [
            "**A check, not a result**: this run is the study's quick profile (`--quick`); "
            "its numbers show that the pipeline works, and its report says what it is too "
            "small for. The full profile's run replaces it here when it is regenerated.",
            "",
        ]
    else:
        lines += [
            f"The study's full profile (`studies/{study}.toml` without `--quick`).",
            "",
        ]
    source = _source(run, file, prov)
    timed = guides.run_time(summary)
    if timed:
        ptr, seconds = timed
        source.insert(
            -1,
            f"- run time: {_cell(seconds, run, ptr)} s of wall time, measured by the run "
            f"({guides.duration(seconds)})",
        )
    lines += source
    for key in ROW_LISTS:
        lines += _row_list(summary, run, key)
    lines += _extra_tables(summary, run, study)
    return lines


#: what a benchmark's record or JSON holds beside its measured values
BENCH_CONTEXT = ("provenance", "command", "stdout", "data", "load_average", "wall_s", "name")

#: a name a benchmark's output may carry: the page's anchor and its stored file's name
_BENCH_NAME = re.compile(r"\w[\w.-]*")

#: the parts of a statistic's mapping (``report.stats``) one table cell shows
_INTERVAL = ("mean", "low", "high")


def _interval_cell(stat: dict, run: str, ptr: str) -> str:
    """A statistic as one cell: mean (low–high), and its verdict when it does not resolve."""
    mean, low, high = (_cell(stat[k], run, ptr + pointer(k)) for k in _INTERVAL)
    text = f"{mean} ({low}–{high})"
    if stat.get("resolved") is False and isinstance(stat.get("verdict"), str):
        text += f", {_text(stat['verdict'])}"
    return text


def _value_cell(value: Any, run: str, ptr: str) -> str:
    if isinstance(value, dict) and all(k in value for k in _INTERVAL):
        return _interval_cell(value, run, ptr)
    return _cell(value, run, ptr)


#: a table wider than this many columns is shown turned (one column per row) when it has
#: at most as many rows as :data:`TURN_ROWS`, so it fits the page
TURN_COLUMNS, TURN_ROWS = 6, 3


def _rows_table(
    title: str, rows: dict | list, run: str, ptr: str, columns: tuple[str, ...] = ()
) -> list[str]:
    """A table of a list of mappings (one row each) or a mapping of mappings (row names), of
    the given columns (by default every key a row has). Columns that hold one number in every
    row are stated once above the table; a wide table of few rows is turned."""
    named = isinstance(rows, dict)
    items = [
        (k, v) for k, v in (rows.items() if named else enumerate(rows)) if isinstance(v, dict)
    ]
    if not columns:
        columns = []
        for _, row in items:
            columns += [k for k in row if k not in columns]
    lines = [f"**{_text(title)}**", ""]
    first, row0 = items[0] if items else (None, {})
    shared = [
        c
        for c in columns
        if len(items) > 2
        and _is_number(row0.get(c))  # a number, linked and so checked
        and all(c in row and row[c] == row0[c] for _, row in items)
    ]
    if shared:
        lines += [
            "In every row: "
            + ", ".join(
                f"{_text(c)} {_value_cell(row0[c], run, ptr + pointer(first, c))}" for c in shared
            ),
            "",
        ]
    columns = [c for c in columns if c not in shared]
    cells = {
        (name, c): _value_cell(row[c], run, ptr + pointer(name, c)) if c in row else ""
        for name, row in items
        for c in columns
    }
    if named and len(columns) > TURN_COLUMNS and len(items) <= TURN_ROWS:
        header = ("", *(_label(name) for name, _ in items))
        body = [[_label(c)] + [cells[name, c] for name, _ in items] for c in columns]
    else:
        header = (("",) if named else ()) + tuple(_label(c) for c in columns)
        body = [
            ([_label(name)] if named else []) + [cells[name, c] for c in columns]
            for name, _ in items
        ]
    return [*lines, *_table(header, body)]


def bench_values(values: dict, run: str, root: str = "") -> list[str]:
    """A benchmark's measured values as tables, every number linked to its source."""
    lines, single = [], []
    for key, value in values.items():
        if key in BENCH_CONTEXT or value in ([], {}, None):
            continue
        ptr = root + pointer(key)
        title = key.replace("_", " ")
        if value and isinstance(value, list) and all(isinstance(v, dict) for v in value):
            lines += _rows_table(title, value, run, ptr)
        elif (
            value
            and isinstance(value, dict)
            and all(isinstance(v, dict) for v in value.values())
            and not all(k in value for k in _INTERVAL)
        ):
            lines += _rows_table(title, value, run, ptr)
        else:
            single.append([_label(key), _value_cell(value, run, ptr)])
    if single:
        lines = [*_table(("", "value"), single), *lines]
    return lines


def bench_section(record: dict, run: str, file: str) -> list[str]:
    """The page's section of one benchmark: its values as tables, or its output as printed."""
    prov = record["provenance"]
    load = record.get("load_average") or prov.get("load_average")
    extra = f"; load average {load[0]:.2f} (1 min)" if load else ""
    if prov.get("provenance_added"):
        extra += f" ({_text(prov['provenance_added'])})"
    lines = [f"### `{run}`", ""]
    if isinstance(prov.get("script_summary"), str):     # what the script says it measures
        lines += [_text(prov["script_summary"]), ""]
    lines += _source(run, file, prov, extra)
    if isinstance(record.get("data"), dict):
        lines += bench_values(record["data"], run, "/data")
    elif "stdout" in record:
        lines += ["```text", record["stdout"].rstrip("\n"), "```", ""]
    else:
        lines += bench_values(record, run)
    return lines


def render(summaries: list[Path], benches: list[Path], command: str) -> str:
    """The whole page from its sources."""
    lines = [
        "# Results",
        "",
        "Every number on this page comes from a run's `summary.json` or a benchmark's "
        "recorded output, stored beside this page in `docs/results/`; nothing is typed by "
        "hand. Each number links to the command, commit and machine that made it. "
        "Benchmarks ran on a shared machine: read their ratios, measured side by side in "
        "one run, rather than their times.",
        "",
        "Each study's section is the run of its full profile, unless its first line says "
        "it is a quick check: a quick profile's numbers show that the pipeline works and "
        "are not results.",
        "",
        "Regenerate this page from the sources stored beside it (see "
        "`snn_antenna.report.results`):",
        "",
        "```bash",
        command,
        "```",
        "",
        "Run every study's full profile and every benchmark again, reusing each stored run "
        "and benchmark whose code hash is this checkout's, then write this page, its "
        "sources, the guides' figures and run times (see `snn_antenna.report.regenerate`; "
        "`--plan` prints what it would run):",
        "",
        "```bash",
        REGENERATE,
        "```",
        "",
    ]
    for path in summaries:
        summary = json.loads(path.read_text())
        lines += study_section(summary, path.stem, _shown(path))
    if benches:
        lines += ["## Benchmarks", ""]
        for path in benches:
            record = json.loads(path.read_text())
            lines += bench_section(record, path.stem, _shown(path))
    return "\n".join(lines).rstrip("\n") + "\n"


def check_page(page: Path, sources: Path) -> list[str]:
    """Every linked number of ``page`` read back from its file in ``sources``; the mismatches
    (an empty list when every number is its source's)."""
    problems = []
    text = page.read_text()
    links = _LINK.findall(text)
    if not links:
        problems.append(f"{page}: no number links to a source")
    cache: dict[str, Any] = {}
    for shown, run, ptr in links:
        file = sources / f"{run}.json"
        if run not in cache:
            cache[run] = json.loads(file.read_text()) if file.is_file() else None
        if cache[run] is None:
            problems.append(f"{shown!r} cites {file}, which does not exist")
            continue
        try:
            value = resolve(cache[run], ptr)
        except (KeyError, IndexError, ValueError, TypeError):
            problems.append(f"{shown!r} cites {ptr} in {file}, which it does not hold")
            continue
        if not _is_number(value) or fmt(value) != shown:
            problems.append(f"{shown!r} cites {ptr} in {file}, which holds {value!r}")
    run, printed = None, None
    labels: dict[str, set[str]] = {}        # a source's keys as the page labels them
    for line in text.splitlines():  # text in the tables and printed output: the cited file's
        label = re.fullmatch(r"\(run-([\w.-]+)\)=", line)
        if label:
            run = label.group(1)
            if run not in cache:
                file = sources / f"{run}.json"
                cache[run] = json.loads(file.read_text()) if file.is_file() else None
            continue
        if run is not None and line == "```text":
            printed = []
            continue
        if printed is not None:
            if line != "```":
                printed.append(line)
                continue
            stdout = (cache.get(run) or {}).get("stdout", "").rstrip("\n")
            if "\n".join(printed) != stdout:
                problems.append(f"the printed output of run {run} is not its record's stdout")
            printed = None
            continue
        if run is None or not line.startswith("| ") or set(line) <= set("|- "):
            continue
        source = json.dumps(cache.get(run), ensure_ascii=False)
        if run not in labels:
            labels[run] = _labels_of(cache.get(run))
        for cell in line.strip("|").split(" | "):
            for chunk in _LINK.split(cell)[::4]:
                # a label of the source, or a list of them ("I = 0.1: –, I = 0.15: ")
                if not _cited(chunk, source, labels[run]) and not all(
                        _cited(item, source, labels[run]) for item in re.split(r",\s+", chunk)):
                    words = chunk.replace("\\|", "|").strip(" ,:;()[]–")
                    problems.append(f"{words!r} (run {run}) is not in the file it cites")
    return problems


def _cited(text: str, source: str, labels) -> bool:
    """Whether text between a table's links types no number its cited source lacks."""
    words = text.replace("\\|", "|").strip(" ,:;()[]–")
    return (not re.search(r"\d", words)
            or json.dumps(words, ensure_ascii=False)[1:-1] in source or words in labels)


# -- the command ----------------------------------------------------------------------------


def _summary_of(path: Path) -> Path:
    file = path / "summary.json" if path.is_dir() else path
    if not file.is_file():
        raise SpecError(
            "results",
            str(path),
            "a run's output folder holding summary.json, or a summary.json file",
        )
    return file


def read_runs(runs: list[Path], store: Path) -> list[tuple[Path, Path, dict]]:
    """Each run's summary file, its summary and where the page cites it (``store/STUDY.json``,
    one run per study), read and checked before anything is written."""
    cited: dict[str, tuple[Path, Path, dict]] = {}
    for run in runs:
        file = _summary_of(run)
        summary = json.loads(file.read_text())
        study = summary.get("provenance", {}).get("spec", {}).get("study")
        if not study:
            raise SpecError("results", str(run), "a study's summary.json (with its provenance)")
        if study in cited:
            raise SpecError(
                "results", str(run), f"one run per study ({study} is also {cited[study][1]})"
            )
        cited[study] = (store / f"{study}.json", file, summary)
    return list(cited.values())


def _script_identity(script: Path) -> dict:
    """A benchmark script's digest and what it measures (its docstring's first paragraph,
    the line its section on the page opens with)."""
    import ast

    found = {"script_sha256": file_digest(script)}
    try:
        doc = ast.get_docstring(ast.parse(script.read_text()))
    except (SyntaxError, UnicodeDecodeError):
        doc = None
    if doc:
        found["script_summary"] = " ".join(doc.split("\n\n")[0].split())
    return found


def machine_provenance(command: str | None = None, **extra) -> dict:
    """What a benchmark's output records about how it was made: the command (this process's
    own by default), the code (``code_identity``: version, source hash, commit; and of the
    script the command runs, its digest and first paragraph: ``_script_identity``), the
    machine, its load and the time. A benchmark writing JSON puts it under ``"provenance"``."""
    import datetime as _dt

    if command is None:
        command = " ".join(["python", *sys.argv])
    scripts = [w for w in command.split() if w.endswith(".py") and Path(w).is_file()]
    return {
        **code_identity(),
        **(_script_identity(Path(scripts[0])) if scripts else {}),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpus": os.cpu_count(),
        "load_average": list(os.getloadavg()),
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "command": command,
        **extra,
    }


def write_benchmark_json(path: str | Path, values: dict, name: str | None = None) -> Path:
    """A benchmark's ``--json PATH``: its measured values with their provenance. ``name``: the
    results page's section for a mode whose output stands beside the script's default run
    (``bench_coders_cost_only``); without it the section is the script's (:func:`_bench_name`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    record = {**values, **({"name": name} if name else {}), "provenance": machine_provenance()}
    atomic_write(path, json.dumps(record, indent=1, default=float) + "\n")
    return path


def record_benchmark(out: Path, command: list[str], data: Path | None = None) -> dict:
    """Run a benchmark and keep what it printed with its provenance in ``out`` (JSON), and
    with ``data`` the JSON the benchmark wrote there."""
    started = time.perf_counter()
    prov = machine_provenance(" ".join(command))
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SpecError(
            "record-bench",
            " ".join(command),
            f"a benchmark that ends well (it exited {done.returncode}: "
            f"{done.stderr.strip().splitlines()[-1:] or ''})",
        )
    record = {
        "command": " ".join(command),
        "stdout": done.stdout,
        "wall_s": time.perf_counter() - started,
        "load_average": prov["load_average"],
        "provenance": prov,
    }
    if data is not None:
        record["data"] = json.loads(data.read_text())
        if isinstance(record["data"], dict) and "name" in record["data"]:
            record["name"] = record["data"]["name"]  # the section the data names
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, json.dumps(record, indent=1, default=float) + "\n")
    return record


def _bench_record(path: Path) -> dict:
    """A benchmark's output that carries its provenance (with the command)."""
    try:
        record = json.loads(path.read_text()) if path.is_file() else None
    except (json.JSONDecodeError, UnicodeDecodeError):
        record = None
    if not isinstance(record, dict) or "command" not in record.get("provenance", {}):
        raise SpecError(
            "--bench",
            str(path),
            "a benchmark's JSON with its provenance (--json of benchmarks/, or record-bench); "
            "for output without it: --bench-output FILE COMMAND",
        )
    return record


def adopt_output(path: Path, command: str) -> dict:
    """A benchmark's JSON or printed text without provenance, given the command that made it:
    the record, with this machine and this checkout as its provenance, marked as added."""
    import datetime as _dt

    if not path.is_file():
        raise SpecError("--bench-output", str(path), "a benchmark's JSON or printed output")
    text = path.read_text()
    try:
        values = json.loads(text)
    except json.JSONDecodeError:
        values = None
    made = _dt.datetime.fromtimestamp(path.stat().st_mtime, _dt.UTC)
    prov = machine_provenance(
        command,
        created=made.isoformat(timespec="seconds"),
        provenance_added="commit and machine recorded when the results page was made",
    )
    prov.pop("load_average")
    if isinstance(values, dict):
        if "provenance" in values:
            raise SpecError("--bench-output", str(path), "output without provenance (use --bench)")
        return {**values, "provenance": prov}
    return {"command": command, "stdout": text, "provenance": prov}


def _bench_name(path: Path, record: dict) -> str:
    """The name a benchmark's output is stored and cited under: the name it carries (a mode
    of a script beside its default run: ``bench_coders_cost_only``), else its script's
    (``benchmarks/NAME.py`` in its command), so the page's sections keep their anchors
    whatever the output file was called."""
    if "name" in record:
        name = record["name"]
        if not (isinstance(name, str) and _BENCH_NAME.fullmatch(name)):
            raise SpecError(
                "--bench",
                f"{path} (name {name!r})",
                "a benchmark's output named by letters, digits, '_', '.' and '-' "
                "(its section's anchor and file name)",
            )
        return name
    found = re.search(r"benchmarks/(\w+)\.py", record["provenance"]["command"])
    return found.group(1) if found else path.stem


def _shown(path: Path) -> str:
    """``path`` as the page names it: relative to the folder the command runs in (the
    repository), so the page reads the same on every checkout."""
    return Path(os.path.relpath(path.resolve())).as_posix()


def _not_written_here(store: Path, known: set[Path]) -> list[str]:
    """The files below ``store`` that the results command does not write there: not one of
    ``known`` (this page's sources and guide fragments), nor a figure a guide shows
    (``figures/STUDY/NAME.png`` of ``guides.GUIDE_FIGURES``)."""
    found = []
    for rel, st in walk(store):
        parts = Path(rel).parts
        figure = (len(parts) == 3 and parts[0] == guides.FIGURES and parts[2].endswith(".png")
                  and parts[2].removesuffix(".png") in guides.GUIDE_FIGURES.get(parts[1], {}))
        if not (stat.S_ISDIR(st.st_mode) or figure or store / rel in known):
            found.append(rel)
    return sorted(found)


#: the one command that runs every study's full profile and every benchmark again (or reuses
#: what matches this checkout's code) and writes the page (``report.regenerate``)
REGENERATE = "snn-antenna results --regenerate"

#: the results page's output folder is the page's own: the documentation, which it shares
#: with the pages beside it (``outputs.output_folder``, ``shared``)
STUDY = "results"


def make_page(
    runs: list[Path],
    benches: list[Path],
    out: Path,
    outputs: list[tuple[Path, str]] = (),
) -> Path:
    """Copy the runs' summaries and the benchmarks' outputs beside ``out`` (into
    ``results/``), write the page from those copies, and check every number on it. The
    page's folder is an output folder shared with the user's files: every source is read
    and every name decided before it is claimed, and only ``out`` and ``results/`` are
    written there, each new or the toolkit's by the folder's manifest."""
    out = Path(out)
    store = out.parent / "results"
    summaries = read_runs(runs, store)
    records = [(bench, _bench_record(bench)) for bench in benches]
    records += [(path, adopt_output(path, command)) for path, command in outputs]
    stored: list[tuple[Path, Path, dict]] = []
    for path, record in records:
        target = store / f"{_bench_name(path, record)}.json"
        if any(target == other for other, _, _ in stored):
            raise SpecError("--bench", str(path), f"one output per benchmark ({target.stem})")
        stored.append((target, path, record))
    runs_figures = {  # a run's folder gives its figures; a stored source keeps those stored
        target.stem: guides.run_figures(target.stem, summary, file.parent)
        if file.resolve() != target.resolve()
        else guides.stored_figures(target.stem, summary, store)
        for target, file, summary in summaries
    }
    fragments = guides.fragments(
        store, [(t.stem, summary, runs_figures[t.stem]) for t, _, summary in summaries]
    )
    pending = {path: text for path, text in fragments.items()
               if not path.is_file() or path.read_text() != text}
    known = {t for t, _, _ in summaries + stored} | set(fragments)
    with output_folder(out.parent, STUDY, shared=True) as folder:
        # the page is made from results/, so it is checked even when nothing is copied in
        if store.name in folder.changed or (os.path.lexists(store) and
                                            store.name not in folder.listed):
            foreign = _not_written_here(store, known)
            if foreign:
                raise SpecError(
                    "results", _shown(store / foreign[0]),
                    "a file the results command writes in results/ (the folder is its own, "
                    "listed by content in the manifest beside it; this file is not one it "
                    "writes): move it out of results/ (in docs/ itself your files are left "
                    "alone)")
        folder.check_writes([out.name, store.name])
        folder.claim()
        for target, file, summary in summaries:
            if file.resolve() != target.resolve():
                atomic_write(target, json.dumps(summary, indent=1, sort_keys=False) + "\n")
        for target, path, record in stored:
            if path.resolve() != target.resolve():
                atomic_write(target, json.dumps(record, indent=1, default=float) + "\n")
        for target, file, _ in summaries:
            if file.resolve() != target.resolve():
                guides.copy_figures(target.stem, runs_figures[target.stem], file.parent, store)
        for path, text in pending.items():
            atomic_write(path, text)
        cited = [target for target, _, _ in summaries]
        command = " ".join(
            [
                "snn-antenna results",
                *map(_shown, cited),
                *(f"--bench {_shown(target)}" for target, _, _ in stored),
                f"--out {_shown(out)}",
            ]
        )
        atomic_write(out, render(cited, [target for target, _, _ in stored], command))
    problems = check_page(out, store)
    if problems:
        raise RuntimeError("the results page does not match its sources: " + problems[0])
    return out


def _results(options) -> int:
    if options.regenerate:
        if options.runs or options.bench or options.bench_output:
            raise SpecError("--regenerate", " ".join(options.runs + options.bench) or
                            "--bench-output", "no runs or benchmarks of your own: it runs or "
                            "reuses every study and benchmark itself")
        out = regenerate(Path(options.out), Path(options.runs_dir), make_page,
                         record_benchmark, options.quick_check, set(options.keep), options.plan)
        if out is not None:
            print(f"{out}: written from every study and benchmark")
        return 0
    if options.keep or options.quick_check or options.plan:
        raise SpecError("--keep/--quick-check/--plan", "given", "only with --regenerate")
    outputs = [(Path(f), c) for f, c in options.bench_output]
    out = make_page(
        [Path(p) for p in options.runs], [Path(p) for p in options.bench], Path(options.out),
        outputs
    )
    print(
        f"{out}: written from {len(options.runs)} run(s) and "
        f"{len(options.bench) + len(outputs)} benchmark(s)"
    )
    return 0


COMMANDS = (
    Command(
        "results",
        "write the results page from runs' summary.json and recorded benchmarks",
        _results,
        (
            Option(
                "runs",
                "output folders of study runs (or summary.json files), one per study",
                kind=POSITIONALS,
            ),
            Option(
                "bench",
                "a benchmark's output with its provenance: the JSON of a benchmark's --json, "
                "or a record (python -m snn_antenna.report.results record-bench FILE.json -- "
                "COMMAND)",
                kind=LIST,
                metavar="FILE.json",
            ),
            Option(
                "bench_output",
                "a benchmark's JSON or printed output that carries no provenance, and the "
                "command that made it (the page records this machine and checkout, and says so)",
                kind=LIST,
                nargs=2,
                metavar=("FILE", "COMMAND"),
            ),
            Option(
                "regenerate",
                "run every study's full profile and every benchmark of benchmarks/ (its page "
                "command, regenerate.PAGE_BENCHMARKS) again, reusing each whose code hash is "
                "this checkout's, then write the page (run from the repository's checkout)",
                kind=SWITCH,
            ),
            Option(
                "runs_dir",
                "with --regenerate: where the study runs and benchmark outputs are made and "
                "found (default out/results-runs)",
                check=out_path,
                text=True,
                default="out/results-runs",
                metavar="DIR",
            ),
            Option(
                "keep",
                "with --regenerate: keep this stored study or benchmark as it is, whatever "
                "code made it (its section names its own commit)",
                kind=LIST,
                metavar="NAME",
            ),
            Option("quick_check", "with --regenerate: the studies' quick profiles, a check of "
                                  "the whole chain (the page marks each as a check)",
                   kind=SWITCH),
            Option("plan", "with --regenerate: print what would be reused and run, and stop",
                   kind=SWITCH),
            Option(
                "out",
                "the page (default docs/results.md)",
                check=out_path,
                text=True,
                default="docs/results.md",
            ),
        ),
    ),
)


def main(argv: list[str] | None = None) -> int:
    """``python -m snn_antenna.report.results record-bench OUT.json [--data FILE] -- COMMAND``"""
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) >= 3 and argv[0] == "record-bench" and "--" in argv:
        split = argv.index("--")
        options = argv[2:split]
        data = None
        if options[:1] == ["--data"] and len(options) == 2:
            data = Path(options[1])
        elif options:
            print(f"record-bench: unknown options {options}", file=sys.stderr)
            return 2
        record = record_benchmark(Path(argv[1]), argv[split + 1 :], data)
        print(record["stdout"], end="")
        return 0
    print(
        "usage: python -m snn_antenna.report.results record-bench OUT.json [--data FILE] "
        "-- COMMAND ...",
        file=sys.stderr,
    )
    return 2


if __name__ == "__main__":
    sys.exit(main())
