"""A sample source on a serial port, in the shape of pyserial's ``serial.threaded``.

transport  :class:`SerialTransport` opens, reads and reopens the port (``serial_for_url``: device
           paths, ``loop://``, ``socket://``, ``rfc2217://``) and turns pyserial's errors into
           messages a user can act on.
framing    :class:`~snn_antenna.bridge.wire.protocol.Decoder`, a pure function of the bytes.
handling   whoever consumes :class:`Batch` objects from :meth:`SerialSource.get` (the recorder,
           the online pipeline), on their own thread, through a bounded queue.

The reader thread blocks on a full queue instead of dropping: the kernel's buffer then fills and
any loss shows up where it belongs, as counted gaps in the sequence numbers.
"""
from __future__ import annotations

import collections
import errno
import queue
import signal
import threading
import time
from dataclasses import dataclass, field

import serial

from ...core import bounds
from ...core.errors import DeviceError, SpecError
from .handler import BatchHandler
from .protocol import Decoder, Sample, Session, check_wire_format

DEFAULT_BAUDRATE = 250000
MAX_QUEUE_BATCHES = 1_000_000    # batches held for a slow consumer (one per read, ~50 ms each)
ACCEPTED_PORTS = ("an existing serial device path (e.g. /dev/ttyACM0) or a pyserial URL "
                  "(loop://, socket://HOST:PORT, rfc2217://HOST:PORT)")


class PortError(DeviceError):
    """The port exists but cannot be used: busy, lost for good, or silent."""


@dataclass
class Batch:
    """What one read of the port produced, stamped with the host clock when it was read.

    ``event`` marks a change of link state (``"opened"``, ``"lost"``, ``"reconnected"``,
    ``"failed"``, or ``"end"`` of a replayed file) and then ``raw`` and ``samples`` are empty.
    ``counts`` is a snapshot of the decoder's and the transport's counters after this batch, so
    a consumer writing both data and counts stays consistent. ``sessions`` are the board sessions
    that began in this batch, ``Session.index`` counted in samples delivered since the start.
    """
    host_time_s: float
    raw: bytes = b""
    samples: list[Sample] = field(default_factory=list)
    counts: dict = field(default_factory=dict)
    event: str | None = None
    message: str = ""
    sessions: list[Session] = field(default_factory=list)


def describe_open_error(url: str, exc: Exception) -> Exception:
    """pyserial's open errors, turned into a message that says what to do."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.ENOENT or "No such file" in text:
        return SpecError("port", url, ACCEPTED_PORTS + "; no such device exists")
    if code in (errno.EAGAIN, errno.EBUSY) or "exclusively lock" in text:
        return PortError(f"serial port {url!r} is busy: another program holds it open "
                         "(close the serial monitor, or find it with `fuser " + url + "`)")
    if code == errno.EACCES:
        return PortError(f"permission denied on serial port {url!r}: add your user to the "
                         "'dialout' group or run with access to the device")
    if isinstance(exc, ValueError) and ("invalid URL" in text or "unknown URL scheme" in text):
        return SpecError("port", url, ACCEPTED_PORTS)
    return PortError(f"cannot open serial port {url!r}: {text}")


class SerialTransport:
    """The port itself. ``exclusive=True`` takes an advisory lock so that two recorders on one
    device fail loudly instead of each receiving half of the bytes."""

    def __init__(self, url: str, baudrate: int = DEFAULT_BAUDRATE, read_timeout_s: float = 0.05,
                 port: serial.SerialBase | None = None):
        bounds.declared(self, url=url, baudrate=baudrate, read_timeout_s=read_timeout_s, port=port)
        bounds.seconds("read_timeout_s", read_timeout_s)
        if not isinstance(baudrate, int) or baudrate <= 0:
            raise SpecError("baudrate", baudrate, "a positive integer (the board uses 250000)")
        self.url, self.baudrate, self.read_timeout_s = url, baudrate, read_timeout_s
        self.port = port
        self.reopenable = port is None and not url.startswith("loop://")

    def open(self) -> None:
        if self.port is not None and self.port.is_open:
            return
        try:
            self.port = serial.serial_for_url(self.url, baudrate=self.baudrate,
                                              timeout=self.read_timeout_s, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise describe_open_error(self.url, exc) from exc

    def read(self) -> bytes:
        """Whatever is waiting, or b"" after the read timeout; ``serial.SerialException`` when the
        device went away."""
        try:
            return self.port.read(self.port.in_waiting or 1)
        except OSError as exc:          # in_waiting on a vanished pty raises a bare OSError
            raise serial.SerialException(str(exc)) from exc

    def close(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            except (serial.SerialException, OSError):
                pass
            if self.reopenable:
                self.port = None


class SerialSource:
    """Reads a port on a thread, decodes it and hands :class:`Batch` objects to one consumer.

    When the device disappears (USB unplugged, adapter re-enumerated) the source retries the same
    path with exponential backoff until ``reconnect_timeout_s`` runs out; each success is counted
    in ``reconnects``. Everything decoded before the loss has already been handed over.
    """

    def __init__(self, url: str, *, wire_format: str = "binary", baudrate: int = DEFAULT_BAUDRATE,
                 port: serial.SerialBase | None = None, queue_size: int = 4096,
                 reconnect_timeout_s: float = 30.0, backoff_initial_s: float = 0.02,
                 backoff_max_s: float = 1.0):
        bounds.declared(self, url=url, wire_format=wire_format, baudrate=baudrate, port=port,
                        queue_size=queue_size, reconnect_timeout_s=reconnect_timeout_s,
                        backoff_initial_s=backoff_initial_s, backoff_max_s=backoff_max_s)
        check_wire_format(wire_format)
        # 0 would make the queue unbounded: a stalled consumer would then grow it without end
        bounds.integer("queue_size", queue_size, 1, MAX_QUEUE_BATCHES)
        for name, value in (("reconnect_timeout_s", reconnect_timeout_s),
                            ("backoff_initial_s", backoff_initial_s),
                            ("backoff_max_s", backoff_max_s)):
            if not value >= 0:
                raise SpecError(name, value, "a number of seconds >= 0")
        self.url = url
        self.transport = SerialTransport(url, baudrate, port=port)
        self.decoder = Decoder(wire_format)
        self.reconnects = 0
        self.reconnect_timeout_s = reconnect_timeout_s
        self.backoff_initial_s, self.backoff_max_s = backoff_initial_s, backoff_max_s
        self._queue: queue.Queue[Batch] = queue.Queue(maxsize=queue_size)
        self._leftover: collections.deque[Batch] = collections.deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bytes_received = 0
        self._sessions_told = 0
        # The board's silence, on the reader's own clock: the reader stamps when a read returned
        # a valid frame and when its last read ended. A host that stalls stops both clocks, and
        # its first read after the stall takes what the port buffered meanwhile.
        self._last_valid_s = self._last_read_end_s = time.monotonic()

    # -- consumer side -------------------------------------------------------------------------
    def start(self) -> SerialSource:
        """Open the port now, so that a missing or busy port fails in the caller's thread."""
        self.transport.open()
        self.started_monotonic = time.monotonic()
        self._put(Batch(time.time(), counts=self.counts(), event="opened"))
        self._thread = threading.Thread(target=self._run, name=f"serial-reader {self.url}",
                                        daemon=True)
        self._thread.start()
        return self

    def get(self, timeout: float | None = None) -> Batch | None:
        if self._leftover:
            return self._leftover.popleft()
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def pending(self) -> bool:
        """Whether :meth:`get` would return a batch without waiting."""
        return bool(self._leftover) or not self._queue.empty()

    def stop(self) -> None:
        """Stop reading; batches already read stay available to :meth:`get`."""
        self._stop.set()
        while self._thread is not None and self._thread.is_alive():
            self._take_queued()         # unblocks a reader waiting on a full queue
            self._thread.join(timeout=0.05)
        self._take_queued()
        self._release_held(self._leftover.append)
        self.transport.close()

    def _release_held(self, put) -> None:
        """Frames the decoder holds behind a hole are delivered once no more bytes can come."""
        held = self.decoder.flush()
        if held:
            put(self._batch(time.time(), b"", held))

    def _batch(self, now: float, raw: bytes, samples: list[Sample]) -> Batch:
        sessions = self.decoder.sessions[self._sessions_told:]
        self._sessions_told = len(self.decoder.sessions)
        return Batch(now, raw, samples, self.counts(), sessions=sessions)

    def board_silent_s(self) -> float:
        """How long the reader has been reading without a valid frame (the board's silence, not
        the host's: a stalled reader reads nothing and counts nothing)."""
        return max(0.0, self._last_read_end_s - self._last_valid_s)

    def _take_queued(self) -> None:
        while True:
            try:
                self._leftover.append(self._queue.get_nowait())
            except queue.Empty:
                return

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def counts(self) -> dict:
        stats = self.decoder.stats.as_dict()
        stats["reconnects"] = self.reconnects
        stats["bytes"] = self.bytes_received
        return stats

    # -- reader thread -------------------------------------------------------------------------
    def _put(self, batch: Batch) -> None:
        while not self._stop.is_set():
            try:
                self._queue.put(batch, timeout=0.1)
                return
            except queue.Full:
                continue

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                raw = self.transport.read()
            except serial.SerialException as exc:
                self._release_held(self._put)
                self._put(Batch(time.time(), counts=self.counts(), event="lost", message=str(exc)))
                self.transport.close()
                if not self._reconnect():
                    return
                continue
            ended = time.monotonic()
            if raw:
                now = time.time()
                self.bytes_received += len(raw)
                samples = self.decoder.feed(raw, ended)
                if samples:
                    self._last_valid_s = ended
                self._put(self._batch(now, raw, samples))
            self._last_read_end_s = ended

    def _reconnect(self) -> bool:
        if not self.transport.reopenable:
            self._put(Batch(time.time(), counts=self.counts(), event="failed",
                            message=f"{self.url} cannot be reopened"))
            return False
        deadline = time.monotonic() + self.reconnect_timeout_s
        delay = self.backoff_initial_s
        last_error = ""
        while not self._stop.is_set():
            try:
                self.transport.open()
            except (SpecError, PortError) as exc:
                last_error = str(exc)
            else:
                self.reconnects += 1
                self.decoder.resync()
                self._last_valid_s = self._last_read_end_s = time.monotonic()
                self._put(Batch(time.time(), counts=self.counts(), event="reconnected"))
                return True
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                self._put(Batch(time.time(), counts=self.counts(), event="failed",
                                message=f"serial port {self.url!r} disappeared and did not come "
                                        f"back within {self.reconnect_timeout_s:g} s "
                                        f"(last error: {last_error})"))
                return False
            self._stop.wait(min(delay, remaining))
            delay = min(delay * 2, self.backoff_max_s)
        return False


@dataclass
class RunResult:
    status: str             # "ok": the duration was reached, the stop was set or the file ended
    counts: dict = field(default_factory=dict)
    busy_s: float = 0.0     # wall time not spent waiting for the port


@dataclass
class SourceLoop:
    """Drives a started source: hands every batch to each handler (a
    :class:`~snn_antenna.bridge.wire.handler.BatchHandler`: ``handle(batch)``, and ``idle()``
    when nothing came) and yields it, until ``duration_s`` of wall time, ``stop``, or
    an error. Iterating is for consumers that do more with the batches (the online pipeline);
    :func:`run_source` just exhausts it.

    Raises :class:`PortError` when the port is lost for good, or when no valid frame arrives for
    ``no_data_timeout_s`` while the link is up (a board reset by DTR is silent for 1-3 s, hence
    the 5 s default). That silence is the board's, as the reader saw it
    (``source.board_silent_s()``): a host that stalled longer than the timeout first reads what
    the port buffered. Handlers have seen everything received before the error.
    """
    source: object
    handlers: tuple = ()
    duration_s: float | None = None
    no_data_timeout_s: float = 5.0
    stop: threading.Event | None = None
    idle_interval_s: float = 0.02
    waiting_s: float = 0.0          # time spent blocked waiting for the port

    def __post_init__(self):
        if self.duration_s is not None and not self.duration_s > 0:
            raise SpecError("duration", self.duration_s, "a number of seconds > 0")
        if not self.no_data_timeout_s > 0:
            raise SpecError("no_data_timeout", self.no_data_timeout_s, "a number of seconds > 0")
        self.handlers = tuple(self.handlers)
        for handler in self.handlers:
            if not isinstance(handler, BatchHandler):
                raise SpecError("handlers", type(handler).__name__,
                                "BatchHandler instances (bridge/wire/handler.py)")

    def __iter__(self):
        last_valid = time.monotonic()
        # A duration counts from the port's opening: a consumer may start iterating later
        # (Brian2 builds its network first) while the reader is already collecting.
        started = getattr(self.source, "started_monotonic", last_valid)
        link_up = True
        while self.stop is None or not self.stop.is_set():
            if self.duration_s is not None and time.monotonic() - started >= self.duration_s:
                break
            asked = time.monotonic()
            batch = self.source.get(timeout=self.idle_interval_s)
            now = time.monotonic()
            self.waiting_s += now - asked
            if batch is None:
                for handler in self.handlers:
                    handler.idle()
            else:
                for handler in self.handlers:
                    handler.handle(batch)
                if batch.samples:
                    last_valid = now
                if batch.event == "lost":
                    link_up = False
                elif batch.event == "reconnected":
                    link_up, last_valid = True, now
                elif batch.event == "failed":
                    raise PortError(batch.message)
                elif batch.event == "end":      # a replayed file is exhausted
                    return
                yield batch
            silent_s = (self.source.board_silent_s() if hasattr(self.source, "board_silent_s")
                        else now - last_valid)
            if link_up and silent_s > self.no_data_timeout_s:
                self._drain()
                raise PortError(_silence_message(self.source, silent_s))
        # Stopped by the clock or a signal: what the port delivered until now is still kept.
        self._drain()

    def _drain(self) -> None:
        self.source.stop()
        while (batch := self.source.get(timeout=0)) is not None:
            for handler in self.handlers:
                handler.handle(batch)


def run_source(source, handlers, *, duration_s: float | None = None,
               no_data_timeout_s: float = 5.0, stop: threading.Event | None = None) -> RunResult:
    """Run a started source into ``handlers`` (see :class:`SourceLoop`)."""
    loop = SourceLoop(source, handlers, duration_s, no_data_timeout_s, stop)
    t0 = time.monotonic()
    for _ in loop:
        pass
    return RunResult("ok", source.counts(), time.monotonic() - t0 - loop.waiting_s)


def _silence_message(source: SerialSource, silent_s: float) -> str:
    head = f"no valid frame from {source.url!r} for {silent_s:.1f} s"
    if source.bytes_received and not source.decoder.stats.frames:
        return (f"{head}: received {source.bytes_received} bytes that do not decode as "
                f"{source.decoder.wire_format} frames; check --baudrate (the board uses "
                f"{DEFAULT_BAUDRATE}) and --format (binary or ascii)")
    if not source.bytes_received:
        return (f"{head}: nothing was received; is the board powered and streaming, "
                "and is this its port?")
    return f"{head}: the board stopped sending"


def stop_on_signals() -> threading.Event:
    """Ctrl-C and SIGTERM end a recording cleanly (data flushed, meta.json complete)."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop
