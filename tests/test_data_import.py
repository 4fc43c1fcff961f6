"""`snn-antenna data import`: recordings and a labels table become the generator's data-set
layout with their provenance; contacts left out are listed; bad input is one line and imports
nothing."""
import contextlib
import csv
import hashlib
import io
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.io import wavfile

from data_helpers import RATE, ringing_counts, write_labels, write_record
from snn_antenna.cli import main
from snn_antenna.core.errors import SpecError
from snn_antenna.sources import bench, recorded
from snn_antenna.sources.source import BenchSet

ONSETS = [1.0, 2.5, 4.0, 5.5, 7.0, 8.5]
DISTANCES = [10.0, 20.0, 30.0, 10.0, 20.0, 30.0]
MATERIALS = ["wood", "wood", "wood", "aluminium", "aluminium", "aluminium"]
DURATION_S = 10.0


def run_cli(*argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["data", "import", *map(str, argv)])
    return code, err.getvalue()


def label_rows(name="run1", onsets=ONSETS):
    return [(name, o, d, m, i % 3) for i, (o, d, m) in enumerate(zip(onsets, DISTANCES,
                                                                       MATERIALS))]


@pytest.fixture
def counts():
    return ringing_counts(ONSETS, DISTANCES, DURATION_S)


@pytest.fixture
def imported(tmp_path, counts):
    write_record(tmp_path / "recs" / "run1", counts)
    write_labels(tmp_path / "labels.csv", label_rows())
    code, err = run_cli(tmp_path / "recs", tmp_path / "labels.csv", "--out", tmp_path / "ds")
    assert code == 0, err
    return tmp_path


def test_an_import_has_the_generators_layout_and_every_contact_window(imported, counts):
    source = recorded.open_bench(imported / "ds")
    assert isinstance(source, BenchSet) and isinstance(bench.BenchSpec(), BenchSet)
    ds = bench.load(source)
    generated = bench.generate(bench.BenchSpec(materials=["wood"], positions_cm=[10.0],
                                               repetitions=1, duration_s=0.1))
    assert set(generated.data_vars) == set(ds.data_vars)
    assert set(generated.coords) <= set(ds.coords)
    assert set(generated.attrs) - {"spec"} <= set(ds.attrs)
    assert ds["counts"].dims == generated["counts"].dims
    assert list(ds["material"].values) == MATERIALS
    assert list(ds["distance_cm"].values) == DISTANCES
    assert list(ds["position"].values) == [0, 1, 2, 0, 1, 2]
    assert list(ds["repetition"].values) == [0, 1, 2, 0, 1, 2]
    pre = int(0.05 * RATE)
    for k, onset in enumerate(ONSETS):
        start = int(round(onset * RATE)) - pre
        assert np.array_equal(ds["counts"].values[k], counts[start:start + 1050])
    assert source.n_events == 6 and source.rate_hz == RATE
    assert source.materials == ["aluminium", "wood"]


def test_the_provenance_holds_the_sha256_of_every_raw_file_and_of_the_labels(imported):
    meta = json.loads((imported / "ds" / "import.json").read_text())
    sha = lambda p: hashlib.sha256(p.read_bytes()).hexdigest()      # noqa: E731
    assert meta["labels"]["sha256"] == sha(imported / "labels.csv")
    files = {f["file"]: f["sha256"] for f in meta["recordings"][0]["files"]}
    assert set(files) == {"meta.json", "samples.bin", "raw.bin"}
    for name, digest in files.items():
        assert digest == sha(imported / "recs" / "run1" / name)
    rows = dict(recorded.open_bench(imported / "ds").provenance_rows())
    assert meta["labels"]["sha256"] in rows["labels"]
    assert rows["contacts imported"].startswith("6 of 6")


def test_a_changed_raw_file_is_a_different_data_set(imported, counts):
    key = recorded.open_bench(imported / "ds").key()
    changed = counts.copy()
    changed[-1] += 1
    write_record(imported / "recs2" / "run1", changed)
    code, err = run_cli(imported / "recs2", imported / "labels.csv", "--out", imported / "ds2")
    assert code == 0, err
    assert recorded.open_bench(imported / "ds2").key() != key


def test_every_file_format_gives_the_same_contacts(tmp_path, counts):
    reference = None
    for name, write in (
            ("run1.npy", lambda p: np.save(p, counts)),
            ("run1.npz", lambda p: np.savez(p, counts=counts, rate_hz=RATE)),
            ("run1.csv", lambda p: p.write_text("t_s,x,y\n" + "".join(
                f"{i / RATE:.6f},{x},{y}\n" for i, (x, y) in enumerate(counts)))),
            ("run1.wav", lambda p: wavfile.write(p, int(RATE), (counts * 64 - 32768).astype(
                np.int16)))):
        folder = tmp_path / name.replace(".", "_")
        folder.mkdir()
        write(folder / name)
        write_labels(tmp_path / f"{name}.labels.csv", label_rows(name))
        code, err = run_cli(folder, tmp_path / f"{name}.labels.csv", "--out",
                            tmp_path / f"ds_{name}", "--rate", RATE)
        assert code == 0, f"{name}: {err}"
        ds = recorded.open_bench(tmp_path / f"ds_{name}").dataset
        events = ds["counts"].values.astype(float)
        if name.endswith(".wav"):
            events = events / 64             # 16-bit PCM of the 10-bit counts
            assert ds.attrs["adc_bits"] == 16
        if reference is None:
            reference = events
        assert ds.sizes["event"] == 6
        assert np.array_equal(events, reference), name


def test_every_contact_left_out_is_listed_by_recording_time_and_line(tmp_path):
    onsets = ONSETS + [9.3]                      # 9.3 s: its window runs past the end
    distances = DISTANCES + [20.0]
    counts = ringing_counts(onsets, distances, DURATION_S)
    counts[int(4.2 * RATE), 0] = 1023            # the 4.0 s contact clipped at the rail
    seq = np.delete(np.arange(len(counts)), np.arange(int(5.8 * RATE), int(5.8 * RATE) + 7))
    counts = np.delete(counts, np.arange(int(5.8 * RATE), int(5.8 * RATE) + 7), axis=0)
    write_record(tmp_path / "recs" / "run1", counts, seq)   # 7 samples lost in the 5.5 s one
    rows = label_rows()
    rows[1] = ("run1", 3.0, 20.0, "wood", 1)                # no contact at 3.0 (it is at 2.5)
    rows.append(("run1", 9.3, 20.0, "wood", 5))
    write_labels(tmp_path / "labels.csv", rows)
    code, err = run_cli(tmp_path / "recs", tmp_path / "labels.csv", "--out", tmp_path / "ds")
    assert code == 0, err
    with open(tmp_path / "ds" / "exclusions.csv") as f:
        listed = {(r["reason"], round(float(r["t_s"]), 2), r["label_line"])
                  for r in csv.DictReader(f)}
    assert listed == {("no_contact", 3.0, "3"), ("unlabelled", 2.5, ""), ("clipped", 4.0, "4"),
                      ("gap", 5.5, "5"), ("beyond_end", 9.3, "8")}
    meta = json.loads((tmp_path / "ds" / "import.json").read_text())
    assert meta["counts"]["events"] == 3
    assert meta["counts"]["excluded"] == {"no_contact": 1, "unlabelled": 1, "gap": 1,
                                          "clipped": 1, "beyond_end": 1}
    assert meta["recordings"][0]["lost_samples"] == 7
    assert "3 contacts imported" in err and "1 gap" in err
    ds = recorded.open_bench(tmp_path / "ds").dataset
    assert list(ds["onset_s"].values) == [1.0, 7.0, 8.5]


# -- bad data: one line, exit 2, nothing written -------------------------------------------------
def _good(tmp_path, counts):
    write_record(tmp_path / "recs" / "run1", counts)
    write_labels(tmp_path / "labels.csv", label_rows())
    return tmp_path / "recs", tmp_path / "labels.csv"


def refused(tmp_path, recs, labels, *extra) -> str:
    code, err = run_cli(recs, labels, "--out", tmp_path / "ds", *extra)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("snn-antenna: error: "), err
    assert not (tmp_path / "ds").exists()
    return err


@pytest.mark.parametrize("row, named", [
    (("run1", 12.0, 10, "wood", 9), "labels.csv line 8 onset_s"),      # outside the recording
    (("run1", -1.0, 10, "wood", 9), "labels.csv line 8 onset_s"),
    (("run1", 9.0, 10, "Marble", 9), "labels.csv line 8 material"),    # not a name
    (("run1", 9.0, 60, "wood", 9), "labels.csv line 8 distance_cm"),
    (("run1", 1.0, 10, "wood", 9), "labels.csv line 8 onset_s"),       # duplicated contact
    (("run1", 9.0, 10, "wood", 0), "labels.csv line 8 repetition"),    # duplicated repetition
    (("run2", 9.0, 10, "wood", 9), "labels.csv line 8 recording"),
    (("run1", "soon", 10, "wood", 9), "labels.csv line 8 onset_s"),
])
def test_a_bad_label_names_the_file_line_and_field(tmp_path, counts, row, named):
    recs, labels = _good(tmp_path, counts)
    write_labels(labels, label_rows() + [row])
    assert named in refused(tmp_path, recs, labels)


def test_a_rate_that_disagrees_with_the_header_is_refused(tmp_path, counts):
    recs, labels = _good(tmp_path, counts)
    err = refused(tmp_path, recs, labels, "--rate", 2000)
    assert "--rate" in err and "meta.json rate_hz" in err and "run1" in err


def test_an_empty_folder_is_refused(tmp_path):
    (tmp_path / "recs").mkdir()
    write_labels(tmp_path / "labels.csv", label_rows())
    assert "empty" in refused(tmp_path, tmp_path / "recs", tmp_path / "labels.csv")


def test_a_truncated_recording_is_refused(tmp_path, counts):
    recs, labels = _good(tmp_path, counts)
    samples = recs / "run1" / "samples.bin"
    samples.write_bytes(samples.read_bytes()[:-5])
    err = refused(tmp_path, recs, labels)
    # the recording reader names the field the sizes disagree with, and the file
    assert "n_samples_written" in err and "samples.bin holds" in err


def test_a_recording_that_ends_too_soon_for_its_labels_is_refused(tmp_path, counts):
    recs, labels = _good(tmp_path, counts[:int(8 * RATE)])
    assert "labels.csv line 7 onset_s" in refused(tmp_path, recs, labels)


# The Hypothesis property: each mutation below makes a valid import invalid.
def _drop_column(rows, header, draw):
    i = draw(st.integers(1, 3))                 # a required column
    return [r[:i] + r[i + 1:] for r in rows], header[:i] + header[i + 1:]


def _garbage_cell(rows, header, draw):
    r, c = draw(st.integers(0, len(rows) - 1)), draw(st.integers(1, 4))
    rows[r] = rows[r][:c] + (draw(st.sampled_from(["", "nan", "x", "inf", "-3", "1e999", "½"]))
                             ,) + rows[r][c + 1:]
    if c == 3:                                   # not a material name
        rows[r] = rows[r][:3] + (draw(st.sampled_from(["", "3d", "Wood", "nan", "pvc foam"])),) + \
            rows[r][4:]
    if c == 4 and rows[r][4] in ("", "nan", "inf", "1e999"):
        rows[r] = rows[r][:4] + ("-1",)
    return rows, header


def _out_of_recording(rows, header, draw):
    r = draw(st.integers(0, len(rows) - 1))
    t = draw(st.one_of(st.floats(DURATION_S, 1e9), st.floats(-1e9, -1e-9)))
    rows[r] = (rows[r][0], t) + rows[r][2:]
    return rows, header


def _duplicate(rows, header, draw):
    r = draw(st.integers(0, len(rows) - 1))
    return rows + [rows[r]], header


def _short_row(rows, header, draw):
    r = draw(st.integers(0, len(rows) - 1))
    rows[r] = rows[r][:draw(st.integers(1, 4))]
    return rows, header


def _unknown_column(rows, header, draw):
    return [r + ("1",) for r in rows], header + (draw(st.sampled_from(["speed", "t", "Onset"])),)


LABEL_MUTATIONS = [_drop_column, _garbage_cell, _out_of_recording, _duplicate, _short_row,
                   _unknown_column]


def _truncate_samples(folder: Path, draw):
    p = folder / "run1" / "samples.bin"
    p.write_bytes(p.read_bytes()[:-draw(st.integers(1, 15))])


def _damage_meta(folder: Path, draw):
    p = folder / "run1" / "meta.json"
    text = p.read_text()
    p.write_text(text[:int(draw(st.floats(0, 0.99)) * len(text))])   # its length varies


def _wrong_rate(folder: Path, draw):
    p = folder / "run1" / "meta.json"
    meta = json.loads(p.read_text())
    meta["rate_hz"] = draw(st.sampled_from([0, -5, "fast", None]))
    p.write_text(json.dumps(meta))


def _foreign_file(folder: Path, draw):
    (folder / draw(st.sampled_from(["notes.txt", "run2.mp3", "x"]))).write_text("hello")


def _truncated_npy(folder: Path, draw):
    buf = io.BytesIO()
    np.save(buf, np.full((100, 2), 512, dtype=np.int16))
    data = buf.getvalue()
    (folder / "run2.npy").write_bytes(data[:draw(st.integers(0, len(data) - 1))])


def _truncated_wav(folder: Path, draw):
    buf = io.BytesIO()
    wavfile.write(buf, int(RATE), np.zeros((100, 2), dtype=np.int16))
    data = buf.getvalue()
    (folder / "run2.wav").write_bytes(data[:draw(st.integers(0, len(data) - 1))])


RECORDING_MUTATIONS = [_truncate_samples, _damage_meta, _wrong_rate, _foreign_file,
                       _truncated_npy, _truncated_wav]
BASE_COUNTS = ringing_counts(ONSETS, DISTANCES, DURATION_S)


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.data())
def test_malformed_labels_and_recordings_end_in_one_line_and_import_nothing(data):
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_record(tmp / "recs" / "run1", BASE_COUNTS)
        rows, header = [tuple(r) for r in label_rows()], ("recording", "onset_s",
                                                          "distance_cm", "material",
                                                          "repetition")
        if data.draw(st.booleans(), label="labels or recordings"):
            mutation = data.draw(st.sampled_from(LABEL_MUTATIONS))
            rows, header = mutation(list(rows), header, data.draw)
        else:
            data.draw(st.sampled_from(RECORDING_MUTATIONS))(tmp / "recs", data.draw)
        write_labels(tmp / "labels.csv", rows, header)
        code, err = run_cli(tmp / "recs", tmp / "labels.csv", "--out", tmp / "ds")
        assert code == 2, err
        assert err.count("\n") == 1 and err.startswith("snn-antenna: error: "), err
        assert "is not accepted" in err
        assert not (tmp / "ds").exists()


def test_a_study_refuses_a_folder_that_is_not_a_finished_import(imported):
    (imported / "ds" / "import.json").unlink()
    with pytest.raises(SpecError, match="import.json is missing"):
        recorded.open_bench(imported / "ds")
    with pytest.raises(SpecError, match="data"):
        bench.source_from_spec({"data": str(imported / "recs")})


# -- drives ---------------------------------------------------------------------------------------
def test_a_drive_is_kept_whole_with_its_speed_log_lost_samples_and_labelled_contacts(tmp_path):
    counts = ringing_counts([2.0, 5.0, 8.0], [19.0, 27.0, 12.0], DURATION_S, seed=3)
    lost = np.arange(int(5.2 * RATE), int(5.2 * RATE) + 4)
    seq = np.delete(np.arange(len(counts)), lost)
    write_record(tmp_path / "drives" / "drive1", np.delete(counts, lost, axis=0), seq,
                 speed_cm_s=12.0, speed_changes=[(int(6 * RATE), 20.0)])
    write_labels(tmp_path / "drive.csv", [("drive1", 2.0, 19.0, "wood"),
                                          ("drive1", 5.0, 27.0, ""),
                                          ("drive1", 8.0, 12.0, "aluminium")],
                 columns=("recording", "contact_s", "distance_cm", "material"))
    code, err = run_cli(tmp_path / "drives", tmp_path / "drive.csv", "--out", tmp_path / "ds")
    assert code == 0, err
    drives = recorded.open_drives(tmp_path / "ds")
    rec = drives.recording(0)
    assert rec.n_samples == len(counts) and rec.rate_hz == RATE
    kept = np.ones(len(counts), bool)
    kept[lost] = False
    assert np.array_equal(rec.samples[kept], counts[kept])
    assert np.array_equal(rec.samples[lost], np.repeat(counts[lost[0] - 1:lost[0]], 4, axis=0))
    assert list(np.flatnonzero(rec.meta["lost"])) == list(lost)
    speed = rec.meta["speed_cm_s"]     # the change applied at the 6000th sample received:
    change = int(6 * RATE) + len(lost)  # after the 4 lost ones, the board's sample 6004
    assert speed[0] == 12.0 and speed[change - 1] == 12.0 and speed[change] == 20.0
    # the 5 s contact's stretch holds the lost samples: left out, listed, never scored
    assert [(c.t_s, c.distance_cm, c.material) for c in rec.truth.contacts] == \
        [(2.0, 19.0, "wood"), (8.0, 12.0, "aluminium")]
    with open(tmp_path / "ds" / "exclusions.csv") as f:
        assert [(r["reason"], r["label_line"]) for r in csv.DictReader(f)] == [("gap", "3")]
    with pytest.raises(SpecError, match="imported bench recordings"):
        recorded.open_bench(tmp_path / "ds")


def write_imu_bag(path, counts: np.ndarray, topic: str = "/antenna/imu") -> None:
    """A ROS 2 bag with one Imu topic: the counts as accelerations (m/s²), stamped at RATE."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    from snn_antenna.data.inputs import STANDARD_GRAVITY
    from data_helpers import BOARD

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    g = BOARD.to_g(counts) * STANDARD_GRAVITY
    zeros = np.zeros(9)
    with Writer(path, version=8) as writer:
        connection = writer.add_connection(topic, "sensor_msgs/msg/Imu", typestore=store)
        for i, (x, y) in enumerate(g):
            ns = int(round(i * 1e9 / RATE))
            msg = t["sensor_msgs/msg/Imu"](
                header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](
                    sec=ns // 10**9, nanosec=ns % 10**9), frame_id="antenna"),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=zeros,
                angular_velocity=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                angular_velocity_covariance=zeros,
                linear_acceleration=t["geometry_msgs/msg/Vector3"](x=float(x), y=float(y),
                                                                   z=STANDARD_GRAVITY),
                linear_acceleration_covariance=zeros)
            writer.write(connection, ns, store.serialize_cdr(msg, "sensor_msgs/msg/Imu"))


def test_a_ros2_bags_imu_topic_gives_the_same_contacts(tmp_path, counts):
    pytest.importorskip("rosbags")
    write_imu_bag(tmp_path / "bags" / "run1", counts)
    write_labels(tmp_path / "labels.csv", label_rows())
    code, err = run_cli(tmp_path / "bags", tmp_path / "labels.csv", "--out", tmp_path / "ds",
                        "--rate", RATE)
    assert code == 0, err
    ds = recorded.open_bench(tmp_path / "ds").dataset
    assert ds.attrs["rate_hz"] == RATE and ds.attrs["adc_bits"] == 16
    assert list(ds["onset_s"].values) == ONSETS
    assert list(ds["material"].values) == MATERIALS
    meta = json.loads((tmp_path / "ds" / "import.json").read_text())
    assert meta["recordings"][0]["topic"] == "/antenna/imu"
    code, err = run_cli(tmp_path / "bags", tmp_path / "labels.csv", "--out", tmp_path / "ds2",
                        "--topic", "/other")
    assert code == 2 and "--topic" in err and "/antenna/imu" in err
