"""The robot network on the live page, in headless Chromium (skipped only where Chromium is
missing): ``stream --network networks/live_robot.toml --speed 12`` while the emulator plays two
contacts. The page shows the speed gate's, the CPG's and the control layer's panels; the first
contact stops the robot (the control layer's motor unit), and the page then sets Th by hand
(above the signal) and drives the robot on at 6 cm/s, pauses and resumes. Both changes land
in the recording's events.jsonl at window boundaries, and a replay of the recording (its
speed from meta.json, its changes from events.jsonl) finds the live run's contacts: the first
only, the second coded as silence.

``LIVE_ROBOT_SCREENSHOT=docs/live_robot.png`` writes the docs' screenshot.
"""
import json
import re
import subprocess
from pathlib import Path

import pytest

from snn_antenna.bridge.online.controls import recorded_events
from test_live_controls_chromium import (CHROMIUM, CLI, HIGH_TH_G, _wait, ask,
                                         model, replay_report, screenshot, streamed_page,
                                         two_contacts)
from test_live_view import get_json

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "networks" / "live_robot.toml"
SPEED, DRIVE_ON = 12.0, 6.0


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (Debian package `chromium`)")
def test_the_page_reads_the_robot_panels_steers_and_the_replay_reproduces_it(tmp_path):
    counts = two_contacts()
    with streamed_page(tmp_path, counts, ["--network", ROBOT, "--speed", str(SPEED)],
                       screenshot_env="LIVE_ROBOT_SCREENSHOT",
                       viewport={"width": 1400, "height": 980}, ready_model="speed",
                       no_data_timeout_s=90) as session:
        page, url = session.page, session.url
        session.board.start()
        # The panels while driving: the gate's Th from 12 cm/s, the CPG sweeping.
        panels = page.locator("[data-panel]")
        page.locator("[data-panel='cpg']").get_by_text("phase (°)").wait_for(timeout=60_000)
        gate = page.locator("[data-panel='gate']").inner_text()
        assert "Th source" in gate and "gate" in gate and "speed (cm/s)" in gate
        # The first contact: decided, and the control layer stops the robot.
        page.get_by_text(re.compile(r"→ \d+\.\d cm")).first.wait_for(timeout=60_000)
        page.locator("[data-panel='control']").get_by_text(
            re.compile(r"stopped since \(s\)\s*\d")).wait_for(timeout=30_000)
        control = page.locator("[data-panel='control']").inner_text()
        shown = {name: page.locator(f"[data-panel='{name}']").count()
                 for name in ("gate", "cpg", "control", "readout", "threshold")}
        # Th by hand above the signal, and the robot driven on, from the page.
        ask(page, "Th (g)", HIGH_TH_G, "Apply Th", "asked Th 5 g")
        ask(page, "speed (cm/s)", DRIVE_ON, "Apply speed", "asked speed 6 cm/s")
        ask(page, None, None, "Pause display", "display paused")
        paused_at = page.evaluate("() => " + model("antenna", "_lines?.d.t.at(-1)"))
        session.second_half.set()
        session.board.join(30)
        _wait(lambda: get_json(url + "state.json")["t_s"] >= len(counts) / 1000, 60)
        state = get_json(url + "state.json")
        still = page.evaluate("() => " + model("antenna", "_lines?.d.t.at(-1)"))
        page.get_by_role("button", name="Resume display").click()
        page.wait_for_function(f"() => {model('antenna', '_lines?.d.t.at(-1)')} > {paused_at}",
                               timeout=30_000)
        screenshot(session, 0.5)
        final = get_json(url + "state.json")
        n_panels = panels.count()
    assert session.returncode == 0, "".join(session.lines)
    live = json.loads(session.out[session.out.index("{"):])
    rec = session.rec
    # A panel per part of the running network (the gate's holds Th: no fixed-Th panel), and
    # the control list's.
    assert shown == {"gate": 1, "cpg": 1, "control": 1, "readout": 1, "threshold": 0}
    assert n_panels == 5
    assert "motor unit spikes" in control
    network = final["network"]
    assert network["parts"] == ["resonators", "gate", "cpg", "control"]
    assert network["decided"]["gate"] == {**network["decided"]["gate"], "th_source": "manual",
                                          "th_g": HIGH_TH_G, "commanded_cm_s": DRIVE_ON}
    assert network["decided"]["control"]["stopped_since_s"] is None   # driven on
    assert still == paused_at and state["t_s"] > paused_at
    # Both changes: asked from the page, applied at window boundaries, journaled, shown.
    applied = final["controls"]["applied"]
    assert [(e["field"], e["value"], e["by"]) for e in applied] == \
        [("th_g", HIGH_TH_G, "page"), ("speed_cm_s", DRIVE_ON, "page")]
    window = round(live["window_s"] * 1000)
    assert all(e["sample"] % window == 0 for e in applied)
    assert applied[1]["was"] == SPEED
    assert recorded_events(rec) == live["controls"] == applied
    # Live: the first contact only (the second coded as silence under the page's Th).
    assert len(live["contacts"]) == 1 and abs(live["contacts"][0]["distance_cm"] - 19) < 3
    replay, replayed = replay_report(rec, ROBOT)
    assert replayed["contacts"] == live["contacts"]
    assert [(e["sample"], e["field"], e["value"]) for e in replayed["controls"]] == \
        [(e["sample"], e["field"], e["value"]) for e in applied]
    assert "2 control change" in replay.stderr and "speed command 12 cm/s" in replay.stderr
    # Without the journal the replay is another run: the second contact is found.
    (rec / "events.jsonl").rename(tmp_path / "events.jsonl")
    plain = subprocess.run([*CLI, "replay", rec, "--network", ROBOT],
                           capture_output=True, text=True, timeout=180)
    assert len(json.loads(plain.stdout[plain.stdout.index("{\n"):])["contacts"]) > 1
