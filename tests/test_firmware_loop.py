"""The board's firmware (firmware/antenna_stream/main.c, unmodified) in simavr, in the loop:
`snn-antenna emulate --pty --firmware` streams a shipped stimulus through it over a real pty,
and the host's recorder, decoder and live pipeline read it as they read the board."""
import json
import os
import select
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.bridge import load_recording
from snn_antenna.bridge.emulate.firmware_loop import (
    build,
    missing_tools,
    run_harness,
    write_counts,
)
from snn_antenna.bridge.emulate.links import PtyLink
from snn_antenna.bridge.wire.protocol import Decoder
from snn_antenna.bridge.wire.recorder import Recorder
from snn_antenna.bridge.wire.source import SerialSource, run_source
from snn_antenna.bridge.emulate.stimulus import stimulus_recording
from snn_antenna.core.errors import PipelineError

ROOT = Path(__file__).resolve().parents[1]
FIRMWARE = ROOT / "firmware" / "antenna_stream"
QUICKSTART = ROOT / "stimuli" / "quickstart_scene.toml"
CLI = [sys.executable, "-m", "snn_antenna.cli"]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}

needs_simavr = pytest.mark.skipif(
    bool(missing_tools()), reason=f"missing {', '.join(missing_tools())} (Debian: apt-get install "
                                  "gcc-avr avr-libc simavr libsimavr-dev; .ci/run installs them)")


class Recording:
    """What `record` does (SerialSource into a Recorder), in a thread, until stopped."""

    def __init__(self, port, out_dir):
        self.source = SerialSource(port).start()
        self.recorder = Recorder(out_dir, port=port, wire_format="binary", baudrate=250000)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=run_source, daemon=True, args=(
            self.source, [self.recorder]), kwargs={"stop": self.stop, "no_data_timeout_s": 60})
        self.thread.start()

    def finish(self):
        self.stop.set()
        self.thread.join(10)
        self.source.stop()
        self.recorder.close()
        return load_recording(self.recorder.dir)


def start_emulate(tmp_path, *options):
    """`emulate --pty --firmware` as a user runs it: the pty path is its first line."""
    emu = subprocess.Popen([*CLI, "emulate", "--pty", "--link", tmp_path / "tty", "--firmware",
                            FIRMWARE, "--stimulus", QUICKSTART, "--log", tmp_path / "emu.json",
                            *map(str, options)],
                           cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, env=ENV)
    path = emu.stdout.readline().strip()
    assert path == str(tmp_path / "tty"), emu.stderr.read()
    return emu


def assert_bit_exact(rec, expected: np.ndarray):
    assert np.array_equal(rec.seq, np.arange(len(expected))), "seq not continuous from 0"
    assert np.array_equal(np.column_stack([rec.x, rec.y]), expected), "counts differ"
    assert rec.counts["gaps"] == rec.counts["lost_samples"] == 0
    assert rec.counts["crc_errors"] == rec.counts["framing_errors"] == 0


@needs_simavr
def test_quickstart_through_the_firmware_is_recorded_count_for_count(tmp_path):
    frames = 3000                       # 3 s of the scene: the default suite stays quick
    emu = start_emulate(tmp_path, "--frames", frames, "--fast")
    try:
        recording = Recording(str(tmp_path / "tty"), tmp_path / "rec")
        out, err = emu.communicate(timeout=120)
    finally:
        emu.kill()
    rec = recording.finish()
    assert emu.returncode == 0, err
    expected = stimulus_recording(QUICKSTART, seed=0).samples[:frames]
    assert expected.std(axis=0).min() > 0           # the robot moves: a real signal to match
    assert_bit_exact(rec, expected)
    summary = json.loads(out)
    assert summary["frames_fed"] == frames
    harness = summary["simavr"]
    assert harness["bytes_sent"] == 1 + 12 + 10 * frames    # 0x00, the boot frame, 10 a frame
    assert abs(harness["simulated_s"] - frames / 1000) < 0.02       # the firmware's 1 kHz
    assert 0.39 < harness["line_load"] < 0.41                       # 40 % of 250000 baud
    assert "× real time" in err and "UART line load" in err
    assert json.loads((tmp_path / "emu.json").read_text())["frames_fed"] == frames


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    return build(FIRMWARE, tmp_path_factory.mktemp("firmware-sim"))


@needs_simavr
def test_a_held_uart_drops_samples_as_a_counted_gap_never_a_time_warp(tmp_path, built):
    """The harness holds the UART 100 ms (a stalled line): the firmware's queue (32 entries,
    31 usable) fills and the ADC interrupt drops what finds it full, keeping their sequence
    numbers. The host must see one gap of exactly the dropped samples, and every sample after
    it carrying the counts of its own instant."""
    n, hold_at_ms, hold_ms = 1500, 500, 100
    counts = np.random.default_rng(7).integers(0, 1024, (n, 2))
    write_counts(tmp_path / "counts.txt", counts)
    link = PtyLink(tmp_path / "tty")
    try:
        recording = Recording(link.path, tmp_path / "rec")
        link.wait_for_peer(30, threading.Event())
        summary = run_harness(built, tmp_path / "counts.txt", link, fast=True,
                              holds=((hold_at_ms, hold_ms),))
        link.drain()
    finally:
        link.close()
    rec = recording.finish()
    assert summary["samples_fed"] == n and summary["held_s"] == pytest.approx(0.1)
    lost = rec.counts["lost_samples"]
    assert rec.counts["gaps"] == 1 and len(rec.gaps) == 1
    # 100 samples fall in the hold; the queue keeps 31 and the frame being sent one more.
    assert 60 <= lost <= 70, lost
    assert rec.counts["frames"] + lost == n
    assert rec.counts["crc_errors"] == rec.counts["framing_errors"] == 0
    seq = rec.seq.astype(np.int64)
    jump = np.flatnonzero(np.diff(seq) != 1)
    assert len(jump) == 1 and seq[jump[0] + 1] - seq[jump[0]] - 1 == lost
    assert hold_at_ms <= seq[jump[0]] + 1 < hold_at_ms + hold_ms   # dropped during the hold
    assert np.array_equal(np.column_stack([rec.x, rec.y]), counts[seq]), \
        "a sample carries another instant's counts: a time warp"


@needs_simavr
def test_a_reset_board_is_one_restart_never_a_gap_or_duplicates(tmp_path, built):
    """The MCU is reset (its RESET pin) at 700 ms of a 1500-sample stream, after its count passed
    the 1,024 a duplicate check remembers and before it wrapped: the firmware boots again, sends
    its boot frame and counts from 0. `record` must see two sessions, each continuous, one
    restart, no gap, no duplicate; only the frame on the line at the reset is cut (one framing
    error), and the new session's samples carry the counts of their own instants."""
    n, reset_at_ms = 1500, 700
    counts = np.random.default_rng(11).integers(0, 1024, (n, 2))
    write_counts(tmp_path / "counts.txt", counts)
    link = PtyLink(tmp_path / "tty")
    try:
        recording = Recording(link.path, tmp_path / "rec")
        link.wait_for_peer(30, threading.Event())
        summary = run_harness(built, tmp_path / "counts.txt", link, fast=True,
                              resets=(reset_at_ms,))
        link.drain()
    finally:
        link.close()
    rec = recording.finish()
    assert summary["samples_fed"] == n
    counted = rec.counts
    assert (counted["seq_restarts"], counted["boot_frames"]) == (1, 2)
    assert counted["gaps"] == counted["lost_samples"] == counted["duplicates"] == 0
    assert counted["crc_errors"] == 0 and counted["framing_errors"] <= 1
    assert rec.session_starts[:1] == [0] and len(rec.session_starts) == 2
    k = rec.session_starts[1]
    seq = rec.seq.astype(np.int64)
    assert np.array_equal(seq[:k], np.arange(k))
    assert np.array_equal(seq[k:], np.arange(len(seq) - k))
    assert abs(k - reset_at_ms) <= 2
    got = np.column_stack([rec.x, rec.y])
    assert np.array_equal(got[:k], counts[:k])
    first = n - (len(seq) - k)          # the stimulus went on: the new count's first instant
    assert np.array_equal(got[k:], counts[first:]), "the new session's counts are not its own"
    assert counted["frames"] + (first - k) == n and first - k <= 2


@needs_simavr
def test_counts_the_adc_cannot_give_are_refused_by_the_harness(tmp_path, built):
    (tmp_path / "counts.txt").write_text("1 2\n3 1024\n")
    link = PtyLink()
    try:
        with pytest.raises(PipelineError, match=r"counts line 2: 3 1024; accepted: 0\.\.1023"):
            run_harness(built, tmp_path / "counts.txt", link)
    finally:
        link.close()


def test_firmware_option_refuses_what_the_firmware_cannot_do(tmp_path):
    for options, field in ((["--faults", "drop=2"], "faults"), (["--format", "ascii"], "format"),
                           ([], "firmware")):
        firmware = tmp_path / "nowhere" if field == "firmware" else FIRMWARE
        result = subprocess.run([*CLI, "emulate", "--pty", "--firmware", firmware, *options],
                                capture_output=True, text=True, timeout=60, env=ENV)
        assert result.returncode == 2, result.stderr
        assert result.stderr.startswith(f"snn-antenna: error: {field} = ")
        assert "/dev/" not in result.stdout


@needs_simavr
@pytest.mark.slow
def test_stream_finds_the_quickstart_contact_through_the_firmware(tmp_path):
    """The whole quickstart scene at the board's pace, `stream` on the firmware's pty: the
    recording is the stimulus count for count, and the contact is found at 19 cm."""
    emu = start_emulate(tmp_path)
    try:
        result = subprocess.run(
            [*CLI, "stream", "--port", tmp_path / "tty", "--network", ROOT / "networks" /
             "live.toml", "--set", "preprocess.threshold=0.05", "--out", tmp_path / "rec",
             "--duration", "19", "--json"], capture_output=True, text=True, timeout=300,
            env=ENV)
        emu.wait(30)
    finally:
        emu.kill()
    assert result.returncode == 0, result.stderr
    assert emu.returncode == 0, emu.stderr.read()
    expected = stimulus_recording(QUICKSTART, seed=0)
    assert_bit_exact(load_recording(tmp_path / "rec"), expected.samples)
    report = json.loads(result.stdout[result.stdout.index("{\n"):])
    [contact] = report["contacts"]
    [truth] = expected.truth.events
    assert abs(contact["onset_s"] - truth.t_s) < 0.5
    assert abs(contact["distance_cm"] - 19.0) <= 1.5, contact


@needs_simavr
@pytest.mark.slow
def test_a_reader_that_stops_reading_holds_the_paced_uart(tmp_path, built):
    """At the board's pace, a reader that opens the port and reads nothing for 5 s: once the
    pty's buffer is full the harness holds the UART (a line that cannot send) instead of
    buffering without end, and the firmware drops as it would, one counted gap, no warp."""
    n = 7000
    counts = np.random.default_rng(3).integers(0, 1024, (n, 2))
    write_counts(tmp_path / "counts.txt", counts)
    link = PtyLink()
    reader = os.open(link.slave_name, os.O_RDWR | os.O_NOCTTY)
    summary = {}
    try:
        tty.setraw(reader)
        harness = threading.Thread(target=lambda: summary.update(
            run_harness(built, tmp_path / "counts.txt", link)))
        harness.start()
        time.sleep(5)
        data = bytearray()
        os.set_blocking(reader, False)
        while harness.is_alive() or select.select([reader], [], [], 0.2)[0]:
            try:
                data += os.read(reader, 1 << 16)
            except BlockingIOError:
                time.sleep(0.01)
        harness.join()
    finally:
        os.close(reader)
        link.close()
    decoder = Decoder("binary")
    got = np.array([tuple(s) for s in decoder.feed(bytes(data))])
    assert summary["held_s"] > 1 and decoder.stats.gaps >= 1
    assert decoder.stats.frames + decoder.stats.lost_samples == n
    assert decoder.stats.crc_errors == decoder.stats.framing_errors == 0
    assert np.array_equal(got[:, 1:], counts[got[:, 0]]), "a time warp"
