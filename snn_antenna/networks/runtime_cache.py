"""Which of the toolkit's runtime networks this interpreter has compiled on Brian2's cython
target, so an estimate charges the compile only to a network that will be compiled.

Brian2 keeps each compiled code object in its cython cache (``~/.cython/brian_extensions``)
under a hash of the generated code, the Python executable and the Cython and numpy versions:
a new virtual environment compiles every network again, and an unchanged one finds them all.
Finding that hash needs the code generated, so instead a network's run leaves a marker
(``note``) named by what that hash covers: the network's name, the source of the module that
builds it (with its imports), the executable and the versions; ``compiled`` asks for it
without importing Brian2.
"""
from __future__ import annotations

import hashlib
import json
import sys
from importlib.metadata import PackageNotFoundError, version

from ..core.files import atomic_write, cache_root, make_folder
from ..core.provenance import code_hash


def _version(package: str) -> str:
    try:
        return version(package)
    except PackageNotFoundError:
        return ""


def key(network: str, module: str) -> str:
    """The marker's name for ``network`` built by ``module`` (a dotted module name)."""
    import numpy

    text = json.dumps([network, code_hash(module), sys.executable, _version("brian2"),
                       _version("Cython"), ".".join(numpy.__version__.split(".")[:2])])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _marker(network: str, module: str):
    return cache_root() / "cython_networks" / key(network, module)


def compiled(network: str, module: str) -> bool:
    """Whether this interpreter ran ``network`` on the cython target with this code."""
    return _marker(network, module).is_file()


def note(network: str, module: str, target: str) -> None:
    """Record that ``network`` ran on ``target`` (a marker for cython only: numpy compiles
    nothing)."""
    if target != "cython":
        return
    path = _marker(network, module)
    if not path.is_file():
        make_folder(path.parent)
        atomic_write(path, f"{network} ({module}) compiled by {sys.executable}\n")
