"""The live page's hands on the controls (bridge/view/page.py lays them out): pause and resume the
display, scrub back through the kept minute, change Th, the rate-map window and (on a network
whose gate or CPG reads one) the robot's speed command, save the view.

Pausing is the page's own business (its plots stop following; the pipeline and the other pages
go on). Th and the window go through the view process's one parser to the pipeline
(bridge/online/controls.py), which applies them at a window boundary and journals them; the page
shows what was asked and what was applied. A small script draws the page's canvases (the
rate map's among them, bridge/view/rate_map.py) into one PNG and posts it to ``/save``.
"""
from __future__ import annotations

import html

from ...core.errors import SpecError

# Bokeh draws each plot on canvases inside shadow roots: walk them, draw each where it sits.
SAVE_JS = """
function canvases(root, out) {
  for (const el of root.querySelectorAll('*')) {
    if (el.tagName === 'CANVAS' && el.width > 0 && el.height > 0) { out.push(el); }
    if (el.shadowRoot) { canvases(el.shadowRoot, out); }
  }
  return out;
}
const list = canvases(document, []);
const rects = list.map(c => c.getBoundingClientRect());
const left = Math.min(...rects.map(r => r.left)), top = Math.min(...rects.map(r => r.top));
const out = document.createElement('canvas');
out.width = Math.max(...rects.map(r => r.right)) - left;
out.height = Math.max(...rects.map(r => r.bottom)) - top;
const ctx = out.getContext('2d');
ctx.fillStyle = 'white';
ctx.fillRect(0, 0, out.width, out.height);
list.forEach((c, i) => ctx.drawImage(c, rects[i].left - left, rects[i].top - top,
                                     rects[i].width, rects[i].height));
status.text = 'saving…';
out.toBlob(blob => {
  fetch(`save?start=${x_range.start}&end=${x_range.end}`,
        {method: 'POST', headers: {'Content-Type': 'image/png'}, body: blob})
    .then(r => r.json())
    .then(j => { status.text = j.saved ? `saved ${j.saved.png} and ${j.saved.data}`
                                       : `not saved: ${j.error}`; })
    .catch(e => { status.text = 'not saved: ' + e; });
}, 'image/png');
"""


def control_widgets(view, mode: dict, reload, x_range):
    """The controls row and its status line. ``mode``: this page's {"paused", "back_s"};
    ``reload(end_s)``: show the kept history up to ``end_s`` (None: the latest, live)."""
    from bokeh.layouts import row
    from bokeh.models import Button, CustomJS, Div, Slider, TextInput

    pause = Button(label="Pause display", name="pause", width=130)
    back = Slider(start=0, end=max(view.keep_s - view.history_s, 0.5), value=0, step=0.5,
                  title="seconds back (paused)", name="scrub", width=200, disabled=True)
    th = TextInput(value=f"{view.th_g:g}", title="Th (g)", name="th", width=90)
    apply_th = Button(label="Apply Th", name="apply_th", width=90)
    window = TextInput(value=f"{view.window_s:g}", title="rate-map window (s)", name="window",
                       width=130)
    apply_window = Button(label="Apply window", name="apply_window", width=110)
    speed = apply_speed = None
    if view.config.speed_range_cm_s is not None:
        speed = TextInput(value=f"{view.config.speed_cm_s:g}", title="speed (cm/s)",
                          name="speed", width=90)
        apply_speed = Button(label="Apply speed", name="apply_speed", width=100)
    save = Button(label="Save view", name="save", width=100)
    status = Div(text="", name="status", width=600, height=40)

    def toggle() -> None:
        mode["paused"] = not mode["paused"]
        pause.label = "Resume display" if mode["paused"] else "Pause display"
        back.disabled = not mode["paused"]
        if mode["paused"]:
            mode["frozen_end"] = max(view.t_s, view.history_s)
        else:
            back.value = 0
            reload(None)
        status.text = ("display paused (the stream goes on)" if mode["paused"]
                       else "display live")

    def scrub(_attr, _old, value) -> None:
        if mode["paused"]:
            reload(mode["frozen_end"] - value)

    def ask(field: str, text: str) -> None:
        try:
            value = float(text)
        except ValueError:
            value = text
        try:
            asked = view.request({field: value})
        except SpecError as exc:
            status.text = f"<span style='color:#d62728'>{html.escape(str(exc))}</span>"
            return
        shown = {"th_g": f"Th {value:g} g", "window_s": f"window {value:g} s",
                 "speed_cm_s": f"speed {value:g} cm/s"}[field]
        status.text = (f"asked {shown} at {asked['asked_t_s']:.2f} s: it applies at the next "
                       "window boundary")

    pause.on_click(toggle)
    back.on_change("value", scrub)
    apply_th.on_click(lambda: ask("th_g", th.value))
    apply_window.on_click(lambda: ask("window_s", window.value))
    save.js_on_click(CustomJS(args={"status": status, "x_range": x_range}, code=SAVE_JS))
    speed_widgets = []
    if speed is not None:
        apply_speed.on_click(lambda: ask("speed_cm_s", speed.value))
        speed_widgets = [speed, apply_speed]
    bar = row(pause, back, th, apply_th, window, apply_window, *speed_widgets, save,
              sizing_mode="stretch_width")
    return bar, status


def controls_html(view) -> str:
    """The changes applied so far (the latest five) and those still waiting for a boundary."""
    items = []
    for event in view.controls[-5:]:
        if event["field"] == "th_g":
            what = f"Th {event['was']:.3g} → <b>{event['value']:.3g} g</b>"
        elif event["field"] == "speed_cm_s":
            what = f"speed {event['was']:.3g} → <b>{event['value']:.3g} cm/s</b>"
        else:
            what = f"window {event['was']:.3g} → <b>{event['shown']['window_s']:.3g} s</b>"
        items.append(f"<li>{event['t_s']:.2f} s: {what} ({event['by']})</li>")
    for asked in view.requested:
        unit = {"th_g": "g", "speed_cm_s": "cm/s"}.get(asked["field"], "× the network's window")
        items.append(f"<li>asked: {asked['field']} {asked['value']:g} {unit} (waiting for a "
                     "window boundary)</li>")
    listing = f"<ul style='margin:2px 0'>{''.join(items)}</ul>" if items else " none yet"
    return (f"<div data-panel='controls' style='font-family:sans-serif;font-size:12px'>"
            f"<b>Control changes</b>{listing}</div>")
