"""The live page in headless Chromium, fed without Brian2 (the default suite's one Chromium
test; the end-to-end one, stream → page → recording → replay, is
tests/test_live_controls_chromium.py, marked slow).

A thread plays the pipeline's part through LiveView's own gathering API (samples, the coder's
input, windows, a contact) at 1 kHz of stream time, and takes the page's control requests as
the pipeline does (a Th asked is applied at the next window). In Chromium: the plots draw and
follow the stream, the contact's distance is marked, Th asked on the page comes back applied,
the display pauses (while the stream goes on) and resumes, the page reports its paints, and
"save view" writes a PNG and data that load_view reads back.
"""
import json
import re
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.bridge.wire.handler import Published, Window
from snn_antenna.bridge.online.pipeline import build_online
from snn_antenna.bridge.online.schedule import Change, InputSchedule
from snn_antenna.bridge.wire.protocol import Sample
from snn_antenna.bridge.view.saved_view import load_view
from snn_antenna.bridge.wire.source import Batch
from snn_antenna.bridge.view.view import LiveView
from snn_antenna.readout.contacts import ContactEstimate
from snn_antenna.sources.stimuli import Contact, RobotScene
from test_live_controls_chromium import CHROMIUM, model

ROOT = Path(__file__).resolve().parents[1]
NETWORK = ROOT / "networks" / "live.toml"
STEP = 50                       # samples per step of the fake pipeline (its window: 0.1 s)
SCENE_S = 6.0                   # played again and again


def state(url: str) -> dict:
    with urllib.request.urlopen(url + "state.json", timeout=5) as reply:
        return json.loads(reply.read())


class FakePipeline(threading.Thread):
    """Feeds ``view`` as run_online does, paced at 1 kHz, with an input schedule of its own:
    the view submits what the page asks to it, and each change it applies (a Th at the next
    window, a window length at the end of one) goes back to the view with ``view.changed``."""

    def __init__(self, view, parts, counts):
        super().__init__(daemon=True)
        self.view, self.parts, self.counts = view, parts, counts
        self.window = int(round(parts.window_s * 1000))
        self.schedule = InputSchedule(parts.th_g, parts.window_s, 1000.0, n_calibration=0)
        self.stop = threading.Event()
        self.asked: list = []

    def run(self) -> None:
        rng = np.random.default_rng(0)
        n, t0 = 0, time.monotonic()
        self.view.stream_started(self.parts, self.schedule)
        while not self.stop.is_set():            # the scene again and again, until stopped
            start = n % len(self.counts)
            chunk = self.counts[start:start + STEP]
            now = time.time()
            self.view.handle(Batch(now, b"", [Sample(n + i, int(x), int(y))
                                              for i, (x, y) in enumerate(chunk)],
                                   {"frames": n + STEP}))
            signal = np.sin(np.arange(n, n + STEP) / 20.0)
            pieces, events = self.schedule.code(STEP)
            begin = 0
            for end, th_g in pieces:
                piece = signal[begin:end, None]
                self.view.coded(piece, th_g, np.sign(piece) * 0.15)
                begin = end
            self._changed(events)
            n += STEP
            if n % self.window == 0:
                t_s = (n - self.window) / 1000
                # The scene's contact, each time the scene comes round (every 6 s).
                at = round(t_s % SCENE_S, 3)
                event = {1.0: ("onset", t_s), 1.5: ("contact", ContactEstimate(
                    t_s - 0.5, t_s, 16.0, 19.3))}.get(at)
                rates = rng.uniform(0, 20, len(self.parts.array.neuron_hz))
                self.view.window(Window(t_s + self.parts.window_s, n, 0.0, Published(
                    t_s, self.parts.window_s, rates, event, now, 1.0, 1.0)))
                self._changed(self.schedule.window_ended(n, published=True))
            time.sleep(max(0.0, t0 + n / 1000 - time.monotonic()))
        self.view.flush()

    def _changed(self, events) -> None:
        for event in events:
            self.asked.append(Change(event["field"], event["value"]))
            self.view.changed(event)


@pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (Debian package `chromium`)")
def test_the_page_draws_takes_th_pauses_reports_paints_and_saves(tmp_path):
    playwright = pytest.importorskip("playwright.sync_api")
    parts = build_online(NETWORK, ["preprocess.threshold=0.04"])
    counts = RobotScene(duration_s=SCENE_S, contacts=[Contact(1.0, 19.0)]).generate(seed=3).samples
    view = LiveView(parts, port=0, save_dir=str(tmp_path / "views"))
    url = view.start()
    pipeline = FakePipeline(view, parts, counts)
    try:
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                        args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1300, "height": 900})
            page.goto(url)
            page.wait_for_function("() => window.Bokeh && Bokeh.documents.length > 0",
                                   timeout=30_000)
            pipeline.start()
            last_t = f"({model('antenna', '_lines?.d.t.at(-1)')} ?? 0)"
            latest = f"() => {last_t}"
            page.get_by_text(re.compile(r"→ 19\.3 cm")).first.wait_for(timeout=30_000)
            page.get_by_label("Th (g)").fill("0.2")
            page.get_by_role("button", name="Apply Th").click()
            page.get_by_text("0.04 → 0.2 g").first.wait_for(timeout=30_000)
            # A bad value is refused on the page, naming the field, the value and the range.
            page.get_by_label("rate-map window (s)").fill("0.15")
            page.get_by_role("button", name="Apply window").click()
            page.get_by_text("window_s = 0.15 is not accepted").wait_for(timeout=30_000)
            page.get_by_label("rate-map window (s)").fill("0.2")
            page.get_by_role("button", name="Apply window").click()
            page.get_by_text("asked window 0.2 s").wait_for(timeout=30_000)
            page.get_by_role("button", name="Pause display").click()
            page.get_by_text("display paused").wait_for(timeout=30_000)
            paused_at = page.evaluate(latest)
            t_paused = state(url)["t_s"]
            time.sleep(0.6)
            still, t_later = page.evaluate(latest), state(url)["t_s"]
            page.get_by_role("button", name="Resume display").click()
            page.wait_for_function(f"() => {last_t} > {paused_at}", timeout=30_000)
            page.get_by_role("button", name="Save view").click()
            page.get_by_text("saved ").wait_for(timeout=30_000)
            shown = page.evaluate(latest)
            final = state(url)
            browser.close()
    finally:
        pipeline.stop.set()
        pipeline.join(5)
        view.stop()
    assert [(c.field, c.value) for c in pipeline.asked] == [("th_g", 0.2), ("windows", 2.0)]
    assert final["th_g"] == 0.2 and final["controls"]["applied"][0]["by"] == "page"
    assert still == paused_at and t_later > t_paused + 0.3      # paused: the stream went on
    assert shown > paused_at
    assert final["display_latency_ms"]["n"] >= 3
    (png,) = (tmp_path / "views").glob("view-*.png")
    assert png.stat().st_size > 20_000 and png.read_bytes().startswith(b"\x89PNG")
    saved = load_view(png)
    assert saved.rates.sizes["window_s"] > 10 and len(saved.x_g) > 100
    contacts = json.loads(saved.attrs["contacts"])     # those within the saved span
    assert contacts and {c["distance_cm"] for c in contacts} == {19.3}
    assert all(saved.attrs["start_s"] <= c["onset_s"] <= saved.attrs["end_s"] for c in contacts)
