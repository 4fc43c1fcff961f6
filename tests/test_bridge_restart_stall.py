"""What a real robot does to the link, on a real pseudo-terminal with the real ``record``: the
board restarts its count (reset faults, with and without boot frames, across the 16-bit wrap,
with duplicates and swaps), and the host stalls longer than the no-data timeout while the board
keeps sending. Every frame written is recorded and every counter equals the emulator's log."""
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from snn_antenna.bridge import load_recording
from snn_antenna.bridge.emulate.emulator import Emulator, FaultPlan
from snn_antenna.bridge.emulate.links import PtyLink
from snn_antenna.bridge.wire.recorder import COUNT_FIELDS

CLI = [sys.executable, "-m", "snn_antenna.cli"]


def start_record(port, out, *options):
    return subprocess.Popen([*CLI, "record", "--port", port, "--out", out, *map(str, options)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish_record(recorder, timeout_s=20):
    """Ctrl-C, as a user ends a recording; its exit status and stderr."""
    recorder.send_signal(signal.SIGINT)
    _, err = recorder.communicate(timeout=timeout_s)
    return recorder.returncode, err


def assert_recorded_exactly(rec, log):
    sent = np.array([tuple(s) for s in log.in_order]).reshape(-1, 3)
    assert np.array_equal(np.column_stack([rec.seq, rec.x, rec.y]), sent)
    assert {k: rec.counts[k] for k in COUNT_FIELDS} == log.expected_counts()
    assert rec.session_starts == log.session_starts
    assert rec.complete and len(rec.gaps) == rec.counts["gaps"]


@pytest.mark.parametrize("boot_frames, start_seq", [
    (True, 64_000), pytest.param(False, 64_000, marks=pytest.mark.slow), (False, 40_000)])
def test_board_resets_over_a_pty_are_restarts_never_loss_or_duplicates(tmp_path, boot_frames,
                                                                       start_seq):
    """Three resets of a board whose count starts at 64,000 (it wraps first) or 40,000 (its
    first reset is a jump forward, which only the host's clock tells from a gap), between
    duplicates, swaps and drops: three restarts, each session continuous, nothing lost but the
    drops, a duplicate only where one was sent; and a replay decides as the live run did."""
    n = 3000
    counts = np.random.default_rng(3).integers(0, 1024, (n, 2))
    plan = FaultPlan(reset=3, dup=6, swap=6, drop=3, reset_s=0.15)
    emulator = Emulator(counts, faults=plan, seed=21, start_seq=start_seq,
                        boot_frames=boot_frames)
    link = PtyLink(tmp_path / "tty")
    recorder = start_record(link.path, tmp_path / "rec")
    try:
        log = emulator.run(link, peer_timeout_s=30)
        link.drain()
        status, err = finish_record(recorder)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        link.close()
    assert status == 0, err
    assert log.injected()["reset"] == 3 and len(log.session_starts) == 4
    rec = load_recording(tmp_path / "rec")
    assert_recorded_exactly(rec, log)
    assert rec.counts["seq_restarts"] == 3
    assert rec.counts["duplicates"] == log.injected()["dup"]
    assert [session[0].seq for session in log.sessions()] == [start_seq, 0, 0, 0]
    assert rec.counts["lost_samples"] == log.injected()["drop"]
    # Per session, what the board sent: frames + lost = sent.
    assert rec.counts["frames"] + rec.counts["lost_samples"] == log.frames_due == n
    # The replay begins each session at the same byte, host-time rules included.
    causes = {s["cause"] for s in rec.meta["sessions"][1:]}
    if boot_frames:
        assert causes == {"boot"}
    else:                               # decided by arrival times, which raw.bin does not hold
        assert causes & {"silence", "jump"} and "boot" not in causes
    replay = subprocess.run([*CLI, "replay", tmp_path / "rec"], capture_output=True, text=True,
                            timeout=120)
    assert replay.returncode == 0 and '"match": true' in replay.stdout, replay.stdout


def test_a_host_stall_longer_than_the_no_data_timeout_loses_nothing(tmp_path):
    """``record --no-data-timeout 1`` is stopped (SIGSTOP) for 3 s while the board goes on
    writing: when it resumes, it reads what the port buffered (and what the board wrote while
    its writes waited) before any decision about silence, so it records every frame and ends
    only when asked."""
    n = 5000
    counts = np.random.default_rng(5).integers(0, 1024, (n, 2))
    emulator = Emulator(counts, seed=2)
    link = PtyLink(tmp_path / "tty")
    recorder = start_record(link.path, tmp_path / "rec", "--no-data-timeout", 1)
    box = {}

    def write():
        try:
            box["log"] = emulator.run(link, peer_timeout_s=30)
        except BaseException as exc:      # reported below, not lost with the thread
            box["error"] = exc

    writer = threading.Thread(target=write, daemon=True)
    try:
        writer.start()
        time.sleep(1.5)
        os.kill(recorder.pid, signal.SIGSTOP)
        time.sleep(3.0)
        os.kill(recorder.pid, signal.SIGCONT)
        writer.join(120)
        assert "log" in box, f"the emulator did not finish: {box.get('error', 'still writing')!r}"
        link.drain()
        assert recorder.poll() is None, recorder.communicate()[1]
        status, err = finish_record(recorder)
    finally:
        if recorder.poll() is None:
            os.kill(recorder.pid, signal.SIGCONT)
            recorder.kill()
        link.close()
    assert status == 0, err
    assert "stopped sending" not in err
    rec = load_recording(tmp_path / "rec")
    assert_recorded_exactly(rec, box["log"])
    assert rec.n_samples == n and rec.counts["gaps"] == 0


def test_a_silent_board_still_ends_the_recording_after_the_timeout(tmp_path):
    """The board's silence is what the timeout measures: a board that stops sending (the
    emulator ends, the pty stays open) ends ``record`` after the no-data timeout, with what it
    sent recorded."""
    emulator = Emulator(np.random.default_rng(1).integers(0, 1024, (300, 2)), seed=1)
    link = PtyLink(tmp_path / "tty")
    recorder = start_record(link.path, tmp_path / "rec", "--no-data-timeout", 1)
    try:
        log = emulator.run(link, peer_timeout_s=30)
        _, err = recorder.communicate(timeout=20)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        link.close()
    assert recorder.returncode != 0 and "stopped sending" in err
    rec = load_recording(tmp_path / "rec")
    assert rec.n_samples == len(log.in_order) == 300


def test_the_no_data_timeout_runs_on_the_readers_clock_not_the_hosts(tmp_path):
    """The reader thread is held for 2.5 s inside one read (as a host stall holds it) while the
    loop that decides about silence runs on, with a 1 s timeout: the board was sending all along
    and its bytes wait in the port, so no silence may be declared; when the read returns, the
    backlog is recorded and the stream goes on without a gap."""
    from snn_antenna.bridge.wire.recorder import Recorder
    from snn_antenna.bridge.wire.source import SerialSource, run_source

    emulator = Emulator(np.random.default_rng(9).integers(0, 1024, (4000, 2)), seed=9)
    link = PtyLink(tmp_path / "tty")
    source = SerialSource(link.path).start()
    real_read, calls = source.transport.read, []

    def held_read():
        calls.append(1)
        if len(calls) == 20:
            time.sleep(2.5)
        return real_read()

    source.transport.read = held_read
    recorder = Recorder(tmp_path / "rec", port=link.path, wire_format="binary",
                        baudrate=250000)
    writer = threading.Thread(target=emulator.run, args=(link,), kwargs={"peer_timeout_s": 30},
                              daemon=True)
    writer.start()
    try:
        run_source(source, [recorder], duration_s=5.0, no_data_timeout_s=1.0)
    finally:
        recorder.close()
        writer.join(30)
        link.close()
    rec = load_recording(tmp_path / "rec")
    assert len(calls) > 20 and rec.n_samples > 3000
    assert rec.counts["gaps"] == 0 and np.array_equal(rec.seq, np.arange(rec.n_samples))
