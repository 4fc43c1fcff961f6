"""The wire protocol between the sensor board and the host: framing as pure functions of bytes.

binary (default): one frame per sample, payload little-endian ``seq u16, x u16, y u16`` followed by
``crc u16`` = CRC-16/XMODEM of those 6 bytes, the 8 bytes COBS-encoded and ended by one ``0x00``.
At reset the board sends one *boot frame*: ``"BOOT", version u8, reset cause u8, first seq u16``
and the CRC, COBS-encoded (12 bytes on the wire, never the length of a sample frame).
ascii (debug): lines ``seq,x,y`` ending in ``\\n`` or ``\\r\\n``; the boot line is
``boot,VERSION,CAUSE,FIRST_SEQ``.

The :class:`Decoder` is fed whatever chunks the port returns and yields samples; it never fills a
gap, it counts it. Like an RTP receiver it keeps sequence discipline within one *board session*
(the board's count from one reset to the next): a sequence number already delivered is a
duplicate (dropped, counted); a frame arriving ahead of a hole is held for up to
``REORDER_WINDOW`` frames so that a late frame can be put back in order (counted ``reordered``);
a hole still open after that is a gap, its samples lost, counted once; a frame older than the
window, or that falls in a hole already counted lost, is dropped (``late``).

A new session (RTP's change of SSRC) is never booked as loss or duplicates. A boot frame starts
one for certain. For a board that sends none, the host tells a restart from a fault by rules
(:data:`RESTART_CAUSES`): the count went back to numbers never delivered (``backward``); two
frames in a row continue a count behind the delivered one (``sequence``, RTP's probation); the
count went back after the board was silent (``silence``); or it jumped ahead further than the
board could have sampled in the host time since the session began (``jump``). A restart that lands
on numbers the old count could have reached in that time is a gap to the host: only a boot frame
tells it apart. Nothing here touches a port, so every property is testable on bytes alone.
"""
from __future__ import annotations

import binascii
import collections
import struct
from dataclasses import dataclass
from typing import NamedTuple

from ...core import bounds
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
# Board sessions. The boot frame's payload, its magic and the protocol version it announces.
BOOT = struct.Struct("<4sBBH")          # magic, version, reset cause, first seq
BOOT_MAGIC = b"BOOT"
PROTOCOL_VERSION = 1
ENCODED_BOOT_LEN = BOOT.size + 2 + 1    # + crc, + COBS overhead
# Host-time rules for boards that send no boot frame. A board resetting is silent for longer than
# this (an Arduino's bootloader waits 1-2 s; a power cycle longer), a duplicate never is.
RESTART_SILENCE_S = 0.05
# How far ahead of the host clock a frame may claim to be before its jump is a restart: the
# host's read latency, plus the board's clock running fast by up to 1 % (a ceramic resonator is
# 0.5 %) over the session.
RESTART_SLACK_S = 0.5
CLOCK_TOLERANCE = 0.01
RESTART_CAUSES = ("boot", "backward", "sequence", "silence", "jump")
HOST_TIME_CAUSES = ("silence", "jump")     # decided by arrival times, which a replay has not


class Sample(NamedTuple):
    seq: int
    x: int
    y: int


class Boot(NamedTuple):
    version: int
    cause: int                  # the board's reset cause (the AVR's MCUSR bits)
    first_seq: int              # the sequence number of its first sample


class Session(NamedTuple):
    """A board session began with the ``index``-th sample delivered (0-based), ``raw_offset``
    bytes into the stream, for ``cause`` (``"start"`` or one of :data:`RESTART_CAUSES`);
    ``first_seq`` is the number its boot frame announced (None without one)."""
    index: int
    raw_offset: int
    cause: str
    first_seq: int | None = None


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
    seq_restarts: int = 0       # a new board session began (a boot frame, or a host rule)
    boot_frames: int = 0        # boot frames received (the first one starts the first session)

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


def encode_boot(wire_format: str = "binary", first_seq: int = 0, cause: int = 0) -> bytes:
    """The frame a board sends once at reset, before its first sample."""
    check_wire_format(wire_format)
    if wire_format == "ascii":
        return f"boot,{PROTOCOL_VERSION},{cause},{first_seq}\r\n".encode()
    payload = BOOT.pack(BOOT_MAGIC, PROTOCOL_VERSION, cause, first_seq)
    return cobs_encode(payload + struct.pack("<H", crc16_xmodem(payload))) + DELIMITER


def encoder_for(wire_format: str):
    check_wire_format(wire_format)
    return encode_binary if wire_format == "binary" else encode_ascii


def check_wire_format(wire_format: str) -> str:
    if wire_format not in WIRE_FORMATS:
        raise SpecError("format", wire_format, " or ".join(WIRE_FORMATS))
    return wire_format


class Decoder:
    """Incremental decoder: ``feed(chunk, host_time_s)`` returns the valid samples completed by
    that chunk.

    The result does not depend on where the chunk boundaries fall. After :meth:`resync` (the
    source calls it on every port open) bytes up to the first valid frame are boot noise: a board
    reset by DTR, or a frame cut in half by the open, is discarded and counted in ``noise_bytes``
    rather than as an error. Sequence continuity survives a resync, so samples the board produced
    while the link was down appear as a gap.

    ``host_time_s`` (seconds on a monotonic clock, when the chunk was read) enables the
    host-time restart rules; without it (decoding a file) only the byte-level rules apply, and
    ``restarts_at`` (raw offsets of frames that began a session by a host-time rule, as a live
    decoder recorded them) makes a replay decide as the live run did. ``sessions`` lists every
    session begun, ``gap_list`` every gap (never across a session's start).
    """

    def __init__(self, wire_format: str = "binary", synced: bool = False,
                 rate_hz: float = BOARD_RATE_HZ, restarts_at: dict[int, str] | None = None):
        bounds.declared(self, wire_format=wire_format, synced=synced, rate_hz=rate_hz,
                        restarts_at=restarts_at)
        bounds.rate_hz("rate_hz", rate_hz)
        self.wire_format = check_wire_format(wire_format)
        self._terminator = DELIMITER if wire_format == "binary" else b"\n"
        self._parse = self._parse_binary if wire_format == "binary" else self._parse_ascii
        self.rate_hz = float(rate_hz)
        self.stats = DecoderStats()
        self.gap_list: list[Gap] = []
        self.sessions: list[Session] = []
        self._buffer = bytearray()
        self._segment_len = 0           # true length of the unterminated segment, kept or not
        self._synced = synced
        self._fed = 0                   # bytes fed so far
        self._segment_start = 0         # raw offset of the segment being completed
        self._restarts_at = dict(restarts_at or {})
        self._now: float | None = None
        self._last_frame_s: float | None = None     # host time of the last valid frame
        self._suspect: tuple[Sample, str, int] | None = None    # (frame, counted as, offset)
        self._new_session("start")

    def _new_session(self, cause: str) -> None:
        self._last_seq: int | None = None     # the last sequence number delivered
        self._held: dict[int, Sample] = {}      # frames ahead of a hole, by sequence number
        self._recent: collections.deque[int] = collections.deque()
        self._recent_set: set[int] = set()
        self._steps = 0                 # sequence steps since the session's first sample
        self._session_start_s: float | None = None
        self._min_offset_s: float | None = None    # min over samples of host time - board time
        self._suspect = None
        self._session_cause = cause
        self._session_first_seq: int | None = None

    def resync(self) -> None:
        self.stats.noise_bytes += self._segment_len
        self._buffer.clear()
        self._segment_len = 0
        self._segment_start = self._fed
        self._synced = False

    @property
    def last_seq(self) -> int | None:
        return self._last_seq

    def feed(self, chunk: bytes, host_time_s: float | None = None) -> list[Sample]:
        samples: list[Sample] = []
        self._now = host_time_s
        pieces = bytes(chunk).split(self._terminator)
        position = self._fed
        for piece in pieces[:-1]:
            self._append(piece)
            self._complete(samples)
            position += len(piece) + 1
            self._segment_start = position
        self._append(pieces[-1])
        self._fed += len(chunk)
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
            if isinstance(verdict, (Sample, Boot)):
                self._synced = True
            else:
                self.stats.noise_bytes += length + 1
                return
        if isinstance(verdict, Sample):
            self._accept(verdict, out)
            if self._now is not None:
                self._last_frame_s = self._now
        elif isinstance(verdict, Boot):
            self._boot(verdict, out)
        elif verdict == "crc":
            self.stats.crc_errors += 1
        elif verdict == "range":
            self.stats.range_errors += 1
        else:
            self.stats.framing_errors += 1

    # -- sessions -------------------------------------------------------------------------------
    def _boot(self, boot: Boot, out: list[Sample]) -> None:
        self.stats.boot_frames += 1
        if self._last_seq is not None or self._held:
            self._restart("boot", out)
        else:                           # the first session, or a boot before any sample
            self._session_cause = "boot"
        # Its first sample is expected: if that one is lost, it is a gap of this session.
        self._last_seq = (boot.first_seq - 1) % SEQ_MODULUS
        self._session_first_seq = boot.first_seq
        self._steps = -1

    def _restart(self, cause: str, out: list[Sample]) -> None:
        """The old session ends (its held frames delivered, its holes gaps); a new one begins
        with the next sample delivered."""
        self._release(out, everything=True)
        self.stats.seq_restarts += 1
        self._new_session(cause)

    def _too_far_ahead(self, ahead: int) -> bool:
        """A forward jump to a number the board could not have reached by now."""
        if self._now is None or self._min_offset_s is None:
            return False
        board_s = (self._steps + ahead + 1) / self.rate_hz
        slack = RESTART_SLACK_S + CLOCK_TOLERANCE * (self._now - self._session_start_s)
        return self._now - board_s < self._min_offset_s - slack

    def _after_silence(self) -> bool:
        return (self._now is not None and self._last_frame_s is not None
                and self._now - self._last_frame_s >= RESTART_SILENCE_S)

    def _accept(self, sample: Sample, out: list[Sample]) -> None:
        suspect, self._suspect = self._suspect, None
        cause = self._restarts_at.pop(self._segment_start, None)
        if cause is not None:
            self._restart(cause, out)
        if self._last_seq is None:
            self._deliver(sample, out)
            return
        ahead = (sample.seq - self._last_seq - 1) % SEQ_MODULUS   # 0: the one expected next
        if (suspect is not None and ahead != 0 and sample.seq not in self._held
                and sample.seq == (suspect[0].seq + 1) % SEQ_MODULUS):
            # Two frames in a row continue a count behind ours: the board restarted.
            setattr(self.stats, suspect[1], getattr(self.stats, suspect[1]) - 1)
            self._restart("sequence", out)
            here, self._segment_start = self._segment_start, suspect[2]
            self._deliver(suspect[0], out)
            self._segment_start = here
            self._deliver(sample, out)
            return
        if REORDER_WINDOW < ahead < HALF_MODULUS and self._too_far_ahead(ahead):
            self._restart("jump", out)
            self._deliver(sample, out)
            return
        if ahead >= HALF_MODULUS and self._after_silence():
            self._restart("silence", out)
            self._deliver(sample, out)
            return
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
            self._suspect = (sample, "duplicates", self._segment_start)
        elif SEQ_MODULUS - ahead <= REORDER_WINDOW + 1 or (
                SEQ_MODULUS - ahead <= DUPLICATE_WINDOW and self._in_recent_gap(sample.seq)):
            self.stats.late += 1                # overtaken beyond repair, or counted lost
            self._suspect = (sample, "late", self._segment_start)
        else:
            self._restart("backward", out)      # back to numbers never delivered nor missed
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
        if self._last_seq is None or self._steps < 0:      # the session's first sample
            self.sessions.append(Session(self.stats.frames, self._segment_start,
                                         self._session_cause, self._session_first_seq))
            self._steps = 0
            self._session_start_s = self._now
        else:
            self._steps += (sample.seq - self._last_seq) % SEQ_MODULUS
        if self._now is not None:
            offset = self._now - self._steps / self.rate_hz
            if self._min_offset_s is None or offset < self._min_offset_s:
                self._min_offset_s = offset
            if self._session_start_s is None:
                self._session_start_s = self._now
        if len(self._recent) == DUPLICATE_WINDOW:
            self._recent_set.discard(self._recent.popleft())
        self._recent.append(sample.seq)
        self._recent_set.add(sample.seq)
        self._last_seq = sample.seq
        self.stats.frames += 1
        out.append(sample)

    @staticmethod
    def _parse_binary(segment: bytes):
        if len(segment) == ENCODED_BOOT_LEN:
            return Decoder._parse_boot(segment)
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
    def _parse_boot(segment: bytes):
        try:
            raw = cobs_decode(segment)
        except CobsError:
            return "framing"
        if len(raw) != BOOT.size + 2:
            return "framing"
        magic, version, cause, first_seq = BOOT.unpack(raw[:BOOT.size])
        if int.from_bytes(raw[BOOT.size:], "little") != crc16_xmodem(raw[:BOOT.size]):
            return "crc"
        if magic != BOOT_MAGIC or version != PROTOCOL_VERSION:
            return "framing"
        return Boot(version, cause, first_seq)

    @staticmethod
    def _parse_ascii(segment: bytes):
        fields = segment.rstrip(b"\r").split(b",")
        if len(fields) == 4 and fields[0] == b"boot":
            if not all(f.strip().isdigit() for f in fields[1:]):
                return "framing"
            version, cause, first_seq = (int(f) for f in fields[1:])
            if version != PROTOCOL_VERSION or cause > 255 or first_seq >= SEQ_MODULUS:
                return "framing"
            return Boot(version, cause, first_seq)
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


def find_gaps(seq, sessions=()) -> list[Gap]:
    """The gaps in a whole sequence-number column, by the same rule the Decoder applies online
    (a recording read back after a crash recomputes them this way). ``sessions``
    (:class:`Session`, or ``(index, first_seq)`` pairs) are where a board session began: no gap
    spans one, except the samples before the first one its boot frame announced."""
    import numpy as np

    seq = np.asarray(seq, dtype=np.int64)
    if seq.size == 0:
        return []
    missing = np.zeros(seq.size, dtype=np.int64)    # missing[i]: lost before sample i
    missing[1:] = (np.diff(seq) - 1) % SEQ_MODULUS
    for start in sessions:
        index, first_seq = (start.index, start.first_seq) if isinstance(start, Session) \
            else start
        if 0 <= index < seq.size:
            missing[index] = 0 if first_seq is None else (seq[index] - first_seq) % SEQ_MODULUS
    gaps = []
    for i in np.flatnonzero(missing):
        after_seq = seq[i - 1] if i and not _starts(sessions, i) else None
        if after_seq is None:               # a session's first samples were lost
            after_seq = (seq[i] - missing[i] - 1) % SEQ_MODULUS
        gaps.append(Gap(int(i) - 1, int(after_seq), int(missing[i])))
    return gaps


def _starts(sessions, index: int) -> bool:
    return any((s.index if isinstance(s, Session) else s[0]) == index for s in sessions)
