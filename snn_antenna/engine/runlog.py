"""A resumable log of finished runs: ``runs.jsonl``, one JSON row per line.

Every row is appended as soon as it is measured, so an interrupted study resumes where it
stopped: a re-run with the same spec skips the rows already there. The first line holds a
hash of the spec; a changed spec (or ``fresh=True``) starts the log over. A last line cut
short by an interruption is skipped. ``Measurements`` measures settings of the
``engine.devices`` workloads through such a log.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ..core.errors import SpecError
from ..evaluation.tradeoff import describe
from ..core.files import atomic_write, open_append, refuse_symlink
from ..core.provenance import code_hash
from .devices import Setting, measure

# What names one measured run in the log
RUN_IDENTITY = ("sweep", "scene", "method", "dt_ms", "target", "dtype", "n_neurons")


def spec_key(spec: dict) -> str:
    """A short hash of the spec and of the code that measures: which log belongs to which
    run (rows measured by other code are measured again)."""
    text = json.dumps({"spec": spec, "code": code_hash()}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class RunLog:
    """Rows keyed by the values of ``identity`` (the fields that name one configuration)."""

    def __init__(self, path: Path, spec: dict, fresh: bool = False,
                 identity: tuple[str, ...] = RUN_IDENTITY):
        self.path, self.identity = Path(path), tuple(identity)
        self.key = spec_key(spec)
        self.rows: dict[tuple, dict] = {}
        refuse_symlink(self.path)
        if self.path.exists() and not fresh:
            self._load()
        if not self.rows:
            atomic_write(self.path, json.dumps({"spec_key": self.key}) + "\n")

    def _load(self) -> None:
        lines = self.path.read_text(errors="replace").splitlines()
        try:
            header = json.loads(lines[0]) if lines else None
            known = isinstance(header, dict) and isinstance(header.get("spec_key"), str)
        except ValueError:
            known = False
        if not known:
            raise SpecError("run log", str(self.path),
                            "a run log snn-antenna wrote (its first line names the spec it "
                            "belongs to); this one is damaged: pass --fresh to measure again, "
                            "or move the file away")
        if header["spec_key"] != self.key:
            return
        for line in lines[1:]:
            try:
                row = json.loads(line)
                self.rows[self._id(row)] = row
            except (ValueError, KeyError, TypeError):  # a line cut short by an interruption
                continue

    def _id(self, row: dict) -> tuple:
        # 1 and 1.0 are equal and hash alike: a step read from TOML finds its JSON row
        return tuple(row[name] for name in self.identity)

    def get(self, **config) -> dict | None:
        return self.rows.get(self._id(config))

    def add(self, row: dict) -> None:
        self.rows[self._id(row)] = row
        with open_append(self.path) as f:
            f.write(json.dumps(row) + "\n")


class Measurements:
    """Measures (scene, setting) pairs on the workloads (``devices.measure`` against each
    scene's reference), skipping those the run log already holds."""

    def __init__(self, workloads: dict, refs: dict, runs: RunLog, log=print):
        self.workloads, self.refs, self.runs, self.log = workloads, refs, runs, log
        self.warmed: set = set()   # (scene, setting) pairs compiled in this process

    def sweep(self, sweep: str, pairs: list[tuple[str, Setting]]) -> list[dict]:
        """One row per pair, each tagged with ``sweep`` and logged as soon as it is known."""
        rows = []
        for j, (scene, setting) in enumerate(pairs, 1):
            workload = self.workloads[scene]
            row = self.runs.get(sweep=sweep, scene=scene, method=setting.method,
                                dt_ms=setting.dt_ms, target=setting.target,
                                dtype=setting.dtype,
                                n_neurons=setting.n_neurons or workload.n_neurons)
            if row is None:
                row = measure(workload, self.refs[scene], setting, self.warmed)
                row["sweep"] = sweep
                self.runs.add(row)
            rows.append(row)
            self.log(f"  [{j}/{len(pairs)}] {describe(row)}")
        return rows
