"""The bridge's commands as a user runs them: subprocesses, real ptys, timeouts, SIGKILL."""
import fcntl
import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np

from snn_antenna.bridge import load_recording
from snn_antenna.bridge.emulate.emulator import Emulator
from snn_antenna.bridge.emulate.links import PeerGone, PtyLink

CLI = [sys.executable, "-m", "snn_antenna.cli"]


def run_cli(*args, timeout=30):
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


def test_missing_port_is_a_clear_error(tmp_path):
    t0 = time.monotonic()
    result = run_cli("record", "--port", "/dev/ttyDOESNOTEXIST", "--out", tmp_path / "rec")
    assert result.returncode == 2
    assert "port = '/dev/ttyDOESNOTEXIST'" in result.stderr
    assert "no such device" in result.stderr and "socket://" in result.stderr
    assert not (tmp_path / "rec").exists()
    assert time.monotonic() - t0 < 15


def test_unknown_url_scheme_is_a_clear_error(tmp_path):
    result = run_cli("record", "--port", "bogus://x", "--out", tmp_path / "rec")
    assert result.returncode == 2 and "port = 'bogus://x'" in result.stderr


def test_busy_port_is_a_clear_error(tmp_path):
    link = PtyLink()
    holder = os.open(link.slave_name, os.O_RDWR | os.O_NOCTTY)
    fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)   # what pyserial's exclusive open takes
    try:
        result = run_cli("record", "--port", link.path, "--out", tmp_path / "rec")
    finally:
        os.close(holder)
        link.close()
    assert result.returncode == 1
    assert "is busy" in result.stderr and link.path in result.stderr


def test_silent_port_fails_after_the_no_data_timeout(tmp_path):
    link = PtyLink()
    t0 = time.monotonic()
    try:
        result = run_cli("record", "--port", link.path, "--out", tmp_path / "rec",
                         "--no-data-timeout", "1")
    finally:
        link.close()
    assert result.returncode == 1
    assert "no valid frame" in result.stderr and "nothing was received" in result.stderr
    assert time.monotonic() - t0 < 15
    rec = load_recording(tmp_path / "rec")       # what there is, is still a valid recording
    assert rec.complete and rec.meta["status"] == "port-error" and rec.n_samples == 0


def test_wrong_baudrate_or_format_is_named_in_the_message(tmp_path):
    link = PtyLink()
    writer = threading.Thread(target=lambda: _write_noise(link), daemon=True)
    writer.start()
    try:
        result = run_cli("record", "--port", link.path, "--out", tmp_path / "rec",
                         "--no-data-timeout", "1", "--format", "ascii")
    finally:
        link.close()
    assert result.returncode == 1 and "--baudrate" in result.stderr


def _write_noise(link):
    try:
        link.wait_for_peer(10, threading.Event())
        for _ in range(200):
            link.write(bytes(range(1, 200)), threading.Event())
            time.sleep(0.01)
    except (PeerGone, OSError, TypeError):
        pass


def test_bad_fault_spec_names_the_field():
    result = run_cli("emulate", "--pty", "--faults", "garbage=2,meteor=1")
    assert result.returncode == 2
    assert "faults = 'meteor=1'" in result.stderr and "bitflip" in result.stderr


def test_emulate_and_record_processes_agree(tmp_path):
    """Two processes: `emulate --pty` with faults, `record` on the path it prints."""
    emu = subprocess.Popen([*CLI, "emulate", "--pty", "--link", tmp_path / "tty", "--frames",
                            "1500", "--faults", "garbage=2,drop=2,bitflip=2,range=1,stall=1",
                            "--seed", "4", "--log", tmp_path / "emu.json"],
                           stdout=subprocess.PIPE, text=True)
    try:
        path = emu.stdout.readline().strip()
        assert path == str(tmp_path / "tty")
        result = run_cli("record", "--port", path, "--out", tmp_path / "rec", "--duration", "3")
        assert emu.wait(10) == 0
    finally:
        emu.kill()
    assert result.returncode == 0, result.stderr
    expected = json.loads((tmp_path / "emu.json").read_text())["expected_counts"]
    rec = load_recording(tmp_path / "rec")
    assert {k: rec.counts[k] for k in expected} == expected
    replay = run_cli("replay", tmp_path / "rec")
    assert replay.returncode == 0 and json.loads(replay.stdout)["match"] is True


def test_sigkill_loses_at_most_the_last_100_ms(tmp_path):
    link = PtyLink(tmp_path / "tty")
    counts = np.random.default_rng(1).integers(0, 1024, (20000, 2))
    emulator = Emulator(counts)
    stop = threading.Event()
    failure = []

    def stream():
        try:
            emulator.run(link, stop=stop)
        except Exception as exc:        # PeerGone is how the kill ends it; kept for diagnostics
            failure.append(repr(exc))

    recorder = subprocess.Popen([*CLI, "record", "--port", link.path, "--out", tmp_path / "rec"],
                                stderr=subprocess.PIPE)
    streamer = threading.Thread(target=stream, daemon=True)
    streamer.start()
    # What the recorder has *received* at each moment: frames written minus bytes still unread
    # in the pty (under CPU load the reader may lag the writer; that lag is not a loss).
    received = []                                       # (time, frames received)
    try:
        deadline = time.monotonic() + 20
        while len(emulator.log.written) < 2000:         # two seconds of streaming
            if recorder.poll() is not None:
                raise AssertionError(f"the recorder exited early: {recorder.stderr.read()!r}; "
                                     f"emulator: {failure or 'running'}, "
                                     f"{len(emulator.log.written)} frames written")
            assert time.monotonic() < deadline, "two seconds of streaming took over 20 s"
            written = len(emulator.log.written)
            received.append((time.time(), written - -(-link.unread_bytes() // 10)))
            time.sleep(0.005)
        killed_at = time.time()
        recorder.send_signal(signal.SIGKILL)
        recorder.wait(5)
    finally:
        stop.set()
        streamer.join(5)
        recorder.kill()
        link.close()
    rec = load_recording(tmp_path / "rec")
    assert not rec.complete
    log = emulator.log
    sent = np.array([tuple(s) for s in log.written])
    got = np.column_stack([rec.seq, rec.x, rec.y])
    assert np.array_equal(got, sent[:len(got)]), "the recording is not a prefix of the stream"
    must_have = max(n for t, n in received if t <= killed_at - 0.1)
    assert must_have > 500
    assert len(got) >= must_have, (f"lost {must_have - len(got)} samples received more than "
                                   "100 ms before the kill")
    assert rec.raw_path.stat().st_size >= 10 * must_have
