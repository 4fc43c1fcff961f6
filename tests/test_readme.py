"""The README is a short guide whose commands work: the install and test commands CI reads, every
``snn-antenna`` command line parses, every study and file it names exists, and its Python example
runs as printed (a moved module would break it silently)."""

import re
import shlex
from pathlib import Path

import pytest

from snn_antenna.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TEXT = README.read_text()
INSTALL = (
    "python3 -m venv .venv && .venv/bin/pip install -e . && "
    ".venv/bin/snn-antenna run studies/quickstart.toml --out out/quickstart"
)
TEST = "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && .venv/bin/python -m pytest"


def _command_lines() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", TEXT, re.S)
    return [
        line.split("  #")[0].strip()
        for block in blocks
        for line in block.splitlines()
        if line.startswith("snn-antenna ")
    ]


def test_the_two_commands_open_the_readme_verbatim():
    lines = TEXT.splitlines()
    assert lines[3] == INSTALL and lines[4] == TEST  # .ci/run reads the second one
    assert len(lines) <= 200


def test_every_snn_antenna_command_is_accepted_and_names_files_that_exist():
    commands = _command_lines()
    assert len(commands) >= 10
    parser = build_parser()
    for line in commands:
        argv = shlex.split(line)[1:]
        if "NAME" in line:  # the generic form: every shipped study
            argv = [a.replace("NAME", "quickstart") for a in argv]
        args = parser.parse_args(argv)
        args.command.options_from(args)  # every value in its declared bounds
        for value in vars(args).values():
            if isinstance(value, str) and re.match(r"(studies|networks|stimuli|firmware)/", value):
                assert (ROOT / value).exists(), f"{line}: {value} does not exist"


def test_every_study_has_its_command_and_every_link_resolves():
    studies = {p.stem for p in (ROOT / "studies").glob("*.toml")}
    named = set(re.findall(r"run studies/(\w+)\.toml", TEXT))
    assert studies <= named | {"NAME"}, f"studies without a command: {studies - named}"
    links = re.findall(r"\]\(((?:docs|CHANGELOG)[^)#]*)", TEXT)
    assert links
    for link in links:
        assert (ROOT / link).exists(), f"README links to {link}, which does not exist"


@pytest.mark.parametrize(
    "pattern", [r"\bissue \d+", r"#\d{2}\b", r"\b20\d\d-\d\d-\d\d\b", r"\bbefore (issue|the)\b"]
)
def test_no_history_and_no_dated_measurement(pattern):
    assert not re.search(pattern, TEXT, re.I), re.search(pattern, TEXT, re.I).group(0)


def test_the_python_example_in_the_readme_runs():
    section = TEXT[TEXT.index("## Using the pieces from Python") :]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    counts = [int(c) for c in namespace["res"].spike_counts]
    # three neurons, one per k; the square wave at 7 Hz drives at least the one tuned near it
    assert len(counts) == 3 and sum(counts) > 0, counts
