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
ping timeout); a closed one ends its session. The page itself is ``bridge/page.py``.
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
from functools import partial
from itertools import chain

import numpy as np

from ..errors import SpecError
from .page import build_page
from .protocol import BOARD_RATE_HZ

HISTORY_S = 10.0                # what the plots keep
DRAIN_MS = 50                   # the server thread empties the pipeline's inbox
DISPLAY_EVERY = 4               # 1 kHz → 250 points/s per line: 8 per period at 30 Hz
INBOX_ITEMS = 4096              # seconds of port reads even at one frame a read; drained each 50 ms
SHOWN_COUNTERS = ("frames", "crc_errors", "gaps", "lost_samples", "duplicates", "reordered",
                  "reconnects")


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
    check_view_host(args.view_host)
    from .hostguard import LOOPBACK   # with tornado, loaded only when a view is asked for

    view = LiveView(parts, host=args.view_host, port=args.view_port)
    url = view.start()
    if args.view_host not in LOOPBACK:
        print(f"warning: the live view listens on {args.view_host}, beyond this machine: anyone "
              "who can reach it sees the stream", file=sys.stderr, flush=True)
    print(f"live view: {url}  (plain state: {url}state.json)", file=sys.stderr, flush=True)
    ended = False
    try:
        yield view
        ended = True
    finally:
        if ended and args.view_hold != 0:
            _hold(url, args.view_hold)
        view.stop()


def check_view_host(host: str) -> str:
    """Listening beyond loopback takes an explicit address: an empty one would bind every
    interface by accident."""
    if not isinstance(host, str) or not host.strip():
        raise SpecError("view-host", host, "an explicit address: 127.0.0.1 (this machine), "
                                           "or e.g. 0.0.0.0 to expose the view deliberately")
    return host


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
                 history_s: float = HISTORY_S, rate_hz: float = BOARD_RATE_HZ,
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
            if len(rows):           # a run shorter than DISPLAY_EVERY may have no shown point
                rows[:, 1:] = self.to_g.transform(rows[:, 1:])
                self.xy.add(rows)
        for first, parts in coded.runs():
            self.coded.add(self._rows(first, np.concatenate(parts)))
            if self.coded.total:
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
    def counts(self) -> dict:
        """The link's latest counters (frames, CRC errors, gaps, ...)."""
        return self._counts

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

        from .hostguard import HostGuard, allowed_hosts

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
            bound = sockets[0].getsockname()[0]
            allowed = allowed_hosts(self.host, port)
            app = BokehTornado({"/": Application(FunctionHandler(partial(build_page, self)))},
                               extra_websocket_origins=sorted(allowed),
                               extra_patterns=[(r"/state\.json", _state_handler(), {"view": self})],
                               websocket_ping_interval=10, websocket_ping_timeout=10)
            http = HTTPServer(HostGuard(app, allowed))
            http.add_sockets(sockets)
            self._server = BaseServer(loop, app, http)
            self._server.start()
            PeriodicCallback(self.drain, DRAIN_MS).start()
        except Exception as exc:
            failed.append(exc)
            ready.set()
            return
        shown = f"[{bound}]" if ":" in bound else bound
        self.port, self.url = port, f"http://{shown}:{port}/"
        self._loop = loop
        ready.set()
        loop.start()
        loop.close(all_fds=True)


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
