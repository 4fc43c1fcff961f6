"""What a live page's browser is made to draw (bridge/view/page.py, bridge/view/rate_map.py):
with three pages on two cores, the browsers' drawing is what delays a column on screen.

- Between two periodic pulls a new column changes the rate map's source alone: the time axis
  (whose move repaints every plot on the page) moves with the pull, ahead of the columns that
  come before the next one; no Div's text is ever changed (a Div's new text makes BokehJS lay
  the whole page out again): the counters and panels go through a data source the page's own
  script writes into them.
- The rate map's script, run in Chromium on a bare canvas: however many triggers a task
  brings, it draws once, in the next animation frame; a column added while the axes stand
  costs its own rectangles only, in the right place and colour; a moved axis redraws all;
  each live column is reported painted once, after its frame.
"""
import queue
import time

import pytest

from snn_antenna.bridge.view.history import ViewHistory
from snn_antenna.bridge.view.page import build_page
from snn_antenna.bridge.view.rate_map import FRAME, RATE_MAP_JS
from snn_antenna.bridge.view.view import LiveView
from test_live_controls import _frame, _parts
from test_live_controls_chromium import CHROMIUM


def test_a_column_between_pulls_changes_the_map_alone_and_no_div_text_changes(monkeypatch):
    import types

    from bokeh.document import Document
    from bokeh.models import CustomJS

    from snn_antenna.bridge.view import page as page_module

    clock = [500.0]
    monkeypatch.setattr(page_module, "time", types.SimpleNamespace(monotonic=lambda: clock[0]))
    history = ViewHistory(LiveView(_parts()).config)
    doc = Document()
    build_page(history, doc)
    (pull,) = doc.session_callbacks
    token = next(m.args["page"] for m in doc.select({"type": CustomJS}) if "page" in m.args)
    changed = []
    doc.on_change(lambda event: hasattr(event, "model") and changed.append(
        (type(event.model).__name__, event.model.name, getattr(event, "attr", "data"))))
    history.take(_frame(0, 12.0))                   # past the 10 s the plots show
    clock[0] += page_module.TEXT_UPDATE_S
    pull.callback()
    x_range = doc.get_model_by_name("time")
    at_pull = (x_range.start, x_range.end)
    assert at_pull[1] > history.t_s                 # the axis leads the stream
    assert {("ColumnDataSource", "text", "data"), ("ColumnDataSource", "xy", "data"),
            ("ColumnDataSource", "map", "data"), ("Range1d", "time", "end")} <= set(changed)
    assert not [key for key in changed if key[0] == "Div"]
    history.painted(12.0, time.time(), page=token)
    changed.clear()
    clock[0] += 0.01
    # A column ending half a window past the stream time of the pull: pushed alone.
    arrived = queue.Queue()
    arrived.put(_frame(1, 12.15))
    history.drain(arrived)
    (push,) = (c for c in doc.session_callbacks if c is not pull)
    push.callback()
    assert doc.get_model_by_name("map").data["t"] == [12.15]
    assert (x_range.start, x_range.end) == at_pull
    assert changed == [("ColumnDataSource", "map", "data")]


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
  window.fetch = (url, options) => {
    window.reports.push(JSON.parse(options.body));
    return Promise.resolve();
  };
  const div = {}, source = {data: {}}, x_range = {start: 0, end: 10};
  const contacts = {data: {t: []}};
  const palette = Array.from({length: 256}, (_, i) => `rgb(${i},0,0)`);
  const run = new Function('source', 'x_range', 'contacts', 'div', 'n', 'page', 'palette',
                           'ticks', 'history_s', 'frame', 'title', 'contact_colour', 'align',
                           'on', code);
  window.trigger = on => run(source, x_range, contacts, div, n, 'p1', palette, [], 10, frame,
                             'map', '#d62728', null, on);
  window.rows = (rows, reset) => {
    source.data = {t: rows.map(r => r[0]), w: rows.map(() => 0.1),
                   rates: rows.map(r => new Float32Array(n).fill(r[1])),
                   high: rows.map(() => 10), live: rows.map(() => true),
                   reset: rows.map(() => reset)};
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
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                    args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1100, "height": 400},
                                device_scale_factor=1)
        page.set_content("<body style='margin:0'></body>")
        page.evaluate(SETUP_JS, [RATE_MAP_JS, n, FRAME])

        def fills(script: str) -> int:
            return page.evaluate(f"""async () => {{
                const before = counted.fillRect;
                {script}
                await painted();
                return counted.fillRect - before;
            }}""")

        # 50 columns (0-5 s) and the axis moving with them, all in one task: one drawing.
        once = fills("rows(Array.from({length: 50}, (_, i) => [i / 10, 6]), true);"
                     "trigger('data'); trigger('view'); trigger('view');")
        full = fills("trigger('view');")
        assert once == full > 50 * n
        assert [r["t_s"] for r in page.evaluate("reports")] == [4.9]
        # A column while the axes stand: its own rectangles, where and as it should be.
        assert fills("rows([[5.0, 4]], false); trigger('data');") == n
        x0, x1 = FRAME["left"], 1000 - FRAME["right"]
        x = int(x0 + 5.05 * (x1 - x0) / 10)
        y = (FRAME["top"] + 260 - FRAME["bottom"]) // 2
        assert page.evaluate(f"red_at({x}, {y})") == round(4 / 10 * 255)      # the new one
        assert page.evaluate(f"red_at({x - 10}, {y})") == round(6 / 10 * 255)
        assert [r["t_s"] for r in page.evaluate("reports")] == [4.9, 5.0]
        # The axis moved: everything again.
        assert fills("x_range.start = 0.5; x_range.end = 10.5; trigger('view');") > 40 * n
        assert len(page.evaluate("reports")) == 2           # no new column: nothing reported
        browser.close()
