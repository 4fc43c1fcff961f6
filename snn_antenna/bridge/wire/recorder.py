"""Recording a serial stream so that nothing received is lost, even to ``kill -9``.

A recording is a directory:

``raw.bin``      every byte received, append-only (replay decodes it again).
``samples.bin``  one fixed-size little-endian record per valid sample: ``seq u16, x u16, y u16,
                 pad u16, host_time_s f64`` (16 bytes). Appending whole records means a crash can
                 only tear the last one, which the reader drops.
``events.jsonl`` the live controls' changes (Th, the rate-map window), a JSON line each with the
                 sample index it applied at, written and flushed as it happens (bridge/controls.py
                 reads them back; ``replay`` applies them again).
``meta.json``    port, format, link events (opens, losses, reconnects, with their offset in
                 ``raw.bin``) and the counts; rewritten atomically (tmp + ``os.replace``) so it is
                 never half-written. ``complete`` is true only after a clean close.

Both data files are flushed to the OS every ``flush_interval_s`` (50 ms), which is what survives a
killed process, and fsynced every ``fsync_interval_s`` (1 s), which is what survives power loss.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ... import __version__ as package_version
from ...core.errors import SpecError
from ...core import outputs
from ...core.files import open_append, refuse_symlink, write_json
from ...core.signals import Recording
from .protocol import BOARD_RATE_HZ, Gap, find_gaps
from .source import DEFAULT_BAUDRATE, Batch

SAMPLE_DTYPE = np.dtype([("seq", "<u2"), ("x", "<u2"), ("y", "<u2"), ("pad", "<u2"),
                         ("host_time_s", "<f8")])
RAW_FILE, SAMPLES_FILE, META_FILE = "raw.bin", "samples.bin", "meta.json"
EVENTS_FILE = "events.jsonl"            # bridge/controls.py reads it
FORMAT_VERSION = 1
COUNT_FIELDS = ("frames", "crc_errors", "framing_errors", "range_errors", "gaps", "lost_samples",
                "duplicates", "reordered", "late", "seq_restarts", "reconnects")


class Recorder:
    """Writes :class:`~snn_antenna.bridge.wire.source.Batch` objects into a recording directory."""

    def __init__(self, out_dir, *, port: str, wire_format: str, baudrate: int,
                 rate_hz: float = BOARD_RATE_HZ, flush_interval_s: float = 0.05,
                 fsync_interval_s: float = 1.0, meta_interval_s: float = 0.5,
                 extra_meta: dict | None = None):
        self.dir = Path(out_dir)
        if os.path.lexists(self.dir / META_FILE):
            raise SpecError("out", str(self.dir),
                            "a new or empty directory (an existing recording is never overwritten)")
        if self.dir.exists() and not self.dir.is_dir():
            raise SpecError("out", str(self.dir), "a directory path")
        for name in (RAW_FILE, SAMPLES_FILE, EVENTS_FILE):  # a link would write elsewhere
            refuse_symlink(self.dir / name)
        self._folder = outputs.prepare(self.dir, "recording")  # one recorder per folder,
        outputs.claim(self._folder)                            # journaled until close
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
            "status": "recording", "message": "", "link_events": [], "counts": self.counts,
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

    def note_event(self, event: dict) -> None:
        """A control change applied by the pipeline (bridge/controls.py): one JSON line in
        ``events.jsonl``, flushed at once (it is rare, and replay needs every one)."""
        if self._events is None:
            self._events = open_append(self.dir / EVENTS_FILE)
        self._events.write(json.dumps(event) + "\n")
        self._events.flush()
        self.meta["control_events"] = self.meta.get("control_events", 0) + 1

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
        outputs.record(self._folder)

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

    def to_recording(self) -> Recording:
        """The two axes as a :class:`~snn_antenna.core.signals.Recording` in ADC counts. Gaps are not
        filled: their positions travel in ``meta['gaps']`` for any stage that must know."""
        return Recording(samples=np.column_stack([self.x, self.y]).astype(float),
                         rate_hz=float(self.meta["rate_hz"]), units="counts",
                         meta={"source": str(self.path), "port": self.meta.get("port"),
                               "gaps": [g._asdict() for g in self.gaps]})


def load_recording(path) -> BridgeRecording:
    """Read a recording directory written by ``snn-antenna record`` (also after a crash)."""
    path = Path(path)
    accepted = "a directory written by `snn-antenna record` (meta.json, samples.bin, raw.bin)"
    meta_path, samples_path = path / META_FILE, path / SAMPLES_FILE
    if not meta_path.is_file() or not samples_path.is_file():
        raise SpecError("recording", str(path), accepted)
    try:
        meta = json.loads(meta_path.read_text())
    except (ValueError, OSError) as exc:       # not JSON, not UTF-8, unreadable
        raise SpecError("recording", str(path), f"{accepted}; its meta.json is damaged "
                                                f"({type(exc).__name__}: {str(exc)[:80]}): "
                                                "restore it, or rebuild it from raw.bin") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("rate_hz"), (int, float)):
        raise SpecError("recording", str(path), f"{accepted}; its meta.json is damaged (no "
                                                "table with a rate_hz): restore it")
    if meta.get("format_version") != FORMAT_VERSION:
        raise SpecError("meta.json format_version", meta.get("format_version"),
                        f"{FORMAT_VERSION} (this version of snn-antenna)")
    blob = samples_path.read_bytes()
    torn = len(blob) % SAMPLE_DTYPE.itemsize
    records = np.frombuffer(blob[:len(blob) - torn], dtype=SAMPLE_DTYPE)
    seq = records["seq"].astype(np.int64)
    return BridgeRecording(path=path, meta=meta, seq=seq, x=records["x"].astype(np.int64),
                           y=records["y"].astype(np.int64),
                           host_time_s=records["host_time_s"].copy(),
                           gaps=find_gaps(seq), torn_bytes=torn)


def record_counts(path, counts: np.ndarray) -> Path:
    """Write ADC counts (samples × 2, e.g. a simulated scene's ``samples``) as a recording
    that ``snn-antenna replay`` and :func:`load_recording` read, as ``record`` would have
    written them from the board (binary frames, one batch), without a port."""
    from .protocol import Sample, encode_binary

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
