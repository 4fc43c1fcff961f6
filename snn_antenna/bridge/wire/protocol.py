"""The wire protocol between the sensor board and the host: framing as pure functions of bytes.

binary (default): one frame per sample, payload little-endian ``seq u16, x u16, y u16`` followed by
``crc u16`` = CRC-16/XMODEM of those 6 bytes, the 8 bytes COBS-encoded and ended by one ``0x00``.
ascii (debug): lines ``seq,x,y`` ending in ``\\n`` or ``\\r\\n``.

The :class:`Decoder` is fed whatever chunks the port returns and yields samples; it never fills a
gap, it counts it. Like an RTP receiver it keeps sequence discipline: a sequence number already
delivered is a duplicate (dropped, counted); a frame arriving ahead of a hole is held for up to
``REORDER_WINDOW`` frames so that a late frame can be put back in order (counted ``reordered``);
a hole still open after that is a gap, its samples lost, counted once. A frame older than the
window, or that falls in a hole already counted lost, is dropped (``late``); a step further
back to numbers never delivered nor missed means the board restarted its counter (``seq_restarts``). Nothing here touches a port, so every property is testable on bytes alone.
"""
from __future__ import annotations

import binascii
import collections
import struct
from dataclasses import dataclass
from typing import NamedTuple

from ...core.errors import SpecError

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
# Sequence discipline. A hole is waited for during this many frames (8 ms at 1 kHz) before it
# is declared a gap; a link that reorders further than that loses those frames, counted as late.
REORDER_WINDOW = 8
# Sequence numbers delivered this recently are recognised as duplicates; a number further back
# than this (and more than half the 16-bit circle away) means the board restarted its counter.
DUPLICATE_WINDOW = 1024
HALF_MODULUS = 32768


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
    duplicates: int = 0         # a sequence number already delivered (or held), dropped
    reordered: int = 0          # overtaken by a later frame, within the window: put back in order
    late: int = 0               # arrived after its hole was declared a gap: dropped
    seq_restarts: int = 0       # the counter jumped far back: the board restarted

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
        self._last_seq: int | None = None     # the last sequence number delivered
        self._held: dict[int, Sample] = {}      # frames ahead of a hole, by sequence number
        self._recent: collections.deque[int] = collections.deque()
        self._recent_set: set[int] = set()

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
        if self._last_seq is None:
            self._deliver(sample, out)
            return
        ahead = (sample.seq - self._last_seq - 1) % SEQ_MODULUS   # 0: the one expected next
        while REORDER_WINDOW < ahead < HALF_MODULUS and self._held:
            # Too far ahead to wait for the oldest hole: it is a gap now.
            self._release(out, give_up=True)
            ahead = (sample.seq - self._last_seq - 1) % SEQ_MODULUS
        if ahead == 0:
            if self._held:
                self.stats.reordered += 1       # it fills the hole the held frames wait on
            self._deliver(sample, out)
            self._release(out)
        elif REORDER_WINDOW < ahead < HALF_MODULUS:
            self._gap_to(sample.seq)            # too far ahead to be a reorder: a gap
            self._deliver(sample, out)
        elif ahead < HALF_MODULUS:
            if sample.seq in self._held:
                self.stats.duplicates += 1
                return
            if any((held - self._last_seq - 1) % SEQ_MODULUS > ahead for held in self._held):
                self.stats.reordered += 1       # a later frame overtook it
            self._held[sample.seq] = sample
            if len(self._held) >= REORDER_WINDOW:
                self._release(out, everything=False, give_up=True)
        elif sample.seq in self._recent_set:
            self.stats.duplicates += 1
        elif SEQ_MODULUS - ahead <= REORDER_WINDOW + 1 or (
                SEQ_MODULUS - ahead <= DUPLICATE_WINDOW and self._in_recent_gap(sample.seq)):
            self.stats.late += 1                # overtaken beyond repair, or counted lost
        else:
            self.stats.seq_restarts += 1        # back to numbers never missed: a new count
            self._release(out, everything=True)
            self._deliver(sample, out)

    def flush(self) -> list[Sample]:
        """Deliver the frames held behind a hole: the stream ended or the link went down, so the
        hole is a gap now."""
        out: list[Sample] = []
        self._release(out, everything=True)
        return out

    def _release(self, out: list[Sample], everything: bool = False,
                 give_up: bool = False) -> None:
        """Deliver the held frames that are next in line; with ``give_up`` the first hole is
        declared a gap, with ``everything`` every hole is."""
        while self._held:
            expected = (self._last_seq + 1) % SEQ_MODULUS
            if expected in self._held:
                self._deliver(self._held.pop(expected), out)
                continue
            if not (everything or give_up):
                return
            first = min(self._held, key=lambda seq: (seq - expected) % SEQ_MODULUS)
            self._gap_to(first)
            self._deliver(self._held.pop(first), out)
            give_up = False

    def _in_recent_gap(self, seq: int) -> bool:
        return any((seq - gap.after_seq - 1) % SEQ_MODULUS < gap.length
                   for gap in self.gap_list[-16:])

    def _gap_to(self, seq: int) -> None:
        missing = (seq - self._last_seq - 1) % SEQ_MODULUS
        self.stats.gaps += 1
        self.stats.lost_samples += missing
        self.gap_list.append(Gap(self.stats.frames - 1, self._last_seq, missing))

    def _deliver(self, sample: Sample, out: list[Sample]) -> None:
        if len(self._recent) == DUPLICATE_WINDOW:
            self._recent_set.discard(self._recent.popleft())
        self._recent.append(sample.seq)
        self._recent_set.add(sample.seq)
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
    return decoder.feed(data) + decoder.flush(), decoder


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
