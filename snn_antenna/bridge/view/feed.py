"""A live page's own websocket, ``/feed?page=TOKEN`` (bridge/view/process.py): what streams to
the page (the rate map's columns as they arrive, the line plots' new points at each pull) as
binary messages its script decodes, and the page's paint reports back.

Why not the page's Bokeh websocket: a Bokeh message is a document patch in several websocket
frames, each a task of the page's main thread, serialised in Python by the view process, and
the paint report would be an HTTP request. Here a message is one binary frame of float64 rows
made once with numpy. With three pages on two cores, those costs on the shared cores are what
delayed a column on screen. Bokeh keeps what a person changes or reads: the time axis, the
controls, the text.

A message, float64 in this machine's byte order: its kind (``KINDS``), ``reset`` (1: the page
starts that plot again from these rows: the socket opening, a reload, a scrub), ``live`` (rate
map: shown live; only live columns are reported painted), ``high`` (rate map: the colour
scale's top, spikes/s), the number of rows and their width, then the rows: the rate map's
(window start s, width s, spikes/s per resonator), the antenna's (t s, x g, y g), the coded
input's (t s, signal g, Th g, coded). A report from the page: ``{t_s, received_unix_s,
painted_unix_s}`` of the latest live column it painted (bridge/view/history.py turns it into the
display delay).
"""
from __future__ import annotations

import json
import time

import numpy as np

KINDS = {"map": 0, "xy": 1, "coded": 2}
# A page that has not painted the last column sent waits (its columns and points gather)
# rather than queue more than its browser draws; one that never reports (a hidden tab does
# not paint) still gets one this often.
UNPAINTED_WAIT_S = 1.0

# The page's side, run by each plot's script (rate_map.py, lines.py) before its own: one
# socket for the page, opened by the first script the loaded page runs; each plot registers
# the function that takes the messages of its kind.
FEED_JS = """
const feed = window._snn_feed || (window._snn_feed = {socket: null, take: {}});
function open_feed() {
  if (feed.socket) { return; }
  const url = new URL('feed?page=' + page, document.baseURI);
  url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
  const socket = feed.socket = new WebSocket(url);
  socket.binaryType = 'arraybuffer';
  socket.onmessage = event => {
    const a = new Float64Array(event.data);
    const take = feed.take[a[0]];
    if (take) { take(a); }
  };
}
"""


class PageFeed:
    """What one page is sent on its socket: on opening and at each reload the kept span up to
    the shown end (a reset of each plot), then each new rate-map column as it arrives and the
    lines' new points at each pull, unless the page is paused or its browser has not painted
    the last column sent (for up to ``UNPAINTED_WAIT_S``).

    ``view``: the :class:`~snn_antenna.bridge.view.history.ViewHistory`; ``mode``: the page's
    own (``paused``); ``on_sent(t_s)``: told the start of the latest live column sent (the
    page moves its time axis when a column would fall past it). All of it runs on the view
    process's server loop."""

    def __init__(self, view, page: str, mode: dict, on_sent=None):
        self.view, self.page, self.mode, self.on_sent = view, page, mode, on_sent
        self.socket = None
        self.end_s = None               # the end of the span shown; None: the latest, live
        self.cursors = {"map": view.windows.total, "xy": view.xy.total,
                        "coded": view.coded.total}
        self.sent_t, self.sent_at = None, 0.0

    def attach(self, socket) -> None:
        """The page's socket opened (a reopened one replaces it): it starts with the span."""
        self.socket = socket
        self._reset()

    def detach(self, socket) -> None:
        if self.socket is socket:
            self.socket = None

    def show(self, end_s: float | None = None) -> None:
        """The kept span up to ``end_s`` (None: the latest, and follow the stream again)."""
        self.end_s = end_s
        self._reset()

    def behind(self) -> bool:
        """The browser has not painted the last column sent to it yet (for a while)."""
        return (self.sent_t is not None
                and self.view.painted_by.get(self.page) != round(self.sent_t, 6)
                and time.monotonic() - self.sent_at < UNPAINTED_WAIT_S)

    def waiting(self) -> bool:
        """Columns arrived that this page has not been sent."""
        return self.cursors["map"] != self.view.windows.total

    def send_columns(self) -> bool:
        """Send the rate-map columns that came since the last ones sent, unless the page is
        paused or behind; whether it follows the stream now."""
        if self.mode["paused"] or self.behind():
            return False
        if self.socket is not None and self.waiting():
            self._send_new("map")
        return True

    def send_points(self) -> None:
        """Send the lines' points that came since the last ones sent (the caller checked
        that the page follows the stream)."""
        if self.socket is not None:
            self._send_new("xy")
            self._send_new("coded")

    def report(self, message) -> None:
        """A paint report from the page: the display delay, and what waited for it goes."""
        try:
            report = json.loads(message[:300])
            received = report.get("received_unix_s")
            self.view.painted(float(report["t_s"]), float(report["painted_unix_s"]),
                              page=self.page,
                              received_unix_s=None if received is None else float(received))
        except (ValueError, KeyError, TypeError, AttributeError):
            return                      # not a report: nothing to count
        if self.waiting():
            self.send_columns()

    def _rings(self) -> dict:
        return {"map": self.view.windows, "xy": self.view.xy, "coded": self.view.coded}

    def _send_new(self, kind: str) -> None:
        ring = self._rings()[kind]
        new = ring.since(self.cursors[kind])
        self.cursors[kind] = ring.total
        if len(new):
            self._write(kind, new, live=True, reset=False)

    def _reset(self) -> None:
        view = self.view
        live = self.end_s is None
        end = max(view.t_s, view.history_s) if live else self.end_s
        for kind, ring in self._rings().items():
            self.cursors[kind] = ring.total
            rows = ring.rows
            self._write(kind, rows[(rows[:, 0] >= end - view.history_s) & (rows[:, 0] <= end)],
                        live=live, reset=True)

    def _write(self, kind: str, rows: np.ndarray, live: bool, reset: bool) -> None:
        if self.socket is None:
            return
        from tornado.websocket import WebSocketClosedError

        socket = self.socket
        try:
            written = socket.write_message(encode(kind, rows, live, self.view.peak_rate_hz,
                                                  reset), binary=True)
        except WebSocketClosedError:
            self.detach(socket)
            return
        # A page that goes away while a message is on its way: the socket is closed (and
        # forgotten) then, not an error.
        written.add_done_callback(lambda done: done.exception() and self.detach(socket))
        if kind == "map" and live and len(rows):
            last = float(rows[-1, 0])
            self.view.sending(last)
            self.sent_t, self.sent_at = last, time.monotonic()
            if self.on_sent is not None:
                self.on_sent(last)


def encode(kind: str, rows: np.ndarray, live: bool, high: float, reset: bool = False) -> bytes:
    """One message of a page's socket: the header, then the rows, float64 in this machine's
    byte order (a Float64Array's in the page)."""
    rows = np.asarray(rows, dtype=np.float64)
    header = [float(KINDS[kind]), float(reset), float(live), float(high), float(len(rows)),
              float(rows.shape[-1])]
    return np.concatenate([np.array(header), rows.ravel()]).tobytes()
