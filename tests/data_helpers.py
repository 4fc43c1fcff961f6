"""Recordings with known contacts for the import tests: the board's counts at rest, with
decaying two-axis ringing at chosen onsets, written as `record` writes them."""
from __future__ import annotations

import time

import numpy as np

from snn_antenna.bridge.wire.protocol import BOARD_RATE_HZ, Sample, encode_binary
from snn_antenna.bridge.wire.recorder import Recorder
from snn_antenna.bridge.wire.source import DEFAULT_BAUDRATE, Batch
from snn_antenna.sources.antenna import ADC, high_mode_hz, low_mode_hz

RATE = BOARD_RATE_HZ
BOARD = ADC(10, 18.0)


def ringing_counts(onsets_s, distances_cm, duration_s: float, seed: int = 0,
                   amplitude_g: float = 2.0, tau_s: float = 0.15, high: float = 0.0
                   ) -> np.ndarray:
    """(samples, 2) board counts: sensor noise, and at each onset the rod's low mode ringing
    (its frequency from the distance) on both axes, and its high mode at ``high`` × the low
    mode's amplitude, decaying four times as fast."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * RATE))
    g = rng.standard_normal((n, 2)) * 0.01
    t = np.arange(n) / RATE
    for onset, d in zip(onsets_s, distances_cm):
        after = t >= onset
        s = t[after] - onset
        ring = amplitude_g * np.exp(-s / tau_s) * np.sin(2 * np.pi * float(low_mode_hz(d)) * s
                                                         + np.pi / 2)
        ring += high * amplitude_g * np.exp(-4 * s / tau_s) * np.sin(
            2 * np.pi * float(high_mode_hz(d)) * s)
        g[after, 0] += ring * np.cos(0.5)
        g[after, 1] += ring * np.sin(0.5)
    return BOARD.to_counts(g)


def write_record(path, counts: np.ndarray, seq=None, complete: bool = True,
                 speed_cm_s: float | None = None, speed_changes=()):
    """A `record` folder holding ``counts`` with sequence numbers ``seq`` (default 0, 1, …;
    leave numbers out for lost samples), the speed command it started at and its changes
    ((sample index, cm/s), as the live controls journal them)."""
    seq = np.arange(len(counts)) if seq is None else np.asarray(seq)
    recorder = Recorder(path, port="test://", wire_format="binary", baudrate=DEFAULT_BAUDRATE,
                        extra_meta={} if speed_cm_s is None else {"speed_cm_s": speed_cm_s})
    for sample, value in speed_changes:
        recorder.note_event({"sample": sample, "field": "speed_cm_s", "value": value})
    raw = b"".join(encode_binary(int(s) % 65536, int(x), int(y))
                   for s, (x, y) in zip(seq, counts))
    samples = [Sample(int(s) % 65536, int(x), int(y)) for s, (x, y) in zip(seq, counts)]
    recorder.handle(Batch(time.time(), raw, samples, {"frames": len(samples)}))
    recorder.close(complete=complete)
    return path


def write_labels(path, rows, columns=("recording", "onset_s", "distance_cm", "material",
                                      "repetition")):
    lines = [",".join(columns)] + [",".join(str(v) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def import_dir(recordings, labels, out):
    """``snn-antenna data import RECORDINGS LABELS --out OUT``, quietly; the data set's folder."""
    import contextlib
    import io

    from snn_antenna.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        assert main(["data", "import", str(recordings), str(labels), "--out", str(out)]) == 0, \
            err.getvalue()
    return out


def import_quickstart_drive(tmp, spec):
    """The quickstart's scene of ``spec``, recorded as the board sends it and its contacts
    labelled, imported: ``(recording, data set folder)``."""
    from snn_antenna.bridge.wire.recorder import record_counts
    from snn_antenna.studies import quickstart

    rec = quickstart.plan(spec).parts.scene.generate(int(spec["seed"]))
    record_counts(tmp / "drives" / "drive1", rec.samples)
    rows = [("drive1", c.t_s, c.distance_cm, c.material) for c in rec.truth.contacts]
    write_labels(tmp / "labels.csv", rows, ("recording", "contact_s", "distance_cm", "material"))
    return rec, import_dir(tmp / "drives", tmp / "labels.csv", tmp / "data")


def record_scene(path, rec) -> None:
    """A generated drive written as `record` keeps a drive: its counts, the speed command it
    started at and every change (as the live controls journal them)."""
    speed = np.asarray(rec.meta["speed_cm_s"], dtype=float)
    changes = [(int(i), float(speed[i])) for i in np.flatnonzero(np.diff(speed)) + 1]
    write_record(path, rec.samples, speed_cm_s=float(speed[0]), speed_changes=changes)


def import_gating_drives(tmp, spec, per_speed: int = 2, calibration_s: float = 5.0):
    """Drives as the gating study of ``spec`` generates its scenes — ``per_speed`` course
    drives at each swept speed, each on its own seeded course with a contact after the
    settling time, and one drive in the open —
    recorded with their speed log, their contacts labelled, imported: the data set's folder
    and the generated recordings by drive name."""
    from snn_antenna.sources.scenes import SpeedProfile, drive as open_drive
    from snn_antenna.studies.gating_threshold.plan import make_parts
    from snn_antenna.studies.gating_threshold.scenes import make_scene

    parts = make_parts(spec)
    recs = {"open": open_drive(parts.scene, SpeedProfile("constant", 15.0), calibration_s,
                               []).generate(7)}
    for v in parts.sweep.speeds_cm_s:
        kept, k = 0, 0
        while kept < per_speed:       # courses with a contact after the settling time
            course, seed = make_scene(parts, SpeedProfile("constant", float(v)),
                                      (9, int(v * 10), k))
            rec, k = course.generate(seed), k + 1
            if any(c.t_s >= parts.sweep.settle_s for c in rec.truth.contacts):
                recs[f"v{v:g}_{kept}"], kept = rec, kept + 1
    rows = []
    for name, rec in recs.items():
        record_scene(tmp / "drives" / name, rec)
        rows += [(name, c.t_s, c.distance_cm, c.material) for c in rec.truth.contacts]
    write_labels(tmp / "labels.csv", rows, ("recording", "contact_s", "distance_cm", "material"))
    return import_dir(tmp / "drives", tmp / "labels.csv", tmp / "data"), recs


def import_board_bench(tmp, table: dict, seed: int = 0):
    """The bench ``table``'s contacts as the shipped board streams them (1 kHz, 10 bits, back
    to back), recorded and labelled from what was played, imported: the data set's folder."""
    from snn_antenna.bridge.emulate.stimulus import bench_on_board
    from snn_antenna.bridge.wire.recorder import record_counts

    board = bench_on_board(table, seed=seed, log=lambda text: None)
    record_counts(tmp / "recs" / "bench1", board.samples)
    write_labels(tmp / "labels.csv", [("bench1", c.t_s, c.distance_cm, c.material)
                                      for c in board.truth.contacts],
                 ("recording", "onset_s", "distance_cm", "material"))
    return import_dir(tmp / "recs", tmp / "labels.csv", tmp / "data")
