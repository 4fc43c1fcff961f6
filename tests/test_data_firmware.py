"""End to end with a client no one here wrote: the board's shipped firmware, in simavr, streams a
small bench protocol; `record` keeps it; the emulator's log of what it streamed becomes the
labels table; `data import` makes the data set; the baseline comparison on it agrees with the
same study on the generated contacts it came from."""
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.bridge.emulate.firmware_loop import missing_tools
from snn_antenna.bridge.wire.recorder import Recorder, load_recording
from snn_antenna.bridge.wire.source import SerialSource, run_source
from snn_antenna.cli import main
from snn_antenna.data.labels import from_emulator_log
from snn_antenna.sources import recorded
from snn_antenna.studies import baseline_comparison

ROOT = Path(__file__).resolve().parents[1]
FIRMWARE = ROOT / "firmware" / "antenna_stream"
CLI = [sys.executable, "-m", "snn_antenna.cli"]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}

needs_simavr = pytest.mark.skipif(
    bool(missing_tools()), reason=f"missing {', '.join(missing_tools())} (Debian: apt-get install "
                                  "gcc-avr avr-libc simavr libsimavr-dev)")


def bench_table(tmp_path, repetitions: int) -> dict:
    return {"kind": "bench", "materials": ["wood", "aluminium"],
            "positions_cm": [10.0, 16.0, 22.0, 28.0], "repetitions": repetitions,
            "n_jobs": 1, "cache_dir": str(tmp_path / "cache")}


def stream_through_firmware(tmp_path, table: dict | None = None, stimulus: Path | None = None,
                            name: str = "bench1", *options) -> tuple[Path, dict]:
    """`emulate --pty --firmware` plays the bench ``table`` (or the ``stimulus`` file) once;
    the recorder keeps what arrives."""
    if table is not None:
        stimulus = tmp_path / "bench.toml"
        stimulus.write_text("".join(f"{k} = {json.dumps(v)}\n" for k, v in table.items()))
    emu = subprocess.Popen([*CLI, "emulate", "--pty", "--link", tmp_path / "tty", "--firmware",
                            FIRMWARE, "--stimulus", stimulus, "--log", tmp_path / "emu.json",
                            "--fast", *map(str, options)], cwd=tmp_path, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        assert emu.stdout.readline().strip() == str(tmp_path / "tty"), emu.stderr.read()
        source = SerialSource(str(tmp_path / "tty")).start()
        recorder = Recorder(tmp_path / "recs" / name, port=str(tmp_path / "tty"),
                            wire_format="binary", baudrate=250000)
        stop = threading.Event()
        thread = threading.Thread(target=run_source, daemon=True, args=(source, [recorder]),
                                  kwargs={"stop": stop, "no_data_timeout_s": 60})
        thread.start()
        _, err = emu.communicate(timeout=600)
    finally:
        emu.kill()
    stop.set()
    thread.join(10)
    source.stop()
    recorder.close()
    assert emu.returncode == 0, err
    return tmp_path / "recs", json.loads((tmp_path / "emu.json").read_text())


def import_it(tmp_path, recordings: Path, log: dict) -> Path:
    labels = tmp_path / "labels.csv"
    labels.write_text(from_emulator_log(log, "bench1"))
    assert main(["data", "import", str(recordings), str(labels), "--out",
                 str(tmp_path / "data")]) == 0
    return tmp_path / "data"


def study_spec(tmp_path, **source) -> dict:
    """The baseline comparison without its spiking part, at the board's rate (its spectrum
    stops below the 500 Hz Nyquist frequency of the 1 kHz board)."""
    return {"study": "baseline_comparison", "seed": 0, **source,
            "events": {"max_hz": 499.0},
            "evaluation": {"seeds": [0, 1, 2, 3, 4], "nmf_dims": [3],
                           "pipelines": ["distance", "material"], "mlp_max_iter": 100,
                           "material_max_iter": 60}}


def check_the_same_contacts(tmp_path, table, data_dir, log) -> None:
    """Every contact streamed is imported, at its onset, with its labels, its counts the
    board's."""
    source = recorded.open_bench(data_dir)
    rec = load_recording(tmp_path / "recs" / "bench1")
    assert rec.counts["gaps"] == rec.counts["lost_samples"] == rec.counts["crc_errors"] == 0
    n = len(table["materials"]) * len(table["positions_cm"]) * table["repetitions"]
    assert source.n_events == n == len(log["events"])
    ds = source.dataset
    truth = np.array([e["t_s"] for e in log["events"]])
    assert np.abs(ds["onset_s"].values - truth).max() <= 0.002       # 2 board samples
    assert list(ds["material"].values) == [e["material"] for e in log["events"]]
    assert list(ds["distance_cm"].values) == [e["distance_cm"] for e in log["events"]]
    meta = json.loads((data_dir / "import.json").read_text())
    assert meta["counts"]["excluded"] == dict.fromkeys(meta["counts"]["excluded"], 0)


def compare_studies(tmp_path, table, data_dir) -> tuple[dict, dict]:
    from snn_antenna.studies.contract import Options

    def run(spec, out):
        return baseline_comparison.run(baseline_comparison.plan(spec), tmp_path / out,
                                       Options(quick=True), log=lambda *a: None)

    on_recordings = run(study_spec(tmp_path, data=str(data_dir),
                                   stimulus={"cache_dir": table["cache_dir"]}), "study_recorded")
    on_generated = run(study_spec(tmp_path, stimulus=table), "study_generated")
    return on_recordings, on_generated


def assert_agree(on_recordings: dict, on_generated: dict) -> None:
    """Distance within the sensor's precision, accuracy within its interval."""
    precision = on_generated["calibration"]["ours"]["single_contact_precision_mm"]
    rec, gen = (s["distance_rmse_mm"]["linear_low_peak"]["mean"]
                for s in (on_recordings, on_generated))
    assert abs(rec - gen) <= precision, (rec, gen, precision)
    recorded_accuracy = {p["quantity"]: p for p in on_recordings["predicted"]}
    row = recorded_accuracy["materials, full-spectrum MLP accuracy"]
    low, high = row["interval"]
    generated = 100 * on_generated["material_accuracy"]["mlp_spectrum_material"]["mean"]
    assert low - 1e-9 <= generated <= high + 1e-9, (generated, row)
    # on recordings the only calibrated numbers are the antenna's, fitted on its labels
    assert on_generated["calibrated"] and on_recordings["calibrated"]
    assert all(row["source"].startswith("labels ") for row in on_recordings["calibrated"])
    assert on_recordings["data"]["recorded"]["counts"]["events"] > 0


@needs_simavr
def test_a_small_bench_protocol_through_the_firmware_is_imported_contact_for_contact(tmp_path):
    table = bench_table(tmp_path, repetitions=2)
    recordings, log = stream_through_firmware(tmp_path, table)
    data_dir = import_it(tmp_path, recordings, log)
    check_the_same_contacts(tmp_path, table, data_dir, log)
    # the recorded counts are the board's conversion of the generated contacts, sample for
    # sample: the study reads exactly what the generator made, as the board sent it
    from snn_antenna.bridge.emulate.stimulus import bench_on_board
    board = bench_on_board(table, seed=0)
    ds = recorded.open_bench(data_dir).dataset
    for k, onset in enumerate(ds["onset_s"].values):
        start = int(round(onset * 1000)) - 50                  # the window's 50 ms lead-in
        assert np.array_equal(ds["counts"].values[k], board.samples[start:start + 1050])


@needs_simavr
@pytest.mark.slow
def test_the_baseline_comparison_on_firmware_recordings_agrees_with_the_generated_data(tmp_path):
    table = bench_table(tmp_path, repetitions=10)
    recordings, log = stream_through_firmware(tmp_path, table)
    data_dir = import_it(tmp_path, recordings, log)
    check_the_same_contacts(tmp_path, table, data_dir, log)
    assert_agree(*compare_studies(tmp_path, table, data_dir))
    page = (tmp_path / "study_recorded" / "report.html").read_text()
    sha = json.loads((data_dir / "import.json").read_text())["recordings"][0]["files"][0]
    assert sha["sha256"] in page and str(data_dir.resolve()) in page


@needs_simavr
@pytest.mark.slow
def test_a_drive_through_the_firmware_is_the_quickstarts_scene_sample_for_sample(tmp_path):
    """The quickstart's scene streamed by the firmware, recorded, labelled from the emulator's
    log and imported as a drive: the study reads the board's counts and the scene's contacts."""
    from snn_antenna.core import spec as specs
    from snn_antenna.studies import quickstart

    spec = specs.load(ROOT / "studies" / "quickstart.toml", [])   # the scene the file holds
    scene = quickstart.plan(spec).parts.scene
    n = int(scene.duration_s * scene.rate_hz)
    recordings, log = stream_through_firmware(tmp_path, None,
                                              ROOT / "stimuli" / "quickstart_scene.toml",
                                              "drive1", "--frames", n, "--seed", spec["seed"])
    labels = tmp_path / "labels.csv"
    labels.write_text(from_emulator_log(log, "drive1", drive=True))
    assert main(["data", "import", str(recordings), str(labels), "--out",
                 str(tmp_path / "data")]) == 0
    parts = quickstart.plan({**spec, "data": str(tmp_path / "data")}).parts
    rec, generated = parts.scene.generate(0), scene.generate(int(spec["seed"]))
    assert np.array_equal(rec.samples, generated.samples)
    assert [(c.t_s, c.distance_cm) for c in rec.truth.contacts] == \
        [(c.t_s, c.distance_cm) for c in generated.truth.contacts]
