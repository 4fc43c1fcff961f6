"""``replay --network`` runs with the ``--set`` the recording was streamed with (its meta.json),
says so, and an explicit ``--set`` wins; when its settings differ from the live run's it says
which, and its report shows the live run's contacts beside its own."""
import argparse
import json

import numpy as np
import pytest

from snn_antenna.bridge import cli
from snn_antenna.bridge.online import pipeline as online
from snn_antenna.bridge.wire.recorder import META_FILE, record_counts


class Built(Exception):
    pass


@pytest.fixture
def streamed(tmp_path):
    rec = record_counts(tmp_path / "rec", np.full((200, 2), 512))
    meta_path = rec / META_FILE
    meta = json.loads(meta_path.read_text())
    meta.update(network="networks/live.toml", set=["preprocess.threshold=0.07"])
    meta_path.write_text(json.dumps(meta))
    return rec


def replay_parts(monkeypatch, recording, *sets):
    """The parts ``replay --network`` builds (by the real build_online), stopped before the
    network runs."""
    real_build, built = online.build_online, []

    def build(path, overrides=(), **kw):
        built.append(real_build(path, overrides, **kw))
        raise Built

    monkeypatch.setattr(online, "build_online", build)
    args = argparse.Namespace(recording=str(recording), network="networks/live.toml",
                              set=list(sets), view=False, realtime=False)
    with pytest.raises(Built):
        cli.cmd_replay(args)
    return built[0]


def test_replay_applies_the_recorded_set_and_says_so(streamed, monkeypatch, capsys):
    parts = replay_parts(monkeypatch, streamed)
    assert parts.spec["preprocess"]["threshold"] == pytest.approx(0.07)
    err = capsys.readouterr().err
    assert "applying the recording's --set preprocess.threshold=0.07" in err


def test_an_explicit_set_overrides_the_recorded_one(streamed, monkeypatch, capsys):
    parts = replay_parts(monkeypatch, streamed, "preprocess.threshold=0.03")
    assert parts.spec["preprocess"]["threshold"] == pytest.approx(0.03)
    assert "then the explicit --set preprocess.threshold=0.03" in capsys.readouterr().err


def test_a_replay_whose_settings_differ_from_the_live_run_says_so(streamed, monkeypatch, capsys):
    replay_parts(monkeypatch, streamed, "preprocess.threshold=0.03")
    err = capsys.readouterr().err
    assert "its settings differ from the live run's (preprocess.threshold: 0.07 -> 0.03)" in err
    assert "the live run's beside them" in err


def test_a_replay_with_the_live_settings_does_not_claim_a_difference(streamed, monkeypatch,
                                                                      capsys):
    replay_parts(monkeypatch, streamed, "preprocess.threshold=0.07")
    assert "differ" not in capsys.readouterr().err


def test_the_live_runs_contacts_and_differences_travel_with_the_replay(streamed):
    from snn_antenna.bridge.wire.recorder import read_meta
    from snn_antenna.bridge.wire.replay import live_comparison

    meta_path = streamed / META_FILE
    meta = json.loads(meta_path.read_text())
    contacts = [{"t_s": 3.2, "distance_cm": 19.4}]
    meta.update(live={"contacts": contacts}, speed_cm_s=2.0)
    meta_path.write_text(json.dumps(meta))
    live = live_comparison(read_meta(streamed), "networks/live_robot.toml",
                           ["preprocess.threshold=0.07", "readout.window_s=0.2"], 3.0)
    assert live["contacts"] == contacts
    assert live["settings_differ"] == ["network: networks/live.toml -> networks/live_robot.toml",
                                       "readout.window_s: the network file -> 0.2",
                                       "speed_cm_s: 2.0 -> 3"]


@pytest.mark.slow                       # the network runs (Brian2): ~20 s of CPU, more under load
def test_replay_reports_the_live_contacts_beside_its_own(tmp_path):
    """The whole command: a recording `stream` made (network, --set, its contacts in meta.json)
    replayed with another Th; the report carries both contact lists and the difference."""
    import subprocess
    import sys

    rec = record_counts(tmp_path / "rec", np.full((1500, 2), 512))
    meta_path = rec / META_FILE
    meta = json.loads(meta_path.read_text())
    live_contacts = [{"t_s": 0.7, "distance_cm": 19.0}]
    meta.update(network="networks/live.toml", set=["preprocess.threshold=0.07"],
                live={"contacts": live_contacts})
    meta_path.write_text(json.dumps(meta))
    done = subprocess.run([sys.executable, "-m", "snn_antenna.cli", "replay", str(rec),
                           "--network", "networks/live.toml", "--set",
                           "preprocess.threshold=0.03"], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout[done.stdout.index("{\n"):])
    assert report["live"]["contacts"] == live_contacts
    assert report["live"]["settings_differ"] == ["preprocess.threshold: 0.07 -> 0.03"]
    assert "contacts" in report and "its settings differ" in done.stderr
