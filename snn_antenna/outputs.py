"""Output folders: what a study run may write into, and what it wrote.

A run never destroys what the user owns. Before a study starts, :func:`prepare` decides the
folder:

- a path that is a file, lies under a file, or cannot be written is refused (before any work);
- a new or empty folder is used as it is;
- a folder of this same study (its manifest says so) is reused: re-running a study into its own
  folder updates its report and resumes its stores;
- a folder holding another study's outputs, or files snn-antenna did not write, is refused,
  unless ``force``: then the files the toolkit wrote there (listed in the manifest) are removed
  (:meth:`OutputFolder.clear`, once every other check has passed) and the user's files are
  kept.

After the run (also a failed or interrupted one), :func:`record` lists every top-level entry the
run wrote in the folder's manifest, :data:`MANIFEST`, with the study's name. Only entries listed
there are ever removed (``--force``), and ``--fresh`` discards only a store the toolkit created.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from .errors import SpecError

MANIFEST = ".snn-antenna-manifest.json"
KIND = "snn-antenna output folder"


@dataclass
class OutputFolder:
    path: Path
    study: str
    before: dict = field(default_factory=dict)      # entry -> signature before the run
    listed: set = field(default_factory=set)        # entries the toolkit wrote before
    replace: set = field(default_factory=set)       # another study's entries, for --force
    created: bool = False                           # the run made the folder (claim)

    def clear(self) -> None:
        """Remove the other study's entries (``--force``): only what the manifest lists.
        Called once every check has passed, so a refused run removes nothing."""
        for entry in sorted(self.replace):
            _remove(self.path / entry)
        self.replace = set()
        self.before = _signatures(self.path)


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
    try:
        data = json.loads((Path(path) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("kind") != KIND \
            or not isinstance(data.get("files"), list):
        return None
    return data


def _legacy_study(path: Path) -> str | None:
    """A folder written before manifests existed: its summary.json names the study."""
    try:
        summary = json.loads((path / "summary.json").read_text())
        return summary["provenance"]["spec"]["study"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _entries(path: Path) -> list[str]:
    return sorted(e for e in os.listdir(path) if e != MANIFEST) if path.is_dir() else []


def prepare(path, study: str, force: bool = False, fresh: bool = False) -> OutputFolder:
    """Decide the output folder of a ``study`` run (see the module docstring); creates nothing."""
    path = check_writable(path)
    entries = _entries(path)
    manifest = read_manifest(path)
    if manifest is not None:
        owner, listed = manifest.get("study"), set(manifest["files"]) & set(entries)
        if owner == study and manifest.get("status") == "running":
            # a run of this study was killed before it could record what it wrote: the folder
            # held only listed entries when it started (anything else was refused then), so
            # what appeared since is that run's own partial output, to be resumed
            listed = set(entries)
    else:
        owner = _legacy_study(path) if entries else None
        listed = set(entries) if owner == study else set()
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
    return OutputFolder(path, study, _signatures(path), listed, replace)


def _remove(target: Path) -> None:
    if target.is_dir() and not target.is_symlink():
        shutil.rmtree(target)
    else:
        target.unlink(missing_ok=True)


def _signature(target: Path):
    try:
        if target.is_dir() and not target.is_symlink():
            latest, count = target.stat().st_mtime_ns, 0
            for root, dirs, files in os.walk(target):
                for name in dirs + files:
                    latest = max(latest, os.lstat(os.path.join(root, name)).st_mtime_ns)
                    count += 1
            return ("dir", latest, count)
        st = target.lstat()
        return ("file", st.st_mtime_ns, st.st_size)
    except OSError:
        return None


def _signatures(path: Path) -> dict:
    return {e: _signature(path / e) for e in _entries(path)}


def claim(folder: OutputFolder) -> None:
    """Mark the folder as being written by this study before the run starts, so a run killed
    outright (SIGKILL, power loss) leaves a folder its study may resume and no other may take."""
    folder.created = not folder.path.exists()
    folder.path.mkdir(parents=True, exist_ok=True)
    _write_manifest(folder.path, folder.study, set(folder.listed) & set(_entries(folder.path)),
                    "running")
    folder.before = _signatures(folder.path)


def record(folder: OutputFolder) -> None:
    """Write the manifest: every entry this run created or changed, and the toolkit's earlier
    entries that are still there. Atomic (a reader sees the old or the new manifest)."""
    path = folder.path
    if not path.is_dir():
        return                          # the run failed before writing anything
    written = set(folder.listed)
    for entry, signature in _signatures(path).items():
        if folder.before.get(entry) != signature:
            written.add(entry)
    written &= set(_entries(path))
    if not written and folder.created:
        # refused or failed before writing anything: leave no trace of a folder it made
        (path / MANIFEST).unlink(missing_ok=True)
        if not any(path.iterdir()):
            path.rmdir()
        return
    _write_manifest(path, folder.study, written, "ended")


def _write_manifest(path: Path, study: str, files: set, status: str) -> None:
    data = {"kind": KIND, "study": study, "files": sorted(files), "status": status,
            "updated_unix_s": time.time()}
    tmp = path / (MANIFEST + ".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path / MANIFEST)


@contextmanager
def output_folder(path, study: str, force: bool = False, fresh: bool = False):
    """``prepare`` and ``clear`` the folder, yield it, and ``record`` what the run wrote
    however it ended."""
    folder = prepare(path, study, force=force, fresh=fresh)
    folder.clear()
    claim(folder)
    try:
        yield folder
    finally:
        record(folder)
