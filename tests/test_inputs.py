"""Every input answered in one line, before any work.

Each case a careless user tries gets one line naming the field, the value and
what is accepted (SpecError, exit 2), before a scene is generated or Brian2 runs; long jobs
show their estimate and need --yes; a message shows at most 80 characters of a value.
"""
import os

import numpy as np
import pytest

from snn_antenna.core import bounds
from snn_antenna.cli import main
from snn_antenna.core.errors import MAX_SHOWN, SpecError, shown
from snn_antenna.preprocess import fit_warmup, make_chain
from snn_antenna.sources import stimuli
from snn_antenna.sources.stimuli import Contact, RobotScene

QUICKSTART = "studies/quickstart.toml"


def refused(capsys, argv, field):
    """Run the CLI; it must exit 2 with one line naming ``field``, before any work."""
    try:
        status = main(argv)
    except SystemExit as exc:           # argparse: an option's type refused it
        status = exc.code
    out, err = capsys.readouterr()
    assert status == 2, err
    lines = err.strip().splitlines()       # the estimate may come first
    assert len(lines) <= 2 and sum("error" in line for line in lines) == 1, err
    assert field in lines[-1] and "internal error" not in err and "Traceback" not in err
    assert "[1/4]" not in out                        # no scene was generated
    return lines[-1]


@pytest.mark.parametrize("setting, field", [
    ("stimulus.duration_s=1e308", "stimulus.duration_s"),     # was OverflowError
    ("network.dt_ms=1e-308", "network.dt_ms"),                # was a Brian2 error
    ("readout.window_s=1e-9", "readout.window_s"),            # was MemoryError, after the run
    ("stimulus.rate_hz=1e308", "stimulus.rate_hz"),
    ("seed=-1", "seed"),
])
def test_quickstart_settings_are_refused_before_work(tmp_path, capsys, setting, field):
    refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(tmp_path / "o"),
                     "--set", setting], field)
    assert not (tmp_path / "o").exists()


def test_an_include_that_is_a_binary_file_is_named(tmp_path, capsys):
    (tmp_path / "net.toml").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "study.toml").write_text('study = "quickstart"\nnetwork = "net.toml"\n')
    line = refused(capsys, ["run", str(tmp_path / "study.toml"), "--out", str(tmp_path / "o")],
                   "network")
    assert "UTF-8" in line


@pytest.mark.parametrize("out", ["x" * 300, "ok/" + "y" * 256, "caf\udce9"])
def test_an_out_the_file_system_cannot_hold_is_refused(tmp_path, capsys, out):
    refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(tmp_path / out)], "--out")
    assert not os.path.lexists(tmp_path / out)       # refused before anything was made


@pytest.mark.parametrize("option, value", [("--view-hold", "inf"), ("--baudrate", "10" * 20),
                                           ("--duration", "nan"), ("--duration", "1e308"),
                                           ("--no-data-timeout", "-1")])
def test_stream_options_are_typed_and_bounded(capsys, option, value):
    line = refused(capsys, ["stream", "--port", "loop://", "--network", "networks/live.toml",
                            option, value], option)
    # the value as read (1e308 is the number 1e+308), and what would be accepted
    assert shown(bounds.parse_value(value)) in line and "accepted" in line


def test_a_long_value_is_cut_in_the_message(tmp_path, capsys):
    huge = "x" * 4_000_000
    line = refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(tmp_path / "o"),
                            "--set", f'stimulus.terrain="{huge}"'], "stimulus.terrain")
    assert len(line) < 400 and "xxx\u2026" in line
    assert len(str(SpecError("f", huge, "short"))) <= len("f = ") + MAX_SHOWN + 40


def test_a_28_hour_scene_shows_its_estimate_and_needs_yes(tmp_path, capsys, monkeypatch):
    # on a busy machine (a load of 13 on the table's rates, no probe) this scene takes over
    # an hour, and a scene long enough for that on an idle one would not fit in memory
    from snn_antenna.engine import rates

    monkeypatch.setenv("SNN_ANTENNA_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(rates, "competing_load", lambda: 13.0)
    line = refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(tmp_path / "o"),
                            "--set", "stimulus.duration_s=20000"], "stimulus.duration_s")
    assert "--yes" in line and " h" in line
    # with --yes the scene that would not fit in memory is still refused, before any work
    line = refused(capsys, ["run", QUICKSTART, "--quick", "--yes", "--out",
                            str(tmp_path / "o"), "--set", "stimulus.duration_s=100000"],
                   "stimulus.duration_s")
    assert "GiB" in line


@pytest.mark.parametrize("spec, setting, field", [
    ("studies/baseline_comparison.toml", "stimulus.repetitions=2000", "stimulus.repetitions"),
    ("studies/gating_threshold.toml", "sweep.n_scenes=40000", "sweep.n_scenes"),
    ("studies/exploration.toml", "loop.duration_s=40000", "loop.duration_s"),
])
def test_bench_sets_and_sweeps_of_scenes_need_yes_beyond_an_hour(tmp_path, capsys, spec,
                                                                   setting, field):
    line = refused(capsys, ["run", spec, "--quick", "--out", str(tmp_path / "o"),
                            "--set", setting], field)
    assert "--yes" in line


@pytest.mark.parametrize("make, field", [
    (lambda: stimuli.square(5.0, 1.0, amplitude=1e308), "amplitude"),
    (lambda: stimuli.square(5.0, 1.0, amplitude="x"), "amplitude"),
    (lambda: stimuli.sine("x", 1.0), "freq_hz"),
    (lambda: stimuli.silence(1e9), "duration_s"),          # 7.28 TiB was allocated for
    (lambda: stimuli.dc(1.0, 1.0, rate_hz=float("inf")), "rate_hz"),
    (lambda: RobotScene().generate(seed=-1), "seed"),
    (lambda: RobotScene().generate(seed="a"), "seed"),
    (lambda: RobotScene(duration_s=1e9).generate(), "duration_s"),
    (lambda: RobotScene(contacts=None).generate(), "contacts"),
    (lambda: RobotScene(contacts=[(1.0, 19.0)]).generate(), "contacts.0"),
    (lambda: RobotScene(contacts=[Contact("1", 19.0)]).generate(), "t_s"),
    (lambda: RobotScene(contacts=[Contact(1.0, 19.0, ["wood"])]).generate(), "material"),
    (lambda: RobotScene(speed_cm_s="fast").generate(), "speed_cm_s"),
    (lambda: RobotScene(adc_bits=10.5).generate(), "adc_bits"),
    (lambda: fit_warmup(make_chain(1000.0), np.ones((100, 2)), 0.0, 0.05), "rate_hz"),
    (lambda: make_chain(1000.0, threshold="x"), "threshold"),
    (lambda: make_chain(1000.0, highpass_hz=600.0), "highpass_hz"),
    (lambda: make_chain(1000.0, lowpass_order=2.0), "lowpass_order"),
])
def test_public_constructors_refuse_by_name(make, field):
    with pytest.raises(SpecError) as info:
        make()
    assert info.value.field == field


def test_bounds_name_what_is_accepted():
    with pytest.raises(SpecError, match=r"x = 2 is not accepted: an integer >= 3 and <= 5"):
        bounds.integer("x", 2, 3, 5)
    with pytest.raises(SpecError, match="finite number > 0"):
        bounds.number("x", 10**400, 0.0, lo_open=True)        # an int too big for a float
    assert bounds.number("x", 0.5, 0.0, 1.0) == 0.5
    assert bounds.seed("s", np.int64(7)) == 7
    for bad in (True, 2.0, "3", None, [1]):
        with pytest.raises(SpecError):
            bounds.integer("x", bad)
    with pytest.raises(SpecError, match="GiB"):
        bounds.n_samples("d", 10.0, 1000.0, 8, budget=1000)


# -- the first phase: what --check accepts, the run accepts; what it refuses, the run refuses --
def first_phase_refuses(capsys, monkeypatch, argv, *names):
    """``argv`` refused in one line naming ``names`` by ``--check``, and by the run with the
    same line, before the study's run starts (it is replaced by one that fails the test)."""
    from snn_antenna.engine import rates
    from snn_antenna.studies import runner

    # one load for both (a live watch of the CPU moves between the two estimates)
    monkeypatch.setattr(rates, "competing_load", lambda *a: 0.0)

    def must_not_run(plan, out_dir, options, log=print):
        raise AssertionError("the study ran")

    for name in ("quickstart", "gating_threshold", "exploration", "baseline_comparison",
                 "speed_accuracy", "model_selection", "tuning_sweep"):
        monkeypatch.setattr(runner(name), "run", must_not_run)
    lines = []
    for extra in (["--check"], []):
        status = main([*argv, *extra])
        err = capsys.readouterr().err
        assert status == 2, err
        last = err.strip().splitlines()[-1]
        assert "internal error" not in err and "Traceback" not in err
        for name in names:
            assert name in last, last
        lines.append(last)
    assert lines[0] == lines[1]
    return lines[0]


@pytest.mark.parametrize("spec, setting, field", [
    ("gating_threshold", "seed=4294967296", "seed"),            # the gate's Brian2 seed
    ("baseline_comparison", "evaluation.seeds=[0, 4294967296]", "evaluation.seeds.1"),
    ("quickstart", "seed=18446744073709551616", "seed"),
])
def test_seeds_beyond_numpys_range_are_refused_at_check(tmp_path, capsys, monkeypatch, spec,
                                                         setting, field):
    first_phase_refuses(capsys, monkeypatch, ["run", f"studies/{spec}.toml", "--quick", "--out",
                                              str(tmp_path / "o"), "--set", setting], field)


def test_a_report_of_the_users_in_out_is_refused_at_check_even_with_force(tmp_path, capsys,
                                                                            monkeypatch):
    out = tmp_path / "o"
    out.mkdir()
    (out / "report.html").write_text("my report")
    first_phase_refuses(capsys, monkeypatch, ["run", QUICKSTART, "--quick", "--force", "--out",
                                              str(out)], "--out", "report.html")
    assert (out / "report.html").read_text() == "my report"


def test_a_cache_folder_that_is_a_file_is_refused_at_check(tmp_path, capsys, monkeypatch):
    cache = tmp_path / "cache"
    cache.write_text("mine")
    first_phase_refuses(capsys, monkeypatch, [
        "run", "studies/baseline_comparison.toml", "--quick", "--out", str(tmp_path / "o"),
        "--set", f'stimulus.cache_dir="{cache}"'], "stimulus.cache_dir", "file")
    assert cache.read_text() == "mine"


def test_an_out_that_is_a_dangling_link_is_refused_at_check(tmp_path, capsys, monkeypatch):
    link = tmp_path / "o"
    link.symlink_to(tmp_path / "nowhere")
    first_phase_refuses(capsys, monkeypatch, ["run", QUICKSTART, "--quick", "--out", str(link)],
                        "--out", "link")
    assert link.is_symlink() and not (tmp_path / "nowhere").exists()


def test_an_out_too_long_for_what_the_run_writes_is_refused_at_check(tmp_path, capsys,
                                                                     monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = "/".join(["d" * 200] * 20)[:4000]          # fits PATH_MAX alone, not its files
    first_phase_refuses(capsys, monkeypatch, ["run", str(bounds_root() / QUICKSTART), "--quick",
                                              "--out", out], "--out", "short enough")
    assert not (tmp_path / ("d" * 200)).exists()


def bounds_root():
    from pathlib import Path

    return Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("spec, settings, field", [
    ("gating_threshold", ["gate.present_s=30000"], "gate"),
    ("exploration", ["network.gate.present_s=6000"], "network.gate"),
    ("exploration", ["network.gate.epochs=10000", "network.gate.present_s=10"], "network.gate"),
    ("speed_accuracy", ["cost.n_neurons=[24, 100000]", 'cost.settings=[["euler", 0.0001]]'],
     "cost.n_neurons"),
    ("model_selection", ["stimulus.repetitions=20000"], "stimulus.repetitions"),
])
def test_every_knob_that_makes_a_run_long_needs_yes(tmp_path, capsys, monkeypatch, spec,
                                                   settings, field):
    """The gate's training (its epochs and presentation time), the cost sweep's array sizes,
    the model selection's bench sets: each was outside the estimate, or had none."""
    argv = ["run", f"studies/{spec}.toml", "--quick", "--out", str(tmp_path / "o")]
    for setting in settings:
        argv += ["--set", setting]
    line = first_phase_refuses(capsys, monkeypatch, argv, field, "--yes")
    assert line.startswith(f"snn-antenna: error: {field} = ")


def test_every_study_prints_its_estimate(tmp_path, capsys):
    from snn_antenna.studies import STUDIES

    for study in sorted(STUDIES):
        assert main(["run", f"studies/{study}.toml", "--quick", "--check", "--out",
                     str(tmp_path / study)]) == 0
        assert "about " in capsys.readouterr().err, study


@pytest.mark.parametrize("text, accepted, in_file", [
    ("9" * 5000, "digits", "spec"),                       # the reader's ValueError
    ("[" * 3000 + "]" * 3000, "nested", "spec"),          # the reader's RecursionError
    ("[" * 40 + "1" + "]" * 40, "nested", "network.b"),   # read, and refused by its key
    ("{a = " * 50 + "1" + "}" * 50, "nested", "network.b"),
])
def test_values_past_pythons_limits_are_one_line(tmp_path, capsys, text, accepted, in_file):
    """In a spec file and in --set: a RecursionError or ValueError inside the reader before."""
    spec = tmp_path / "spec.toml"
    spec.write_text(f'study = "quickstart"\nseed = 0\n[network]\nb = {text}\n')
    line = refused(capsys, ["run", str(spec), "--check", "--out", str(tmp_path / "o")],
                   in_file)
    assert accepted in line and len(line) < 400
    line = refused(capsys, ["run", QUICKSTART, "--quick", "--check", "--out",
                            str(tmp_path / "o"), "--set", f"network.b={text}"], "network.b")
    assert accepted in line and len(line) < 400


def test_a_standalone_cache_that_cannot_be_made_is_refused_at_check(tmp_path, capsys,
                                                                     monkeypatch):
    blocker = tmp_path / "cache"
    blocker.write_text("mine")
    monkeypatch.setenv("SNN_ANTENNA_CACHE", str(blocker / "snn_antenna"))
    first_phase_refuses(capsys, monkeypatch, [
        "run", "studies/tuning_sweep.toml", "--out", str(tmp_path / "o")],
        "SNN_ANTENNA_CACHE", "is a file")
    assert blocker.read_text() == "mine"
