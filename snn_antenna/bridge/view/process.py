"""The live view's own process: the Bokeh server, its pages and ``/state.json``, fed by the frames
the pipeline hands over (bridge/view/view.py's :class:`~snn_antenna.bridge.view.view.LiveView`).

Why a process of its own: a Bokeh server does real work while holding the GIL (a page that is
reloaded tears its document down, ``Document.destroy`` → ``gc.collect``; each open page pulls
and serialises new points five times a second and each new column). In the pipeline's process that
work stalled the
stream itself. Here it can only slow the view: the pipeline never waits for this process, and
frames the view could not take are counted here (``view_frames_dropped``), never a sample.

What it shows is kept in :class:`~snn_antenna.bridge.view.view.history.ViewHistory`
(bridge/view/history.py). Besides the pages and ``/state.json``, it answers the pages' POSTs
``/control`` (checked here, then queued to the pipeline) and ``/save``
(bridge/view/saved_view.py), and holds each page's own socket, ``/feed``: the plots' data
out, the paint reports (the display delay) back (bridge/view/feed.py).

Started with the ``spawn`` context, so this module and what it imports are all the process
holds: no Brian2, no port, no recorder.
"""
from __future__ import annotations

import asyncio
import json
import logging
import os
import queue
import signal
import sys
import threading
from functools import partial

from ...core.errors import SpecError
from .page import build_page
from .history import ViewConfig, ViewHistory
from .saved_view import save_view

VIEW_NICENESS = 10              # the view's CPU priority below the pipeline's (os.nice)
# The thread that takes a frame from the hand-off needs the GIL while the server's loop builds
# a page's update: at Python's default 5 ms interval a column waited that long for it.
GIL_SWITCH_S = 0.001
LAST_FRAMES_S = 2.0             # at the end, how long the view waits for frames still in transit
# A page's session outlives its page by this much (Bokeh's default: 15 s, checked every 17 s):
# a storm of reloads leaves a session per load until then (page.py keeps one nobody holds
# idle). Long enough for a busy machine's browser to load BokehJS and connect to the session
# its page was built with.
SESSION_LINGER_MS = 10_000
SESSION_CHECK_MS = 2_000


def serve(config: ViewConfig, inbox, control, requests=None) -> None:
    """The view process's main: bind, tell the pipeline the URL over ``control``, serve until
    it says ``("stop", frames published, frames handed over)`` (or goes away), then answer
    with the view's count."""
    # Ctrl-C in a terminal reaches the whole process group; the pipeline decides when the
    # view ends (a KeyboardInterrupt here would only print a traceback).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # When the cores are busy, the pipeline comes first: a page may update late, a sample not.
    os.nice(VIEW_NICENESS)
    sys.setswitchinterval(GIL_SWITCH_S)
    from bokeh.application import Application
    from bokeh.application.handlers.function import FunctionHandler
    from bokeh.server.server import BaseServer
    from bokeh.server.tornado import BokehTornado
    from bokeh.server.util import bind_sockets
    from tornado.httpserver import HTTPServer
    from tornado.ioloop import IOLoop

    from .hostguard import HostGuard, allowed_hosts  # lazy: tornado loads with a view

    # A stalled tab's queued messages are the only thing a slow browser costs; "closed the
    # websocket" is the normal end of one.
    logging.getLogger("bokeh.server.views.ws").setLevel(logging.ERROR)
    asyncio.set_event_loop(asyncio.new_event_loop())
    loop = IOLoop.current()
    history = ViewHistory(config)
    inbox, arrived = _receive(inbox, loop, history)
    history.requests, history.inbox = requests, inbox
    try:
        sockets, port = bind_sockets(config.host, config.port)
    except OSError as exc:
        control.send(("failed", ("view-port", config.port,
                                 f"a free port on {config.host} ({exc.strerror}), or 0 for "
                                 "any free port")))
        return
    allowed = allowed_hosts(config.host, port)
    handlers, routed = _handlers(), {"history": history, "inbox": inbox}
    app = BokehTornado({"/": Application(FunctionHandler(partial(build_page, history)))},
                       extra_websocket_origins=sorted(allowed),
                       extra_patterns=[(r"/state\.json", handlers["state"], routed),
                                       (r"/control", handlers["control"], routed),
                                       (r"/feed", handlers["feed"], routed),
                                       (r"/save", handlers["save"], routed)],
                       websocket_ping_interval=10, websocket_ping_timeout=10,
                       unused_session_lifetime_milliseconds=SESSION_LINGER_MS,
                       check_unused_sessions_milliseconds=SESSION_CHECK_MS)
    http = HTTPServer(HostGuard(app, allowed))
    http.add_sockets(sockets)
    BaseServer(loop, app, http).start()
    bound = sockets[0].getsockname()[0]
    shown = f"[{bound}]" if ":" in bound else bound
    control.send(("ready", f"http://{shown}:{port}/", port))

    threading.Thread(target=_answer_stop, args=(control, arrived), name="view-stop",
                     daemon=True).start()
    loop.start()


class _Arrived:
    """The frames that came through the pipeline's hand-off (counted by the thread that takes
    them, whatever the server's loop is busy with), and a condition to wait for more."""

    def __init__(self):
        self.count = 0
        self.changed = threading.Condition()

    def add(self) -> None:
        with self.changed:
            self.count += 1
            self.changed.notify_all()

    def wait_for(self, count: int, timeout_s: float) -> int:
        with self.changed:
            self.changed.wait_for(lambda: self.count >= count, timeout_s)
            return self.count


def _receive(handoff, loop, history) -> tuple[queue.Queue, _Arrived]:
    """A thread that waits on the pipeline's hand-off and passes each frame to the server's
    loop as it comes (``IOLoop.add_callback`` is the one thread-safe call): polling it every
    few ms would add up to that much to every column's delay. Returns the queue this process
    reads the frames from, in the order they came, and their count."""
    frames: queue.Queue = queue.Queue()
    arrived = _Arrived()

    def wait() -> None:
        while True:
            try:
                frame = handoff.get()
            except (EOFError, OSError, ValueError):     # the pipeline's end of it closed
                return
            frames.put(frame)
            arrived.add()
            loop.add_callback(history.drain, frames)

    threading.Thread(target=wait, name="view-handoff", daemon=True).start()
    return frames, arrived


def _answer_stop(control, arrived: _Arrived) -> None:
    """Wait for the pipeline's ``("stop", published, handed over)`` (or its going away),
    answer with the frames this process received and dropped, and end the process. All of it
    off the server's loop: however busy the loop is (a storm of reloaded pages leaves it
    sessions to tear down), the answer does not wait on it. Nothing is left to do after the
    answer (a saved view is written whole when asked), so the process exits at once: an
    interpreter's teardown with Bokeh and scikit-learn loaded takes 1-2 s on a busy machine."""
    try:
        _, published, handed = control.recv()
    except (EOFError, OSError):                 # the pipeline's process is gone
        os._exit(0)
    # The last frames may still be on their way (the queue's feeder thread writes them);
    # those the hand-off refused never come.
    received = arrived.wait_for(handed, LAST_FRAMES_S)
    try:
        control.send(("stopped", {"received": received, "dropped": published - received}))
    except OSError:
        pass
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(0)


def _handlers() -> dict:
    """``/state.json`` (GET), the page's POSTs: ``/control`` (a change of Th or the window),
    ``/save`` (the view's PNG: written with the shown span's data), and its own socket
    ``/feed``. All behind the HostGuard (bridge/view/hostguard.py)."""
    from tornado.web import RequestHandler
    from tornado.websocket import WebSocketHandler

    class Base(RequestHandler):
        def initialize(self, history: ViewHistory, inbox) -> None:
            self.history, self.inbox = history, inbox

        def reply(self, status: int, body: dict) -> None:
            self.set_status(status)
            self.set_header("Content-Type", "application/json")
            self.set_header("Cache-Control", "no-store")
            self.write(json.dumps(body))

        def check_xsrf_cookie(self) -> None:    # the HostGuard checked Host and Origin
            pass

    class State(Base):
        def get(self) -> None:
            self.history.drain(self.inbox)
            self.reply(200, self.history.state())

    class Control(Base):
        def post(self) -> None:
            try:
                asked = self.history.request(self.request.body)
            except SpecError as exc:
                self.reply(400, {"error": str(exc), "field": exc.field})
                return
            self.reply(202, {"requested": asked})

    class Feed(WebSocketHandler):
        """A page's own socket, ``/feed?page=TOKEN``: the page's feed (feed.PageFeed, found by
        the token its page was built with) writes the plots' data; the page sends its paint
        reports."""

        def initialize(self, history: ViewHistory, inbox) -> None:
            self.history, self.feed = history, None

        def check_origin(self, origin) -> bool:     # the HostGuard checked Host and Origin
            return True

        def open(self) -> None:
            self.feed = self.history.feeds.get(self.get_query_argument("page", ""))
            if self.feed is None:
                self.close(4404, "no such page: reload it")
                return
            self.set_nodelay(True)                  # a column is one small message: now
            self.feed.attach(self)

        def on_message(self, message) -> None:
            if self.feed is not None:
                self.feed.report(message)

        def on_close(self) -> None:
            if self.feed is not None:
                self.feed.detach(self)

    class Save(Base):
        def post(self) -> None:
            try:
                start = float(self.get_query_argument("start"))
                end = float(self.get_query_argument("end"))
                saved = save_view(self.history, start, end, self.request.body)
            except SpecError as exc:
                self.reply(400, {"error": str(exc), "field": exc.field})
                return
            except ValueError:
                self.reply(400, {"error": "expected ?start=SECONDS&end=SECONDS"})
                return
            self.reply(200, {"saved": saved})

    return {"state": State, "control": Control, "feed": Feed, "save": Save}
