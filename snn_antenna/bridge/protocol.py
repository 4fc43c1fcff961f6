"""The wire protocol between the sensor board and the host: framing as pure functions of bytes.

binary (default): one frame per sample, payload little-endian ``seq u16, x u16, y u16`` followed by
``crc u16`` = CRC-16/XMODEM of those 6 bytes, the 8 bytes COBS-encoded and ended by one ``0x00``.
ascii (debug): lines ``seq,x,y`` ending in ``\\n`` or ``\\r\\n``.

The :class:`Decoder` is fed whatever chunks the port returns and yields samples; it never fills a
gap, it counts it. Nothing here touches a port, so every property is testable on bytes alone.
"""
from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from typing import NamedTuple

from ..errors import SpecError

# The sensor board: an ADXL321 (±18 g) into a 10-bit ADC, sampled at 1 kHz. Every part of the
# bridge that needs to know what the board sends (the decoder's range check, the emulator, the
# recorder's rate, the online pipeline's chain) takes it from here.
BOARD_RATE_HZ = 1000.0
BOARD_ADC_BITS = 10
BOARD_FULL_SCALE_G = 18.0
SEQ_MODULUS = 65536
ADC_MAX = 2 ** BOARD_ADC_BITS - 1
DELIMITER = b"\x00"
PAYLOAD = struct.Struct("<HHH")
FRAME = struct.Struct("<HHHH")          # payload + crc
ENCODED_FRAME_LEN = FRAME.size + 1      # COBS adds one byte to any block shorter than 254
# A binary frame is 9 bytes on the wire; anything far longer without a delimiter is noise, so the
# decoder stops buffering it (but still counts it once when the delimiter finally comes).
MAX_SEGMENT = 64
WIRE_FORMATS = ("binary", "ascii")


class Sample(NamedTuple):
    seq: int
    x: int
    y: int


class Gap(NamedTuple):
    """``length`` samples are missing after the sample with sequence number ``after_seq``,
    which was the ``after_index``-th sample delivered (0-based)."""
    after_index: int
    after_seq: int
    length: int


@dataclass
class DecoderStats:
    frames: int = 0             # valid samples delivered
    crc_errors: int = 0
    framing_errors: int = 0     # COBS violations, wrong length, unparsable ascii lines
    range_errors: int = 0       # CRC fine but x or y beyond the 10-bit ADC
    gaps: int = 0
    lost_samples: int = 0       # sum of gap lengths
    noise_bytes: int = 0        # discarded while (re)synchronising after a port open

    def as_dict(self) -> dict:
        return dict(self.__dict__)      # dataclasses.asdict deep-copies: 10x slower per batch


def crc16_xmodem(payload: bytes) -> int:
    """CRC-16/XMODEM (poly 0x1021, init 0), identical to avr-libc's ``_crc_xmodem_update``."""
    return binascii.crc_hqx(payload, 0)


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the result contains no zero byte."""
    out = bytearray()
    block = bytearray()
    for byte in data:
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
    out.append(len(block) + 1)
    out += block
    return bytes(out)


class CobsError(ValueError):
    pass


def cobs_decode(encoded: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises :class:`CobsError` on a malformed block."""
    out = bytearray()
    i, n = 0, len(encoded)
    while i < n:
        code = encoded[i]
        if code == 0:
            raise CobsError(f"zero byte at offset {i}")
        end = i + code
        if end > n:
            raise CobsError(f"block of {code - 1} bytes at offset {i} overruns the frame")
        block = encoded[i + 1:end]
        if 0 in block:
            raise CobsError(f"zero byte inside block at offset {i}")
        out += block
        i = end
        if code < 255 and i < n:
            out.append(0)
    return bytes(out)


def check_sample(seq: int, x: int, y: int) -> None:
    for name, value, top in (("seq", seq, SEQ_MODULUS - 1), ("x", x, ADC_MAX), ("y", y, ADC_MAX)):
        if not (isinstance(value, int) and 0 <= value <= top):
            raise SpecError(name, value, f"an integer in 0..{top}")


def frame_payload(seq: int, x: int, y: int) -> bytes:
    """The 8 unencoded bytes ``seq x y crc``; x and y are not range-checked so that an emulator
    can build a frame the decoder must reject as out of range."""
    payload = PAYLOAD.pack(seq, x, y)
    return payload + struct.pack("<H", crc16_xmodem(payload))


def encode_binary(seq: int, x: int, y: int) -> bytes:
    check_sample(seq, x, y)
    return cobs_encode(frame_payload(seq, x, y)) + DELIMITER


def encode_ascii(seq: int, x: int, y: int) -> bytes:
    check_sample(seq, x, y)
    return f"{seq},{x},{y}\r\n".encode()


def encoder_for(wire_format: str):
    check_wire_format(wire_format)
    return encode_binary if wire_format == "binary" else encode_ascii


def check_wire_format(wire_format: str) -> str:
    if wire_format not in WIRE_FORMATS:
        raise SpecError("format", wire_format, " or ".join(WIRE_FORMATS))
    return wire_format


class Decoder:
    """Incremental decoder: ``feed(chunk)`` returns the valid samples completed by that chunk.

    The result does not depend on where the chunk boundaries fall. After :meth:`resync` (the
    source calls it on every port open) bytes up to the first valid frame are boot noise: a board
    reset by DTR, or a frame cut in half by the open, is discarded and counted in ``noise_bytes``
    rather than as an error. Sequence continuity survives a resync, so samples the board produced
    while the link was down appear as a gap.
    """

    def __init__(self, wire_format: str = "binary", synced: bool = False):
        self.wire_format = check_wire_format(wire_format)
        self._terminator = DELIMITER if wire_format == "binary" else b"\n"
        self._parse = self._parse_binary if wire_format == "binary" else self._parse_ascii
        self.stats = DecoderStats()
        self.gap_list: list[Gap] = []
        self._buffer = bytearray()
        self._segment_len = 0           # true length of the unterminated segment, kept or not
        self._synced = synced
        self._last_seq: int | None = None

    def resync(self) -> None:
        self.stats.noise_bytes += self._segment_len
        self._buffer.clear()
        self._segment_len = 0
        self._synced = False

    @property
    def last_seq(self) -> int | None:
        return self._last_seq

    def feed(self, chunk: bytes) -> list[Sample]:
        samples: list[Sample] = []
        pieces = bytes(chunk).split(self._terminator)
        for piece in pieces[:-1]:
            self._append(piece)
            self._complete(samples)
        self._append(pieces[-1])
        return samples

    def _append(self, piece: bytes) -> None:
        self._segment_len += len(piece)
        if self._segment_len <= MAX_SEGMENT:
            self._buffer += piece
        else:
            self._buffer.clear()

    def _complete(self, out: list[Sample]) -> None:
        segment, length = bytes(self._buffer), self._segment_len
        self._buffer.clear()
        self._segment_len = 0
        self._segment(segment, length, length > MAX_SEGMENT, out)

    def _segment(self, segment: bytes, length: int, overlong: bool, out: list[Sample]) -> None:
        if length == 0 or (self.wire_format == "ascii" and segment.strip() == b""):
            return                      # idle delimiters / blank lines carry nothing
        verdict = "framing" if overlong else self._parse(segment)
        if not self._synced:
            if isinstance(verdict, Sample):
                self._synced = True
            else:
                self.stats.noise_bytes += length + 1
                return
        if isinstance(verdict, Sample):
            self._accept(verdict, out)
        elif verdict == "crc":
            self.stats.crc_errors += 1
        elif verdict == "range":
            self.stats.range_errors += 1
        else:
            self.stats.framing_errors += 1

    def _accept(self, sample: Sample, out: list[Sample]) -> None:
        if self._last_seq is not None:
            missing = (sample.seq - self._last_seq - 1) % SEQ_MODULUS
            if missing:
                self.stats.gaps += 1
                self.stats.lost_samples += missing
                self.gap_list.append(Gap(self.stats.frames - 1, self._last_seq, missing))
        self._last_seq = sample.seq
        self.stats.frames += 1
        out.append(sample)

    @staticmethod
    def _parse_binary(segment: bytes):
        if len(segment) != ENCODED_FRAME_LEN:
            return "framing"
        try:
            raw = cobs_decode(segment)
        except CobsError:
            return "framing"
        if len(raw) != FRAME.size:
            return "framing"
        seq, x, y, crc = FRAME.unpack(raw)
        if crc16_xmodem(raw[:PAYLOAD.size]) != crc:
            return "crc"
        if x > ADC_MAX or y > ADC_MAX:
            return "range"
        return Sample(seq, x, y)

    @staticmethod
    def _parse_ascii(segment: bytes):
        fields = segment.rstrip(b"\r").split(b",")
        if len(fields) != 3 or not all(f.strip().isdigit() for f in fields):
            return "framing"
        seq, x, y = (int(f) for f in fields)
        if seq >= SEQ_MODULUS:
            return "framing"
        if x > ADC_MAX or y > ADC_MAX:
            return "range"
        return Sample(seq, x, y)


def decode_all(data: bytes, wire_format: str = "binary",
               synced: bool = True) -> tuple[list[Sample], Decoder]:
    """Decode a whole byte string at once (tests, replay of a file)."""
    decoder = Decoder(wire_format, synced=synced)
    return decoder.feed(data), decoder


def find_gaps(seq) -> list[Gap]:
    """The gaps in a whole sequence-number column, by the same rule the Decoder applies online
    (a recording read back after a crash recomputes them this way)."""
    import numpy as np

    seq = np.asarray(seq, dtype=np.int64)
    if seq.size < 2:
        return []
    missing = (np.diff(seq) - 1) % SEQ_MODULUS
    where = np.flatnonzero(missing)
    return [Gap(int(i), int(seq[i]), int(missing[i])) for i in where]
