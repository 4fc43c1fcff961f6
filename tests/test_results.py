"""The results page is what its command makes from the summaries it cites, and every number on
it is the number its source holds."""

import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from snn_antenna.cli import main
from snn_antenna.core import files, outputs, provenance
from snn_antenna.core.errors import SpecError
from snn_antenna.report import guides, labels, regenerate, results

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


def test_a_list_of_labels_passes_and_a_number_typed_into_it_is_caught(tmp_path):
    """A row whose values are listed by label ("I = 0.1: –, I = 0.15: [6.65](…)", a value
    missing) cites each label from its source; a number typed among them is still caught."""
    page, store = tmp_path / "results.md", tmp_path / "results"
    shutil.copytree(SOURCES, store)
    text = PAGE.read_text()
    row = next(line for line in text.splitlines() if "I = 0.1: –, I = 0.15:" in line)
    assert results.check_page(PAGE, SOURCES) == []
    page.write_text(text.replace(row, row.replace("I = 0.1: –,", "I = 0.1: –, I = 9.5: –,"), 1))
    assert any("I = 9.5" in p for p in results.check_page(page, store))


def _checkout(tmp_path) -> Path:
    """A copy of the page, its sources and its folder's manifest, as another checkout has
    them (other inodes and times, the same content)."""
    docs = tmp_path / "docs"
    docs.mkdir()
    shutil.copytree(SOURCES, docs / "results")
    shutil.copy(PAGE, docs / "results.md")
    shutil.copy(ROOT / "docs" / outputs.MANIFEST, docs / outputs.MANIFEST)
    return docs


def test_the_page_is_regenerated_by_its_own_command(tmp_path, monkeypatch):
    """On a checkout of its own, through the page folder's manifest: the same page, the
    same manifest."""
    text = PAGE.read_text()
    command = re.search(r"```bash\n(snn-antenna results .*?)\n```", text).group(1)
    docs = _checkout(tmp_path)
    manifest = (docs / outputs.MANIFEST).read_text()
    monkeypatch.chdir(tmp_path)
    assert main(shlex.split(command)[1:]) == 0
    assert (docs / "results.md").read_text() == text
    assert (docs / outputs.MANIFEST).read_text() == manifest


def test_the_kept_manifest_names_the_page_and_its_sources_as_they_are():
    """What the results command wrote is what is kept: a page or source changed by other
    means (an edit, a merge) fails here, and the command would refuse to write over it."""
    manifest = outputs.read_manifest(ROOT / "docs")
    assert manifest is not None and manifest["study"] == results.STUDY
    assert sorted(manifest["files"]) == ["results", "results.md"]
    changed = [name for name, ident in manifest["identity"].items()
               if not files.matches(ROOT / "docs" / name, ident)]
    assert not changed, f"changed since the results command wrote them: {changed}"


def test_a_page_edited_by_hand_is_refused_and_kept_and_so_are_the_users_files(
        tmp_path, monkeypatch, capsys):
    text = PAGE.read_text()
    command = shlex.split(re.search(r"```bash\n(snn-antenna results .*?)\n```", text).group(1))
    docs = _checkout(tmp_path)
    (docs / "notes.md").write_text("mine")
    (docs / "results.md").write_text(text + "an edit\n")
    (tmp_path / "run").mkdir()                          # a newer run: a source to copy in
    summary = json.loads((SOURCES / "quickstart.json").read_text())
    summary["quick"] = not summary.get("quick")
    (tmp_path / "run" / "summary.json").write_text(json.dumps(summary))
    argv = [a.replace("docs/results/quickstart.json", "run") for a in command[1:]]
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "results.md" in err and "changed since" in err
    assert (docs / "results.md").read_text() == text + "an edit\n"
    assert (docs / "results" / "quickstart.json").read_text() == \
        (SOURCES / "quickstart.json").read_text()          # nothing written before the refusal
    (docs / "results.md").write_text(text)             # restored: the toolkit's again
    assert main(argv) == 0
    assert json.loads((docs / "results" / "quickstart.json").read_text()) == summary
    assert (docs / "notes.md").read_text() == "mine"
    names = outputs.read_manifest(docs)["files"]
    assert sorted(names) == ["results", "results.md"]
    # a source edited by hand is refused, even by the command that copies nothing in (the
    # page is made from it), and stays listed as the command wrote it: restored, it is the
    # toolkit's again
    listed = outputs.read_manifest(docs)["identity"]["results"]
    page = (docs / "results.md").read_text()
    source = docs / "results" / "tuning_sweep.json"
    source.write_text(source.read_text() + "\n")
    assert main(command[1:]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "results" in err and "changed since" in err
    assert outputs.read_manifest(docs)["identity"]["results"] == listed
    assert (docs / "results.md").read_text() == page
    source.write_text(source.read_text()[:-1])
    assert files.matches(docs / "results", listed)
    assert main(command[1:]) == 0


def test_a_file_of_the_users_in_the_sources_folder_is_refused_naming_it(tmp_path, monkeypatch,
                                                                        capsys):
    """``results/`` is the command's own folder, listed by its content: a file put there
    makes it one the command cannot vouch for, so even the stored sources' command (which
    copies nothing in) refuses in one line naming the file, and writes nothing; beside it,
    in ``docs/``, the same file is the user's and left alone."""
    text = PAGE.read_text()
    command = shlex.split(re.search(r"```bash\n(snn-antenna results .*?)\n```", text).group(1))
    docs = _checkout(tmp_path)
    manifest = (docs / outputs.MANIFEST).read_text()
    monkeypatch.chdir(tmp_path)
    for foreign in (docs / "results" / "notes.txt",
                    docs / "results" / "figures" / "quickstart" / "mine.png"):
        foreign.write_text("mine")
        assert main(command[1:]) == 2
        err = capsys.readouterr().err.strip()
        shown = foreign.relative_to(tmp_path).as_posix()
        assert len(err.splitlines()) == 1 and repr(shown) in err, err
        assert (docs / outputs.MANIFEST).read_text() == manifest
        assert foreign.read_text() == "mine"
        foreign.rename(docs / foreign.name)                  # moved beside the page: the user's
        assert main(command[1:]) == 0
        assert (docs / foreign.name).read_text() == "mine"
        assert (docs / outputs.MANIFEST).read_text() == manifest
        assert (docs / "results.md").read_text() == text


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


def test_a_benchmark_value_or_printed_line_changed_on_the_page_is_caught(tmp_path):
    page, store = tmp_path / "results.md", tmp_path / "results"
    shutil.copytree(SOURCES, store)
    text = PAGE.read_text()
    benches = [p.stem for p in SOURCES.glob("bench_*.json")]
    assert benches, "the page cites no benchmark"
    shown, run, ptr = next(link for link in results._LINK.findall(text) if link[1] in benches)
    page.write_text(
        text.replace(f'[{shown}](#run-{run} "{ptr}")', f'[{shown}9](#run-{run} "{ptr}")')
    )
    assert any(run in p for p in results.check_page(page, store))
    printed = re.search(r"```text\n(.*?)\n```", text, re.S)
    if printed:  # a benchmark shown as printed: a changed character is caught
        first = printed.group(1).splitlines()[0]
        page.write_text(text.replace(first, first + " 1.0 ms", 1))
        assert any("printed output" in p for p in results.check_page(page, store))


def test_a_benchmark_json_without_provenance_is_refused_in_one_line(tmp_path, capsys):
    bare = tmp_path / "bench.json"
    bare.write_text(json.dumps({"us_per_event": 12.5}))
    out = tmp_path / "docs" / "results.md"
    assert main(["results", "--bench", str(bare), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--bench-output" in err
    # with the command that made it, its provenance is recorded and marked as added
    assert (
        main(
            [
                "results",
                "--bench-output",
                str(bare),
                "python benchmarks/bench_x.py",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    stored = json.loads((out.parent / "results" / "bench_x.json").read_text())
    assert stored["provenance"]["command"] == "python benchmarks/bench_x.py"
    assert "provenance_added" in stored["provenance"]
    assert '[12.5](#run-bench_x "/us_per_event")' in out.read_text()


def test_a_mode_that_names_its_output_is_a_section_beside_the_default_run(tmp_path, capsys):
    """Two outputs of one script are one section too many, unless one carries a name of its
    own (``bench_coders --cost-only``): then each is its own section, stored and cited under
    its name."""
    full, cost, twin = (tmp_path / f"{n}.json" for n in ("full", "cost", "twin"))
    results.write_benchmark_json(full, {"us_per_event": 12.5})
    results.write_benchmark_json(cost, {"us_per_event": 3.25}, name="bench_x_cost_only")
    for path, mode in ((full, ""), (cost, " --cost-only")):
        record = json.loads(path.read_text())
        record["provenance"]["command"] = f"python benchmarks/bench_x.py{mode}"
        path.write_text(json.dumps(record))
    twin.write_text(full.read_text())
    out = tmp_path / "docs" / "results.md"
    assert main(["results", "--bench", str(full), "--bench", str(twin), "--out", str(out)]) == 2
    assert "one output per benchmark (bench_x)" in capsys.readouterr().err
    assert main(["results", "--bench", str(full), "--bench", str(cost), "--out", str(out)]) == 0
    page = out.read_text()
    assert "### `bench_x`" in page and "### `bench_x_cost_only`" in page
    assert '[12.5](#run-bench_x "/us_per_event")' in page
    assert '[3.25](#run-bench_x_cost_only "/us_per_event")' in page
    assert "| name |" not in page  # the section's title, not one of its values
    assert (out.parent / "results" / "bench_x_cost_only.json").is_file()
    assert results.check_page(out, out.parent / "results") == []
    # a name that cannot be an anchor and a file name is refused in one line
    record = json.loads(cost.read_text())
    cost.write_text(json.dumps({**record, "name": "../elsewhere"}))
    assert main(["results", "--bench", str(cost), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'../elsewhere'" in err


# -- no measured number typed into the reference pages ---------------------------------------

#: the pages that explain; their measured numbers live on the results page
EXPLAINING = ["reference.md", "materials.md", "live.md", "index.md", "contributing.md"] + [
    f"guide/{name}.md"
    for name in (
        "quickstart",
        "tuning_sweep",
        "baseline_comparison",
        "model_selection",
        "bank_tuning",
        "gating_threshold",
        "speed_accuracy",
        "exploration",
        "python",
        "cluster",
        "files",
        "own_antenna",
    )
]

#: a number with a unit of time, a ratio or a share: how a measurement reads
MEASURED_LOOKING = re.compile(
    r"(?<![\w.])[~≈]?\s?\d[\d,.]*(?:\s?[–-]\s?\d[\d,.]*)?\s?(?:ms|µs|us|ns|s|×|x|%)(?![\w/])"
)

#: the values these pages may state, per page, and why each is not a measurement
DECLARED: dict[str, list[tuple[set[str], str]]] = {
    "reference.md": [
        (
            {
                "2s",
                "3×",
                "10%",
                "3ms",
                "0.10s",
                "15ms",
                "1%",
                "0.7%",
                "0.4%",
                "87%",
                "94.2%",
                "9.4%",
                "8.4%",
                "86%",
                "8%",
                "95%",
                "1s",
                "5.5s",
            },
            "the paper's numbers (sections 1-4), each with its role: input, calibration target or "
            "reference for predictions; 0.10 s and 15 ms are the assumed decay times' ends",
        ),
        ({"19ms"}, "the linearised resonator's decay, computed from the model's equations"),
        ({"0.1ms"}, "the array's declared time step"),
        ({"95%", "80%"}, "the statistics rules' declared confidence level and power"),
    ],
    "materials.md": [
        (
            {"0.6%", "1%", "2.2%", "94.2%", "86%", "87%"},
            "calibrated constants of the generator and their targets from the paper",
        ),
        (
            {"0.3%", "15%", "3%", "5%", "0.10s", "50%"},
            "assumed scatters, decay times and friction ranges (declared, not fitted)",
        ),
        (
            {"0.16–0.29ms", "2%", "~1%", "5–16%"},
            "computed from the constants table by the formulas beside them",
        ),
        (
            {"0.5ms", "0.5s", "0.005ms", "0.01ms", "20%", "5×"},
            "declared settings: the generator's sample period, the event window, the channels' "
            "time steps, the channel placement's top share, the cost budget",
        ),
    ],
    "live.md": [
        (
            {
                "10s",
                "60s",
                "0.5ms",
                "0.1s",
                "0.005ms",
                "1ms",
                "10ms",
                "50ms",
                "1s",
                "5s",
                "2s",
                "3s",
                "0.5s",
                "1%",
                "30s",
                "8s",
            },
            "declared constants and settings: view spans, time steps, windows, flush periods, "
            "timeouts, tolerances, and the benchmark's and tests' durations",
        ),
    ],
    "guide/quickstart.md": [({"2s"}, "the declared calibration span")],
    "index.md": [({"2s"}, "the quickstart's declared calibration span")],
    "guide/baseline_comparison.md": [
        ({"10%", "95%"}, "the paper's event end rule and the declared confidence level"),
    ],
    "guide/own_antenna.md": [
        (
            {"100ms", "0.1%", "0.1s", "2ms"},
            "declared settings and tolerances: the recorder's flush period, the rate's agreement, "
            "the labels' match window, the firmware test's onset tolerance",
        ),
        (
            {"3s", "3.000000s", "3.000s", "40ms", "1000s"},
            "the clock offsets and lag the guide's examples (and the tests) are written with",
        ),
    ],
    "guide/gating_threshold.md": [
        ({"95%"}, "the declared confidence level"),
        ({"15s"}, "the full profile's declared scene length (studies/gating_threshold.toml)"),
        ({"5×"}, "the paper's ratio of self-motion amplitudes, a calibration target"),
    ],
    "guide/bank_tuning.md": [({"95%"}, "the declared confidence level")],
    "guide/speed_accuracy.md": [
        ({"0.005–1ms", "0.1ms", "0.5ms"}, "the study's declared grid and the shipped settings"),
    ],
}


def _caption_only(block: re.Match) -> str:
    """A fenced block as prose: a figure's or an image's caption (its option lines left
    out), else nothing (commands and code)."""
    text = block.group(0)
    if not re.match(r"```\{(figure|image)\}", text):
        return ""
    return "\n".join(line for line in text.splitlines()[1:-1] if not line.startswith(":"))


def test_the_explaining_pages_type_no_measured_number():
    """Costs, errors and accuracies are measured by a command and shown on the results page,
    linked to their source; an explaining page states only declared values (the paper's
    numbers, calibration targets, assumptions, settings, computed constants)."""
    found = []
    for name in EXPLAINING:
        text = (ROOT / "docs" / name).read_text()
        text = re.sub(r"```.*?```", _caption_only, text, flags=re.S)  # code is not prose
        allowed = set().union(*(values for values, _ in DECLARED.get(name, [])))
        for line in text.splitlines():
            if line.startswith("    "):  # an indented command
                continue
            for match in MEASURED_LOOKING.finditer(line):
                value = re.sub(r"\s", "", match.group(0))
                if value not in allowed:
                    found.append(f"docs/{name}: {value!r} in {line.strip()[:80]!r}")
    assert found == []


def test_the_scan_finds_a_measured_number():
    line = "the tuned bank costs 14.3 ms per contact (7.5x the FFT), 82.0 % correct"
    assert [m.group(0).strip() for m in MEASURED_LOOKING.finditer(line)] == [
        "14.3 ms",
        "7.5x",
        "82.0 %",
    ]


def test_every_section_the_pages_cite_is_on_the_results_page():
    """Pages cite a section of the results page by its label; one the page lacks would fail the
    site's build (slow), so it is checked here without Sphinx."""
    labels = set(re.findall(r"^\(run-([\w.-]+)\)=$", PAGE.read_text(), re.M))
    cited = set()
    for page in (ROOT / "docs").rglob("*.md"):
        cited |= set(re.findall(r"<run-([\w.-]+)>`", page.read_text()))
    assert cited and cited <= labels, f"cited but not on the page: {sorted(cited - labels)}"
    studies = {p.stem for p in (ROOT / "studies").glob("*.toml")}
    assert studies <= labels, f"studies without a run on the page: {sorted(studies - labels)}"


# -- the guides' fragments, readable rows, and the one command that regenerates everything -------

def _stored_studies() -> list[tuple[str, dict]]:
    cited = re.search(r"```bash\n(snn-antenna results .*?)\n```", PAGE.read_text()).group(1)
    paths = [w for w in shlex.split(cited)[2:] if w.endswith(".json") and "/bench_" not in w]
    stems = [Path(p).stem for p in paths if not p.startswith("--")]
    return [(s, json.loads((SOURCES / f"{s}.json").read_text())) for s in stems]


def test_each_guide_fragment_is_its_stored_run_and_every_study_has_a_guide_that_includes_it():
    """The run time and figures a guide shows are what the results command makes of the
    stored sources: made again here from them, byte for byte."""
    stored = [(s, summary, guides.stored_figures(s, summary, SOURCES))
              for s, summary in _stored_studies()]
    made = guides.fragments(SOURCES, stored)
    assert len(made) == len(stored) + 1
    for path, text in made.items():
        assert path.read_text() == text, f"{path.name} is not what its sources make"
    for study, summary, _ in stored:
        guide = ROOT / "docs" / "guide" / f"{study}.md"
        assert f"```{{include}} ../results/guide_{study}.md" in guide.read_text(), guide.name
        assert guides.run_time(summary), f"{study}: its summary records no run time"
    index = (ROOT / "docs" / "index.md").read_text()
    assert "```{include} results/run_times.md" in index


def test_a_fragment_says_quick_or_full_and_shows_the_runs_figures(tmp_path):
    summary = {"quick": False, "total_s": 754.2, "seeds": [0, 1, 2], "trials": 24,
               "events": 12799, "figures": ["pareto_front.png", "other.png"],
               "figure_captions": {"pareto_front.png": "Every trial. Second sentence."},
               "provenance": {"machine": "AMD EPYC, 2 cores", "created": "2026-11-29T01:02:03",
                              "git_commit": "abc", "code_sha256": "0123456789abcdef"}}
    run = tmp_path / "run"
    run.mkdir()
    (run / "pareto_front.png").write_bytes(b"png")
    (run / "other.png").write_bytes(b"png")
    store = tmp_path / "results"
    names = guides.run_figures("bank_tuning", summary, run)
    assert names == ["pareto_front.png"]                 # only the figures the guide reads
    guides.copy_figures("bank_tuning", names, run, store)
    # a guide figure of an earlier run that this run did not draw goes; a file the command
    # never writes there (a user's) stays
    (store / "figures" / "bank_tuning" / "resonators_on_spectra.png").write_bytes(b"old")
    (store / "figures" / "bank_tuning" / "mine.png").write_bytes(b"user's")
    guides.copy_figures("bank_tuning", names, run, store)
    assert sorted(p.name for p in (store / "figures" / "bank_tuning").iterdir()) == \
        ["mine.png", "pareto_front.png"]
    text = guides.guide_fragment("bank_tuning", summary, names)
    assert "The full profile" in text and "ran in 13 min" in text
    assert "3 seeds, 24 trials, 12799 bench contacts" in text
    assert "/results/figures/bank_tuning/pareto_front.png" in text and "other.png" not in text
    assert "Every trial. Second sentence. n: 3 seeds" in text
    quick = guides.guide_fragment("bank_tuning", {**summary, "quick": True}, names)
    assert "Only a quick check" in quick and "a check, not a result" in quick
    assert "The full profile (" not in quick


def test_the_page_names_rows_in_words_not_code_keys():
    text = PAGE.read_text()
    assert "coder_square_24_bins |" not in text and "| mlp_spectrum |" not in text
    assert labels.readout_label("coder_square_24_bins") == \
        "square coder, 24 resonators: rate in time bins"
    assert labels.readout_label("ceiling_delta_48").startswith("delta coder, 48 channels")
    assert labels.readout_label("distance_rmse_mm") == "distance RMSE (mm)"
    # a label is text the check accepts only as the label of a key its source holds
    page, store = Path(PAGE), SOURCES
    assert results.check_page(page, store) == []


def _fake_checkout(tmp_path, studies=("quickstart", "gating_threshold")) -> Path:
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    for study in studies:
        (root / "studies" / f"{study}.toml").write_text(f'study = "{study}"\n')
    (root / "docs" / "results").mkdir(parents=True)
    return root


def _summary(code_sha256: str, quick=False) -> dict:
    return {"quick": quick, "total_wall_s": 3.0, "figures": [],
            "provenance": {"code_sha256": code_sha256, "command": "snn-antenna run x"}}


def test_regenerate_reuses_what_this_code_made_and_runs_the_rest(tmp_path, monkeypatch):
    """A study or benchmark made by this code (and a benchmark by this script, with its page
    command's options) is reused, from the runs' folder first; the others run."""
    root = _fake_checkout(tmp_path)
    store, runs = root / "docs" / "results", tmp_path / "runs"
    here = provenance.code_hash()
    (store / "quickstart.json").write_text(json.dumps(_summary(here)))
    (store / "gating_threshold.json").write_text(json.dumps(_summary("0" * 16)))
    (runs / "gating_threshold").mkdir(parents=True)         # a quick run: not the full profile
    (runs / "gating_threshold" / "summary.json").write_text(json.dumps(_summary(here, True)))
    (root / "benchmarks").mkdir()
    for name in ("bench_x", "bench_y", "bench_z", "bench_w"):
        (root / "benchmarks" / f"{name}.py").write_text(f"# {name}\n")
    monkeypatch.setattr(regenerate, "PAGE_BENCHMARKS", {
        "bench_x": "--n 2 --json {out}", "bench_y": "--n 1", "bench_z": "--out {out}",
        "bench_w": "--n 3 --json {out}"})

    def bench(name, command, code=here, script=True):
        digest = provenance.file_digest(root / "benchmarks" / f"{name}.py")
        return {"us": 1.0, "provenance": {"code_sha256": code, "command": command,
                                          **({"script_sha256": digest} if script else {})}}
    (store / "bench_x.json").write_text(json.dumps(          # other code
        bench("bench_x", "python benchmarks/bench_x.py --n 2 --json /tmp/a.json", "0" * 16)))
    (store / "bench_y.json").write_text(json.dumps(          # this code, the page's options
        {**bench("bench_y", ".venv/bin/python benchmarks/bench_y.py --n 1"), "stdout": "t\n"}))
    (runs / "bench").mkdir(parents=True)                      # this code's, from a killed run
    (runs / "bench" / "bench_z.json").write_text(json.dumps(
        bench("bench_z", "python benchmarks/bench_z.py --out out/z.json")))
    (store / "bench_w.json").write_text(json.dumps(          # this code, other options
        bench("bench_w", "python benchmarks/bench_w.py --n 1 --json /tmp/w.json")))
    studies, benches = regenerate.plan(root / "docs" / "results.md", runs, False, set(), root)
    assert [(s.name, s.command is None) for s in studies] == \
        [("quickstart", True), ("gating_threshold", False)]
    assert studies[0].output == store / "quickstart.json"
    run = studies[1].command
    assert run[-4:] == ["studies/gating_threshold.toml", "--yes", "--out",
                        str(runs / "gating_threshold")] and "--quick" not in run
    x, y, z, w = benches
    assert x.command == [sys.executable, "benchmarks/bench_x.py", "--n", "2", "--json",
                         str(runs / "bench" / "bench_x.json")] and not x.record
    assert y.command is None and y.output == store / "bench_y.json"      # this code's: reused
    assert z.command is None and z.output == runs / "bench" / "bench_z.json"
    assert w.command[-3:] == ["3", "--json", str(runs / "bench" / "bench_w.json")]
    # the script changed since: run again
    (root / "benchmarks" / "bench_y.py").write_text("# bench_y, changed\n")
    _, benches = regenerate.plan(root / "docs" / "results.md", runs, False, set(), root)
    assert benches[1].command == [sys.executable, "benchmarks/bench_y.py", "--n", "1"]
    assert benches[1].record                           # no output file: recorded as printed
    # a benchmark without its page command is refused before anything runs
    (root / "benchmarks" / "bench_new.py").write_text("")
    try:
        regenerate.plan(root / "docs" / "results.md", runs, False, set(), root)
    except SpecError as exc:
        assert "bench_new" in str(exc) and "PAGE_BENCHMARKS" in str(exc)
    else:
        raise AssertionError("a benchmark without its page command was taken")
    (root / "benchmarks" / "bench_new.py").unlink()
    # --keep takes a stored one as it is; a name that is not there is refused in one line
    studies, _ = regenerate.plan(root / "docs" / "results.md", runs, False,
                                 {"gating_threshold"}, root)
    assert studies[1].command is None and studies[1].output == store / "gating_threshold.json"
    try:
        regenerate.plan(root / "docs" / "results.md", runs, False, {"gating"}, root)
    except SpecError as exc:
        assert "gating" in str(exc) and "gating_threshold" in str(exc)
    else:
        raise AssertionError("an unknown --keep was taken")
    # with --quick the quick run of this code in RUNS is the one reused
    studies, _ = regenerate.plan(root / "docs" / "results.md", runs, True, set(), root)
    assert studies[1].command is None and studies[1].output == runs / "gating_threshold"


def test_regenerate_runs_each_step_then_writes_the_page_from_them(tmp_path, monkeypatch):
    root = _fake_checkout(tmp_path, ("quickstart",))
    runs = tmp_path / "runs"
    ran, pages = [], []

    def fake_run(command, check=False):
        ran.append(command)
        return subprocess.CompletedProcess(command, 0)

    monkeypatch.setattr(regenerate.subprocess, "run", fake_run)
    monkeypatch.chdir(root)
    out = root / "docs" / "results.md"
    assert regenerate.regenerate(out, runs, lambda r, b, o: pages.append((r, b, o)) or o,
                                 None, plan_only=True, log=lambda line: None) is None
    assert ran == [] and pages == []                     # --plan runs and writes nothing
    regenerate.regenerate(out, runs, lambda r, b, o: pages.append((r, b, o)) or o, None,
                          log=lambda line: None)
    assert len(ran) == 1 and ran[0][-3:] == ["--yes", "--out", str(runs / "quickstart")]
    assert pages == [([runs / "quickstart"], [], out)]
    monkeypatch.setattr(regenerate.subprocess, "run",
                        lambda c, check=False: subprocess.CompletedProcess(c, 3))
    try:
        regenerate.regenerate(out, runs, lambda *a: None, None, log=lambda line: None)
    except SpecError as exc:
        assert "exited 3" in str(exc)
    else:
        raise AssertionError("a failed run wrote the page")


def test_the_regenerate_options_are_refused_without_it_and_runs_with_it(tmp_path, capsys):
    assert main(["results", "--keep", "quickstart", "--out", str(tmp_path / "p.md")]) == 2
    assert "only with --regenerate" in capsys.readouterr().err
    assert main(["results", "--regenerate", str(tmp_path), "--out", str(tmp_path / "p.md")]) == 2
    assert "--regenerate" in capsys.readouterr().err


def test_every_benchmark_has_its_page_command_and_a_missing_section_is_planned_to_run(tmp_path):
    """Every script of ``benchmarks/`` has the command that makes its section; a benchmark the
    page lacks (or stored from other code or another command) is one ``--regenerate`` runs,
    and each section the page shows is one of them."""
    scripts = sorted(p.stem for p in (ROOT / "benchmarks").glob("bench_*.py"))
    assert sorted(regenerate.PAGE_BENCHMARKS) == scripts
    assert all("{out}" in options or name == "bench_stream"    # it prints what it measures
               for name, options in regenerate.PAGE_BENCHMARKS.items())
    _, benches = regenerate.plan(PAGE, tmp_path / "runs", False, set(), ROOT)
    assert [step.name for step in benches] == list(regenerate.PAGE_BENCHMARKS)
    for step in benches:
        stored = SOURCES / f"{step.name}.json"
        assert step.command is not None or step.output == stored, step
        if not stored.is_file():
            assert step.command[1] == f"benchmarks/{step.name}.py", step
    sections = set(re.findall(r"^### `([\w.-]+)`$", PAGE.read_text(), re.M))
    assert sections and sections <= set(regenerate.PAGE_BENCHMARKS), sections


def test_a_benchmark_section_opens_with_what_its_script_says_it_measures(tmp_path):
    script = tmp_path / "bench_x.py"
    script.write_text('"""Contacts per second of the x read-out:\nside by side.\n\nMore."""\n')
    prov = results.machine_provenance(f"python {script} --json out.json")
    assert prov["script_sha256"] == provenance.file_digest(script)
    assert prov["script_summary"] == "Contacts per second of the x read-out: side by side."
    lines = results.bench_section({"us": 2.5, "provenance": prov}, "bench_x", "x.json")
    assert lines[:3] == ["### `bench_x`", "", prov["script_summary"]]
    script.write_text(script.read_text() + "# changed\n")
    assert results.machine_provenance(f"python {script}")["script_sha256"] != \
        prov["script_sha256"]
