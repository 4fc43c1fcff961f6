"""The user's files are theirs, by construction: every entry the toolkit creates is journaled
with what identifies it (device, inode; for files size and mtime), and removal, replacement
and append act only on an entry that is still that one; no link is followed at any depth;
staging names are created exclusively and cleaned only when journaled; appends refuse a file
with more than one hard link; the emulator removes only the link it created.

Each test places what a user might place (a file under a staging name, a link inside a store,
a link to a real serial device, an edited or replaced output, a hard link) and asserts that it
is untouched, and that anything refused is refused in one line naming it.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.core import outputs
from snn_antenna.core.errors import SpecError
from snn_antenna.core.files import atomic_write, make_folder, open_append
from snn_antenna.core.store import Output, SweepStore, write_dataset
from folder_runs import Run, claimed


def users_file(path: Path, text: str = "mine") -> tuple:
    path.write_text(text)
    path.chmod(0o640)
    return state(path)


def state(path: Path) -> tuple:
    st_ = os.lstat(path)
    return path.read_bytes(), stat.S_IMODE(st_.st_mode), st_.st_ino


def one_line(err) -> str:
    text = str(err.value)
    assert "\n" not in text
    return text


def _store(path: Path, **kw) -> SweepStore:
    store = SweepStore(path)
    store.prepare({"k": np.arange(4.0)}, {"rate": Output("f8")}, (2,), 2, **kw)
    return store


def _dataset():
    import xarray as xr
    return xr.Dataset({"v": ("i", np.arange(3.0))})


def finished_run(out: Path, study: str, names=("report.html",), store: str | None = None):
    with claimed(out, study):
        for name in names:
            atomic_write(out / name, f"{study} {name}")
        if store:
            write_dataset(_dataset(), out / store)


# -- staging names ---------------------------------------------------------------------------
@pytest.mark.parametrize("staged", ["results.zarr.partial", ".results.zarr.partial"])
def test_force_keeps_a_users_file_that_bears_a_staging_name(tmp_path, staged):
    out = tmp_path / "out"
    finished_run(out, "quickstart")
    mine = users_file(out / staged, "my partial results")
    try:
        with claimed(out, "tuning_sweep", force=True):
            write_dataset(_dataset(), out / "results.zarr")
    except SpecError:
        pass                                        # a refusal is fine; a deletion is not
    assert state(out / staged) == mine


def test_a_store_is_never_staged_over_a_users_folder_of_that_name(tmp_path):
    path = tmp_path / "d.zarr"
    (tmp_path / "d.zarr.partial").mkdir()
    mine = users_file(tmp_path / "d.zarr.partial" / "thesis.tex")
    write_dataset(_dataset(), path)
    assert state(tmp_path / "d.zarr.partial" / "thesis.tex") == mine
    assert (path / "zarr.json").is_file()


def test_the_manifests_temporary_file_never_truncates_a_users_file(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    name = outputs.MANIFEST + ".tmp"
    mine = users_file(out / name, "my own notes")
    for force in (False, True):
        try:
            finished_run(out, "quickstart", force and ("report.html",) or ())
        except SpecError:
            pass
    assert state(out / name) == mine


# -- no link at any depth ----------------------------------------------------------------------
def _outside(tmp_path: Path) -> Path:
    theirs = tmp_path / "theirs"
    theirs.mkdir(exist_ok=True)
    users_file(theirs / "data.bin", "outside --out")
    return theirs


def test_a_link_inside_a_store_is_refused_on_resume_and_never_written_through(tmp_path):
    theirs = _outside(tmp_path)
    before = state(theirs / "data.bin")
    path = tmp_path / "results.zarr"
    _store(path)
    chunk = path / "rate" / "c" / "0"
    chunk.parent.mkdir(parents=True, exist_ok=True)
    chunk.unlink(missing_ok=True)
    chunk.symlink_to(theirs / "data.bin")
    with pytest.raises(SpecError) as err:
        _store(path).write_chunk(0, {"k": slice(0, 2)}, {"rate": np.ones(2)})
    assert "symbolic link" in one_line(err) and str(chunk) in one_line(err)
    assert state(theirs / "data.bin") == before and chunk.is_symlink()


def test_a_linked_folder_inside_a_store_is_refused_on_resume(tmp_path):
    theirs = _outside(tmp_path)
    path = tmp_path / "results.zarr"
    _store(path)
    (path / "rate" / "c").mkdir(parents=True, exist_ok=True)
    import shutil
    shutil.rmtree(path / "rate" / "c")
    (path / "rate" / "c").symlink_to(theirs, target_is_directory=True)
    with pytest.raises(SpecError, match="symbolic link"):
        _store(path).write_chunk(0, {"k": slice(0, 2)}, {"rate": np.ones(2)})
    assert sorted(os.listdir(theirs)) == ["data.bin"]


def test_a_link_inside_a_store_is_kept_when_the_store_would_be_removed(tmp_path):
    theirs = _outside(tmp_path)
    out = tmp_path / "out"
    finished_run(out, "tuning_sweep", (), store="results.zarr")
    link = out / "results.zarr" / "mine"
    link.symlink_to(theirs, target_is_directory=True)
    try:
        with claimed(out, "quickstart", force=True):
            atomic_write(out / "report.html", "quickstart")
    except SpecError as exc:
        assert "mine" in str(exc)
    assert link.is_symlink() and sorted(os.listdir(theirs)) == ["data.bin"]


def test_a_write_below_a_link_inside_the_output_folder_is_refused(tmp_path):
    theirs = _outside(tmp_path)
    out = tmp_path / "out"
    with claimed(out, "quickstart"):
        make_folder(out / "figures")
        (theirs / "sub").mkdir()
        (out / "figures" / "maps").symlink_to(theirs, target_is_directory=True)
        with pytest.raises(SpecError, match="symbolic link"):
            atomic_write(out / "figures" / "maps" / "sub" / "a.png", "png")
    assert sorted(os.listdir(theirs)) == ["data.bin", "sub"] and not os.listdir(theirs / "sub")


# -- ownership by identity ---------------------------------------------------------------------
@pytest.mark.parametrize("how", ["replaced", "edited"])
def test_an_output_the_user_replaced_or_edited_is_theirs(tmp_path, how):
    out = tmp_path / "out"
    finished_run(out, "tuning_sweep", ("report.html", "summary.json"))
    report = out / "report.html"
    if how == "replaced":
        report.unlink()
        mine = users_file(report, "my own report")
    else:
        with open(report, "a") as f:
            f.write("<!-- my notes -->")
        mine = state(report)
    # another study with --force removes only what is still the toolkit's
    with claimed(out, "quickstart", force=True):
        pass
    assert state(report) == mine and not (out / "summary.json").exists()
    # a rerun never replaces it either
    with pytest.raises(SpecError, match="report.html"):
        with claimed(out, "quickstart", force=True):
            atomic_write(report, "quickstart's report")
    assert state(report) == mine


def test_a_store_the_user_replaced_is_not_removed_by_force(tmp_path):
    out = tmp_path / "out"
    finished_run(out, "tuning_sweep", (), store="results.zarr")
    import shutil
    shutil.rmtree(out / "results.zarr")
    (out / "results.zarr").mkdir()
    mine = users_file(out / "results.zarr" / "zarr.json", "my own store")
    with claimed(out, "quickstart", force=True):
        pass
    assert state(out / "results.zarr" / "zarr.json") == mine


def test_a_file_the_user_put_inside_a_store_is_not_removed_by_force(tmp_path):
    out = tmp_path / "out"
    finished_run(out, "tuning_sweep", (), store="results.zarr")
    mine = users_file(out / "results.zarr" / "notes.txt")
    with claimed(out, "quickstart", force=True):
        pass
    assert state(out / "results.zarr" / "notes.txt") == mine


def test_a_killed_sweep_resumes_and_no_other_study_removes_it(tmp_path):
    out = tmp_path / "out"
    run = Run(out, "tuning_sweep")
    _store(out / "results.zarr").write_chunk(0, {"k": slice(0, 2)}, {"rate": np.ones(2)})
    run.kill()                                  # killed: its journal says "running"
    with claimed(out, "tuning_sweep"):
        assert _store(out / "results.zarr").done_chunks() == {0}       # resumed
    run = Run(out, "tuning_sweep")
    _store(out / "results.zarr").write_chunk(1, {"k": slice(2, 4)}, {"rate": np.ones(2)})
    run.kill()                                  # killed again, mid-sweep
    mine = users_file(out / "results.zarr" / "mine.txt")
    with claimed(out, "quickstart", force=True):
        with pytest.raises(SpecError, match="killed left it unfinished"):
            _store(out / "results.zarr")        # what a killed run left is never removed
    assert state(out / "results.zarr" / "mine.txt") == mine


# -- appends ----------------------------------------------------------------------------------
def test_an_append_refuses_a_file_with_another_hard_link(tmp_path):
    log = tmp_path / "run.log"
    log.write_text("first line\n")
    os.link(log, tmp_path / "my_copy.log")
    with pytest.raises(SpecError) as err:
        with open_append(log) as f:
            f.write("more\n")
    assert "hard link" in one_line(err)
    assert (tmp_path / "my_copy.log").read_text() == "first line\n"


def test_an_append_to_a_journaled_log_the_user_replaced_is_refused(tmp_path):
    out = tmp_path / "out"
    with claimed(out, "quickstart"):
        with open_append(out / "run.log") as f:
            f.write("line\n")
    (out / "run.log").unlink()
    mine = users_file(out / "run.log", "my log\n")
    with pytest.raises(SpecError, match="run.log"):
        with claimed(out, "quickstart", force=True):
            with open_append(out / "run.log") as f:
                f.write("line\n")
    assert state(out / "run.log") == mine


# -- the emulator's link -----------------------------------------------------------------------
def test_emulate_link_refuses_a_users_link_to_a_serial_device(tmp_path):
    from snn_antenna.bridge.emulate.links import PtyLink

    link = tmp_path / "ttyANT"
    link.symlink_to("/dev/ttyUSB0")
    with pytest.raises(SpecError) as err:
        PtyLink(link).close()
    assert "left as it is" in one_line(err)
    assert link.is_symlink() and os.readlink(link) == "/dev/ttyUSB0"


def test_the_emulator_removes_only_the_link_it_created(tmp_path):
    from snn_antenna.bridge.emulate.links import PtyLink

    link = tmp_path / "ttyANT"
    pty = PtyLink(link)
    assert os.readlink(link) == pty.slave_name
    link.unlink()                               # the user takes the path for a device of theirs
    link.symlink_to("/dev/ttyS0")
    pty.close()
    assert link.is_symlink() and os.readlink(link) == "/dev/ttyS0"
    pty2 = PtyLink(tmp_path / "ttyB")
    pty2.close()
    assert not os.path.lexists(tmp_path / "ttyB")   # its own link is removed


def test_a_staging_name_already_taken_is_passed_over(tmp_path, monkeypatch):
    import itertools

    from snn_antenna.core import files

    monkeypatch.setattr(files, "_counter", itertools.count())
    taken = [tmp_path / f".report.html.{os.getpid()}-{n}.tmp" for n in range(2)] + \
        [tmp_path / f".{outputs.MANIFEST}.{os.getpid()}-2.tmp"]
    mine = [users_file(path) for path in taken]
    with claimed(tmp_path, "quickstart", force=True):
        atomic_write(tmp_path / "report.html", "report")
    assert [state(path) for path in taken] == mine
    assert (tmp_path / "report.html").read_text() == "report"


# -- the property: a user acting anywhere, the toolkit running anyhow ---------------------------
from hypothesis import HealthCheck, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.stateful import (RuleBasedStateMachine, initialize, invariant,  # noqa: E402
                                 rule)

WRITES = ["run.log", "report.html", "summary.json", "results.zarr", "cache.zarr",
          "figures/a.png"]
USER_NAMES = ["notes.txt", "report.html", "run.log", "results.zarr", "cache.zarr",
              "results.zarr.partial", "cache.zarr.partial",
              f".results.zarr.{os.getpid()}-0.partial",
              f".report.html.{os.getpid()}-1.tmp", outputs.MANIFEST + ".tmp",
              f".{outputs.MANIFEST}.{os.getpid()}-3.tmp", "figures", "figures/a.png"]
INSIDE = ["results.zarr/notes.txt", "results.zarr/rate/c", "results.zarr/rate/c/0",
          "results.zarr/chunk_done/c/1",
          "cache.zarr/v/c/0", "cache.zarr/zarr.json", "figures/mine.png"]


STATS = {"runs": 0, "writes": 0, "refusals": 0}


class UserAndToolkit(RuleBasedStateMachine):
    """A user places files, links and hard links anywhere in and around an output folder
    (under the toolkit's names, staging names, inside its stores), edits or replaces the
    toolkit's outputs; the toolkit runs, is killed, resumes, is forced. Invariant: nothing
    the user made changes or disappears, and nothing outside the folder is written."""

    @initialize()
    def make_folders(self):
        import tempfile
        self.base = Path(tempfile.mkdtemp(prefix="own-"))
        self.out, self.outside = self.base / "out", self.base / "outside"
        self.outside.mkdir()
        (self.outside / "dir").mkdir()
        users_file(self.outside / "shared.txt", "the user's data")
        users_file(self.outside / "dir" / "inner.txt", "more of it")
        self.users: dict[Path, object] = {}
        # Stores a killed run left being written: the run that resumes them writes every
        # chunk it has not finished by path, so a file the user puts inside one at such a path
        # is the one case the journal cannot tell (files.Journal); the user does not here.
        self.unfinished: set[str] = set()

    def teardown(self):
        import shutil
        if hasattr(self, "base"):
            shutil.rmtree(self.base, ignore_errors=True)

    # -- the user ---------------------------------------------------------------------------
    def _free(self, rel: str) -> Path | None:
        path = self.out / rel
        parent = path.parent
        if os.path.lexists(path) or parent.is_symlink() or (parent != self.out
                                                            and not parent.is_dir()):
            return None
        if any(path == p or p in path.parents for p in self.users):
            return None                 # inside something of the user's: theirs already
        if parent == self.out:
            self.out.mkdir(exist_ok=True)
        return path if parent.is_dir() else None

    @rule(rel=st.sampled_from(USER_NAMES + INSIDE), text=st.sampled_from(["a", "bb"]))
    def place_file(self, rel, text):
        path = self._free(rel)
        if path is not None:
            users_file(path, text)
            self.users[path] = state(path)

    @rule(rel=st.sampled_from(USER_NAMES + INSIDE), to_dir=st.booleans())
    def place_link(self, rel, to_dir):
        path = self._free(rel)
        if path is not None:
            path.symlink_to(self.outside / ("dir" if to_dir else "shared.txt"))
            self.users[path] = ("link", os.readlink(path))

    @rule(rel=st.sampled_from(USER_NAMES + INSIDE))
    def place_hard_link(self, rel):
        path = self._free(rel)
        if path is not None:
            os.link(self.outside / "shared.txt", path)
            self.users[path] = ("hard", (self.outside / "shared.txt").stat().st_ino)

    @rule(pick=st.integers(0, 99), how=st.sampled_from(["edit", "replace", "link out",
                                                       "add inside"]))
    def touch_an_output(self, pick, how):
        """The user edits, replaces, hard-links out or adds to something the toolkit wrote."""
        if not self.out.is_dir():
            return
        outputs_ = sorted(p for p in self.out.iterdir() if p not in self.users
                          and p.name != outputs.MANIFEST and not p.is_symlink())
        if not outputs_:
            return
        path = outputs_[pick % len(outputs_)]
        if path.name in self.unfinished:
            return
        if path.is_dir():
            inner = sorted(p for p in path.rglob("*") if p.is_file() and not p.is_symlink()
                           and not any(u == p or u in p.parents for u in self.users))
            if how == "add inside" or not inner:
                if not (path / "mine.txt").exists():
                    self.users[path / "mine.txt"] = users_file(path / "mine.txt") and \
                        state(path / "mine.txt")
                return
            path = inner[pick % len(inner)]
        if how == "link out":               # the user keeps a hard link to an output
            copy = self.outside / f"kept-{len(self.users)}"
            os.link(path, copy)
            self.users[copy] = state(copy)
            return
        if how == "edit" and path.stat().st_nlink > 1:
            return                          # it would edit the user's kept link too
        if how in ("replace", "add inside"):
            path.unlink()
            path.write_text("the user's version")
        else:
            with open(path, "a") as f:
                f.write("the user's line")
        self.users[path] = state(path)

    # -- the toolkit ------------------------------------------------------------------------
    @rule(study=st.sampled_from(["quickstart", "tuning_sweep"]),
          writes=st.lists(st.sampled_from(WRITES), min_size=1, max_size=3),
          force=st.booleans(), fresh=st.booleans(),
          killed=st.one_of(st.none(), st.integers(0, 2)))
    def run(self, study, writes, force, fresh, killed):
        self._run(study, writes, force, fresh, killed)

    @rule(study=st.sampled_from(["quickstart", "tuning_sweep"]),
          writes=st.lists(st.sampled_from(WRITES), min_size=1, max_size=3))
    def run_forced(self, study, writes):
        """What a user does after a refusal: run again with --force."""
        self._run(study, writes, True, False, None)

    def _run(self, study, writes, force, fresh, killed):
        STATS["runs"] += 1
        try:
            run = Run(self.out, study, force=force, fresh=fresh)
            try:
                for i, name in enumerate(writes):
                    if i == killed:
                        break
                    self._write(name, fresh)
                    if name == "results.zarr":
                        (self.unfinished.add if killed is not None
                         else self.unfinished.discard)(name)
            finally:
                if killed is None:
                    run.end()
                else:
                    run.kill()                      # killed: the journal says "running"
        except SpecError:
            STATS["refusals"] += 1

    def _write(self, name: str, fresh: bool) -> None:
        STATS["writes"] += 1
        path = self.out / name
        if name == "results.zarr":
            store = SweepStore(path)
            store.prepare({"k": np.arange(4.0)}, {"rate": Output("f8")}, (2,), 2, fresh=fresh)
            store.write_chunk(0, {"k": slice(0, 2)}, {"rate": np.ones(2)})
            store.write_chunk(1, {"k": slice(2, 4)}, {"rate": np.ones(2)})
        elif name == "cache.zarr":
            write_dataset(_dataset(), path)
        elif name.endswith(".log"):
            with open_append(path) as f:
                f.write("a line\n")
        else:
            atomic_write(path, name)

    # -- what must hold -----------------------------------------------------------------------
    @invariant()
    def the_users_entries_are_untouched(self):
        if not hasattr(self, "base"):
            return
        for path, was in self.users.items():
            assert os.path.lexists(path), f"{path} disappeared"
            if isinstance(was, tuple) and was[0] == "link":
                assert path.is_symlink() and os.readlink(path) == was[1], path
            elif isinstance(was, tuple) and was[0] == "hard":
                assert os.lstat(path).st_ino == was[1], path
            else:
                assert state(path) == was, path
        assert sorted(os.listdir(self.base)) in (["outside"], ["out", "outside"])
        assert (self.outside / "shared.txt").read_text() == "the user's data"
        assert (self.outside / "dir" / "inner.txt").read_text() == "more of it"
        kept = {p.name for p in self.users if p.parent == self.outside}
        assert set(os.listdir(self.outside)) == {"shared.txt", "dir"} | kept
        assert os.listdir(self.outside / "dir") == ["inner.txt"]


UserAndToolkit.TestCase.settings = settings(
    max_examples=20, stateful_step_count=15, deadline=None,
    suppress_health_check=[HealthCheck.too_slow])
test_a_user_and_the_toolkit = UserAndToolkit.TestCase


class UserAndToolkitThoroughly(UserAndToolkit):
    pass


UserAndToolkitThoroughly.TestCase.settings = settings(
    max_examples=300, stateful_step_count=40, deadline=None,
    suppress_health_check=[HealthCheck.too_slow])
test_a_user_and_the_toolkit_thoroughly = pytest.mark.slow(UserAndToolkitThoroughly.TestCase)
