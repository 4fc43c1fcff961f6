"""``replay --network`` runs with the ``--set`` the recording was streamed with (its meta.json),
says so, and an explicit ``--set`` wins."""
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
