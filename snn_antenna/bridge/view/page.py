"""The live view's browser page: the line plots (the antenna's axes, the coded input;
bridge/view/lines.py) and the rate map (bridge/view/rate_map.py), each a canvas of its own drawn
by the page's script, the controls and the text around them, fed from the view process's history
(:class:`~snn_antenna.bridge.view.view.history.ViewHistory`).

Each open page is one Bokeh session (the time axis, the controls, the text) and a socket of its
own (bridge/view/feed.py) that brings its plots their data: the rate map's columns as they
arrive, the lines' new points at each periodic pull (every ``PAGE_UPDATE_MS``). All of it
runs in the view's own process, so a page that falls behind, closes or is reloaded costs the
pipeline nothing.
"""
from __future__ import annotations

import time
import uuid
from .feed import PageFeed
from .page_controls import control_widgets
from .rate_map import rate_map
from .lines import line_plot
from .page_controls import controls_html


# Each page pulls new points 5 times a second (a new rate-map column goes to it on arrival:
# feed.PageFeed). Each pull moves the time axis and redraws the page's three canvases; the
# lines move in steps of a fiftieth of the 10 s they show.
PAGE_UPDATE_MS = 200
# A pull moves the time axis, and the browser redraws all of the page's plots for it: a column
# that came meanwhile would wait for that. A pull due this close before the next column is
# expected waits until this long after it: pulls fall between columns.
COLUMN_GUARD_S = 0.04
# The counters and panels twice a second (a contact at once): a person reads them no faster.
TEXT_UPDATE_S = 0.5
# Their text is written into the Divs' own elements by the page: a change of a Div's ``text``
# makes BokehJS lay the whole page out again and repaint every plot on it. Each box is
# contained (CSS ``contain: strict``, its size fixed): new text lays out that box alone, not
# the page around it (~20 ms of a page's main thread otherwise, twice a second).
TEXT_JS = """
for (const div of divs) {
  const shown = window.Bokeh && Bokeh.index && Bokeh.index.find_one(div);
  if (shown && shown.markup_el) { shown.markup_el.innerHTML = source.data[div.name][0]; }
}
"""
CONTAINED = {"contain": "strict", "overflow-y": "auto"}   # a longer text scrolls in its box
CONTACT_COLOUR = "#d62728"
PANELS_WIDTH = 230


def build_page(view, doc) -> None:
    """Lay out one browser page for ``view`` in the Bokeh document ``doc`` and keep it fed."""
    from bokeh.layouts import column, row
    from bokeh.models import ColumnDataSource, Div, Range1d

    view.sessions += 1
    view.pages_served += 1
    doc.on_session_destroyed(lambda _ctx: setattr(view, "sessions", view.sessions - 1))
    x_range = Range1d(0, view.history_s, name="time")
    sources = {"contacts": ColumnDataSource({"t": [], "label": []}, name="contacts")}
    # This page's own mode: paused (its plots stop following) and how far back it scrubs.
    mode = {"paused": False, "frozen_end": None, "page": uuid.uuid4().hex}
    antenna = _antenna_plot(doc, view, sources["contacts"], x_range, mode["page"])
    coded = _coded_plot(doc, view, sources["contacts"], x_range, mode["page"])
    rate_map_div = rate_map(doc, view, x_range, sources["contacts"], mode["page"],
                            CONTACT_COLOUR)
    # A fixed height: new text does not move the plots below it (the counters, and the last
    # five contacts).
    counters = Div(text="", sizing_mode="stretch_width", height=150, name="counters",
                   styles=CONTAINED)
    # Beside the plots, what the running network decides: a panel per part it has. One column
    # for the plots keeps their time axes aligned.
    panels = Div(text="", width=PANELS_WIDTH, height=680, name="decided", styles=CONTAINED)
    plots = column(antenna, coded, rate_map_div, sizing_mode="stretch_width")
    sources["text"] = _text_source(doc, (counters, panels))
    feed = PageFeed(view, mode["page"], mode)
    update, reload, follow = _updater(view, sources, x_range, mode, feed)
    # A column that would fall past the time axis moves it (with the page's document locked).
    feed.on_sent = lambda t_s: (t_s + view.window_s > x_range.end
                                and doc.add_next_tick_callback(follow))
    bar, status = control_widgets(view, mode, reload, x_range)
    doc.add_root(column(counters, bar, status, row(plots, panels, sizing_mode="stretch_width"),
                        sizing_mode="stretch_width"))
    doc.title = "snn-antenna live view"
    reload(None)                    # the kept span, then its text
    update()
    for div in (counters, panels):  # the text as the page loads
        div.text = sources["text"].data[div.name][0]

    # A page nobody holds (reloaded, closed, or not connected yet) costs nothing until its
    # session is discarded or a browser connects: it then catches up from its cursors.
    def pull() -> None:
        if not connected(doc):
            return
        wait_s = view.next_column_in()
        if wait_s is not None and 0 <= wait_s < COLUMN_GUARD_S:
            doc.add_timeout_callback(lambda: connected(doc) and update(),
                                     (wait_s + COLUMN_GUARD_S) * 1000)
            return
        update()

    doc.add_periodic_callback(pull, PAGE_UPDATE_MS)

    # A new rate-map column goes out as it arrives, alone, on the page's own socket: the
    # browser redraws the rate map only (the lines, panels and counters come with the pull).
    view.feeds[mode["page"]] = feed
    view.column_listeners.add(feed.send_columns)

    def ended(_context) -> None:
        view.column_listeners.discard(feed.send_columns)
        view.feeds.pop(mode["page"], None)
        if feed.socket is not None:
            feed.socket.close()

    doc.on_session_destroyed(ended)


def connected(doc) -> bool:
    """Whether a browser holds the page's session now (a document outside a server: yes)."""
    session = doc.session_context.session if doc.session_context is not None else None
    return session is None or session.connection_count > 0


def _text_source(doc, divs):
    """The Divs' text, one column per Div's name, shown by the page's own script on each
    change and as the page loads."""
    from bokeh.events import DocumentReady
    from bokeh.models import ColumnDataSource, CustomJS

    source = ColumnDataSource({div.name: [""] for div in divs}, name="text")
    show = CustomJS(args={"source": source, "divs": list(divs)}, code=TEXT_JS)
    source.js_on_change("data", show)
    doc.js_on_event(DocumentReady, show)
    doc.add_root(source)            # nothing on the page holds it: a root of its own
    return source


def _antenna_plot(doc, view, contacts, x_range, page: str):
    return line_plot(doc, "xy", ["x", "y"], view.shown_points, x_range, contacts, page=page,
                     title="Antenna: the two accelerometer axes", y_label="g",
                     series=[{"column": "x", "colour": "#1f77b4", "label": "x"},
                             {"column": "y", "colour": "#ff7f0e", "label": "y"}],
                     contact_colour=CONTACT_COLOUR, name="antenna")


def _coded_plot(doc, view, contacts, x_range, page: str):
    amplitude = view.coder_amplitude
    return line_plot(doc, "coded", ["signal", "th", "coded"], view.shown_points, x_range,
                     contacts, page=page,
                     title="Coded input: filtered signal, the gate's threshold ±Th, and the "
                           "square wave fed to the resonators", y_label="signal (g)",
                     series=[{"column": "signal", "colour": "#555555", "label": "signal"},
                             {"column": "th", "colour": CONTACT_COLOUR, "dashed": True,
                              "label": "±Th"},
                             {"column": "th", "colour": CONTACT_COLOUR, "dashed": True,
                              "negated": True, "label": None},
                             {"column": "coded", "colour": "#2ca02c", "step": True,
                              "axis": "right", "alpha": 0.8, "label": "coded"}],
                     right={"label": "coded input",
                            "range": [-1.3 * amplitude, 1.3 * amplitude]},
                     contact_colour=CONTACT_COLOUR, name="coded_input")


def _updater(view, sources: dict, x_range, mode: dict, feed):
    """The page's periodic callback (stream what is new since this page's cursors, unless the
    page is paused or its browser behind), ``reload(end_s)``: show the kept history up to
    ``end_s`` (None: the latest, and follow it again), and ``follow()``: move the time axis
    to the stream."""
    cursor = {"text_at": 0.0}
    shown = {"text": None, "contacts": None, "text_marks": None}

    def reload(end_s=None) -> None:
        end = max(view.t_s, view.history_s) if end_s is None else end_s
        feed.show(end_s)
        x_range.start, x_range.end = end - view.history_s, end

    def follow() -> None:
        """The plots' time axis up to the window in progress and one pull period beyond: the
        columns that come before the next pull are then already in sight, and only the rate
        map is redrawn for them (a move of the axis repaints every plot on the page)."""
        if mode["paused"]:
            return
        end = max(view.t_s, view.history_s) + view.window_s + PAGE_UPDATE_MS / 1000
        if x_range.end != end:
            x_range.start, x_range.end = end - view.history_s, end

    def text(marks) -> None:
        """The counters, contacts and panels: text a person reads, refreshed TEXT_UPDATE_S
        apart, and at once when a contact comes or changes."""
        now = time.monotonic()
        if now - cursor["text_at"] < TEXT_UPDATE_S and marks == shown["text_marks"]:
            return
        cursor["text_at"], shown["text_marks"] = now, marks
        html = {"counters": counters_html(view),
                "decided": panels_html(view) + controls_html(view)}
        if html != shown["text"]:
            shown["text"] = html
            sources["text"].data = {name: [text] for name, text in html.items()}

    def update() -> None:
        view.pull()                 # the frames in transit now
        following = feed.send_columns()
        marks = contact_marks(view)
        text(marks)                 # paused or not: the pipeline goes on
        if not following:
            return
        feed.send_points()
        if marks != shown["contacts"]:
            shown["contacts"] = marks
            sources["contacts"].data = {"t": [m[0] for m in marks], "label": [m[1] for m in marks]}
        follow()

    return update, reload, follow


def contact_marks(view) -> list[tuple[float, str]]:
    """(onset, label) of every contact so far, and of the one still open."""
    marks = [(c["onset_s"], contact_label(c)) for c in view.contacts]
    if view.open_onset_s is not None:
        marks.append((view.open_onset_s, "contact…"))
    return marks


def panels_html(view) -> str:
    """A box per panel of the running network (``view.panels``: name → title) with the latest
    window's decided values; a panel whose window has not come yet says so."""
    boxes = []
    for name, title in view.panels.items():
        values = view.decided.get(name)
        rows = ("".join(f"<tr><td>{field_label(field)}</td><td><b>{shown_value(value)}"
                        f"</b></td></tr>" for field, value in values.items())
                if values else "<tr><td>no window yet</td></tr>")
        boxes.append(f"<div class='panel' data-panel='{name}' style='border:1px solid #ccc;"
                     f"margin:0 0 6px 6px;padding:3px 6px'><div style='font-weight:bold'>"
                     f"{title}</div><table style='font-size:12px'>{rows}</table></div>")
    return f"<div style='font-family:sans-serif;font-size:12px'>{''.join(boxes)}</div>"


UNITS = {"g": "g", "s": "s", "cm": "cm", "hz": "Hz", "deg": "°", "cm_s": "cm/s"}


def field_label(field: str) -> str:
    """``last_distance_cm`` → ``last distance (cm)``; ``th_g`` → ``Th (g)``."""
    words = field.split("_")
    for n in (2, 1):
        if len(words) > n and "_".join(words[-n:]) in UNITS:
            unit = UNITS["_".join(words[-n:])]
            words = words[:-n]
            break
    else:
        unit = None
    text = " ".join("Th" if w == "th" else w for w in words)
    return f"{text} ({unit})" if unit else text


def shown_value(value) -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def counters_html(view) -> str:
    cells = "".join(f"<td style='padding:0 14px 0 0'><b>{name}</b> {value}</td>"
                    for name, value in shown_counters(view))
    rows = "".join(
        f"<li>{c['onset_s']:.2f}–{c['end_s']:.2f} s: ringing {c['frequency_hz']:.1f} Hz "
        f"→ <b>{contact_label(c)}</b></li>" for c in view.contacts[-5:])
    listing = f"<ul style='margin:2px 0'>{rows}</ul>" if rows else "<div>no contact yet</div>"
    return (f"<table style='font-family:sans-serif;font-size:14px'><tr>{cells}</tr></table>"
            f"<div style='font-family:sans-serif;font-size:14px'>contacts "
            f"({len(view.contacts)}):{listing}</div>")


def shown_counters(view) -> list[tuple[str, str]]:
    """The page's counter line: (name, formatted value)."""
    counts = view.counts
    rtf = "–" if view.realtime_factor is None else f"×{view.realtime_factor:.1f}"
    lat = "–" if view.latency_ms is None else f"{view.latency_ms:.1f} ms"
    shown = view.display_latency()
    display = "–" if shown["p95"] is None else f"{shown['last']:.0f} ms (p95 {shown['p95']:.0f})"
    return [("stream time", f"{view.t_s:.1f} s"), ("real-time factor", rtf),
            ("latency", lat), ("on screen after", display), ("Th", f"{view.th_g:.3g} g"),
            ("window", f"{view.window_s:.3g} s"),
            ("frames", counts.get("frames", 0)), ("CRC errors", counts.get("crc_errors", 0)),
            ("gaps", counts.get("gaps", 0)), ("lost samples", counts.get("lost_samples", 0)),
            ("duplicates", counts.get("duplicates", 0)), ("reordered", counts.get("reordered", 0)),
            ("late", counts.get("late", 0)), ("reconnects", counts.get("reconnects", 0)),
            ("view frames dropped", view.dropped)]


def contact_label(contact: dict) -> str:
    label = f"{contact['distance_cm']:.1f} cm"
    if contact.get("material"):         # networks with a material unit name it
        label += f", {contact['material']}"
    return label
