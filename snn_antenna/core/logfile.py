"""``OUT/run.log``: the whole of what a run says, and the warnings a study expects.

``LogFile`` keeps every line, Brian2 log message and Python warning of a run in the output
folder; the terminal gets the same minus the warnings declared expected (``Expected``), each
explained once. ``UNSTABLE_ON_PURPOSE``, ``FLOAT32_CHECK`` and ``CPG_TOKEN_ORDER`` are the ones
the toolkit causes.
"""
from __future__ import annotations

import datetime as _dt
import functools
import logging
import re
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from .files import open_append


@dataclass(frozen=True)
class Expected:
    """Warnings a study knows it causes: ``patterns`` (regular expressions searched in the
    message) and ``why`` they are harmless, said once on the terminal instead of the warnings."""
    why: str
    patterns: tuple[str, ...]


# Warnings the toolkit causes on purpose or harmlessly (use with ``LogFile.expected``).
UNSTABLE_ON_PURPOSE = Expected(
    "the stability map runs each integrator past its stable step on purpose; the NaN and "
    "overflow it meets are what it measures (the red cells)",
    (r"has NaN, very large values", r"overflow encountered", r"invalid value encountered"))
FLOAT32_CHECK = Expected(
    "Brian2 checks float32 state against 1e50, a number float32 cannot hold; the cast in "
    "that check overflows, the state itself is finite",
    (r"overflow encountered in cast",))
CPG_TOKEN_ORDER = Expected(
    "the CPG's ring writes every neuron's token when one neuron fires; only the token's "
    "holder fires, so two writes never meet in one step and the order cannot matter",
    (r"abstract code block that may not be\s+well-defined.*token_post",))


class LogFile:
    """``OUT/run.log``: everything a run says, whole; the terminal gets the same minus the
    warnings the study declared expected, each explained in one line instead.

        with LogFile(out_dir, log) as log:          # log(...) prints and keeps the line
            log("[1/3] sweeping")
            with log.expected(UNSTABLE_ON_PURPOSE):
                smap = accuracy.stability_map(...)

    Brian2's log messages and Python warnings (which Brian2 routes through ``logging``) are
    written to the file as they come. A re-run appends, under a line naming its start. In the
    file, each line the run says carries the seconds since that start (``+  72.5 s``), so a
    run's stages can be timed after the fact (what the estimates are checked against).
    """

    def __init__(self, out_dir: str | Path, echo=print, name: str = "run.log"):
        self.path = Path(out_dir) / name
        self.echo = echo
        self._active: list[list] = []    # [Expected, count] of the open ``expected`` blocks
        self._file = None
        self._handler = None
        self._filter = _ExpectedFilter(self)
        self._consoles: list[logging.Handler] = []

    def __enter__(self) -> LogFile:
        # The file, its folder and the handlers come with the first line logged: a run refused
        # while its spec is checked (before anything is said) leaves no folder and imports no
        # Brian2.
        self._started = False
        return self

    def _start(self) -> None:
        from brian2.utils.logger import BrianLogger  # its console handler prints warnings

        # never through a symlink, and an existing log keeps the mode its owner gave it
        self._file = open_append(self.path)
        self._started = True
        self._t0 = time.monotonic()
        self._write(f"=== run started {_dt.datetime.now(_dt.UTC).isoformat()} "
                    f"({' '.join(sys.argv)})")
        # Python warnings through logging (as Brian2 sets up at import), re-armed in case
        # someone (a test runner, a notebook) replaced warnings.showwarning since
        logging.captureWarnings(False)
        logging.captureWarnings(True)
        self._handler = logging.StreamHandler(self._file)
        self._handler.setLevel(logging.INFO)
        self._handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
        for name in ("brian2", "py.warnings"):
            logging.getLogger(name).addHandler(self._handler)
        self._consoles = [h for h in (BrianLogger.console_handler, logging.lastResort)
                          if h is not None]
        for h in self._consoles:
            h.addFilter(self._filter)

    def __exit__(self, *exc) -> bool:
        if not self._started:
            return False
        for h in self._consoles:
            h.removeFilter(self._filter)
        for name in ("brian2", "py.warnings"):
            logging.getLogger(name).removeHandler(self._handler)
        if exc[0] is not None:
            import traceback
            self._write("".join(traceback.format_exception(*exc)))
        self._file.close()
        return False

    def __call__(self, *message) -> None:
        text = " ".join(str(m) for m in message)
        self.echo(text)
        if not getattr(self, "_started", True):
            self._start()
        t0 = getattr(self, "_t0", None)
        self._write(text if t0 is None else f"+{time.monotonic() - t0:7.1f} s  {text}")

    def _write(self, text: str) -> None:
        if not getattr(self, "_started", True):
            self._start()
        if self._file is not None and not self._file.closed:
            self._file.write(text + "\n")
            self._file.flush()

    @contextmanager
    def expected(self, *kinds: Expected):
        """Within: warnings matching ``kinds`` go to the file only; one line says why."""
        entries = [[kind, 0] for kind in kinds]
        self._active.extend(entries)
        try:
            yield self
        finally:
            for entry in entries:
                self._active.remove(entry)
                kind, count = entry
                if count:
                    self(f"  ({count} expected warning{'s' * (count > 1)} kept in "
                         f"{self.path}: {kind.why})")

    def _swallow(self, message: str) -> bool:
        for entry in self._active:
            if any(re.search(p, message, re.S) for p in entry[0].patterns):
                entry[1] += 1
                return True
        return False


class _ExpectedFilter(logging.Filter):
    def __init__(self, owner: LogFile):
        super().__init__()
        self.owner = owner

    def filter(self, record: logging.LogRecord) -> bool:
        return not self.owner._swallow(record.getMessage())


# ``@logged``: a study's ``run`` keeps everything it says in ``OUT/run.log``; one decorator so
# every output folder gets its log the same way, and a study that needs ``log.expected(...)``
# blocks still gets a LogFile as its ``log``.
def logged(run_study):
    @functools.wraps(run_study)
    def run(spec, out_dir, *args, log=print, **kwargs):
        if isinstance(log, LogFile):      # already kept by the caller
            return run_study(spec, out_dir, *args, log=log, **kwargs)
        with LogFile(out_dir, log) as kept:
            return run_study(spec, out_dir, *args, log=kept, **kwargs)
    return run
