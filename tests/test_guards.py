"""Every probe of a hostile or careless user: one line naming the key or argument, exit status 2
(or the documented behaviour), no traceback, and no file of the user's touched."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.core import outputs
from snn_antenna.core.files import atomic_write
from snn_antenna.cli import main
from folder_runs import Run, checked, claimed
from snn_antenna.core.errors import SpecError

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = str(ROOT / "studies" / "quickstart.toml")
TUNING = str(ROOT / "studies" / "tuning_sweep.toml")
CLI = [sys.executable, "-m", "snn_antenna.cli"]


def refused(capsys, argv, *names):
    """Run the CLI in this process; it must refuse with status 2 and one line naming ``names``."""
    status = main(argv)
    err = capsys.readouterr().err
    assert status == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for name in names:
        assert name in err, err
    return err


# -- the spec ---------------------------------------------------------------------------------
@pytest.mark.parametrize("setting, names", [
    ("stimulus.contacts.5.distance_cm=25", ["stimulus.contacts.5", "an index in 0.."]),
    ("stimulus.contacts.x.distance_cm=25", ["stimulus.contacts.x"]),
    ("stimulus.contacts.-1.distance_cm=25", ["stimulus.contacts.-1"]),
    ("network.band_hz=[7,20,30]", ["network.band_hz", "a list of 2 numbers"]),
    ("network.n_neurons=true", ["network.n_neurons", "not true/false"]),
    ("preprocess.lowpass_hz=900", ["preprocess.lowpass_hz", "stimulus.rate_hz = 1000"]),
    ("readout.window_s=0", ["readout.window_s"]),
    ("network.band_hz=[7,600]", ["network.band_hz", "stimulus.rate_hz"]),
    ("network.band_hz=[5,900]", ["network.band_hz", "stimulus.rate_hz"]),
    ("stimulus.rate_hz=50", ["stimulus.rate_hz"]),
    ('preprocess.threshold="x"', ["preprocess.threshold", "a finite number"]),
    ("network=5", ["network = 5", "a table"]),
    ("stimulus.contacts.0=5", ["stimulus.contacts", "a table"]),
])
def test_bad_settings_are_refused_naming_the_users_key(tmp_path, capsys, setting, names):
    out = tmp_path / "out"
    err = refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(out), "--set", setting],
                  *names)
    for internal in ("cutoff_hz", "order =", "network.rate_hz"):
        assert internal not in err
    assert not out.exists()


@pytest.mark.parametrize("setting", ["sweep.workers=true", "sweep.workers=500"])
def test_worker_counts_are_capped_by_the_machine(tmp_path, capsys, setting):
    refused(capsys, ["run", TUNING, "--quick", "--out", str(tmp_path / "o"), "--set", setting],
            "sweep.workers")
    assert not (tmp_path / "o").exists()


FORTY_MILLION = ['axes.k={start=0.3,stop=2,num=400,scale="log"}',
                 "axes.b={start=0.2,stop=0.3,num=100}", "axes.I={start=0.1,stop=0.8,num=100}",
                 "axes.input_hz={start=2,stop=60,num=10}"]
BILLIONS = ['axes.k={start=0.3,stop=2,num=1000,scale="log"}',
            "axes.b={start=0.2,stop=0.3,num=1000}", "axes.I={start=0.1,stop=0.8,num=160}",
            "axes.input_hz={start=2,stop=60,num=10}"]


def test_a_long_sweep_shows_its_estimate_and_needs_yes(tmp_path, capsys):
    argv = ["run", TUNING, "--quick", "--out", str(tmp_path / "o")]
    for s in FORTY_MILLION:
        argv += ["--set", s]
    t0 = time.perf_counter()
    status = main(argv)
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert status == 2 and "Traceback" not in err
    assert "40,000,000 points" in err and "neuron-steps" in err and " h " in err
    assert "--yes" in err and "MB of results" in err
    assert elapsed < 2.0               # sized from the axes, nothing materialised
    assert not (tmp_path / "o").exists()


def test_a_grid_too_big_for_memory_is_refused_at_once_even_with_yes(tmp_path, capsys):
    argv = ["run", TUNING, "--quick", "--yes", "--out", str(tmp_path / "o")]
    for s in BILLIONS:
        argv += ["--set", s]
    t0 = time.perf_counter()
    err = refused(capsys, argv, "axes", "1,600,000,000 points")
    assert time.perf_counter() - t0 < 2.0      # no Dask cluster starts before the check
    assert "GB needed" in err


def test_refusals_come_before_brian2_and_show_no_traceback(tmp_path):
    """As the user runs it: a fresh process, one line, status 2, Brian2 never imported."""
    code = ("import sys; from snn_antenna.cli import main; s = main(sys.argv[1:]); "
            "print('brian2' in sys.modules); sys.exit(s)")
    for setting in ("network.n_neurons=true", "stimulus.contacts.5.distance_cm=25",
                    "preprocess.lowpass_hz=900"):
        proc = subprocess.run([sys.executable, "-c", code, "run", QUICKSTART, "--quick",
                               "--out", str(tmp_path / "o"), "--set", setting],
                              capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
        assert proc.stdout.strip() == "False"


# -- output folders ---------------------------------------------------------------------------
def test_out_that_is_a_file_or_under_a_file_is_refused_before_work(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("mine")
    refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(afile)], "--out", "file")
    refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(afile / "sub")], "--out",
            "is a file")
    assert afile.read_text() == "mine"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_out_that_cannot_be_written_is_refused(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(locked / "o")], "--out",
                "not writable")
        assert not os.path.lexists(locked / "o")
    finally:
        locked.chmod(0o700)


def fake_outputs(folder: Path, study: str, files=("report.html", "summary.json")) -> None:
    """A finished run of ``study`` into ``folder``, written as the toolkit writes (journaled)."""
    from snn_antenna.core.files import atomic_write, make_folder

    with claimed(folder, study):
        for name in files:
            atomic_write(folder / name, study)
        make_folder(folder / "results.zarr")
        atomic_write(folder / "results.zarr" / "zarr.json", "{}")


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


def test_another_studys_folder_or_the_users_files_are_refused_untouched(tmp_path, capsys):
    sweep_out = tmp_path / "sweep"
    fake_outputs(sweep_out, "tuning_sweep")
    before = snapshot(sweep_out)
    refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(sweep_out)], "--out",
            "'tuning_sweep' study", "--force")
    assert snapshot(sweep_out) == before
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("my notes")
    refused(capsys, ["run", QUICKSTART, "--quick", "--out", str(mine)], "--out", "notes.txt")
    assert (mine / "notes.txt").read_text() == "my notes" and len(list(mine.iterdir())) == 1


def test_force_clears_only_what_the_toolkit_wrote(tmp_path):
    folder = tmp_path / "o"
    fake_outputs(folder, "tuning_sweep")
    (folder / "notes.txt").write_text("my notes")
    with outputs.output_folder(folder, "quickstart", force=True) as prepared:
        assert (folder / "report.html").exists()             # not yet
        prepared.claim()
        assert sorted(p.name for p in folder.iterdir()) == [outputs.MANIFEST, "notes.txt"]
        atomic_write(folder / "report.html", "new report")
    manifest = outputs.read_manifest(folder)
    assert manifest["study"] == "quickstart" and manifest["files"] == ["report.html"]


def test_a_study_reruns_into_its_own_folder(tmp_path):
    folder = tmp_path / "o"
    fake_outputs(folder, "quickstart")
    with outputs.output_folder(folder, "quickstart") as prepared:   # no refusal
        assert (folder / "results.zarr" / "zarr.json").is_file()  # nothing removed
        prepared.claim()
        atomic_write(folder / "rate_map.png", "new figure")
    assert outputs.read_manifest(folder)["files"] == ["rate_map.png", "report.html",
                                                      "results.zarr", "summary.json"]


def test_quickstart_with_force_keeps_the_users_files(tmp_path, capsys):
    folder = tmp_path / "sweep"
    fake_outputs(folder, "tuning_sweep", files=("report.html", "summary.json", "maps.png"))
    (folder / "notes.txt").write_text("my notes")
    assert main(["run", QUICKSTART, "--quick", "--force", "--out", str(folder)]) == 0
    names = {p.name for p in folder.iterdir()}
    assert "maps.png" not in names and "results.zarr" not in names   # the sweep's, removed
    assert (folder / "notes.txt").read_text() == "my notes"          # the user's, kept
    assert outputs.read_manifest(folder)["study"] == "quickstart"
    assert json.loads((folder / "summary.json").read_text())["provenance"]["spec"]["study"] \
        == "quickstart"


def test_fresh_never_removes_a_store_the_toolkit_did_not_create(tmp_path, capsys):
    folder = tmp_path / "o"
    (folder / "results.zarr").mkdir(parents=True)
    (folder / "results.zarr" / "thesis.tex").write_text("mine")
    refused(capsys, ["run", TUNING, "--quick", "--fresh", "--force", "--out", str(folder)],
            "--fresh", "results.zarr")
    refused(capsys, ["run", TUNING, "--quick", "--fresh", "--out", str(folder)], "--out")
    assert (folder / "results.zarr" / "thesis.tex").read_text() == "mine"


# -- the emulator -----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["file", "folder", "symlink"])
def test_emulate_link_never_replaces_the_users_path(tmp_path, capsys, kind):
    link = tmp_path / "ttyANT"
    if kind == "file":
        link.write_text("precious")
    elif kind == "folder":
        link.mkdir()
    else:
        (tmp_path / "target").write_text("precious")
        link.symlink_to(tmp_path / "target")
    refused(capsys, ["emulate", "--pty", "--link", str(link), "--frames", "100",
                     "--peer-timeout", "1"], "link", "left as it is")
    assert not (tmp_path / "ttyANT.new").exists() and not (tmp_path / "ttyANT.new").is_symlink()
    if kind == "file":
        assert link.read_text() == "precious" and not link.is_symlink()
    elif kind == "folder":
        assert link.is_dir()
    else:
        assert link.resolve() == tmp_path / "target"


def test_emulate_log_is_written_when_the_reader_stops_first(tmp_path):
    import serial

    link, log = tmp_path / "tty", tmp_path / "emu.json"
    emu = subprocess.Popen([*CLI, "emulate", "--pty", "--link", str(link), "--frames", "20000",
                            "--peer-timeout", "60", "--log", str(log)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 60
        while not link.is_symlink() and time.monotonic() < deadline:
            time.sleep(0.05)
        port = serial.Serial(str(link), timeout=0.2)
        got = b""
        while len(got) < 500 and time.monotonic() < deadline:
            got += port.read(256)
        port.close()                    # the reader goes away mid-stream
        out, err = emu.communicate(timeout=60)
    finally:
        emu.kill()
    assert emu.returncode == 1 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and "reader closed" in err
    summary = json.loads(log.read_text())
    assert summary["frames_written"] > 0 and "reader closed" in summary["stopped"]
    assert not link.exists()


def test_emulate_on_a_port_that_vanishes_is_one_line(tmp_path):
    master, slave = os.openpty()
    name = os.ttyname(slave)
    os.close(slave)
    emu = subprocess.Popen([*CLI, "emulate", "--port", name, "--frames", "20000"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    received = []

    def drain():
        end = time.monotonic() + 60
        while time.monotonic() < end:
            try:
                chunk = os.read(master, 4096)
            except OSError:            # EIO until the emulator opens the port; EBADF at the end
                if received:
                    return
                time.sleep(0.05)
                continue
            if not chunk:
                return
            received.append(len(chunk))

    threading.Thread(target=drain, daemon=True).start()
    # the device disappears once the emulator has opened it and is streaming (a fixed sleep
    # raced the emulator's start-up on a loaded machine: the port was gone before it opened)
    deadline = time.monotonic() + 60
    while not received and time.monotonic() < deadline:
        time.sleep(0.05)
    assert received, "the emulator never wrote to the port"
    os.close(master)
    out, err = emu.communicate(timeout=60)
    assert emu.returncode == 1 and "Traceback" not in err, err
    assert "failed" in err
    assert len(err.strip().splitlines()) == 1


def test_emulate_on_a_missing_port_names_it(capsys):
    err = refused(capsys, ["emulate", "--port", "/dev/pts/99999", "--frames", "10"], "port")
    assert "/dev/pts/99999" in err and "pyserial URL" in err    # the value, and what would do


# -- Brian2's temporary files ------------------------------------------------------------------
def test_a_failed_run_leaves_no_brian2_temp_files(tmp_path):
    """A bug inside a Brian2 run (injected here) is one line, and Brian2's debug log and
    script copy are removed at exit: Brian2 keeps them only for exceptions that reach its
    excepthook."""
    temp = tmp_path / "tmp"
    temp.mkdir()
    code = ("import sys, numpy as np\n"
            "from snn_antenna.networks import neurons\n"
            "from snn_antenna.core.errors import guarded\n"
            "def boom(args):\n"
            "    neurons.simulate('resonator', np.full(100, 0.1), record_traces='v')\n"
            "    raise IndexError('injected')\n"
            "sys.exit(guarded(boom, None, 'snn-antenna'))\n")
    script = tmp_path / "boom.py"
    script.write_text(code)
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "TMPDIR": str(temp)})
    assert proc.returncode == 1 and "internal error: IndexError: injected" in proc.stderr
    assert "Traceback" not in proc.stderr and "please report this issue" not in proc.stderr
    assert not [p.name for p in temp.iterdir() if p.name.startswith("brian_")]


# -- the Python API ----------------------------------------------------------------------------
DRIVE = np.full(200, 0.15)


@pytest.mark.parametrize("kwargs, name", [
    ({"n_neurons": 0}, "n_neurons"),
    ({"n_neurons": True}, "n_neurons"),
    ({"k": []}, "k"),
    ({"k": 1j}, "k"),
    ({"dt_ms": "0.1"}, "dt_ms"),
    ({"record_traces": "w"}, "record_traces"),
    ({"check_every_ms": 0}, "check_every_ms"),
    ({"current": DRIVE.astype(complex)}, "current"),
    ({"current": np.zeros((3, 2000))}, "current"),         # (inputs, steps): looks transposed
    ({"input_index": [0.5]}, "input_index"),
])
def test_simulate_refuses_bad_arguments_by_name(kwargs, name):
    from snn_antenna.networks import neurons

    kwargs = dict(kwargs)
    current = kwargs.pop("current", DRIVE if "input_index" not in kwargs
                         else np.zeros((100, 2)))
    with pytest.raises(SpecError) as err:
        neurons.simulate("resonator", current, **kwargs)
    assert err.value.field == name


@pytest.mark.parametrize("kwargs, name", [
    ({"band_hz": [7, 20, 30]}, "band_hz"), ({"band_hz": "7-30"}, "band_hz"),
    ({"n_neurons": True}, "n_neurons"), ({"dt_ms": "0.1"}, "dt_ms"),
    ({"force": "yes"}, "force"),
])
def test_resonator_array_refuses_bad_arguments_by_name(kwargs, name):
    from snn_antenna.networks.resonators import ResonatorArray

    with pytest.raises(SpecError) as err:
        ResonatorArray(**kwargs)
    assert err.value.field == name


@pytest.mark.parametrize("kwargs, name", [
    ({"motion_band_hz": [7]}, "motion_band_hz"), ({"min_rate_hz": "20"}, "min_rate_hz"),
    ({"max_gap_windows": True}, "max_gap_windows"),
])
def test_contact_detector_refuses_bad_arguments_by_name(kwargs, name):
    from snn_antenna.readout.contacts import ContactDetector

    with pytest.raises(SpecError) as err:
        ContactDetector(**kwargs)
    assert err.value.field == name


def test_record_and_stream_refuse_an_out_that_is_not_new_or_empty(tmp_path, capsys):
    full = tmp_path / "full"
    full.mkdir()
    (full / "raw.bin").write_bytes(b"mine")
    refused(capsys, ["record", "--port", "loop://", "--out", str(full)], "out",
            "new or empty")
    assert (full / "raw.bin").read_bytes() == b"mine"
    afile = tmp_path / "afile"
    afile.write_text("mine")
    refused(capsys, ["stream", "--port", "loop://", "--network",
                     str(ROOT / "networks" / "resonator_array.toml"), "--out",
                     str(afile / "rec")], "--out", "is a file")


def test_resonator_array_run_refuses_bad_arguments_by_name():
    from snn_antenna.networks.resonators import ResonatorArray
    from snn_antenna.core.signals import Recording

    coded = Recording(np.zeros(100), 1000.0, units="coded")
    for kwargs, name in [({"coded": np.zeros(100)}, "coded"), ({"window_s": 0}, "window_s"),
                         ({"check_every_ms": 0}, "check_every_ms")]:
        args = {"coded": coded, **kwargs}
        with pytest.raises(SpecError) as err:
            ResonatorArray(target="numpy").run(**args)
        assert err.value.field == name


def test_a_killed_run_leaves_a_folder_its_own_study_resumes_and_no_other_takes(tmp_path):
    from snn_antenna.core.files import make_folder, open_append

    out = tmp_path / "sweep"
    run = Run(out, "tuning_sweep")
    make_folder(out / "results.zarr")
    with open_append(out / "run.log") as f:
        f.write("started\n")
    run.kill()                               # the run is killed here: record never runs
    (out / "notes.txt").write_text("mine")   # the user's, added after the kill
    again = checked(out, "tuning_sweep", force=True)
    assert set(again.listed) == {"results.zarr", "run.log"}
    with pytest.raises(SpecError, match="tuning_sweep"):
        checked(out, "quickstart")


def test_a_refused_run_leaves_no_folder_behind(tmp_path):
    out = tmp_path / "new"
    with pytest.raises(SpecError):
        with claimed(out, "quickstart"):        # made, then refused before any write
            raise SpecError("seed", -1, "a seed ≥ 0")
    assert not out.exists()


def test_ctrl_c_ends_with_one_line_not_brian2s_deletion_warnings(tmp_path):
    """Objects of a run cut short by Ctrl-C are deleted on the way out; Brian2 warns about
    each like a traceback. The interrupted command says one line and nothing more."""
    script = tmp_path / "interrupt.py"
    script.write_text(
        "import sys\n"
        "import brian2 as b2\n"
        "from snn_antenna.core.errors import guarded\n"
        "def run(_):\n"
        "    group = b2.NeuronGroup(3, 'dv/dt = -v/(10*ms) : 1')   # never in a network\n"
        "    raise KeyboardInterrupt\n"
        "code = guarded(run, None, 'snn-antenna')\n"
        "import gc; gc.collect()               # the abandoned objects go here\n"
        "sys.exit(code)\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert proc.returncode == 130
    assert proc.stderr.strip() == "snn-antenna: interrupted", proc.stderr


@pytest.mark.slow
def test_ctrl_c_stops_a_closed_loop_study_at_once(tmp_path):
    """Brian2 answers Ctrl-C by ending the current run and returning; the closed loop would go
    on with the next run. The study must stop, with one line, and no expected warning shown."""
    proc = subprocess.Popen([*CLI, "run", str(ROOT / "studies" / "exploration.toml"), "--quick",
                             "--out", str(tmp_path / "o")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    lines = []
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("[3/5]"):
            break
    time.sleep(3)                       # inside the loop's Brian2 runs
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "[4/5]" not in out
    assert err.strip().endswith("snn-antenna: interrupted")
    assert "getting deleted" not in err and "token_post" not in err
