"""The live view's panels of what the running network decides (bridge/online/live_state.py): a
panel per part the live network runs and none for a part it does not, their values carried in the
pipeline's own frames, shown on the page and in /state.json."""
import copy
import json
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from snn_antenna.bridge.online.controls import RecordedChanges
from snn_antenna.bridge.online.pipeline import build_online, run_online
from snn_antenna.bridge.view.page import build_page, panels_html
from snn_antenna.bridge.wire.recorder import record_counts
from snn_antenna.bridge.wire.replay import ReplaySource
from snn_antenna.bridge.view.view import LiveView
from snn_antenna.bridge.view.history import ViewHistory
from snn_antenna.sources.stimuli import Contact, RobotScene

ROOT = Path(__file__).resolve().parents[1]
NETWORK = ROOT / "networks" / "live.toml"
CLI = [sys.executable, "-m", "snn_antenna.cli"]
# Parts a live network does not run: none of their panels may appear.
ABSENT = ("Speed gate", "speed (cm/s)", "CPG", "phase", "pan-tilt", "stop signal", "Control")


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A robot driving, one contact at 1.5 s, 19 cm from the base; 3 s."""
    counts = RobotScene(duration_s=3.0, contacts=[Contact(1.5, 19.0)]).generate(seed=3).samples
    return record_counts(tmp_path_factory.mktemp("panels") / "rec", counts)


def replay_into_view(recording, parts, scheduled=(), chunk_bytes=800, journal=None):
    """A replay read flat out into a LiveView that is never started: every frame it published
    (a 200-frame hand-off holds them all), taken one by one by the view's own history; the
    changes ``scheduled`` submitted as a recording's, applied as the page's were (and
    journaled by the recorder ``journal``). Returns (report, history, what each window
    decided, view)."""
    parts = copy.deepcopy(parts)
    view = LiveView(parts)
    handlers = [RecordedChanges(parts, scheduled), view, *([journal] if journal else [])]
    report = run_online(ReplaySource(recording, chunk_bytes=chunk_bytes).start(), parts,
                        handlers, no_data_timeout_s=1e9)
    view.flush()
    history, decided = ViewHistory(view.config), []
    while history.received < view.published:
        frame = view._inbox.get(timeout=5)
        history.take(frame)
        decided += [window[4] for window in frame["windows"]]
    return report, history, decided, view


@pytest.fixture(scope="module")
def viewed(recording):
    return replay_into_view(recording, build_online(NETWORK, ["preprocess.threshold=0.04"]))


def test_the_live_network_has_the_panels_of_its_parts_only(viewed):
    report, history, _, view = viewed
    state = history.state()["network"]
    assert state["parts"] == ["resonators"]
    assert list(state["panels"]) == ["threshold", "readout"]
    assert set(state["decided"]) == set(state["panels"])
    html = panels_html(history)
    assert "Gate: input threshold Th" in html and "Contact read-out" in html
    assert not [word for word in ABSENT if word in html]


def test_each_window_carries_what_was_decided(viewed):
    report, history, decided, _ = viewed
    last = history.state()["network"]["decided"]
    # Th is the one the spec's override set, and says so.
    assert last["threshold"] == {"th_g": 0.04, "set_by": "preprocess.threshold (fixed: the "
                                                         "network has no speed gate)"}
    assert history.th_g == 0.04
    # The read-out's decision: contact windows only within the contact the pipeline reported,
    # an episode open during it, and its distance once it closed.
    (contact,) = report["contacts"]
    assert last["readout"]["t_s"] == pytest.approx(2.9)
    assert last["readout"]["last_distance_cm"] == contact["distance_cm"]
    assert abs(contact["distance_cm"] - 19.0) < 3.0
    readouts = [d["readout"] for d in decided if d]
    hits = [r["t_s"] for r in readouts if r["contact_window"]]
    assert hits and contact["onset_s"] <= min(hits) and max(hits) < contact["end_s"]
    assert any(r["contact_open_since_s"] == contact["onset_s"] for r in readouts)
    assert all(r["last_distance_cm"] is None for r in readouts if r["t_s"] < contact["onset_s"])
    assert [r["peak_hz"] for r in readouts if r["contact_window"]] != [None] * len(hits)
    # The page shows those values.
    html = panels_html(history)
    assert "Th (g)</td><td><b>0.04<" in html
    assert f"last distance (cm)</td><td><b>{contact['distance_cm']:.3g}<" in html


def test_a_network_without_those_parts_shows_no_panel(viewed):
    """A view of a network with no part that decides (no panels): the page's panel column is
    empty and /state.json says so, however many windows it saw."""
    from bokeh.document import Document
    from bokeh.models import Div

    _, history, _, view = viewed
    bare = ViewHistory(type(view.config)(**{**vars(view.config), "parts": (), "panels": {}}))
    bare.windows, bare.decided = history.windows, history.decided
    assert bare.state()["network"]["parts"] == [] and bare.state()["network"]["panels"] == {}
    assert "class='panel'" not in panels_html(bare)
    # The page itself: its panel column holds the running network's panels, nothing else.
    doc = Document()
    build_page(history, doc)
    (column,) = [m for m in doc.select({"type": Div}) if m.name == "decided"]
    assert column.text.count("class='panel'") == 2 and "Contact read-out" in column.text
    doc = Document()
    build_page(bare, doc)
    (column,) = [m for m in doc.select({"type": Div}) if m.name == "decided"]
    assert "class='panel'" not in column.text


@pytest.mark.slow
def test_state_json_serves_the_panels_during_a_replay(recording):
    """Over HTTP from the view's own process, while the command holds the page (~20 s: the
    command imports Brian2 and spawns the view's process)."""
    proc = subprocess.Popen([*CLI, "replay", recording, "--network", NETWORK, "--set",
                             "preprocess.threshold=0.04", "--view", "--view-port", "0",
                             "--view-hold", "60"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = None
        for line in proc.stderr:
            if line.startswith("live view: http"):
                url = line.split()[2]
                break
        assert url, "no view URL printed"
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with urllib.request.urlopen(url + "state.json", timeout=5) as reply:
                state = json.loads(reply.read())
            if state["windows"] == 30 and not state["contact_open_since_s"]:
                break
            time.sleep(0.1)
    finally:
        proc.terminate()
        proc.wait(30)
    network = state["network"]
    assert network["parts"] == ["resonators"] and list(network["panels"]) == ["threshold",
                                                                               "readout"]
    assert network["decided"]["threshold"]["th_g"] == 0.04
    (contact,) = state["contacts"]
    assert network["decided"]["readout"]["last_distance_cm"] == contact["distance_cm"]


def test_new_columns_are_pushed_to_the_open_pages_as_they_arrive(recording):
    """The view process tells each open page when new rate-map columns came in (its update is
    then scheduled at once, not at the next periodic pull), and only then."""
    parts = build_online(NETWORK, ["preprocess.threshold=0.04"])
    view = LiveView(parts)
    run_online(ReplaySource(recording, chunk_bytes=800).start(), parts, [view],
               no_data_timeout_s=1e9)
    view.flush()
    history, pushes = ViewHistory(view.config), []
    history.column_listeners.add(lambda: pushes.append(history.windows.total))
    while history.received < view.published:
        history.drain(view._inbox, wait_s=5)
    assert pushes and pushes[-1] == history.windows.total == 30
    assert pushes == sorted(set(pushes))        # once per drain that brought columns
    seen = len(pushes)
    history.drain(view._inbox)                  # nothing new: no page is disturbed
    assert len(pushes) == seen
