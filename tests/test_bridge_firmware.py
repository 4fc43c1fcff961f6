"""The board's C framing against the Python decoder, and the AVR build when avr-gcc is present."""
import importlib.util
import json
import random
import shutil
import subprocess
from pathlib import Path

import pytest

from snn_antenna.bridge.wire.protocol import Decoder, Sample, decode_all, encode_binary

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware" / "antenna_stream"
HOST_CC = shutil.which("cc") or shutil.which("gcc")


def load_make_vectors():
    spec = importlib.util.spec_from_file_location("make_vectors", FIRMWARE / "make_vectors.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def make(tmp_path, *targets, **variables):
    args = ["make", "-C", str(FIRMWARE), f"BUILD={tmp_path}",
            *(f"{k}={v}" for k, v in variables.items()), *targets]
    return subprocess.run(args, capture_output=True, text=True, timeout=120)


def test_boot_vectors_decode_as_a_new_session_never_a_sample():
    vectors = json.loads((FIRMWARE / "test_vectors.json").read_text())["boot_vectors"]
    assert len(vectors) == 6
    for v in vectors:
        decoder = Decoder()
        before = decoder.feed(encode_binary(7, 1, 2))
        after = decoder.feed(bytes.fromhex(v["frame"]) + encode_binary(v["first_seq"], 3, 4))
        assert before + after == [(7, 1, 2), (v["first_seq"], 3, 4)]
        stats = decoder.stats
        assert (stats.boot_frames, stats.seq_restarts, stats.framing_errors) == (1, 1, 0)
        assert decoder.sessions[-1].cause == "boot" and decoder.sessions[-1].first_seq == \
            v["first_seq"]


def test_vectors_file_matches_the_python_encoder():
    assert (FIRMWARE / "test_vectors.json").read_text() == load_make_vectors().render(), \
        "regenerate with: python firmware/antenna_stream/make_vectors.py"


needs_host_toolchain = pytest.mark.skipif(
    HOST_CC is None or shutil.which("make") is None,
    reason="no host C compiler or make on PATH (Debian: build-essential)")


@pytest.fixture(scope="module")
def frame_test(tmp_path_factory):
    build = tmp_path_factory.mktemp("fw-host")
    result = make(build, "host-test", HOSTCC=HOST_CC)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 failed" in result.stdout
    return build / "frame_test"


@needs_host_toolchain
def test_c_encoder_passes_the_shared_vectors(frame_test):
    result = subprocess.run([frame_test, FIRMWARE / "test_vectors.json"], capture_output=True,
                            text=True, timeout=10)
    assert result.returncode == 0 and "70 vectors checked, 0 failed" in result.stdout


@needs_host_toolchain
def test_c_frames_decode_in_python(frame_test):
    rng = random.Random(3)
    samples = [Sample(rng.randrange(65536), rng.randrange(1024), rng.randrange(1024))
               for _ in range(2000)]
    samples += [Sample(65535, 0, 0), Sample(0, 1023, 1023), Sample(0x100, 0x100, 0)]
    result = subprocess.run([frame_test, "-"], input="".join(f"{s.seq} {s.x} {s.y}\n"
                                                             for s in samples),
                            capture_output=True, text=True, timeout=10)
    frames = [bytes.fromhex(h) for h in result.stdout.split()]
    assert frames == [encode_binary(*s) for s in samples]
    # frame by frame: the random sequence numbers are no stream (as one, the decoder's
    # sequence discipline would rightly drop and reorder them)
    for frame, sample in zip(frames, samples):
        decoded, decoder = decode_all(frame)
        assert decoded == [sample]
        assert decoder.stats.crc_errors == decoder.stats.framing_errors == 0


@pytest.mark.skipif(shutil.which("avr-gcc") is None,
                    reason="avr-gcc is not on PATH (Debian: apt-get install gcc-avr avr-libc; "
                           ".ci/run installs them)")
@pytest.mark.parametrize("mcu, flash_bytes", [("atmega328p", 32768), ("atmega2560", 262144)])
def test_avr_firmware_builds(tmp_path, mcu, flash_bytes):
    result = make(tmp_path, MCU=mcu)
    assert result.returncode == 0, result.stdout + result.stderr
    hex_file = tmp_path / f"antenna_stream-{mcu}.hex"
    assert hex_file.read_text().startswith(":")
    text_size = int(result.stdout.split("filename")[1].split()[0])
    assert 0 < text_size < flash_bytes - 2048      # leaves room for the Arduino bootloader
