"""The bridge over real links: pseudo-terminals, socat and loop://, with injected faults."""
import fcntl
import os
import select
import shutil
import socket
import subprocess
import threading
import time

import numpy as np
import pytest
import serial

from snn_antenna.bridge import load_recording
from snn_antenna.bridge.emulate.emulator import Emulator, FaultPlan
from snn_antenna.bridge.emulate.links import PtyLink, SerialLink
from snn_antenna.bridge.wire.handler import BatchHandler
from snn_antenna.bridge.wire.protocol import encode_binary
from snn_antenna.bridge.wire.recorder import COUNT_FIELDS, Recorder
from snn_antenna.bridge.wire.replay import ReplaySource
from snn_antenna.bridge.wire.source import PortError, SerialSource, run_source

COUNT_KEYS = COUNT_FIELDS


def random_counts(n, seed=0):
    return np.random.default_rng(seed).integers(0, 1024, (n, 2))


class Session:
    """A SerialSource feeding a Recorder on a background thread, stopped on demand."""

    def __init__(self, url, out_dir, port=None, **source_kwargs):
        self.source = SerialSource(url, port=port, **source_kwargs).start()
        self.recorder = Recorder(out_dir, port=url, wire_format=self.source.decoder.wire_format,
                                 baudrate=250000)
        self.stop = threading.Event()
        self.error = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        try:
            run_source(self.source, [self.recorder], stop=self.stop, no_data_timeout_s=20)
        except Exception as exc:        # surfaced by finish()
            self.error = exc

    def finish(self, settle_s=0.3):
        time.sleep(settle_s)
        self.stop.set()
        self.thread.join(10)
        self.source.stop()
        self.recorder.close()
        if self.error:
            raise self.error
        return load_recording(self.recorder.dir)


def assert_recording_matches(rec, log):
    sent = np.array([tuple(s) for s in log.in_order]).reshape(-1, 3)
    got = np.column_stack([rec.seq, rec.x, rec.y])
    assert got.shape == sent.shape
    assert np.array_equal(got, sent), "recorded samples differ from the valid frames sent"
    counts = {k: rec.counts[k] for k in COUNT_KEYS}
    assert counts == log.expected_counts()
    assert rec.complete and rec.torn_bytes == 0
    assert len(rec.gaps) == rec.counts["gaps"]


def test_the_links_own_queue_probe_is_not_taken_for_a_reader(monkeypatch):
    """unread_bytes() opens the slave for a moment. A peer check from the streaming thread in
    that moment must still see no reader; it used to see one, so the emulator started, met
    POLLHUP when the probe closed and gave up before the real reader had opened the port."""
    link = PtyLink()
    real_ioctl = fcntl.ioctl
    hup_during_probe, seen, checkers = [], [], []

    def ioctl_with_a_peer_check(fd, *args):
        # Called while the probe holds the slave open, which clears POLLHUP on the master...
        poller = select.poll()
        poller.register(link.master, select.POLLOUT)
        hup_during_probe.append(any(ev & select.POLLHUP for _, ev in poller.poll(0)))
        # ...and the emulator's thread asks whether a reader is there.
        checker = threading.Thread(target=lambda: seen.append(link.peer_open()))
        checker.start()
        checkers.append(checker)
        checker.join(0.2)
        return real_ioctl(fd, *args)

    try:
        assert not link.peer_open()
        monkeypatch.setattr(fcntl, "ioctl", ioctl_with_a_peer_check)
        assert link.unread_bytes() == 0
        monkeypatch.undo()
        checkers[0].join(5)
        assert hup_during_probe == [False], "the probe did not open the slave: nothing tested"
        assert seen == [False], "the link took its own probe for a reader"
        reader = os.open(link.slave_name, os.O_RDWR | os.O_NOCTTY)
        try:
            assert link.peer_open()             # a real reader is still seen...
        finally:
            os.close(reader)
        assert not link.peer_open()             # ...and so is its leaving
    finally:
        link.close()


def test_pty_stream_with_every_fault_is_recorded_exactly(tmp_path):
    plan = FaultPlan(garbage=4, drop=4, bitflip=4, range=3, stall=2, disconnect=1,
                     stall_s=0.15, outage_s=0.25)
    link = PtyLink(tmp_path / "ttyEMU")
    emulator = Emulator(random_counts(2500), faults=plan, seed=11)
    session = Session(link.path, tmp_path / "rec")
    log = emulator.run(link)
    rec = session.finish()
    link.close()
    injected = log.injected()
    # Everything planned happened (faults planned inside an outage are legitimately skipped).
    assert injected["disconnect"] == 1 and injected["bitflip"] >= 3 and injected["garbage"] >= 3
    assert_recording_matches(rec, log)
    assert rec.counts["reconnects"] == 1 and rec.counts["gaps"] >= 1
    events = [e["event"] for e in rec.meta["link_events"]]
    assert events == ["opened", "lost", "reconnected"]
    # raw.bin holds every byte the port delivered.
    assert rec.raw_path.stat().st_size == rec.counts["bytes"]


def test_duplicated_and_swapped_frames_over_a_pty_are_put_right_and_reconcile(tmp_path):
    """A link that repeats and swaps frames (valid CRCs) across the 16-bit wrap: the recording
    is the board's stream in order, and every frame the emulator wrote is accounted for."""
    plan = FaultPlan(dup=30, swap=30, drop=3, garbage=2)
    link = PtyLink(tmp_path / "ttyEMU")
    emulator = Emulator(random_counts(1500, 4), faults=plan, seed=3, start_seq=65000)
    session = Session(link.path, tmp_path / "rec")
    log = emulator.run(link)
    rec = session.finish()
    link.close()
    assert log.injected()["dup"] >= 25 and log.injected()["swap"] >= 25
    assert_recording_matches(rec, log)
    counts = rec.counts
    assert counts["duplicates"] == log.injected()["dup"]
    assert counts["reordered"] == log.injected()["swap"]
    # Everything written: delivered, or dropped as a counted duplicate.
    assert counts["frames"] + counts["duplicates"] + counts["late"] == len(log.written)
    # Every frame the board produced: delivered, or lost (dropped on the way) and counted once.
    assert counts["frames"] + counts["lost_samples"] == log.frames_due == 1500
    assert counts["lost_samples"] == log.injected()["drop"] == 3


def test_replay_reproduces_samples_and_counts(tmp_path):
    link = PtyLink(tmp_path / "tty")
    emulator = Emulator(random_counts(1500, 2), seed=5,
                        faults=FaultPlan(garbage=3, drop=2, bitflip=2, disconnect=1,
                                         outage_s=0.1))
    session = Session(link.path, tmp_path / "rec")
    emulator.run(link)
    rec = session.finish()
    link.close()
    replay = ReplaySource(tmp_path / "rec").start()
    samples = []

    class Collect(BatchHandler):
        def handle(self, batch):
            samples.extend(batch.samples)

    result = run_source(replay, [Collect()], no_data_timeout_s=60)
    assert np.array_equal(np.array(samples), np.column_stack([rec.seq, rec.x, rec.y]))
    assert {k: result.counts[k] for k in COUNT_KEYS} == {k: rec.counts[k] for k in COUNT_KEYS}


def test_loop_url_ascii_with_faults(tmp_path):
    port = serial.serial_for_url("loop://", timeout=0.05)
    plan = FaultPlan(garbage=3, drop=3, range=2, stall=1, stall_s=0.1)
    emulator = Emulator(random_counts(800, 3), faults=plan, seed=2, wire_format="ascii")
    session = Session("loop://", tmp_path / "rec", port=port, wire_format="ascii")
    log = emulator.run(SerialLink(port), realtime=False)
    rec = session.finish()
    assert log.injected()["garbage"] == 3
    assert_recording_matches(rec, log)


def test_boot_noise_after_open_is_discarded_not_counted(tmp_path):
    """A board reset by DTR prints bootloader noise, then frames: no errors, nothing lost."""
    port = serial.serial_for_url("loop://", timeout=0.05)
    session = Session("loop://", tmp_path / "rec", port=port)
    port.write(b"\x1b[0m boot v1.2\r\n\xff\xfe" + encode_binary(5, 1, 2)[3:])
    port.write(b"".join(encode_binary(s, s, s) for s in range(10, 30)))
    rec = session.finish()
    assert rec.seq.tolist() == list(range(10, 30))
    assert rec.counts["framing_errors"] == rec.counts["crc_errors"] == 0
    assert rec.meta["counts"]["noise_bytes"] > 0


@pytest.mark.skipif(shutil.which("socat") is None, reason="socat is not installed "
                    "(Debian package socat; .ci/run installs it)")
def test_socat_port_vanishes_and_returns_at_the_same_path(tmp_path):
    """A socat pty pair; socat is killed (its links vanish) and restarted at the same paths."""
    dev, board = tmp_path / "ttyUSB0", tmp_path / "board"

    def start_socat():
        proc = subprocess.Popen(["socat", f"PTY,raw,echo=0,link={dev}",
                                 f"PTY,raw,echo=0,link={board}"], stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 5
        while not (dev.exists() and board.exists()):
            assert time.monotonic() < deadline, "socat did not create its ptys"
            time.sleep(0.01)
        return proc

    socat = start_socat()
    session = Session(str(dev), tmp_path / "rec", backoff_initial_s=0.02)
    seq = 0

    def send(n):
        nonlocal seq
        with serial.serial_for_url(str(board)) as out:
            for _ in range(n):
                out.write(encode_binary(seq, seq % 1024, 3))
                seq += 1
                time.sleep(0.001)
        time.sleep(0.2)                 # let socat and the reader pass the last bytes on

    try:
        send(300)
        before = seq
        socat.terminate()
        socat.wait(5)
        time.sleep(0.2)
        assert not dev.exists()         # the path really vanished
        seq += 50                       # the board kept sampling while the port was gone
        socat = start_socat()
        time.sleep(0.5)                 # the reader's backoff finds the port again
        send(300)
    finally:
        socat.terminate()
        socat.wait(5)
    rec = session.finish(settle_s=0)
    assert rec.counts["reconnects"] == 1
    assert rec.seq[:before].tolist() == list(range(before))
    assert rec.seq[before:].tolist() == list(range(before + 50, seq))
    assert rec.counts["gaps"] == 1 and rec.counts["lost_samples"] == 50


def test_port_gone_for_good_fails_with_a_message(tmp_path):
    link = PtyLink(tmp_path / "tty")
    source = SerialSource(link.path, reconnect_timeout_s=0.3).start()
    link.write(b"".join(encode_binary(s, 1, 1) for s in range(5)), threading.Event())
    time.sleep(0.1)
    link.disconnect()
    t0 = time.monotonic()
    with pytest.raises(PortError, match="disappeared and did not come back within 0.3 s"):
        run_source(source, [], no_data_timeout_s=10)
    assert time.monotonic() - t0 < 3
    source.stop()


def test_socket_url_reconnects_when_the_server_comes_back(tmp_path):
    """``socket://``: the TCP peer (a serial-to-network bridge) drops the connection, the
    source reconnects to the same URL and the recording continues with the outage as a gap."""
    server = socket.create_server(("127.0.0.1", 0))
    url = f"socket://127.0.0.1:{server.getsockname()[1]}"

    def serve():
        seq = 0
        for _ in range(2):
            conn, _ = server.accept()
            time.sleep(0.1)             # pyserial flushes input right after connecting
            for _ in range(200):
                conn.sendall(encode_binary(seq, seq % 1024, 7))
                seq += 1
                time.sleep(0.001)
            time.sleep(0.2)
            conn.close()
            seq += 25                   # samples the board took while nobody was connected

    threading.Thread(target=serve, daemon=True).start()
    session = Session(url, tmp_path / "rec", reconnect_timeout_s=5)
    deadline = time.monotonic() + 10
    while session.recorder.n_samples < 400 and time.monotonic() < deadline:
        time.sleep(0.05)
    rec = session.finish(settle_s=0)
    server.close()
    assert rec.seq.tolist() == list(range(200)) + list(range(225, 425))
    assert rec.counts["reconnects"] >= 1 and rec.counts["crc_errors"] == 0
    assert (rec.counts["gaps"], rec.counts["lost_samples"]) == (1, 25)


def test_torn_last_record_is_dropped_and_recordings_are_never_overwritten(tmp_path):
    from snn_antenna.bridge.wire.source import Batch
    from snn_antenna.core.errors import SpecError

    recorder = Recorder(tmp_path / "rec", port="loop://", wire_format="binary", baudrate=250000)
    samples = [(s, s, 1023 - s) for s in range(50)]
    recorder.handle(Batch(123.5, b"\x01" * 500, samples, {"frames": 50}))
    recorder.close()
    with open(tmp_path / "rec" / "samples.bin", "ab") as f:
        f.write(b"\x33" * 7)                # a record cut short by a crash
    rec = load_recording(tmp_path / "rec")
    assert rec.torn_bytes == 7 and rec.n_samples == 50
    assert rec.seq.tolist() == list(range(50)) and rec.y.tolist() == [1023 - s for s in range(50)]
    assert np.all(rec.host_time_s == 123.5)
    assert rec.to_recording().samples.shape == (50, 2)
    with pytest.raises(SpecError, match="out = .*never overwritten"):
        Recorder(tmp_path / "rec", port="loop://", wire_format="binary", baudrate=250000)
    with pytest.raises(SpecError, match="recording = .*snn-antenna record"):
        load_recording(tmp_path)
