"""How the toolkit touches the disk: the one place that writes, appends and removes.

Three promises, kept here so that every writer keeps them the same way:

- **Whole or not at all.** ``atomic_write`` writes beside the target and renames into place: a
  reader never sees half a report, summary or recording header, and an interruption leaves the
  previous version in place.
- **No symlink is followed.** Where the toolkit expects its own file or folder and finds a
  symlink, it refuses with one line (``refuse_symlink``); appends open with ``O_NOFOLLOW``;
  removal (``remove_entry``) never descends through a link. A link the user made points at the
  user's data, which the toolkit did not write.
- **Write-ahead ownership.** While a run holds a :class:`Journal` on its output folder, every
  name the toolkit creates at the top of that folder is recorded in the journal *before* it is
  created (``declare``), so a run killed at any instant leaves exactly the names it created, and
  nothing else in the folder is ever taken as the toolkit's (``outputs`` keeps the journal).
"""
from __future__ import annotations

import itertools
import json
import os
import shutil
import stat
import threading
from pathlib import Path
from typing import Callable

from .errors import SpecError


# -- write-ahead journals -----------------------------------------------------------------------
class Journal:
    """The top-level names one run creates in ``folder``; ``on_new(names)`` persists the
    set (atomically, synchronously) each time it grows, before the name is created. A name
    that already exists and is not ``owned`` (the toolkit's from before) is the user's: it is
    refused, never overwritten (``--force`` keeps the user's files, so a study may meet one
    that bears a name it writes)."""

    def __init__(self, folder: str | Path, on_new: Callable[[set], None], owned=()):
        self.folder = Path(os.path.abspath(folder))
        self.names: set[str] = set()
        self.owned = set(owned)
        self.on_new = on_new

    def declare(self, path: Path) -> None:
        try:
            rel = Path(os.path.abspath(path)).relative_to(self.folder)
        except ValueError:
            return
        if not rel.parts:
            return
        name = rel.parts[0]
        if name not in self.names:
            if name not in self.owned and os.path.lexists(self.folder / name):
                raise SpecError("--out", str(self.folder),
                                f"a folder where snn-antenna may write {name}; that name is "
                                "a file of yours there, which it never overwrites: move it, "
                                "or choose another --out")
            self.names.add(name)
            self.on_new(set(self.names))


_journals: list[Journal] = []
_journal_lock = threading.Lock()


def open_journal(journal: Journal) -> None:
    with _journal_lock:
        _journals.append(journal)


def close_journal(journal: Journal) -> None:
    with _journal_lock:
        if journal in _journals:
            _journals.remove(journal)


def declare(path: str | Path) -> None:
    """Record ``path`` (its name at the top of an output folder a run is writing) in that
    run's journal before the caller creates it. Outside any journaled folder: nothing."""
    with _journal_lock:
        for journal in _journals:
            journal.declare(Path(path))


# -- no symlinks ---------------------------------------------------------------------------------
def refuse_symlink(path: str | Path, what: str = "file") -> Path:
    """``path`` itself, refused with one line when it is a symbolic link (never followed)."""
    path = Path(path)
    if path.is_symlink():
        raise SpecError(what, str(path),
                        f"a {what} snn-antenna writes itself; this is a symbolic link (to "
                        f"{os.readlink(path)}), which snn-antenna never follows when writing, "
                        "replacing or removing: remove the link or choose another --out")
    return path


def make_folder(path: str | Path) -> Path:
    """``path`` as a folder (created with its parents, each declared first); a symlink where a
    folder of the toolkit's goes is refused."""
    path = Path(path)
    missing = []
    probe = path
    while not os.path.lexists(probe):
        missing.append(probe)
        if probe.parent == probe:
            break
        probe = probe.parent
    for folder in reversed(missing):
        declare(folder)
        try:
            os.mkdir(folder)
        except FileExistsError:
            pass
    refuse_symlink(path, "folder")
    return path


def open_append(path: str | Path, binary: bool = False):
    """``path`` opened to append, never through a symlink. A file the call creates gets the
    mode any new file would get; an existing file's mode is left as its owner set it."""
    path = Path(path)
    make_folder(path.parent)
    refuse_symlink(path)
    declare(path)
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) \
        | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags, 0o666)      # the umask applies, as to any new file
    except OSError as exc:
        if path.is_symlink():                 # made a link between the check and the open
            refuse_symlink(path)
        raise SpecError("file", str(path), f"a file snn-antenna can append to ({exc.strerror})"
                        ) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise SpecError("file", str(path), "a regular file (this is a device, pipe or folder)")
    return os.fdopen(fd, "ab" if binary else "a", **({} if binary else {"encoding": "utf-8"}))


def write_new(path: str | Path, data: bytes | str, force: bool = False,
              option: str = "--log") -> None:
    """``data`` as a new file at ``path`` (atomically); an existing file is the user's and is
    refused unless ``force`` (a symlink always is)."""
    path = Path(path)
    refuse_symlink(path, "file")
    if path.exists() and not force:
        raise SpecError(option, str(path), "a path that does not exist yet (this file would be "
                                           "overwritten): choose another, or pass --force")
    atomic_write(path, data)


# -- whole or not at all -------------------------------------------------------------------------
_tmp_counter = itertools.count()


def atomic_write(path: str | Path, data: bytes | str) -> None:
    """Write to a temporary file beside ``path`` and rename it into place.

    The temporary name is declared (and made with ``O_EXCL``) before it exists, so a run killed
    mid-write leaves only a name its journal holds. The file gets the mode any new file would
    get (0644 under the usual umask 022). A symlink at ``path`` is refused, not replaced.
    """
    path = Path(path)
    make_folder(path.parent)
    refuse_symlink(path)
    declare(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{next(_tmp_counter)}.tmp")
    declare(tmp)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    fd = os.open(tmp, flags, 0o666)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data if isinstance(data, bytes) else data.encode("utf-8"))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.lexists(tmp):
            os.unlink(tmp)
        raise


def write_json(path: str | Path, data, indent: int = 1) -> None:
    """``data`` as JSON, written atomically (``atomic_write``)."""
    atomic_write(path, json.dumps(data, indent=indent))


def remove_entry(target: str | Path) -> None:
    """Remove a file or folder the toolkit created: a folder's tree is removed without
    following any link inside it; a symlink where the toolkit's entry was is refused (the
    user put it there)."""
    target = Path(target)
    refuse_symlink(target, "entry")
    if target.is_dir():
        shutil.rmtree(target)
    elif os.path.lexists(target):
        target.unlink()
