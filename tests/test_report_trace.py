"""A report mailed without its folder can be traced: its header names the command, commit, code
hash, machine and date; its footer promises only what its tables show; and every repository
path that a report or a documentation page cites exists."""
from __future__ import annotations

import json
import re
from html.parser import HTMLParser
from pathlib import Path

from snn_antenna.core.provenance import code_hash, machine
from snn_antenna.report.page import Calibrated, Predicted, Report, shown_command

ROOT = Path(__file__).resolve().parents[1]


class _Page(HTMLParser):
    """The header's terms and definitions, and each table's header cells with their keys."""

    def __init__(self):
        super().__init__()
        self.identity: dict[str, str] = {}
        self.tables: list[list[tuple[str, str]]] = []    # (column name, key shown) per table
        self._in, self._term, self._text, self._key = None, "", "", ""

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "dl" and attrs.get("class") == "run-identity":
            self._in = "dl"
        elif tag in ("dt", "dd") and self._in == "dl":
            self._text = ""
        elif tag == "table":
            self.tables.append([])
        elif tag == "th":
            self._in, self._text, self._key = "th", "", ""
        elif tag == "span" and attrs.get("class") == "key" and self._in == "th":
            self._in = "key"

    def handle_endtag(self, tag):
        if tag == "dt" and self._in == "dl":
            self._term = self._text.strip()
        elif tag == "dd" and self._in == "dl":
            self.identity[self._term] = self._text.strip()
        elif tag == "dl" and self._in == "dl":
            self._in = None
        elif tag == "span" and self._in == "key":
            self._in = "th"
        elif tag == "th" and self._in == "th":
            self.tables[-1].append((self._text.strip(), self._key.strip()))
            self._in = None

    def handle_data(self, data):
        if self._in == "key":
            self._key += data
        else:
            self._text += data


def _report(tmp_path, monkeypatch) -> tuple[_Page, dict, str]:
    monkeypatch.setattr("sys.argv", ["/home/someone/.venv/bin/snn-antenna", "run",
                                     "studies/quickstart.toml", "--out", "out/q"])
    rep = Report(tmp_path, "a study")
    rep.calibrated(Calibrated("hertz per unit k", 20.6, 20.44, "Hz", "docs/reference.md",
                              "neurons.k_for_frequency"))
    rep.predicted(Predicted("contacts detected", 3, "", paper=None, source="this run",
                            interval=(2.0, 4.0), n=5, note="none missed"))
    rep.table([{"distance_cm": 19.0, "onset_s": 5.5, "material": "wood"}])
    summary = rep.write({"x": 1.0}, {"seed": 3})
    text = (tmp_path / "report.html").read_text()
    page = _Page()
    page.feed(text)
    return page, summary, text


def test_the_header_names_command_commit_code_hash_machine_and_date(tmp_path, monkeypatch):
    page, summary, _ = _report(tmp_path, monkeypatch)
    prov = summary["provenance"]
    head = page.identity
    assert list(head) == ["command", "commit", "code hash", "machine", "date"]
    assert head["command"] == "snn-antenna run studies/quickstart.toml --out out/q"
    assert head["commit"] == (prov["git_commit"] or head["commit"]) and head["commit"]
    assert head["code hash"].startswith(code_hash()) and prov["code_sha256"] == code_hash()
    assert head["machine"] == machine() == prov["machine"]
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", head["date"]), head["date"]
    assert head["date"].startswith(prov["created"][:10])
    assert "cores" in machine()


def test_the_command_is_shown_as_typed():
    assert shown_command("/x/.venv/bin/snn-antenna run a.toml") == "snn-antenna run a.toml"
    assert shown_command("/x/snn_antenna/__main__.py run a.toml") == \
        "python -m snn_antenna run a.toml"
    assert shown_command("") == ""


def test_the_calibrated_and_predicted_columns_show_the_fields_they_come_from(tmp_path,
                                                                           monkeypatch):
    """The footer promises each number of these tables under the field shown below its
    column's name: every column shows one, and it is a field of the summary's rows."""
    page, summary, text = _report(tmp_path, monkeypatch)
    assert "each number under the field shown below its" in text
    calibrated, predicted = page.tables[0], page.tables[1]
    for table, rows in ((calibrated, summary["calibrated"]), (predicted, summary["predicted"])):
        for name, key in table:
            field = key or name
            assert field in rows[0], f"column {name!r} shows {field!r}, not a field"
    assert ("model", "value") in calibrated and ("tuned by", "how") in calibrated
    assert ("95 % interval", "interval") in predicted
    assert ("distance (cm)", "distance_cm") in page.tables[2]    # a study's table: its keys


# -- cited paths ------------------------------------------------------------------------------
# A path that starts at one of the repository's top folders, as reports and pages cite them
# (``snn_antenna/networks/neurons.py``, ``studies/quickstart.toml``, ``docs/reference.md``).
_TOP = r"(?:snn_antenna|networks|stimuli|studies|tests|benchmarks|firmware|docs|\.ci)"
_CITED = re.compile(r"(?<![\w./-])(" + _TOP + r"/[A-Za-z0-9_./*-]*[A-Za-z0-9_/*])")
# what the build or a run writes, never in a checkout
_WRITTEN = ("docs/_build", "docs/api/generated", "docs/gallery")


def cited_paths(text: str) -> set[str]:
    """Repository paths cited in ``text``, leaving out placeholders (``networks/NAME.toml``)."""
    found = set()
    for match in _CITED.finditer(text):
        path = match.group(1).rstrip(".")
        if re.search(r"/[A-Z][A-Z_]*(\.|/|$)", path):
            continue
        found.add(path)
    return found


def missing(path: str) -> bool:
    """Neither the path nor, for a study's or a spec's name, its ``.toml``/``.py`` exists (a
    pattern, ``docs/examples/plot_*.py``: matches nothing)."""
    if path.startswith(_WRITTEN):
        return False
    if "*" in path:
        return next(ROOT.glob(path), None) is None
    return not any((ROOT / (path + suffix)).exists() for suffix in ("", ".toml", ".py"))


def _cited_by_the_project() -> dict[str, set[str]]:
    sources = [*(ROOT / "snn_antenna").rglob("*.py"), *(ROOT / "docs").rglob("*.md"),
               *(ROOT / "docs" / "examples").glob("*.py"), ROOT / "README.md",
               *(ROOT / "benchmarks").glob("*.py"),
               *(p for folder in ("studies", "networks", "stimuli")
                 for p in (ROOT / folder).glob("*.toml"))]
    cited: dict[str, set[str]] = {}
    for source in sources:
        if any(part in ("_build", "generated", "gallery") for part in source.parts):
            continue
        for path in cited_paths(source.read_text(encoding="utf-8")):
            cited.setdefault(path, set()).add(str(source.relative_to(ROOT)))
    return cited


def test_every_path_a_report_or_page_cites_exists():
    cited = _cited_by_the_project()
    assert "snn_antenna/sources/antenna.py" in cited and "studies/quickstart.toml" in cited
    gone = {path: sorted(where) for path, where in cited.items() if missing(path)}
    assert not gone, f"cited paths that do not exist: {json.dumps(gone, indent=1)}"


def test_the_path_check_catches_a_path_that_does_not_exist():
    text = ("tuned by networks/neurons.py; see snn_antenna/networks/neurons.py, "
            "networks/NAME.toml, studies/speed_accuracy's bands, docs/_build/html, "
            "studies/*.toml and docs/examples/plot_*.c.")
    paths = cited_paths(text)
    assert paths == {"networks/neurons.py", "snn_antenna/networks/neurons.py",
                     "studies/speed_accuracy", "docs/_build/html", "studies/*.toml",
                     "docs/examples/plot_*.c"}
    assert [p for p in sorted(paths) if missing(p)] == ["docs/examples/plot_*.c",
                                                         "networks/neurons.py"]


def test_every_study_writes_its_report_through_the_one_page_that_carries_the_header():
    """The header is written by ``Report.write`` alone: every study's package makes its page
    with ``Report``, and nothing else in the package writes a ``report.html``."""
    from snn_antenna.studies import STUDIES

    package = ROOT / "snn_antenna"
    for study, module in STUDIES.items():
        folder = package.joinpath(*module.split(".")[1:])
        text = "".join(p.read_text() for p in folder.rglob("*.py"))
        assert re.search(r"\bReport\(", text), f"{study} makes no Report"
    writers = [f"{p.relative_to(ROOT)}: {line.strip()}" for p in package.rglob("*.py")
               for line in p.read_text().splitlines()
               if "report.html" in line and re.search(r"write|open\(", line)]
    assert writers == ['snn_antenna/report/page.py: atomic_write(self.out_dir / "report.html", '
                       'page)'], f"report.html written outside report/page.py: {writers}"
