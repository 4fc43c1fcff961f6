"""One command registry and one door to an output folder.

Each subcommand declares its options once: the parser's options and the options object's
fields are that declaration, and a value out of its bounds is refused by the same line from
the command line and from Python. One guard maps every exit. Every writer of an output folder
goes through ``outputs.output_folder``, and a recording's folder is checked once."""
from __future__ import annotations

import argparse
import ast
import dataclasses
from pathlib import Path

import pytest

from snn_antenna import cli
from snn_antenna.core import outputs
from snn_antenna.core.commands import POSITIONAL, POSITIONALS
from snn_antenna.core.errors import SpecError
from snn_antenna.core.files import atomic_write
from snn_antenna.studies.contract import STUDY_OPTIONS, Options

PACKAGE = Path(cli.__file__).resolve().parent


def command(name: str):
    return next(c for c in cli.COMMANDS if c.prog == name)


def parser_of(prog: str) -> argparse.ArgumentParser:
    parser = cli.build_parser()
    for word in prog.split():
        parser = next(a for a in parser._actions
                      if isinstance(a, argparse._SubParsersAction)).choices[word]
    return parser


@pytest.mark.parametrize("prog", [c.prog for c in cli.COMMANDS])
def test_the_parser_and_the_options_object_are_the_declaration(prog):
    declared = command(prog)
    parser = parser_of(prog)
    taken = {a.dest: a for a in parser._actions if not isinstance(a, argparse._HelpAction)}
    assert set(taken) == {o.name for o in declared.options}
    assert [f.name for f in dataclasses.fields(declared.Options)] == \
        [o.name for o in declared.options]
    for option in declared.options:
        action = taken[option.name]
        assert action.help == option.help
        if option.kind not in (POSITIONAL, POSITIONALS):
            assert action.option_strings == [option.flag]


def test_the_study_flags_are_declared_once():
    run = command("run")
    assert [o for o in run.options if o.name in {s.name for s in STUDY_OPTIONS}] == \
        list(STUDY_OPTIONS)
    assert [f.name for f in dataclasses.fields(Options)] == [o.name for o in STUDY_OPTIONS]
    # and nowhere else: no other module declares an option of a study's
    study_only = {o.name for o in STUDY_OPTIONS} - {"force"}    # data import has a --force
    declared = [f"{path.relative_to(PACKAGE)}: {node.args[0].value}"
                for path in PACKAGE.rglob("*.py") for node in ast.walk(ast.parse(path.read_text()))
                if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Option"
                and node.args and isinstance(node.args[0], ast.Constant)
                and node.args[0].value in study_only]
    assert sorted(declared) == sorted(f"studies/contract.py: {n}" for n in study_only)


# (command line, the options object's keyword arguments): one bad value each
BOUNDS = [
    (["stream", "--port", "loop://", "--network", "networks/live.toml", "--duration", "-1"],
     "stream", {"port": "loop://", "network": "networks/live.toml", "duration": -1}),
    (["stream", "--port", "loop://", "--network", "networks/live.toml", "--view-hold", "inf"],
     "stream", {"port": "loop://", "network": "networks/live.toml", "view_hold": float("inf")}),
    (["record", "--port", "loop://", "--out", "o", "--baudrate", "7"],
     "record", {"port": "loop://", "out": "o", "baudrate": 7}),
    (["record", "--port", "loop://", "--out", "o", "--format", "morse"],
     "record", {"port": "loop://", "out": "o", "format": "morse"}),
    (["replay", "rec", "--speed", "-3"], "replay", {"recording": "rec", "speed": -3}),
    (["emulate", "--pty", "--frames", "0"], "emulate", {"pty": True, "frames": 0}),
    (["data", "import", "r", "l", "--out", "o", "--adc-bits", "99"],
     "data import", {"recordings": "r", "labels": "l", "out": "o", "adc_bits": 99}),
    (["run", "studies/quickstart.toml", "--scheduler", "http://x"],
     "run", {"spec": "studies/quickstart.toml", "scheduler": "http://x"}),
]


@pytest.mark.parametrize("argv, prog, kwargs", BOUNDS, ids=[" ".join(b[0][:1] + b[0][-2:])
                                                         for b in BOUNDS])
def test_a_declared_bound_is_refused_identically_from_the_cli_and_from_python(
        capsys, argv, prog, kwargs):
    with pytest.raises(SpecError) as refused:
        command(prog).Options(**kwargs)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err == f"snn-antenna: error: {refused.value}\n"
    assert refused.value.field == f"--{argv[-2][2:]}"


def test_a_study_option_is_checked_when_the_study_is_given_it():
    with pytest.raises(SpecError, match="--scheduler = 'nowhere'"):
        Options(scheduler="nowhere")
    with pytest.raises(SpecError, match="--quick = 'yes' is not accepted: true or false"):
        Options(quick="yes")
    assert Options(quick=True).given() == ["quick"]


def test_one_guard_and_one_parser_in_the_package():
    guards, parsers, mains = [], [], []
    for path in PACKAGE.rglob("*.py"):
        tree = ast.parse(path.read_text())
        where = str(path.relative_to(PACKAGE))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and node.name.endswith("guarded"):
                guards.append(f"{where}:{node.name}")
            if isinstance(node, ast.Call) and getattr(node.func, "attr", None) in (
                    "ArgumentParser", "add_subparsers", "add_argument"):
                parsers.append(where)
            if isinstance(node, ast.FunctionDef) and node.name == "main":
                mains.append(where)
    assert guards == ["core/errors.py:guarded"]
    assert set(parsers) == {"core/commands.py"}
    # the command line's one entry; report/results.py's is the record-bench tool, no command
    assert sorted(mains) == ["cli.py", "report/results.py"]


def test_every_writer_of_an_output_folder_goes_through_its_door():
    """outputs' phases are reached only through ``output_folder``: nothing else in the package
    names them, and each command that writes a folder opens that door."""
    phases = {"_prepare", "_claim", "_record", "_release", "prepare", "claim", "record",
              "release"}
    assert not {p for p in phases if not p.startswith("_")} & set(dir(outputs))
    doors = set()
    for path in PACKAGE.rglob("*.py"):
        if path.name == "outputs.py":
            continue
        where = str(path.relative_to(PACKAGE))
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id == "outputs":
                assert node.attr not in phases, f"{where} calls outputs.{node.attr}"
            if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("outputs"):
                assert not {a.name for a in node.names} & phases, where
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(
                    node.func, "attr", None)) == "output_folder":
                doors.add(where)
    assert doors == {"cli.py", "bridge/cli.py", "bridge/wire/recorder.py", "data/command.py",
                     "report/results.py"}


def test_a_recording_folder_is_checked_once(tmp_path, monkeypatch, capsys):
    calls = []
    real = outputs.check_writable
    monkeypatch.setattr(outputs, "check_writable",
                        lambda *a, **k: calls.append(a) or real(*a, **k))
    assert cli.main(["record", "--port", "loop://", "--out", str(tmp_path / "rec"),
                     "--duration", "0.2"]) == 0
    assert len(calls) == 1 and (tmp_path / "rec" / "meta.json").is_file()
    full = tmp_path / "full"
    full.mkdir()
    (full / "raw.bin").write_bytes(b"mine")
    assert cli.main(["record", "--port", "loop://", "--out", str(full)]) == 2
    assert "a new or empty folder; it holds raw.bin" in capsys.readouterr().err
    assert (full / "raw.bin").read_bytes() == b"mine"


def test_check_leaves_a_folder_as_it_was_and_a_run_records_it(tmp_path):
    out = tmp_path / "out"
    with outputs.output_folder(out, "quickstart") as folder:    # --check: the first phase
        assert folder.journal is None
    assert not out.exists()
    with outputs.output_folder(out, "quickstart") as folder:
        folder.claim()
        assert outputs.read_manifest(out)["status"] == "running"
        atomic_write(out / "report.html", "a report")
        (out / "notes.txt").write_text("a file of the user's, made meanwhile")
    manifest = outputs.read_manifest(out)
    assert manifest["status"] == "ended" and manifest["files"] == ["report.html"]
