"""A device emulator: the sensor board's stream, at 1 kHz real time, with faults on demand.

It writes the wire format to a pseudo-terminal it creates (:class:`PtyLink`, optionally behind a
symlink that survives a disconnect) or to any pyserial URL (:class:`SerialLink`). Faults are
placed by a seeded generator and every one is logged, so a test can compare what the receiver
counted with what was injected:

garbage     random bytes, ended by a delimiter, before a frame: each zero-free run is one framing
            error (runs are never 9 bytes long, the length of a real frame, so none can pass).
drop        a frame is not sent: a gap.
bitflip     one bit of a frame's content (payload or CRC) flipped: a CRC error and a gap.
range       a frame with a valid CRC but x beyond 1023: a range error and a gap.
stall       the link pauses for ``stall_s``; the board keeps sampling and the backlog follows in
            a burst: nothing is lost.
disconnect  the port vanishes for ``outage_s`` and comes back at the same path; the board keeps
            sampling, so the frames due meanwhile are lost: one gap per outage, one reconnect.

Like a board whose host opens the port, the emulator waits for a reader before it streams, and
before it pulls the port away it waits until the reader has taken every byte already written:
"written" then means "received", which is what makes exact comparisons possible.
"""
from __future__ import annotations

import array
import errno
import fcntl
import math
import os
import select
import termios
import threading
import time
import tty
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SpecError
from .protocol import (
    ADC_MAX,
    ENCODED_FRAME_LEN,
    SEQ_MODULUS,
    Sample,
    cobs_encode,
    encoder_for,
    find_gaps,
    frame_payload,
    DELIMITER,
)

FAULT_KINDS = ("garbage", "drop", "bitflip", "range", "stall", "disconnect")


class PeerGone(RuntimeError):
    """The reader closed the port (or never opened it in time)."""


# -- links -------------------------------------------------------------------------------------
class PtyLink:
    """The emulator's end of a pseudo-terminal; the reader opens :attr:`path`.

    With ``link`` the path is a symlink that is removed on disconnect and recreated, pointing at
    a fresh pty, on reconnect: the same path disappears and returns, as a USB adapter's
    ``/dev/serial/by-id`` name does.
    """

    def __init__(self, link: str | os.PathLike | None = None):
        self.link = Path(link) if link is not None else None
        self.master: int | None = None
        self.slave_name = ""
        # Held while unread_bytes() has the slave open itself: that fd clears POLLHUP on the
        # master exactly as a reader's would, so peer_open() must not look meanwhile. Without
        # this, a probe from another thread (a test watching the queue) passed for the reader:
        # the emulator started, the probe closed, the first write saw POLLHUP and gave up
        # before the real reader had opened the port, which then received nothing at all.
        self._probing = threading.Lock()
        if self.link is not None:
            check_link_path(self.link)
        self._open()

    @property
    def path(self) -> str:
        return str(self.link) if self.link is not None else self.slave_name

    def _open(self) -> None:
        self.master, slave = os.openpty()
        # Raw before the first byte: a cooked tty would echo, translate CR and swallow ^C/^S.
        tty.setraw(slave)
        self.slave_name = os.ttyname(slave)
        # Holding no slave fd lets POLLHUP on the master tell whether a reader has it open.
        os.close(slave)
        os.set_blocking(self.master, False)
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".new")
            tmp.unlink(missing_ok=True)
            os.symlink(self.slave_name, tmp)
            os.replace(tmp, self.link)

    def peer_open(self) -> bool:
        """Whether a reader holds the slave open (the link's own probe does not count)."""
        with self._probing:
            poller = select.poll()
            poller.register(self.master, select.POLLOUT)
            return not any(ev & select.POLLHUP for _, ev in poller.poll(0))

    def wait_for_peer(self, timeout_s: float | None, stop: threading.Event) -> None:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.peer_open():
            if stop.is_set():
                raise PeerGone("stopped")
            if deadline is not None and time.monotonic() > deadline:
                raise PeerGone(f"nobody opened {self.path} within {timeout_s:g} s")
            time.sleep(0.005)
        # pyserial configures the tty and flushes its input right after open(): bytes written
        # in that instant would vanish, so give it a moment.
        time.sleep(0.05)

    def write(self, data: bytes, stop: threading.Event) -> None:
        view = memoryview(data)
        poller = select.poll()
        poller.register(self.master, select.POLLOUT)
        while view:
            events = poller.poll(100)
            if any(ev & select.POLLHUP for _, ev in events):
                raise PeerGone(f"the reader closed {self.path}")
            if stop.is_set():
                raise PeerGone("stopped")
            if not events:
                continue
            try:
                view = view[os.write(self.master, view):]
            except BlockingIOError:
                continue
            except OSError as exc:
                if exc.errno == errno.EIO:
                    raise PeerGone(f"the reader closed {self.path}") from exc
                raise

    def unread_bytes(self) -> int:
        """Bytes written but not yet read by the peer (the slave's input queue).

        The queue is only visible from the slave side, so this opens the slave for a moment;
        ``_probing`` keeps that moment from being taken for a reader (see :meth:`peer_open`).
        """
        with self._probing:
            try:
                fd = os.open(self.slave_name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            except OSError:
                return 0
            try:
                count = array.array("i", [0])
                fcntl.ioctl(fd, termios.FIONREAD, count, True)
                return count[0]
            finally:
                os.close(fd)

    def drain(self, timeout_s: float = 2.0) -> None:
        time.sleep(0.02)                # the pty moves written bytes to the reader asynchronously
        deadline = time.monotonic() + timeout_s
        while self.unread_bytes() and self.peer_open() and time.monotonic() < deadline:
            time.sleep(0.005)

    def disconnect(self) -> None:
        if self.link is not None:
            self.link.unlink(missing_ok=True)
        if self.master is not None:
            os.close(self.master)
            self.master = None

    def reconnect(self) -> None:
        self._open()

    def close(self) -> None:
        self.disconnect()

    @property
    def can_disconnect(self) -> bool:
        return self.link is not None


def is_own_link(path: Path) -> bool:
    """A symlink to a pseudo-terminal: what PtyLink makes (perhaps left by a killed emulator)."""
    return path.is_symlink() and os.readlink(path).startswith(("/dev/pts/", "/dev/tty"))


def check_link_path(link: Path) -> None:
    """Refuse a --link path that holds anything but an emulator's own link: the emulator
    replaces that path and removes it on exit, so it must never be a file or folder of the
    user's."""
    link = Path(link)
    if link.is_symlink() and not is_own_link(link):
        raise SpecError("link", str(link), f"a new path or an emulator's own link to a pty; "
                                           f"this is a symlink to {os.readlink(link)}, left as "
                                           "it is")
    if link.exists() and not link.is_symlink():
        what = "folder" if link.is_dir() else "file"
        raise SpecError("link", str(link), f"a new path or an emulator's own link to a pty; "
                                           f"this is an existing {what}, left as it is")
    if not link.parent.is_dir() or not os.access(link.parent, os.W_OK | os.X_OK):
        raise SpecError("link", str(link), f"a path in a folder you can write to "
                                           f"({link.parent} is not one)")
    tmp = link.with_name(link.name + ".new")
    if (tmp.exists() or tmp.is_symlink()) and not is_own_link(tmp):
        raise SpecError("link", str(link), f"a path whose {tmp.name} is free (the emulator "
                                           "creates the link there first)")


class SerialLink:
    """Any pyserial URL or open port (``loop://``, ``socket://``, a real device)."""

    can_disconnect = False

    def __init__(self, port_or_url):
        import serial

        if isinstance(port_or_url, str):
            self.port = serial.serial_for_url(port_or_url, baudrate=250000, write_timeout=1.0)
            self._owned = True
        else:
            self.port, self._owned = port_or_url, False
        self.path = self.port.port or "loop://"

    def wait_for_peer(self, timeout_s, stop) -> None:
        pass

    def write(self, data: bytes, stop: threading.Event) -> None:
        self.port.write(data)

    def drain(self, timeout_s: float = 2.0) -> None:
        self.port.flush()
        deadline = time.monotonic() + timeout_s
        # loop:// holds unread bytes in a queue the reader empties; a real port has no such view.
        pending = getattr(self.port, "in_waiting", 0)
        while pending and time.monotonic() < deadline:
            time.sleep(0.005)
            pending = self.port.in_waiting

    def close(self) -> None:
        if self._owned:
            self.port.close()


# -- faults ------------------------------------------------------------------------------------
@dataclass
class FaultPlan:
    """How many faults of each kind to inject, placed at seeded random frames."""
    garbage: int = 0
    drop: int = 0
    bitflip: int = 0
    range: int = 0
    stall: int = 0
    disconnect: int = 0
    stall_s: float = 0.2
    outage_s: float = 0.3

    @classmethod
    def parse(cls, text: str) -> "FaultPlan":
        """``"garbage=3,drop=2,stall_s=0.1"`` -> FaultPlan."""
        plan = cls()
        for item in filter(None, (part.strip() for part in (text or "").split(","))):
            name, _, value = item.partition("=")
            name = name.strip()
            if name not in cls.__dataclass_fields__:
                raise SpecError("faults", item, "comma-separated NAME=VALUE with NAME in "
                                + ", ".join(cls.__dataclass_fields__))
            try:
                number = float(value) if name.endswith("_s") else int(value)
            except ValueError:
                raise SpecError(f"faults.{name}", value, "a number") from None
            setattr(plan, name, number)
        plan.validate()
        return plan

    def validate(self) -> None:
        for kind in FAULT_KINDS:
            value = getattr(self, kind)
            if not (isinstance(value, int) and value >= 0):
                raise SpecError(f"faults.{kind}", value, "a count >= 0")
        for name in ("stall_s", "outage_s"):
            value = getattr(self, name)
            if not (0 <= value <= 60):
                raise SpecError(f"faults.{name}", value, "seconds in [0, 60]")

    @property
    def total(self) -> int:
        return sum(getattr(self, kind) for kind in FAULT_KINDS)


@dataclass
class EmulatorLog:
    """What the emulator did: every valid frame written, and every fault with its frame index."""
    written: list[Sample] = field(default_factory=list)
    write_times_s: list[float] = field(default_factory=list)     # time.time() after each write
    faults: list[tuple[str, int, int]] = field(default_factory=list)   # (kind, frame, seq)
    framing_errors: int = 0
    frames_due: int = 0

    def injected(self) -> dict:
        return {kind: sum(1 for k, *_ in self.faults if k == kind) for kind in FAULT_KINDS}

    def expected_counts(self) -> dict:
        """The counts a correct receiver reports for this stream."""
        gaps = find_gaps([s.seq for s in self.written])
        injected = self.injected()
        return {"frames": len(self.written), "crc_errors": injected["bitflip"],
                "framing_errors": self.framing_errors, "range_errors": injected["range"],
                "gaps": len(gaps), "lost_samples": sum(g.length for g in gaps),
                "reconnects": injected["disconnect"]}


def garbage_burst(rng: np.random.Generator) -> tuple[bytes, int]:
    """Random bytes ended by a delimiter, and the number of framing errors they must cause."""
    while True:
        body = rng.integers(0, 256, int(rng.integers(1, 33)), dtype=np.uint8).tobytes()
        runs = [len(run) for run in body.split(DELIMITER)]
        if ENCODED_FRAME_LEN not in runs:
            return body + DELIMITER, sum(1 for n in runs if n)


def ascii_garbage(rng: np.random.Generator) -> tuple[bytes, int]:
    letters = rng.integers(ord("a"), ord("z") + 1, int(rng.integers(1, 20)), dtype=np.uint8)
    return letters.tobytes() + b"\n", 1


# -- the emulator -------------------------------------------------------------------------------
class Emulator:
    """Streams ``counts`` (shape (n, 2), ADC counts) as frames, looping over them if needed."""

    def __init__(self, counts, *, rate_hz: float = 1000.0, faults: FaultPlan | None = None,
                 seed: int = 0, wire_format: str = "binary", start_seq: int = 0,
                 fault_margin: int = 20):
        counts = np.asarray(counts)
        if counts.ndim != 2 or counts.shape[1] != 2 or counts.shape[0] == 0:
            raise SpecError("counts", f"array of shape {counts.shape}", "shape (n_samples, 2)")
        if counts.min() < 0 or counts.max() > ADC_MAX:
            raise SpecError("counts", f"range [{counts.min()}, {counts.max()}]",
                            f"ADC counts in 0..{ADC_MAX}")
        if not (0 < rate_hz <= 5000):
            raise SpecError("rate_hz", rate_hz, "a frame rate in (0, 5000] Hz")
        self.counts = counts.astype(int)
        self.rate_hz = rate_hz
        self.faults = faults or FaultPlan()
        self.faults.validate()
        if wire_format == "ascii" and self.faults.bitflip:
            raise SpecError("faults.bitflip", self.faults.bitflip,
                            "0 with --format ascii (ascii lines carry no CRC to catch a flip)")
        self.encode = encoder_for(wire_format)
        self.wire_format = wire_format
        self.seed, self.start_seq, self.fault_margin = seed, start_seq, fault_margin
        self.log = EmulatorLog()

    def schedule(self, n_frames: int) -> dict[int, str]:
        """Seeded, distinct frame indices for every planned fault."""
        slots = n_frames - 2 * self.fault_margin
        if self.faults.total == 0:
            return {}
        if self.faults.total > max(slots, 0):
            raise SpecError("faults", self.faults.total,
                            f"at most {max(slots, 0)} faults for {n_frames} frames "
                            f"(none in the first and last {self.fault_margin})")
        rng = np.random.default_rng(self.seed)
        where = rng.choice(slots, self.faults.total, replace=False) + self.fault_margin
        kinds = [k for k in FAULT_KINDS for _ in range(getattr(self.faults, k))]
        return {int(i): k for i, k in zip(where, kinds)}

    def run(self, link, n_frames: int | None = None, *, realtime: bool = True,
            stop: threading.Event | None = None,
            peer_timeout_s: float | None = 30.0) -> EmulatorLog:
        stop = stop or threading.Event()
        n_frames = len(self.counts) if n_frames is None else n_frames
        if n_frames <= 0:
            raise SpecError("frames", n_frames, "a number of frames > 0")
        plan = self.schedule(n_frames)
        if "disconnect" in plan.values() and not link.can_disconnect:
            raise SpecError("faults.disconnect", self.faults.disconnect,
                            "0 unless the emulator owns a pty with a stable --link path")
        rng = np.random.default_rng(self.seed + 1)
        log = self.log
        link.wait_for_peer(peer_timeout_s, stop)
        t0 = time.monotonic()
        pending, pending_samples = bytearray(), []

        def flush():
            if pending:
                link.write(bytes(pending), stop)
                now = time.time()
                log.written += pending_samples
                log.write_times_s += [now] * len(pending_samples)
                pending.clear()
                pending_samples.clear()

        i, resyncing = 0, False
        while i < n_frames and not stop.is_set():
            due = t0 + i / self.rate_hz
            if realtime and time.monotonic() < due:
                flush()
                time.sleep(max(0.0, min(due - time.monotonic(), 0.002)))
                continue
            seq = (self.start_seq + i) % SEQ_MODULUS
            x, y = (int(v) for v in self.counts[i % len(self.counts)])
            # After a reconnect the receiver treats bytes before its first valid frame as boot
            # noise; a fault there would go uncounted, so the first frame goes out clean.
            kind = None if resyncing else plan.get(i)
            resyncing = False
            log.frames_due = i + 1
            if kind:
                log.faults.append((kind, i, seq))
            if kind == "garbage":
                noise, errors = (garbage_burst if self.wire_format == "binary"
                                 else ascii_garbage)(rng)
                pending += noise
                log.framing_errors += errors
            if kind == "stall":
                flush()
                stop.wait(self.faults.stall_s)
            if kind == "disconnect":
                flush()
                link.drain()
                link.disconnect()
                stop.wait(self.faults.outage_s)
                link.reconnect()
                link.wait_for_peer(peer_timeout_s, stop)
                # The board kept sampling during the outage: the frames due meanwhile are gone.
                if realtime:
                    i = max(i + 1, math.ceil((time.monotonic() - t0) * self.rate_hz))
                else:
                    i += max(1, int(self.faults.outage_s * self.rate_hz))
                resyncing = True
                continue
            if kind == "drop":
                pass
            elif kind == "bitflip":
                raw = bytearray(frame_payload(seq, x, y))
                raw[int(rng.integers(len(raw)))] ^= 1 << int(rng.integers(8))
                pending += cobs_encode(bytes(raw)) + DELIMITER
            elif kind == "range":
                bad_x = int(rng.integers(ADC_MAX + 1, 65536))
                pending += (cobs_encode(frame_payload(seq, bad_x, y)) + DELIMITER
                            if self.wire_format == "binary" else f"{seq},{bad_x},{y}\n".encode())
            else:
                pending += self.encode(seq, x, y)
                pending_samples.append(Sample(seq, x, y))
            i += 1
            if len(pending) >= 4096:
                flush()
        flush()
        link.drain()
        return log


def default_scene_counts(duration_s: float = 8.0, seed: int = 0) -> np.ndarray:
    """A robot scene with two contacts (19 cm and 27 cm), as (n, 2) ADC counts."""
    from ..sources.stimuli import Contact, RobotScene

    scene = RobotScene(duration_s=duration_s, contacts=[Contact(2.0, 19.0), Contact(5.0, 27.0)])
    return scene.generate(seed).samples


def stimulus_counts(path: str | os.PathLike | None, seed: int = 0) -> np.ndarray:
    """ADC counts of the scene in a stimulus spec (``[stimulus]`` table), or the default scene."""
    if path is None:
        return default_scene_counts(seed=seed)
    import tomllib

    from ..sources.scenes import scene_from_spec

    path = Path(path)
    if not path.is_file():
        raise SpecError("stimulus", str(path), "an existing TOML file with a [stimulus] table")
    spec = tomllib.loads(path.read_text())
    table = spec.get("stimulus", spec)
    recording = scene_from_spec(table).generate(seed)
    if recording.units != "counts" or recording.samples.ndim != 2:
        raise SpecError("stimulus", str(path), "a scene that yields 2-axis ADC counts")
    return recording.samples
