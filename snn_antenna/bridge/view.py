"""A live browser view of the online pipeline: the antenna's two axes, the coded input with the
gate's threshold Th, the resonators' rate map and each contact with its distance, plus the
link's counters; and ``/state.json`` with the same state for scripts and tests.

Why Bokeh: its server streams new points into a browser plot (``ColumnDataSource.stream`` with
a rollover) without any hand-written JavaScript, and it ships its own BokehJS, so the page works
on a robot's laptop with no internet.

The view never slows the pipeline. The pipeline thread only appends what it already has
(samples, the coder's input, each rate-map window, contact events) to a bounded
``collections.deque``: an append never waits, and when the server thread falls behind the
oldest view frames are overwritten (counted in ``view_frames_dropped``), never a sample, which
the recorder has already written. The server thread (Tornado's IO loop, its own thread) drains
that inbox into a 10 s history every 50 ms; each open page pulls what is new in the history
every 100 ms. A browser that stalls only queues messages on its own websocket (closed after the
ping timeout); a closed one ends its session.
"""
from __future__ import annotations

import asyncio
import json
import logging
import math
import sys
import threading
from collections import deque
from contextlib import contextmanager
from itertools import chain

import numpy as np

from ..errors import SpecError

HISTORY_S = 10.0                # what the plots keep
PAGE_UPDATE_MS = 100            # each page pulls new points 10 times a second
DRAIN_MS = 50                   # the server thread empties the pipeline's inbox
DISPLAY_EVERY = 4               # 1 kHz → 250 points/s per line: 8 per period at 30 Hz
INBOX_ITEMS = 4096              # seconds of port reads even at one frame a read; drained each 50 ms
SHOWN_COUNTERS = ("frames", "crc_errors", "gaps", "lost_samples", "reconnects")
LOOPBACK = ("127.0.0.1", "localhost", "::1")


def add_view_args(parser) -> None:
    """``--view``, ``--view-host``, ``--view-port``, ``--view-hold`` for ``stream``/``replay``."""
    parser.add_argument("--view", action="store_true",
                        help="serve a live browser view (rate map, coded input, contacts) and "
                             "print its URL")
    parser.add_argument("--view-host", default="127.0.0.1",
                        help="address the view listens on (default 127.0.0.1: this machine "
                             "only; 0.0.0.0 exposes it to the network deliberately)")
    parser.add_argument("--view-port", type=int, default=5006,
                        help="port of the view (default 5006; 0 = any free port)")
    parser.add_argument("--view-hold", type=float, default=None,
                        help="seconds to keep the view up after the stream ends (default: "
                             "until Ctrl-C; 0 closes it at once)")


@contextmanager
def live_view(args, parts):
    """Yield a started :class:`LiveView` when ``args.view`` (else None); stop it at the end,
    after holding the final page for ``--view-hold`` seconds (default until Ctrl-C)."""
    if not getattr(args, "view", False):
        yield None
        return
    if not 0 <= args.view_port <= 65535:
        raise SpecError("view-port", args.view_port, "a port 1-65535, or 0 for any free port")
    if args.view_hold is not None and not args.view_hold >= 0:
        raise SpecError("view-hold", args.view_hold, "seconds >= 0")
    view = LiveView(parts, host=args.view_host, port=args.view_port)
    url = view.start()
    print(f"live view: {url}  (plain state: {url}state.json)", file=sys.stderr, flush=True)
    ended = False
    try:
        yield view
        ended = True
    finally:
        if ended and args.view_hold != 0:
            _hold(url, args.view_hold)
        view.stop()


def _hold(url: str, seconds: float | None) -> None:
    import signal

    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    print(f"stream ended; the view stays at {url} "
          + (f"for {seconds:g} s" if seconds else "until Ctrl-C"), file=sys.stderr, flush=True)
    done.wait(seconds)


def _tap_coder(coder, tap) -> None:
    """Make the chain's own coder also hand its input (the filtered, centred signal the gate
    compares with Th), the Th in force and its output to ``tap``. The pipeline exposes only the
    coded output; the coder's input is the one place the signal before the gate exists."""
    plain = coder.partial_transform

    def partial_transform(X, threshold=None):
        coded = plain(X, threshold)
        tap(X, coder.threshold if threshold is None else threshold, coded)
        return coded

    coder.partial_transform = partial_transform


class _Ring:
    """The last ``capacity`` rows of a stream, and how many rows it ever had (a page's cursor)."""

    def __init__(self, columns: int, capacity: int):
        self.rows = np.empty((0, columns))
        self.capacity = capacity
        self.total = 0

    def add(self, rows: np.ndarray) -> None:
        if len(rows):
            self.rows = np.concatenate([self.rows, rows])[-self.capacity:]
            self.total += len(rows)

    def since(self, cursor: int) -> np.ndarray:
        return self.rows[len(self.rows) - min(self.total - cursor, len(self.rows)):]


class _Runs:
    """Consecutive pieces of one stream, joined: (first index, pieces) per unbroken run (a
    dropped view frame breaks a run)."""

    def __init__(self):
        self._runs: list[tuple[int, list]] = []
        self._next = None

    def add(self, first: int, piece) -> None:
        if first != self._next:
            self._runs.append((first, []))
        self._runs[-1][1].append(piece)
        self._next = first + len(piece)

    def runs(self):
        return self._runs


class LiveView:
    """Pipeline side: a :class:`~snn_antenna.bridge.source.SourceLoop` handler (``handle``,
    ``idle``) and ``run_online``'s ``view`` hook (``window``, ``event``); all of them only append
    to the inbox. Server side: the Bokeh page and ``/state.json`` on their own thread."""

    def __init__(self, parts, *, host: str = "127.0.0.1", port: int = 0,
                 history_s: float = HISTORY_S, rate_hz: float = 1000.0,
                 inbox_items: int = INBOX_ITEMS):
        from sklearn.base import clone

        self.parts, self.host, self.port = parts, host, port
        self.rate_hz, self.history_s = rate_hz, history_s
        self.neuron_hz = np.asarray(parts.array.neuron_hz, dtype=float)
        self.window_s = parts.window_s
        # Its own copy: the pipeline's is unfitted until calibration, and the two threads
        # should share nothing they call.
        self.to_g = clone(parts.chain.named_steps["to_g"]).fit(np.zeros((1, 2)))
        coder = parts.chain.named_steps["coder"]
        self.coder_amplitude = coder.amplitude
        _tap_coder(coder, self._coded)
        # Pipeline → server: a bounded deque never blocks its writer and drops the oldest item
        # when full; appends and pops are thread-safe. Counters are a latest-value slot.
        self._inbox: deque = deque(maxlen=inbox_items)
        self._pushed = 0
        self._counts: dict = {}
        self._n_xy = self._n_coded = 0
        # Server side only (the IO loop thread): the history the pages and /state.json read.
        n = int(history_s * rate_hz) // DISPLAY_EVERY + 1
        self.xy = _Ring(3, n)                       # t_s, x_g, y_g
        self.coded = _Ring(4, n)                    # t_s, signal_g, th_g, coded
        n_windows = int(math.ceil(history_s / self.window_s)) + 1
        self.windows = _Ring(1 + len(self.neuron_hz), n_windows)     # t_s, rates
        self.contacts: list[dict] = []
        self.open_onset_s: float | None = None
        self.realtime_factor = self.latency_ms = None
        self.th_g = float(coder.threshold)
        self.drained = 0
        self.peak_rate_hz = 10.0
        self.sessions = 0
        self.url = None
        self._thread = None
        self._loop = None

    # ---- pipeline side: append and return -------------------------------------------------
    def handle(self, batch) -> None:
        if batch.counts:
            self._counts = batch.counts
        if batch.samples:           # the list itself: converting it is the server's work
            self._push(("xy", self._n_xy, batch.samples))
            self._n_xy += len(batch.samples)

    def idle(self) -> None:
        pass

    def _coded(self, signal, th, coded) -> None:
        # References only (the chain makes new arrays for every chunk); shaped by the server.
        self._push(("coded", self._n_coded, (signal, th, coded)))
        self._n_coded += len(coded)

    def window(self, t_s: float, rates: np.ndarray, event, realtime_factor: float,
               latency_ms: float | None) -> None:
        self._push(("window", t_s, rates.copy(), realtime_factor, latency_ms))
        self.event(event)

    def event(self, event) -> None:
        if event is not None:
            kind, what = event
            self._push((kind, what if kind == "onset" else what.as_dict()))

    def _push(self, item) -> None:
        self._inbox.append(item)
        self._pushed += 1

    # ---- server side (IO loop thread) -----------------------------------------------------
    def drain(self) -> None:
        """Move everything in the inbox into the history. A port delivers thousands of small
        batches a second when the pipeline runs ahead of real time: they are joined first and
        converted in one go (per-item numpy calls would cost the pipeline the GIL)."""
        xy, coded, windows = _Runs(), _Runs(), []
        while True:
            try:
                item = self._inbox.popleft()
            except IndexError:
                break
            self.drained += 1
            kind = item[0]
            if kind == "xy":
                xy.add(item[1], item[2])
            elif kind == "coded":
                signal, th, out = item[2]
                n = len(out)
                coded.add(item[1], np.column_stack([
                    np.asarray(signal, dtype=float).reshape(n, -1)[:, 0],
                    np.broadcast_to(np.asarray(th, dtype=float), (n,)),
                    np.asarray(out, dtype=float).reshape(n, -1)[:, 0]]))
            elif kind == "window":
                _, t_s, rates, rtf, latency_ms = item
                windows.append(np.r_[t_s, rates])
                self.peak_rate_hz = max(self.peak_rate_hz, float(rates.max()))
                self.realtime_factor = rtf if rtf is not None and np.isfinite(rtf) else None
                self.latency_ms = latency_ms
            elif kind == "onset":
                self.open_onset_s = float(item[1])
            elif kind == "contact":
                self.contacts.append(item[1])
                self.open_onset_s = None
        for first, batches in xy.runs():
            samples = np.asarray(list(chain.from_iterable(batches)), dtype=float)
            rows = self._rows(first, samples[:, 1:])
            rows[:, 1:] = self.to_g.transform(rows[:, 1:])
            self.xy.add(rows)
        for first, parts in coded.runs():
            self.coded.add(self._rows(first, np.concatenate(parts)))
            self.th_g = float(self.coded.rows[-1, 2])
        if windows:
            self.windows.add(np.vstack(windows))

    def _rows(self, first: int, values: np.ndarray) -> np.ndarray:
        """Rows (t_s, values...) of every DISPLAY_EVERY-th sample by stream index, so that
        decimation does not depend on how the port chunked the samples."""
        index = np.arange(first, first + len(values))
        keep = index % DISPLAY_EVERY == 0
        return np.column_stack([index[keep] / self.rate_hz, values[keep]])

    @property
    def dropped(self) -> int:
        return max(0, self._pushed - self.drained - len(self._inbox))

    @property
    def t_s(self) -> float:
        """Stream time: the samples received so far at the sample rate."""
        return self._n_xy / self.rate_hz

    def state(self) -> dict:
        """The live state as plain JSON (``/state.json``)."""
        self.drain()
        last = self.windows.rows[-1] if self.windows.total else None
        counts = dict(self._counts)
        return {
            "t_s": self.t_s,
            "rate_map": {"t_s": float(last[0]) if last is not None else None,
                         "window_s": self.window_s,
                         "neuron_hz": [round(float(f), 3) for f in self.neuron_hz],
                         "rates_hz": ([float(r) for r in last[1:]] if last is not None
                                      else None)},
            "windows": self.windows.total,
            "contacts": list(self.contacts),
            "contact_open_since_s": self.open_onset_s,
            "th_g": self.th_g,
            "counters": {"realtime_factor": _finite(self.realtime_factor),
                         "latency_ms": _finite(self.latency_ms),
                         **{k: counts.get(k, 0) for k in SHOWN_COUNTERS},
                         "view_frames_dropped": self.dropped},
            # Points kept for the plots (every DISPLAY_EVERY-th sample), ever.
            "plotted": {"xy": self.xy.total, "coded_input": self.coded.total},
            "sessions": self.sessions,
        }

    def start(self) -> str:
        """Start the server thread; returns the page's URL once it listens."""
        ready, failed = threading.Event(), []
        self._thread = threading.Thread(target=self._serve, args=(ready, failed),
                                        name="live-view", daemon=True)
        self._thread.start()
        ready.wait(30)
        if failed:
            raise failed[0]
        if not self.url:
            raise SpecError("view", "server", "a view server that starts within 30 s")
        return self.url

    def stop(self) -> None:
        if self._loop is not None:
            self._loop.add_callback(self._shutdown)
            self._thread.join(10)
            self._loop = None

    def _shutdown(self) -> None:
        self._server.stop()
        self._loop.stop()

    def _serve(self, ready: threading.Event, failed: list) -> None:
        from bokeh.application import Application
        from bokeh.application.handlers.function import FunctionHandler
        from bokeh.server.server import BaseServer
        from bokeh.server.tornado import BokehTornado
        from bokeh.server.util import bind_sockets
        from tornado.httpserver import HTTPServer
        from tornado.ioloop import IOLoop, PeriodicCallback

        # A stalled tab's queued messages are the only thing a slow browser costs; "closed
        # the websocket" is the normal end of one.
        logging.getLogger("bokeh.server.views.ws").setLevel(logging.ERROR)
        asyncio.set_event_loop(asyncio.new_event_loop())
        loop = IOLoop.current()
        try:
            try:
                sockets, port = bind_sockets(self.host, self.port)
            except OSError as exc:
                raise SpecError("view-port", self.port,
                                f"a free port on {self.host} ({exc.strerror}), or 0 for any "
                                "free port") from exc
            origins = [f"localhost:{port}", f"127.0.0.1:{port}"]
            if self.host not in LOOPBACK:   # exposed deliberately: any name of this machine
                origins.append(f"*:{port}")
            app = BokehTornado({"/": Application(FunctionHandler(self._page))},
                               extra_websocket_origins=origins,
                               extra_patterns=[(r"/state\.json", _state_handler(), {"view": self})],
                               websocket_ping_interval=10, websocket_ping_timeout=10)
            http = HTTPServer(app)
            http.add_sockets(sockets)
            self._server = BaseServer(loop, app, http)
            self._server.start()
            PeriodicCallback(self.drain, DRAIN_MS).start()
        except Exception as exc:
            failed.append(exc)
            ready.set()
            return
        shown = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host
        self.port, self.url = port, f"http://{shown}:{port}/"
        self._loop = loop
        ready.set()
        loop.start()
        loop.close(all_fds=True)

    # ---- the page ------------------------------------------------------------------------
    def _page(self, doc) -> None:
        """One browser page (a Bokeh session): its own sources, fed from the history."""
        from bokeh.layouts import column
        from bokeh.models import (ColorBar, ColumnDataSource, Div, FixedTicker, LabelSet,
                                  LinearAxis, LinearColorMapper, Range1d)
        from bokeh.palettes import Viridis256
        from bokeh.plotting import figure

        self.sessions += 1
        doc.on_session_destroyed(lambda _ctx: setattr(self, "sessions", self.sessions - 1))
        x_range = Range1d(0, self.history_s, name="time")
        # The same borders on every plot keep their time axes aligned.
        common = dict(x_range=x_range, height=210, sizing_mode="stretch_width",
                      tools="pan,wheel_zoom,reset,save", toolbar_location="right",
                      min_border_left=70, min_border_right=110)
        src_xy = ColumnDataSource({"t": [], "x": [], "y": []}, name="xy")
        src_in = ColumnDataSource({"t": [], "signal": [], "th": [], "neg_th": [], "coded": []})
        src_map = ColumnDataSource({"image": [], "x": [], "y": [], "dw": [], "dh": []})
        src_contacts = ColumnDataSource({"t": [], "label": []}, name="contacts")

        antenna = figure(title="Antenna: the two accelerometer axes", y_axis_label="g",
                         **common)
        antenna.line("t", "x", source=src_xy, color="#1f77b4", legend_label="x")
        antenna.line("t", "y", source=src_xy, color="#ff7f0e", legend_label="y")

        coded = figure(title="Coded input: filtered signal, the gate's threshold ±Th, and the "
                             "square wave fed to the resonators", y_axis_label="signal (g)",
                       **common)
        coded.line("t", "signal", source=src_in, color="#555555", legend_label="signal")
        coded.line("t", "th", source=src_in, color="#d62728", line_dash="dashed",
                   legend_label="±Th")
        coded.line("t", "neg_th", source=src_in, color="#d62728", line_dash="dashed")
        amplitude = self.coder_amplitude
        coded.extra_y_ranges = {"coded": Range1d(-1.3 * amplitude, 1.3 * amplitude)}
        coded.add_layout(LinearAxis(y_range_name="coded", axis_label="coded input"), "right")
        coded.step("t", "coded", source=src_in, y_range_name="coded", color="#2ca02c",
                   mode="after", alpha=0.8, legend_label="coded")


        # One image (a row per resonator, a column per window) rather than a rectangle per
        # cell: the browser redraws it ten times a second, and it competes for the same cores.
        n = len(self.neuron_hz)
        mapper = LinearColorMapper(palette=Viridis256, low=0, high=self.peak_rate_hz)
        rate_map = figure(title="Rate map: resonators (tuning frequency) × time",
                          y_axis_label="resonator tuning (Hz)", x_axis_label="stream time (s)",
                          y_range=Range1d(-0.5, n - 0.5), **{**common, "height": 260})
        rate_map.image(image="image", x="x", y="y", dw="dw", dh="dh", source=src_map,
                       color_mapper=mapper)
        ticks = list(range(0, n, max(1, n // 8)))
        rate_map.yaxis.ticker = FixedTicker(ticks=ticks)
        rate_map.yaxis.major_label_overrides = {i: f"{self.neuron_hz[i]:.1f}" for i in ticks}
        rate_map.add_layout(ColorBar(color_mapper=mapper, title="rate (spikes/s)",
                                     width=12), "right")

        for fig in (antenna, coded):
            fig.legend.location, fig.legend.orientation = "top_right", "horizontal"
            fig.legend.background_fill_alpha = 0.7
        for fig in (antenna, coded, rate_map):
            fig.vspan(x="t", source=src_contacts, line_color="#d62728", line_width=2)
            fig.add_layout(LabelSet(x="t", y=5, y_units="screen", text="label", x_offset=4,
                                    source=src_contacts, text_color="#d62728",
                                    text_font_style="bold", text_font_size="13px",
                                    background_fill_color="white",
                                    background_fill_alpha=0.75))
        # A fixed height: new text then never re-lays the page out (ten times a second).
        counters = Div(text="", sizing_mode="stretch_width", height=80)
        doc.add_root(column(counters, antenna, coded, rate_map, sizing_mode="stretch_width"))
        doc.title = "snn-antenna live view"

        cursor = {"xy": 0, "coded": 0, "windows": 0, "contacts": 0}
        shown = {"counters": None, "contacts": None}
        rollover_samples = self.xy.capacity

        def update() -> None:
            new_xy = self.xy.since(cursor["xy"])
            cursor["xy"] = self.xy.total
            if len(new_xy):
                src_xy.stream({"t": new_xy[:, 0], "x": new_xy[:, 1], "y": new_xy[:, 2]},
                              rollover=rollover_samples)
            new_in = self.coded.since(cursor["coded"])
            cursor["coded"] = self.coded.total
            if len(new_in):
                src_in.stream({"t": new_in[:, 0], "signal": new_in[:, 1], "th": new_in[:, 2],
                               "neg_th": -new_in[:, 2], "coded": new_in[:, 3]},
                              rollover=rollover_samples)
            if cursor["windows"] != self.windows.total:
                cursor["windows"] = self.windows.total
                shown_windows = self.windows.rows
                # The windows of one stream follow each other; a new stream starts again at 0.
                restart = np.flatnonzero(np.diff(shown_windows[:, 0]) <= 0)
                if len(restart):
                    shown_windows = shown_windows[restart[-1] + 1:]
                src_map.data = {"image": [np.ascontiguousarray(shown_windows[:, 1:].T)],
                                "x": [shown_windows[0, 0]], "y": [-0.5],
                                "dw": [len(shown_windows) * self.window_s], "dh": [n]}
                if mapper.high != self.peak_rate_hz:
                    mapper.high = self.peak_rate_hz
            marks = self._contact_marks()
            if marks != shown["contacts"]:
                shown["contacts"] = marks
                src_contacts.data = {"t": [m[0] for m in marks], "label": [m[1] for m in marks]}
            html = self._counters_html()
            if html != shown["counters"]:
                shown["counters"] = counters.text = html
            end = max(self.t_s, self.history_s)
            if x_range.end != end:
                x_range.start, x_range.end = end - self.history_s, end

        update()
        doc.add_periodic_callback(update, PAGE_UPDATE_MS)

    def _contact_marks(self) -> list[tuple[float, str]]:
        marks = [(c["onset_s"], _contact_label(c)) for c in self.contacts]
        if self.open_onset_s is not None:
            marks.append((self.open_onset_s, "contact…"))
        return marks

    def _counters_html(self) -> str:
        s = self.state_counters()
        cells = "".join(f"<td style='padding:0 14px 0 0'><b>{name}</b> {value}</td>"
                        for name, value in s)
        rows = "".join(
            f"<li>{c['onset_s']:.2f}–{c['end_s']:.2f} s: ringing {c['frequency_hz']:.1f} Hz "
            f"→ <b>{_contact_label(c)}</b></li>" for c in self.contacts[-5:])
        listing = (f"<ul style='margin:2px 0'>{rows}</ul>" if rows
                   else "<div>no contact yet</div>")
        return (f"<table style='font-family:sans-serif;font-size:14px'><tr>{cells}</tr></table>"
                f"<div style='font-family:sans-serif;font-size:14px'>contacts "
                f"({len(self.contacts)}):{listing}</div>")

    def state_counters(self) -> list[tuple[str, str]]:
        counts = self._counts
        rtf = "–" if self.realtime_factor is None else f"×{self.realtime_factor:.1f}"
        lat = "–" if self.latency_ms is None else f"{self.latency_ms:.1f} ms"
        return [("stream time", f"{self.t_s:.1f} s"), ("real-time factor", rtf),
                ("latency", lat), ("Th", f"{self.th_g:.3g} g"),
                ("frames", counts.get("frames", 0)), ("CRC errors", counts.get("crc_errors", 0)),
                ("gaps", counts.get("gaps", 0)), ("lost samples", counts.get("lost_samples", 0)),
                ("reconnects", counts.get("reconnects", 0)),
                ("view frames dropped", self.dropped)]


def _contact_label(contact: dict) -> str:
    label = f"{contact['distance_cm']:.1f} cm"
    if contact.get("material"):         # networks with a material unit name it
        label += f", {contact['material']}"
    return label


def _finite(value):
    return None if value is None or not np.isfinite(value) else round(float(value), 3)


def _state_handler():
    from tornado.web import RequestHandler

    class StateHandler(RequestHandler):
        def initialize(self, view: LiveView) -> None:
            self.view = view

        def get(self) -> None:
            self.set_header("Content-Type", "application/json")
            self.set_header("Cache-Control", "no-store")
            self.write(json.dumps(self.view.state()))

    return StateHandler
