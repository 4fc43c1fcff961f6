"""Output folders: what a study run may write into, what it wrote, and who is writing.

A run never destroys what the user owns. Ownership is kept by a write-ahead journal, never
guessed: the folder's manifest, :data:`MANIFEST`, is written before anything else, and every
name the run creates at the top of the folder is added to it *before* it is created (the
toolkit's writers call ``files.declare``). A run killed at any instant leaves exactly the names
it created listed; nothing else in the folder is ever taken as the toolkit's.

Before a study starts, :func:`prepare` decides the folder:

- a path that is a file, lies under a file, or cannot be written is refused (before any work);
- a folder another run is writing (it holds the folder's lock) is refused, naming its PID and
  start time; a lock left by a dead process is released by the kernel and simply taken;
- a new or empty folder is used as it is;
- a folder of this same study (its manifest says so) is reused: re-running a study into its own
  folder updates its report and resumes its stores (also after a killed run: its journal lists
  what it made);
- a folder holding another study's outputs, or files snn-antenna did not write, is refused,
  unless ``force``: then the entries the manifest lists are removed (:meth:`OutputFolder.clear`,
  once every other check has passed) and the user's files are kept. No symlink is followed: a
  link where a listed entry was is refused, not removed through.

:func:`claim` takes the folder's lock (``fcntl.flock`` on the folder itself, held for the run)
and opens the journal; :func:`record` closes it, however the run ended.
"""
from __future__ import annotations

import datetime as _dt
import fcntl
import json
import os
import socket
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from . import files
from .errors import SpecError

MANIFEST = ".snn-antenna-manifest.json"
_MANIFEST_TMP = MANIFEST + ".tmp"
KIND = "snn-antenna output folder"


@dataclass
class OutputFolder:
    path: Path
    study: str
    listed: set = field(default_factory=set)        # entries the toolkit wrote before
    replace: set = field(default_factory=set)       # another study's entries, for --force
    created: bool = False                           # the run made the folder
    lock_fd: int | None = None                      # the folder's flock, held for the run
    journal: files.Journal | None = None
    started: str | None = None

    def clear(self) -> None:
        """Remove the other study's entries (``--force``): only what the manifest lists.
        Called once every check has passed, so a refused run removes nothing."""
        for entry in sorted(self.replace):
            files.remove_entry(self.path / entry)
        self.replace = set()


def check_writable(path) -> Path:
    """Refuse an output path that is a file, lies under a file, or cannot be written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SpecError("--out", str(path), "a folder path (this is an existing file)")
    ancestor = path
    while not ancestor.exists():
        if ancestor.parent == ancestor:
            break
        ancestor = ancestor.parent
    if ancestor != path and not ancestor.is_dir():
        raise SpecError("--out", str(path), f"a folder path ({ancestor} is a file, so nothing "
                                            "can be created under it)")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise SpecError("--out", str(path), f"a folder you can write to ({ancestor} is not "
                                            "writable)")
    return path


def read_manifest(path) -> dict | None:
    """The folder's manifest, ``None`` when there is none; a damaged one is named."""
    target = Path(path) / MANIFEST
    if not os.path.lexists(target):
        return None
    files.refuse_symlink(target, "manifest")
    try:
        data = json.loads(target.read_text())
    except (OSError, ValueError) as exc:
        raise SpecError("--out", str(path),
                        f"a folder whose {MANIFEST} is readable; it is damaged ({exc}): "
                        "choose another --out (snn-antenna cannot tell which files there are "
                        "its own)") from None
    if not isinstance(data, dict) or data.get("kind") != KIND \
            or not isinstance(data.get("files"), list):
        raise SpecError("--out", str(path),
                        f"a folder whose {MANIFEST} is one snn-antenna wrote; this one is "
                        "not: choose another --out")
    return data


def _entries(path: Path) -> list[str]:
    if not path.is_dir():
        return []
    return sorted(e for e in os.listdir(path) if e not in (MANIFEST, _MANIFEST_TMP))


def prepare(path, study: str, force: bool = False, fresh: bool = False) -> OutputFolder:
    """Decide the output folder of a ``study`` run (see the module docstring) and take its
    lock when the folder exists; creates nothing."""
    path = check_writable(path)
    lock_fd = lock_folder(path) if path.is_dir() else None
    try:
        folder = _decide(path, study, force, fresh)
    except BaseException:
        _unlock(lock_fd)
        raise
    folder.lock_fd = lock_fd
    return folder


def _decide(path: Path, study: str, force: bool, fresh: bool) -> OutputFolder:
    entries = _entries(path)
    manifest = read_manifest(path)
    owner = manifest.get("study") if manifest else None
    listed = set(manifest["files"]) & set(entries) if manifest else set()
    foreign = [e for e in entries if e not in listed]
    other_study = owner is not None and owner != study
    if (other_study or foreign) and not force:
        held = (f"the outputs of the {owner!r} study" if other_study
                else "files snn-antenna did not write")
        shown = ", ".join(foreign[:4]) + (", …" if len(foreign) > 4 else "")
        raise SpecError("--out", str(path),
                        f"a new or empty folder, or this study's own earlier output; it holds "
                        f"{held}{f' ({shown})' if foreign and not other_study else ''}: "
                        "choose another --out, or "
                        "pass --force to replace what snn-antenna wrote there (other files "
                        "are kept)")
    if fresh:
        for entry in foreign:
            if entry.endswith(".zarr"):
                raise SpecError("--fresh", str(path / entry),
                                "a store snn-antenna created (this one is not in the folder's "
                                f"{MANIFEST}); --fresh never removes anything else")
    replace = set()
    if other_study and force:
        replace, listed = listed, set()
    for entry in replace:
        files.refuse_symlink(path / entry, "entry")      # before anything is removed
    return OutputFolder(path, study, listed, replace)


# -- one writer per folder ----------------------------------------------------------------------
def lock_folder(path: Path) -> int:
    """An exclusive ``flock`` on the folder itself (no lock file to leave behind); refused at
    once, naming the holder, when another run holds it. The kernel releases the lock of a
    process that dies, so a killed run's folder is simply taken."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | os.O_CLOEXEC)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        try:
            holder = json.loads((path / MANIFEST).read_text())
            who = (f"run by PID {holder.get('pid')} on {holder.get('host')} since "
                   f"{holder.get('started')} ({holder.get('study')})")
        except (OSError, ValueError, AttributeError):
            who = "run by another process"
        raise SpecError("--out", str(path),
                        f"a folder no other run is writing; it is being written by a "
                        f"{who}: wait for it, or choose another --out") from None
    return fd


def _unlock(fd: int | None) -> None:
    if fd is not None:
        os.close(fd)                        # closing releases the flock


def release(folder: OutputFolder) -> None:
    """Give up a prepared folder without running (a refusal after ``prepare``)."""
    _unlock(folder.lock_fd)
    folder.lock_fd = None


def claim(folder: OutputFolder) -> None:
    """Create and lock the folder, write its manifest before anything else, and open the
    write-ahead journal that lists every name the run creates before it is created."""
    folder.created = not folder.path.exists()
    folder.path.mkdir(parents=True, exist_ok=True)
    if folder.lock_fd is None:
        folder.lock_fd = lock_folder(folder.path)
    folder.started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    folder.listed &= set(_entries(folder.path))
    folder.journal = files.Journal(
        folder.path, lambda names: _write_manifest(folder, folder.listed | names, "running"),
        owned=folder.listed)
    _write_manifest(folder, folder.listed, "running")
    files.open_journal(folder.journal)


def record(folder: OutputFolder) -> None:
    """Close the journal and write the manifest: every entry this run created and the
    toolkit's earlier entries that are still there; release the lock. Atomic (a reader sees
    the old or the new manifest)."""
    try:
        if folder.journal is not None:
            files.close_journal(folder.journal)
        path = folder.path
        if not path.is_dir():
            return                          # the run failed before writing anything
        made = folder.journal.names if folder.journal else set()
        written = (folder.listed | made) & set(_entries(path))
        if not made & written and folder.created:
            # refused or failed before writing anything: leave no trace of a folder it made
            (path / MANIFEST).unlink(missing_ok=True)
            if not any(path.iterdir()):
                path.rmdir()
            return
        _write_manifest(folder, written, "ended")
    finally:
        release(folder)


def _write_manifest(folder: OutputFolder, names: set, status: str) -> None:
    data = {"kind": KIND, "study": folder.study, "files": sorted(names), "status": status,
            "pid": os.getpid(), "host": socket.gethostname(),
            "started": folder.started, "updated_unix_s": time.time()}
    tmp = folder.path / _MANIFEST_TMP
    files.refuse_symlink(folder.path / MANIFEST, "manifest")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o666)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(json.dumps(data, indent=1))
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, folder.path / MANIFEST)


@contextmanager
def output_folder(path, study: str, force: bool = False, fresh: bool = False):
    """``prepare`` and ``clear`` the folder, ``claim`` it, yield it, and ``record`` what the
    run wrote however it ended."""
    folder = prepare(path, study, force=force, fresh=fresh)
    try:
        folder.clear()
        claim(folder)
    except BaseException:
        release(folder)
        raise
    try:
        yield folder
    finally:
        record(folder)
