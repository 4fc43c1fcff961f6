"""The live page's rate map: a canvas of its own, drawn by a small script in the page, fed
over the page's own socket (bridge/view/feed.py).

Why not a Bokeh plot: each paint of a Bokeh plot costs its page's main thread ~10 ms (axes,
tick labels, CSS look-ups), and with three pages on two cores the browsers' drawing is what
delays a column. The page's script keeps the columns it shows and paints them with
``fillRect`` (one rectangle per resonator and window). It draws at most once per animation
frame, whatever triggered it, and while the axes stand only the columns added since (a column
then costs its page one rectangle per resonator, not the whole map). The plot follows the
page's shared time axis (``x_range``: paused, scrubbed, panned), marks the contacts' onsets,
and reports each live column it painted back on the socket.
"""
from __future__ import annotations

from .feed import FEED_JS, KINDS

HEIGHT = 260
TITLE = "Rate map: resonators (tuning frequency) × time"

# The plot's frame inside each of the page's canvases, in CSS pixels: the same on all of them
# lines their time axes up (bridge/view/lines.py).
FRAME = {"left": 70, "right": 110, "top": 26, "bottom": 40}

# Run on two triggers (``on``): "ready" (the document as the page loaded it: the page's socket
# opens, and its first message is the kept span) and "view" (the time axis or the contacts
# changed). FEED_JS (bridge/view/feed.py) comes first.
RATE_MAP_JS = """
const st = div._rate_map || (div._rate_map = {t: [], w: [], r: [], high: 10, live: true,
                                               canvas: null, dirty: true});
st.draw = draw;
feed.take[kind] = take;
if (on === 'ready') { open_feed(); }
if (on === 'view') { st.dirty = true; }
ask();

// One drawing per animation frame, whatever triggered it (new rows and the time axis moving
// with them come together): each trigger only asks for the next frame's.
function ask() {
  if (!st.frame) { st.frame = requestAnimationFrame(() => { st.frame = 0; st.draw(); }); }
}
function take(a) {                      // a message (bridge/view/feed.py): header, then rows
  const reset = a[1] === 1, live = a[2] === 1, rows = a[4], width = a[5];
  const clear = () => { st.t = []; st.w = []; st.r = []; st.dirty = true; };
  if (reset) { clear(); }
  for (let k = 0, o = 6; k < rows; k++, o += width) {
    if (st.t.length && a[o] <= st.t[st.t.length - 1]) { clear(); }   // a new stream
    st.t.push(a[o]); st.w.push(a[o + 1]); st.r.push(a.subarray(o + 2, o + width));
  }
  st.high = a[3]; st.live = live;
  const oldest = st.t.length ? st.t[st.t.length - 1] - 2 * history_s : 0;
  let k = 0;
  while (k < st.t.length && st.t[k] + st.w[k] < oldest) { k++; }
  if (k) { st.t.splice(0, k); st.w.splice(0, k); st.r.splice(0, k); }
  // The columns reached this page's document; the latest live one is reported once painted.
  if (live && rows) {
    st.report = {t_s: st.t[st.t.length - 1], received_unix_s: Date.now() / 1000};
  }
  ask();
}
function find(root) {                   // Bokeh renders a Div's text in a shadow root
  for (const el of root.querySelectorAll('*')) {
    if (el.tagName === 'CANVAS' && el.dataset.rateMap === page) { return el; }
    if (el.shadowRoot) { const found = find(el.shadowRoot); if (found) { return found; } }
  }
  return null;
}
function column(ctx, g, j) {            // the window j's rectangles, one per resonator
  const t = st.t[j], w = st.w[j];
  if (t + w < g.start || t > g.end) { return; }
  const a = Math.max(g.x0, Math.floor(g.x0 + (t - g.start) * g.sx));
  const b = Math.min(g.x1, Math.ceil(g.x0 + (t + w - g.start) * g.sx));
  const r = st.r[j], top = palette.length - 1;
  for (let i = 0; i < n; i++) {
    ctx.fillStyle = palette[Math.max(0, Math.min(top, Math.round(r[i] / g.high * top)))];
    ctx.fillRect(a, g.y1 - (i + 1) * g.rowH, b - a, g.rowH + 0.5);
  }
}
function marks(ctx, g, from_t, to_t) {  // the contacts' onsets within [from_t, to_t]
  ctx.strokeStyle = contact_colour; ctx.lineWidth = 2;
  for (const onset of contacts.data.t) {
    if (onset < Math.max(from_t, g.start) || onset > Math.min(to_t, g.end)) { continue; }
    const x = g.x0 + (onset - g.start) * g.sx;
    ctx.beginPath(); ctx.moveTo(x, g.y0); ctx.lineTo(x, g.y1); ctx.stroke();
  }
}
function draw() {
  if (!st.canvas || !st.canvas.isConnected) { st.canvas = find(document); st.dirty = true; }
  const canvas = st.canvas;
  const host = canvas && canvas.getRootNode().host;     // the Div, stretched to the column
  if (host && host.clientWidth > 0) {
    const dpr = window.devicePixelRatio || 1;
    const W = host.clientWidth, H = canvas.clientHeight;
    const high = st.high > 0 ? st.high : 1;
    const key = [W, H, dpr, x_range.start, x_range.end, high].join();
    const ctx = canvas.getContext('2d');
    const last = st.t.length ? st.t[st.t.length - 1] : -Infinity;
    if (!st.dirty && key === st.key) {
      // Only columns were added, the axes stand: draw those alone (and the marks over them).
      let j = st.t.length;
      while (j > 0 && st.t[j - 1] > st.drawn_t) { j--; }
      for (let k = j; k < st.t.length; k++) { column(ctx, st.g, k); }
      if (j < st.t.length) { marks(ctx, st.g, st.t[j], last + st.w[st.t.length - 1]); }
    } else {
      if (canvas.style.width !== W + 'px') { canvas.style.width = W + 'px'; }
      if (canvas.width !== Math.round(W * dpr) || canvas.height !== Math.round(H * dpr)) {
        canvas.width = Math.round(W * dpr); canvas.height = Math.round(H * dpr);
      }
      ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
      ctx.fillStyle = 'white'; ctx.fillRect(0, 0, W, H);
      const x0 = frame.left, x1 = W - frame.right;
      const y0 = frame.top, y1 = H - frame.bottom;
      const start = x_range.start, end = x_range.end, sx = (x1 - x0) / (end - start);
      const g = {x0, x1, y0, y1, start, end, sx, high, rowH: (y1 - y0) / n};
      for (let j = 0; j < st.t.length; j++) { column(ctx, g, j); }
      ctx.strokeStyle = '#e5e5e5'; ctx.lineWidth = 1;
      ctx.strokeRect(x0 + 0.5, y0 + 0.5, x1 - x0 - 1, y1 - y0 - 1);
      marks(ctx, g, start, end);
      const rowH = g.rowH, top = palette.length - 1;
      ctx.fillStyle = '#444'; ctx.font = '11px sans-serif';
      ctx.textAlign = 'right'; ctx.textBaseline = 'middle';
      for (const [i, label] of ticks) { ctx.fillText(label, x0 - 5, y1 - (i + 0.5) * rowH); }
      ctx.textAlign = 'center'; ctx.textBaseline = 'top';
      const step = [0.5, 1, 2, 5, 10, 20, 60].find(s => s * sx >= 50) || 60;
      for (let s = Math.ceil(start / step) * step; s <= end; s += step) {
        const x = x0 + (s - start) * sx;
        ctx.fillText(String(+s.toFixed(2)), x, y1 + 4);
        ctx.fillRect(x, y1, 1, 3);
      }
      ctx.fillText('stream time (s)', (x0 + x1) / 2, y1 + 20);
      ctx.save(); ctx.translate(12, (y0 + y1) / 2); ctx.rotate(-Math.PI / 2);
      ctx.fillText('resonator tuning (Hz)', 0, 0); ctx.restore();
      ctx.font = 'bold 13px sans-serif'; ctx.textAlign = 'left';
      ctx.fillText(title, x0, 6);
      const bx = x1 + 14, bw = 12;      // the colour bar: 0 at the bottom, high at the top
      for (let p = 0; p <= top; p++) {
        ctx.fillStyle = palette[p];
        const y = y1 - (p + 1) * (y1 - y0) / (top + 1);
        ctx.fillRect(bx, y, bw, (y1 - y0) / (top + 1) + 0.5);
      }
      ctx.fillStyle = '#444'; ctx.font = '11px sans-serif';
      ctx.textAlign = 'left'; ctx.textBaseline = 'middle';
      ctx.fillText(String(+high.toFixed(1)), bx + bw + 4, y0 + 4);
      ctx.fillText('0', bx + bw + 4, y1 - 4);
      ctx.save(); ctx.translate(bx + bw + 40, (y0 + y1) / 2); ctx.rotate(-Math.PI / 2);
      ctx.textAlign = 'center'; ctx.fillText('rate (spikes/s)', 0, 0); ctx.restore();
      st.g = g; st.key = key; st.dirty = false;
    }
    st.drawn_t = last;
  }
  // A live column reported once painted: this runs in an animation frame, whose paint
  // follows it, and a task queued from it runs once that paint is done.
  const report = st.report;
  st.report = null;
  if (report) {
    setTimeout(() => {
      if (feed.socket && feed.socket.readyState === WebSocket.OPEN) {
        feed.socket.send(JSON.stringify({...report, painted_unix_s: Date.now() / 1000}));
      }
    }, 0);
  }
}
"""


def rate_map(doc, view, x_range, contacts, page: str, colour: str):
    """The rate map of one page (the Bokeh document ``doc``): the Div holding its canvas.
    ``contacts``: the page's contact marks (a source with ``t``); ``page``: the page's token,
    which names its socket (bridge/view/feed.py)."""
    from bokeh.events import DocumentReady
    from bokeh.models import CustomJS, Div
    from bokeh.palettes import Viridis256

    n = len(view.neuron_hz)
    div = Div(text=f"<canvas data-rate-map='{page}' style='display:block;width:100%;"
                   f"height:{HEIGHT}px'></canvas>", sizing_mode="stretch_width", height=HEIGHT,
              name="rate_map")
    ticks = [[i, f"{view.neuron_hz[i]:.1f}"] for i in range(0, n, max(1, n // 8))]
    args = dict(x_range=x_range, contacts=contacts, div=div, n=n, page=page,
                palette=list(Viridis256), ticks=ticks, history_s=view.history_s, frame=FRAME,
                title=TITLE, contact_colour=colour, kind=KINDS["map"])

    def draw(on: str) -> CustomJS:
        return CustomJS(args={**args, "on": on}, code=FEED_JS + RATE_MAP_JS)

    x_range.js_on_change("end", draw("view"))       # the page's code moves both ends
    x_range.js_on_change("start", draw("view"))     # ... a pan or zoom may move one
    contacts.js_on_change("data", draw("view"))
    doc.js_on_event(DocumentReady, draw("ready"))   # the socket opens with the page
    return div
