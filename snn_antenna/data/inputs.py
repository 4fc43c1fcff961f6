"""The recordings of an import, each read and checked: samples, clock, rate, ADC, raw-file hashes.

A recordings folder holds any mix of (its entries' names are how the labels table refers to
them, with or without a file's extension; names starting with a dot are skipped):

- a folder written by ``snn-antenna record`` (``meta.json``, ``samples.bin``, ``raw.bin``): the
  board's 10-bit ADC counts, its rate from ``meta.json``; each sample's time is the board's own
  clock, its sequence number (unwrapped) over the rate, so a lost stretch keeps every later
  sample at its instant, and the lost samples are known;
- ``NAME.csv``: a header naming the axes ``x``, ``y`` (and ``z``) and optionally the time ``t_s``
  (seconds on the recording's clock: the first row's time is the recording's origin, its
  spacing its rate); other names are mapped with ``columns``. Spreadsheet files are read as
  written: a byte-order mark, ``;`` or tab between fields and decimal commas (the dialect is
  ``csv.Sniffer``'s);
- ``NAME.npy``: an array (samples, 2 or 3); ``NAME.npz``: the same as ``counts`` (or, for
  ``units`` g or m/s², ``acceleration``), optionally ``rate_hz`` and ``start_s`` (the clock's
  reading at the first sample);
- ``NAME.wav``: two or three channels of PCM, the rate in its header: integer PCM as ADC counts
  (an ADC narrower than the container, ``adc_bits``, left- or right-justified), float PCM as a
  fraction of ``full_scale_g``;
- a ROS 2 bag (a folder with ``metadata.yaml``, sqlite3 or MCAP storage): the linear
  acceleration of one ``sensor_msgs/msg/Imu`` topic (m/s²), each message at its header stamp in
  integer nanoseconds, read with the ``rosbags`` package.

Every recording keeps its own clock: ``origin_s`` is the clock's reading at frame 0 (a CSV's
first ``t_s``, a bag's first stamp, an ``.npz``'s ``start_s``; 0 for a ``record`` folder, whose
frames are the board's sequence numbers). Stamped samples (``t_s``, bag stamps) are placed on
frames by their median step: a stamp off its frame by less than half a period is jitter, a
step of several periods is a gap of lost samples, and the rate is the least-squares slope of the
stamps over the frames.

What the samples are is declared, not assumed: ``units`` (ADC counts, g, m/s²), ``adc_bits`` and
``full_scale_g`` (the counts' ADC, or the ADC the accelerations are quantised to), ``signed``
(two's-complement counts, 0 at rest) and ``axes`` (which two of three axes carry the
antenna's plane). An option a format cannot honour is refused, never ignored. Files are read in
chunks of ``CHUNK_ROWS`` rows, so memory follows the samples kept, not the text.

A rate given on the command line must agree with every rate a recording states (within 0.1 %);
a recording without one needs it. Every refusal names the file, the row and the field.
"""
from __future__ import annotations

import csv
import hashlib
import itertools
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core import bounds
from ..bridge.wire.protocol import BOARD_ADC_BITS, BOARD_FULL_SCALE_G, SEQ_MODULUS
from ..bridge.wire.recorder import (EVENTS_FILE, META_FILE, RAW_FILE, SAMPLES_FILE, SAMPLE_DTYPE,
                                    load_recording)
from ..core.errors import SpecError
from ..sources.antenna import ADC
from ..bridge.online.controls import recorded_events

FILE_KINDS = {".csv": "csv", ".npy": "npy", ".npz": "npz", ".wav": "wav"}
RATE_TOLERANCE = 1e-3
STANDARD_GRAVITY = 9.80665
ACCELERATION_ADC_BITS = 16      # counts that accelerations (g, m/s², float PCM) are quantised to
UNITS = ("counts", "g", "m/s2")
AXES = "xyz"
TIME_COLUMN = "t_s"
CHUNK_ROWS = 1 << 16
SNIFF_BYTES = 1 << 16
ACCEPTED_ENTRY = ("a folder written by `snn-antenna record`, a ROS 2 bag folder (metadata.yaml), "
                  "or a .csv, .npy, .npz or .wav file")


@dataclass
class Options:
    """What the command line says about the recordings (None: the format's own)."""
    rate_hz: float | None = None
    adc_bits: int | None = None         # the counts' ADC; None: the board's, a WAV's container
    full_scale_g: float | None = None   # the sensor's range ± g; None: the board's
    topic: str | None = None            # ROS 2 bags: the Imu topic (default: the only one)
    units: str | None = None            # CSV and NumPy values: counts (default), g or m/s2
    signed: bool = False                # counts in two's complement, 0 at rest
    axes: str = "xy"                    # the two axes of the antenna's plane, of x, y, z
    columns: dict = field(default_factory=dict)    # a CSV's column name of t_s, x, y, z

    def __post_init__(self):
        bounds.declared(self)
        if self.rate_hz is not None:
            bounds.rate_hz("rate_hz", self.rate_hz)
        if self.adc_bits is not None:
            bounds.integer("adc_bits", self.adc_bits, 4, 24)
        if self.full_scale_g is not None:
            bounds.number("full_scale_g", self.full_scale_g, 0.0, bounds.MAX_AMPLITUDE,
                          lo_open=True)


@dataclass
class Stream:
    """One recording, read: ``counts`` (samples, 2) at the frames ``frames`` (sample index on
    the recording's own clock; missing indexes are lost samples), frame 0 at ``origin_s`` on
    that clock."""
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
    origin_s: float = 0.0

    @property
    def duration_s(self) -> float:
        return (int(self.frames[-1]) + 1) / self.rate_hz if len(self.frames) else 0.0

    @property
    def span_s(self) -> tuple[float, float]:
        """[start, end) of the recording on its own clock, as its labels give times."""
        return self.origin_s, self.origin_s + self.duration_s

    def time_of(self, frames):
        """The recording's clock at ``frames``."""
        return self.origin_s + np.asarray(frames) / self.rate_hz

    def frame_at(self, t_s: float) -> float:
        return (t_s - self.origin_s) * self.rate_hz

    def aliases(self) -> list[str]:
        """Names a labels table may give it: its entry's name and, for a file, its stem."""
        stem = Path(self.name).stem
        return [self.name] + ([stem] if self.kind in FILE_KINDS.values() and stem else [])

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind, "samples": int(len(self.counts)),
                "rate_hz": self.rate_hz, "adc_bits": self.adc_bits,
                "full_scale_g": self.full_scale_g, "duration_s": self.duration_s,
                "origin_s": self.origin_s, "files": self.files, **self.notes}


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


def check_options(options: Options) -> None:
    """The declarations themselves, before any file is read."""
    if options.units is not None and options.units not in UNITS:
        raise SpecError("--units", options.units, f"one of {', '.join(UNITS)}")
    axes = options.axes
    if not (isinstance(axes, str) and len(axes) == 2 and set(axes) <= set(AXES)
            and axes[0] != axes[1]):
        raise SpecError("--axes", axes, "two different axes of x, y, z (e.g. xy, xz, yz): "
                                        "the antenna's plane")
    for name, column in options.columns.items():
        if name not in (TIME_COLUMN, *AXES):
            raise SpecError("--columns", f"{name}={column}",
                            f"NAME=COLUMN pairs whose NAME is one of {TIME_COLUMN}, x, y, z")
    if options.signed and options.units not in (None, "counts"):
        raise SpecError("--signed", True, "counts (--units counts): accelerations have no sign "
                                          "convention to declare")


def parse_columns(text: str) -> dict:
    """``--columns t_s=time,x=ax,y=ay``: the file's column name of each of t_s, x, y, z."""
    out = {}
    for pair in filter(None, (p.strip() for p in text.split(","))):
        name, sep, column = (s.strip() for s in pair.partition("="))
        if not sep or not column or name in out:
            raise SpecError("--columns", text, "NAME=COLUMN pairs, each NAME once, separated by "
                                               "commas (e.g. t_s=time,x=ax,y=ay)")
        out[name] = column
    return out


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
                        f"ADC counts in [0, {levels - 1}] ({stream.adc_bits}-bit unsigned; set "
                        "--adc-bits, --signed and --full-scale-g to the sensor's ADC)")
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
        p.name for p in path.rglob("*") if p.is_file()))]
    return [{"file": p.relative_to(path).as_posix() if path.is_dir() else path.name,
             **sha256_of(p)} for p in paths if p.is_file()]


def _refuse(path: Path, options: Options, what: str, **fixed) -> None:
    """Refuse each option the format of ``path`` fixes (``fixed``: option → the one value it
    can have) when the command line declared another."""
    defaults = Options()
    for name, value in fixed.items():
        given = getattr(options, name)
        if given != getattr(defaults, name) and given != value:
            raise SpecError("--" + name.replace("_", "-"), given,
                            f"{value if value not in (None, {}) else 'nothing'} for "
                            f"{path.name}: {what}")


# -- clocks ------------------------------------------------------------------------------------
def stamp_frames(where: str, ns: np.ndarray) -> tuple[np.ndarray, float, dict]:
    """Frames of samples stamped at ``ns`` (integer nanoseconds from the first stamp): each
    step is a whole number of periods of the median step (a stamp off by less than half a
    period is jitter; several periods are lost samples), and the rate is the least-squares
    slope of the stamps over those frames. Returns (frames, rate in Hz, clock notes). Worked
    through in blocks of ``CHUNK_ROWS``: memory beyond the frames is one block's."""
    ns = np.asarray(ns, dtype=np.int64)
    n = len(ns)
    blocks = range(0, n, CHUNK_ROWS)
    step = float(np.median(np.diff(ns)))
    frames = np.empty(n, dtype=np.int64)
    frames[0], gaps, lost = 0, 0, 0
    for lo in blocks:
        hi = min(n, lo + CHUNK_ROWS + 1)
        steps = np.diff(ns[lo:hi])
        bad = np.flatnonzero(steps <= 0)
        if len(bad):
            row = lo + int(bad[0]) + 1
            raise SpecError(f"{where} sample {row}", f"{int(steps[bad[0]])} ns after the "
                                                     "previous one", "increasing stamps")
        periods = np.rint(steps / step).astype(np.int64)
        bad = np.flatnonzero(periods < 1)
        if len(bad):
            row = lo + int(bad[0]) + 1
            raise SpecError(f"{where} sample {row}", f"{int(steps[bad[0]])} ns after the "
                                                     "previous one",
                            f"a step of about one sample period ({step:g} ns, the median) or "
                            "whole periods (lost samples): the stamps jitter by more than "
                            "half a period")
        gaps += int(np.sum(periods > 1))
        lost += int(np.sum(periods[periods > 1] - 1))
        frames[lo + 1:hi] = frames[lo] + np.cumsum(periods)
    t_mean = sum(float(ns[lo:lo + CHUNK_ROWS].astype(np.float64).sum()) for lo in blocks) / n
    f_mean = sum(float(frames[lo:lo + CHUNK_ROWS].sum()) for lo in blocks) / n
    sxy = sxx = 0.0
    for lo in blocks:
        df = frames[lo:lo + CHUNK_ROWS] - f_mean
        sxy += float(np.dot(df, ns[lo:lo + CHUNK_ROWS] - t_mean))
        sxx += float(np.dot(df, df))
    slope = sxy / sxx
    worst, worst_row, square = 0.0, 0, 0.0
    for lo in blocks:
        residual = ns[lo:lo + CHUNK_ROWS] - (t_mean + slope * (frames[lo:lo + CHUNK_ROWS]
                                                               - f_mean))
        k = int(np.argmax(np.abs(residual)))
        if abs(residual[k]) > abs(worst):
            worst, worst_row = float(residual[k]), lo + k
        square += float(np.dot(residual, residual))
    if abs(worst) >= 0.5 * slope:
        raise SpecError(f"{where} sample {worst_row}", f"{worst / 1e3:+.1f} µs off the "
                                                       "recording's steady clock",
                        f"stamps within half a period ({slope / 2e3:.1f} µs) of a steady "
                        "clock: the sample clock drifts against the stamps' clock, or the "
                        "stamps jitter too much")
    notes = {"gaps": gaps, "lost_samples": lost,
             "stamp_jitter_us": round((square / n) ** 0.5 / 1e3, 3),
             "stamp_jitter_max_us": round(abs(worst) / 1e3, 3)}
    return frames, 1e9 / slope, notes


def _rate_of(rate: float, digits: int = 6) -> float:
    """A rate to the digits its stamps carry."""
    return float(f"{rate:.{digits}g}")


# -- units -------------------------------------------------------------------------------------
def _adc(options: Options, default_bits: int) -> ADC:
    bits = options.adc_bits if options.adc_bits is not None else default_bits
    full = options.full_scale_g if options.full_scale_g is not None else BOARD_FULL_SCALE_G
    return ADC(int(bits), float(full))


def _to_counts(where: str, values: np.ndarray, units: str, adc: ADC, signed: bool,
               row_name=lambda row: f"sample {row}") -> np.ndarray:
    """(rows, 2) values in ``units`` → unsigned ADC counts of ``adc`` (int32); a bad value
    names its row (``row_name``) and axis."""
    good = np.isfinite(values)
    if units == "counts":
        good &= values == np.round(values)
    if not good.all():
        row, axis = divmod(int(np.flatnonzero(~good.ravel())[0]), 2)
        raise SpecError(f"{where} {row_name(row)} axis {axis}", float(values[row, axis]),
                        "an integer ADC count (or declare --units g or m/s2)"
                        if units == "counts" else f"a finite acceleration in {units}")
    if units == "counts":
        counts = values.astype(np.int64) + (2 ** (adc.bits - 1) if signed else 0)
        return counts.astype(np.int32)
    g = values / STANDARD_GRAVITY if units == "m/s2" else values
    return adc.to_counts(g)


def _axes_of(where: str, n_axes: int, options: Options) -> list[int]:
    """Column indexes of the two declared axes among ``n_axes`` (2: x, y; 3: x, y, z)."""
    if n_axes not in (2, 3):
        raise SpecError(where, f"{n_axes} axes", "2 (x, y) or 3 (x, y, z) axes")
    if n_axes == 2 and "z" in options.axes:
        raise SpecError("--axes", options.axes, f"axes of {where}, which holds x and y only")
    return [AXES.index(a) for a in options.axes]


def _unit_notes(units: str, options: Options, extra: dict | None = None) -> dict:
    return {"units": units, "axes": options.axes, "signed": bool(options.signed),
            **(extra or {})}


# -- readers -----------------------------------------------------------------------------------
def _read_record(path: Path, options: Options) -> Stream:
    _refuse(path, options, "a `record` folder holds the board's counts",
            adc_bits=BOARD_ADC_BITS, full_scale_g=BOARD_FULL_SCALE_G, units="counts",
            signed=False, axes="xy", columns={})
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
    counts = np.column_stack([rec.x, rec.y]).astype(np.int32)
    names = [n for n in (META_FILE, SAMPLES_FILE, RAW_FILE, EVENTS_FILE) if (path / n).is_file()]
    notes = {"gaps": len(rec.gaps), "lost_samples": int(sum(g.length for g in rec.gaps)),
             "complete": rec.complete, "counters": dict(rec.counts),
             "units": "counts", "axes": "xy", "signed": False}
    return Stream(path.name, "record", counts, frames, rate, BOARD_ADC_BITS, BOARD_FULL_SCALE_G,
                  _files(path, names), notes, _speed_log(path, rec.meta, frames))


def _speed_log(path: Path, meta: dict, frames: np.ndarray) -> list[tuple[int, float]]:
    """The speed command a drive was recorded at: where it started (``meta.json``) and each
    change the live controls applied (``events.jsonl``, at the sample it applied from)."""
    log = []
    if isinstance(meta.get("speed_cm_s"), (int, float)):
        log.append((int(frames[0]) if len(frames) else 0, float(meta["speed_cm_s"])))
    for event in recorded_events(path):
        if event["field"] == "speed_cm_s" and len(frames):
            index = min(max(int(event["sample"]), 0), len(frames) - 1)
            log.append((int(frames[index]), float(event["value"])))
    return log


def _read_npy(path: Path, options: Options) -> Stream:
    _refuse(path, options, "a NumPy file has no named columns", columns={})
    units = options.units or "counts"
    key = "counts" if units == "counts" else "acceleration"
    start = None
    try:
        loaded = np.load(path, allow_pickle=False, mmap_mode="r" if path.suffix == ".npy"
                         else None)
        if isinstance(loaded, np.ndarray):
            array, stated = loaded, None
        else:
            with loaded:
                if key not in loaded.files:
                    raise SpecError(f"{path.name}", sorted(loaded.files),
                                    f"an .npz holding '{key}' (samples, 2 or 3) in {units} "
                                    "(--units), and optionally 'rate_hz' and 'start_s'")
                array = loaded[key]
                stated = float(loaded["rate_hz"]) if "rate_hz" in loaded.files else None
                start = float(loaded["start_s"]) if "start_s" in loaded.files else None
    except SpecError:
        raise
    except Exception as exc:            # numpy's parser: value, EOF, zip and pickle errors
        raise SpecError(path.name, f"{type(exc).__name__}: {exc}",
                        "a whole NumPy file: it is truncated or damaged") from None
    if array.ndim != 2:
        raise SpecError(f"{path.name} {key}", f"shape {array.shape}",
                        "an array of shape (samples, 2 or 3): the axes x, y (, z)")
    columns = _axes_of(f"{path.name} {key}", array.shape[1], options)
    if units == "counts" and array.dtype.kind not in "iu":
        raise SpecError(f"{path.name} {key}", f"dtype {array.dtype}",
                        "integer ADC counts, or declare the units (--units g or m/s2)")
    if units != "counts" and array.dtype.kind not in "iuf":
        raise SpecError(f"{path.name} {key}", f"dtype {array.dtype}", f"numbers in {units}")
    if start is not None and not np.isfinite(start):
        raise SpecError(f"{path.name} start_s", start, "a finite time in s")
    adc = _adc(options, BOARD_ADC_BITS if units == "counts" else ACCELERATION_ADC_BITS)
    parts = [_to_counts(path.name, np.asarray(array[lo:lo + CHUNK_ROWS][:, columns],
                                              dtype=np.float64), units, adc, options.signed,
                        lambda row, lo=lo: f"sample {lo + row}")
             for lo in range(0, len(array), CHUNK_ROWS)]
    counts = np.concatenate(parts) if parts else np.zeros((0, 2), np.int32)
    rate = _rate(path, stated, options, "rate_hz")
    return Stream(path.name, path.suffix[1:], counts, np.arange(len(counts)), rate, adc.bits,
                  adc.full_scale_g, _files(path), _unit_notes(units, options),
                  origin_s=start or 0.0)


def _sniff(path: Path, sample: str) -> tuple[type[csv.Dialect] | csv.Dialect, str]:
    """The dialect of a CSV (``csv.Sniffer``) from its first lines, and its decimal mark."""
    whole = sample[:sample.rfind("\n") + 1] if "\n" in sample else sample
    try:
        dialect = csv.Sniffer().sniff(whole, delimiters=",;\t|")
    except csv.Error:
        raise SpecError(path.name, "fields separated by no delimiter csv.Sniffer recognises",
                        "a CSV whose fields are separated by ',', ';', tab or '|'") from None
    body = whole.split("\n", 1)[1] if "\n" in whole else ""
    decimal = "," if dialect.delimiter != "," and re.search(r"\d,\d", body) else "."
    return dialect, decimal


def _column_index(path: Path, header: list[str], options: Options) -> dict[str, int]:
    """Where t_s, x, y, z sit in ``header`` (named as ``options.columns`` maps them)."""
    folded = [h.strip().lower() for h in header]
    mapping = {name: options.columns.get(name, name) for name in (TIME_COLUMN, *AXES)}
    index = {}
    for name, column in mapping.items():
        hits = [i for i, h in enumerate(folded) if h == column.strip().lower()]
        if len(hits) > 1:
            raise SpecError(f"{path.name} line 1", ",".join(header),
                            f"each column named once ({column!r} is named {len(hits)} times)")
        if hits:
            index[name] = hits[0]
        elif name in options.columns:
            raise SpecError("--columns", f"{name}={column}",
                            f"a column of {path.name}, whose header names "
                            f"{', '.join(h.strip() for h in header)}")
    if not options.columns:
        unknown = [h for i, h in enumerate(header) if i not in index.values()]
        if unknown:
            raise SpecError(f"{path.name} line 1", unknown[0].strip(),
                            "a header naming the columns t_s (optional), x, y (and z), or "
                            "their names given with --columns (e.g. x=ax,y=ay,t_s=time)")
    for name in options.axes:
        if name not in index:
            raise SpecError(f"{path.name} line 1", ",".join(h.strip() for h in header),
                            f"a header naming the axis {name!r} (--axes {options.axes}), or its "
                            f"column given with --columns ({name}=NAME)")
    return index


def _read_csv(path: Path, options: Options) -> Stream:
    units = options.units or "counts"
    adc = _adc(options, BOARD_ADC_BITS if units == "counts" else ACCELERATION_ADC_BITS)
    try:
        f = open(path, encoding="utf-8-sig", newline="")
    except OSError as exc:
        raise SpecError(path.name, type(exc).__name__, "a readable CSV file") from None
    try:
        with f:
            sample = f.read(SNIFF_BYTES)
            if not sample.strip():
                raise SpecError(path.name, "an empty file", "a CSV with a header naming x, y "
                                                            "(and optionally t_s)")
            dialect, decimal = _sniff(path, sample)
            f.seek(0)
            header = next(csv.reader([f.readline()], dialect))
            index = _column_index(path, header, options)
            wanted = [index[a] for a in options.axes]
            timed = TIME_COLUMN in index
            used = wanted + ([index[TIME_COLUMN]] if timed else [])
            parts, times, first_line = [], [], 2
            while True:
                lines = list(itertools.islice(f, CHUNK_ROWS))
                if not lines:
                    break
                values, line = _parse_lines(path, header, lines, first_line, used, dialect,
                                            decimal)
                parts.append(_to_counts(path.name, values[:, :2], units, adc, options.signed,
                                        lambda row, line=line: f"line {line(row)}"))
                if timed:
                    times.append(values[:, 2].copy())
                first_line += len(lines)
    except UnicodeDecodeError as exc:
        raise SpecError(path.name, type(exc).__name__, "a UTF-8 text CSV file") from None
    except csv.Error as exc:
        raise SpecError(path.name, f"csv.Error: {exc}", "a whole CSV file") from None
    except StopIteration:
        raise SpecError(path.name, "an empty file", "a CSV with a header") from None
    counts = np.concatenate(parts) if parts else np.zeros((0, 2), np.int32)
    del parts
    notes = _unit_notes(units, options, {"columns": [h.strip() for h in header],
                                         "delimiter": dialect.delimiter, "decimal": decimal})
    frames, origin, stated = np.arange(len(counts)), 0.0, None
    if timed and len(counts) >= 2:
        t = np.concatenate(times)
        del times
        origin = float(t[0])
        t -= origin
        t *= 1e9
        ns = np.rint(t, out=t).astype(np.int64)
        del t
        frames, clock_rate, clock = stamp_frames(f"{path.name} t_s", ns)
        del ns
        stated = _rate_of(clock_rate)
        notes.update(clock)
    rate = _rate(path, stated, options, "t_s column")
    return Stream(path.name, "csv", counts, frames, rate, adc.bits, adc.full_scale_g,
                  _files(path), notes, origin_s=origin)


def _parse_lines(path: Path, header, lines: list[str], first_line: int, columns, dialect,
                 decimal: str):
    """(rows, len(columns)) floats of the CSV ``lines`` (the first at file line
    ``first_line``), read by NumPy's parser, and the file line of each row. A chunk NumPy
    refuses is read again with ``csv`` to name the line, the column and the value."""
    import warnings

    text = lines if decimal == "." else [s.replace(",", ".") for s in lines]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            values = np.loadtxt(text, delimiter=dialect.delimiter, quotechar=dialect.quotechar,
                                usecols=columns, ndmin=2, dtype=np.float64, comments=None)
        blank = [k for k, s in enumerate(lines) if not s.strip()]
        if np.isfinite(values).all() and len(values) + len(blank) == len(lines):
            keep = np.delete(np.arange(len(lines)), blank) if blank else None
            return values, (lambda k: first_line + int(keep[k])) if blank else \
                (lambda k: first_line + k)
    except (ValueError, UserWarning):
        pass
    numbered = [(first_line + k, row) for k, row in enumerate(csv.reader(lines, dialect))
                if len(row) > 1 or (row and row[0].strip())]
    rows = [row for _, row in numbered]
    return _parse_chunk(path, header, rows, lambda k: numbered[k][0], columns, decimal), \
        (lambda k: numbered[k][0])


def _parse_chunk(path: Path, header, rows, line, columns, decimal: str,
                 what: str = "a number") -> np.ndarray:
    """(rows, len(columns)) floats of ``rows`` of a CSV; a bad row names its file line
    (``line``: row → line)."""
    n = len(header)
    if set(map(len, rows)) != {n}:
        k = next(k for k, r in enumerate(rows) if len(r) != n)
        raise SpecError(f"{path.name} line {line(k)}", ",".join(rows[k]),
                        f"{n} fields ({','.join(h.strip() for h in header)}): the file is "
                        "truncated or damaged")
    out = np.empty((len(rows), len(columns)))
    for j, c in enumerate(columns):
        cells = [r[c] for r in rows]
        if decimal == ",":
            cells = [s.replace(",", ".") for s in cells]
        try:
            out[:, j] = np.asarray(cells, dtype=np.float64)
        except ValueError:
            for k, s in enumerate(cells):
                try:
                    float(s)
                except ValueError:
                    raise SpecError(f"{path.name} line {line(k)} {header[c].strip()}",
                                    rows[k][c], what) from None
    if not np.isfinite(out).all():
        k, j = divmod(int(np.flatnonzero(~np.isfinite(out).ravel())[0]), len(columns))
        raise SpecError(f"{path.name} line {line(k)} {header[columns[j]].strip()}",
                        rows[k][columns[j]], f"a finite number ({what})")
    return out


def _wav_header(path: Path) -> dict:
    """The fmt chunk's valid bits per sample (WAVE_FORMAT_EXTENSIBLE), or {} without one."""
    import struct

    with open(path, "rb") as f:
        head = f.read(1 << 12)
    at = head.find(b"fmt ")
    if at < 0 or len(head) < at + 8 + 24:
        return {}
    size = struct.unpack_from("<I", head, at + 4)[0]
    tag = struct.unpack_from("<H", head, at + 8)[0]
    if tag == 0xFFFE and size >= 40 and len(head) >= at + 8 + 20:
        return {"valid_bits": struct.unpack_from("<H", head, at + 8 + 18)[0]}
    return {}


def _read_wav(path: Path, options: Options) -> Stream:
    import warnings

    from scipy.io import wavfile

    _refuse(path, options, "a WAV file holds PCM counts or fractions of full scale",
            columns={}, units="counts")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")          # a short data chunk is a truncated file
            try:                                    # mapped, read chunk by chunk below
                rate, data = wavfile.read(path, mmap=True)
            except ValueError as exc:
                if "mmap" not in str(exc):          # 24-bit PCM cannot be mapped: read whole
                    raise
                rate, data = wavfile.read(path)
    except Exception as exc:            # scipy's parser: struct, value, EOF errors, warnings
        raise SpecError(path.name, f"{type(exc).__name__}: {exc}",
                        "a whole WAV file: it is truncated or damaged") from None
    channels = data.shape[1] if data.ndim == 2 else 1
    columns = _axes_of(f"{path.name} channels", channels, options)
    rate = _rate(path, float(rate), options, "header")
    if data.dtype.kind == "f":
        if options.signed:
            raise SpecError("--signed", True, f"integer PCM; {path.name} is float PCM "
                                              "(fractions of full scale)")
        adc = _adc(options, ACCELERATION_ADC_BITS)
        counts = np.concatenate([_to_counts(path.name, np.asarray(
            data[lo:lo + CHUNK_ROWS, columns], dtype=np.float64) * adc.full_scale_g, "g", adc,
            False, lambda row, lo=lo: f"sample {lo + row}")
            for lo in range(0, len(data), CHUNK_ROWS)])
        notes = _unit_notes("full scale (float PCM)", options)
        return Stream(path.name, "wav", counts, np.arange(len(counts)), rate, adc.bits,
                      adc.full_scale_g, _files(path), notes)
    if data.dtype.kind not in "iu":
        raise SpecError(f"{path.name} format", str(data.dtype), "integer or float PCM")
    container = data.dtype.itemsize * 8
    if container == 32 and options.adc_bits is None:
        bits = _wav_header(path).get("valid_bits") or 24
    else:
        bits = options.adc_bits or _wav_header(path).get("valid_bits") or container
    if bits > min(container, 24):
        raise SpecError("--adc-bits", bits, f"at most {min(container, 24)} for "
                                            f"{path.name}'s {container}-bit PCM")
    shift = container - bits
    mid = 2 ** (container - 1) if data.dtype.kind == "i" else 0
    low = (1 << shift) - 1
    parts, justified = [], "left" if shift else "whole"
    for lo in range(0, len(data), CHUNK_ROWS):
        offset = np.asarray(data[lo:lo + CHUNK_ROWS, columns], dtype=np.int64) + mid
        parts.append(offset)
    full = np.concatenate(parts) if parts else np.zeros((0, 2), np.int64)
    if shift and np.any(full & low):
        centred = full - 2 ** (container - 1)
        if container == 32 and options.adc_bits is None and not _wav_header(path):
            justified = "top 24 of 32 bits"        # 32-bit PCM of a 32-bit converter
            counts = full >> shift
        elif np.all((centred >= -2 ** (bits - 1)) & (centred < 2 ** (bits - 1))):
            justified = "right"
            counts = centred + 2 ** (bits - 1)
        else:
            row, axis = divmod(int(np.flatnonzero((full & low).ravel())[0]), 2)
            raise SpecError("--adc-bits", bits,
                            f"the bits {path.name} holds: sample {row} ({'xy'[axis]}) uses the "
                            f"low {shift} bits of its {container}-bit PCM (a {bits}-bit ADC is "
                            "left-justified, low bits 0, or right-justified, within "
                            f"±{2 ** (bits - 1)})")
    else:
        counts = full >> shift
    adc = _adc(options, bits)
    notes = _unit_notes("counts", options, {"container_bits": container,
                                            "justified": justified})
    return Stream(path.name, "wav", counts.astype(np.int32), np.arange(len(counts)), rate,
                  bits, adc.full_scale_g, _files(path), notes)


def _read_rosbag(path: Path, options: Options) -> Stream:
    from rosbags.highlevel import AnyReader

    _refuse(path, options, "a ROS 2 Imu message holds accelerations in m/s²", columns={},
            signed=False, units="m/s2")
    imu = "sensor_msgs/msg/Imu"
    stamps, xyz = [], []
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
                stamp = msg.header.stamp
                stamps.append(int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec))
                a = msg.linear_acceleration
                xyz.append((a.x, a.y, a.z))
    except SpecError:
        raise
    except Exception as exc:               # rosbags' own errors: a damaged or foreign bag
        raise SpecError(path.name, f"{type(exc).__name__}: {exc}",
                        "a whole ROS 2 bag with an Imu topic") from None
    if len(stamps) < 2:
        raise SpecError(f"{path.name} {wanted}", f"{len(stamps)} message(s)",
                        "an Imu topic with at least two messages")
    ns = np.asarray(stamps, dtype=np.int64)
    del stamps
    # messages in bag order; a stamp may be written late, so they are placed by stamp
    order = np.argsort(ns, kind="stable")
    ns = ns[order]
    frames, clock_rate, clock = stamp_frames(f"{path.name} {wanted} header.stamp", ns - ns[0])
    rate = _rate(path, _rate_of(clock_rate), options, f"{wanted} header stamps")
    values = np.asarray(xyz, dtype=np.float64)[order][:, [AXES.index(a) for a in options.axes]]
    adc = _adc(options, ACCELERATION_ADC_BITS)
    counts = _to_counts(path.name, values, options.units or "m/s2", adc, False,
                        lambda row: f"message {int(order[row])}")
    notes = _unit_notes(options.units or "m/s2", options,
                        {"topic": wanted, "first_stamp_ns": int(ns[0]), **clock})
    return Stream(path.name, "rosbag", counts, frames, rate, adc.bits, adc.full_scale_g,
                  _files(path), notes, origin_s=int(ns[0]) / 1e9)
