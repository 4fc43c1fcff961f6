"""What a live page's browser is made to draw (bridge/view/page.py, bridge/view/rate_map.py):
with three pages on two cores, the browsers' drawing is what delays a column on screen.

- Between two periodic pulls a new column goes to the page's own socket alone and changes
  nothing in the page's Bokeh document (the lines' points go on the socket too, at the pull):
  the time axis (whose move repaints every plot on the page) moves with the pull, ahead of the
  columns that come before the next one; no Div's text is ever changed (a Div's new text makes
  BokehJS lay the whole page out again): the counters and panels go through a data source the
  page's own script writes into their contained boxes.
- The rate map's script, run in Chromium on a bare canvas fed by a stand-in socket: it opens
  its socket at the page's address; however many messages and triggers a task brings, it
  draws once, in the next animation frame; a column added while the axes stand costs its own
  rectangles only, in the right place and colour; a moved axis redraws all; each live column
  is reported painted once, after its frame, on the socket.
- The page holds no Bokeh plot: its line plots are canvases drawn by their own script from
  the points the socket brings. That script, run in Chromium: however many triggers a task
  brings, it draws once, in the next animation frame; a line lands where its points say,
  within the shared time axis, its path holding only the points where it turns; dragging the
  plot pans that axis.
"""
import queue
import time

import pytest

from snn_antenna.bridge.view.history import ViewHistory
from snn_antenna.bridge.view.feed import FEED_JS
from snn_antenna.bridge.view.lines import LINES_JS
from snn_antenna.bridge.view.rate_map import FRAME, RATE_MAP_JS
from snn_antenna.bridge.view.view import LiveView
from test_live_controls import _frame, _page, _painted, _parts
from test_live_controls_chromium import CHROMIUM


def test_a_column_between_pulls_goes_to_the_socket_alone_and_no_div_text_changes(monkeypatch):
    import types

    from bokeh.models import Div, GlyphRenderer, Plot

    from snn_antenna.bridge.view import page as page_module

    clock = [500.0]
    monkeypatch.setattr(page_module, "time", types.SimpleNamespace(monotonic=lambda: clock[0]))
    history = ViewHistory(LiveView(_parts()).config)
    pull, feed, socket, doc = _page(history)
    assert not [*doc.select({"type": Plot}), *doc.select({"type": GlyphRenderer})]
    texts = [div for div in doc.select({"type": Div}) if div.name in ("counters", "decided")]
    assert len(texts) == 2 and all(div.styles["contain"] == "strict" for div in texts)
    changed = []
    doc.on_change(lambda event: hasattr(event, "model") and changed.append(
        (type(event.model).__name__, event.model.name, getattr(event, "attr", "data"))))
    history.take(_frame(0, 12.0))                   # past the 10 s the plots show
    clock[0] += page_module.TEXT_UPDATE_S
    pull()
    x_range = doc.get_model_by_name("time")
    at_pull = (x_range.start, x_range.end)
    assert at_pull[1] > history.t_s                 # the axis leads the stream
    assert {("ColumnDataSource", "text", "data"), ("Range1d", "time", "end")} <= set(changed)
    assert not [key for key in changed if key[0] == "ColumnDataSource" and key[1] != "text"]
    assert not [key for key in changed if key[0] == "Div"]
    assert socket.of("map")[-1]["t"] == [12.0] and socket.of("xy")[-1]["t"][-1] > 12.0
    _painted(feed, 12.0)
    changed.clear()
    scheduled = len(doc.session_callbacks)
    clock[0] += 0.01
    # A column ending half a window past the stream time of the pull: sent alone, at once.
    arrived = queue.Queue()
    arrived.put(_frame(1, 12.15))
    history.drain(arrived)
    assert socket.sent[-1]["t"] == [12.15] and not socket.sent[-1]["reset"]
    assert socket.sent[-1]["kind"] == "map" and socket.sent[-2]["kind"] != "map"
    assert (x_range.start, x_range.end) == at_pull
    assert changed == [] and len(doc.session_callbacks) == scheduled   # nor an axis move



def test_a_pull_due_just_before_a_column_waits_until_after_it():
    """A pull moves the axis and the browser redraws every plot for it: one due within
    COLUMN_GUARD_S of the next column goes COLUMN_GUARD_S after that column instead."""
    from snn_antenna.bridge.view.page import COLUMN_GUARD_S

    history = ViewHistory(LiveView(_parts()).config)
    pull, feed, socket, doc = _page(history)
    arrived = queue.Queue()
    arrived.put(_frame(0, 0.0))
    history.drain(arrived)                          # a column came in: sent at once
    _painted(feed, 0.0)
    history.take(_frame(1, 0.1))                    # points for the next pull
    sent = len(socket.sent)
    # The next column is due 30 ms after ``before``; the pull reads the clock a little later
    # (more on a busy machine): the wait it sets is due + guard less what elapsed by then.
    before = time.monotonic()
    history.column_at = before - history.window_s + 0.03
    pull()
    elapsed_ms = (time.monotonic() - before) * 1000
    assert len(socket.sent) == sent                 # nothing now...
    (later,) = [c for c in doc.session_callbacks if type(c).__name__ == "TimeoutCallback"]
    due_ms = (0.03 + COLUMN_GUARD_S) * 1000
    assert due_ms - elapsed_ms - 0.5 <= later.timeout <= due_ms + 0.5
    later.callback()                                # ... but just after that column
    assert {m["kind"] for m in socket.sent[sent:]} == {"map", "xy", "coded"}
    history.column_at -= 0.05                       # mid-way between columns: at once
    _painted(feed, 0.1)
    history.take(_frame(2, 0.2))
    sent = len(socket.sent)
    pull()
    assert {m["kind"] for m in socket.sent[sent:]} == {"map", "xy", "coded"}


def _blank(playwright, height: int):
    """Chromium and an empty page 1100 px wide at an http address (a page's socket opens
    relative to its address): (browser, page)."""
    browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True,
                                         args=["--no-sandbox"])
    page = browser.new_page(viewport={"width": 1100, "height": height}, device_scale_factor=1)
    page.route("http://view.test/", lambda route: route.fulfill(
        body="<body style='margin:0'></body>", content_type="text/html"))
    page.goto("http://view.test/")
    return browser, page


SETUP_JS = """([code, n, frame]) => {
  const host = document.createElement('div');
  host.style.cssText = 'display:block;width:1000px';
  document.body.appendChild(host);
  host.attachShadow({mode: 'open'}).innerHTML =
    "<canvas data-rate-map='p1' style='display:block;width:100%;height:260px'></canvas>";
  window.counted = {fillRect: 0};
  const fill = CanvasRenderingContext2D.prototype.fillRect;
  CanvasRenderingContext2D.prototype.fillRect = function (...args) {
    window.counted.fillRect++;
    return fill.apply(this, args);
  };
  window.reports = [];
  window.sockets = [];
  window.WebSocket = class {                 // the page's socket, as the view process's end
    constructor(url) { this.url = String(url); this.readyState = 1; sockets.push(this); }
    send(message) { reports.push(JSON.parse(message)); }
  };
  window.WebSocket.OPEN = 1;
  const div = {}, x_range = {start: 0, end: 10};
  const contacts = {data: {t: []}};
  const palette = Array.from({length: 256}, (_, i) => `rgb(${i},0,0)`);
  const run = new Function('x_range', 'contacts', 'div', 'n', 'page', 'palette', 'ticks',
                           'history_s', 'frame', 'title', 'contact_colour', 'kind', 'on', code);
  window.trigger = on => run(x_range, contacts, div, n, 'p1', palette, [], 10, frame, 'map',
                             '#d62728', 0, on);
  window.rows = (rows, reset) => {    // a message: kind, reset, live, high, rows, width, rows
    const a = [0, reset ? 1 : 0, 1, 10, rows.length, 2 + n];
    for (const [t, rate] of rows) { a.push(t, 0.1, ...Array(n).fill(rate)); }
    sockets[0].onmessage({data: new Float64Array(a).buffer});
  };
  window.x_range = x_range;
  window.painted = () => new Promise(done => requestAnimationFrame(() => setTimeout(done, 0)));
  window.red_at = (x, y) => host.shadowRoot.querySelector('canvas').getContext('2d')
    .getImageData(x, y, 1, 1).data[0];
}"""


@pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (Debian package `chromium`)")
def test_the_rate_map_draws_once_per_frame_and_a_new_column_alone():
    playwright = pytest.importorskip("playwright.sync_api")
    n = 24
    with playwright.sync_playwright() as p:
        browser, page = _blank(p, height=400)
        page.evaluate(SETUP_JS, [FEED_JS + RATE_MAP_JS, n, FRAME])

        def fills(script: str) -> int:
            return page.evaluate(f"""async () => {{
                const before = counted.fillRect;
                {script}
                await painted();
                return counted.fillRect - before;
            }}""")

        # The page loaded: its socket opens at the page's own address, once.
        fills("trigger('ready'); trigger('ready');")
        assert page.evaluate("sockets.map(s => s.url)") == ["ws://view.test/feed?page=p1"]
        # 50 columns (0-5 s) and the axis moving with them, all in one task: one drawing.
        once = fills("rows(Array.from({length: 50}, (_, i) => [i / 10, 6]), true);"
                     "trigger('view'); trigger('view');")
        full = fills("trigger('view');")
        assert once == full > 50 * n
        assert [r["t_s"] for r in page.evaluate("reports")] == [4.9]
        # A column while the axes stand: its own rectangles, where and as it should be.
        assert fills("rows([[5.0, 4]], false);") == n
        x0, x1 = FRAME["left"], 1000 - FRAME["right"]
        x = int(x0 + 5.05 * (x1 - x0) / 10)
        y = (FRAME["top"] + 260 - FRAME["bottom"]) // 2
        assert page.evaluate(f"red_at({x}, {y})") == round(4 / 10 * 255)      # the new one
        assert page.evaluate(f"red_at({x - 10}, {y})") == round(6 / 10 * 255)
        reports = page.evaluate("reports")
        assert [r["t_s"] for r in reports] == [4.9, 5.0]
        assert all(r["received_unix_s"] <= r["painted_unix_s"] for r in reports)
        # The axis moved: everything again.
        assert fills("x_range.start = 0.5; x_range.end = 10.5; trigger('view');") > 40 * n
        assert len(page.evaluate("reports")) == 2           # no new column: nothing reported
        # A reset with no rows: an empty map (white where the columns were).
        fills("rows([], true);")
        assert page.evaluate(f"red_at({x}, {y})") == page.evaluate(f"red_at({x - 10}, {y})") == 255
        browser.close()


LINES_SETUP_JS = """([code, frame]) => {
  const host = document.createElement('div');
  host.style.cssText = 'display:block;width:1000px';
  document.body.appendChild(host);
  host.attachShadow({mode: 'open'}).innerHTML =
    "<canvas style='display:block;width:100%;height:210px'></canvas>";
  window.Bokeh = {index: {find_one: () => ({markup_el: host.shadowRoot})}};
  window.counted = {stroke: 0, lineTo: 0};
  const stroke = CanvasRenderingContext2D.prototype.stroke;
  CanvasRenderingContext2D.prototype.stroke = function (...args) {
    window.counted.stroke++;
    return stroke.apply(this, args);
  };
  const lineTo = CanvasRenderingContext2D.prototype.lineTo;
  CanvasRenderingContext2D.prototype.lineTo = function (...args) {
    window.counted.lineTo++;
    return lineTo.apply(this, args);
  };
  window.sockets = [];
  window.WebSocket = class {
    constructor(url) { this.url = String(url); sockets.push(this); }
  };
  const x_range = {start: 0, end: 10, setv(o) { Object.assign(this, o); }};
  const contacts = {data: {t: [], label: []}};
  const series = [{column: 'x', colour: 'rgb(0,0,255)', label: 'x', dashed: false,
                   negated: false, step: false, axis: 'left', alpha: 1},
                  {column: 'y', colour: 'rgb(255,0,0)', label: 'y', dashed: false,
                   negated: false, step: false, axis: 'left', alpha: 1}];
  const div = {};
  const run = new Function('x_range', 'contacts', 'div', 'series', 'right', 'title',
                           'y_label', 'frame', 'contact_colour', 'kind', 'columns', 'keep',
                           'page', 'on', code);
  window.trigger = on => run(x_range, contacts, div, series, null, 'lines', 'g', frame,
                             '#d62728', 1, ['x', 'y'], 2501, 'p1', on);
  window.points = () => {   // a message of 1,001 points: x 0 until 5 s, 1 after; y 0
    const a = [1, 1, 1, 0, 1001, 3];
    for (let i = 0; i <= 1000; i++) { a.push(i / 100, i < 500 ? 0 : 1, 0); }
    sockets[0].onmessage({data: new Float64Array(a).buffer});
  };
  window.x_range = x_range;
  window.canvas = host.shadowRoot.querySelector('canvas');
  window.painted = () => new Promise(done => requestAnimationFrame(() => setTimeout(done, 0)));
  window.colour = (x, y) => {       // a line's colour within a pixel of (x, y), if any
    const d = window.canvas.getContext('2d').getImageData(x, y - 1, 1, 3).data;
    for (let i = 0; i < 12; i += 4) {
      if (d[i] > 150 && d[i + 1] < 120 && d[i + 2] < 120) { return 'red'; }
      if (d[i + 2] > 150 && d[i] < 120 && d[i + 1] < 120) { return 'blue'; }
    }
    return null;
  };
}"""


@pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (Debian package `chromium`)")
def test_the_line_plots_draw_once_per_frame_on_the_shared_axis_and_pan_it():
    playwright = pytest.importorskip("playwright.sync_api")
    with playwright.sync_playwright() as p:
        browser, page = _blank(p, height=300)
        page.evaluate(LINES_SETUP_JS, [FEED_JS + LINES_JS, FRAME])
        strokes = page.evaluate("""async () => {
            trigger('ready'); points(); trigger('view'); trigger('view');
            await painted();
            return counted.stroke;
        }""")
        assert strokes == 2 * 2                 # one drawing: each line and its legend entry
        # 1,001 points a line, flat but for x's step at 5 s: only the turns are in the paths
        # (x: 0 → 4.99 s, 5 s → 10 s; y: 0 → 10 s), and a line in each legend entry.
        assert page.evaluate("counted.lineTo") == 3 + 1 + 2
        x0, x1 = FRAME["left"], 1000 - FRAME["right"]
        y0, y1 = FRAME["top"], 210 - FRAME["bottom"]
        pad = 0.05 * (y1 - y0) / 1.1            # the left axis spans the points shown, ±5 %
        at = lambda t_s: round(x0 + t_s * (x1 - x0) / 10)          # noqa: E731
        assert page.evaluate(f"colour({at(2.5)}, {round(y1 - pad)})") == "red"    # y over x
        assert page.evaluate(f"colour({at(7.5)}, {round(y0 + pad)})") == "blue"   # x at 1
        assert page.evaluate(f"colour({at(7.5)}, {round(y1 - pad)})") == "red"
        assert page.evaluate(f"colour({at(2.5)}, {round(y0 + pad)})") is None
        # Dragging the plot 82 px to the right shows one second earlier.
        box = page.evaluate("(() => { const r = canvas.getBoundingClientRect();"
                            " return [r.left, r.top]; })()")
        page.mouse.move(box[0] + 500, box[1] + 100)
        page.mouse.down()
        page.mouse.move(box[0] + 500 + (x1 - x0) / 10, box[1] + 100)
        page.mouse.up()
        assert page.evaluate("[x_range.start, x_range.end]") == pytest.approx([-1, 9])
        browser.close()
