"""Replay a recording through the same decoder and handlers as a live port.

:class:`ReplaySource` reads ``raw.bin`` (every byte the port delivered) and offers the same
``start / get / stop / counts`` interface as :class:`~snn_antenna.bridge.wire.source.SerialSource`,
so :func:`~snn_antenna.bridge.wire.source.run_source` drives either. Decoding the raw bytes again,
with a
resync wherever the recorder saw the port (re)open, and a new board session wherever the live
decoder began one by the arrival times of the bytes (which a replay has not), must reproduce the
recorded samples, sessions and counts exactly: replay doubles as a check of a recording.
"""
from __future__ import annotations

import time
from pathlib import Path

from .protocol import Decoder
from .recorder import RAW_FILE, load_recording
from .source import Batch

RESYNC_EVENTS = ("opened", "reconnected")


class ReplaySource:
    def __init__(self, recording_dir, *, realtime: bool = False, chunk_bytes: int | None = None):
        self.recording = load_recording(recording_dir)
        meta = self.recording.meta
        self.url = str(Path(recording_dir) / RAW_FILE)
        self.rate_hz = float(meta["rate_hz"])
        self.realtime = realtime
        # Real time releases about 10 ms of frames at a time; flat out, big chunks.
        self.chunk_bytes = chunk_bytes or (100 if realtime else 1 << 16)
        self.decoder = Decoder(meta["wire_format"], rate_hz=self.rate_hz,
                               restarts_at=self.recording.restarts_by_host_time())
        self._sessions_told = 0
        self.reconnects = 0
        self.bytes_received = 0
        self._raw = b""
        self._resync_at = sorted({e["raw_offset"] for e in meta.get("link_events", [])
                                  if e["event"] in RESYNC_EVENTS and e["raw_offset"] > 0})
        self._reconnect_at = [e["raw_offset"] for e in meta.get("link_events", [])
                              if e["event"] == "reconnected"]
        self._pos = 0
        self._t0 = None
        self._ended = False

    def start(self) -> ReplaySource:
        self._raw = self.recording.raw_path.read_bytes()
        self._t0 = self.started_monotonic = time.monotonic()
        return self

    def pending(self) -> bool:
        return False                    # one chunk at a time keeps real-time pacing simple

    def stop(self) -> None:
        self._pos = len(self._raw)
        self._ended = True

    def counts(self) -> dict:
        stats = self.decoder.stats.as_dict()
        stats["reconnects"] = self.reconnects
        stats["bytes"] = self.bytes_received
        return stats

    def get(self, timeout: float | None = None) -> Batch | None:
        if self._pos >= len(self._raw):
            if self._ended:
                time.sleep(timeout or 0)
                return None
            held = self.decoder.flush()
            if held:                    # frames held behind a hole: the file has no more
                return self._batch(b"", held)
            self._ended = True
            self.reconnects = len(self._reconnect_at)
            return Batch(time.time(), counts=self.counts(), event="end")
        if self._pos in self._resync_at:
            held = self.decoder.flush()     # as the live source did when the link went down
            if held:
                return self._batch(b"", held)
            self.decoder.resync()
        self.reconnects = sum(1 for o in self._reconnect_at if o <= self._pos)
        end = min(len(self._raw), self._pos + self.chunk_bytes,
                  *(o for o in self._resync_at if o > self._pos))
        chunk = self._raw[self._pos:end]
        self._pos = end
        self.bytes_received += len(chunk)
        samples = self.decoder.feed(chunk)
        if self.realtime:
            stats = self.decoder.stats
            due = self._t0 + (stats.frames + stats.lost_samples) / self.rate_hz
            time.sleep(max(0.0, due - time.monotonic()))
        return self._batch(chunk, samples)

    def _batch(self, raw: bytes, samples) -> Batch:
        sessions = self.decoder.sessions[self._sessions_told:]
        self._sessions_told = len(self.decoder.sessions)
        return Batch(time.time(), raw, samples, self.counts(), sessions=sessions)


def live_comparison(meta: dict, network, explicit_set=(), speed_cm_s=None) -> dict:
    """A replay with a network, against the live run it replays (``meta``, as ``stream`` wrote
    it): the settings that differ (another network, a ``--set`` that changes a key's recorded
    value, another speed command), each as ``"KEY: LIVE -> REPLAY"``, and the live run's
    contacts, to show beside the replay's own."""
    differ = []
    recorded_network = meta.get("network")
    if recorded_network and Path(recorded_network).resolve() != Path(network).resolve():
        differ.append(f"network: {recorded_network} -> {network}")
    recorded = dict(_key_value(item) for item in meta.get("set") or [])
    for item in explicit_set:
        key, value = _key_value(item)
        if recorded.get(key) != value:
            differ.append(f"{key}: {recorded.get(key, 'the network file')} -> {value}")
    live_speed = meta.get("speed_cm_s")
    if speed_cm_s is not None and speed_cm_s != live_speed:
        differ.append(f"speed_cm_s: {live_speed} -> {speed_cm_s:g}")
    return {"settings_differ": differ, "contacts": (meta.get("live") or {}).get("contacts")}


def _key_value(item: str) -> tuple[str, str]:
    key, _, value = str(item).partition("=")
    return key.strip(), value.strip()
