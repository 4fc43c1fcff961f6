"""Write test_vectors.json from the Python encoder (snn_antenna.bridge.wire.protocol).

    python firmware/antenna_stream/make_vectors.py

The C host test (``make host-test``) and tests/test_bridge_firmware.py both read the file; the
Python test also checks that it still matches the encoder, so it cannot go stale silently.
"""
import json
import random
from pathlib import Path

from snn_antenna.bridge.wire.protocol import encode_binary, encode_boot

HERE = Path(__file__).resolve().parent


def vectors() -> list[dict]:
    edge = [(0, 0, 0), (1, 2, 3), (65535, 1023, 1023), (256, 512, 768), (255, 255, 1),
            (0xff00, 0x0300, 0x0001), (65535, 0, 1023)]
    rng = random.Random(20120806)       # fixed: the file must be reproducible
    rand = [(rng.randrange(65536), rng.randrange(1024), rng.randrange(1024)) for _ in range(57)]
    return [{"seq": s, "x": x, "y": y, "frame": encode_binary(s, x, y).hex()}
            for s, x, y in edge + rand]


def boot_vectors() -> list[dict]:
    edge = [(0, 0), (1, 0), (0x0f, 0), (0, 1), (255, 65535), (2, 0x0100)]
    return [{"boot_cause": cause, "first_seq": first, "frame": encode_boot("binary", first,
                                                                         cause).hex()}
            for cause, first in edge]


def render() -> str:
    lines = ",\n".join("  " + json.dumps(v) for v in vectors())
    boots = ",\n".join("  " + json.dumps(v) for v in boot_vectors())
    return ('{"description": "wire frames (COBS(seq x y crc16-xmodem) + 0x00) and boot frames '
            '(COBS(BOOT version cause first_seq crc16-xmodem) + 0x00) from '
            'snn_antenna.bridge.wire.protocol",\n "vectors": [\n' + lines + "\n ],\n"
            ' "boot_vectors": [\n' + boots + "\n ]\n}\n")


if __name__ == "__main__":
    (HERE / "test_vectors.json").write_text(render())
