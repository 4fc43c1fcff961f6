"""The results page is what its command makes from the summaries it cites, and every number on
it is the number its source holds."""

import json
import re
import shlex
import shutil
from pathlib import Path

from snn_antenna.cli import main
from snn_antenna.report import results

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "results.md"
SOURCES = ROOT / "docs" / "results"


def test_every_number_on_the_page_is_in_the_summary_it_cites():
    assert results.check_page(PAGE, SOURCES) == []
    links = results._LINK.findall(PAGE.read_text())
    studies = {run for _, run, _ in links}
    assert {"quickstart", "gating_threshold"} <= studies


def test_text_typed_into_a_table_is_caught(tmp_path):
    page, store = tmp_path / "results.md", tmp_path / "results"
    shutil.copytree(SOURCES, store)
    text = PAGE.read_text()
    row = next(line for line in text.splitlines() if line.startswith("| ") and "#run-" in line)
    page.write_text(text.replace(row, row.replace(" | ", " | measured 3.5 ms | ", 1), 1))
    problems = results.check_page(page, store)
    assert any("measured 3.5 ms" in p for p in problems)


def test_the_page_is_regenerated_by_its_own_command(tmp_path, monkeypatch):
    text = PAGE.read_text()
    command = re.search(r"```bash\n(snn-antenna results .*?)\n```", text).group(1)
    (tmp_path / "docs").mkdir()
    shutil.copytree(SOURCES, tmp_path / "docs" / "results")
    monkeypatch.chdir(tmp_path)
    assert main(shlex.split(command)[1:]) == 0
    assert (tmp_path / "docs" / "results.md").read_text() == text


def test_a_changed_source_or_a_changed_number_is_caught(tmp_path):
    page, store = tmp_path / "results.md", tmp_path / "results"
    shutil.copytree(SOURCES, store)
    page.write_text(PAGE.read_text())
    shown, run, ptr = results._LINK.findall(page.read_text())[0]
    summary = json.loads((store / f"{run}.json").read_text())
    value = results.resolve(summary, ptr)
    parent = results.resolve(summary, ptr.rsplit("/", 1)[0] or "")
    key = ptr.rsplit("/", 1)[1]
    parent[int(key) if isinstance(parent, list) else key] = value * 2 + 1
    (store / f"{run}.json").write_text(json.dumps(summary))
    assert results.check_page(page, store)  # the source moved
    shutil.copy(SOURCES / f"{run}.json", store / f"{run}.json")
    assert results.check_page(page, store) == []
    page.write_text(
        page.read_text().replace(
            f'[{shown}](#run-{run} "{ptr}")', f'[{shown}1](#run-{run} "{ptr}")', 1
        )
    )
    assert results.check_page(page, store)  # the page moved


def test_json_pointers_escape_what_they_must():
    doc = {"a/b": {"~c": [10, 20]}}
    ptr = results.pointer("a/b", "~c", 1)
    assert ptr == "/a~1b/~0c/1" and results.resolve(doc, ptr) == 20


def test_a_run_without_a_summary_is_refused_in_one_line(tmp_path, capsys):
    assert main(["results", str(tmp_path), "--out", str(tmp_path / "page.md")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "summary.json" in err
    assert not (tmp_path / "page.md").exists()
