"""Which code made a result: the package version, a hash of its source, the git commit.

Every cache key and every store fingerprint includes :func:`code_hash` of the code that
computes it, so a result computed by other code is never taken for this code's (a changed
neuron constant, a changed preprocessing step: the old store is refused on resume, the old
cache rebuilt). A computation names the module that computes it (``code_hash("snn_antenna.
sources.bench")``) and the hash covers that module and every package module it imports, at
any depth, including imports inside functions (:func:`import_closure`): editing the live page
leaves 12,800 generated bench contacts valid, editing the antenna physics does not.
A module that imports by name at run time (``importlib``) could reach code the closure cannot
see, so a closure holding one widens to the whole package. Summaries record the whole
package's hash and the git commit (:func:`code_identity`).
"""
from __future__ import annotations

import ast
import datetime as _dt
import functools
import hashlib
import os
import platform
import subprocess
import sys
from pathlib import Path
from .. import __version__

PACKAGE = Path(__file__).resolve().parents[1]


@functools.cache
def code_hash(*modules: str) -> str:
    """SHA-256 (16 hex digits) of the package version and of source files by relative path
    and content: with no argument every ``.py`` file of the package, else the
    :func:`import_closure` of ``modules`` (dotted names, e.g. ``"snn_antenna.engine.events"``)."""
    h = hashlib.sha256(__version__.encode())
    files = import_closure(modules) if modules else sorted(PACKAGE.rglob("*.py"))
    for path in files:
        h.update(str(path.relative_to(PACKAGE)).encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def file_digest(path) -> str:
    """SHA-256 (16 hex digits) of one file's bytes: a script outside the package (a
    benchmark's) that a record names beside :func:`code_hash`."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def import_closure(modules) -> list[Path]:
    """The source files of ``modules`` and of every package module they import, followed to
    any depth: ``import`` and ``from ... import`` statements anywhere in a module (a function's
    lazy import too), relative or absolute, and the ``__init__.py`` of every package on the
    way. Imported names outside the package are left out (their versions are recorded
    elsewhere). A root outside the package (a user's evaluator) or a module calling
    ``import_module`` makes it the whole package: its imports cannot be followed."""
    whole = sorted(PACKAGE.rglob("*.py"))
    if any(_source_of(name) is None for name in modules):
        return whole
    seen: dict[str, Path] = {}
    todo = list(modules)
    while todo:
        name = todo.pop()
        path = _source_of(name)
        if path is None or name in seen:
            continue
        seen[name] = path
        parts = name.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]     # parent packages
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_bytes())):
            if isinstance(node, ast.Call) and "import_module" in ast.unparse(node.func):
                return whole
            if isinstance(node, ast.Import):
                todo += [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = here.split(".")[:len(here.split(".")) - node.level + 1] \
                    if node.level else []
                base = ".".join(base + ([node.module] if node.module else []))
                # ``from pkg import name``: name is a submodule or an attribute of pkg
                todo += [base] + [f"{base}.{alias.name}" for alias in node.names]
    return sorted(set(seen.values()))


def _source_of(name: str) -> Path | None:
    """The file of package module ``name``, or None for anything else."""
    parts = name.split(".")
    if parts[0] != PACKAGE.name:
        return None
    stem = PACKAGE.joinpath(*parts[1:])
    for path in (stem.with_suffix(".py"), stem / "__init__.py"):
        if len(parts) > 1 and path.is_file() or path == PACKAGE / "__init__.py":
            return path
    return None


@functools.lru_cache(maxsize=1)
def git_commit() -> str | None:
    """The commit of the checkout the package runs from, ``+dirty`` when its files differ;
    ``None`` outside a git checkout (an installed wheel)."""
    try:
        run = functools.partial(subprocess.run, cwd=PACKAGE, capture_output=True, text=True,
                                timeout=5)
        head = run(["git", "rev-parse", "HEAD"])
        if head.returncode != 0:
            return None
        dirty = run(["git", "status", "--porcelain", "--untracked-files=no", "--", "."])
        return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


@functools.lru_cache(maxsize=1)
def machine() -> str:
    """The machine a run ran on, in words a reader of a mailed report can compare: the CPU's
    model name (``/proc/cpuinfo``, else ``platform.processor()``), its logical cores, and the
    operating system (``platform.platform()``)."""
    cpu = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as info:
            cpu = next((line.split(":", 1)[1].strip() for line in info
                        if line.startswith("model name")), "")
    except OSError:
        pass
    cpu = cpu or platform.processor() or platform.machine() or "unknown CPU"
    cores = os.cpu_count()
    return f"{cpu}, {cores} cores, {platform.platform()}" if cores else \
        f"{cpu}, {platform.platform()}"


def code_identity() -> dict:
    """What summaries and store attributes record about the code that made them."""
    return {"snn_antenna_version": __version__, "code_sha256": code_hash(),
            "git_commit": git_commit()}


def provenance(spec: dict, target: str | None = None) -> dict:
    """What ``summary.json`` records about a run: its resolved spec and seed, the code that
    made it (``code_identity``), the libraries' versions, the Brian2 target, the command."""
    import brian2
    import numpy
    import scipy
    import sklearn

    return {
        "spec": spec,
        "seed": spec.get("seed", 0),
        **code_identity(),             # version, source hash, git commit
        "brian2_version": brian2.__version__,
        "brian2_target": target or str(brian2.prefs.codegen.target),
        "numpy_version": numpy.__version__,
        "scipy_version": scipy.__version__,
        "sklearn_version": sklearn.__version__,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "command": " ".join(sys.argv),
    }
