"""Running a sweep: chunk by chunk, in this process or on Dask, into a resumable zarr store.

    grid = Grid({"k": [0.5, 1, 2], "input_hz": {"start": 2, "stop": 60, "num": 59}})
    evaluate = NeuronSweep(duration_s=2.0)                 # or any callable, see below
    with dask_client(workers=0) as client:                 # local cluster sized to the machine
        outcome = run_sweep(grid, evaluate, "out/results.zarr",
                            {"spike_count": Output("i4")}, client=client)
    outcome.data                                           # xarray Dataset, dims k × input_hz

- ``evaluate(points) -> {output: array}``: ``points`` maps each axis to one value per point
  (1-D arrays, all of one chunk); the result holds one value per point for each output. It
  runs on a worker, so it must pickle (a module-level function, a ``functools.partial`` or a
  dataclass instance). An optional ``evaluate.for_grid(grid, block_shape)`` validates the
  grid before any work starts (raising ``SpecError``) and returns the evaluator to use.
- ``run_sweep(grid, evaluate, store_path, outputs, client=None, ...)``: refuses a bad grid
  up front (empty or duplicated axis values, a result too big for memory, whatever
  ``for_grid`` refuses), pre-creates the store (``store.SweepStore``), skips chunks already
  finished, runs the rest (in this process when ``client`` is None, else as Dask tasks that
  return their blocks to this process, which alone writes each into its region of the store
  as it arrives), shows a progress bar and returns a ``SweepOutcome``.
"""
from __future__ import annotations

import dataclasses
import hashlib
import itertools
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable

import numpy as np

from ..core.errors import check
from ..core.store import Output, SweepStore
from .cost import check_memory
from .executor import prepare_workers
from .grid import Grid


@dataclass
class SweepOutcome:
    data: Any                       # xarray.Dataset of every output over the grid
    chunks_total: int
    chunks_computed: list[int]      # chunk ids run by this call
    chunks_skipped: list[int]       # already finished in the store
    wall_s: float
    workers: dict = dataclasses.field(default_factory=dict)  # worker → chunks it ran


def _compute_chunk(chunk_id: int, region: dict, points: dict, evaluate,
                   outputs: dict) -> tuple[int, dict[str, np.ndarray], float, str]:
    """One task: evaluate a chunk and return its blocks (runs on a worker). It touches no
    file: the client alone writes the store, so a worker on another machine needs no view
    of the output folder."""
    t0 = time.perf_counter()
    results = evaluate(points)
    n = len(next(iter(points.values())))
    shape = tuple(s.stop - s.start for s in region.values())
    blocks = {}
    for name, out in outputs.items():
        value = np.asarray(results[name])
        if value.shape != (n,):
            raise ValueError(f"evaluate returned {name} of shape {value.shape}, expected ({n},)")
        if value.dtype.kind == "f" and not np.all(np.isfinite(value)):
            raise ValueError(f"evaluate returned non-finite {name}: results are never NaN")
        blocks[name] = value.astype(out.dtype).reshape(shape)
    return chunk_id, blocks, time.perf_counter() - t0, f"{os.uname().nodename}:{os.getpid()}"


def run_sweep(grid: Grid, evaluate: Callable, store_path: str | Path,
              outputs: dict[str, Output | str], *, client=None, chunk_points: int = 4096,
              fresh: bool = False, attrs: dict | None = None, settings=None,
              progress: bool = True, desc: str = "sweep") -> SweepOutcome:
    """Run ``evaluate`` over ``grid`` into the zarr store at ``store_path`` (resumable).

    ``settings`` (anything JSON-able; default: the evaluator's repr) enter the store's
    fingerprint: resuming with other settings is refused. ``attrs`` (the resolved spec,
    versions) are written to the Dataset's attributes.
    """
    from tqdm.auto import tqdm

    outputs = {name: (o if isinstance(o, Output) else Output(str(o)))
               for name, o in outputs.items()}
    check(len(outputs) >= 1, "outputs", outputs, "at least one output variable")
    block_shape = grid.block_shape(chunk_points)
    if hasattr(evaluate, "for_grid"):
        evaluate = evaluate.for_grid(grid, block_shape)
    check_memory(grid, outputs, int(np.prod(block_shape)),
                 getattr(evaluate, "bytes_per_point", 0))
    regions = grid.blocks(chunk_points)
    # never resolved: a link is refused, not followed
    store = SweepStore(Path(os.path.abspath(store_path)))
    settings = repr(evaluate) if settings is None else settings
    # the evaluator's module and its imports compute the results (the whole package when the
    # evaluator is not the package's own: provenance.import_closure)
    computed_by = getattr(evaluate, "__module__", None) or type(evaluate).__module__
    done = store.prepare(grid.coords(), outputs, block_shape, len(regions), attrs=attrs,
                         settings=settings, fresh=fresh, computed_by=computed_by)
    todo = [i for i in range(len(regions)) if i not in done]
    t0 = time.perf_counter()
    bar = tqdm(total=len(regions), initial=len(done), unit="chunk", desc=desc,
               disable=not progress, smoothing=0.1)
    try:
        with _interruptible() as interrupted:
            chunks = _Chunks(grid=grid, regions=regions, evaluate=evaluate, outputs=outputs,
                             store=store, bar=bar, interrupted=interrupted)
            if client is None:
                chunks.run_here(todo)
            else:
                chunks.run_on_dask(client, todo)
    finally:
        bar.close()
    return SweepOutcome(store.load(), len(regions), todo, sorted(done),
                        time.perf_counter() - t0, chunks.workers)


@contextmanager
def _interruptible():
    """Ctrl-C raises KeyboardInterrupt and is also remembered: Python drops an exception
    raised while a weakref callback runs (Brian2 has many), so the sweep checks the flag
    after every chunk and stops there even when the exception was lost."""
    import signal
    import threading

    requested = []
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return

    def handler(signum, frame):
        requested.append(signum)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield lambda: bool(requested)
    finally:
        signal.signal(signal.SIGINT, previous)


@dataclass
class _Chunks:
    """The chunks of one ``run_sweep`` call: how each is computed, and what happens as each
    finishes (its blocks written to the store, counted per worker, the bar advanced)."""
    grid: Grid
    regions: list[dict]
    evaluate: Callable
    outputs: dict[str, Output]
    store: SweepStore
    bar: Any
    interrupted: Callable[[], bool]
    workers: dict[str, int] = dataclasses.field(default_factory=dict)  # worker → chunks run

    def finished(self, chunk_id: int, blocks: dict[str, np.ndarray], who: str) -> None:
        self.store.write_chunk(chunk_id, self.regions[chunk_id], blocks)
        self.workers[who] = self.workers.get(who, 0) + 1
        self.bar.update()
        if self.interrupted():
            raise KeyboardInterrupt

    def run_here(self, todo: list[int]) -> None:
        for i in todo:
            _, blocks, _, who = _compute_chunk(i, self.regions[i],
                                               self.grid.points(self.regions[i]),
                                               self.evaluate, self.outputs)
            self.finished(i, blocks, who)

    def run_on_dask(self, client, todo: list[int]) -> None:
        """Chunks run as Dask tasks that return their blocks; this process writes each block
        into the store as it arrives (``distributed.as_completed``), so workers need no shared
        folder.

        Only a window of tasks (two per worker thread) is submitted at a time and refilled as
        chunks finish: finished blocks never pile up on the workers or here, whatever the
        grid's size, while every worker still has a chunk queued behind the one it runs."""
        from distributed import as_completed

        if not todo:
            return
        prepare_workers(client)
        evaluate_future = client.scatter(self.evaluate, broadcast=True)
        run = f"{hashlib.sha1(str(self.store.path).encode()).hexdigest()[:8]}-{time.time_ns()}"
        waiting = iter(todo)
        running: dict = {}  # future -> chunk id, cancelled if the sweep stops

        def submit(count: int) -> list:
            futures = []
            for i in itertools.islice(waiting, max(0, count)):
                future = client.submit(_compute_chunk, i, self.regions[i],
                                       self.grid.points(self.regions[i]), evaluate_future,
                                       self.outputs, key=f"sweep-{run}-chunk-{i}", pure=False)
                running[future] = i
                futures.append(future)
            return futures

        def window() -> int:  # asked again after every chunk: workers may join or leave
            return max(2, 2 * sum(client.nthreads().values()))

        completed = as_completed(submit(window()), loop=client.loop)
        try:
            for future in completed:
                running.pop(future)
                chunk_id, blocks, _, who = future.result()  # re-raises a worker's exception
                self.finished(chunk_id, blocks, who)
                completed.update(submit(window() - len(running)))
        except BaseException:  # Ctrl-C or a failed chunk: finished chunks stay in the store
            client.cancel(list(running))
            raise
