"""The one shape of a study: what its module declares and what the command calls.

A study module declares

- ``SECTIONS``: the top-level keys its spec may hold besides ``study``, ``seed`` and
  ``description``: its tables, and ``data`` for a study that reads recorded data sets;
- ``OPTIONS``: the command-line options it takes (names of :class:`Options` fields); an option
  it does not take is refused before any work, naming the study and the ones it takes;
- ``plan(spec) -> Plan``: the whole spec checked and every part built that needs no
  simulation; the plan sizes its own work (:meth:`Plan.estimate`) from those parts, so the
  study's defaults are written once, in its own dataclasses;
- ``run(plan, out_dir, options, log=print) -> dict``: the study itself, on the parts its plan
  built; it returns the summary (``log`` takes its progress lines).

:func:`check_study` states the contract as a test can check it.
"""
from __future__ import annotations

import dataclasses
import inspect
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable
from collections.abc import Callable

from ..core.errors import SpecError
from ..core.bounds import out_path
from ..engine.cost import study_overhead_s

# What every study takes: the quick profile, stopping after the checks, running beyond the
# cost limit, reusing a folder that holds another study's outputs.
COMMON = ("quick", "check", "yes", "force")


@dataclass(frozen=True)
class Options:
    """The command-line options of ``snn-antenna run``, as a study receives them."""
    quick: bool = False          # the spec's [quick] profile was applied
    check: bool = False          # stop after the first phase (every check), run nothing
    yes: bool = False            # run even when the estimate is beyond the limit
    force: bool = False          # replace another study's outputs in --out
    fresh: bool = False          # discard stored results or caches and start over
    scheduler: str | None = None  # an existing Dask cluster's address
    data: str | None = None      # a folder of recorded data sets (the spec's ``data``)

    def given(self) -> list[str]:
        """The options set to something other than their default, in declaration order."""
        return [f.name for f in dataclasses.fields(self)
                if getattr(self, f.name) != f.default]


def flag(name: str) -> str:
    return "--" + name.replace("_", "-")


# Dask's address schemes (``distributed.comm``): what --scheduler may name
SCHEDULER_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


def scheduler_address(field: str, value: str) -> str:
    """A Dask scheduler's address, ``[SCHEME://]HOST:PORT`` (checked by its form: connecting
    is the run's first step)."""
    from urllib.parse import urlsplit

    accepted = (f"an address such as tcp://HOST:8786 (schemes: "
                f"{', '.join(SCHEDULER_SCHEMES)})")
    try:
        parts = urlsplit(value if "://" in value else f"tcp://{value}")   # Dask's default
        port = parts.port
    except ValueError:
        raise SpecError(field, value, accepted) from None
    if parts.scheme not in SCHEDULER_SCHEMES or not parts.hostname or parts.path.strip("/") \
            or any(c.isspace() for c in value) \
            or (parts.scheme != "inproc" and port is None):
        raise SpecError(field, value, accepted)
    return value


def refused_options(study: str, accepted, options: Options) -> str | None:
    """The message refusing the first option ``study`` does not take, or None."""
    for name in options.given():
        if name not in accepted:
            takes = ", ".join(flag(o) for o in accepted)
            return f"{flag(name)}: the {study} study takes {takes}"
    return None


@dataclass
class Plan:
    """A study's spec, checked, and the parts built from it before any simulation.

    ``parts`` is the study's own (its dataclass of built objects); ``sizes`` turns them into
    the cost of the run (``engine.cost.JobEstimate`` or, for a neuron sweep,
    ``engine.cost.Estimate``), or None for a study with nothing to size. ``left_out``: one
    line per part of the spec the run leaves out or clips because its data cannot carry it
    (a recorded set's rate); the run logs them and keeps them in its summary, ``--check``
    prints them."""
    study: str
    spec: dict
    parts: Any
    sizes: Callable[[Any], Any] | None = None
    left_out: list[str] = field(default_factory=list)

    def estimate(self):
        """The study's cost (``sizes``), its process's start and its report included."""
        if self.sizes is None:
            return None
        sized = self.sizes(self.parts)
        sized.seconds += study_overhead_s()
        return sized

    @property
    def seed(self) -> int:
        return int(self.spec.get("seed", 0))


@runtime_checkable
class Study(Protocol):
    """What a study module is (modules satisfy it by their attributes)."""
    SECTIONS: tuple
    OPTIONS: tuple

    def plan(self, spec: dict) -> Plan: ...

    def run(self, plan: Plan, out_dir, options: Options, log=print) -> dict: ...


def check_study(module) -> list[str]:
    """What ``module`` lacks of the contract (empty: it keeps it)."""
    problems = []
    if not isinstance(module, Study):
        problems.append("lacks one of SECTIONS, OPTIONS, plan, run")
        return problems
    known = {f.name for f in dataclasses.fields(Options)}
    unknown = set(module.OPTIONS) - known
    if unknown:
        problems.append(f"declares options no command has: {sorted(unknown)}")
    if not set(COMMON) <= set(module.OPTIONS):
        problems.append(f"does not take every common option {COMMON}")
    # ``log``: where a run's progress goes (tests silence it); nothing else, and no catch-all
    for name, params in (("plan", ["spec"]), ("run", ["plan", "out_dir", "options", "log"])):
        signature = inspect.signature(getattr(module, name))
        got = [p.name for p in signature.parameters.values()]
        if got != params or any(p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL)
                                for p in signature.parameters.values()):
            problems.append(f"{name}{signature} is not {name}({', '.join(params)})")
    return problems


# -- what several studies check the same way -------------------------------------------------
def data_folder(spec: dict) -> Path | None:
    """The spec's ``data``: a folder of recorded data sets that exists (``--data``)."""
    if "data" not in spec:
        return None
    value = spec["data"]
    path = Path(out_path("data", value))
    if not path.is_dir():
        raise SpecError("data", value, "the path of an existing folder of recorded data sets"
                        + (" (this one is a file)" if path.exists() else ""))
    return path


def cache_folder(field: str, value) -> Path:
    """A cache folder the run can create or reuse: not a file, nor under one, and writable."""
    path = Path(out_path(field, value))
    if os.path.lexists(path) and not path.is_dir():
        raise SpecError(field, str(value), "a folder for the cache (this path is a file)")
    ancestor = path
    while not os.path.lexists(ancestor) and ancestor.parent != ancestor:
        ancestor = ancestor.parent
    if ancestor != path and not ancestor.is_dir():
        raise SpecError(field, str(value), f"a folder for the cache ({ancestor} is a file, so "
                                           "nothing can be created under it)")
    if not os.access(ancestor if ancestor.is_dir() else ancestor.parent, os.W_OK | os.X_OK):
        raise SpecError(field, str(value), f"a folder you can write to ({ancestor} is not "
                                           "writable)")
    return path
