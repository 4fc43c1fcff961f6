"""Recording a serial stream so that nothing received is lost, even to ``kill -9``.

A recording is a directory:

``raw.bin``      every byte received, append-only (replay decodes it again).
``samples.bin``  one fixed-size little-endian record per valid sample: ``seq u16, x u16, y u16,
                 flags u16, host_time_s f64`` (16 bytes); flag bit 0 marks the first sample of a
                 board session (the board restarted before it). Appending whole records means a
                 crash can only tear the last one, which the reader drops.
``events.jsonl`` the changes the live input schedule applied (Th, the rate-map window in seconds,
                 the speed command), a JSON line each with the sample index it applied at,
                 written and flushed as it happens (``read_events`` reads them back; ``replay``
                 submits them to its schedule again).
``meta.json``    port, format, link events (opens, losses, reconnects, with their offset in
                 ``raw.bin``), the board sessions (where each began, and why) and the counts;
                 rewritten atomically (tmp + ``os.replace``) so it is never half-written.
                 ``complete`` is true only after a clean close.

:func:`load_recording` is the one reader: it checks every file and field it uses (regular files,
sizes that agree with ``meta.json``, types and values) and names the file, the field and the
value of the first that is wrong.

Both data files are flushed to the OS every ``flush_interval_s`` (50 ms), which is what survives a
killed process, and fsynced every ``fsync_interval_s`` (1 s), which is what survives power loss.
"""
from __future__ import annotations

import json
import math
import os
import stat
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ... import __version__ as package_version
from ...core.errors import SpecError
from ...core import outputs
from ...core.files import open_append, write_json
from ...core.signals import Recording
from .protocol import (
    BOARD_RATE_HZ,
    HOST_TIME_CAUSES,
    RESTART_CAUSES,
    SEQ_MODULUS,
    WIRE_FORMATS,
    Gap,
    find_gaps,
)
from .handler import WindowHandler
from .source import DEFAULT_BAUDRATE, Batch
from .protocol import Sample, encode_binary

SAMPLE_DTYPE = np.dtype([("seq", "<u2"), ("x", "<u2"), ("y", "<u2"), ("flags", "<u2"),
                         ("host_time_s", "<f8")])
SESSION_START = 1                       # samples.bin flag: a board session begins here
RAW_FILE, SAMPLES_FILE, META_FILE = "raw.bin", "samples.bin", "meta.json"
EVENTS_FILE = "events.jsonl"            # the input schedule's changes (read_events)
RECORDING = "recording"                 # what a recording's output folder holds
FORMAT_VERSION = 1
COUNT_FIELDS = ("frames", "crc_errors", "framing_errors", "range_errors", "gaps", "lost_samples",
                "duplicates", "reordered", "late", "seq_restarts", "boot_frames", "reconnects")


class Recorder(WindowHandler):
    """Writes :class:`~snn_antenna.bridge.wire.source.Batch` objects into a recording directory,
    and journals the changes the live input schedule applied (a WindowHandler of the online
    pipeline, bridge/wire/handler.py)."""

    def __init__(self, out, *, port: str, wire_format: str, baudrate: int,
                 rate_hz: float = BOARD_RATE_HZ, flush_interval_s: float = 0.05,
                 fsync_interval_s: float = 1.0, meta_interval_s: float = 0.5,
                 extra_meta: dict | None = None):
        """``out``: the recording's folder, new or empty. A path goes through
        ``outputs.output_folder`` here (checked, claimed, recorded on ``close``); the commands
        pass the folder they checked before opening the port, and record it themselves."""
        self._door = ExitStack()
        try:
            folder = out if isinstance(out, outputs.OutputFolder) else \
                self._door.enter_context(outputs.output_folder(out, RECORDING, new=True))
            folder.claim()                  # one recorder per folder, journaled until close
        except BaseException:
            self._door.close()
            raise
        self.dir = folder.path
        self.flush_interval_s = flush_interval_s
        self.fsync_interval_s = fsync_interval_s
        self.meta_interval_s = meta_interval_s
        self._raw = open_append(self.dir / RAW_FILE, binary=True)
        self._samples = open_append(self.dir / SAMPLES_FILE, binary=True)
        self._events = None                       # opened by the first control event
        self.raw_bytes = 0
        self.n_samples = 0
        self.counts = {name: 0 for name in COUNT_FIELDS}
        self.meta = {
            "format_version": FORMAT_VERSION, "kind": "snn-antenna serial recording",
            "package_version": package_version, "port": port, "wire_format": wire_format,
            "baudrate": baudrate, "rate_hz": rate_hz,
            "samples_dtype": [[name, SAMPLE_DTYPE[name].str] for name in SAMPLE_DTYPE.names],
            "started_unix_s": time.time(), "stopped_unix_s": None, "complete": False,
            "status": "recording", "message": "", "link_events": [], "sessions": [],
            "counts": self.counts,
            **(extra_meta or {}),
        }
        now = time.monotonic()
        self._last_flush = self._last_fsync = self._last_meta = now
        self._write_meta()

    def handle(self, batch: Batch) -> None:
        if batch.event:
            self.meta["link_events"].append({"event": batch.event, "raw_offset": self.raw_bytes,
                                             "host_time_s": batch.host_time_s,
                                             "message": batch.message})
        if batch.raw:
            self._raw.write(batch.raw)
            self.raw_bytes += len(batch.raw)
        if batch.samples:
            records = np.zeros(len(batch.samples), SAMPLE_DTYPE)
            columns = np.array(batch.samples, dtype=np.uint16).reshape(-1, 3)
            records["seq"], records["x"], records["y"] = columns.T
            records["host_time_s"] = batch.host_time_s
            for session in batch.sessions:
                records["flags"][session.index - self.n_samples] |= SESSION_START
                self.meta["sessions"].append(session._asdict())
            self._samples.write(records.tobytes())
            self.n_samples += len(batch.samples)
        if batch.counts:
            self.counts.update({k: batch.counts[k] for k in batch.counts})
        self.idle()

    def idle(self) -> None:
        """Called at least every ``flush_interval_s`` by the loop, data or not."""
        now = time.monotonic()
        if now - self._last_flush >= self.flush_interval_s:
            self._raw.flush()
            self._samples.flush()
            self._last_flush = now
            if now - self._last_fsync >= self.fsync_interval_s:
                os.fsync(self._raw.fileno())
                os.fsync(self._samples.fileno())
                self._last_fsync = now
        if now - self._last_meta >= self.meta_interval_s:
            self._write_meta()
            self._last_meta = now

    def changed(self, event: dict) -> None:
        """A change the input schedule applied, journaled with the value the page showed (the
        rate-map window in seconds, not in the network's windows)."""
        (field, value), = event["shown"].items()
        self.note_event({**event, "field": field, "value": value})

    def note_event(self, event: dict) -> None:
        """One JSON line in ``events.jsonl``, flushed at once (a change is rare, and replay
        needs every one)."""
        if self._events is None:
            self._events = open_append(self.dir / EVENTS_FILE)
        self._events.write(json.dumps(event) + "\n")
        self._events.flush()
        self.meta["control_events"] = self.meta.get("control_events", 0) + 1

    def note_outcome(self, **outcome) -> None:
        """What the live run found (``stream``: its contacts), kept in ``meta.json`` under
        ``live`` so that a replay can show it beside its own."""
        self.meta["live"] = outcome

    def close(self, status: str = "ok", message: str = "", complete: bool = True) -> None:
        """Flush and close; ``complete=False`` records that the session ended in a failure
        (``status`` and ``message`` say which), although every byte received is kept."""
        if self._raw.closed:
            return
        for f in (self._raw, self._samples, *([self._events] if self._events else [])):
            f.flush()
            os.fsync(f.fileno())
            f.close()
        self.meta.update(status=status, message=message, complete=complete,
                         stopped_unix_s=time.time())
        self._write_meta()
        self._door.close()

    def _write_meta(self) -> None:
        self.meta["counts"] = dict(self.counts)
        self.meta["n_samples_written"] = self.n_samples
        self.meta["raw_bytes_written"] = self.raw_bytes
        write_json(self.dir / META_FILE, self.meta)


@dataclass
class BridgeRecording:
    """A recording read back. ``gaps`` and the frame count are recomputed from the samples, so
    they are exact even when ``complete`` is false (the process died and ``meta.json`` holds the
    counts of up to ``meta_interval_s`` before)."""
    path: Path
    meta: dict
    seq: np.ndarray
    x: np.ndarray
    y: np.ndarray
    host_time_s: np.ndarray
    gaps: list[Gap] = field(default_factory=list)
    torn_bytes: int = 0
    events: list[dict] = field(default_factory=list)
    session_starts: list[int] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return bool(self.meta.get("complete"))

    @property
    def counts(self) -> dict:
        return self.meta["counts"]

    @property
    def n_samples(self) -> int:
        return int(self.seq.size)

    @property
    def raw_path(self) -> Path:
        return self.path / RAW_FILE

    def restarts_by_host_time(self) -> dict[int, str]:
        """Where the live decoder began a session by a host-time rule (raw offset: cause), for
        a replay, which has the bytes but not their arrival times, to decide the same."""
        return {s["raw_offset"]: s["cause"] for s in self.meta.get("sessions", [])
                if s["cause"] in HOST_TIME_CAUSES}

    def to_recording(self) -> Recording:
        """The two axes as a :class:`~snn_antenna.core.signals.Recording` in ADC counts. Gaps are
        not filled: their positions travel in ``meta['gaps']`` for any stage that must know."""
        return Recording(samples=np.column_stack([self.x, self.y]).astype(float),
                         rate_hz=float(self.meta["rate_hz"]), units="counts",
                         meta={"source": str(self.path), "port": self.meta.get("port"),
                               "gaps": [g._asdict() for g in self.gaps]})


RECORDING_ACCEPTED = ("a directory written by `snn-antenna record` "
                      "(meta.json, samples.bin, raw.bin)")
MAX_META_BYTES = 16 << 20               # a meta.json holds counts and link events: kilobytes
MAX_EVENTS_BYTES = 16 << 20
LINK_EVENTS = ("opened", "lost", "reconnected", "failed", "end")
CONTROL_FIELDS = ("th_g", "window_s", "speed_cm_s")


def _count(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _number(value) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


# meta.json: each field the toolkit reads, with its check and what it accepts.
META_FIELDS = {
    "format_version": (lambda v: v == FORMAT_VERSION and not isinstance(v, bool),
                       f"{FORMAT_VERSION} (this version of snn-antenna)"),
    "port": (lambda v: isinstance(v, str), "the port's name (text)"),
    "wire_format": (lambda v: v in WIRE_FORMATS, " or ".join(WIRE_FORMATS)),
    "baudrate": (lambda v: _count(v) and v > 0, "a baud rate (an integer > 0)"),
    "rate_hz": (lambda v: _number(v) and 0 < v <= 100_000, "samples per second in (0, 100000]"),
    "complete": (lambda v: isinstance(v, bool), "true or false"),
    "link_events": (lambda v: isinstance(v, list), "a list of link events"),
    "counts": (lambda v: isinstance(v, dict) and all(_count(c) for c in v.values()),
               "a table of counts (integers >= 0)"),
    "n_samples_written": (_count, "a number of samples (an integer >= 0)"),
    "raw_bytes_written": (_count, "a number of bytes (an integer >= 0)"),
}
META_OPTIONAL = {
    "sessions": (lambda v: isinstance(v, list), "a list of board sessions"),
    "samples_dtype": (lambda v: v == [[n, SAMPLE_DTYPE[n].str] for n in SAMPLE_DTYPE.names],
                      "the 16-byte sample record of this version of snn-antenna"),
    "speed_cm_s": (lambda v: v is None or _number(v), "a speed in cm/s, or null"),
    "network": (lambda v: v is None or isinstance(v, str), "a network's path, or null"),
    "set": (lambda v: v is None or (isinstance(v, list) and all(isinstance(i, str) for i in v)),
            "a list of KEY=VALUE texts"),
    "live": (lambda v: isinstance(v, dict) and isinstance(v.get("contacts", []), (list, int)),
             "a table of the live run's outcome, its contacts a list"),
}


def _refuse(file: Path, name: str, value, accepted: str) -> SpecError:
    return SpecError(f"{file} {name}".strip(), value, accepted)


def _regular_size(path: Path, required: bool = True) -> int | None:
    """The size of a regular file (None when it is absent and not ``required``): a fifo or a
    device would hang the reader, a folder cannot be read."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        if required:
            raise SpecError("recording", str(path.parent),
                            f"{RECORDING_ACCEPTED}; {path.name} is missing") from None
        return None
    except OSError as exc:
        raise _refuse(path, "", str(path), f"a readable file ({exc.strerror})") from None
    if not stat.S_ISREG(info.st_mode):
        raise _refuse(path, "", "not a regular file", "a regular file (not a folder, a fifo or a "
                                                      "device)")
    return info.st_size


def _read(path: Path, size: int, limit: int) -> bytes:
    if size > limit:
        raise _refuse(path, "size", f"{size} bytes", f"at most {limit} bytes")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise _refuse(path, "", str(path), f"a readable file ({exc.strerror})") from None


def read_meta(path) -> dict:
    """``meta.json`` of a recording, every field the toolkit reads checked."""
    meta_path = Path(path) / META_FILE
    blob = _read(meta_path, _regular_size(meta_path), MAX_META_BYTES)
    try:
        meta = json.loads(blob.decode("utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise _refuse(meta_path, "", f"{type(exc).__name__}: {str(exc)[:60]}",
                      "JSON text written by `snn-antenna record`: restore it, or rebuild it "
                      "from raw.bin") from None
    if not isinstance(meta, dict):
        raise _refuse(meta_path, "", meta, "a JSON table of the recording's settings")
    for name, (valid, accepted) in META_FIELDS.items():
        if name not in meta:
            raise _refuse(meta_path, name, "missing", accepted)
        if not valid(meta[name]):
            raise _refuse(meta_path, name, meta[name], accepted)
    for name, (valid, accepted) in META_OPTIONAL.items():
        if name in meta and not valid(meta[name]):
            raise _refuse(meta_path, name, meta[name], accepted)
    return meta


def _check_entries(meta_path: Path, meta: dict, n_samples: int, raw_size: int) -> None:
    """Link events and sessions point into the data files that are there."""
    for i, event in enumerate(meta["link_events"]):
        name = f"link_events[{i}]"
        if not isinstance(event, dict):
            raise _refuse(meta_path, name, event, "a table with event and raw_offset")
        if event.get("event") not in LINK_EVENTS:
            raise _refuse(meta_path, f"{name}.event", event.get("event"), ", ".join(LINK_EVENTS))
        offset = event.get("raw_offset")
        if not (_count(offset) and offset <= raw_size):
            raise _refuse(meta_path, f"{name}.raw_offset", offset,
                          f"an offset into raw.bin, 0..{raw_size}")
    causes = ("start",) + RESTART_CAUSES
    for i, session in enumerate(meta.get("sessions", [])):
        name = f"sessions[{i}]"
        if not isinstance(session, dict):
            raise _refuse(meta_path, name, session, "a table with index, raw_offset and cause")
        checks = (("index", lambda v: _count(v) and v <= n_samples,
                   f"a sample index 0..{n_samples}"),
                  ("raw_offset", lambda v: _count(v) and v <= raw_size,
                   f"an offset into raw.bin, 0..{raw_size}"),
                  ("cause", lambda v: v in causes, ", ".join(causes)),
                  ("first_seq", lambda v: v is None or (_count(v) and v < SEQ_MODULUS),
                   f"null or a sequence number 0..{SEQ_MODULUS - 1}"))
        for key, valid, accepted in checks:
            if not valid(session.get(key)):
                raise _refuse(meta_path, f"{name}.{key}", session.get(key), accepted)


def _check_size(path: Path, size: int, expected: int, meta_path: Path, name: str,
                complete: bool) -> None:
    """A complete recording's file holds what meta.json says; an incomplete one (the process
    died) at least that much: meta.json lags the data by up to ``meta_interval_s``."""
    if size == expected or (not complete and size > expected):
        return
    raise _refuse(meta_path, name, f"{expected} bytes, but {path.name} holds {size}",
                  f"the size of {path.name}" + ("" if complete else " or less (the recording "
                                                                     "is incomplete)"))


def read_events(path, n_samples: int | None = None) -> list[dict]:
    """The control changes a recording journaled (``events.jsonl``), each checked: a value a
    replay could not apply as the live run did is refused, never applied as something else. A
    torn last line (a killed process) is dropped."""
    events_path = Path(path) / EVENTS_FILE
    size = _regular_size(events_path, required=False)
    if size is None:
        return []
    text = _read(events_path, size, MAX_EVENTS_BYTES).decode("utf-8", errors="replace")
    lines = text.split("\n")
    events = []
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        where = f"line {number}"
        try:
            event = json.loads(line)
        except ValueError:
            if number == len(lines):        # no newline after it: torn by a kill
                break
            raise _refuse(events_path, where, line[:60], "a JSON table per line") from None
        if not isinstance(event, dict):
            raise _refuse(events_path, where, event, "a JSON table per line")
        sample = event.get("sample")
        if not (_count(sample) and (n_samples is None or sample <= n_samples)):
            raise _refuse(events_path, f"{where} sample", sample,
                          "a sample index" + ("" if n_samples is None else f" 0..{n_samples}"))
        if event.get("field") not in CONTROL_FIELDS:
            raise _refuse(events_path, f"{where} field", event.get("field"),
                          ", ".join(CONTROL_FIELDS))
        if not _number(event.get("value")):
            raise _refuse(events_path, f"{where} value", event.get("value"), "a finite number")
        events.append(event)
    return events


def load_recording(path) -> BridgeRecording:
    """Read a recording directory written by ``snn-antenna record`` (also after a crash),
    checking it first (see the module's docstring)."""
    path = Path(path)
    if not path.is_dir():
        raise SpecError("recording", str(path), RECORDING_ACCEPTED)
    meta = read_meta(path)
    meta_path = path / META_FILE
    samples_path, raw_path = path / SAMPLES_FILE, path / RAW_FILE
    samples_size, raw_size = _regular_size(samples_path), _regular_size(raw_path)
    complete = meta["complete"]
    _check_size(samples_path, samples_size - samples_size % SAMPLE_DTYPE.itemsize,
                meta["n_samples_written"] * SAMPLE_DTYPE.itemsize, meta_path,
                "n_samples_written × 16 bytes", complete)
    _check_size(raw_path, raw_size, meta["raw_bytes_written"], meta_path, "raw_bytes_written",
                complete)
    n_samples = samples_size // SAMPLE_DTYPE.itemsize
    _check_entries(meta_path, meta, n_samples, raw_size)
    blob = _read(samples_path, samples_size, 1 << 40)
    torn = len(blob) % SAMPLE_DTYPE.itemsize
    records = np.frombuffer(blob[:len(blob) - torn], dtype=SAMPLE_DTYPE)
    seq = records["seq"].astype(np.int64)
    starts = [int(i) for i in np.flatnonzero(records["flags"] & SESSION_START)]
    announced = {s["index"]: s.get("first_seq") for s in meta.get("sessions", [])}
    return BridgeRecording(path=path, meta=meta, seq=seq, x=records["x"].astype(np.int64),
                           y=records["y"].astype(np.int64),
                           host_time_s=records["host_time_s"].copy(),
                           gaps=find_gaps(seq, [(i, announced.get(i)) for i in starts]),
                           torn_bytes=torn, events=read_events(path, n_samples),
                           session_starts=starts)


def record_counts(path, counts: np.ndarray) -> Path:
    """Write ADC counts (samples × 2, e.g. a simulated scene's ``samples``) as a recording
    that ``snn-antenna replay`` and :func:`load_recording` read, as ``record`` would have
    written them from the board (binary frames, one batch), without a port."""
    counts = np.asarray(counts)
    if counts.ndim != 2 or counts.shape[1] != 2:
        raise SpecError("counts", f"shape {counts.shape}", "ADC counts of shape (samples, 2)")
    recorder = Recorder(path, port="test://", wire_format="binary", baudrate=DEFAULT_BAUDRATE)
    seq = np.arange(len(counts)) % 65536
    raw = b"".join(encode_binary(int(s), int(x), int(y)) for s, (x, y) in zip(seq, counts))
    samples = [Sample(int(s), int(x), int(y)) for s, (x, y) in zip(seq, counts)]
    recorder.handle(Batch(time.time(), raw, samples, {"frames": len(samples)}))
    recorder.close()
    return Path(path)
