"""A misbehaving link between a real board and the host, over real pseudo-terminals: a relay
that repeats every 50th frame and swaps pairs of frames (CRCs valid). The stream reports the
same contact as over a clean link, counts every duplicate and reorder, and its counters
reconcile with what the emulator logged."""
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import serial

from snn_antenna.bridge import load_recording
from snn_antenna.bridge.emulate.emulator import Emulator
from snn_antenna.bridge.emulate.links import PeerGone, PtyLink
from snn_antenna.sources.stimuli import Contact, RobotScene

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "snn_antenna.cli"]
NETWORK = ROOT / "networks" / "resonator_array.toml"


class Relay:
    """Reads frames from one pty and writes them to another: every 50th frame twice, and every
    37th pair of frames in swapped order."""

    def __init__(self, upstream: str, downstream: PtyLink):
        self.up = serial.Serial(upstream, timeout=0.05)
        self.down = downstream
        self.duplicated = self.swapped = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        self.down.wait_for_peer(60, self.stop)
        pending, held, n = b"", None, 0
        while not self.stop.is_set():
            data = self.up.read(self.up.in_waiting or 1)
            if not data:
                continue
            *frames, pending = (pending + data).split(b"\x00")
            out = bytearray()
            for frame in frames:
                frame += b"\x00"
                n += 1
                if held is not None:            # the second of a pair goes first
                    out += frame + held
                    held = None
                    self.swapped += 1
                elif n % 37 == 0:
                    held = frame
                else:
                    out += frame * (2 if n % 50 == 0 else 1)
                    self.duplicated += n % 50 == 0
            try:
                self.down.write(bytes(out), self.stop)
            except PeerGone:
                return


def stream(tmp_path, counts, name, relay: bool):
    board = PtyLink(tmp_path / f"board-{name}")
    emulator = Emulator(counts)
    host_link, relay_obj = board, None
    if relay:
        host_link = PtyLink(tmp_path / f"host-{name}")
    result = {}

    def serve():
        try:
            result["log"] = emulator.run(board, peer_timeout_s=120)
        except PeerGone:
            pass
        if relay_obj:                   # the relay forwards what is left, then lets go
            time.sleep(0.5)
            relay_obj.stop.set()
            relay_obj.thread.join(5)
        host_link.disconnect()          # the board is unplugged once the scene is over

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    if relay:
        relay_obj = Relay(board.path, host_link)
        relay_obj.thread.start()
    cmd = [*CLI, "stream", "--port", host_link.path, "--network", NETWORK, "--out",
           tmp_path / name, "--duration", "7", "--set", "preprocess.threshold=0.05"]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=150)
        assert out.returncode == 0, out.stderr
    finally:
        server.join(20)
        if relay_obj:
            relay_obj.stop.set()
            relay_obj.thread.join(5)
            relay_obj.up.close()
            host_link.close()
        board.close()
    report = json.loads(out.stdout[out.stdout.index("{\n"):])
    return load_recording(tmp_path / name), report, result["log"], relay_obj


@pytest.mark.slow
def test_a_relay_that_duplicates_and_swaps_gives_the_clean_contacts(tmp_path):
    counts = RobotScene(duration_s=6.0, contacts=[Contact(2.0, 19.0)]).generate(seed=3).samples
    counts = counts[:4000]
    clean, clean_report, _, _ = stream(tmp_path, counts, "clean", relay=False)
    bad, bad_report, log, relay = stream(tmp_path, counts, "relay", relay=True)
    assert relay.duplicated >= 70 and relay.swapped >= 90
    assert bad.counts["duplicates"] == relay.duplicated
    assert bad.counts["reordered"] == relay.swapped
    # Everything the board sent is accounted for, once.
    assert bad.counts["frames"] == len(log.written) == clean.counts["frames"] == 4000
    assert bad.counts["lost_samples"] == bad.counts["gaps"] == bad.counts["late"] == 0
    assert list(bad.seq) == list(clean.seq)
    a, b = clean_report["contacts"], bad_report["contacts"]
    assert len(a) == len(b) == 1
    assert abs(a[0]["distance_cm"] - b[0]["distance_cm"]) <= 0.5
