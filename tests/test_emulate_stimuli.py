"""`snn-antenna emulate --stimulus` for every file in stimuli/: frames arrive on a real pty and
decode to the stimulus's counts, and the log labels its contacts. The list is the directory's,
so a new stimulus is covered the day it is added."""
import errno
import json
import os
import select
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.bridge.wire.protocol import Decoder
from snn_antenna.bridge.emulate.stimulus import played_events, stimulus_recording

ROOT = Path(__file__).resolve().parents[1]
STIMULI = sorted((ROOT / "stimuli").glob("*.toml"))
FRAMES = 3000


def read_until_closed(path: str, emulator: subprocess.Popen, timeout_s: float = 180) -> bytes:
    """Everything the emulator writes to the pty, read as the host would, until it closes it."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    data = bytearray()
    try:
        while True:
            ready, _, _ = select.select([fd], [], [], timeout_s)
            assert ready, f"nothing from the emulator for {timeout_s} s"
            try:
                chunk = os.read(fd, 1 << 16)
            except BlockingIOError:
                continue
            except OSError as exc:      # the emulator closed its end: all was sent
                assert exc.errno == errno.EIO
                return bytes(data)
            if not chunk and emulator.poll() is not None:
                return bytes(data)
            data += chunk
    finally:
        os.close(fd)


def test_every_shipped_stimulus_is_listed():
    assert {p.name for p in STIMULI} >= {"bench.toml", "exploration_course.toml",
                                         "quickstart_scene.toml", "robot_course.toml",
                                         "robot_ramp.toml", "robot_steps.toml"}


# the bench set's stimulus is the longest to emulate; the others cover the same path
@pytest.mark.parametrize("stimulus", [pytest.param(p, marks=pytest.mark.slow)
                                      if p.name == "bench.toml" else p for p in STIMULI],
                         ids=lambda p: p.stem)
def test_emulate_streams_the_stimulus(stimulus, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)     # a bench's data-set cache goes under ./out/.cache
    log = tmp_path / "emu.json"
    emulator = subprocess.Popen(
        [sys.executable, "-m", "snn_antenna.cli", "emulate", "--pty", "--stimulus", stimulus,
         "--frames", str(FRAMES), "--fast", "--seed", "2", "--log", log,
         "--peer-timeout", "300"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        path = emulator.stdout.readline().strip()
        assert path.startswith("/dev/"), emulator.stderr.read()
        raw = read_until_closed(path, emulator)
        assert emulator.wait(60) == 0, emulator.stderr.read()
    finally:
        emulator.kill()
    decoder = Decoder("binary")
    samples = np.array([tuple(s) for s in decoder.feed(raw)])
    assert decoder.stats.crc_errors == decoder.stats.framing_errors == 0
    assert np.array_equal(samples[:, 0], np.arange(FRAMES))

    expected = stimulus_recording(stimulus, seed=2, n_frames=FRAMES)
    assert np.array_equal(samples[:, 1:], expected.samples[:FRAMES])
    assert samples[:, 1:].std(axis=0).min() > 0     # the antenna moves or rings
    summary = json.loads(log.read_text())
    assert summary["frames_written"] == FRAMES
    assert summary["events"] == played_events(expected, FRAMES)
    if stimulus.stem == "bench":            # contact after contact, each labelled
        assert len(summary["events"]) >= 2
        assert all(e["kind"] == "contact" and e["material"] for e in summary["events"])


def test_a_scene_not_sampled_as_the_board_is_refused(tmp_path):
    spec = tmp_path / "fast.toml"
    spec.write_text('kind = "robot"\nduration_s = 2.0\nrate_hz = 2000.0\n')
    result = subprocess.run([sys.executable, "-m", "snn_antenna.cli", "emulate", "--pty",
                             "--stimulus", spec], capture_output=True, text=True, timeout=60,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 2
    assert "stimulus.rate_hz" in result.stderr and "1000" in result.stderr
