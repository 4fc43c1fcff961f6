"""The emulator's end of a link: a pseudo-terminal it creates, or any pyserial URL or port.

Both offer what :class:`~snn_antenna.bridge.emulate.emulator.Emulator` needs of a link: wait for a
reader (``wait_for_peer``), write while the reader is there (``write``), wait until the reader
has taken every byte written (``drain``), and, for a pty behind a stable symlink only,
``disconnect``/``reconnect`` as a USB adapter does when it is pulled and plugged back in.
"""
from __future__ import annotations

import array
import errno
import fcntl
import os
import select
import termios
import threading
import time
import tty
from pathlib import Path

from ...core.errors import SpecError
from ..wire.source import DEFAULT_BAUDRATE


class PeerGone(RuntimeError):
    """The reader closed the port (or never opened it in time)."""


class PtyLink:
    """The emulator's end of a pseudo-terminal; the reader opens :attr:`path`.

    With ``link`` the path is a symlink that is removed on disconnect and recreated, pointing at
    a fresh pty, on reconnect: the same path disappears and returns, as a USB adapter's
    ``/dev/serial/by-id`` name does. The link is created exclusively (a path that exists is
    refused, whatever it points at) and removed only while it is still the one this link made
    (same inode, same target): a link the user put there meanwhile is theirs.
    """

    def __init__(self, link: str | os.PathLike | None = None):
        self.link = Path(link) if link is not None else None
        self.master: int | None = None
        self.slave_name = ""
        self._made: tuple[int, int, str] | None = None  # (dev, ino, target) of our link
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
            try:
                os.symlink(self.slave_name, self.link)   # fails on any entry already there
            except FileExistsError:
                os.close(self.master)
                self.master = None
                check_link_path(self.link)
                raise
            st = os.lstat(self.link)
            self._made = (st.st_dev, st.st_ino, self.slave_name)

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
        if self.link is not None and self._is_ours():          # never a path the user took
            self.link.unlink()
            self._made = None
        if self.master is not None:
            os.close(self.master)
            self.master = None

    def _is_ours(self) -> bool:
        """Whether :attr:`link` is still the link this object made (by identity)."""
        try:
            st = os.lstat(self.link)
            return self._made == (st.st_dev, st.st_ino, os.readlink(self.link))
        except OSError:
            return False

    def reconnect(self) -> None:
        self._open()

    def close(self) -> None:
        self.disconnect()

    @property
    def can_disconnect(self) -> bool:
        return self.link is not None


def check_link_path(link: Path) -> None:
    """Refuse a --link path that holds anything at all: the emulator creates the link there and
    removes it on exit, so it must never be a file, folder or link of the user's (a link left
    by an emulator that was killed is not provably its own either: remove it)."""
    link = Path(link)
    if os.path.lexists(link):
        what = (f"a symlink to {os.readlink(link)}" if link.is_symlink()
                else "an existing folder" if link.is_dir() else "an existing file")
        raise SpecError("link", str(link), f"a new path, where the emulator makes its own "
                                           f"link to a pty; this is {what}, left as it is "
                                           "(remove it, or choose another --link)")
    if not link.parent.is_dir() or not os.access(link.parent, os.W_OK | os.X_OK):
        raise SpecError("link", str(link), f"a path in a folder you can write to "
                                           f"({link.parent} is not one)")


class SerialLink:
    """Any pyserial URL or open port (``loop://``, ``socket://``, a real device)."""

    can_disconnect = False

    def __init__(self, port_or_url):
        import serial

        if isinstance(port_or_url, str):
            self.port = serial.serial_for_url(port_or_url, baudrate=DEFAULT_BAUDRATE,
                                              write_timeout=1.0)
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
