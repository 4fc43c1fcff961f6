"""The recordings of an import, each read whole and checked: samples, rate, ADC, raw-file hashes.

A recordings folder holds any mix of (its entries' names are how the labels table refers to
them; names starting with a dot are skipped):

- a folder written by ``snn-antenna record`` (``meta.json``, ``samples.bin``, ``raw.bin``): the
  board's ADC counts, its rate from ``meta.json``; each sample's time is the board's own clock,
  its sequence number (unwrapped) over the rate, so a lost stretch keeps every later sample at
  its instant, and the lost samples are known;
- ``NAME.csv``: a header naming ``x`` and ``y`` (ADC counts) and optionally ``t_s`` (seconds;
  the rate is then its sample spacing);
- ``NAME.npy``: an integer array (samples, 2) of ADC counts; ``NAME.npz``: ``counts`` the same and
  optionally ``rate_hz``;
- ``NAME.wav``: two channels of integer PCM (the rate in its header), read as ADC counts of the
  sample width (16-bit PCM: counts 0-65535, mid-scale at rest);
- a ROS 2 bag (a folder with ``metadata.yaml``): the x and y linear acceleration of one
  ``sensor_msgs/msg/Imu`` topic (m/s², stamped), read with the ``rosbags`` package and converted
  to 16-bit counts over ``full_scale_g``.

A rate given on the command line must agree with every rate a recording states (within 0.1 %);
a recording without one needs it. Every refusal names the file, the row and the field.
"""
from __future__ import annotations

import csv
import hashlib
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core import bounds
from ..bridge.wire.protocol import BOARD_ADC_BITS, BOARD_FULL_SCALE_G, SEQ_MODULUS
from ..bridge.wire.recorder import (EVENTS_FILE, META_FILE, RAW_FILE, SAMPLES_FILE, SAMPLE_DTYPE,
                                    load_recording)
from ..core.errors import SpecError
from ..sources.antenna import ADC

FILE_KINDS = {".csv": "csv", ".npy": "npy", ".npz": "npz", ".wav": "wav"}
RATE_TOLERANCE = 1e-3
STANDARD_GRAVITY = 9.80665
IMU_ADC_BITS = 16
ACCEPTED_ENTRY = ("a folder written by `snn-antenna record`, a ROS 2 bag folder (metadata.yaml), "
                  "or a .csv, .npy, .npz or .wav file")


@dataclass
class Options:
    """What the command line says about the recordings."""
    rate_hz: float | None = None
    adc_bits: int = BOARD_ADC_BITS
    full_scale_g: float = BOARD_FULL_SCALE_G
    topic: str | None = None            # ROS 2 bags: the Imu topic (default: the only one)

    def __post_init__(self):
        bounds.declared(self)
        if self.rate_hz is not None:
            bounds.rate_hz("rate_hz", self.rate_hz)
        bounds.integer("adc_bits", self.adc_bits, 4, 24)
        bounds.number("full_scale_g", self.full_scale_g, 0.0, bounds.MAX_AMPLITUDE, lo_open=True)


@dataclass
class Stream:
    """One recording, read: ``counts`` (samples, 2) at the board's instants ``frames``
    (sample index on the recording's own clock; missing indexes are lost samples)."""
    name: str
    kind: str
    counts: np.ndarray
    frames: np.ndarray
    rate_hz: float
    adc_bits: int
    full_scale_g: float
    files: list[dict] = field(default_factory=list)     # {"file", "sha256", "bytes"}
    notes: dict = field(default_factory=dict)           # the recording's own counters
    speed_log: list[tuple[int, float]] = field(default_factory=list)   # (frame, cm/s) changes

    @property
    def duration_s(self) -> float:
        return (int(self.frames[-1]) + 1) / self.rate_hz if len(self.frames) else 0.0

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind, "samples": int(len(self.counts)),
                "rate_hz": self.rate_hz, "adc_bits": self.adc_bits,
                "full_scale_g": self.full_scale_g, "duration_s": self.duration_s,
                "files": self.files, **self.notes}


def sha256_of(path: Path) -> dict:
    h, size = hashlib.sha256(), 0
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
            size += len(block)
    return {"sha256": h.hexdigest(), "bytes": size}


def recording_entries(folder) -> list[Path]:
    """The recordings in ``folder`` (or ``folder`` itself, a single ``record`` folder or bag)."""
    folder = Path(folder)
    if not folder.exists():
        raise SpecError("recordings", str(folder), "an existing folder of recordings")
    if folder.is_file() or _kind(folder) in ("record", "rosbag"):
        return [folder]
    entries = sorted(p for p in folder.iterdir() if not p.name.startswith("."))
    if not entries:
        raise SpecError("recordings", str(folder), f"a folder holding recordings ({ACCEPTED_ENTRY}"
                                                   "); this one is empty")
    for p in entries:
        if _kind(p) is None:
            raise SpecError("recordings", str(p), ACCEPTED_ENTRY)
    return entries


def _kind(path: Path) -> str | None:
    if path.is_dir():
        if (path / META_FILE).is_file():
            return "record"
        if (path / "metadata.yaml").is_file():
            return "rosbag"
        return None
    return FILE_KINDS.get(path.suffix.lower()) if path.is_file() else None


def read_stream(path: Path, options: Options) -> Stream:
    """Read and check one recording (see the module docstring)."""
    kind = _kind(path)
    stream = {"record": _read_record, "csv": _read_csv, "npy": _read_npy, "npz": _read_npy,
              "wav": _read_wav, "rosbag": _read_rosbag}[kind](path, options)
    if len(stream.counts) < 2:
        raise SpecError(f"{path.name}", f"{len(stream.counts)} sample(s)",
                        "a recording of at least two samples")
    levels = 2 ** stream.adc_bits
    bad = np.flatnonzero((stream.counts < 0) | (stream.counts >= levels))
    if len(bad):
        row, axis = divmod(int(bad[0]), 2)
        raise SpecError(f"{path.name} sample {row} {'xy'[axis]}", int(stream.counts[row, axis]),
                        f"ADC counts in [0, {levels - 1}] ({stream.adc_bits}-bit; set "
                        "--adc-bits and --full-scale-g to the sensor's ADC)")
    return stream


def _rate(path: Path, stated: float | None, options: Options, where: str) -> float:
    """The recording's rate: the one it states, which the command line's must match."""
    given = options.rate_hz
    if stated is None:
        if given is None:
            raise SpecError("--rate", None, f"the sample rate in Hz of {path.name}, which does "
                                             "not state one")
        return float(given)
    if not (np.isfinite(stated) and stated > 0):
        raise SpecError(f"{path.name} {where}", stated, "a sample rate > 0 Hz")
    if given is not None and abs(given - stated) > RATE_TOLERANCE * stated:
        raise SpecError("--rate", given, f"the rate {path.name} states in its {where} "
                                         f"({stated:g} Hz): drop --rate or correct it")
    return float(stated)


def _files(path: Path, names=None) -> list[dict]:
    paths = [path] if path.is_file() else [path / n for n in (names or sorted(
        p.name for p in path.iterdir() if p.is_file()))]
    return [{"file": p.name if path.is_dir() else path.name, **sha256_of(p)}
            for p in paths if p.is_file()]


def _read_record(path: Path, options: Options) -> Stream:
    rec = load_recording(path)
    if rec.torn_bytes:
        raise SpecError(f"{path.name}/{SAMPLES_FILE}", f"{rec.torn_bytes} byte(s) after sample "
                                                       f"{rec.n_samples}",
                        f"whole {SAMPLE_DTYPE.itemsize}-byte samples: the file is truncated "
                        f"(a recording cut off mid-sample); `snn-antenna replay` rebuilds the "
                        f"samples from {RAW_FILE}")
    written = rec.meta.get("n_samples_written")
    if rec.complete and isinstance(written, int) and written != rec.n_samples:
        raise SpecError(f"{path.name}/{SAMPLES_FILE}", f"{rec.n_samples} samples",
                        f"the {written} its {META_FILE} counts: the file is truncated or "
                        "was changed")
    rate = _rate(path, float(rec.meta["rate_hz"]), options, f"{META_FILE} rate_hz")
    steps = (np.diff(rec.seq) - 1) % SEQ_MODULUS + 1
    frames = int(rec.seq[0]) + np.concatenate([[0], np.cumsum(steps)]) if rec.n_samples \
        else np.zeros(0, int)
    counts = np.column_stack([rec.x, rec.y])
    names = [n for n in (META_FILE, SAMPLES_FILE, RAW_FILE, EVENTS_FILE) if (path / n).is_file()]
    notes = {"gaps": len(rec.gaps), "lost_samples": int(sum(g.length for g in rec.gaps)),
             "complete": rec.complete, "counters": dict(rec.counts)}
    return Stream(path.name, "record", counts, frames, rate, BOARD_ADC_BITS, BOARD_FULL_SCALE_G,
                  _files(path, names), notes, _speed_log(path, rec.meta, frames))


def _speed_log(path: Path, meta: dict, frames: np.ndarray) -> list[tuple[int, float]]:
    """The speed command a drive was recorded at: where it started (``meta.json``) and each
    change the live controls applied (``events.jsonl``, at the sample it applied from)."""
    from ..bridge.online.controls import recorded_events

    log = []
    if isinstance(meta.get("speed_cm_s"), (int, float)):
        log.append((int(frames[0]) if len(frames) else 0, float(meta["speed_cm_s"])))
    for event in recorded_events(path):
        if event["field"] == "speed_cm_s" and len(frames):
            index = min(max(int(event["sample"]), 0), len(frames) - 1)
            log.append((int(frames[index]), float(event["value"])))
    return log


def _plain(path: Path, counts: np.ndarray, rate: float, options: Options, kind: str,
           adc_bits: int | None = None) -> Stream:
    return Stream(path.name, kind, counts, np.arange(len(counts)), rate,
                  adc_bits or options.adc_bits, options.full_scale_g, _files(path))


def _counts_array(path: Path, array, where: str) -> np.ndarray:
    array = np.asarray(array)
    if array.ndim != 2 or array.shape[1] != 2:
        raise SpecError(f"{path.name} {where}", f"shape {array.shape}",
                        "ADC counts of shape (samples, 2): the x and y axes")
    if array.dtype.kind not in "iu":
        raise SpecError(f"{path.name} {where}", f"dtype {array.dtype}",
                        "integer ADC counts (convert readings in g with the ADC's range)")
    return array.astype(np.int64)


def _read_npy(path: Path, options: Options) -> Stream:
    try:
        loaded = np.load(path, allow_pickle=False)
        if isinstance(loaded, np.ndarray):
            array, stated = loaded, None
        else:
            with loaded:
                if "counts" not in loaded.files:
                    raise SpecError(f"{path.name}", sorted(loaded.files),
                                    "an .npz holding 'counts' (samples, 2) and optionally "
                                    "'rate_hz'")
                array = loaded["counts"]
                stated = float(loaded["rate_hz"]) if "rate_hz" in loaded.files else None
    except SpecError:
        raise
    except Exception as exc:            # numpy's parser: value, EOF, zip and pickle errors
        raise SpecError(path.name, f"{type(exc).__name__}: {exc}",
                        "a whole NumPy file: it is truncated or damaged") from None
    counts = _counts_array(path, array, "counts")
    return _plain(path, counts, _rate(path, stated, options, "rate_hz"), options, path.suffix[1:])


def _read_csv(path: Path, options: Options) -> Stream:
    try:
        text = path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError) as exc:
        raise SpecError(path.name, type(exc).__name__, "a UTF-8 text CSV file") from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise SpecError(path.name, "an empty file", "a CSV with a header naming x, y "
                                                    "(and optionally t_s)")
    header = [h.strip() for h in rows[0]]
    known = {"t_s", "x", "y"}
    for column in header:
        if column not in known:
            raise SpecError(f"{path.name} line 1", column, "a header of the columns x, y "
                                                           "(ADC counts) and optionally t_s")
    if not {"x", "y"} <= set(header) or len(set(header)) != len(header):
        raise SpecError(f"{path.name} line 1", ",".join(header),
                        "a header naming x and y once each (and optionally t_s)")
    columns = {name: [] for name in header}
    for line, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise SpecError(f"{path.name} line {line}", ",".join(row),
                            f"{len(header)} fields ({','.join(header)}): the file is "
                            "truncated or damaged")
        for name, value in zip(header, row):
            try:
                number = float(value) if name == "t_s" else int(value)
            except ValueError:
                raise SpecError(f"{path.name} line {line} {name}", value,
                                "seconds" if name == "t_s" else "an integer ADC count") from None
            if name == "t_s" and not np.isfinite(number):
                raise SpecError(f"{path.name} line {line} {name}", value, "a finite time in s")
            columns[name].append(number)
    counts = np.column_stack([columns["x"], columns["y"]]).astype(np.int64) \
        if columns["x"] else np.zeros((0, 2), np.int64)
    stated = None
    if "t_s" in columns and len(columns["t_s"]) >= 2:
        t = np.asarray(columns["t_s"])
        dt = np.diff(t)
        step = float(np.median(dt))
        uneven = np.flatnonzero(np.abs(dt - step) > 0.5 * step)
        if step <= 0 or len(uneven):
            line = int(uneven[0]) + 3 if len(uneven) else 3
            raise SpecError(f"{path.name} line {line} t_s", columns["t_s"][line - 2],
                            f"evenly spaced, increasing times (every {step:g} s)")
        stated = _rate_of(step)
    return _plain(path, counts, _rate(path, stated, options, "t_s column"), options, "csv")


def _rate_of(step_s: float) -> float:
    """The rate a sample spacing states, to the six digits a written time carries."""
    return float(f"{1.0 / step_s:.6g}") if step_s > 0 else float("nan")


def _read_wav(path: Path, options: Options) -> Stream:
    import warnings

    from scipy.io import wavfile

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")          # a short data chunk is a truncated file
            rate, data = wavfile.read(path)
    except Exception as exc:            # scipy's parser: struct, value, EOF errors, warnings
        raise SpecError(path.name, f"{type(exc).__name__}: {exc}",
                        "a whole WAV file: it is truncated or damaged") from None
    if data.ndim != 2 or data.shape[1] != 2:
        raise SpecError(f"{path.name} channels", data.shape[1] if data.ndim == 2 else 1,
                        "2 channels: the x and y axes")
    if data.dtype.kind not in "iu":
        raise SpecError(f"{path.name} format", str(data.dtype), "integer PCM (8, 16 or 32 bit)")
    bits = data.dtype.itemsize * 8
    counts = data.astype(np.int64) + (2 ** (bits - 1) if data.dtype.kind == "i" else 0)
    stream = _plain(path, counts, _rate(path, float(rate), options, "header"), options, "wav",
                    adc_bits=min(bits, 24))
    if bits > 24:
        stream.counts >>= bits - 24
    return stream


def _read_rosbag(path: Path, options: Options) -> Stream:
    from rosbags.highlevel import AnyReader
    imu = "sensor_msgs/msg/Imu"
    stamps, xy = [], []
    try:
        with AnyReader([path]) as reader:
            topics = [c for c in reader.connections if c.msgtype == imu]
            names = sorted({c.topic for c in topics})
            wanted = options.topic or (names[0] if len(names) == 1 else None)
            if wanted is None or wanted not in names:
                raise SpecError("--topic", options.topic,
                                f"one {imu} topic of {path.name}: {names or 'it has none'}")
            for connection, _, raw in reader.messages(
                    connections=[c for c in topics if c.topic == wanted]):
                msg = reader.deserialize(raw, connection.msgtype)
                stamps.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
                xy.append((msg.linear_acceleration.x, msg.linear_acceleration.y))
    except SpecError:
        raise
    except Exception as exc:               # rosbags' own errors: a damaged or foreign bag
        raise SpecError(path.name, f"{type(exc).__name__}: {exc}",
                        "a whole ROS 2 bag with an Imu topic") from None
    t = np.asarray(stamps)
    if len(t) < 2:
        raise SpecError(f"{path.name} {wanted}", f"{len(t)} message(s)",
                        "an Imu topic with at least two messages")
    stated = _rate_of(float(np.median(np.diff(t))))
    rate = _rate(path, stated, options, f"{wanted} header stamps")
    frames = np.round((t - t[0]) * rate).astype(np.int64)
    if np.any(np.diff(frames) < 1):
        row = int(np.flatnonzero(np.diff(frames) < 1)[0]) + 1
        raise SpecError(f"{path.name} {wanted} message {row} header.stamp", float(t[row]),
                        "increasing stamps, one sample period apart or a whole number of "
                        "periods (lost messages)")
    g = np.asarray(xy, dtype=float) / STANDARD_GRAVITY
    counts = ADC(IMU_ADC_BITS, options.full_scale_g).to_counts(g).astype(np.int64)
    lost = int(frames[-1] + 1 - len(frames))
    return Stream(path.name, "rosbag", counts, frames, rate, IMU_ADC_BITS, options.full_scale_g,
                  _files(path), {"topic": wanted, "lost_samples": lost,
                                 "gaps": int(np.sum(np.diff(frames) > 1))})
