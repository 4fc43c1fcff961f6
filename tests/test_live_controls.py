"""The live controls (bridge/online/controls.py) and the input schedule
(bridge/online/schedule.py): the one parser of control requests refuses every bad value with a
SpecError naming field, value and range; changes are scheduled at window boundaries ahead of the
coder, journaled in events.jsonl, and a replay that re-applies them finds what the live run found;
the view's paint reports and its saved views (bridge/view/saved_view.py) read back."""
import concurrent.futures
import json
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.bridge.online.controls import (
    MAX_WINDOWS,
    TH_MAX_G,
    RecordedChanges,
    parse_control,
    recorded_events,
)
from snn_antenna.bridge.online.pipeline import build_online, run_online
from snn_antenna.bridge.online.schedule import Change, InputSchedule
from snn_antenna.bridge.wire.handler import Published, Window, WindowHandler
from snn_antenna.bridge.view.feed import KINDS
from snn_antenna.bridge.view.page import build_page
from snn_antenna.bridge.wire.recorder import EVENTS_FILE, Recorder, record_counts
from snn_antenna.bridge.wire.replay import ReplaySource
from snn_antenna.bridge.view.saved_view import load_view, save_view
from snn_antenna.bridge.view.view import LiveView
from snn_antenna.bridge.view.history import ViewHistory
from snn_antenna.core.errors import SpecError
from snn_antenna.sources.stimuli import Contact, RobotScene
from tests.test_live_view_panels import NETWORK

BASE = 0.05
JSON_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
                        st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8))


@settings(max_examples=250, deadline=None)
@given(field=st.sampled_from(["th_g", "window_s", "speed_cm_s", "Th", ""]), value=JSON_VALUES,
       speeds=st.sampled_from([None, (0.0, 30.0), (5.0, 12.5)]))
def test_a_request_is_accepted_exactly_when_in_range_else_named(field, value, speeds):
    """``speeds``: the running network's speed range (None: no part reads a speed)."""
    body = json.dumps({field: value}).encode()
    number = isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)
    if field == "speed_cm_s":
        ok = number and speeds is not None and speeds[0] <= value <= speeds[1]
        if ok:
            assert parse_control(body, BASE, speeds) == Change("speed_cm_s", float(value))
            return
        with pytest.raises(SpecError) as caught:
            parse_control(body, BASE, speeds)
        assert caught.value.field == "speed_cm_s" and "not accepted" in str(caught.value)
        assert (f"[{speeds[0]:g}, {speeds[1]:g}]" if speeds else "no part that reads the "
                "speed command") in str(caught.value)
        return
    if field == "th_g":
        ok = number and 0 <= value <= TH_MAX_G
    elif field == "window_s":
        k = value / BASE if number else None
        ok = number and math.isfinite(k) and abs(k - round(k)) <= 1e-6 * max(1, k) \
            and 1 <= round(k) <= MAX_WINDOWS
    else:
        ok = False
    if ok:
        change = parse_control(body, BASE)
        assert change.value == (float(value) if field == "th_g" else round(value / BASE))
        return
    with pytest.raises(SpecError) as caught:
        parse_control(body, BASE)
    message = str(caught.value)
    if field in ("th_g", "window_s"):       # the field, the value and the accepted range
        assert caught.value.field == field and "not accepted" in message
        assert (f"[0, {TH_MAX_G:g}]" if field == "th_g" else f"{MAX_WINDOWS * BASE:g} s") \
            in message
    else:
        assert caught.value.field == "control" and "th_g, window_s, speed_cm_s" in message


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.binary(max_size=2000), st.text(max_size=200),
                 st.dictionaries(st.text(max_size=5), JSON_VALUES, max_size=3)))
def test_any_body_gives_a_change_or_a_spec_error(body):
    try:
        change = parse_control(body, BASE)
    except SpecError as exc:
        assert str(exc).count("\n") == 0            # one line
        return
    assert isinstance(change, Change) and change.field in ("th_g", "windows")


def test_a_request_applies_at_the_next_boundary_ahead_of_the_coder_and_calibration():
    schedule = InputSchedule(0.04, BASE, 1000.0, n_calibration=1000)
    schedule.position = 500
    schedule.submit(Change("th_g", 0.2), "page")            # still calibrating: after it
    schedule.position = 1234
    schedule.submit(Change("windows", 3), "page")
    assert [(p.at, p.change.value) for p in schedule._pending] == [(1000, 0.2), (1250, 3)]
    # The window change moves the boundaries after it: every 150 samples from 1250.
    assert schedule.next_boundary(1251) == 1400
    with pytest.raises(SpecError, match="sample"):          # the coder is past sample 1000
        schedule.submit(Change("th_g", 0.3), "replay", 1000)


def test_the_schedule_applies_th_where_the_coder_reaches_its_sample_a_person_outranks_the_gate():
    schedule = InputSchedule(0.04, BASE, 1000.0, n_calibration=0)
    schedule.submit(Change("th_g", 0.1), "gate", 0)
    schedule.submit(Change("th_g", 0.3), "page", 100)
    schedule.submit(Change("th_g", 0.2), "gate", 100)       # at the same sample: the page's holds
    assert schedule.coded_until() == 150                    # the gate's Th codes one window
    pieces, events = schedule.code(120)
    assert pieces == [(100, 0.1), (120, 0.3)] and schedule.th_source == "manual"
    # The gate's Th for that window was applied first, then the page's in its place.
    assert [(e["sample"], e["was"], e["value"], e["by"]) for e in events] == \
        [(100, 0.2, 0.3, "page")]
    schedule.submit(Change("th_g", 0.5), "gate", 150)       # overridden: dropped
    assert schedule.code(100) == ([(100, 0.3)], []) and schedule.coded_until() is None
    assert schedule.events == events                        # the gate's steps are not events


class ThTap(WindowHandler):
    """The Th of every sample the coder coded, as the pipeline hands the pieces over."""

    def __init__(self):
        self.th: list[np.ndarray] = []

    def coded(self, signal_g, th_g, coded) -> None:
        self.th.append(np.full(len(coded), th_g))


@pytest.fixture(scope="module")
def two_contacts(tmp_path_factory):
    counts = RobotScene(duration_s=4.0, contacts=[Contact(1.5, 19.0), Contact(3.0, 25.0)]
                        ).generate(seed=3).samples
    return record_counts(tmp_path_factory.mktemp("controls") / "rec", counts)


def _parts():
    return build_online(NETWORK, ["preprocess.threshold=0.04"])


def _replay(recording, scheduled=(), chunk_bytes=800, handlers=(), parts=None):
    """A replay flat out, the changes ``scheduled`` submitted as a recording's."""
    parts = parts or _parts()
    return run_online(ReplaySource(recording, chunk_bytes=chunk_bytes).start(), parts,
                      [RecordedChanges(parts, scheduled), *handlers], no_data_timeout_s=1e9)


def test_a_journaled_th_change_replays_to_the_same_contacts(two_contacts, tmp_path):
    before = _replay(two_contacts)
    assert len(before["contacts"]) == 2
    # As the live run journals a change: the recorder's events.jsonl, a torn last line kept
    # out by the reader.
    recorder = Recorder(tmp_path / "live", port="test://", wire_format="binary", baudrate=1)
    recorder.note_event({"sample": 2500, "field": "th_g", "value": 5.0})
    recorder.close()
    with open(tmp_path / "live" / EVENTS_FILE, "a") as f:
        f.write('{"sample": 26')
    events = recorded_events(tmp_path / "live")
    assert events == [{"sample": 2500, "field": "th_g", "value": 5.0}]
    after = _replay(two_contacts, events)
    # Th above the signal from 2.5 s: the second contact is coded as silence.
    assert after["contacts"] == before["contacts"][:1]
    assert [(e["sample"], e["was"], e["by"]) for e in after["controls"]] == \
        [(2500, 0.04, "replay")]
    # However the port chunked the bytes, the change lands on the same sample: the coder's
    # Th is the old one up to sample 2499, the new one from 2500, sample by sample.
    tap = ThTap()
    assert _replay(two_contacts, events, chunk_bytes=333, handlers=[tap])["contacts"] == \
        after["contacts"]
    th = np.concatenate(tap.th)
    assert set(th[:2500]) == {0.04} and set(th[2500:]) == {5.0}


def test_the_journal_of_a_run_replays_to_the_same_th_steps_at_the_same_samples(two_contacts,
                                                                               tmp_path):
    """A run's changes, journaled by the recorder as it handles them, submitted again by a
    replay (another chunking): the same Th at every sample, the same changes applied."""
    asked = [{"sample": 1800, "field": "th_g", "value": 0.08},
             {"sample": 2200, "field": "window_s", "value": 0.2},
             {"sample": 3050, "field": "th_g", "value": 0.02}]
    recorder = Recorder(tmp_path / "live", port="test://", wire_format="binary", baudrate=1)
    live_tap, replay_tap = ThTap(), ThTap()
    live = _replay(two_contacts, asked, handlers=[recorder, live_tap])
    recorder.close()
    journal = recorded_events(tmp_path / "live")
    assert sorted((e["sample"], e["field"], e["value"]) for e in journal) == \
        [(1800, "th_g", 0.08), (2200, "window_s", 0.2), (3050, "th_g", 0.02)]
    replayed = _replay(two_contacts, journal, chunk_bytes=333, handlers=[replay_tap])
    th_live, th_replayed = np.concatenate(live_tap.th), np.concatenate(replay_tap.th)
    assert np.array_equal(th_live, th_replayed)
    assert np.flatnonzero(np.diff(th_live)).tolist() == [1799, 3049]
    keep = ("sample", "field", "value", "was")
    assert [{k: e[k] for k in keep} for e in replayed["controls"]] == \
        [{k: e[k] for k in keep} for e in live["controls"]]
    assert replayed["contacts"] == live["contacts"]


def test_a_saved_view_reads_back_as_the_rate_map_the_read_out_takes(two_contacts, tmp_path):
    parts = build_online(NETWORK, ["preprocess.threshold=0.04"])
    view = LiveView(parts, save_dir=str(tmp_path / "views"))
    events = [{"sample": 2000, "field": "windows", "value": 2}]
    _replay(two_contacts, events, handlers=[view], parts=parts)
    view.flush()
    history = ViewHistory(view.config)
    while history.received < view.published:
        history.take(view._inbox.get(timeout=5))
    assert history.controls[0]["shown"] == {"window_s": 2 * parts.window_s}
    png = b"\x89PNG\r\n\x1a\n" + bytes(100)
    saved = save_view(history, 0.0, 4.0, png)
    ds = load_view(saved["data"])
    with open(saved["png"], "rb") as f:
        assert f.read() == png
    # The windows since the change, twice the network's: the second contact (3 s) is there.
    assert ds.rates.attrs["window_s"] == 2 * parts.window_s
    assert float(ds.rates.window_s[0]) == pytest.approx(2.0)
    kept = history.windows.rows[history.windows.rows[:, 0] >= 2.0]
    assert np.array_equal(ds.rates.values.T, kept[:, 2:])
    found = parts.detector.detect(ds.rates)         # the first contact's tail, the second
    assert [round(c.onset_s, 1) for c in found] == [2.0, 3.0]
    assert json.loads(ds.attrs["controls"])[0]["field"] == "windows"
    assert len(ds.x_g) > 0 and float(ds.t_s.max()) <= 4.0
    with pytest.raises(SpecError, match="png"):
        save_view(history, 0.0, 4.0, b"not a png")


def test_a_paint_report_counts_from_the_arrival_and_trusts_the_page_clock_only_between():
    parts = build_online(NETWORK, ["preprocess.threshold=0.04"])
    history = ViewHistory(LiveView(parts).config)
    history.take({"seq": 0, "counts": {}, "xy": (0, np.empty((0, 3))),
                  "coded": (0, np.empty((0, 3))), "events": [],
                  "windows": [(1.0, np.zeros(24), 1.0, 1.0, {}, 100.0, BASE)]})
    history.painted(1.0, 100.05, now=100.2, received_unix_s=100.03)
    history.painted(1.0, 99.0, now=100.2)           # a page clock behind: not below arrival
    history.painted(1.0, 500.0, now=100.2)          # ahead: not after the report came
    history.painted(2.0, 100.1, now=100.2)          # a window never shown: ignored
    assert np.allclose(history.display_delays_ms, [50.0, 0.0, 200.0])
    assert np.allclose(history.received_delays_ms, [30.0])   # in the page, not drawn yet
    assert history.display_latency()["n"] == 3


def _frame(seq: int, t_s: float) -> dict:
    """A view frame of 100 samples and one window starting at ``t_s`` (arrived now)."""
    first = int(round(t_s * 1000))
    samples = np.column_stack([np.arange(first, first + 100), np.full((100, 2), 2048)])
    return {"seq": seq, "counts": {}, "xy": (first, samples.astype(float)),
            "coded": (first, np.zeros((100, 3))), "events": [],
            "windows": [(t_s, np.ones(24), 1.0, 1.0, {}, 1.0, 0.1)]}


class PageSocket:
    """Stands in for a page's own socket (``/feed``): what its feed wrote, decoded."""

    def __init__(self):
        self.sent = []

    def write_message(self, message, binary=False):
        assert binary
        a = np.frombuffer(message, dtype=np.float64)
        kind, reset, live, high, n, width = a[:6]
        rows = a[6:].reshape(int(n), int(width))
        (name,) = (name for name, code in KINDS.items() if code == kind)
        self.sent.append({"kind": name, "reset": bool(reset), "live": bool(live),
                          "high": float(high), "t": rows[:, 0].round(6).tolist(), "rows": rows})
        written = concurrent.futures.Future()
        written.set_result(None)
        return written

    def of(self, kind: str) -> list[dict]:
        return [m for m in self.sent if m["kind"] == kind]

    def points(self, kind: str) -> int:
        """The points of ``kind`` the page holds: since its last reset."""
        held = 0
        for m in self.of(kind):
            held = len(m["t"]) + (0 if m["reset"] else held)
        return held

    def close(self):
        pass


def _page(history):
    """A page built for ``history`` with its socket open: (pull, feed, socket, document)."""
    from bokeh.document import Document

    doc = Document()
    build_page(history, doc)
    (callback,) = doc.session_callbacks
    (feed,) = history.feeds.values()
    socket = PageSocket()
    feed.attach(socket)
    return callback.callback, feed, socket, doc


def _painted(feed, t_s: float) -> None:
    feed.report(json.dumps({"t_s": t_s, "painted_unix_s": time.time()}))


def test_a_page_that_has_not_painted_the_last_column_gets_no_more_until_it_does():
    """Backpressure per page: updates wait (their points gather) while the browser has not
    painted the column sent last, so a slow browser does not queue up seconds of updates."""
    history = ViewHistory(LiveView(_parts()).config)
    update, feed, socket, _doc = _page(history)
    # The socket opens with the (empty) span of each plot.
    assert [(m["kind"], m["reset"], m["t"]) for m in socket.sent] == [
        ("map", True, []), ("xy", True, []), ("coded", True, [])]
    history.take(_frame(0, 0.0))
    update()
    assert socket.points("xy") == socket.points("coded") == 25
    (column,) = socket.of("map")[1:]
    assert column["t"] == [0.0] and not column["reset"] and np.all(column["rows"][:, 2:] == 1)
    in_g = history.config.to_g.transform(np.full((1, 2), 2048.0))       # the frame's counts
    assert np.allclose(socket.of("xy")[-1]["rows"][:, 1:], in_g)
    history.take(_frame(1, 0.1))
    update()                                        # column 0.0 not painted yet: waits
    assert socket.points("xy") == 25 and len(socket.of("map")) == 2
    # The paint report releases the held column at once, the column alone.
    _painted(feed, 0.0)
    assert socket.sent[-1]["kind"] == "map" and socket.sent[-1]["t"] == [0.1]
    assert socket.points("xy") == 25
    _painted(feed, 0.1)                             # nothing held back: nothing sent
    assert len(socket.of("map")) == 3
    update()                                        # the lines come with the periodic pull
    assert socket.points("xy") == socket.points("coded") == 50


def test_a_paused_page_gets_no_column_and_its_resume_or_reopened_socket_shows_the_span():
    history = ViewHistory(LiveView(_parts()).config)
    update, feed, socket, _doc = _page(history)
    history.take(_frame(0, 0.0))
    update()
    _painted(feed, 0.0)
    feed.mode["paused"] = True
    history.take(_frame(1, 0.1))
    history.take(_frame(2, 0.2))
    update()
    assert [m["t"] for m in socket.of("map")] == [[], [0.0]] and socket.points("xy") == 25
    feed.mode["paused"] = False
    feed.show(None)                                 # resumed: the kept span to the latest
    assert socket.of("map")[-1]["reset"] and socket.of("map")[-1]["t"] == [0.0, 0.1, 0.2]
    assert socket.points("xy") == 75
    feed.show(0.15)                                 # scrubbed back: the span to 0.15, not live
    last = socket.of("map")[-1]
    assert last["reset"] and not last["live"] and last["t"] == [0.0, 0.1]
    assert max(socket.of("xy")[-1]["t"]) <= 0.15
    again = PageSocket()                            # the page's socket reopened: its span
    feed.detach(socket)
    feed.attach(again)
    assert [m["kind"] for m in again.sent] == ["map", "xy", "coded"]
    assert again.of("map")[-1]["reset"] and again.of("map")[-1]["t"] == [0.0, 0.1]
    counted = history.display_latency()["n"]
    feed.report(b"not a report")                    # counted as nothing, refused as nothing
    assert history.display_latency()["n"] == counted == 1


def test_a_page_gone_while_a_message_was_on_its_way_is_forgotten_not_an_error():
    from tornado.websocket import WebSocketClosedError

    class Gone(PageSocket):
        def write_message(self, message, binary=False):
            super().write_message(message, binary)
            written = concurrent.futures.Future()
            written.set_exception(WebSocketClosedError())
            return written

    history = ViewHistory(LiveView(_parts()).config)
    _update, feed, _socket, _doc = _page(history)
    feed.attach(Gone())
    assert feed.socket is None                      # its first message failed: forgotten
    history.take(_frame(0, 0.0))
    assert feed.send_columns() and feed.socket is None


def test_the_page_text_refreshes_twice_a_second_and_at_once_for_a_contact(monkeypatch):
    """The counters and panels are text a person reads, refreshed TEXT_UPDATE_S apart; a
    contact is not held back."""
    import types

    from bokeh.document import Document

    from snn_antenna.bridge.view import page as page_module

    clock = [500.0]
    monkeypatch.setattr(page_module, "time", types.SimpleNamespace(monotonic=lambda: clock[0]))
    history = ViewHistory(LiveView(_parts()).config)
    doc = Document()
    build_page(history, doc)
    (callback,) = doc.session_callbacks
    text = doc.get_model_by_name("text")     # what the page's script writes into the Divs
    history.take(_frame(0, 0.0))
    clock[0] += page_module.TEXT_UPDATE_S
    callback.callback()
    assert "<b>stream time</b> 0.1 s" in text.data["counters"][0]
    history.take(_frame(1, 0.1))
    clock[0] += page_module.PAGE_UPDATE_MS / 1000
    callback.callback()                             # the plots move on, the text waits
    assert "<b>stream time</b> 0.1 s" in text.data["counters"][0]
    history.take({**_frame(2, 0.2), "events": [("onset", 0.25)]})
    clock[0] += page_module.PAGE_UPDATE_MS / 1000
    callback.callback()                             # a contact's onset: at once
    assert "<b>stream time</b> 0.3 s" in text.data["counters"][0]
    history.take(_frame(3, 0.3))
    clock[0] += page_module.TEXT_UPDATE_S
    callback.callback()
    assert "<b>stream time</b> 0.4 s" in text.data["counters"][0]


def test_a_window_goes_to_the_view_process_at_once_even_right_after_a_frame(monkeypatch):
    """Samples go in frames every FLUSH_S; a window does not wait for the next one: it goes at
    once (the delay a person sees), and windows in a burst at most every WINDOW_FLUSH_S."""
    import types

    from snn_antenna.bridge.view import view as view_module

    clock = [1000.0]
    monkeypatch.setattr(view_module, "time", types.SimpleNamespace(monotonic=lambda: clock[0]))
    parts = _parts()
    live = LiveView(parts)
    live.stream_started(parts, InputSchedule(parts.th_g, parts.window_s, 1000.0, 1000))
    live.handle(types.SimpleNamespace(counts={"frames": 1}, samples=[(0, 1.0, 2.0)]))
    clock[0] += view_module.FLUSH_S + 1e-6          # a frame of samples goes
    live.idle()
    assert live.published == 1
    clock[0] += 0.001
    live.window(Window(0.1, 100, 0.0, Published(0.0, 0.1, np.ones(24), None, 1.0, 1.0, 1.0)))
    assert live.published == 2                      # 1 ms after a frame: at once
    clock[0] += 0.001
    live.window(Window(0.2, 200, 0.0, Published(0.1, 0.1, np.ones(24), None, 1.0, 1.0, 1.0)))
    assert live.published == 2                      # 1 ms after a window: held back...
    clock[0] += view_module.WINDOW_FLUSH_S
    live.idle()
    assert live.published == 3                      # ... WINDOW_FLUSH_S, not FLUSH_S
    assert live._inbox.get(timeout=5)["seq"] == 0
    assert [len(live._inbox.get(timeout=5)["windows"]) for _ in range(2)] == [1, 1]
