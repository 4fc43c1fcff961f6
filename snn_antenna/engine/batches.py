"""Batches of work on a Dask client, or in this process: submit now, collect later.

A study often has many small, independent pieces of work (codings to read out, scenes to
simulate) that run best in a few large runs: Brian2's cost per step hardly grows with the
group's size. ``Batches`` cuts a list of items into runs of ``per_run`` items, hands each run
to ``work`` (one call per run, returning one result per item) and gives the results back in
the items' order.

``submit`` returns at once: with a Dask client the runs start on its workers, so this process
can do other work meanwhile; without one they are deferred and ``collect`` runs them here.
``work`` must pickle when a client is given (a frozen dataclass holding a spec, say), and
only what ``work`` takes travels to the workers.

``ScoredCodings`` is the detection case: coded columns read out blind in batches, scored
against their recordings' contacts when they come back.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any
from collections.abc import Callable

import numpy as np

from ..evaluation.scoring import score_with
from ..readout.detection import BlindReadOut
from .codings import COMPILED, compiled_rate_maps
from .sweep import prepare_workers


@dataclass
class Pending:
    """One submitted run: a Dask future, or a deferred call for this process."""
    handle: Any
    size: int

    def result(self) -> list:
        outcome = self.handle() if isinstance(self.handle, partial) else self.handle.result()
        results = list(outcome)
        if len(results) != self.size:
            raise RuntimeError(f"a run of {self.size} item(s) returned {len(results)} result(s)")
        return results


class Batches:
    """Runs of ``per_run`` items through ``work(items) -> [result per item]``."""

    def __init__(self, work: Callable[[list], list], per_run: int, client=None):
        if not (isinstance(per_run, int) and per_run >= 1):
            raise ValueError(f"per_run must be an integer >= 1, not {per_run!r}")
        self.work, self.per_run, self.client = work, per_run, client
        if client is not None:
            prepare_workers(client)

    def submit(self, items: list) -> list[Pending]:
        pending = []
        for start in range(0, len(items), self.per_run):
            run = items[start:start + self.per_run]
            handle = (partial(self.work, run) if self.client is None else
                      self.client.submit(self.work, run, pure=False))
            pending.append(Pending(handle, len(run)))
        return pending

    def collect(self, pending: list[Pending], desc: str | None = None) -> list:
        """Every item's result in order, waiting for (or running) each run; ``desc`` shows a
        progress bar when there is more than one run."""
        from tqdm import tqdm

        results = []
        for run in tqdm(pending, desc=desc, unit="run", disable=desc is None or len(pending) < 2):
            results += run.result()
        return results

    def run(self, items: list, desc: str | None = None) -> list:
        return self.collect(self.submit(items), desc)


@dataclass(frozen=True)
class DetectColumns:
    """One batch's read-out (``Batches`` work): coded columns → (detections, rate map) each.
    Only the coded columns travel; the labels stay with ``ScoredCodings``. A read-out whose
    target is ``"standalone"`` runs on the compiled engine (``engine.codings``: one project
    of ``per_run`` codings per process, re-run per batch), the runtime targets through
    ``BlindReadOut.detect``."""
    readout: BlindReadOut
    per_run: int = 1

    def __call__(self, columns: list) -> list:
        coded = np.stack(columns, axis=1)
        if self.readout.target == COMPILED:
            r = self.readout
            maps = compiled_rate_maps(r.array, coded, r.rate_hz, r.window_s, self.per_run)
            detections = [r.detector.detect(rates) for rates in maps]
        else:
            detections, maps = self.readout.detect(coded)
        return list(zip(detections, maps))


@dataclass
class Submitted:
    runs: list
    labels: list      # (contacts, duration_s) of each item, to score after the read-out


class ScoredCodings:
    """[(recording, coded column)] → (Score, rate map) each: ``per_run`` columns per Brian2
    group (``BlindReadOut.detect``), on the Dask workers (``client``) or in this process;
    each recording's labels stay here and score its detections once they are back."""

    def __init__(self, readout: BlindReadOut, per_run: int, client=None):
        self.readout = readout
        self.batches = Batches(DetectColumns(readout, per_run), per_run, client)

    def submit(self, items: list) -> Submitted:
        return Submitted(self.batches.submit([coded for _, coded in items]),
                         [(rec.truth.contacts, rec.duration_s) for rec, _ in items])

    def collect(self, submitted: Submitted, desc: str | None = None) -> tuple[list, list]:
        results = self.batches.collect(submitted.runs, desc)
        scores = [score_with(self.readout, detections, contacts, duration_s)
                  for (detections, _), (contacts, duration_s) in zip(results, submitted.labels)]
        return scores, [rates for _, rates in results]

    def run(self, items: list, desc: str | None = None) -> tuple[list, list]:
        return self.collect(self.submit(items), desc)
