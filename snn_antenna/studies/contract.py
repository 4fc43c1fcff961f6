"""The one shape of a study: what its module declares and what the command calls.

A study module declares

- ``SECTIONS``: the top-level keys its spec may hold besides ``study``, ``seed`` and
  ``description``: its tables, and ``data`` for a study that reads recorded data sets;
- ``OPTIONS``: the command-line options it takes (names of :class:`Options` fields, declared
  once in :data:`STUDY_OPTIONS`); an option it does not take is refused before any work,
  naming the study and the ones it takes;
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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable
from collections.abc import Callable
from urllib.parse import urlsplit

from ..core.bounds import out_path
from ..core.commands import SWITCH, Option, options_class
from ..core.errors import SpecError
from ..core.outputs import check_writable
from ..engine import rates
from ..engine.cost import study_overhead_s

# Dask's address schemes (``distributed.comm``): what --scheduler may name
SCHEDULER_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


def scheduler_address(field: str, value: str) -> str:
    """A Dask scheduler's address, ``[SCHEME://]HOST:PORT`` (checked by its form: connecting
    is the run's first step)."""
    accepted = (f"an address such as tcp://HOST:8786 (schemes: "
                f"{', '.join(SCHEDULER_SCHEMES)})")
    if not isinstance(value, str):
        raise SpecError(field, value, accepted)
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


# The options of ``snn-antenna run`` a study receives, declared once: the command line's
# flags, their help and bounds, and the fields of :class:`Options`.
STUDY_OPTIONS = (
    Option("quick", "apply the spec's [quick] profile: a small run for tests and first looks",
           kind=SWITCH),
    Option("fresh", "studies that keep results or caches: discard them and start over",
           kind=SWITCH),
    Option("scheduler", "studies with Dask workers: run on an existing Dask cluster instead "
                        "of a local one", check=scheduler_address, text=True,
           metavar="tcp://HOST:PORT"),
    Option("data", "studies that read recorded data sets: the folder they are in (sets the "
                   "spec's data)", check=out_path, text=True, metavar="PATH"),
    Option("force", "reuse an --out folder that holds another study's outputs or other "
                    "files: what snn-antenna wrote there is replaced, other files are kept",
           kind=SWITCH),
    Option("check", "check the spec, its estimate and --out as a run would, then stop "
                    "without running or writing anything", kind=SWITCH),
    Option("yes", "run even when the estimate is beyond the limit (1 h)", kind=SWITCH),
)
Options = options_class("Options", STUDY_OPTIONS, __name__,
                        "The options of ``snn-antenna run``, as a study receives them.")

# What every study takes: the quick profile, stopping after the checks, running beyond the
# cost limit, reusing a folder that holds another study's outputs.
COMMON = ("quick", "check", "yes", "force")


def flag(name: str) -> str:
    """The command-line flag of the study option ``name``."""
    return next(o.flag for o in STUDY_OPTIONS if o.name == name)


def check_options(study: str, accepted, options: Options) -> None:
    """Refuse the first option ``study`` does not take, naming the ones it takes."""
    for name in options.given():
        if name not in accepted:
            takes = ", ".join(flag(o) for o in accepted)
            raise SpecError(flag(name), getattr(options, name),
                            f"an option of a study that takes it; the {study} study takes "
                            f"{takes}")


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
        sized.parts["the process's start and its report"] = study_overhead_s()
        # the rates were measured at one load; the run shares the machine as it is now
        factor, note = rates.load_factor()
        sized.scale(factor)
        if note and hasattr(sized, "sources"):
            sized.sources = f"{sized.sources}; {note}"
        elif note:
            sized.rate = dataclasses.replace(sized.rate, source=f"{sized.rate.source}; {note}")
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
    return check_writable(out_path(field, value), field, "a folder for the cache")
