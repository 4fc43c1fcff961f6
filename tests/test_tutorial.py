"""The tutorial's blocks run as a reader runs them, each on its own, and print what the page
shows: its Python blocks each in a fresh interpreter from an empty folder (the default suite),
its commands each in a fresh shell from a checkout's folder (slow: five quick runs)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from doc_blocks import ROOT, blocks, expected_lines_missing, run_python

PAGE = ROOT / "docs" / "tutorial.md"
README = ROOT / "README.md"


def _python_blocks():
    return [b for b in blocks(PAGE) if b.language == "python"]


def _shell_blocks():
    return [b for b in blocks(PAGE) if b.language == "bash"]


def test_the_tutorial_has_every_step_with_its_output():
    headings = [line for line in PAGE.read_text().splitlines() if line.startswith("## ")]
    steps = ["Install", "A quick run", "Read its report", "--set", "Several seeds",
             "from Python"]
    for step in steps:
        assert any(step in h for h in headings), step
    assert len(_python_blocks()) >= 2
    for block in blocks(PAGE):
        if "pip install" in block.code:        # pip's own output: the page says its last line
            continue
        assert block.expected, f"a block without its expected output:\n{block.code}"
        assert "@" not in block.expected, f"an output not filled in: {block.expected}"
    install = _shell_blocks()[0].code
    assert "pip install -e ." in install and "pip install -e ." in README.read_text()


@pytest.mark.parametrize("index", range(2))
def test_each_python_block_runs_on_its_own_and_prints_what_the_page_shows(index, tmp_path):
    block = _python_blocks()[index]
    done = run_python(block.code, tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    missing = expected_lines_missing(block.expected, done.stdout)
    assert not missing, f"printed:\n{done.stdout}\nnot printed: {missing}"
    assert list(tmp_path.iterdir()) == []          # and wrote nothing where it ran


def test_an_expected_output_that_differs_is_caught():
    assert expected_lines_missing("contact at 5.5 s, 20.2 cm", "contact at 5.5 s, 20.2 cm") == []
    assert expected_lines_missing("a\nb", "a\nc") == ["b"]
    assert expected_lines_missing("took … s\nend", "took 3.2 s\nend\n") == []
    assert expected_lines_missing("end\ntook … s", "took 3.2 s\nend") == ["took … s"]


@pytest.mark.slow    # five quick runs of the quickstart study
def test_each_command_runs_on_its_own_in_a_checkout_and_prints_what_the_page_shows(tmp_path):
    for folder in ("studies", "networks", "stimuli"):
        (tmp_path / folder).symlink_to(ROOT / folder)
    bin_dir = str(Path(sys.executable).parent)
    env = {**os.environ, "PATH": bin_dir + os.pathsep + os.environ.get("PATH", ""),
           "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}
    for block in _shell_blocks():
        if "pip install" in block.code:        # the install itself: what .ci/run does
            continue
        done = subprocess.run(["bash", "-c", "set -o pipefail\n" + block.code], cwd=tmp_path,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              env=env, timeout=1800)
        shown = done.stdout          # as the terminal shows it: both streams, in order
        if block.expected:
            missing = expected_lines_missing(block.expected, shown)
            assert not missing, f"{block.code}\nprinted:\n{shown}\nnot printed: {missing}"
        assert done.returncode == 0 or "exit status" in block.code, f"{block.code}\n{shown}"
