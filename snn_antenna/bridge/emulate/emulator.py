"""A device emulator: the sensor board's stream, at 1 kHz real time, with faults on demand.

It writes the wire format to a pseudo-terminal it creates (``links.PtyLink``, optionally behind a
symlink that survives a disconnect) or to any pyserial URL (``links.SerialLink``); what it
streams for a stimulus file is ``bridge/emulate/stimulus.py``'s. Faults are
placed by a seeded generator and every one is logged, so a test can compare what the receiver
counted with what was injected:

garbage     random bytes, ended by a delimiter, before a frame: each zero-free run is one framing
            error (runs are never 9 bytes long, the length of a real frame, so none can pass).
drop        a frame is not sent: a gap.
bitflip     one bit of a frame's content (payload or CRC) flipped: a CRC error and a gap.
range       a frame with a valid CRC but x beyond 1023: a range error and a gap.
stall       the link pauses for ``stall_s``; the board keeps sampling and the backlog follows in
            a burst: nothing is lost.
dup         a frame is sent twice: one duplicate, nothing lost.
swap        a frame and the next are sent in swapped order: one reordered frame, nothing lost.
disconnect  the port vanishes for ``outage_s`` and comes back at the same path; the board keeps
            sampling, so the frames due meanwhile are lost: one gap per outage, one reconnect.
reset       the board restarts, as when power-cycled or reset by DTR: silent for ``reset_s``
            while it boots, then (with boot frames, as the shipped firmware) a boot frame, and
            its count starts again from 0: one restart, nothing lost, no duplicate.

A board that sends no boot frame (``boot_frames=False``, ``emulate --no-boot-frame``) leaves
the restart to the host's rules (bridge/wire/protocol.py). A host that stalls (suspend, swap, a
stopped process) is the reader's fault, not the board's: the emulator keeps writing, the port
buffers what it can and the emulator's writes wait for the rest, so nothing is lost.

Like a board whose host opens the port, the emulator waits for a reader before it streams, and
before it pulls the port away it waits until the reader has taken every byte already written:
"written" then means "received", which is what makes exact comparisons possible.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ...core import bounds
from ...core.errors import SpecError
from ..wire.protocol import (
    ADC_MAX,
    BOARD_RATE_HZ,
    DELIMITER,
    ENCODED_FRAME_LEN,
    REORDER_WINDOW,
    SEQ_MODULUS,
    Sample,
    cobs_encode,
    encode_boot,
    encoder_for,
    find_gaps,
    frame_payload,
)

# What each fault does, in one line (``emulate --help`` shows them; the module's docstring says
# what the receiver must count for each).
FAULT_DESCRIPTIONS = {
    "garbage": "random bytes before a frame (framing errors)",
    "drop": "a frame not sent (a gap)",
    "bitflip": "one bit of a frame flipped (a CRC error, a gap)",
    "range": "a frame with x beyond the ADC (a range error, a gap)",
    "stall": "the link pauses for stall_s, then the backlog (nothing lost)",
    "dup": "a frame sent twice (a duplicate)",
    "swap": "two frames in swapped order (one reordered)",
    "disconnect": "the port vanishes for outage_s (a gap, a reconnect; needs --link)",
    "reset": "the board restarts, silent for reset_s, its count from 0 (a restart)",
}
FAULT_KINDS = tuple(FAULT_DESCRIPTIONS)
FAULT_SECONDS = ("stall_s", "outage_s", "reset_s")
# After a reset the first frames go out clean: a board without boot frames is recognised by its
# new count, which a fault there would hide.
CLEAN_AFTER_RESET = REORDER_WINDOW + 2


# -- faults ------------------------------------------------------------------------------------
@dataclass
class FaultPlan:
    """How many faults of each kind to inject, placed at seeded random frames."""
    garbage: int = 0
    drop: int = 0
    bitflip: int = 0
    range: int = 0
    stall: int = 0
    dup: int = 0
    swap: int = 0
    disconnect: int = 0
    reset: int = 0
    stall_s: float = 0.2
    outage_s: float = 0.3
    reset_s: float = 0.1

    def __post_init__(self):
        bounds.declared(self)
        self.validate()

    @classmethod
    def parse(cls, text: str) -> FaultPlan:
        """``"garbage=3,drop=2,stall_s=0.1"`` -> FaultPlan."""
        plan = cls()
        for item in filter(None, (part.strip() for part in (text or "").split(","))):
            name, _, value = item.partition("=")
            name = name.strip()
            if name not in cls.__dataclass_fields__:
                raise SpecError("faults", item, "comma-separated NAME=VALUE with NAME in "
                                + ", ".join(cls.__dataclass_fields__))
            try:
                number = float(value) if name.endswith("_s") else int(value)
            except ValueError:
                raise SpecError(f"faults.{name}", value, "a number") from None
            setattr(plan, name, number)
        plan.validate()
        return plan

    def validate(self) -> None:
        for kind in FAULT_KINDS:
            value = getattr(self, kind)
            if not (isinstance(value, int) and value >= 0):
                raise SpecError(f"faults.{kind}", value, "a count >= 0")
        for name in FAULT_SECONDS:
            value = getattr(self, name)
            if not (0 <= value <= 60):
                raise SpecError(f"faults.{name}", value, "seconds in [0, 60]")

    @property
    def total(self) -> int:
        return sum(getattr(self, kind) for kind in FAULT_KINDS)


@dataclass
class EmulatorLog:
    """What the emulator did: every valid frame written, and every fault with its frame index."""
    written: list[Sample] = field(default_factory=list)
    in_order: list[Sample] = field(default_factory=list)     # written, less dups, swaps undone
    write_times_s: list[float] = field(default_factory=list)     # time.time() after each write
    faults: list[tuple[str, int, int]] = field(default_factory=list)   # (kind, frame, seq)
    framing_errors: int = 0
    frames_due: int = 0
    session_starts: list[int] = field(default_factory=lambda: [0])   # indices into in_order
    boot_frames: int = 0

    def injected(self) -> dict:
        return {kind: sum(1 for k, *_ in self.faults if k == kind) for kind in FAULT_KINDS}

    def expected_counts(self) -> dict:
        """The counts a correct receiver reports for this stream."""
        gaps = find_gaps([s.seq for s in self.in_order],
                         [(i, None) for i in self.session_starts])
        injected = self.injected()
        return {"frames": len(self.in_order), "crc_errors": injected["bitflip"],
                "framing_errors": self.framing_errors, "range_errors": injected["range"],
                "gaps": len(gaps), "lost_samples": sum(g.length for g in gaps),
                "reconnects": injected["disconnect"], "duplicates": injected["dup"],
                "reordered": injected["swap"], "late": 0, "seq_restarts": injected["reset"],
                "boot_frames": self.boot_frames}

    def sessions(self) -> list[list[Sample]]:
        """What the board sent in order, one list per board session."""
        bounds = self.session_starts + [len(self.in_order)]
        return [self.in_order[a:b] for a, b in zip(bounds, bounds[1:])]


def garbage_burst(rng: np.random.Generator) -> tuple[bytes, int]:
    """Random bytes ended by a delimiter, and the number of framing errors they must cause."""
    while True:
        body = rng.integers(0, 256, int(rng.integers(1, 33)), dtype=np.uint8).tobytes()
        runs = [len(run) for run in body.split(DELIMITER)]
        if ENCODED_FRAME_LEN not in runs:
            return body + DELIMITER, sum(1 for n in runs if n)


def ascii_garbage(rng: np.random.Generator) -> tuple[bytes, int]:
    letters = rng.integers(ord("a"), ord("z") + 1, int(rng.integers(1, 20)), dtype=np.uint8)
    return letters.tobytes() + b"\n", 1


# -- the emulator -------------------------------------------------------------------------------
class _Outbox:
    """Bytes and the valid samples among them, written to the link in one go (and logged as
    written only then)."""

    def __init__(self, link, log: EmulatorLog, stop: threading.Event):
        self.link, self.log, self.stop = link, log, stop
        self.data, self.samples, self.in_order = bytearray(), [], []

    def flush(self) -> None:
        if self.data:
            self.link.write(bytes(self.data), self.stop)
            now = time.time()
            self.log.written += self.samples
            self.log.in_order += self.in_order
            self.log.write_times_s += [now] * len(self.samples)
            self.data.clear()
            self.samples.clear()
            self.in_order.clear()


class Emulator:
    """Streams ``counts`` (shape (n, 2), ADC counts) as frames, looping over them if needed."""

    def __init__(self, counts, *, rate_hz: float = BOARD_RATE_HZ,
                 faults: FaultPlan | None = None, seed: int = 0, wire_format: str = "binary",
                 start_seq: int = 0, fault_margin: int = 20, boot_frames: bool = True):
        bounds.declared(self, counts=counts, rate_hz=rate_hz, faults=faults, seed=seed,
                        wire_format=wire_format, start_seq=start_seq, fault_margin=fault_margin,
                        boot_frames=boot_frames)
        bounds.seed("seed", seed)
        bounds.integer("start_seq", start_seq, 0, bounds.MAX_COUNT)
        bounds.integer("fault_margin", fault_margin, 0, bounds.MAX_COUNT)
        counts = np.asarray(counts)
        if counts.ndim != 2 or counts.shape[1] != 2 or counts.shape[0] == 0:
            raise SpecError("counts", f"array of shape {counts.shape}", "shape (n_samples, 2)")
        if not (np.issubdtype(counts.dtype, np.integer) or (
                np.issubdtype(counts.dtype, np.floating) and np.all(np.isfinite(counts))
                and np.all(counts == np.round(counts)))):
            raise SpecError("counts", f"array of dtype {counts.dtype}",
                            f"whole ADC counts in 0..{ADC_MAX} (no NaN, no fractions)")
        if counts.min() < 0 or counts.max() > ADC_MAX:
            raise SpecError("counts", f"range [{counts.min()}, {counts.max()}]",
                            f"ADC counts in 0..{ADC_MAX}")
        if not (0 < rate_hz <= 5000):
            raise SpecError("rate_hz", rate_hz, "a frame rate in (0, 5000] Hz")
        self.counts = counts            # any integer dtype: a whole bench is 13 M samples
        self.rate_hz = rate_hz
        self.faults = faults or FaultPlan()
        self.faults.validate()
        if wire_format == "ascii" and self.faults.bitflip:
            raise SpecError("faults.bitflip", self.faults.bitflip,
                            "0 with --format ascii (ascii lines carry no CRC to catch a flip)")
        self.encode = encoder_for(wire_format)
        self.wire_format = wire_format
        self.seed, self.start_seq, self.fault_margin = seed, start_seq, fault_margin
        self.boot_frames = boot_frames
        self.log = EmulatorLog()
        self._session = (0, start_seq)      # (frame index, seq) where the board's count began

    def schedule(self, n_frames: int) -> dict[int, str]:
        """Seeded, distinct frame indices for every planned fault."""
        slots = n_frames - 2 * self.fault_margin
        if self.faults.total == 0:
            return {}
        if self.faults.total > max(slots, 0):
            raise SpecError("faults", self.faults.total,
                            f"at most {max(slots, 0)} faults for {n_frames} frames "
                            f"(none in the first and last {self.fault_margin})")
        rng = np.random.default_rng(self.seed)
        where = rng.choice(slots, self.faults.total, replace=False) + self.fault_margin
        kinds = [k for k in FAULT_KINDS for _ in range(getattr(self.faults, k))]
        return {int(i): k for i, k in zip(where, kinds)}

    def run(self, link, n_frames: int | None = None, *, realtime: bool = True,
            stop: threading.Event | None = None,
            peer_timeout_s: float | None = 30.0) -> EmulatorLog:
        """Stream ``n_frames`` (default: all counts once) to ``link``, with the planned faults."""
        stop = stop or threading.Event()
        n_frames = len(self.counts) if n_frames is None else n_frames
        if n_frames <= 0:
            raise SpecError("frames", n_frames, "a number of frames > 0")
        plan = self.schedule(n_frames)
        if "disconnect" in plan.values() and not link.can_disconnect:
            raise SpecError("faults.disconnect", self.faults.disconnect,
                            "0 unless the emulator owns a pty with a stable --link path")
        rng = np.random.default_rng(self.seed + 1)
        link.wait_for_peer(peer_timeout_s, stop)
        t0 = time.monotonic()
        out = _Outbox(link, self.log, stop)
        if self.boot_frames:
            self._boot(out, self.start_seq)
        i, clean_until = 0, 0
        while i < n_frames and not stop.is_set():
            if realtime and time.monotonic() < t0 + i / self.rate_hz:
                out.flush()
                time.sleep(max(0.0, min(t0 + i / self.rate_hz - time.monotonic(), 0.002)))
                continue
            # After a reconnect the receiver treats bytes before its first valid frame as boot
            # noise; a fault there would go uncounted, so the first frame goes out clean.
            kind = None if i < clean_until else plan.get(i)
            self.log.frames_due = i + 1
            if kind:
                self.log.faults.append((kind, i, self._sample(i).seq))
            if kind == "disconnect":
                i = self._disconnect(link, out, i, t0, realtime, peer_timeout_s)
                clean_until = i + 1
                continue
            if kind == "reset":
                t0 += self._reset(out, i)
                clean_until = i + CLEAN_AFTER_RESET
            self._frame(out, i, kind, rng)
            i += 2 if kind == "swap" else 1
            if len(out.data) >= 4096:
                out.flush()
        out.flush()
        link.drain()
        return self.log

    def _frame(self, out: _Outbox, i: int, kind: str | None, rng: np.random.Generator) -> None:
        """Frame ``i`` into the outbox: as it should be, or with the fault ``kind``."""
        seq, x, y = self._sample(i)
        if kind == "garbage":
            noise, errors = (garbage_burst if self.wire_format == "binary"
                             else ascii_garbage)(rng)
            out.data += noise
            self.log.framing_errors += errors
        elif kind == "stall":
            out.flush()
            out.stop.wait(self.faults.stall_s)
        if kind == "drop":
            return
        if kind == "bitflip":
            raw = bytearray(frame_payload(seq, x, y))
            raw[int(rng.integers(len(raw)))] ^= 1 << int(rng.integers(8))
            out.data += cobs_encode(bytes(raw)) + DELIMITER
        elif kind == "range":
            bad_x = int(rng.integers(ADC_MAX + 1, 65536))
            out.data += (cobs_encode(frame_payload(seq, bad_x, y)) + DELIMITER
                         if self.wire_format == "binary" else f"{seq},{bad_x},{y}\n".encode())
        elif kind == "swap":            # the next frame overtakes this one
            after = self._sample(i + 1)
            for sample in (after, Sample(seq, x, y)):
                out.data += self.encode(*sample)
                out.samples.append(sample)
            out.in_order += [Sample(seq, x, y), after]
        else:
            copies = 2 if kind == "dup" else 1
            out.data += self.encode(seq, x, y) * copies
            out.samples += [Sample(seq, x, y)] * copies
            out.in_order.append(Sample(seq, x, y))

    def _sample(self, i: int) -> Sample:
        x, y = (int(v) for v in self.counts[i % len(self.counts)])
        first_frame, first_seq = self._session
        return Sample((first_seq + i - first_frame) % SEQ_MODULUS, x, y)

    def _boot(self, out: _Outbox, first_seq: int) -> None:
        out.data += encode_boot(self.wire_format, first_seq)
        self.log.boot_frames += 1

    def _reset(self, out: _Outbox, i: int) -> float:
        """The board restarts before frame ``i``: silent while it boots, then a new count from
        0. Returns the time it took, which the board did not spend sampling."""
        started = time.monotonic()
        out.flush()
        out.stop.wait(self.faults.reset_s)
        self._session = (i, 0)
        self.log.session_starts.append(len(self.log.in_order) + len(out.in_order))
        if self.boot_frames:
            self._boot(out, 0)
        return time.monotonic() - started

    def _disconnect(self, link, out: _Outbox, i: int, t0: float, realtime: bool,
                    peer_timeout_s: float | None) -> int:
        """Pull the port away for ``outage_s`` and bring it back; returns the next frame due.
        The board kept sampling during the outage: the frames due meanwhile are gone."""
        out.flush()
        link.drain()
        link.disconnect()
        out.stop.wait(self.faults.outage_s)
        link.reconnect()
        link.wait_for_peer(peer_timeout_s, out.stop)
        if realtime:
            return max(i + 1, math.ceil((time.monotonic() - t0) * self.rate_hz))
        return i + max(1, int(self.faults.outage_s * self.rate_hz))
