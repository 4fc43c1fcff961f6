"""What the live view shows, kept in the view's own process: the frames the pipeline hands over
become rolling histories (the antenna's axes, the coded input, rate-map windows), the contacts,
the panels' latest decisions, the link's counters, the display delay the pages report and the
control requests from them (:class:`ViewHistory`). bridge/view/process.py serves it; the pages
(bridge/view/page.py) read it.
"""
from __future__ import annotations

import math
import os
import queue
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from ...core.errors import SpecError
from ..online.controls import parse_control

DELAYS_KEPT = 2000               # display delays kept for the p95
DISPLAY_EVERY = 4               # 1 kHz → 250 points/s per line: 8 per period at 30 Hz
SHOWN_COUNTERS = ("frames", "crc_errors", "gaps", "lost_samples", "duplicates", "reordered",
                  "late", "reconnects")



@dataclass
class ViewConfig:
    """What the view process needs from the pipeline's parts: plain values and its own fitted
    copy of the chain's ``to_g`` (counts → g), all picklable."""
    host: str
    port: int
    rate_hz: float
    history_s: float
    window_s: float
    neuron_hz: np.ndarray
    to_g: object
    coder_amplitude: float
    th_g: float
    parts: tuple = ()               # the parts of the running network
    panels: dict = None             # panel → title: what it decides (bridge/online/live_state.py)
    keep_s: float = 60.0            # what the view keeps: a paused page scrubs back through it
    save_dir: str | None = None     # where "save view" writes (bridge/view/saved_view.py)
    # The speeds the running network accepts from the page (None: no part reads a speed), and
    # the speed command at the start (bridge/online/robot.py).
    speed_range_cm_s: tuple | None = None
    speed_cm_s: float | None = None


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


class ViewHistory:
    """The view's side: the last ``history_s`` of what the frames carried, read by the pages
    (bridge/view/page.py) and ``/state.json``. A frame is a dict made by ``LiveView.flush``; its
    ``seq`` numbers frames, so a frame the pipeline could not hand over shows as a gap here."""

    def __init__(self, config: ViewConfig):
        self.config = config
        self.rate_hz, self.history_s = config.rate_hz, config.history_s
        self.neuron_hz, self.window_s = np.asarray(config.neuron_hz, float), config.window_s
        self.coder_amplitude, self.th_g = config.coder_amplitude, config.th_g
        self.keep_s = max(config.keep_s, self.history_s)
        # Points a plot shows at once (its rollover), and the rings: keep_s of them.
        self.shown_points = int(self.history_s * self.rate_hz) // DISPLAY_EVERY + 1
        n = int(self.keep_s * self.rate_hz) // DISPLAY_EVERY + 1
        self.xy = _Ring(3, n)                       # t_s, x_g, y_g
        self.coded = _Ring(4, n)                    # t_s, signal_g, th_g, coded
        n_windows = int(math.ceil(self.keep_s / self.window_s)) + 1
        self.windows = _Ring(2 + len(self.neuron_hz), n_windows)     # t_s, width_s, rates
        self.base_window_s = self.window_s
        self.arrivals: dict[float, float] = {}      # window start → host arrival (live only)
        self.display_delays_ms: deque = deque(maxlen=DELAYS_KEPT)
        # Of each delay, the part until a page's update left this process (the rest is the
        # websocket and the browser drawing): where the time goes.
        self.sent: dict[float, float] = {}          # window start → first sent to a page
        self.server_delays_ms: deque = deque(maxlen=DELAYS_KEPT)
        # ... the part until this process took the window from the pipeline's hand-off, and
        # the part until the page's document had it (the rest: the browser drawing)
        self.taken_at: dict[float, float] = {}      # window start → taken here
        self.handoff_delays_ms: deque = deque(maxlen=DELAYS_KEPT)
        self.received_delays_ms: deque = deque(maxlen=DELAYS_KEPT)
        self.painted_by: dict[str, float] = {}      # page → the latest column it painted
        self.controls: list[dict] = []              # changes the pipeline applied
        self.requested: list[dict] = []             # asked from a page, not applied yet
        self.requests = None                        # the queue to the pipeline (serve sets it)
        self.inbox = None                           # the frames from it (serve sets it)
        self.contacts: list[dict] = []
        self.open_onset_s: float | None = None
        self.realtime_factor = self.latency_ms = None
        self.counts: dict = {}
        self.parts, self.panels = tuple(config.parts), dict(config.panels or {})
        self.decided: dict = {}                     # panel → the latest window's values
        self.n_samples = 0
        self.peak_rate_hz = 10.0
        self.sessions = 0                           # pages open now
        # Each open page's "send me the new columns" (feed.PageFeed.send_columns): called when
        # new rate-map columns arrive, so a column goes out on arrival, not at the next pull.
        self.column_listeners: set = set()
        # ... and each page's feed by the page's token: its socket (/feed) finds it here.
        self.feeds: dict = {}
        self.column_at: float | None = None         # when the latest columns came in
        self.pages_served = 0                       # pages built, ever (each load makes one)
        self.received = 0                           # frames taken
        self.dropped = 0                            # frames the pipeline published, never seen
        self.next_seq = 0                           # the frame number expected next

    def drain(self, inbox, wait_s: float = 0.0) -> int:
        """Take every frame waiting in ``inbox`` (waiting up to ``wait_s`` for the first);
        tell the open pages when new rate-map columns came with them."""
        taken, columns = 0, self.windows.total
        while True:
            try:
                frame = inbox.get(timeout=wait_s) if wait_s and not taken else inbox.get_nowait()
            except queue.Empty:
                break
            self.take(frame)
            taken += 1
        if self.windows.total != columns:
            self.column_at = time.monotonic()
            for update_now in list(self.column_listeners):
                update_now()
        return taken

    def next_column_in(self) -> float | None:
        """Seconds until the next rate-map column is expected (a window after the last came
        in), None before the first; negative when it is late."""
        if self.column_at is None:
            return None
        return self.column_at + self.window_s - time.monotonic()

    def pull(self) -> None:
        """Take the frames waiting in the inbox, if this history has one."""
        if self.inbox is not None:
            self.drain(self.inbox)

    def take(self, frame: dict) -> None:
        self.dropped += frame["seq"] - self.next_seq       # the frames between never came
        self.next_seq = frame["seq"] + 1
        self.received += 1
        if frame["counts"]:
            self.counts = frame["counts"]
        first, samples = frame["xy"]
        if len(samples):
            rows = self._rows(first, samples[:, 1:])
            if len(rows):           # a piece shorter than DISPLAY_EVERY may have no shown point
                rows[:, 1:] = self.config.to_g.transform(rows[:, 1:])
                self.xy.add(rows)
            self.n_samples = first + len(samples)
        first, coded = frame["coded"]
        if len(coded):
            self.coded.add(self._rows(first, coded))
            if self.coded.total:
                self.th_g = float(self.coded.rows[-1, 2])
        for t_s, rates, rtf, latency_ms, decided, arrived, width_s in frame["windows"]:
            self.decided = decided
            self.window_s = width_s
            self.windows.add(np.r_[t_s, width_s, rates][None, :])
            if arrived is not None:
                self.arrivals[round(float(t_s), 6)] = arrived
                self.taken_at[round(float(t_s), 6)] = time.time()
                while len(self.arrivals) > self.windows.capacity:
                    oldest = next(iter(self.arrivals))
                    del self.arrivals[oldest]
                    self.sent.pop(oldest, None)
                    self.taken_at.pop(oldest, None)
            self.peak_rate_hz = max(self.peak_rate_hz, float(rates.max()))
            self.realtime_factor = rtf if rtf is not None and np.isfinite(rtf) else None
            self.latency_ms = latency_ms
        for kind, what in frame["events"]:
            if kind == "onset":
                self.open_onset_s = float(what)
            else:
                self.contacts.append(what)
                self.open_onset_s = None
        for event in frame.get("controls", ()):
            self.controls.append(event)
            for asked in self.requested:
                if asked["field"] == event["field"] and asked["value"] == event["value"]:
                    self.requested.remove(asked)
                    break

    # ---- the page's hands on the controls --------------------------------------------------
    def request(self, body) -> dict:
        """A control request from a page or ``POST /control``: checked (SpecError names the
        field, value and accepted range), then handed to the pipeline without waiting; it
        applies at the next window boundary."""
        change = parse_control(body, self.base_window_s, self.config.speed_range_cm_s)
        if self.requests is None:
            raise SpecError("control", change.field, "a running pipeline to apply it to")
        try:
            self.requests.put_nowait(change)
        except queue.Full:
            raise SpecError("control", change.field, "a moment later: the pipeline has not "
                                                     "taken the requests before it") from None
        asked = {"field": change.field, "value": change.value, "asked_t_s": self.t_s}
        self.requested.append(asked)
        return asked

    def painted(self, t_s: float, painted_unix_s: float, now: float | None = None,
                page: str | None = None, received_unix_s: float | None = None) -> None:
        """A page painted the rate-map column of the window starting at ``t_s`` (its clock):
        the delay from the arrival of that window's last sample (``received_unix_s``: when
        the column reached the page's document, before drawing). The page's clock is
        trusted only between arrival and now (this host's clock)."""
        if page is not None and len(self.painted_by) < 1000:
            self.painted_by[page] = round(float(t_s), 6)
        arrived = self.arrivals.get(round(float(t_s), 6))
        if arrived is None:
            return
        now = time.time() if now is None else now

        def on_this_clock(page_s) -> float:
            return min(max(float(page_s), arrived), now) if math.isfinite(page_s) else now

        painted = on_this_clock(painted_unix_s)
        self.display_delays_ms.append((painted - arrived) * 1e3)
        if received_unix_s is not None:
            self.received_delays_ms.append((min(on_this_clock(received_unix_s), painted)
                                            - arrived) * 1e3)
        sent = self.sent.get(round(float(t_s), 6))
        if sent is not None:
            self.server_delays_ms.append((sent - arrived) * 1e3)
        taken = self.taken_at.get(round(float(t_s), 6))
        if taken is not None:
            self.handoff_delays_ms.append((taken - arrived) * 1e3)

    def sending(self, t_s: float) -> None:
        """A page's update carries the rate-map column of the window starting at ``t_s``."""
        self.sent.setdefault(round(float(t_s), 6), time.time())

    def display_latency(self) -> dict:
        delays = np.asarray(self.display_delays_ms)
        if not len(delays):
            return {"last": None, "median": None, "p95": None, "n": 0, "sent_p95": None,
                    "taken_p95": None, "received_p95": None}

        def p95(parts) -> float | None:
            return round(float(np.percentile(parts, 95)), 2) if len(parts) else None

        return {"last": round(float(delays[-1]), 2), "median": round(float(np.median(delays)), 2),
                "p95": p95(delays), "n": int(len(delays)),
                # arrival → the page's update leaving this process (the rest: websocket, paint)
                "sent_p95": p95(self.server_delays_ms),
                # arrival → taken by this process from the pipeline's hand-off
                "taken_p95": p95(self.handoff_delays_ms),
                # arrival → in the page's document (the rest: the browser drawing it)
                "received_p95": p95(self.received_delays_ms)}

    def ended(self, published: int) -> None:
        """The pipeline published ``published`` frames in all: those never taken are dropped."""
        self.dropped = max(self.dropped, published - self.received)

    def _rows(self, first: int, values: np.ndarray) -> np.ndarray:
        """Rows (t_s, values...) of every DISPLAY_EVERY-th sample by stream index, so that
        decimation does not depend on how the port chunked the samples."""
        index = np.arange(first, first + len(values))
        keep = index % DISPLAY_EVERY == 0
        return np.column_stack([index[keep] / self.rate_hz, values[keep]])

    @property
    def t_s(self) -> float:
        """Stream time: the samples received so far at the sample rate."""
        return self.n_samples / self.rate_hz

    def state(self) -> dict:
        """The live state as plain JSON (``/state.json``)."""
        last = self.windows.rows[-1] if self.windows.total else None
        if last is not None:
            last = np.r_[last[0], last[2:]]
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
            "window_s": self.window_s,
            # The page's hands: changes applied (with the sample they applied at), and asked.
            "controls": {"applied": list(self.controls), "requested": list(self.requested)},
            # Arrival of a window's last sample → its column painted on a page.
            "display_latency_ms": self.display_latency(),
            # What the running network decided on the latest window, a panel per part it has.
            "network": {"parts": list(self.parts), "panels": dict(self.panels),
                        "decided": self.decided},
            "counters": {"realtime_factor": _finite(self.realtime_factor),
                         "latency_ms": _finite(self.latency_ms),
                         **{k: self.counts.get(k, 0) for k in SHOWN_COUNTERS},
                         "view_frames_dropped": self.dropped},
            # Points kept for the plots (every DISPLAY_EVERY-th sample), ever.
            "plotted": {"xy": self.xy.total, "coded_input": self.coded.total},
            "sessions": self.sessions,
            "pages_served": self.pages_served,
            "view_pid": os.getpid(),
        }


def _finite(value):
    return None if value is None or not np.isfinite(value) else round(float(value), 3)
