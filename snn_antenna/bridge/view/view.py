"""A live browser view of the online pipeline: the antenna's two axes, the coded input with the
gate's threshold Th, the resonators' rate map and each contact with its distance, plus the
link's counters; and ``/state.json`` with the same state for scripts and tests.

Why Bokeh: its server keeps a page's widgets, time axis and text in step with the view
process (a person's click reaches a Python callback), and it ships its own BokehJS, so the
page works on a robot's laptop with no internet. What streams (the plots' data) goes to each
page on a socket of its own (bridge/view/feed.py), drawn by the page's own small scripts.

The view never touches the pipeline's time. Its server runs in a process of its own
(bridge/view/process.py, started with ``spawn``): a page reloaded twice a second makes Bokeh
tear documents down (``gc.collect`` under the GIL), which in the pipeline's process stalled the
stream. The pipeline only gathers what it already has (samples, the coder's input, each
rate-map window, contact events) and every 50 ms hands one frame to a bounded
``multiprocessing`` queue with ``put_nowait``: it never waits. When the view process falls
behind (or is stopped), the frames it cannot take are dropped and counted by it
(``view_frames_dropped`` on the page and in the report), never a sample, which the recorder has
already written. The page itself is ``bridge/view/page.py``; its controls (pause, scrub, Th, the
rate-map window, save view) are ``bridge/view/page_controls.py``. A change of Th or window travels
the other way through a second bounded queue (``LiveView.requests``), which the view's handler
reads without waiting and submits to the stream's input schedule (bridge/online/schedule.py).
"""
from __future__ import annotations

import multiprocessing
import queue
import sys
import threading
import time
from contextlib import contextmanager
from itertools import chain
from pathlib import Path

import numpy as np

from ...core.errors import SpecError
from ..online.live_state import Decisions
from ..wire.handler import WindowHandler
from ..wire.protocol import BOARD_RATE_HZ
from .history import ViewConfig
from .process import serve

HISTORY_S = 10.0                # what the plots show
SCRUB_S = 60.0                  # what the view keeps: a paused page scrubs back through it
REQUESTS = 16                   # control requests from the page not yet taken by the pipeline
REQUEST_POLL_S = 0.02           # how often the pipeline's thread looks for them
FLUSH_S = 0.05                  # the pipeline hands a frame of samples over at most this often
# ... except that a new rate-map column goes at once, whenever the last frame went (the delay
# from a window's last sample to its column on screen is what a person watching sees), and
# at most this often: a backlog worked off (or a replay flat out) publishes windows in bursts.
WINDOW_FLUSH_S = 0.01
INBOX_FRAMES = 200              # 10 s of frames: the view may stall that long and lose nothing
START_TIMEOUT_S = 60.0          # a spawned interpreter imports Bokeh: seconds on a busy machine
STOP_TIMEOUT_S = 5.0


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

    out = getattr(args, "out", None)
    save_dir = getattr(args, "view_save", None) or (Path(out) / "views" if out
                                                    else Path("out") / "views")
    view = LiveView(parts, host=args.view_host, port=args.view_port, save_dir=str(save_dir))
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
        view.flush()                # the stream's last samples and contact, shown while held
        if ended and args.view_hold != 0:
            _hold(url, args.view_hold)
        summary = view.stop()
    dropped = summary["frames_dropped"]
    print(f"live view: {summary['frames_published']} frames published, "
          + ("the view process did not answer" if dropped is None
             else f"{dropped} dropped by the view"), file=sys.stderr, flush=True)


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


class LiveView(WindowHandler):
    """Pipeline side of the live view: a :class:`~snn_antenna.bridge.wire.handler.WindowHandler`
    of ``run_online`` that only gathers (the source's batches, the coder's pieces, the windows,
    the applied changes), and every ``FLUSH_S`` (a new rate-map column: ``WINDOW_FLUSH_S``)
    hands one frame to the view process without waiting; and that submits the page's requests
    to the input schedule. ``start`` spawns that process and returns the URL it is bound to;
    ``stop`` ends it."""

    def __init__(self, parts, *, host: str = "127.0.0.1", port: int = 0,
                 history_s: float = HISTORY_S, rate_hz: float = BOARD_RATE_HZ,
                 inbox_frames: int = INBOX_FRAMES, save_dir=None):
        from sklearn.base import clone

        coder = parts.chain.named_steps["coder"]
        # Its own fitted copy: the pipeline's is unfitted until calibration.
        to_g = clone(parts.chain.named_steps["to_g"]).fit(np.zeros((1, 2)))
        self.decisions = Decisions(parts)
        self.config = ViewConfig(host, port, rate_hz, history_s, parts.window_s,
                                 np.asarray(parts.array.neuron_hz, dtype=float), to_g,
                                 coder.amplitude, float(coder.threshold),
                                 self.decisions.parts, self.decisions.panels,
                                 keep_s=max(SCRUB_S, history_s), save_dir=save_dir,
                                 speed_range_cm_s=parts.robot.speed_range if parts.robot
                                 else None,
                                 speed_cm_s=parts.robot.start_speed if parts.robot else None)
        self.schedule = None                # the stream's, from its start
        self._context = multiprocessing.get_context("spawn")
        self._inbox = self._context.Queue(inbox_frames)
        # The page's control requests, checked in the view process (bridge/online/controls.py);
        # the pipeline takes them without waiting.
        self.requests = self._context.Queue(REQUESTS)
        self.requests.cancel_join_thread()
        # Its feeder thread must never hold this process up at exit (a stopped view's pipe
        # is full); what it still held is counted dropped by the view.
        self._inbox.cancel_join_thread()
        self.published = 0          # frames made
        self.handoff_full = 0       # of those, refused by a full hand-off (the view lagging)
        self._counts: dict = {}
        self._xy: list = []
        self._in: list = []
        self._windows: list = []
        self._events: list = []
        self._applied: list = []
        self._n_xy = self._n_in = 0
        self._flushed = self._window_flushed = time.monotonic()
        self._polled = 0.0
        self.url = self.port = None
        self.process = self._control = None
        self._counts_sent = self._view_count = None

    # ---- a WindowHandler (bridge/wire/handler.py): on the pipeline's thread ----------------
    def handle(self, batch) -> None:
        if batch.counts:
            self._counts = batch.counts
        if batch.samples:
            self._xy.append(batch.samples)
        self._take_requests()
        self._due()

    def idle(self) -> None:
        self._take_requests()
        self._due()

    def stream_started(self, parts, schedule) -> None:
        self.schedule = schedule
        self.decisions.stream_started(parts, schedule)

    def coded(self, signal_g, th_g, coded) -> None:
        self._in.append((signal_g, th_g, coded))

    def window(self, window) -> None:
        """A published window goes to the pages with what the network decided on it; its
        ``arrived`` (host time of its last sample, live only) is where the view process
        measures the delay to its column on a page from."""
        self.decisions.window(window)
        published = window.published
        if published is None:
            return
        self._windows.append((published.t_s, published.rates.copy(), published.realtime_factor,
                              published.latency_ms, self.decisions.latest, published.arrived,
                              published.window_s))
        self._note(published.event)
        self._due()

    def stream_ended(self, final_event) -> None:
        """The stream's last contact, closed at its end (no window of its own)."""
        self.decisions.stream_ended(final_event)
        self._note(final_event)
        self._due()

    def changed(self, event: dict) -> None:
        """A change the input schedule applied: shown on the page."""
        self._applied.append(event)
        self._due()

    def _take_requests(self) -> None:
        """What the page asked for (never waiting), submitted to the input schedule: applied
        at the first boundary of a published window the coder has not reached."""
        now = time.monotonic()
        if self.schedule is None or now - self._polled < REQUEST_POLL_S:
            return
        self._polled = now
        while True:
            try:
                change = self.requests.get_nowait()
            except (queue.Empty, OSError, ValueError):  # empty, or the view process is gone
                return
            self.schedule.submit(change, "page")

    def _note(self, event) -> None:
        if event is not None:
            kind, what = event
            self._events.append((kind, what if kind == "onset" else what.as_dict()))

    def _due(self) -> None:
        now = time.monotonic()
        if now - self._flushed >= FLUSH_S or (self._windows
                                              and now - self._window_flushed >= WINDOW_FLUSH_S):
            self.flush()

    def flush(self) -> None:
        """Hand what was gathered to the view process as one frame, without waiting."""
        self._flushed = time.monotonic()
        if self._windows:
            self._window_flushed = self._flushed
        if not (self._xy or self._in or self._windows or self._events or self._applied
                or self._counts is not self._counts_sent):     # e.g. a link lost: counts only
            return
        self._counts_sent = self._counts
        samples = (np.asarray(list(chain.from_iterable(self._xy)), dtype=float) if self._xy
                   else np.empty((0, 3)))
        coded = np.concatenate([_coded_rows(*piece) for piece in self._in]) if self._in \
            else np.empty((0, 3))
        frame = {"seq": self.published, "counts": self._counts,
                 "xy": (self._n_xy, samples), "coded": (self._n_in, coded),
                 "windows": self._windows, "events": self._events, "controls": self._applied}
        self._n_xy += len(samples)
        self._n_in += len(coded)
        self._xy, self._in, self._windows, self._events, self._applied = [], [], [], [], []
        self.published += 1
        try:
            self._inbox.put_nowait(frame)
        except queue.Full:
            self.handoff_full += 1

    # ---- the view process ------------------------------------------------------------------
    def start(self) -> str:
        """Spawn the view process; returns the page's URL (the address bound) once it listens."""
        control, child_end = self._context.Pipe()
        self.process = self._context.Process(target=serve, name="snn-antenna-view", daemon=True,
                                             args=(self.config, self._inbox, child_end,
                                                   self.requests))
        self.process.start()
        child_end.close()
        message = None
        try:
            if control.poll(START_TIMEOUT_S):
                message = control.recv()
        except EOFError:                        # it died before listening
            pass
        if message is None or message[0] != "ready":
            self._end_process()
            if message is not None:
                raise SpecError(*message[1])
            raise SpecError("view", "server", f"a view server that starts within "
                                              f"{START_TIMEOUT_S:g} s")
        _, self.url, self.port = message
        self._control = control
        return self.url

    def stop(self) -> dict:
        """Hand over the last frame, end the view process (killed if it does not answer within
        STOP_TIMEOUT_S, e.g. when stopped) and return :meth:`summary`."""
        self.flush()
        if self._control is not None:
            answer = None
            try:
                self._control.send(("stop", self.published,
                                    self.published - self.handoff_full))
                if self._control.poll(STOP_TIMEOUT_S):
                    answer = self._control.recv()[1]
            except (EOFError, OSError):
                pass
            self._view_count = answer
            self._control.close()
            self._control = None
            self._end_process()
        return self.summary()

    def _end_process(self) -> None:
        if self.process is not None:
            self.process.join(STOP_TIMEOUT_S)
            if self.process.is_alive():
                self.process.kill()
                self.process.join()
            self.process = None
        self._inbox.close()
        self.requests.close()

    def summary(self) -> dict:
        """The view's part of the run's report: frames published, and those the view process
        counted as dropped (None when it did not answer at the end)."""
        answer = self._view_count
        return {"frames_published": self.published,
                "frames_dropped": None if answer is None else answer["dropped"],
                "handoff_full": self.handoff_full}


def _coded_rows(signal, th, coded) -> np.ndarray:
    """(signal_g, th_g, coded) rows of one chunk through the coder."""
    n = len(coded)
    return np.column_stack([np.asarray(signal, dtype=float).reshape(n, -1)[:, 0],
                            np.broadcast_to(np.asarray(th, dtype=float), (n,)),
                            np.asarray(coded, dtype=float).reshape(n, -1)[:, 0]])
