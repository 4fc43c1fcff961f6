"""The command line explains itself: --version, help for every option, and a misspelt option
answered with its own command's usage."""
import argparse

import pytest

from snn_antenna import __version__
from snn_antenna.cli import build_parser, main


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out.strip() == \
        f"snn-antenna {__version__}"


def test_a_misspelt_option_is_one_line_of_its_command_with_the_likely_option(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["run", "studies/quickstart.toml", "--quik"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and len(err.strip().splitlines()) == 1
    assert err.startswith("snn-antenna run: error:") and "--quik" in err
    assert "did you mean --quick?" in err and "snn-antenna run -h" in err


def test_every_option_of_every_command_has_help():
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = [f"{name} {'/'.join(a.option_strings) or a.dest}"
               for name, sub in commands.choices.items() for a in sub._actions
               if not a.help and not isinstance(a, argparse._HelpAction)]
    assert not missing, f"options without help: {missing}"


def test_stream_ends_with_a_short_summary_not_a_json_dump():
    from snn_antenna.bridge.cli import stream_summary

    lat = {"median": 3.21, "p95": 8.0, "max": 1234.5, "windows": 70}
    report = {"samples": 7000, "windows": 70, "simulated_s": 7.0, "wall_s": 6.93456,
              "realtime_factor": 1.0094, "latency_ms": lat, "steady_latency_ms": lat,
              "contacts": [{"onset_s": 2.1}], "counts": {"frames": 7000, "crc_errors": 0}}
    text = stream_summary(report, "out/rec")
    assert len(text.splitlines()) == 4 and "{" not in text
    assert "7 s of signal" in text and "median 3.21 ms" in text and "contacts: 1" in text
