"""A lab's own antenna and equipment through `snn-antenna data import`: each recording keeps its
own clock (a CSV's first time, a bag's real-clock stamps), its units, axes and columns are
declared, and every contact comes out labelled as the lab labelled it. The recordings come
from ``lab_antenna``: another rod, written without the package's physics."""
import contextlib
import csv
import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lab_antenna as lab
from snn_antenna.cli import main
from snn_antenna.core.errors import SpecError
from snn_antenna.data.inputs import stamp_frames
from snn_antenna.readout.spiking import CentroidDistance
from snn_antenna.sources import recorded

REAL_CLOCK_NS = 1_795_000_000_123_456_789       # a stamp of late 2026, since 1970


def run_cli(*argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["data", "import", *map(str, argv)])
    return code, err.getvalue()


def imported(tmp_path, recs, labels, *extra, out="ds"):
    code, err = run_cli(recs, labels, "--out", tmp_path / out, *extra)
    assert code == 0, err
    return recorded.open_bench(tmp_path / out), err


def refused(tmp_path, recs, labels, *extra) -> str:
    code, err = run_cli(recs, labels, "--out", tmp_path / "refused", *extra)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("snn-antenna: error: "), err
    assert not (tmp_path / "refused").exists()
    return err


def assert_labelled_right(source, sess: lab.Session, origin_s: float, tol_s: float = 0.01):
    """Every contact of the session imported, each at its own onset with its own label."""
    ds = source.dataset
    assert ds.sizes["event"] == len(sess.contacts)
    truth = sorted(sess.contacts, key=lambda c: c.t_s)
    got = sorted(zip(ds["onset_s"].values, ds["material"].values, ds["distance_cm"].values,
                     ds["repetition"].values))
    for c, (onset, material, distance, rep) in zip(truth, got):
        assert abs(onset - (origin_s + c.t_s)) < tol_s
        assert (str(material), float(distance), int(rep)) == (c.material, c.distance_cm,
                                                               c.repetition)


@pytest.fixture(scope="module")
def sess():
    return lab.session(2000.0, seed=1)


def test_a_spreadsheet_csv_on_its_own_clock_imports_every_contact_labelled_right(tmp_path,
                                                                                 sess):
    """A byte-order mark, semicolons, decimal commas, the lab's column names, g, a third axis
    and a clock starting at 1000 s: declared, and every contact lands on its label."""
    (tmp_path / "recs").mkdir()
    lab.spreadsheet_csv(tmp_path / "recs" / "r1.csv", sess, origin_s=1000.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1", origin_s=1000.0)
    source, _ = imported(tmp_path, tmp_path / "recs", labels, "--units", "g", "--columns",
                         "t_s=time,x=ax,y=ay,z=az", "--full-scale-g", "16")
    assert_labelled_right(source, sess, 1000.0)
    assert source.rate_hz == 2000.0 and source.adc_bits == 16
    assert source.materials == ["aluminium", "rubber", "wood"]
    assert "np.str_" not in repr(source.materials)
    meta = source.provenance
    rec = meta["recordings"][0]
    assert rec["origin_s"] == 1000.0 and rec["delimiter"] == ";" and rec["decimal"] == ","
    assert meta["clocks"][0]["matched"] == len(sess.contacts)
    # the time and the axes come from the declared columns: x and z are not the plane
    code, err = run_cli(tmp_path / "recs", labels, "--out", tmp_path / "xz", "--units", "g",
                        "--columns", "t_s=time,x=ax,y=ay,z=az", "--axes", "xz")
    assert code == 0, err
    assert recorded.open_bench(tmp_path / "xz").dataset.sizes["event"] == len(sess.contacts)


def test_labels_off_the_recordings_clock_are_refused_with_the_offset_that_fits(tmp_path,
                                                                               sess):
    """A CSV whose time starts at 3 s, labelled from 0: every label would land 3 s early.
    The import says so, with the shift that fits, and applies it only when told."""
    from lab_antenna import adc_counts

    (tmp_path / "recs").mkdir()
    counts = adc_counts(sess.g[:, :2], 10, 18.0)
    lab.counts_csv(tmp_path / "recs" / "r1.csv", counts, 2000.0, origin_s=3.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1.csv", origin_s=0.0)
    err = refused(tmp_path, tmp_path / "recs", labels)
    assert "--clock-offset-s 3" in err and "onset_s" in err, err
    source, log = imported(tmp_path, tmp_path / "recs", labels, "--clock-offset-s", "3")
    assert_labelled_right(source, sess, 3.0)
    assert source.provenance["settings"]["clock_offset_s"] == 3.0
    # labels 3 s late on the file's clock: the same refusal, the other way
    late = lab.labels_csv(tmp_path / "late.csv", sess, "r1", origin_s=6.0)
    assert "--clock-offset-s -3" in refused(tmp_path, tmp_path / "recs", late)


def test_a_consistent_lag_is_reported_never_applied(tmp_path, sess):
    (tmp_path / "recs").mkdir()
    counts = lab.adc_counts(sess.g[:, :2], 10, 18.0)
    lab.counts_csv(tmp_path / "recs" / "r1.csv", counts, 2000.0, origin_s=0.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1", lag_s=0.04)
    source, log = imported(tmp_path, tmp_path / "recs", labels)
    clock = source.provenance["clocks"][0]
    assert abs(clock["median_lag_s"] + 0.04) < 0.002, clock
    assert "-40." in log or "-39." in log, log
    assert_labelled_right(source, sess, 0.0)            # the onsets found, not the labels


def test_an_import_matching_few_labels_says_so(tmp_path, sess):
    (tmp_path / "recs").mkdir()
    counts = lab.adc_counts(sess.g[:, :2], 10, 18.0)
    lab.counts_csv(tmp_path / "recs" / "r1.csv", counts, 2000.0, origin_s=0.0)
    rng = np.random.default_rng(5)
    lines = ["recording,onset_s,distance_cm,material,repetition"]
    for k, c in enumerate(sess.contacts):     # most labels written at a random time
        t = c.t_s if k < 4 else rng.uniform(0.5, sess.duration_s - 1.2)
        lines.append(f"r1,{t:.4f},{c.distance_cm:g},{c.material},{c.repetition}")
    (tmp_path / "labels.csv").write_text("\n".join(lines) + "\n")
    code, err = run_cli(tmp_path / "recs", tmp_path / "labels.csv", "--out", tmp_path / "ds")
    assert code == 0, err
    assert "few" in err


def test_a_narrow_adc_in_a_wide_wav_is_read_at_its_own_bits_and_its_clipping_found(tmp_path):
    """A 12-bit converter left-justified in 16-bit PCM: with --adc-bits 12 its counts and its
    rails are its own (a contact that hit them is left out as clipped)."""
    sess = lab.session(2000.0, materials=("rubber", "wood"), distances_cm=(10.0, 26.0),
                       seed=4)
    loud = sorted(sess.contacts, key=lambda c: c.t_s)[2]
    start = int(np.ceil(loud.t_s * 2000.0))
    sess.g[start + 40:start + 44, 0] = 40.0               # past the ±16 g range
    (tmp_path / "recs").mkdir()
    lab.narrow_wav(tmp_path / "recs" / "r1.wav", sess, bits=12, full_scale_g=16.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    source, _ = imported(tmp_path, tmp_path / "recs", labels, "--adc-bits", "12",
                         "--full-scale-g", "16")
    ds = source.dataset
    assert source.adc_bits == 12 and int(ds["counts"].values.max()) < 4095
    assert ds.sizes["event"] == len(sess.contacts) - 1
    assert source.provenance["counts"]["excluded"]["clipped"] == 1
    assert source.provenance["counts"]["excluded_by_position"] == {
        f"{loud.distance_cm:g}": {"clipped": 1}}
    with open(tmp_path / "ds" / "exclusions.csv") as f:
        assert [(r["reason"], float(r["distance_cm"])) for r in csv.DictReader(f)] == [
            ("clipped", loud.distance_cm)]
    assert source.provenance["recordings"][0]["justified"] == "left"
    counts = lab.adc_counts(sess.g[:, :2], 12, 16.0)
    onset = int(round(ds["onset_s"].values[0] * 2000.0))
    assert np.array_equal(ds["counts"].values[0], counts[onset - 100:onset - 100 + 2100])
    # wider than the container, or low bits a 12-bit ADC cannot set: refused
    assert "--adc-bits" in refused(tmp_path, tmp_path / "recs", labels, "--adc-bits", "20")
    assert "low 8 bits" in refused(tmp_path, tmp_path / "recs", labels, "--adc-bits", "8")


def test_float_wav_and_signed_counts_are_read_as_declared(tmp_path):
    from scipy.io import wavfile

    sess = lab.session(2000.0, materials=("rubber", "pom"), distances_cm=(14.0, 30.0),
                       seed=6)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    (tmp_path / "wav").mkdir()
    wavfile.write(tmp_path / "wav" / "r1.wav", 2000, (sess.g / 8.0).astype(np.float32))
    source, _ = imported(tmp_path, tmp_path / "wav", labels, "--full-scale-g", "8",
                         "--axes", "xy", out="fwav")
    assert_labelled_right(source, sess, 0.0)
    assert source.adc_bits == 16
    (tmp_path / "npy").mkdir()
    signed = lab.adc_counts(sess.g, 14, 8.0) - 2 ** 13
    np.save(tmp_path / "npy" / "r1.npy", signed.astype(np.int16))
    source, _ = imported(tmp_path, tmp_path / "npy", labels, "--signed", "--adc-bits", "14",
                         "--full-scale-g", "8", "--rate", "2000", out="signed")
    assert_labelled_right(source, sess, 0.0)
    # the same counts read as unsigned are refused by name, never shifted silently
    err = refused(tmp_path, tmp_path / "npy", labels, "--adc-bits", "14", "--rate", "2000")
    assert "--signed" in err


@pytest.mark.parametrize("extra, named", [
    (("--adc-bits", "12"), "--adc-bits"),             # a record folder is the board's
    (("--units", "g"), "--units"),
    (("--axes", "xz"), "--axes"),
    (("--columns", "x=ax"), "--columns"),
])
def test_an_option_a_record_folder_cannot_honour_is_refused(tmp_path, extra, named):
    from data_helpers import ringing_counts, write_labels, write_record

    write_record(tmp_path / "recs" / "run1", ringing_counts([1.0], [10.0], 3.0))
    write_labels(tmp_path / "labels.csv", [("run1", 1.0, 10.0, "wood", 0)])
    assert named in refused(tmp_path, tmp_path / "recs", tmp_path / "labels.csv", *extra)


def test_declarations_a_file_cannot_meet_are_refused_by_name(tmp_path, sess):
    (tmp_path / "recs").mkdir()
    lab.spreadsheet_csv(tmp_path / "recs" / "r1.csv", sess, origin_s=0.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    assert "ax" in refused(tmp_path, tmp_path / "recs", labels)    # columns not declared
    err = refused(tmp_path, tmp_path / "recs", labels, "--units", "g", "--columns",
                  "t_s=time,x=ax,y=acc_y")
    assert "--columns" in err and "acc_y" in err
    err = refused(tmp_path, tmp_path / "recs", labels, "--columns", "t_s=time,x=ax,y=ay")
    assert "integer ADC count" in err and "--units" in err     # g read as counts: refused
    (tmp_path / "npy").mkdir()
    np.save(tmp_path / "npy" / "r1.npy", np.zeros((100, 2), np.int16))
    err = refused(tmp_path, tmp_path / "npy", labels, "--axes", "yz", "--rate", "2000")
    assert "--axes" in err


def test_stamps_in_integer_nanoseconds_tell_jitter_from_gaps_at_any_length():
    """250,000 stamps at 2 kHz on a real clock, jittered by ±50 µs, with lost stretches:
    every stamp on its own frame, the rate exact, the gaps counted."""
    rng = np.random.default_rng(0)
    n = 250_000
    frames = np.arange(n + 40)
    lost = np.r_[1000:1003, 200_000:200_037]
    frames = np.delete(frames, lost)
    ns = REAL_CLOCK_NS + frames * 500_000 + rng.integers(-50_000, 50_001, len(frames))
    got, rate, clock = stamp_frames("bag", ns - ns[0])
    assert np.array_equal(got, frames - frames[0])
    assert abs(rate - 2000.0) < 1e-4
    assert clock["gaps"] == 2 and clock["lost_samples"] == 40
    # float seconds at this clock carry 0.24 µs: the same stamps as float64 s still place
    as_seconds = (ns.astype(np.float64) / 1e9)
    assert as_seconds[1] - as_seconds[0] != (ns[1] - ns[0]) / 1e9


def test_a_ros2_bag_on_a_real_clock_imports_with_its_jitter_and_gaps(tmp_path):
    """A bag stamped by the lab computer's clock (seconds since 1970, ±50 µs of jitter, a
    stretch of lost messages), labelled on that clock."""
    sess = lab.session(1000.0, materials=("rubber", "aluminium"), distances_cm=(12.0, 30.0),
                       repetitions=1, seed=2)
    (tmp_path / "bags").mkdir()
    lab.imu_bag(tmp_path / "bags" / "r1", sess, REAL_CLOCK_NS, jitter_ns=50_000,
                drop=range(300, 320))
    origin = REAL_CLOCK_NS / 1e9
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1", origin_s=origin)
    source, _ = imported(tmp_path, tmp_path / "bags", labels)
    assert_labelled_right(source, sess, origin)
    rec = source.provenance["recordings"][0]
    assert rec["rate_hz"] == 1000.0 and rec["lost_samples"] == 20 and rec["gaps"] == 1
    assert abs(rec["first_stamp_ns"] - REAL_CLOCK_NS) <= 50_000
    # the same labels from the bag's start: refused with the shift that fits
    relative = lab.labels_csv(tmp_path / "relative.csv", sess, "r1", origin_s=0.0)
    err = refused(tmp_path, tmp_path / "bags", relative)
    assert "--clock-offset-s 1795000000.12" in err, err


def test_the_two_material_network_takes_any_two_of_the_labs_materials(tmp_path):
    """A set without aluminium: the paper's pair is refused by its field, naming the set's
    materials cleanly; any two the labels name are taken."""
    from snn_antenna.studies import baseline_comparison

    sess = lab.session(2000.0, materials=("rubber", "wood"), distances_cm=(10.0, 30.0),
                       repetitions=4, seed=8)
    (tmp_path / "recs").mkdir()
    lab.counts_csv(tmp_path / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                   2000.0, 0.0)
    lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    imported(tmp_path, tmp_path / "recs", tmp_path / "labels.csv")
    sets = ["evaluation.pipelines=[\"two_material\"]", "evaluation.seeds=[0]"]
    with pytest.raises(SpecError) as refusal:
        baseline_comparison.plan({**fft_spec(*sets), "data": str(tmp_path / "ds")})
    assert refusal.value.field == "evaluation.two_materials"
    assert "np.str_" not in str(refusal.value) and "'rubber'" in str(refusal.value)
    spec = fft_spec(*sets, "evaluation.two_materials=[\"rubber\", \"wood\"]")
    parts = baseline_comparison.plan({**spec, "data": str(tmp_path / "ds")}).parts
    assert parts.evaluation.two_materials == ["rubber", "wood"]


def test_labels_may_name_a_file_with_or_without_its_extension(tmp_path, sess):
    (tmp_path / "recs").mkdir()
    counts = lab.adc_counts(sess.g[:, :2], 10, 18.0)
    lab.counts_csv(tmp_path / "recs" / "r1.csv", counts, 2000.0, 0.0)
    for name in ("r1", "r1.csv"):
        labels = lab.labels_csv(tmp_path / f"{name}.labels", sess, name)
        source, _ = imported(tmp_path, tmp_path / "recs", labels, out=f"ds_{name}")
        assert set(source.dataset["recording"].values) == {"r1.csv"}


@pytest.mark.slow
@pytest.mark.parametrize("storage", ["mcap"])
def test_a_long_real_clock_bag_imports_every_contact(tmp_path, storage):
    """More than 100,000 messages at 2 kHz stamped on a real clock with jitter."""
    sess = lab.session(2000.0, materials=("rubber", "wood", "pom", "aluminium"),
                       distances_cm=(10.0, 22.0, 34.0), repetitions=4, seed=3)
    assert len(sess.g) > 100_000
    (tmp_path / "bags").mkdir()
    lab.imu_bag(tmp_path / "bags" / "r1", sess, REAL_CLOCK_NS, jitter_ns=50_000,
                storage=storage)
    origin = REAL_CLOCK_NS / 1e9
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1", origin_s=origin)
    source, _ = imported(tmp_path, tmp_path / "bags", labels)
    assert_labelled_right(source, sess, origin)
    assert source.provenance["recordings"][0]["samples"] == len(sess.g)
    assert json.loads((tmp_path / "ds" / "import.json").read_text())["recordings"][0][
        "rate_hz"] == 2000.0


# -- promises: the raw folder untouched, a data set read only as imported ----------------------
def test_an_out_folder_inside_the_recordings_is_refused(tmp_path, sess):
    (tmp_path / "recs").mkdir()
    lab.counts_csv(tmp_path / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                   2000.0, 0.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    for out in (tmp_path / "recs" / "ds", tmp_path / "recs"):
        code, err = run_cli(tmp_path / "recs", labels, "--out", out)
        assert code == 2 and "--out" in err and "outside the recordings" in err, err
    assert sorted(p.name for p in (tmp_path / "recs").iterdir()) == ["r1.csv"]


@pytest.mark.parametrize("damage", ["changed", "missing"])
def test_a_data_set_changed_after_its_import_is_refused_never_read(tmp_path, sess, damage):
    """A chunk of the store rewritten, or deleted (zarr would read its fill value): the study
    refuses the data set, so no cache keyed by the import is reused on other data."""
    import zarr

    from snn_antenna.sources import bench

    (tmp_path / "recs").mkdir()
    lab.counts_csv(tmp_path / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                   2000.0, 0.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    source, _ = imported(tmp_path, tmp_path / "recs", labels)
    assert bench.load(source, log=lambda *a: None).sizes["event"] == len(sess.contacts)
    store = tmp_path / "ds" / recorded.DATASET
    if damage == "changed":
        counts = zarr.open_array(store / "counts", mode="r+")
        counts[0, 0, 0] = int(counts[0, 0, 0]) + 1
    else:
        chunks = sorted(p for p in (store / "counts").rglob("*") if p.is_file()
                        and p.name != "zarr.json")
        chunks[-1].unlink()
    with pytest.raises(SpecError, match="changed after the import"):
        recorded.open_bench(tmp_path / "ds")


def big_counts_csv(path: Path, seconds: int, rate: int = 2000) -> list[float]:
    """A CSV of board counts with its time column, ``seconds`` long, a contact every 7 s
    (written from a 7 s template, so a 200 MB file takes seconds); the contacts' onsets."""
    block_s = 7
    t = np.arange(block_s * rate) / rate
    ring = np.where(t >= 3.0, 3 * np.exp(-(t - 3.0) / 0.1) * np.sin(2 * np.pi * 30 * (t - 3.0)),
                    0.0) + np.random.default_rng(0).standard_normal(len(t)) * 0.01
    x = lab.adc_counts(ring * 0.8, 10, 18.0)
    y = lab.adc_counts(ring * 0.6, 10, 18.0)
    seconds_text = ["".join(f"{{s}}.{i * 10 ** 6 // rate:06d},{x[j * rate + i]},"
                            f"{y[j * rate + i]}\n" for i in range(rate))
                    for j in range(block_s)]
    onsets = []
    with open(path, "w") as f:
        f.write("t_s,x,y\n")
        for b in range(seconds // block_s):
            for j, text in enumerate(seconds_text):
                f.write(text.replace("{s}", str(b * block_s + j)))
            onsets.append(b * block_s + 3.0)
    return onsets


@pytest.mark.slow
@pytest.mark.skipif(not Path("/usr/bin/time").exists(),
                    reason="needs /usr/bin/time (GNU time) to measure the peak memory")
def test_importing_a_200_mb_csv_stays_under_1_gb(tmp_path):
    """Measured as the kernel counts it (``/usr/bin/time -v``: the import's peak resident
    memory), on a 200 MB CSV of 2 kHz counts with its time column."""
    import shutil
    import subprocess
    import sys

    (tmp_path / "recs").mkdir()
    onsets = big_counts_csv(tmp_path / "recs" / "big.csv", 5600)
    size = (tmp_path / "recs" / "big.csv").stat().st_size
    assert size > 200e6
    (tmp_path / "labels.csv").write_text("recording,onset_s,distance_cm,material\n" + "".join(
        f"big,{t:.3f},{[12, 20, 30][k % 3]},{['wood', 'rubber'][k % 2]}\n"
        for k, t in enumerate(onsets)))
    cli = shutil.which("snn-antenna", path=str(Path(sys.executable).parent))
    done = subprocess.run(["/usr/bin/time", "-v", cli, "data", "import", str(tmp_path / "recs"),
                           str(tmp_path / "labels.csv"), "--out", str(tmp_path / "ds")],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    peak_kb = int(next(line.split(":")[1] for line in done.stderr.splitlines()
                       if "Maximum resident set size" in line))
    assert peak_kb * 1024 < 1e9, f"{peak_kb / 1024:.0f} MB for a {size / 1e6:.0f} MB CSV"
    source = recorded.open_bench(tmp_path / "ds")
    assert source.n_events == len(onsets)


def test_a_bad_csv_value_is_named_by_its_file_line_past_blank_lines(tmp_path):
    (tmp_path / "recs").mkdir()
    rows = [f"{i / 2000:.6f},512,512" for i in range(70_000)]
    rows[68_000] = "34.000000,512,5x2"
    rows.insert(100, "")                        # a blank line: skipped, still counted
    (tmp_path / "recs" / "r1.csv").write_text("t_s,x,y\n" + "\n".join(rows) + "\n")
    (tmp_path / "labels.csv").write_text("recording,onset_s,distance_cm,material\n"
                                         "r1,1.0,10,wood\n")
    err = refused(tmp_path, tmp_path / "recs", tmp_path / "labels.csv")
    assert "r1.csv line 68003 y" in err and "5x2" in err, err


# Read-outs of the shipped comparison that read the lab's rod as well as one feature does
# (material within 5 points of the decay time's read-out, distance within 2x the peak
# frequency's rmse), on every profile, and on the quick profiles only (more training
# contacts); every NMF size the split fits comes with them.
MEETS = ("mlp_parametric_material", "mlp_spectrum_material", "linear_low_peak",
         "mlp_parametric", "mlp_spectrum", "mlp_spectrum_sub10", "mlp_low_half",
         "spiking_dominant", "spiking_centroid", "spiking_mlp_distance_low",
         "spiking_mlp_distance",
         "spiking_mlp_material_rod", "spiking_tuned_bins", "spiking_tuned_late",
         "spiking_tuned_decay", "spiking_tuned_all", "spiking_tuned_rate",
         "spiking_tuned_timing", "coder_analog_24_bins",
         "coder_analog_24_decay", "ceiling_analog_24", "ceiling_delta_24",
         "ceiling_square_24", "coder_square_24_bins", "coder_square_24_decay",
         "coder_delta_24_bins", "coder_delta_24_decay")
MEETS_QUICK = ("spiking_mlp_material",)


# The rods the comparison reads (``lab_antenna.session``'s keys): the lab's, and another lab's
# (``lab_antenna.OTHER_ROD``, another session's seed) that no fitted rule was chosen on; and
# the families of ``MEETS`` / ``MEETS_QUICK`` that miss on the other rod (the test's docstring
# says why).
RODS = {"lab": {"seed": 9}, "other": {"seed": 33, **lab.OTHER_ROD}}
MISSES_ON_OTHER = ("spiking_tuned_rate", "spiking_tuned_timing", "spiking_mlp_material")


@pytest.mark.slow
@pytest.mark.parametrize("rate, profile, rod", [(1000.0, ["--quick"], "lab"),
                                                (2000.0, ["--quick"], "lab"),
                                                (2000.0, [], "lab"),
                                                (2000.0, ["--quick"], "other")])
def test_the_shipped_comparison_checks_runs_and_reads_as_well_as_one_feature(tmp_path, rate,
                                                                              profile, rod):
    """`run studies/baseline_comparison.toml --data DIR` (quick at the board's 1 kHz and at
    2 kHz, full at 2 kHz), with `--check` first, on the lab's rod (its four materials, four
    distances, ten repetitions): the check passes and so does the run, every statistic
    finite; on the same splits, every read-out family in ``MEETS`` reads the material within
    5 points of the one-feature decay read-out, or the distance within 2× the peak-frequency
    read-out's rmse. ``benchmarks/bench_lab_readouts.py`` prints every read-out beside them.

    The lab's antenna is fitted on the calibration contacts first: its law, split, decay
    window and bands from their labels; the hand-set bands' thresholds that lie within the
    band's quiet level, the tuned coder's threshold, gain and level step, the rate
    centroid's neighbourhood, the dominant resonator's bias and the spiking distance MLPs'
    L2 penalty from their recordings.

    Measured with that script on the sessions these cases record (quick at 1 kHz, quick at
    2 kHz, full at 2 kHz, against the decay read-out's 0.95, 0.95, 0.96): every family of
    ``MEETS`` meets, among them the tuned bank's rate (0.92, 0.95, 0.95), its latency code
    (0.95, 0.91, 0.92: a test contact or two above the mark), its rate, latency, span and time
    bins together (0.98, 0.97, 0.98) and its rate in the time bins from 100 ms on (0.95,
    0.98, 0.975), and the sign and level coders on the tuned channels (square 0.98, 0.98,
    0.95 in time bins, 0.98, 0.98, 0.96 with the decay; level 1.00, 1.00, 0.96 and 1.00,
    0.98, 0.95). The tuned coders' gain brings the 0.95 quantile of the channels' peaks to
    their range (``antenna_fit.PEAK_QUANTILE`` says what the median peak and the largest
    read).

    The read-outs left out, and why:
    - on the full profile (5 of 10 repetitions held out to calibrate, 48 training contacts),
      both bands' spiking MLP (0.90, 0.95, 0.86): its 144 inputs on those few contacts;
    - the high band's spiking MLP (0.78, 0.92, 0.74): this rod's modes' ranges overlap (the
      low mode 12-60 Hz, the high one 44-222 Hz), so the high band's band-pass passes the low
      mode at the near positions and its square-wave coder follows the stronger mode's zero
      crossings, and its high mode decays twice as fast as the low one (rubber's rings 15 ms,
      under a period at 44 Hz): at 26 and 34 cm rubber and wood leave it nearly silent. Its
      typed threshold (20 mg) lies above its quiet rms (12 mg at 2 kHz) and stays; at 5
      times its noise alone (the samples before the trigger less their mean, through its
      filters: 35 mg at 2 kHz, 46 mg at 1 kHz) it reads 0.84, 0.94, 0.83, still under.
    The spiking distance MLP on both bands meets with its L2 penalty fitted on the
    calibration contacts (2.9, 3.7, 4.8 mm against the peak read-out's 5.2, 5.4, 6.0).

    On another lab's rod (``lab_antenna.OTHER_ROD``: five materials, its first mode from 75 to
    15 Hz, the second at 3.1 times it; seed 33, quick at 2 kHz), which none of the fitted
    rules was chosen on, the same families meet but ``MISSES_ON_OTHER`` (against the decay
    read-out's 0.95 and the peak read-out's 4.6 mm): the tuned bank's rate (0.86) and its
    latency code (0.86), and both bands' spiking MLP (0.84), on 99 training contacts; the
    tuned bank's rate, latency, span and time bins together meet (0.95). The dominant
    resonator, which sits about one channel below the ringing, meets there with its bias
    fitted on the calibration contacts (6.8 mm), and so does the spiking distance MLP on both
    bands (4.1 mm). On the other rod's session of seed 34 the same families meet and miss
    (the rate 0.84, the latency code 0.84, both bands' MLP 0.81, against 0.925). The latency
    code lies near the mark on the lab's rod too: on its session of seed 21 (quick, 2 kHz) it
    misses (0.875 against the decay read-out's 0.97) where every other family of ``MEETS``
    and ``MEETS_QUICK`` meets."""
    from snn_antenna.cli import main as cli

    antenna = RODS[rod]
    sess = lab.session(rate, materials=tuple(antenna.get("decay_s", lab.DECAY_S)),
                       repetitions=10, **antenna)
    (tmp_path / "recs").mkdir()
    lab.counts_csv(tmp_path / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                   rate, origin_s=2.5)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1", origin_s=2.5)
    source, _ = imported(tmp_path, tmp_path / "recs", labels)
    assert_labelled_right(source, sess, 2.5)
    study = str(Path(__file__).resolve().parents[1] / "studies" / "baseline_comparison.toml")
    args = ["run", study, "--data", str(tmp_path / "ds"), *profile, "--set",
            f"stimulus.cache_dir=\"{tmp_path / 'cache'}\"", "--set", "spiking.workers=1",
            "--out", str(tmp_path / "run")]
    assert cli([*args, "--check"]) == 0
    assert cli(args) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["data"]["skipped"]["no_decay_fit"] <= 0.05 * source.n_events
    scores = lab.against_one_feature(tmp_path / "run", source)
    meets = [*MEETS, *(MEETS_QUICK if profile else ()),
             *(name for name in scores if name.startswith("nmf_"))]
    if rod == "other":
        meets = [name for name in meets if name not in MISSES_ON_OTHER]
    assert len(meets) > len(MEETS) and set(meets) <= set(scores), sorted(scores)
    missed = {name: scores[name][:2] for name in meets if not (
        scores[name][0] >= scores[name][1] - 0.05 if scores[name][2] == "material"
        else scores[name][0] <= 2 * scores[name][1])}
    assert not missed, (missed, scores)
    assert_reports_recorded_data(tmp_path / "run")
    # (a hand-set band's threshold is fitted only where the typed one lies within its quiet
    # level: test_the_tuned_coders_levels_are_fitted_on_the_calibration_recordings)
    for fitted in ("a silent low band reads", "the rate centroid over the low-band",
                   "spiking.tuned.tuning.threshold_g", "the dominant resonator's bias",
                   "spiking_mlp_distance's L2 penalty", "spiking_mlp_distance_low's L2 penalty"):
        assert any(line.startswith(f"fitted: {fitted}")
                   for line in summary["data"]["fitted"]), (fitted, summary["data"]["fitted"])


# -- the lab's antenna, fitted from its labels, and the comparison on it ---------------------
def assert_reports_recorded_data(run: Path):
    """The page and summary say what the data is: recorded, with what was fitted and every
    contact left out, never the generator's words."""
    page = (run / "report.html").read_text()
    summary = json.loads((run / "summary.json").read_text())
    for generated in ("generat", "8 × 16", "8 x 16", "in this generator"):
        assert generated not in page.lower(), generated
    assert "recorded by a lab" in page and "held out to calibrate" in page
    assert "low-mode law" in page and summary["data"]["recorded"]["labels"]["sha256"][:16] in page
    held = summary["data"]["left_out_by_position"]["calibration"]
    assert sum(held.values()) == summary["data"]["n_events"] - summary["data"]["n_processed"] \
        - sum(summary["data"]["skipped"].values())


def fft_spec(*sets):
    """The shipped comparison's quick profile without its spiking read-out."""
    from snn_antenna.core import spec as specs

    study = Path(__file__).resolve().parents[1] / "studies" / "baseline_comparison.toml"
    spec = specs.load(study, list(sets), quick=True)
    del spec["spiking"]
    return spec


@pytest.fixture(scope="module")
def lab_set(tmp_path_factory):
    """The lab's rod at 1 kHz, its four materials at four distances, six repetitions, on a
    clock from 12 s: imported."""
    tmp = tmp_path_factory.mktemp("lab_set")
    sess = lab.session(1000.0, materials=tuple(lab.DECAY_S), repetitions=6, seed=4)
    (tmp / "recs").mkdir()
    lab.counts_csv(tmp / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0), 1000.0,
                   origin_s=12.0)
    labels = lab.labels_csv(tmp / "labels.csv", sess, "r1", origin_s=12.0)
    with open(labels, "a") as table:          # a label where nothing rang: left out at import
        table.write("r1,12.300000,26,wood,9\n")
    code, err = run_cli(tmp / "recs", labels, "--out", tmp / "ds")
    assert code == 0, err
    return recorded.open_bench(tmp / "ds")


def test_the_labs_antenna_is_fitted_from_its_calibration_labels_only(lab_set):
    """Its falling law, a mode split where no frequency lies between the modes at every
    distance, and a decay-fit window that fits nearly every contact; the labels of the
    scored contacts never enter the fit."""
    from dataclasses import replace

    from snn_antenna.evaluation import antenna_fit
    from snn_antenna.studies import baseline_comparison

    plan = baseline_comparison.plan({**fft_spec(), "data": str(lab_set.path)})
    parts, fit = plan.parts, plan.parts.antenna
    slope = np.log10(lab.FAR_HZ / lab.NEAR_HZ) / (lab.FAR_CM - lab.NEAR_CM)
    assert fit.low_law[0] == pytest.approx(slope, rel=0.05)
    assert fit.low_law[1] == pytest.approx(np.log10(lab.NEAR_HZ) - slope * lab.NEAR_CM,
                                           abs=0.05)
    assert fit.r2_low > 0.99 and fit.distances_cm == (10.0, 18.0, 26.0, 34.0)
    assert max(fit.low_hz) > min(fit.high_hz)          # no one frequency between the modes
    assert 1 < fit.split_ratio < lab.HIGH_RATIO and fit.split_hz > lab.NEAR_HZ
    assert parts.processor.split_ratio == pytest.approx(fit.split_ratio, rel=1e-4)
    assert fit.fitted_fraction >= 0.95 and fit.low_identified_fraction == 1.0
    assert fit.repetitions == tuple(parts.calibration_repetitions)
    assert any(line.startswith("fitted: events.split_hz") for line in plan.left_out)
    assert "generat" not in plan.spec["description"]
    # a silent low band reads where the calibration contacts it stayed silent for were struck
    labels = np.array([10.0, 34.0, 34.0, 26.0])
    assert fit.silent_cm(np.array([False, True, True, False]), labels)[0] == 34.0
    assert fit.silent_cm(np.zeros(4, bool), labels)[0] == np.mean(fit.range_cm)
    # the scored contacts' labels scrambled: the same fit
    ds = lab_set.dataset
    held = np.isin(ds["repetition"].values, parts.calibration_repetitions)
    scrambled = ds.copy()
    distance = ds["distance_cm"].values.copy()
    distance[~held] = np.random.default_rng(0).permutation(distance[~held])
    scrambled["distance_cm"] = ("event", distance)
    like = replace(parts.processor, split_hz=55.0, split_ratio=None)
    assert antenna_fit.fit(scrambled, held, like, "x") == antenna_fit.fit(ds, held, like, "x")


def test_the_tuned_coders_levels_are_fitted_on_the_calibration_recordings(lab_set):
    """The tuned bank's coder threshold is the channels' quiet rms before the trigger and
    its analog gain (the level coder's step) brings the channels' median peak to the
    coder's range, both measured on the calibration contacts alone and named as fitted;
    the lab's rod is louder and noisier in its channels than the bench's rod the typed
    levels suit, and so are the hand-set high and rod bands; on the generated bench set the
    typed levels stay."""
    from snn_antenna.core import spec as specs
    from snn_antenna.evaluation import antenna_fit
    from snn_antenna.studies import baseline_comparison
    from snn_antenna.readout.spiking_decoders import SpikingPlan
    from snn_antenna.studies.baseline_comparison.plan import fit_to_rate

    study = Path(__file__).resolve().parents[1] / "studies" / "baseline_comparison.toml"
    typed = specs.load(study, [], quick=True)
    plan = baseline_comparison.plan({**typed, "data": str(lab_set.path)})
    fit, tuned = plan.parts.antenna, plan.spec["spiking"]["tuned"]
    threshold = tuned["tuning"]["threshold_g"]
    assert threshold == pytest.approx(antenna_fit.NOISE_MULTIPLE * fit.coder_noise_g, rel=1e-4)
    assert threshold > typed["spiking"]["tuned"]["tuning"]["threshold_g"]
    for table in (tuned["tuning"], tuned["coders"]["analog"]):
        assert table["coder_options"]["gain"] == pytest.approx(
            table["coder_amplitude"] / (fit.coder_peak_g - threshold), rel=1e-4)
        assert table["coder_options"]["gain"] < typed["spiking"]["tuned"]["coders"]["analog"][
            "coder_options"]["gain"] / 10       # the typed gain holds these peaks at its ceiling
    # the sign and level coders above the channels' noise, as a hand-set band's
    # square wave; the level coder's top level still at the channels' peak
    quantised = antenna_fit.BAND_NOISE_MULTIPLE * fit.coder_noise_g
    for name in ("square", "delta"):
        assert tuned["coders"][name]["threshold_g"] == pytest.approx(quantised, rel=1e-4)
    delta = tuned["coders"]["delta"]["coder_options"]
    top = (2 ** (delta["levels"] - 1) - 1) * delta["step_g"]       # ratio 2
    assert top == pytest.approx(fit.coder_peak_g - quantised, rel=1e-4)
    assert "threshold_g" not in tuned["coders"]["analog"]        # the tuning's, as fitted
    for key in ("tuning.threshold_g", "tuning.coder_options.gain", "coders.square.threshold_g",
                "coders.delta.threshold_g", "coders.delta.coder_options.step_g",
                "coders.analog.coder_options.gain"):
        assert any(line.startswith(f"fitted: spiking.tuned.{key} ") for line in
                   plan.left_out), (key, plan.left_out)
    assert [r for r in fit.rows() if "tuned channels" in r[0]]
    # the scored contacts' recordings silenced: the same levels
    ds = lab_set.dataset
    held = np.isin(ds["repetition"].values, plan.parts.calibration_repetitions)
    quiet = ds.copy()
    counts = ds["counts"].values.copy()
    counts[~held] = 2 ** (int(ds.attrs["adc_bits"]) - 1)
    quiet["counts"] = (ds["counts"].dims, counts)
    fitted = fit.applied(typed)[0]
    at_rate = fit_to_rate(fitted, lab_set.rate_hz)[0]
    again = antenna_fit.fit_coder(fit, quiet, held, fitted, at_rate)[0]
    bank, _ = SpikingPlan(**at_rate["spiking"]).build(lab_set.rate_hz)
    assert antenna_fit.fit_band_thresholds(quiet, held, fitted, bank, "x") == \
        antenna_fit.fit_band_thresholds(ds, held, fitted, bank, "x")
    # the hand-set bands: a typed threshold within the band's quiet level (its rms before
    # the trigger on the calibration contacts) is raised to 5x that level, named as fitted;
    # one above it (the low band's) stays as typed
    bands, typed_bands = plan.spec["spiking"]["bank"]["bands"], typed["spiking"]["bank"]["bands"]
    rate = float(ds.attrs["rate_hz"])
    calibration = ds["counts"].values[held][:, :int(round(bank.duration_s * rate))]
    rms, _ = antenna_fit.channel_levels(calibration, bank.bands, rate, int(ds.attrs["adc_bits"]),
                                        float(ds.attrs["full_scale_g"]),
                                        int(round(float(ds.attrs["pre_trigger_s"]) * rate)))
    for name, level in zip(bank.bands, rms):
        named = any(line.startswith(f"fitted: spiking.bank.bands.{name}.threshold_g ")
                    for line in plan.left_out)
        if typed_bands[name]["threshold_g"] < level:
            assert named and bands[name]["threshold_g"] == pytest.approx(
                antenna_fit.BAND_NOISE_MULTIPLE * level, rel=1e-4), name
        else:
            assert not named and bands[name]["threshold_g"] == typed_bands[name]["threshold_g"]
    assert bands["low"]["threshold_g"] == typed_bands["low"]["threshold_g"]
    assert (again.coder_noise_g, again.coder_peak_g) == (fit.coder_noise_g, fit.coder_peak_g)
    # the generated bench set: nothing fitted, the typed levels as they are
    generated = baseline_comparison.plan(typed)
    assert generated.spec["spiking"]["tuned"] == typed["spiking"]["tuned"]


def test_the_rate_centroid_keeps_to_the_dominant_resonators_neighbourhood_when_that_fits():
    """Contacts whose low mode drives the resonators around it and an overtone drives a few
    at twice its frequency: the centroid over every resonator reads them off the law, the
    neighbourhood fitted on the calibration contacts reads them on it; without the overtone
    every resonator is kept (the wider on a tie)."""
    from snn_antenna.evaluation import antenna_fit

    hz = np.geomspace(9.6, 75.0, 24)
    law = (np.log10(lab.FAR_HZ / lab.NEAR_HZ) / (lab.FAR_CM - lab.NEAR_CM),
           np.log10(lab.NEAR_HZ) - np.log10(lab.FAR_HZ / lab.NEAR_HZ) / (lab.FAR_CM - lab.NEAR_CM)
           * lab.NEAR_CM, 22.0)
    distance = np.repeat([18.0, 22.0, 26.0], 5)
    mode = lab.low_hz(distance)[:, None]
    counts = 10 * np.exp(-np.log(hz[None, :] / mode) ** 2 / 0.01)
    overtone = counts + 4 * np.exp(-np.log(hz[None, :] / (2 * mode)) ** 2 / 0.01)
    around, line = antenna_fit.centroid_around(overtone, hz, distance, law)
    assert around is not None and line.startswith("fitted: the rate centroid"), line
    error = {a: np.abs(CentroidDistance(hz, law, a).fit(overtone).predict(overtone) - distance)
             for a in (None, around)}
    assert error[around].max() < 0.5 < error[None].min(), error
    assert antenna_fit.centroid_around(counts, hz, distance, law)[0] is None


def test_the_neighbourhood_centres_on_the_resonator_driven_most_not_the_one_firing_most():
    """A far contact of a long-ringing material: the low mode drives the low resonators a few
    spikes each over its few cycles, a weak harmonic drives the top one on more spikes than
    any of them (it has five times the cycles): the neighbourhood stays on the low mode."""
    hz = np.geomspace(12.0, 93.8, 24)
    law = (np.log10(15.0 / 75.0) / 24.0, np.log10(75.0) - np.log10(15.0 / 75.0) / 24.0 * 10,
           22.0)
    counts = np.zeros((1, 24))
    counts[0, 1:6] = [6, 6, 6, 4, 2]            # 13-19 Hz: the 15 Hz mode at 34 cm
    counts[0, -1] = 12                          # 94 Hz
    read = CentroidDistance(hz, law, 2.0).fit(counts).predict(counts)[0]
    assert read == pytest.approx(34.0, abs=2.0), read


def test_the_dominant_resonators_bias_is_fitted_into_the_law_it_reads_through():
    """Contacts whose most active resonator sits one channel below their low mode (a
    resonator fires most for input somewhat above its own frequency): through the law as
    fitted on the spectra they read about a channel's distance off; through the law with the
    bias fitted on the calibration contacts they read within half a channel. Contacts that
    left the low band silent do not enter the bias, and none driven leaves the law as is."""
    from snn_antenna.evaluation import antenna_fit
    from snn_antenna.readout.spiking import DominantNeuronDistance

    hz = np.geomspace(9.6, 75.0, 24)
    slope = np.log10(lab.FAR_HZ / lab.NEAR_HZ) / (lab.FAR_CM - lab.NEAR_CM)
    law = (slope, np.log10(lab.NEAR_HZ) - slope * lab.NEAR_CM, 22.0)
    distance = np.repeat([10.0, 14.0, 18.0, 22.0, 26.0, 30.0, 34.0], 3)
    below = np.searchsorted(hz, lab.low_hz(distance)) - 2      # a channel below the mode
    counts = np.zeros((len(distance), len(hz)))
    counts[np.arange(len(distance)), below] = 9
    counts[np.arange(len(distance)), below + 1] = 4
    silent = np.vstack([counts, np.zeros((2, len(hz)))])
    fitted, line = antenna_fit.dominant_bias(silent, hz, np.r_[distance, 10.0, 10.0], law)
    assert line.startswith("fitted: the dominant resonator's bias") and "21 calibration" in line
    assert fitted[0] == law[0] and fitted[2] == law[2] and fitted[1] < law[1]
    step_cm = np.log10(hz[1] / hz[0]) / abs(slope)
    error = {name: np.abs(DominantNeuronDistance(hz, at).fit(counts).predict(counts) - distance)
             for name, at in (("as fitted", law), ("with its bias", fitted))}
    assert np.sqrt(np.mean(error["as fitted"] ** 2)) > 0.9 * step_cm
    assert error["with its bias"].max() < 0.5 * step_cm + 0.1, error
    assert antenna_fit.dominant_bias(np.zeros((3, 24)), hz, [10.0, 20.0, 30.0], law)[0] == law


def test_the_distance_mlps_penalty_is_chosen_on_the_calibration_repetitions_alone():
    """Few contacts and many inputs, one of them the distance: the penalty chosen by reading
    each calibration repetition with the MLP trained on the others reads new contacts better
    than the typed one; one repetition leaves the typed penalty."""
    from dataclasses import replace

    from threadpoolctl import threadpool_limits

    from snn_antenna.evaluation import antenna_fit
    from snn_antenna.readout import baselines as bl

    rng = np.random.default_rng(3)

    def contacts(n):
        d = rng.choice([10.0, 18.0, 26.0, 34.0], n)
        return np.column_stack([d + rng.normal(0, 1.0, n), rng.normal(0, 1, (n, 40))]), d

    X, d = contacts(48)
    repetition = np.repeat([0, 1, 2], 16)
    mlp = bl.Mlp(max_iter=200)
    alpha, line = antenna_fit.distance_alpha(X, d, repetition, mlp, (8,), "the test's MLP")
    assert alpha in antenna_fit.DISTANCE_ALPHAS and alpha > mlp.alpha, line
    assert line.startswith(f"fitted: the test's MLP's L2 penalty {alpha:g} "), line
    new, truth = contacts(200)

    def rmse(a):
        with threadpool_limits(1):
            model = bl.sized_for(bl.regressor_pipeline(replace(mlp, alpha=a), (8,), 0),
                                 len(d)).fit(X, d)
        return float(np.sqrt(np.mean((model.predict(new) - truth) ** 2)))

    assert rmse(alpha) < 0.7 * rmse(mlp.alpha), (alpha, rmse(alpha), rmse(mlp.alpha))
    assert antenna_fit.distance_alpha(X, d, np.zeros(48), mlp, (8,))[0] == mlp.alpha


def test_the_fft_comparison_on_the_labs_recordings_reads_as_one_feature_does(lab_set,
                                                                             tmp_path):
    """The comparison's FFT and parametric half on the lab's rod: the decay fits nearly every
    contact, the parametric and the full-spectrum MLP read the material within 5 points of
    the one-feature decay read-out and the low peak's regression the distance within 2× the
    peak-frequency read-out's rmse, on the same splits; the page says what the data is."""
    from snn_antenna.studies import baseline_comparison
    from snn_antenna.studies.contract import Options

    spec = fft_spec(f"stimulus.cache_dir=\"{tmp_path / 'cache'}\"", "evaluation.nmf_dims=[3]")
    summary = baseline_comparison.run(baseline_comparison.plan({**spec, "data":
                                                                str(lab_set.path)}),
                                      tmp_path / "run", Options(quick=True),
                                      log=lambda *a: None)
    assert summary["data"]["skipped"]["no_decay_fit"] <= 0.05 * lab_set.n_events
    scores = lab.against_one_feature(tmp_path / "run", lab_set)
    material, decay, _ = scores["mlp_parametric_material"]
    assert material >= decay - 0.05, scores
    # the full spectrum, each scaled to its peak: its shape carries the decay time
    material, decay, _ = scores["mlp_spectrum_material"]
    assert material >= decay - 0.05, scores
    distance, peak, _ = scores["linear_low_peak"]
    assert distance <= 2 * peak, scores
    assert summary["two_material"] is None or summary["two_material"]["materials"]
    assert_reports_recorded_data(tmp_path / "run")
    page = (tmp_path / "run" / "report.html").read_text()
    assert "at import: no contact" in page and "26 cm" in page


@pytest.mark.parametrize("rate", [1000.0, 2000.0])
def test_check_fails_exactly_when_the_run_would(tmp_path, rate):
    """A material labelled in one repetition only: some split would train or test without
    it. `--check` refuses it in one line, as the run does, before any work; the same set
    with every material in every repetition passes both."""
    from snn_antenna.cli import main as cli

    sess = lab.session(rate, materials=("rubber", "wood"), distances_cm=(10.0, 30.0),
                       repetitions=4, seed=6)
    (tmp_path / "recs").mkdir()
    lab.counts_csv(tmp_path / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                   rate, 0.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    lines = labels.read_text().splitlines()
    (tmp_path / "few.csv").write_text("\n".join(
        [lines[0]] + [line for line in lines[1:] if not (",rubber," in line and
                                                        not line.endswith(",0"))]) + "\n")
    study = str(Path(__file__).resolve().parents[1] / "studies" / "baseline_comparison.toml")
    for name, table, code in (("few", tmp_path / "few.csv", 2), ("all", labels, 0)):
        imported(tmp_path, tmp_path / "recs", table, out=name)
        args = ["run", study, "--data", str(tmp_path / name), "--quick", "--set",
                "evaluation.pipelines=[\"material\"]", "--set",
                "spiking.tuned.calibration_repetitions=2", "--out", str(tmp_path / f"run_{name}")]
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            assert cli([*args, "--check"]) == code
        if code:
            assert "evaluation.test_fraction" in err.getvalue() or "data" in err.getvalue()
            with contextlib.redirect_stderr(io.StringIO()):
                assert cli(args) == code
            assert not (tmp_path / f"run_{name}" / "summary.json").exists()


def test_a_site_whose_low_peak_never_moves_has_a_finite_spread_ratio():
    """Every scored contact of a site on one FFT bin (the lab's rod at 2 kHz): the ratio of
    the peaks' spreads is pooled over the sites, and None when the low peak never moves."""
    from snn_antenna.evaluation.signal import spread_ratio

    assert spread_ratio([2.0, 4.0], [0.0, 1.0]) == pytest.approx(6.0)
    assert spread_ratio([2.0, 4.0], [0.0, 0.0]) is None
    assert spread_ratio([], []) is None


def test_24_bit_pcm_is_read_as_24_bit_counts(tmp_path):
    """3-byte PCM (which cannot be memory-mapped) holds a 24-bit converter's counts."""
    sess = lab.session(2000.0, materials=("rubber", "wood"), distances_cm=(10.0, 30.0),
                       repetitions=1, seed=12)
    counts = lab.adc_counts(sess.g[:, :2], 24, 16.0)
    raw = b"".join(int(v).to_bytes(3, "little", signed=True)
                   for v in (counts - 2 ** 23).ravel())
    header = (b"RIFF" + struct.pack("<I", 36 + len(raw)) + b"WAVE" + b"fmt "
              + struct.pack("<IHHIIHH", 16, 1, 2, 2000, 2000 * 6, 6, 24)
              + b"data" + struct.pack("<I", len(raw)))
    (tmp_path / "recs").mkdir()
    (tmp_path / "recs" / "r1.wav").write_bytes(header + raw)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1")
    source, _ = imported(tmp_path, tmp_path / "recs", labels, "--full-scale-g", "16")
    assert source.adc_bits == 24
    assert_labelled_right(source, sess, 0.0)
    onset = int(round(source.dataset["onset_s"].values[0] * 2000.0))
    assert np.array_equal(source.dataset["counts"].values[0],
                          counts[onset - 100:onset - 100 + 2100])


def test_the_imported_windows_carry_the_labs_material_difference(tmp_path, sess):
    """The reference the studies are held to: a one-feature read-out of the decay time on the
    imported windows (a threshold between neighbouring materials' medians, set on the first
    repetition, read on the second) reads the lab's materials, which differ in nothing else."""
    (tmp_path / "recs").mkdir()
    lab.counts_csv(tmp_path / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                   2000.0, origin_s=7.0)
    labels = lab.labels_csv(tmp_path / "labels.csv", sess, "r1", origin_s=7.0)
    source, _ = imported(tmp_path, tmp_path / "recs", labels)
    ds = source.dataset
    g = (ds["counts"].values.astype(float) - 512) * 36.0 / 1024
    tau = np.asarray([lab.decay_time_s(ev, 2000.0, source.pre_trigger_s) for ev in g])
    material = ds["material"].values.astype(str)
    train = ds["repetition"].values == 0
    names = sorted(set(material), key=lambda m: np.median(tau[train & (material == m)]))
    medians = [np.median(tau[train & (material == m)]) for m in names]
    edges = np.sqrt(np.multiply(medians[1:], medians[:-1]))
    read = np.asarray(names)[np.searchsorted(edges, tau)]
    assert np.mean(read[~train] == material[~train]) >= 0.9


@settings(max_examples=40, deadline=None)
@given(pair=st.one_of(st.none(), st.text(max_size=3), st.lists(st.text(max_size=4), max_size=3),
                      st.lists(st.integers(), min_size=2, max_size=2)))
def test_a_two_material_pair_is_two_different_names_or_refused_by_its_field(pair):
    from snn_antenna.evaluation.crossval import Evaluation

    good = (isinstance(pair, list) and len(pair) == 2 and all(isinstance(m, str) and m
                                                               for m in pair)
            and pair[0] != pair[1])
    if good:
        assert Evaluation(two_materials=pair).two_materials == pair
    else:
        with pytest.raises(SpecError) as refusal:
            Evaluation(two_materials=pair)
        assert refusal.value.field.split(".")[0] == "two_materials"


@settings(max_examples=40, deadline=None)
@given(ratio=st.one_of(st.none(), st.floats(max_value=1e6), st.just(float("nan")),
                      st.just(float("inf"))))
def test_a_mode_split_ratio_is_above_one_or_refused_by_its_field(ratio):
    from snn_antenna.readout.events import EventProcessor

    if ratio is None or (np.isfinite(ratio) and ratio > 1):
        assert EventProcessor(split_ratio=ratio).split_ratio == ratio
    else:
        with pytest.raises(SpecError) as refusal:
            EventProcessor(split_ratio=ratio)
        assert refusal.value.field == "split_ratio"


def test_peaks_that_never_move_give_no_statistic_rather_than_an_infinite_one():
    """Every contact of each site on one FFT bin and the law through two sites exact: the
    residual spreads are zero; the ratios and the precision have no finite value (None)."""
    import xarray as xr

    from snn_antenna.evaluation.signal import signal_statistics
    from snn_antenna.readout.events import PARAMETERS

    distance = np.repeat([10.0, 30.0], 6)
    f_low = np.where(distance == 10.0, 60.0, 12.0)
    f_high = np.where(distance == 10.0, 222.0, 44.0)
    params = np.column_stack([f_low, np.ones(12), 0.05 + 0.01 * np.arange(12) % 3,
                              f_high, np.ones(12), np.full(12, 0.02)])
    features = xr.Dataset(
        {"params": (("event", "parameter"), params)},
        coords={"parameter": list(PARAMETERS), "distance_cm": ("event", distance),
                "position": ("event", (distance == 30.0).astype(int)),
                "material": ("event", np.tile(["rubber", "wood"], 6))})
    stats = signal_statistics(features)
    assert stats["spread_ratio_high_to_low"] is None
    assert stats["spread_ratio_high_to_low_hz"] is None
    assert stats["single_contact_precision_mm"] == 0.0
    json.dumps(stats, allow_nan=False)


def test_a_rod_whose_first_mode_does_not_move_has_no_law_and_is_refused(tmp_path):
    """Every distance ringing at one frequency: no law to invert, refused at the plan (so at
    `--check`) in one line naming the data set."""
    from snn_antenna.studies import baseline_comparison

    sess = lab.session(1000.0, materials=("rubber", "wood"), distances_cm=(10.0, 30.0),
                       repetitions=3, seed=5, law_hz=(30.0, 30.0))
    (tmp_path / "recs").mkdir()
    lab.counts_csv(tmp_path / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                   1000.0, 0.0)
    imported(tmp_path, tmp_path / "recs", lab.labels_csv(tmp_path / "labels.csv", sess, "r1"))
    with pytest.raises(SpecError) as refusal:
        baseline_comparison.plan({**fft_spec(), "data": str(tmp_path / "ds")})
    assert refusal.value.field == "data" and "moves with distance" in str(refusal.value)
