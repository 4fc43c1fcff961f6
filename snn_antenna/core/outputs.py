"""Output folders: what a study run may write into, what it wrote, and who is writing.

A run never destroys what the user owns. Ownership is kept by a write-ahead journal, never
guessed: the folder's manifest, :data:`MANIFEST`, is written before anything else, and every
name the run creates at the top of the folder is added to it *before* it is created, then with
what identifies it (the toolkit's writers call ``files.declare`` and ``files.note``; see
:mod:`snn_antenna.core.files`). A run killed at any instant leaves exactly the names it created
listed; nothing else in the folder, and no listed entry that has since been replaced or edited,
is ever taken as the toolkit's.

:func:`output_folder` is the one door to an output folder (a study run's, a recording's, an
imported data set's, the results page's), in three phases:

1. **check**, on entering: the folder is decided and, when it exists, locked; everything it
   would refuse is refused here, before anything is created (``--check`` leaves after this
   phase, and the folder is released as it was):

   - a path that is a file, lies under a file, or cannot be written is refused;
   - a folder another run is writing (it holds the folder's lock) is refused, naming its PID
     and start time; a lock left by a dead process is released by the kernel and simply taken;
   - a new or empty folder is used as it is (``new``: only such a folder: a recording is
     never written into one that holds anything);
   - a folder of this same study (its manifest says so) is reused: re-running a study into
     its own folder updates its report and resumes its stores (also after a killed run: its
     journal lists what it made); staging files a killed run left are removed;
   - a folder holding another study's outputs, or files snn-antenna did not write (or wrote
     and the user has replaced or edited since), is refused, unless ``force``: then the
     entries the manifest lists that are still the toolkit's are removed (at the claim, once
     every other check has passed) and the user's files are kept. No link is followed at any
     depth: a folder holding a link, a device or a hard-linked file is refused, not removed.

2. **claim** (:meth:`OutputFolder.claim`): remove what ``force`` replaces, create and lock the
   folder, write its manifest before anything else and open the write-ahead journal.
3. **record**, on leaving however the block ended: close the journal, write the manifest
   (what the run wrote) and release the lock.

A **shared** folder is one the toolkit writes a few names into among the user's files (the
documentation folder, where ``snn-antenna results`` writes ``results.md`` and ``results/``):
the user's files there are neither refused nor touched, and each name the run writes must
still be new or the toolkit's by its manifest. Such a folder is kept under version control,
so its manifest identifies the entries by content (``files.content_identity``), which every
checkout shares, and holds no time, host or process once the run has ended.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from . import files
from .errors import SpecError

MANIFEST = ".snn-antenna-manifest.json"
KIND = "snn-antenna output folder"


@dataclass
class OutputFolder:
    path: Path
    study: str
    listed: dict = field(default_factory=dict)      # the toolkit's earlier entries: identity
    replace: dict = field(default_factory=dict)     # another study's entries, for --force
    unfinished: set = field(default_factory=set)    # what its killed run left: kept
    changed: dict = field(default_factory=dict)     # listed, but edited since: kept
    created: bool = False                           # the run made the folder
    lock_fd: int | None = None                      # the folder's flock, held for the run
    journal: files.Journal | None = None
    started: str | None = None
    shared: bool = False                            # among the user's files (module docstring)

    def claim(self) -> None:
        """The second phase: every check has passed, so the run takes the folder (see
        :func:`output_folder`); a refused run has removed and created nothing."""
        for entry, ident in sorted(self.replace.items()):   # --force: only what its manifest
            files.remove_entry(self.path / entry, ident)      # lists, still the toolkit's
        self.replace = {}
        _claim(self)

    def check_writes(self, names) -> None:
        """Refuse now, before the claim, any of ``names`` (entries at the folder's top the run
        will write) that is there and not the toolkit's: in a shared folder nothing is
        written when one of them would be refused."""
        for name in names:
            if os.path.lexists(self.path / name) and name not in self.listed:
                raise files.not_ours(self.path, name, "it changed since snn-antenna wrote it"
                                     if name in self.changed else files.YOURS)


def check_writable(path, field: str = "--out", what: str = "a folder path") -> Path:
    """Refuse a folder path that is a file, lies under a file, or cannot be written (by the
    user running the toolkit), naming ``field`` and ``what`` the folder is for. A link is
    not followed to decide (a link to a file is refused as one)."""
    path = Path(path)
    if os.path.lexists(path) and not path.is_dir():
        raise SpecError(field, str(path), f"{what} ({path} is a symbolic link to nothing)"
                        if path.is_symlink() and not path.exists()
                        else f"{what} (this is an existing file)")
    ancestor = path                         # the nearest part of the path that exists
    while not os.path.lexists(ancestor) and ancestor.parent != ancestor:
        ancestor = ancestor.parent
    if ancestor != path and not ancestor.is_dir():
        raise SpecError(field, str(path), f"{what} ({ancestor} is a file, so nothing can be "
                                          "created under it)")
    if not os.access(ancestor if ancestor.is_dir() else ancestor.parent, os.W_OK | os.X_OK):
        raise SpecError(field, str(path), f"a folder you can write to ({ancestor} is not "
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
            or not isinstance(data.get("files"), list) \
            or not isinstance(data.get("identity", {}), dict):
        raise SpecError("--out", str(path),
                        f"a folder whose {MANIFEST} is one snn-antenna wrote; this one is "
                        "not: choose another --out")
    return data


def _entries(path: Path) -> list[str]:
    if not path.is_dir():
        return []
    return sorted(e for e in os.listdir(path)
                  if e != MANIFEST and not files.is_staging(e, MANIFEST))


def _prepare(path, study: str, force: bool, fresh: bool, new: bool,
             shared: bool = False) -> OutputFolder:
    """The first phase: decide the output folder of a ``study`` run (see the module
    docstring) and take its lock when the folder exists; creates nothing."""
    path = check_writable(path)
    lock_fd = lock_folder(path) if path.is_dir() else None
    try:
        folder = _decide(path, study, force, fresh, new, shared)
    except BaseException:
        _unlock(lock_fd)
        raise
    folder.lock_fd = lock_fd
    folder.shared = shared
    return folder


def _decide(path: Path, study: str, force: bool, fresh: bool, new: bool,
            shared: bool = False) -> OutputFolder:
    entries = _entries(path)
    if new and entries:
        shown = ", ".join(entries[:4]) + (", …" if len(entries) > 4 else "")
        raise SpecError("--out", str(path), f"a new or empty folder; it holds {shown} (an "
                                            "existing recording or other files are never "
                                            "overwritten or written into): choose another "
                                            "--out")
    manifest = read_manifest(path)
    owner = manifest.get("study") if manifest else None
    known = {name: (manifest.get("identity") or {}).get(name) for name in manifest["files"]
             if isinstance(name, str)} if manifest else {}
    listed = {name: ident for name, ident in known.items()
              if name in entries and files.matches(path / name, ident, writing=True)}
    foreign = [] if shared else [e for e in entries if e not in listed]   # the user's: kept
    changed = [e for e in foreign if e in known]
    other_study = owner is not None and owner != study
    if (other_study or foreign) and not force:
        held = (f"the outputs of the {owner!r} study" if other_study
                else "files snn-antenna did not write" + (" or that changed since it wrote "
                                                          "them" if changed else ""))
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
                                f"{MANIFEST}, or changed since); --fresh never removes anything "
                                "else")
    replace, unfinished = {}, set()
    if other_study and force:       # what a killed run left unfinished is never removed
        replace = {n: i for n, i in listed.items() if files.is_settled(i)}
        unfinished = set(listed) - set(replace)
        listed = {}
    for entry in replace:                   # before anything is removed
        if (path / entry).is_dir():
            files.check_tree(path / entry, "folder")
    return OutputFolder(path, study, listed, replace, unfinished,
                        changed={e: known[e] for e in entries if e in known and e not in listed})


# -- one writer per folder ----------------------------------------------------------------------
def lock_folder(path: Path) -> int:
    """An exclusive lock on the output folder (``files.lock_folder``), refused at once,
    naming the holder, when another run holds it. A killed run's lock is released by the
    kernel, so its folder is simply taken."""
    fd = files.lock_folder(path, follow=True)   # --out may itself be a link the user made
    if fd is None:
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


def _release(folder: OutputFolder) -> None:
    """Give up the folder: close its journal (if claimed) and unlock it."""
    if folder.journal is not None:
        files.close_journal(folder.journal)
    _unlock(folder.lock_fd)
    folder.lock_fd = None


def _claim(folder: OutputFolder) -> None:
    """Create and lock the folder, write its manifest before anything else, open the
    write-ahead journal that lists every name the run creates before it is created, and
    remove the staging files a killed run of the toolkit's left (its journal proves them)."""
    folder.created = not folder.path.exists()
    folder.path.mkdir(parents=True, exist_ok=True)
    if folder.lock_fd is None:
        folder.lock_fd = lock_folder(folder.path)
    folder.started = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    folder.listed = {name: ident for name, ident in folder.listed.items()
                     if files.matches(folder.path / name, ident, writing=True)}
    journal = files.Journal(folder.path,
                            lambda entries: _write_manifest(folder, entries, "running"),
                            owned=folder.listed, itself=MANIFEST,
                            unfinished=folder.unfinished,
                            fingerprint=files.content_identity if folder.shared
                            else files.settled_identity, changed=folder.changed)
    folder.journal = journal
    _write_manifest(folder, journal.entries(), "running")
    files.open_journal(journal)
    for name, ident in sorted(folder.listed.items()):
        if files.is_staging(name):
            files.remove_entry(folder.path / name, ident)
            journal.forget(name)


def _record(folder: OutputFolder) -> None:
    """Close the journal and write the manifest: every entry this run created, with what
    identifies it now that it is written, and the toolkit's earlier entries that are still
    there; release the lock. Atomic (a reader sees the old or the new manifest)."""
    try:
        journal = folder.journal
        if journal is not None:
            files.close_journal(journal)
        path = folder.path
        if not path.is_dir() or journal is None:
            return                          # the run failed before writing anything
        journal.settle()
        if not journal.names and folder.created:
            # refused or failed before writing anything: leave no trace of a folder it made
            (path / MANIFEST).unlink(missing_ok=True)
            if not any(path.iterdir()):
                path.rmdir()
            return
        _write_manifest(folder, journal.entries(), "ended")
    finally:
        _release(folder)


def _write_manifest(folder: OutputFolder, entries: dict, status: str) -> None:
    if folder.shared:               # an entry edited by hand stays listed as the toolkit wrote
        entries = {**folder.changed, **entries}     # it: restored, it is the toolkit's again
    data = {"kind": KIND, "study": folder.study, "files": sorted(entries),
            "identity": {name: entries[name] for name in sorted(entries)}, "status": status}
    if not (folder.shared and status == "ended"):   # a kept manifest: the same on every run
        data.update(pid=os.getpid(), host=socket.gethostname(), started=folder.started,
                    updated_unix_s=time.time())
    files.atomic_write(folder.path / MANIFEST, json.dumps(data, indent=1))


@contextmanager
def output_folder(path, study: str, *, force: bool = False, fresh: bool = False,
                  new: bool = False, shared: bool = False) -> Iterator[OutputFolder]:
    """The one door to an output folder (see the module docstring). Entering checks it (a
    refusal is raised here, before anything is created; a ``--check`` leaves the block now,
    and the folder is released as it was); ``folder.claim()`` takes it; leaving records what
    the run wrote, however the block ended. ``shared``: the folder holds the user's files
    too, and its entries are identified by content (the module docstring)."""
    folder = _prepare(path, study, force, fresh, new, shared)
    try:
        yield folder
    finally:
        if folder.journal is not None:
            _record(folder)
        else:
            _release(folder)
