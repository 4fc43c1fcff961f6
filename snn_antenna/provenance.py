"""Which code made a result: the package version, a hash of its source, the git commit.

Every cache key and every store fingerprint includes :func:`code_hash`, so a result computed by
other code is never taken for this code's (a changed neuron constant, a changed preprocessing
step: the old store is refused on resume, the old cache rebuilt). The hash covers the whole
package's source, which is the simplest rule that cannot miss a dependency; its price is that
any edit of the package invalidates every cache.
"""
from __future__ import annotations

import datetime as _dt
import functools
import hashlib
import platform
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=1)
def code_hash() -> str:
    """SHA-256 (16 hex digits) of the package version and every ``.py`` file of the package,
    by relative path and content."""
    from . import __version__

    h = hashlib.sha256(__version__.encode())
    for path in sorted(PACKAGE.rglob("*.py")):
        h.update(str(path.relative_to(PACKAGE)).encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


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


def code_identity() -> dict:
    """What summaries and store attributes record about the code that made them."""
    from . import __version__

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
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join(sys.argv),
    }
