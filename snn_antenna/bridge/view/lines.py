"""The live page's line plots (the antenna's axes, the coded input): canvases of their own,
drawn by a small script in the page from the points its socket brings (bridge/view/feed.py).

Why not Bokeh plots: each paint of a Bokeh plot costs its page's main thread ~10 ms (axes,
tick labels, CSS look-ups), and a page repaints them at every pull (the time axis moves).
Here each pull sends the page the new points (one binary message a plot), and the page's
script keeps the last ``keep`` of them and draws the points within the shared time axis
(``x_range``) with one path per line, holding only the points where the line turns, at most
once per animation frame whatever triggered it (new points, the axis moving with them, a
reload, a contact). The plots follow the axis as the page moves it (live, paused, scrubbed);
dragging a plot pans it (the wheel is left to scroll the page).
"""
from __future__ import annotations

from .feed import FEED_JS, KINDS
from .rate_map import FRAME

HEIGHT = 210

# Run on two triggers (``on``): "ready" (the document as the page loaded it: the page's socket
# opens) and "view" (the time axis or the contacts moved); new points come as messages. Each
# only asks for the next animation frame. FEED_JS (bridge/view/feed.py) comes first.
LINES_JS = """
const st = div._lines || (div._lines = {canvas: null, frame: 0, d: {t: []}});
st.draw = draw;
feed.take[kind] = take;
if (on === 'ready') { open_feed(); }
ask();

function ask() {
  if (!st.frame) { st.frame = requestAnimationFrame(() => { st.frame = 0; st.draw(); }); }
}
function take(a) {                      // a message (bridge/view/feed.py): header, then rows
  const reset = a[1] === 1, rows = a[4], width = a[5];
  if (reset || !st.d[columns[0]]) {
    st.d = {t: []};
    for (const c of columns) { st.d[c] = []; }
  }
  for (let k = 0, o = 6; k < rows; k++, o += width) {
    st.d.t.push(a[o]);
    for (let c = 0; c < columns.length; c++) { st.d[columns[c]].push(a[o + 1 + c]); }
  }
  const over = st.d.t.length - keep;
  if (over > keep / 4) {                // drop the oldest now and then, not at every message
    for (const c in st.d) { st.d[c].splice(0, over); }
  }
  ask();
}

function ticks(lo, hi, px) {            // round steps at least 30 px apart
  const span = hi - lo, raw = span / Math.max(1, px / 30);
  const p = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map(m => m * p).find(s => s >= raw) || 10 * p;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * span; v += step) {
    out.push(+v.toFixed(10));
  }
  return out;
}
function pan(canvas) {                  // a drag moves the axis with the pointer
  let from = null;
  canvas.addEventListener('pointerdown', e => { from = e.clientX;
                                                canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener('pointerup', () => { from = null; });
  canvas.addEventListener('pointermove', e => {
    if (from === null || !st.g) { return; }
    const dt = (e.clientX - from) / st.g.sx;
    from = e.clientX;
    x_range.setv({start: x_range.start - dt, end: x_range.end - dt});
  });
}
function draw() {
  if (!st.canvas || !st.canvas.isConnected) {
    const shown = window.Bokeh && Bokeh.index && Bokeh.index.find_one(div);
    st.canvas = shown && shown.markup_el ? shown.markup_el.querySelector('canvas') : null;
    if (st.canvas) { pan(st.canvas); }
  }
  const canvas = st.canvas;
  const host = canvas && canvas.getRootNode().host;     // the Div, stretched to the column
  if (!host || host.clientWidth <= 0) { return; }
  const dpr = window.devicePixelRatio || 1;
  const W = host.clientWidth, H = canvas.clientHeight;
  if (canvas.style.width !== W + 'px') { canvas.style.width = W + 'px'; }
  if (canvas.width !== Math.round(W * dpr) || canvas.height !== Math.round(H * dpr)) {
    canvas.width = Math.round(W * dpr); canvas.height = Math.round(H * dpr);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.fillStyle = 'white'; ctx.fillRect(0, 0, W, H);
  const x0 = frame.left, x1 = W - frame.right, y0 = frame.top, y1 = H - frame.bottom;
  const start = x_range.start, end = x_range.end, sx = (x1 - x0) / (end - start);
  st.g = {x0, start, sx};
  const d = st.d, t = d.t;
  // The points within the axis (and one either side, so the lines reach the frame's edges).
  let a = 0, b = t.length;
  while (a < b && t[a] < start) { a++; }
  while (b > a && t[b - 1] > end) { b--; }
  a = Math.max(0, a - 1); b = Math.min(t.length, b + 1);
  let lo = Infinity, hi = -Infinity;
  for (const s of series) {
    if (s.axis !== 'left') { continue; }
    const y = d[s.column] || [], sign = s.negated ? -1 : 1;
    for (let i = a; i < b; i++) {
      const v = sign * y[i];
      if (v < lo) { lo = v; }
      if (v > hi) { hi = v; }
    }
  }
  if (!(hi > lo)) { lo = isFinite(lo) ? lo - 0.5 : -1; hi = lo + 1; }
  const pad = 0.05 * (hi - lo);
  const ranges = {left: [lo - pad, hi + pad], right: right ? right.range : [lo - pad, hi + pad]};
  const yOf = (axis, v) => y1 - (v - ranges[axis][0]) / (ranges[axis][1] - ranges[axis][0])
                                * (y1 - y0);
  ctx.save();
  ctx.beginPath(); ctx.rect(x0, y0, x1 - x0, y1 - y0); ctx.clip();
  for (const s of series) {
    const y = d[s.column] || [], sign = s.negated ? -1 : 1;
    ctx.strokeStyle = s.colour; ctx.lineWidth = 1; ctx.globalAlpha = s.alpha;
    ctx.setLineDash(s.dashed ? [6, 4] : []);
    ctx.beginPath();
    for (let i = a; i < b; i++) {
      // A point whose value its neighbours share adds nothing to the path (a flat run, a held
      // step, the threshold between changes): only the points where the line turns are drawn.
      if (i > a && i < b - 1 && y[i] === y[i - 1] && (s.step || y[i] === y[i + 1])) { continue; }
      const x = x0 + (t[i] - start) * sx, v = yOf(s.axis, sign * y[i]);
      if (i === a) { ctx.moveTo(x, v); continue; }
      if (s.step) { ctx.lineTo(x, yOf(s.axis, sign * y[i - 1])); }
      ctx.lineTo(x, v);
    }
    ctx.stroke();
  }
  ctx.globalAlpha = 1; ctx.setLineDash([]);
  ctx.strokeStyle = contact_colour; ctx.lineWidth = 2;
  ctx.fillStyle = contact_colour; ctx.font = 'bold 13px sans-serif';
  ctx.textAlign = 'left'; ctx.textBaseline = 'top';
  const onsets = contacts.data.t, labels = contacts.data.label;
  for (let k = 0; k < onsets.length; k++) {
    if (onsets[k] < start || onsets[k] > end) { continue; }
    const x = x0 + (onsets[k] - start) * sx;
    ctx.beginPath(); ctx.moveTo(x, y0); ctx.lineTo(x, y1); ctx.stroke();
    ctx.fillText(labels[k], x + 4, y0 + 5);
  }
  ctx.restore();
  ctx.strokeStyle = '#e5e5e5'; ctx.lineWidth = 1;
  ctx.strokeRect(x0 + 0.5, y0 + 0.5, x1 - x0 - 1, y1 - y0 - 1);
  ctx.fillStyle = '#444'; ctx.font = '11px sans-serif';
  ctx.textAlign = 'center'; ctx.textBaseline = 'top';
  for (const s of ticks(start, end, x1 - x0)) {
    const x = x0 + (s - start) * sx;
    ctx.fillText(String(s), x, y1 + 4); ctx.fillRect(x, y1, 1, 3);
  }
  ctx.textAlign = 'right'; ctx.textBaseline = 'middle';
  for (const v of ticks(ranges.left[0], ranges.left[1], y1 - y0)) {
    const y = yOf('left', v);
    ctx.fillText(String(v), x0 - 5, y); ctx.fillRect(x0 - 3, y, 3, 1);
  }
  ctx.save(); ctx.translate(12, (y0 + y1) / 2); ctx.rotate(-Math.PI / 2);
  ctx.textAlign = 'center'; ctx.fillText(y_label, 0, 0); ctx.restore();
  if (right) {
    ctx.textAlign = 'left';
    for (const v of ticks(right.range[0], right.range[1], y1 - y0)) {
      const y = yOf('right', v);
      ctx.fillText(String(v), x1 + 5, y); ctx.fillRect(x1, y, 3, 1);
    }
    ctx.save(); ctx.translate(x1 + 48, (y0 + y1) / 2); ctx.rotate(-Math.PI / 2);
    ctx.textAlign = 'center'; ctx.fillText(right.label, 0, 0); ctx.restore();
  }
  ctx.font = 'bold 13px sans-serif'; ctx.textAlign = 'left'; ctx.textBaseline = 'top';
  ctx.fillText(title, x0, 6);
  ctx.font = '11px sans-serif'; ctx.textBaseline = 'middle';
  let ly = y0 + 6;                      // the legend in the right margin, beside the data
  const lx = right ? x1 + 58 : x1 + 8;
  for (const s of series) {
    if (!s.label) { continue; }
    ctx.strokeStyle = s.colour; ctx.globalAlpha = s.alpha; ctx.setLineDash(s.dashed ? [6, 4] : []);
    ctx.beginPath(); ctx.moveTo(lx, ly); ctx.lineTo(lx + 16, ly); ctx.stroke();
    ctx.globalAlpha = 1; ctx.setLineDash([]);
    ctx.fillText(s.label, lx + 20, ly); ly += 16;
  }
}
"""


def line_plot(doc, kind: str, columns: list, keep: int, x_range, contacts, *, page: str,
              title: str, y_label: str, series: list, right: dict | None = None,
              contact_colour: str, name: str):
    """A line plot on a canvas of its own, a Div named ``name``, of the points the page's
    socket brings for ``kind`` (bridge/view/feed.py: rows of t and ``columns``), the last
    ``keep`` of them kept. ``series``: dicts with ``column``, ``colour``, ``label`` (None: not
    in the legend), and optionally ``dashed``, ``negated`` (drawn at minus the column's
    value), ``step`` (held from each point to the next), ``axis`` ("left", scaled to the
    points shown; "right": ``right``'s fixed ``range``, labelled ``right["label"]``) and
    ``alpha``. ``page``: the page's token, which names its socket."""
    from bokeh.events import DocumentReady
    from bokeh.models import CustomJS, Div

    div = Div(text=f"<canvas style='display:block;width:100%;height:{HEIGHT}px;"
                   f"touch-action:none'></canvas>", sizing_mode="stretch_width", height=HEIGHT,
              name=name)
    series = [{"dashed": False, "negated": False, "step": False, "axis": "left", "alpha": 1.0,
               **s} for s in series]
    args = dict(x_range=x_range, contacts=contacts, div=div, series=series, right=right,
                title=title, y_label=y_label, frame=FRAME, contact_colour=contact_colour,
                kind=KINDS[kind], columns=list(columns), keep=int(keep), page=page)

    def draw(on: str) -> CustomJS:
        return CustomJS(args={**args, "on": on}, code=FEED_JS + LINES_JS)

    x_range.js_on_change("end", draw("view"))       # the page's code moves both ends
    x_range.js_on_change("start", draw("view"))     # ... setv moves both, one signal each
    contacts.js_on_change("data", draw("view"))
    doc.js_on_event(DocumentReady, draw("ready"))
    return div
