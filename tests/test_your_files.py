"""Nothing a user owns is lost, and no result is silently stale.

Each case a hostile probe found is reproduced here: adoption of a user's file after a killed
run, symlinks followed, two writers in one folder, ``emulate --log`` overwriting, stale caches
and stores, corrupt state ending in a traceback. Every test that makes a symlink asserts that
its target's content and mode are untouched. A property-based test drives random sequences of
runs (killed or not, ``--force``, ``--fresh``, another study) and user files through forked
processes killed with SIGKILL, and checks that no file the toolkit did not create is ever
changed or removed.
"""
from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from snn_antenna.core import outputs, provenance
from snn_antenna.cli import main
from snn_antenna.core.errors import SpecError
from snn_antenna.core.files import atomic_write, open_append
from snn_antenna.core.store import DamagedStore, Output, SweepStore
from folder_runs import checked, claimed

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = str(ROOT / "studies" / "quickstart.toml")


def users_file(path: Path, text: str = "mine", mode: int = 0o640) -> tuple[bytes, int]:
    path.write_text(text)
    path.chmod(mode)
    return untouched_state(path)


def untouched_state(path: Path):
    st_ = os.lstat(path)
    return path.read_bytes() if path.is_file() else None, stat.S_IMODE(st_.st_mode)


def tree(path: Path) -> dict:
    return {str(p.relative_to(path)): (p.read_bytes(), stat.S_IMODE(p.lstat().st_mode))
            for p in sorted(path.rglob("*")) if p.is_file()}


# -- ownership by journal ------------------------------------------------------------------------
def _killed_child(folder: Path, study: str, writes, force=False, kill_at=None,
                  fresh=False) -> int:
    """Fork a run of ``study`` into ``folder`` that makes ``writes`` (names) through the
    toolkit's writers and is SIGKILLed before write ``kill_at``; the exit status or -9."""
    pid = os.fork()
    if pid == 0:                                        # the child: a run, as the CLI runs one
        code = 0
        try:
            with claimed(folder, study, force=force, fresh=fresh):
                for i, name in enumerate(writes):
                    if i == kill_at:
                        os.kill(os.getpid(), signal.SIGKILL)
                    if name.endswith(".zarr"):                  # a real sweep store
                        SweepStore(folder / name).prepare({"k": np.arange(4.0)},
                                                          {"rate": Output("f8")}, (2,), 2,
                                                          fresh=fresh)
                    elif name.endswith(".log"):
                        with open_append(folder / name) as f:
                            f.write(f"{study} {i}\n")
                    else:
                        atomic_write(folder / name, f"{study} {i}")
        except SpecError:
            code = 2
        except BaseException:
            code = 1
        os._exit(code)
    _, status = os.waitpid(pid, 0)
    return -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)


def test_a_users_file_added_after_a_killed_run_survives_rerun_and_force(tmp_path):
    out = tmp_path / "out"
    assert _killed_child(out, "quickstart", ["run.log", "report.html", "x.png"],
                         kill_at=2) == -signal.SIGKILL
    mine = users_file(out / "notes.txt")
    # the user's file is not taken for the killed run's output (its journal says what it made)
    with pytest.raises(SpecError, match="notes.txt"):
        checked(out, "quickstart")
    assert _killed_child(out, "quickstart", ["report.html"], force=True) == 0
    assert _killed_child(out, "tuning_sweep", ["results.zarr"], force=True) == 0
    assert untouched_state(out / "notes.txt") == mine
    assert outputs.read_manifest(out)["files"] == ["results.zarr"]
    assert sorted(os.listdir(out)) == [outputs.MANIFEST, "notes.txt", "results.zarr"]


def test_the_killed_runs_journal_lists_exactly_what_it_created(tmp_path):
    out = tmp_path / "out"
    assert _killed_child(out, "quickstart", ["run.log", "a.png", "b.png"], kill_at=2) < 0
    manifest = outputs.read_manifest(out)
    # write-ahead: every name made is listed (also the temporary name of a.png, declared
    # before it existed); nothing that was not made by the run
    listed = set(manifest["files"])
    assert manifest["status"] == "running" and {"a.png", "run.log"} <= listed
    assert all(n in ("a.png", "run.log") or n.startswith(".a.png.") for n in listed)
    assert set(os.listdir(out)) - {outputs.MANIFEST} == {"a.png", "run.log"}


def test_force_never_overwrites_a_users_file_that_bears_a_toolkit_name(tmp_path):
    out = tmp_path / "out"
    assert _killed_child(out, "tuning_sweep", ["maps.png"]) == 0
    mine = users_file(out / "report.html", "my own report")
    assert _killed_child(out, "quickstart", ["report.html"], force=True) == 2   # refused
    assert untouched_state(out / "report.html") == mine


def test_a_second_run_into_a_busy_folder_is_refused_with_the_holder(tmp_path):
    out = tmp_path / "out"
    with claimed(out, "quickstart"):
        with pytest.raises(SpecError, match=f"PID {os.getpid()}") as err:
            checked(out, "quickstart")
        assert "quickstart" in str(err.value) and "since" in str(err.value)
    checked(out, "quickstart")                              # free again once it ended


def test_a_lock_left_by_a_dead_process_is_taken_over(tmp_path):
    out = tmp_path / "out"
    assert _killed_child(out, "quickstart", ["run.log", "a.png"], kill_at=1) < 0
    with claimed(out, "quickstart"):                # the kernel released the dead run's lock
        pass
    assert outputs.read_manifest(out)["status"] == "ended"


def test_two_cli_runs_into_one_folder_one_is_refused_at_once(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    first = subprocess.Popen([sys.executable, "-m", "snn_antenna.cli", "run", QUICKSTART,
                              "--quick", "--out", str(out)], env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not (out / outputs.MANIFEST).exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        t0 = time.monotonic()
        second = subprocess.run([sys.executable, "-m", "snn_antenna.cli", "run", QUICKSTART,
                                 "--quick", "--out", str(out)], env=env, capture_output=True,
                                text=True, timeout=120)
        assert first.poll() is None, "the first run ended before the second could meet it"
        assert second.returncode == 2 and f"PID {first.pid}" in second.stderr
        assert time.monotonic() - t0 < 30                   # at once, not after a run
    finally:
        first.kill()
        first.wait()


# -- no symlink followed --------------------------------------------------------------------------
def _store(path: Path, **kw) -> SweepStore:
    store = SweepStore(path)
    store.prepare({"k": np.arange(4.0)}, {"rate": Output("f8")}, (2,), 2, **kw)
    return store


def test_fresh_on_a_store_that_is_a_symlink_refuses_and_empties_nothing(tmp_path):
    theirs = tmp_path / "my_data"
    theirs.mkdir()
    kept = users_file(theirs / "precious.csv", "1,2,3")
    link = tmp_path / "results.zarr"
    link.symlink_to(theirs, target_is_directory=True)
    with pytest.raises(SpecError, match="symbolic link"):
        _store(link, fresh=True)
    assert untouched_state(theirs / "precious.csv") == kept and link.is_symlink()


def test_run_sweep_does_not_resolve_its_store_path(tmp_path):
    from snn_antenna.engine.grid import Grid
    from snn_antenna.engine.sweep import run_sweep

    theirs = tmp_path / "elsewhere"
    theirs.mkdir()
    kept = users_file(theirs / "notes.txt")
    (tmp_path / "results.zarr").symlink_to(theirs, target_is_directory=True)
    with pytest.raises(SpecError, match="symbolic link"):
        run_sweep(Grid({"a": np.arange(3.0)}), lambda block: {"y": np.zeros(len(block))},
                  tmp_path / "results.zarr", {"y": "f8"}, fresh=True, progress=False)
    assert untouched_state(theirs / "notes.txt") == kept


@pytest.mark.parametrize("name", ["run.log", "runs.jsonl"])
def test_a_log_that_is_a_symlink_is_refused_and_its_target_untouched(tmp_path, name):
    from snn_antenna.engine.runlog import RunLog
    from snn_antenna.core.logfile import LogFile

    target = tmp_path / "diary.txt"
    kept = users_file(target, "dear diary\n", 0o600)
    out = tmp_path / "out"
    out.mkdir()
    (out / name).symlink_to(target)
    with pytest.raises(SpecError, match="symbolic link"):
        if name == "run.log":
            with LogFile(out, echo=lambda *a: None) as log:
                log("a line")
        else:
            RunLog(out / name, {"study": "speed_accuracy"})
    assert untouched_state(target) == kept


def test_a_recording_file_that_is_a_symlink_is_refused(tmp_path):
    from snn_antenna.bridge.wire.recorder import Recorder

    target = tmp_path / "data.bin"
    kept = users_file(target, "bytes", 0o600)
    rec = tmp_path / "rec"
    rec.mkdir()
    (rec / "raw.bin").symlink_to(target)
    with pytest.raises(SpecError, match="new or empty folder; it holds raw.bin"):
        Recorder(rec, port="x", wire_format="binary", baudrate=250000)
    assert untouched_state(target) == kept


def test_force_keeps_a_listed_entry_replaced_by_a_symlink(tmp_path):
    out = tmp_path / "out"
    assert _killed_child(out, "tuning_sweep", ["results.zarr"]) == 0
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    kept = users_file(theirs / "a.txt")
    import shutil
    shutil.rmtree(out / "results.zarr")
    (out / "results.zarr").symlink_to(theirs, target_is_directory=True)
    with claimed(out, "quickstart", force=True) as folder:
        assert "results.zarr" not in folder.listed       # no longer the toolkit's entry
        with pytest.raises(SpecError, match="results.zarr"):
            atomic_write(out / "results.zarr" / "zarr.json", "{}")
    assert untouched_state(theirs / "a.txt") == kept and (out / "results.zarr").is_symlink()


def test_atomic_write_refuses_to_replace_a_symlink(tmp_path):
    target = tmp_path / "t.html"
    kept = users_file(target, "<p>mine</p>")
    (tmp_path / "report.html").symlink_to(target)
    with pytest.raises(SpecError, match="symbolic link"):
        atomic_write(tmp_path / "report.html", "x")
    assert untouched_state(target) == kept and (tmp_path / "report.html").is_symlink()


# -- emulate --log --------------------------------------------------------------------------------
def test_emulate_log_never_overwrites_without_force(tmp_path, capsys):
    log = tmp_path / "sent.json"
    kept = users_file(log, "my notes")
    assert main(["emulate", "--pty", "--frames", "10", "--fast", "--peer-timeout", "0.5",
                 "--log", str(log)]) == 2
    err = capsys.readouterr().err
    # (a long path is cut in the middle: its name stays)
    assert "--force" in err and f"{log.parent.name[-10:]}/{log.name}" in err
    assert untouched_state(log) == kept
    link = tmp_path / "link.json"
    link.symlink_to(log)
    assert main(["emulate", "--pty", "--frames", "10", "--fast", "--force",
                 "--peer-timeout", "0.5", "--log", str(link)]) == 2
    assert "symbolic link" in capsys.readouterr().err and untouched_state(log) == kept


# -- provenance: no stale result ------------------------------------------------------------------
def test_a_store_made_by_other_code_is_refused_on_resume(tmp_path, monkeypatch):
    path = tmp_path / "results.zarr"
    _store(path)
    assert _store(path) is not None                          # same code: resumes
    monkeypatch.setattr(provenance, "code_hash", lambda *modules: "0123456789abcdef")
    import snn_antenna.core.store as store_module
    monkeypatch.setattr(store_module, "code_hash", provenance.code_hash)
    with pytest.raises(SpecError, match="other code") as err:
        _store(path)
    assert "--fresh" in str(err.value)
    _store(path, fresh=True)                                  # --fresh starts over
    import zarr
    assert zarr.open_group(path, mode="r").attrs["code_sha256"] == "0123456789abcdef"


def test_a_cache_made_by_other_code_is_rebuilt_and_said(tmp_path, monkeypatch):
    import xarray as xr

    from snn_antenna.sources import bench

    built = []

    def build():
        built.append(1)
        return xr.Dataset({"v": ("i", np.arange(3.0))})
    lines = []
    by = "snn_antenna.sources.bench"
    bench.cached(tmp_path / "c.zarr", build, by, lines.append)
    bench.cached(tmp_path / "c.zarr", build, by, lines.append)
    assert len(built) == 1 and "reusing" in lines[-1]
    monkeypatch.setattr(bench, "code_hash", lambda *modules: "fedcba9876543210")
    bench.cached(tmp_path / "c.zarr", build, by, lines.append)
    assert len(built) == 2 and any("other code" in line and "rebuilding" in line
                                   for line in lines)


def test_cache_keys_and_fingerprints_cover_the_package_source(monkeypatch):
    from snn_antenna.sources import bench
    from snn_antenna.core.store import fingerprint

    key, fp = bench.cache_key({"a": 1}, "snn_antenna.sources.bench"), \
        fingerprint({"k": [1.0]}, {}, (1,), None)
    monkeypatch.setattr(bench, "code_hash", lambda *modules: "another")
    import snn_antenna.core.store as store_module
    monkeypatch.setattr(store_module, "code_hash", lambda *modules: "another")
    assert bench.cache_key({"a": 1}, "snn_antenna.sources.bench") != key
    assert fingerprint({"k": [1.0]}, {}, (1,), None) != fp


def test_the_code_hash_changes_when_a_source_file_changes(tmp_path, monkeypatch):
    import shutil

    copy = tmp_path / "snn_antenna"
    shutil.copytree(provenance.PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(provenance, "PACKAGE", copy)
    provenance.code_hash.cache_clear()
    try:
        before = provenance.code_hash()
        neurons = copy / "networks" / "neurons.py"
        neurons.write_text(neurons.read_text() + "\nV_PEAK_CHANGED = 1\n")
        provenance.code_hash.cache_clear()
        assert provenance.code_hash() != before
    finally:
        provenance.code_hash.cache_clear()


def _hashes(roots) -> dict:
    provenance.code_hash.cache_clear()
    return {root: provenance.code_hash(root) for root in roots}


def test_a_cache_key_covers_the_code_its_module_runs_and_nothing_else(tmp_path, monkeypatch):
    """Editing the live page keeps 12,800 bench contacts; editing the physics, or the neuron
    model the event engine integrates, makes new ones (each key follows its module's imports,
    the lazy ones inside functions too)."""
    import shutil

    copy = tmp_path / "snn_antenna"
    shutil.copytree(provenance.PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(provenance, "PACKAGE", copy)
    roots = ("snn_antenna.sources.bench", "snn_antenna.engine.events")

    def edit(relative: str):
        path = copy / relative
        path.write_text(path.read_text() + "\nEDITED = 1\n")
        return _hashes(roots)
    try:
        before = _hashes(roots)
        assert edit("bridge/view/page.py") == before                     # not imported by either
        after_neurons = edit("networks/neurons.py")                 # the event engine's model
        assert after_neurons["snn_antenna.sources.bench"] == before["snn_antenna.sources.bench"]
        assert after_neurons["snn_antenna.engine.events"] != before["snn_antenna.engine.events"]
        after_physics = edit("sources/antenna.py")                  # reached by both
        assert all(after_physics[r] != after_neurons[r] for r in roots)
    finally:
        provenance.code_hash.cache_clear()


def test_the_import_closure_follows_lazy_imports_and_widens_when_it_cannot_follow():
    closure = {str(p.relative_to(provenance.PACKAGE))
               for p in provenance.import_closure(["snn_antenna.engine.events"])}
    # cached_features imports sources.bench inside the function; packages' __init__ on the way
    assert {"engine/events.py", "sources/bench.py", "sources/antenna.py", "networks/neurons.py",
            "engine/__init__.py", "__init__.py"} <= closure
    assert not any(name.startswith(("bridge/", "studies/")) for name in closure)
    whole = set(provenance.PACKAGE.rglob("*.py"))
    # studies/__init__ imports studies by name (importlib): nothing can be left out
    assert set(provenance.import_closure(["snn_antenna.studies.quickstart"])) == whole
    # an evaluator from outside the package: its imports cannot be followed
    assert set(provenance.import_closure(["my_lab.evaluators"])) == whole


# -- corrupt state is named ----------------------------------------------------------------------
def test_a_damaged_run_log_is_named_before_any_work(tmp_path):
    from snn_antenna.engine.runlog import RunLog

    (tmp_path / "runs.jsonl").write_bytes(b"\x00\xffgarbage\n{}\n")
    with pytest.raises(SpecError, match="runs.jsonl") as err:
        RunLog(tmp_path / "runs.jsonl", {"study": "speed_accuracy"})
    assert "--fresh" in str(err.value)
    RunLog(tmp_path / "runs.jsonl", {"study": "speed_accuracy"}, fresh=True)   # starts over


def test_a_damaged_store_is_named_in_one_line(tmp_path):
    path = tmp_path / "results.zarr"
    store = _store(path)
    store.write_chunk(0, {"k": slice(0, 2)}, {"rate": np.ones(2)})
    chunk = next(p for p in (path / "rate").rglob("*") if p.is_file() and p.name != "zarr.json")
    chunk.write_bytes(b"not a chunk")
    with pytest.raises(DamagedStore, match="damaged") as err:
        store.load()
    assert "results.zarr" in str(err.value) and "\n" not in str(err.value)
    (path / "zarr.json").unlink()
    with pytest.raises(SpecError, match="--fresh"):
        _store(path)


def test_a_nan_chunk_in_a_cache_is_rebuilt(tmp_path):
    import xarray as xr

    from snn_antenna.sources import bench

    good = xr.Dataset({"v": ("i", np.arange(4.0))})
    by = "snn_antenna.sources.bench"
    bench.cached(tmp_path / "c.zarr", lambda: good.copy(), by, lambda *a: None)
    import zarr
    zarr.open_array(tmp_path / "c.zarr" / "v", mode="r+")[1] = np.nan
    lines = []
    ds = bench.cached(tmp_path / "c.zarr", lambda: good.copy(), by, lines.append)
    assert np.isfinite(ds["v"].values).all()
    assert any("NaN" in line and "rebuilding" in line for line in lines)


def test_a_bad_meta_json_is_named(tmp_path):
    from snn_antenna.bridge.wire.recorder import load_recording, record_counts

    rec = record_counts(tmp_path / "rec", np.zeros((10, 2), dtype=np.int64))
    (rec / "meta.json").write_bytes(b"\xff\xfe{")
    with pytest.raises(SpecError, match=r"meta\.json.*JSON text written by .snn-antenna record."):
        load_recording(rec)
    (rec / "meta.json").write_text("[1, 2]")
    with pytest.raises(SpecError, match=r"meta\.json"):
        load_recording(rec)


def test_a_damaged_manifest_is_named(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / outputs.MANIFEST).write_text("{not json")
    with pytest.raises(SpecError, match="damaged"):
        checked(out, "quickstart")


def test_summary_and_store_attributes_record_the_code(tmp_path):
    path = tmp_path / "results.zarr"
    _store(path)
    import zarr
    attrs = dict(zarr.open_group(path, mode="r").attrs)
    assert attrs["code_sha256"] == provenance.code_hash()
    assert "git_commit" in attrs and "snn_antenna_version" in attrs


# -- the property: no file the toolkit did not create is ever changed or removed ----------------
TOOLKIT_NAMES = ["run.log", "report.html", "summary.json", "a.png", "results.zarr"]
action = st.one_of(
    st.tuples(st.just("run"), st.sampled_from(["quickstart", "tuning_sweep"]),
              st.lists(st.sampled_from(TOOLKIT_NAMES), min_size=1, max_size=4),
              st.booleans(), st.one_of(st.none(), st.integers(0, 3)), st.booleans()),
    st.tuples(st.just("user_file"), st.sampled_from(["notes.txt", "report.html", "run.log",
                                                     "data.csv", "results.zarr"])),
    st.tuples(st.just("user_link"), st.sampled_from(["run.log", "summary.json", "results.zarr",
                                                     "link"])),
)


def check_users_files_survive(base: Path, actions) -> None:
    out, outside = base / "out", base / "outside"
    outside.mkdir()
    target = outside / "target.txt"
    users_file(target, "outside the folder", 0o600)
    out.mkdir()
    mine: dict[str, object] = {}
    for act in actions:
        if act[0] == "run":
            _, study, writes, force, kill_at, fresh = act
            _killed_child(out, study, writes, force=force, kill_at=kill_at, fresh=fresh)
        elif act[0] == "user_file":
            path = out / act[1]
            if not os.path.lexists(path):
                mine[act[1]] = users_file(path, f"user {act[1]}")
        else:
            path = out / act[1]
            if not os.path.lexists(path):
                path.symlink_to(target)
                mine[act[1]] = "link"
        for name, state in mine.items():
            path = out / name
            if state == "link":
                assert path.is_symlink() and os.readlink(path) == str(target), name
            else:
                assert untouched_state(path) == state, name
        assert target.read_text() == "outside the folder"
        assert stat.S_IMODE(target.stat().st_mode) == 0o600
        assert tree(outside) == {"target.txt": (b"outside the folder", 0o600)}



@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(action, min_size=1, max_size=8))
def test_no_user_file_is_ever_changed_or_removed(tmp_path_factory, actions):
    check_users_files_survive(tmp_path_factory.mktemp("prop"), actions)


@pytest.mark.slow
@settings(max_examples=600, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(action, min_size=1, max_size=16))
def test_no_user_file_is_ever_changed_or_removed_thoroughly(tmp_path_factory, actions):
    check_users_files_survive(tmp_path_factory.mktemp("prop"), actions)


@pytest.mark.slow
def test_a_killed_quickstart_then_force_keeps_the_users_file(tmp_path):
    """As a careless user would: SIGKILL a quickstart run once its folder exists, put a file of
    your own there, run the quickstart there again, then another study with ``--force``."""
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "snn_antenna.cli", "run"]
    first = subprocess.Popen(cmd + [QUICKSTART, "--quick", "--out", str(out)], env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (out / "run.log").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    first.send_signal(signal.SIGKILL)
    first.wait()
    mine = users_file(out / "notes.txt", "my notes")
    again = subprocess.run(cmd + [QUICKSTART, "--quick", "--out", str(out)], env=env,
                           capture_output=True, text=True)
    assert again.returncode == 2 and "notes.txt" in again.stderr     # not adopted
    assert subprocess.run(cmd + [QUICKSTART, "--quick", "--force", "--out", str(out)],
                          env=env, capture_output=True).returncode == 0
    other = str(ROOT / "studies" / "exploration.toml")
    assert subprocess.run(cmd + [other, "--quick", "--force", "--out", str(out)], env=env,
                          capture_output=True).returncode == 0
    assert untouched_state(out / "notes.txt") == mine
    assert outputs.read_manifest(out)["study"] == "exploration"


def test_a_done_chunk_whose_data_were_deleted_is_computed_again(tmp_path, capsys):
    path = tmp_path / "results.zarr"
    store = _store(path)
    store.write_chunk(0, {"k": slice(0, 2)}, {"rate": np.zeros(2)})   # equal to no fill
    store.write_chunk(1, {"k": slice(2, 4)}, {"rate": np.ones(2)})
    assert _store(path).done_chunks() == {0, 1}
    (path / "rate" / "c" / "1").unlink()
    assert _store(path).done_chunks() == {0}            # resumed: chunk 1 is redone
    err = capsys.readouterr().err
    assert "chunk 1" in err and str(path) in err

