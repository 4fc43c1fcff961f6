"""How the toolkit touches the disk: the one place that writes, appends, removes and locks.

Four promises, kept here so that every writer keeps them the same way:

- **Whole or not at all.** ``atomic_write`` writes a staging file beside the target and
  renames it into place: a reader never sees half a report, summary, manifest or recording
  header, and an interruption leaves the previous version in place.
- **No link is followed, at any depth.** Where the toolkit expects its own file or folder and
  finds a symlink, it refuses with one line (``refuse_symlink``); inside an output folder every
  folder between it and the written file is checked too; appends open with ``O_NOFOLLOW``; a
  folder is walked without following anything (``check_tree``) before it is resumed or
  removed, and any link, device, pipe or hard-linked file inside it is refused by name. A link
  the user made points at the user's data, which the toolkit did not write.
- **Ownership by identity, written ahead.** While a run holds a :class:`Journal` on its output
  folder, every name the toolkit creates at the top of that folder is recorded *before* it is
  created (``declare``) and, once it exists, with what identifies it (``note``: device and
  inode; at the run's end, for a file its size and modification time, for a folder a digest of
  every entry below it). Removal, replacement and append act only on an entry that is still
  that one (``matches``), never on the journal's word alone: an entry the user replaced or
  edited is the user's. An entry a killed run was still writing carries its device and inode
  only, and is matched on those. A folder whose outputs are kept under version control (the
  documentation's results page) identifies them by content instead (``content_identity``),
  so that its journal still proves them on another checkout.
- **Staging names are never the user's.** A staging name (``staging_name``: hidden, with the
  process id and a counter) is declared first and created exclusively (``O_EXCL``, ``mkdir``),
  so a file already bearing it is refused, never truncated or removed; a staging entry left by
  a killed run is cleaned only when its journal proves it was the toolkit's.

Appends refuse a file with more than one hard link: writing it would change the other name.
"""
from __future__ import annotations

import fcntl
import hashlib
import io
import itertools
import json
import os
import re
import stat
import threading
from pathlib import Path
from collections.abc import Callable, Iterator

from .errors import SpecError

NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
CLOEXEC = getattr(os, "O_CLOEXEC", 0)


# -- what identifies an entry ------------------------------------------------------------------
def identity(st: os.stat_result) -> dict | None:
    """Device, inode and kind of a regular file or folder (``None`` for anything else)."""
    kind = "dir" if stat.S_ISDIR(st.st_mode) else "file" if stat.S_ISREG(st.st_mode) else None
    return None if kind is None else {"kind": kind, "dev": st.st_dev, "ino": st.st_ino}


def settled_identity(path: str | Path, st: os.stat_result | None = None) -> dict | None:
    """``identity`` of ``path`` with its content's fingerprint: a file's size and modification
    time (from ``st`` when given), a folder's ``tree_digest``; ``None`` when it is missing, a
    link or a special file."""
    found = _entry(path, st)
    if found is None:
        return None
    ident, st = found
    if ident["kind"] == "file":
        return {**ident, "size": st.st_size, "mtime_ns": st.st_mtime_ns}
    return {**ident, "tree": tree_digest(path)}


def _entry(path: str | Path, st: os.stat_result | None = None):
    """``(identity, lstat)`` of the file or folder at ``path`` (``st`` when given); ``None``
    when it is missing, a link or a special file."""
    try:
        st = st if st is not None else os.lstat(path)
    except FileNotFoundError:
        return None
    ident = identity(st)
    return None if ident is None else (ident, st)


def is_settled(ident: dict | None) -> bool:
    """Whether ``ident`` holds the content's fingerprint (the entry was finished), not only
    device and inode (it was being written when its run was killed)."""
    return bool(ident) and any(key in ident for key in ("size", "tree", "sha256", "content"))


def content_identity(path: str | Path) -> dict | None:
    """What identifies an entry on every copy of it (a checkout, a clone), where device,
    inode and times differ: its kind and a digest of its content (a file's bytes; a folder's
    names and its files' bytes, ``content_digest``); ``None`` when it is missing, a link or
    a special file."""
    found = _entry(path)
    if found is None:
        return None
    if found[0]["kind"] == "file":
        return {"kind": "file", "sha256": _file_digest(path)}
    return {"kind": "dir", "content": content_digest(path)}


def _file_digest(path: str | Path) -> str:
    fd = os.open(path, os.O_RDONLY | NOFOLLOW | CLOEXEC)
    h = hashlib.sha256()
    with os.fdopen(fd, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def content_digest(folder: str | Path) -> str:
    """A digest of every entry below ``folder`` by name and content, read without following
    anything: a file added, removed or edited below it changes it, a copy of it does not."""
    h = hashlib.sha256()
    for rel, st in sorted(walk(folder), key=lambda item: item[0]):
        content = ("dir" if stat.S_ISDIR(st.st_mode) else
                   _file_digest(Path(folder) / rel) if stat.S_ISREG(st.st_mode) else
                   f"other {stat.S_IFMT(st.st_mode)}")
        h.update(json.dumps([rel, content]).encode())
    return h.hexdigest()


def tree_digest(folder: str | Path) -> str:
    """A digest of every entry below ``folder`` (its relative name, kind, inode, size and
    modification time), read without following anything: any file added, removed, replaced
    or written below it changes the digest."""
    h = hashlib.sha256()
    for rel, st in sorted(walk(folder), key=lambda item: item[0]):
        h.update(json.dumps([rel, stat.S_IFMT(st.st_mode), st.st_ino, st.st_size,
                             st.st_mtime_ns if not stat.S_ISDIR(st.st_mode) else 0]).encode())
    return h.hexdigest()[:24]


def matches(path: str | Path, ident: dict | None, writing: bool = False) -> bool:
    """Whether ``path`` is still the finished entry ``ident`` identifies (never through a
    link): same kind, device and inode, and the same size and modification time (a file) or
    the same tree (a folder). An entry that was still being written (``ident`` without its
    fingerprint) matches on device and inode only when ``writing`` (to resume it)."""
    if not ident or not (writing or is_settled(ident)):
        return False
    if "sha256" in ident or "content" in ident:     # identified by content (content_identity)
        return content_identity(path) == ident
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return False
    now = identity(st)
    if now is None or any(now[k] != ident.get(k) for k in ("kind", "dev", "ino")):
        return False
    if "size" in ident:
        return (st.st_size, st.st_mtime_ns) == (ident["size"], ident.get("mtime_ns"))
    if "tree" in ident:
        return tree_digest(path) == ident["tree"]
    return True


def same_object(path: str | Path, ident: dict | None) -> bool:
    """``matches`` on device, inode and kind only."""
    return bool(ident) and matches(path, {k: ident[k] for k in ("kind", "dev", "ino")},
                                   writing=True)


# -- walking without following --------------------------------------------------------------------
def walk(folder: str | Path) -> Iterator[tuple[str, os.stat_result]]:
    """``(relative name, lstat)`` of every entry below ``folder``; never enters a link."""
    folder = Path(folder)
    stack = [""]
    while stack:
        rel = stack.pop()
        try:
            with os.scandir(folder / rel if rel else folder) as it:
                entries = list(it)
        except (FileNotFoundError, NotADirectoryError):
            continue
        for entry in entries:
            name = f"{rel}/{entry.name}" if rel else entry.name
            st = entry.stat(follow_symlinks=False)
            yield name, st
            if stat.S_ISDIR(st.st_mode):
                stack.append(name)


def check_tree(folder: str | Path, what: str = "store") -> Path:
    """``folder`` (the toolkit's) walked without following anything, before it is resumed
    or removed: a link, a device or pipe, or a file with another hard link anywhere inside
    it is refused in one line naming it (writing there would reach what is not the toolkit's;
    removing it would take what the user placed)."""
    folder = refuse_symlink(folder, what)
    for rel, st in walk(folder):
        path = folder / rel
        if stat.S_ISLNK(st.st_mode):
            problem = f"{path} is a symbolic link (to {os.readlink(path)})"
        elif not (stat.S_ISDIR(st.st_mode) or stat.S_ISREG(st.st_mode)):
            problem = f"{path} is a device, pipe or socket"
        elif stat.S_ISREG(st.st_mode) and st.st_nlink > 1:
            problem = f"{path} is a file with another hard link ({st.st_nlink} names)"
        else:
            continue
        raise SpecError(what, str(folder),
                        f"a {what} holding only what snn-antenna wrote; {problem}, which "
                        "snn-antenna never writes through or removes: move it out, or choose "
                        "another --out")
    return folder


# -- staging names -------------------------------------------------------------------------------
_counter = itertools.count()
_STAGING = re.compile(r"^\..+\.\d+-\d+\.(tmp|partial)$")


def staging_name(path: str | Path, suffix: str = "tmp") -> Path:
    """A fresh hidden name beside ``path`` to build it under (``.NAME.PID-N.SUFFIX``)."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}-{next(_counter)}.{suffix}")


def make_staging(path: str | Path, suffix: str, create: Callable[[Path], object]):
    """``(name, create(name))`` for a fresh staging name beside ``path``: declared first,
    then made by ``create``, which must fail on an existing entry (``O_EXCL``, ``mkdir``); a
    name already taken (by anyone) is passed over, never opened."""
    for _ in range(1000):
        name = staging_name(path, suffix)
        if os.path.lexists(name):
            continue
        declare(name)
        try:
            made = create(name)
        except FileExistsError:
            continue
        note(name)
        return name, made
    raise SpecError("file", str(path), "a folder where snn-antenna can stage a file; every "
                                       "staging name it tried is taken")


def is_staging(name: str, of: str | None = None) -> bool:
    """Whether ``name`` is a staging name (of the entry ``of``, when given)."""
    return bool(_STAGING.match(name)) and (of is None or name.startswith(f".{of}."))


# -- write-ahead journals -----------------------------------------------------------------------
YOURS = "that name is a file of yours there"


class Journal:
    """The top-level entries of ``folder`` the toolkit owns, by identity.

    ``owned`` holds earlier runs' entries (checked by ``matches`` when the folder was
    prepared); ``names`` this run's: ``None`` once declared, then the entry's identity
    (``settled`` once finished). Each change is persisted (``on_change(entries)``, atomically
    and synchronously) before the name is created, and again once it exists. ``itself`` (the
    journal's own file) and its staging names are not journaled. An entry a killed run was
    still writing may be resumed (written, appended) but is never removed: nothing proves
    what was added to it since.
    """

    def __init__(self, folder: str | Path, on_change: Callable[[dict], None],
                 owned: dict | None = None, itself: str = "", unfinished=(),
                 fingerprint: Callable[[Path], dict | None] = settled_identity, changed=()):
        self.folder = Path(os.path.abspath(folder))
        self.owned: dict[str, dict] = dict(owned or {})
        self.names: dict[str, dict | None] = {}
        self.resumed: set[str] = set()             # left unfinished by a killed run
        self.unfinished = set(unfinished)          # the same, of another study: kept
        self.changed = set(changed)                # the toolkit's once, edited since: kept
        self.on_change = on_change
        self.itself = itself
        self.fingerprint = fingerprint             # what identifies a finished entry

    def entries(self) -> dict:
        return {**self.owned, **self.names}

    def _top(self, path: Path) -> tuple[str, tuple[str, ...]] | None:
        try:
            rel = Path(os.path.abspath(path)).relative_to(self.folder)
        except ValueError:
            return None
        if not rel.parts or rel.parts[0] == self.itself or is_staging(rel.parts[0],
                                                                         self.itself):
            return None
        return rel.parts[0], rel.parts

    def declare(self, path: Path) -> None:
        top = self._top(path)
        if top is None:
            return
        name, parts = top
        for depth in range(1, len(parts)):          # no link between the folder and the file
            refuse_symlink(self.folder.joinpath(*parts[:depth]), "folder")
        entry = self.folder / name
        if name in self.names:
            ident = self.names[name]
            if os.path.lexists(entry) and not matches(entry, ident, writing=True):
                raise self._not_ours(name, "it was replaced or edited while snn-antenna was "
                                           "writing")
            return
        if name in self.owned:
            ident = self.owned[name]
            if not matches(entry, ident, writing=True) and os.path.lexists(entry):
                raise self._not_ours(name, "it changed since snn-antenna wrote it")
            if not is_settled(ident):
                self.resumed.add(name)
            self.names[name] = identity(os.lstat(entry)) \
                if os.path.lexists(entry) else None      # being written: settled at the end
        elif os.path.lexists(entry):
            raise self._not_ours(name, "a run that was killed left it unfinished, so it may "
                                       "hold what is not snn-antenna's" if name in self.unfinished
                                 else "it changed since snn-antenna wrote it"
                                 if name in self.changed else YOURS)
        else:
            self.names[name] = None
        self.on_change(self.entries())

    def note(self, path: Path, st: os.stat_result | None = None,
             settled: bool = False) -> None:
        top = self._top(path)
        if top is None or len(top[1]) != 1:
            return
        ident = settled_identity(path, st) if settled else \
            identity(st if st is not None else os.lstat(path))
        if self.names.get(top[0]) != ident:
            self.names[top[0]] = ident
            self.on_change(self.entries())

    def owns(self, path: Path, removing: bool = False) -> bool:
        """Whether the top-level entry holding ``path`` is still the toolkit's (to write or
        append; to remove, when ``removing``: never an entry a killed run left unfinished,
        unless a staging name)."""
        top = self._top(path)
        if top is None:
            return True
        name, entry = top[0], self.folder / top[0]
        if removing and name in self.resumed and not is_staging(name):
            return False
        if name in self.names:
            return matches(entry, self.names[name], writing=True)
        return matches(entry, self.owned.get(name), writing=is_staging(name) or not removing)

    def forget(self, name: str) -> None:
        self.owned.pop(name, None)
        self.names.pop(name, None)
        self.on_change(self.entries())

    def settle(self) -> None:
        """The run has ended: each entry it wrote gets its content's fingerprint, and one no
        longer there (or no longer the one it made) is dropped."""
        for name, ident in list(self.names.items()):
            if matches(self.folder / name, ident, writing=True):
                self.names[name] = self.fingerprint(self.folder / name)
            else:
                del self.names[name]
        self.owned = {n: i for n, i in self.owned.items() if os.path.lexists(self.folder / n)}

    def _not_ours(self, name: str, why: str) -> SpecError:
        return not_ours(self.folder, name, why)


def not_ours(folder: Path, name: str, why: str = YOURS) -> SpecError:
    """The refusal of an output folder where ``name`` is not the toolkit's to write."""
    return SpecError("--out", str(folder),
                     f"a folder where snn-antenna may write {name}; {why}, and it is never "
                     "overwritten, appended to or removed: move it, or choose another --out")


_journals: list[Journal] = []
_journal_lock = threading.RLock()


def open_journal(journal: Journal) -> None:
    with _journal_lock:
        _journals.append(journal)


def close_journal(journal: Journal) -> None:
    with _journal_lock:
        if journal in _journals:
            _journals.remove(journal)


def declare(path: str | Path) -> None:
    """Record ``path`` (its name at the top of an output folder a run is writing) in that
    run's journal before the caller creates, replaces or appends to it; refused when that
    entry is not the toolkit's (see :class:`Journal`). Outside any journaled folder: nothing."""
    with _journal_lock:
        for journal in _journals:
            journal.declare(Path(path))


def note(path: str | Path, st: os.stat_result | None = None, settled: bool = False) -> None:
    """Record what identifies ``path`` (just created by the caller) in its run's journal;
    ``settled``: it is finished, with its content's fingerprint."""
    with _journal_lock:
        for journal in _journals:
            journal.note(Path(path), st, settled)


def _owned(path: Path, removing: bool = False) -> bool:
    with _journal_lock:
        return all(journal.owns(path, removing) for journal in _journals)


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


def cache_root() -> Path:
    """The toolkit's own cache (compiled Brian2 standalone projects): ``SNN_ANTENNA_CACHE``,
    by default ``~/.cache/snn_antenna``."""
    return Path(os.environ.get("SNN_ANTENNA_CACHE", Path.home() / ".cache" / "snn_antenna"))


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
        else:
            note(folder)
    refuse_symlink(path, "folder")
    return path


def open_append(path: str | Path, binary: bool = False):
    """``path`` opened to append, never through a symlink, never to a file with another hard
    link, and (in an output folder) only to the toolkit's own file. A file the call creates
    gets the mode any new file would get; an existing file's mode is left as its owner set it."""
    path = Path(path)
    make_folder(path.parent)
    refuse_symlink(path)
    declare(path)
    existed = os.path.lexists(path)
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | NOFOLLOW | CLOEXEC
    try:
        fd = os.open(path, flags, 0o666)      # the umask applies, as to any new file
    except OSError as exc:
        if path.is_symlink():                 # made a link between the check and the open
            refuse_symlink(path)
        raise SpecError("file", str(path), f"a file snn-antenna can append to ({exc.strerror})"
                        ) from None
    st = os.fstat(fd)
    problem = ("a regular file (this is a device, pipe or folder)" if not stat.S_ISREG(st.st_mode)
               else f"a file with one name; this one has another hard link ({st.st_nlink} "
                    "names), which an append would change too: copy it instead of linking it"
               if st.st_nlink > 1 else None)
    if problem is None and existed and not _owned(path):
        problem = "the toolkit's own file; it was replaced while snn-antenna was writing"
    if problem is not None:
        os.close(fd)
        raise SpecError("file", str(path), problem)
    note(path, st)
    raw = _Appending(fd, path)
    buffered = io.BufferedWriter(raw)
    return buffered if binary else io.TextIOWrapper(buffered, encoding="utf-8",
                                                    line_buffering=False)


class _Appending(io.FileIO):
    """An append-only file that tells its journal what it is once closed (finished)."""

    def __init__(self, fd: int, path: Path):
        super().__init__(fd, "a", closefd=True)
        self._path = path

    def close(self) -> None:
        if not self.closed:
            try:
                note(self._path, os.fstat(self.fileno()), settled=True)
            finally:
                super().close()


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
def atomic_write(path: str | Path, data: bytes | str) -> None:
    """Write to a staging file beside ``path`` and rename it into place.

    The staging name is declared before it exists and made with ``O_EXCL``, so a run killed
    mid-write leaves only a name its journal holds (with its identity), and a file of the
    user's that bears such a name is never opened. The file gets the mode any new file would
    get (0644 under the usual umask 022). A symlink at ``path`` is refused, not replaced, and
    so is (in an output folder) an entry that is no longer the toolkit's.
    """
    path = Path(path)
    make_folder(path.parent)
    refuse_symlink(path)
    declare(path)
    tmp, fd = make_staging(path, "tmp", lambda name: os.open(
        name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | NOFOLLOW | CLOEXEC, 0o666))
    made = os.fstat(fd)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data if isinstance(data, bytes) else data.encode("utf-8"))
            f.flush()
            os.fsync(f.fileno())
            st = os.fstat(f.fileno())
        refuse_symlink(path)
        os.replace(tmp, path)
        note(path, st, settled=True)
    except BaseException:
        if same_object(tmp, identity(made)):          # only the file it made
            os.unlink(tmp)
        raise


def write_json(path: str | Path, data, indent: int = 1) -> None:
    """``data`` as JSON, written atomically (``atomic_write``)."""
    atomic_write(path, json.dumps(data, indent=indent))


def remove_entry(target: str | Path, ident: dict | None = None) -> None:
    """Remove a file or folder the toolkit created, and only that: a symlink where it was is
    refused (the user put it there); in an output folder, an entry that is no longer the one
    its journal identifies is refused; with ``ident``, so is anything that does not
    ``match`` it. A folder is walked first (``check_tree``) and removed without following
    anything."""
    target = Path(target)
    refuse_symlink(target, "entry")
    if not os.path.lexists(target):
        return
    if not _owned(target, removing=True) or (
            ident is not None and not matches(target, ident, writing=is_staging(target.name))):
        raise SpecError("entry", str(target),
                        "an entry snn-antenna wrote and finished, to be removed; this one "
                        "changed since (replaced or edited), or a run that was killed left it "
                        "unfinished, so it may hold what is not snn-antenna's and is kept: "
                        "move it away, or choose another --out")
    if target.is_dir():
        check_tree(target, "folder")
        _remove_tree(target)
    else:
        target.unlink()


def _remove_tree(folder: Path) -> None:
    """Remove ``folder`` and everything below it (``check_tree`` has passed), deepest first,
    each entry by name relative to its parent's descriptor: nothing is followed."""
    for rel, st in sorted(walk(folder), key=lambda item: -item[0].count("/")):
        path = folder / rel
        if stat.S_ISDIR(st.st_mode):
            os.rmdir(path)
        else:
            os.unlink(path)
    os.rmdir(folder)


# -- one writer per folder ----------------------------------------------------------------------
def lock_folder(path: str | Path, follow: bool = False) -> int | None:
    """An exclusive ``flock`` on the folder ``path`` itself (no lock file to leave behind):
    its descriptor, held until closed, or ``None`` when another process holds it. The kernel
    releases the lock of a process that dies. A symlink at ``path`` is refused unless
    ``follow`` (the output folder a user names may itself be a link)."""
    path = Path(path) if follow else refuse_symlink(path, "folder")
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | CLOEXEC
                 | (0 if follow else NOFOLLOW))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd
