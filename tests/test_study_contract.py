"""Every study keeps one contract, and the command holds every study to it: each flag of
``snn-antenna run`` either reaches the study or is refused in one line naming the study and the
flags it takes (exit 2), before any work; never an internal error, never a flag dropped."""
from __future__ import annotations

import dataclasses
import json
import re
import types
from pathlib import Path

import pytest

from snn_antenna.cli import main
from snn_antenna.studies import STUDIES, runner
from snn_antenna.studies.contract import COMMON, Options, Plan, check_study, flag

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "snn_antenna"
OPTION_NAMES = [f.name for f in dataclasses.fields(Options)]


def spec_of(study: str) -> str:
    return str(ROOT / "studies" / f"{study}.toml")


@pytest.fixture(scope="module")
def drive_data(tmp_path_factory):
    """A recorded drive, imported: the data set every study taking --data is given."""
    from data_helpers import import_quickstart_drive
    from snn_antenna.core import spec as specs

    spec = specs.load(ROOT / "studies" / "quickstart.toml", [], quick=True)
    return import_quickstart_drive(tmp_path_factory.mktemp("drive"), spec)[1]


def flag_argv(name: str, data: Path | None = None) -> list[str]:
    """The option ``name`` as a user types it (with a value where it takes one)."""
    if name == "scheduler":
        return [flag(name), "tcp://127.0.0.1:1"]    # the probe is stood in for (below)
    if name == "data":
        return [flag(name), str(data)]
    return [flag(name)]


@pytest.fixture
def any_scheduler(monkeypatch):
    """No Dask scheduler runs here: what --scheduler finds at an address is
    tests/test_scheduler_probe.py's; these tests check that the flag reaches the study."""
    import snn_antenna.engine.executor as executor

    monkeypatch.setattr(executor, "probe_scheduler", lambda address, *a, **k: None)


def outcome(argv, capsys) -> tuple[int, str, str]:
    try:
        status = main(argv)
    except SystemExit as exc:           # argparse's own refusals
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize("study", sorted(STUDIES))
def test_every_study_keeps_the_contract(study):
    module = runner(study)
    assert check_study(module) == []
    assert set(COMMON) <= set(module.OPTIONS) and "study" not in module.SECTIONS


def test_the_contract_check_sees_a_catch_all_and_a_missing_option():
    def plan(spec):
        return Plan("x", spec, None)

    def run(plan, out_dir, options, log=print, **_):
        return {}

    lax = types.SimpleNamespace(SECTIONS=(), OPTIONS=(*COMMON, "colour"), plan=plan, run=run)
    problems = check_study(lax)
    assert any("colour" in p for p in problems) and any("run(" in p for p in problems)
    assert check_study(types.SimpleNamespace(plan=plan)) != []


def test_no_keyword_catch_all_swallows_arguments_in_the_package():
    swallowing = re.compile(r"\*\*_\w*\s*[,)]")
    found = [f"{path.relative_to(ROOT)}:{n}" for path in PACKAGE.rglob("*.py")
             for n, line in enumerate(path.read_text().splitlines(), 1)
             if swallowing.search(line) and "def " in line]
    assert not found, found


@pytest.mark.parametrize("study", sorted(STUDIES))
@pytest.mark.parametrize("name", [n for n in OPTION_NAMES if n != "check"])
def test_every_flag_of_every_study_reaches_it_or_is_refused_in_one_line(
        tmp_path, capsys, monkeypatch, any_scheduler, drive_data, study, name):
    """--check for every flag; then the same command without --check, the study's run
    replaced by one that keeps what it was given: the flag arrived, set. A study given a data
    set of another kind than it reads (a drive, to the bench comparison) refuses it in one
    line naming ``data``: it read the flag."""
    module = runner(study)
    out = tmp_path / "out"
    argv = ["run", spec_of(study), "--quick", "--out", str(out), *flag_argv(name, drive_data)]
    status, said, err = outcome([*argv, "--check"], capsys)
    assert "internal error" not in err and "Traceback" not in err, err
    if name not in module.OPTIONS:
        line = err.strip().splitlines()
        assert status == 2 and len(line) == 1, err
        assert line[0].startswith(f"snn-antenna: error: {flag(name)} = ")
        assert f"the {study} study takes " in line[0]
        assert all(flag(o) in line[0] for o in module.OPTIONS)
        assert not out.exists()
        return
    if name == "data" and status == 2:
        line = err.strip().splitlines()
        assert len(line) == 1 and line[0].startswith("snn-antenna: error: data = "), err
        return
    assert status == 0 and "nothing was run" in said, err
    given = {}

    def keep(plan, out_dir, options, log=print):
        given.update(plan=plan, options=options)
        return {}

    monkeypatch.setattr(module, "run", keep)
    status, _, err = outcome(argv, capsys)
    assert status == 0, err
    value = getattr(given["options"], name)
    assert value not in (None, False), f"{flag(name)} did not reach the {study} study"
    if name == "data":
        assert given["plan"].spec["data"] == value


def test_data_must_be_a_folder_that_exists(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("x")
    for path, why in ((tmp_path / "missing", "existing folder"), (afile, "is a file")):
        status, _, err = outcome(["run", spec_of("quickstart"), "--quick", "--check",
                                  "--data", str(path), "--out", str(tmp_path / "o")], capsys)
        assert status == 2 and len(err.strip().splitlines()) == 1 and "data" in err, err
        assert why in err


def test_a_data_key_in_a_study_that_reads_none_is_an_unknown_key(tmp_path, capsys):
    status, _, err = outcome(["run", spec_of("tuning_sweep"), "--quick", "--check", "--set",
                              f'data="{tmp_path}"', "--out", str(tmp_path / "o")], capsys)
    assert status == 2 and "data" in err and "a known top-level key" in err


def test_quickstart_runs_with_every_flag_it_takes(tmp_path, capsys, drive_data):
    """The one real run of the default suite: quickstart's quick profile with all its flags."""
    data = drive_data
    out = tmp_path / "out"
    status, said, err = outcome(["run", spec_of("quickstart"), "--quick", "--yes", "--force",
                                 "--data", str(data), "--out", str(out)], capsys)
    assert status == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert (out / "report.html").is_file() and summary["provenance"]["spec"]["data"] == str(data)


@pytest.mark.slow
@pytest.mark.parametrize("study", sorted(STUDIES))
def test_every_study_runs_its_quick_profile_with_every_flag_it_takes(tmp_path, capsys, study,
                                                                     drive_data):
    """Every study, for real, with all the flags it declares (no cluster: --scheduler is the
    one flag a machine without a Dask scheduler cannot run with)."""
    module = runner(study)
    argv = ["run", spec_of(study), "--quick", "--out", str(tmp_path / "out")]
    for name in module.OPTIONS:
        if name not in ("check", "scheduler"):
            argv += flag_argv(name, drive_data)
    status, _, err = outcome(argv, capsys)
    assert status == 0, err[-3000:]
    assert (tmp_path / "out" / "report.html").is_file()
