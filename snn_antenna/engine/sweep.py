"""Parameter sweeps: a grid of points, run in chunks on Dask workers, into one zarr store.

The public API is small:

    grid = Grid({"k": [0.5, 1, 2], "input_hz": {"start": 2, "stop": 60, "num": 59}})
    evaluate = NeuronSweep(duration_s=2.0)                 # or any callable, see below
    with dask_client(workers=0) as client:                 # local cluster sized to the machine
        outcome = run_sweep(grid, evaluate, "out/results.zarr",
                            {"spike_count": Output("i4")}, client=client)
    outcome.data                                           # xarray Dataset, dims k × input_hz

- ``Grid(axes)``: named axes, each a list of values or a range ``{start, stop, num,
  scale = "linear" | "log"}`` (``axis_values``). Points are the Cartesian product in axis
  order; ``blocks(chunk_points)`` cuts the grid into rectangular chunks of at most
  ``chunk_points`` points that keep the trailing axes whole (a tuning curve stays in one chunk).
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
- ``dask_client(workers, scheduler)``: a context manager; ``scheduler="tcp://HOST:PORT"``
  attaches to an existing cluster, otherwise a LocalCluster of worker *processes* (Brian2
  holds the GIL) is started and closed again. Workers never open the store: a cluster
  spanning machines needs no shared folder, only the snn_antenna package on every worker.
- ``NeuronSweep``: the vectorised evaluator for Izhikevich neurons driven by the square-wave
  coder's input; axes may be any neuron parameter (``k, a, b, c, d``), the input frequency
  ``input_hz`` and amplitude ``I``. All points of a chunk are neurons of ONE NeuronGroup.
  Engines: ``"standalone"`` (Brian2 cpp_standalone, compiled once per process and re-run per
  chunk with new parameters via ``run_args``; each worker process keeps its own project
  directory) or ``"numpy"`` / ``"cython"`` (runtime, through ``neurons.simulate`` with a 2-D
  input current and ``input_index``). ``benchmarks/bench_sweep.py`` measures which is faster:
  once compiled, standalone is 2.5-7.5x faster than cython and 6-16x faster than numpy per
  neuron-step; its one-off compile (~10-20 s per worker process and group size, cached on
  disk) pays off beyond a few 10^8 neuron-steps, so small first looks use ``numpy``.
- ``SceneSweep``: the same for neurons driven by coded robot scenes, with axes over scene
  and preprocessing fields (``stimulus.speed_cm_s``, ``stimulus.contacts.0.distance_cm``,
  ``preprocess.threshold``) beside ``k, a, b, c, d``: each distinct scene is generated and
  coded once and becomes one input column (runtime engines).

Brian2's cython cache is shared by the workers of a machine (Brian2 locks each extension
while it compiles it), so each extension compiles once, not once per worker.
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import itertools
import math
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..networks import neurons
from ..errors import NumericalInstabilityError, SpecError, check, is_integer
from ..store import Output, SweepStore

__all__ = ["Grid", "axis_values", "run_sweep", "SweepOutcome", "dask_client", "executor",
           "NeuronSweep", "SceneSweep", "Output", "memory_budget_bytes", "max_workers",
           "estimate", "Estimate"]


# -- the grid ---------------------------------------------------------------------------------
def axis_values(name: str, value) -> np.ndarray:
    """Values of one axis: a list of numbers, or ``{start, stop, num, scale}`` (scale
    ``"linear"``, the default, or ``"log"``; stop included)."""
    if isinstance(value, dict):
        unknown = set(value) - {"start", "stop", "num", "scale"}
        check(not unknown and {"start", "stop", "num"} <= set(value), f"axes.{name}", value,
              "a list of values or a range {start, stop, num, scale = 'linear' | 'log'}")
        start, stop, num = value["start"], value["stop"], value["num"]
        scale = value.get("scale", "linear")
        check(isinstance(num, int) and not isinstance(num, bool) and num >= 1,
              f"axes.{name}.num", num, "an integer number of values >= 1")
        check(scale in ("linear", "log"), f"axes.{name}.scale", scale, "'linear' or 'log'")
        check(all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                  for x in (start, stop)), f"axes.{name}", value, "finite start and stop")
        if scale == "log":
            check(start > 0 and stop > 0, f"axes.{name}", value,
                  "start and stop > 0 for a log-spaced axis")
            values = np.geomspace(start, stop, num)
        else:
            values = np.linspace(start, stop, num)
    else:
        raw = value if isinstance(value, (list, tuple, np.ndarray)) else [value]
        try:
            values = np.asarray(raw, dtype=float).ravel()
        except (TypeError, ValueError):
            raise SpecError(f"axes.{name}", value, "numbers") from None
    check(values.size >= 1, f"axes.{name}", value, "at least one value (the axis is empty)")
    check(bool(np.all(np.isfinite(values))), f"axes.{name}", value, "finite values")
    check(np.unique(values).size == values.size, f"axes.{name}", value,
          "distinct values (a repeated value would make the coordinate ambiguous)")
    return values


class Grid:
    """The Cartesian product of named axes (see the module docstring)."""

    def __init__(self, axes: dict[str, Any], units: dict[str, str] | None = None):
        check(isinstance(axes, dict) and len(axes) >= 1, "axes", axes,
              "a table of at least one named axis")
        self.axes = {str(name): axis_values(name, v) for name, v in axes.items()}
        self.units = dict(units or {})

    @classmethod
    def from_spec(cls, table: dict, known: dict[str, str] | None = None) -> "Grid":
        """A grid from a spec's ``[axes]`` table; ``known`` maps accepted axis names to units."""
        check(isinstance(table, dict) and len(table) >= 1, "axes", table,
              "a table of at least one named axis")
        if known is not None:
            for name in table:
                check(name in known, f"axes.{name}", table[name],
                      f"an axis this study can sweep: {', '.join(known)}")
        return cls(table, {n: known[n] for n in table} if known else None)

    @property
    def dims(self) -> tuple[str, ...]:
        return tuple(self.axes)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(v) for v in self.axes.values())

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    def block_shape(self, chunk_points: int) -> tuple[int, ...]:
        """Chunk shape: trailing axes whole while they fit, then a part of the next axis."""
        check(is_integer(chunk_points) and chunk_points >= 1, "chunk_points",
              chunk_points, "an integer >= 1 (not true/false)")
        block, room = [], chunk_points
        for n in reversed(self.shape):
            take = max(1, min(n, room))
            block.append(take)
            room = max(1, room // take) if take == n else 1
        return tuple(reversed(block))

    def blocks(self, chunk_points: int) -> list[dict[str, slice]]:
        """The chunks, in C order, as regions {axis: slice}."""
        block = self.block_shape(chunk_points)
        counts = [math.ceil(n / b) for n, b in zip(self.shape, block)]
        regions = []
        for index in np.ndindex(*counts):
            regions.append({dim: slice(i * b, min((i + 1) * b, n)) for dim, i, b, n in
                            zip(self.dims, index, block, self.shape)})
        return regions

    def points(self, region: dict[str, slice] | None = None) -> dict[str, np.ndarray]:
        """Each axis's value at every point of ``region`` (flattened in C order)."""
        region = region or {d: slice(None) for d in self.dims}
        mesh = np.meshgrid(*(self.axes[d][region[d]] for d in self.dims), indexing="ij")
        return {d: m.ravel() for d, m in zip(self.dims, mesh)}

    def coords(self) -> dict[str, np.ndarray]:
        return dict(self.axes)

    def describe(self) -> str:
        return " × ".join(f"{d} ({n})" for d, n in zip(self.dims, self.shape)) + \
            f" = {self.size:,} points"


def memory_budget_bytes() -> int:
    """A quarter of the memory available now: what a sweep may hold at once."""
    try:
        import psutil
        available = psutil.virtual_memory().available
    except ImportError:  # psutil comes with distributed; this is a fallback
        available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    return int(available) // 4


def check_memory(grid: Grid, outputs: dict[str, Output], chunk_points: int,
                 bytes_per_point_in_chunk: int = 0, budget: int | None = None) -> None:
    """Refuse a grid whose results (loaded for the report) or chunks would not fit."""
    budget = memory_budget_bytes() if budget is None else budget
    per_point = sum(np.dtype(o.dtype).itemsize for o in outputs.values())
    need = grid.size * per_point
    check(need <= budget, "axes", grid.describe(),
          f"a grid whose results fit in memory: {need / 1e9:.3g} GB needed, "
          f"{budget / 1e9:.3g} GB allowed (a quarter of the memory available); "
          "shrink an axis or split the sweep")
    chunk = min(chunk_points, grid.size) * bytes_per_point_in_chunk
    check(chunk <= budget, "sweep.chunk_points", chunk_points,
          f"chunks that fit in memory: {chunk / 1e9:.3g} GB per chunk, "
          f"{budget / 1e9:.3g} GB allowed; lower chunk_points")


# -- what a sweep will cost, before it starts ---------------------------------------------------
# Neuron-steps per second of ONE worker process per engine (points x steps / wall time,
# compile excluded). numpy: measured with the quick tuning sweep (9.4e6 neuron-steps in 4.3 s on
# a loaded 2-core machine, `snn-antenna run studies/tuning_sweep.toml --quick`); cython and
# standalone from the ratios benchmarks/bench_sweep.py measured (standalone 6-16x numpy,
# 2.5-7.5x cython), at their low ends so the estimate errs long.
MEASURED_STEPS_PER_S = {"numpy": 2.2e6, "cython": 5.0e6, "standalone": 1.3e7}
STANDALONE_COMPILE_S = 20.0        # one-off per worker process and group size (cached on disk)
WORKER_MEMORY_BYTES = 500 * 2**20  # one worker process with Brian2 and Dask imported
LONG_SWEEP_S = 3600.0              # beyond this the CLI asks for --yes


def max_workers() -> int:
    """Worker processes this machine can run: one per core, and no more than fit in the
    memory available now (two at least, so the parallel path runs on any machine)."""
    cores = os.cpu_count() or 1
    by_memory = (memory_budget_bytes() * 4) // WORKER_MEMORY_BYTES
    return max(2, min(cores, by_memory))


@dataclass
class Estimate:
    """A sweep's size and expected cost, computed from the grid's shape alone (nothing is
    materialised, so a grid of 10^9 points is sized in microseconds)."""
    points: int
    neuron_steps: int
    workers: int
    seconds: float
    result_bytes: int
    chunk_bytes: int
    engine: str

    def describe(self) -> str:
        return (f"{self.points:,} points, {self.neuron_steps:.3g} neuron-steps on "
                f"{self.workers} worker(s) ({self.engine}): about {_duration(self.seconds)} at "
                f"{MEASURED_STEPS_PER_S[self.engine]:.3g} neuron-steps/s per worker, "
                f"{self.result_bytes / 1e6:.3g} MB of results, "
                f"{self.chunk_bytes / 1e6:.3g} MB per chunk")


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def estimate(grid: Grid, sweep: "NeuronSweep", chunk_points: int, workers: int) -> Estimate:
    """Points, neuron-steps, expected wall time and memory of ``sweep`` over ``grid``."""
    workers = min(workers or os.cpu_count() or 1, max_workers())
    steps = int(round(sweep.duration_s * 1000 / sweep.dt_ms))
    neuron_steps = grid.size * steps
    seconds = neuron_steps / (MEASURED_STEPS_PER_S[sweep.engine] * workers)
    if sweep.engine == "standalone":
        seconds += STANDALONE_COMPILE_S
    per_point = sum(np.dtype(o.dtype).itemsize for o in NeuronSweep.OUTPUTS.values())
    chunk = min(chunk_points, grid.size) * sweep.bytes_per_point
    return Estimate(grid.size, neuron_steps, workers, seconds, grid.size * per_point, chunk,
                    sweep.engine)


# -- running ----------------------------------------------------------------------------------
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
    store = SweepStore(Path(store_path).resolve())
    settings = repr(evaluate) if settings is None else settings
    done = store.prepare(grid.coords(), outputs, block_shape, len(regions), attrs,
                         settings, fresh)
    todo = [i for i in range(len(regions)) if i not in done]
    t0 = time.perf_counter()
    workers: dict[str, int] = {}
    bar = tqdm(total=len(regions), initial=len(done), unit="chunk", desc=desc,
               disable=not progress, smoothing=0.1)
    try:
        with _interruptible() as interrupted:
            if client is None:
                for i in todo:
                    _, blocks, _, who = _compute_chunk(i, regions[i], grid.points(regions[i]),
                                                       evaluate, outputs)
                    store.write_chunk(i, regions[i], blocks)
                    workers[who] = workers.get(who, 0) + 1
                    bar.update()
                    if interrupted():
                        raise KeyboardInterrupt
            else:
                _run_on_dask(client, store, grid, regions, todo, evaluate, outputs, bar,
                             workers, interrupted)
    finally:
        bar.close()
    return SweepOutcome(store.load(), len(regions), todo, sorted(done),
                        time.perf_counter() - t0, workers)


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


def _run_on_dask(client, store, grid, regions, todo, evaluate, outputs, bar, workers,
                 interrupted=lambda: False):
    """Chunks run as Dask tasks that return their blocks; this process writes each block into
    the store as it arrives (``distributed.as_completed``), so workers need no shared folder.

    Only a window of tasks (two per worker thread) is submitted at a time and refilled as
    chunks finish: finished blocks never pile up on the workers or here, whatever the grid's
    size, while every worker still has a chunk queued behind the one it runs."""
    from distributed import as_completed

    if not todo:
        return
    prepare_workers(client)
    evaluate_future = client.scatter(evaluate, broadcast=True)
    run = f"{hashlib.sha1(str(store.path).encode()).hexdigest()[:8]}-{time.time_ns()}"
    waiting = iter(todo)
    running: dict = {}  # future -> chunk id, cancelled if the sweep stops

    def submit(count: int) -> list:
        futures = []
        for i in itertools.islice(waiting, max(0, count)):
            future = client.submit(_compute_chunk, i, regions[i], grid.points(regions[i]),
                                   evaluate_future, outputs, key=f"sweep-{run}-chunk-{i}",
                                   pure=False)
            running[future] = i
            futures.append(future)
        return futures

    def window() -> int:  # asked again after every chunk: workers may join or leave
        return max(2, 2 * sum(client.nthreads().values()))

    completed = as_completed(submit(window()), loop=client.loop)
    try:
        for future in completed:
            running.pop(future)
            chunk_id, blocks, _, who = future.result()  # re-raises a worker's exception here
            store.write_chunk(chunk_id, regions[chunk_id], blocks)
            workers[who] = workers.get(who, 0) + 1
            bar.update()
            if interrupted():
                raise KeyboardInterrupt
            completed.update(submit(window() - len(running)))
    except BaseException:  # Ctrl-C or a failed chunk: finished chunks stay in the store
        client.cancel(list(running))
        raise


def prepare_workers(client) -> None:
    """Make ``client``'s workers (current and future) fit to run Brian2 (``_PrepareWorker``).
    Call it before submitting any Brian2 task; registering again is harmless."""
    client.register_plugin(_prepare_worker_class()(), name="snn-antenna-prepare-worker")


@functools.cache
def _prepare_worker_class():
    # Defined on first use: importing distributed costs half a second, which a refusal of a
    # bad spec (this module is imported to size the grid) should not pay. Pickled by
    # reference through the module's __getattr__ below, as a module-level class would be.
    from distributed.diagnostics.plugin import WorkerPlugin

    class _PrepareWorker(WorkerPlugin):
        """Worker plugin, run in each worker's main thread (restarted workers too, and the workers
        of a cluster given by ``--scheduler``):

        - import Brian2 there, where it may install its SIGINT handler (importing it first inside
          a task thread fails);
        - stop Dask's statistical profiler, which deadlocks workers: every 10 ms it calls
          ``sys._current_frames()``, which holds the interpreter's thread-list lock while it
          allocates; a garbage collection there runs Brian2's weakref callbacks, and a task thread
          starting a thread then waits forever (seen when workers still wrote their chunks:
          one stuck in zarr's I/O pool's ``Thread.start`` with its main thread in Brian2's
          ``InstanceTrackerSet.remove`` under ``Worker.trigger_profile``; the sweep hung).
        """

        def setup(self, worker):
            import brian2  # noqa: F401

            for name in ("profile", "profile-cycle"):
                callback = worker.periodic_callbacks.pop(name, None)
                if callback is not None:
                    callback.stop()

    _PrepareWorker.__module__, _PrepareWorker.__qualname__ = __name__, "_PrepareWorker"
    return _PrepareWorker


def __getattr__(name):
    if name == "_PrepareWorker":
        return _prepare_worker_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@contextmanager
def dask_client(workers: int = 0, scheduler: str | None = None, quiet: bool = True):
    """A Dask client: attach to ``scheduler`` (tcp://HOST:PORT) or start a local cluster.

    The local cluster runs ``workers`` processes (0: one per CPU core) of one thread each:
    Brian2 holds the GIL, so threads would not run chunks in parallel.
    """
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        check(isinstance(scheduler, str) and "://" in scheduler, "--scheduler", scheduler,
              "a Dask scheduler address such as tcp://HOST:8786")
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise SpecError("--scheduler", scheduler,
                            f"the address of a running Dask scheduler ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    check(isinstance(workers, int) and not isinstance(workers, bool) and workers >= 0,
          "sweep.workers", workers, "an integer >= 0 (0: one per core)")
    # Never more processes than the machine has cores and memory for (500 workers on 2
    # cores took ~10 GB in a minute and ran no faster).
    n = min(workers or os.cpu_count() or 1, max_workers())
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address=None,
                           silence_logs=logging.ERROR if quiet else logging.WARNING)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


@contextmanager
def executor(workers: int = 0, scheduler: str | None = None, log=None):
    """Where a study's sweep runs: ``None`` (this process, for ``run_sweep(client=None)``)
    when ``workers == 1`` and no scheduler is given, otherwise a ``dask_client``."""
    if scheduler is None and workers == 1:
        yield None
        return
    with dask_client(workers, scheduler) as client:
        if log is not None:
            log(f"      Dask: {len(client.scheduler_info()['workers'])} worker(s) at "
                f"{client.scheduler.address}")
        yield client


# -- the vectorised neuron evaluator ----------------------------------------------------------
NEURON_AXES = {"k": "", "a": "", "b": "", "c": "", "d": "", "input_hz": "Hz", "I": ""}


@dataclass(frozen=True)
class NeuronSweep:
    """Spike counts of Izhikevich neurons driven by a square wave, one neuron per grid point.

    The input is the square-wave coder's output for a pure tone: ``±I`` switching every half
    period of ``input_hz``, sampled at ``input_rate_hz`` and held (``stimuli.square``). Spikes
    are counted from ``settle_s`` to ``duration_s`` (the onset transient is left out);
    ``rate_hz`` is that count per second. Parameters not swept take the values given here
    (``None``: the preset's). Neurons start at rest for the first input sample.
    """
    preset: str = "resonator"
    duration_s: float = 2.0
    settle_s: float = 0.25
    dt_ms: float = 0.1
    method: str = "euler"
    engine: str = "standalone"
    input_rate_hz: float = 1000.0
    k: float = 1.0
    a: float | None = None
    b: float | None = None
    c: float | None = None
    d: float | None = None
    input_hz: float = 10.0
    I: float = 0.15
    force: bool = False
    group_size: int | None = None  # standalone: neurons per compiled group (set by for_grid)

    OUTPUTS = {"spike_count": Output("i4", "1", "spikes counted after settle_s"),
               "rate_hz": Output("f8", "Hz", "spike rate after settle_s")}

    def __post_init__(self):
        check(self.preset in neurons.PRESETS, "preset", self.preset,
              f"one of {sorted(neurons.PRESETS)}")
        check(self.method in neurons.METHODS, "method", self.method,
              f"one of {list(neurons.METHODS)}")
        check(self.engine in ("standalone", "cython", "numpy"), "engine", self.engine,
              "'standalone' (compiled C++, re-run per chunk), 'cython' or 'numpy'")
        check(math.isfinite(self.dt_ms) and 0 < self.dt_ms <= 1, "dt_ms", self.dt_ms,
              "a step in (0, 1] ms")
        check(math.isfinite(self.input_rate_hz) and self.input_rate_hz > 0 and
              1000.0 / self.input_rate_hz >= self.dt_ms * (1 - 1e-9), "input_rate_hz",
              self.input_rate_hz, f"a sample rate > 0 Hz and at most 1/dt ({1 / self.dt_ms:g} kHz)")
        check(math.isfinite(self.duration_s) and self.duration_s * 1000 >= 10 * self.dt_ms,
              "duration_s", self.duration_s, "a duration of at least 10 steps")
        check(math.isfinite(self.settle_s) and 0 <= self.settle_s < self.duration_s,
              "settle_s", self.settle_s, f"a time in [0, duration_s = {self.duration_s:g}) s")

    # the grid's checks, before any work
    def for_grid(self, grid: Grid, block_shape) -> "NeuronSweep":
        for name in grid.dims:
            check(name in NEURON_AXES, f"axes.{name}", list(grid.axes[name]),
                  f"a parameter of the neuron sweep: {', '.join(NEURON_AXES)}")
        values = {name: grid.axes.get(name, np.atleast_1d(getattr(self, name)))
                  for name in ("k", "input_hz", "I")}
        check(bool(np.all(values["k"] > 0)), "axes.k", list(values["k"]),
              "time-scale factors > 0")
        limit = neurons.MAX_STABLE_K_DT[self.method]
        k_max = float(np.max(values["k"]))
        if not self.force and k_max * self.dt_ms > limit:
            raise SpecError("axes.k", list(grid.axes.get("k", [self.k])),
                            f"k <= {limit / self.dt_ms:g} at dt = {self.dt_ms:g} ms with "
                            f"method {self.method!r} (the stable range k·dt <= {limit:g} "
                            f"model-ms, neurons.MAX_STABLE_K_DT), or a smaller dt_ms")
        nyquist = self.input_rate_hz / 4  # the coder needs both half-cycles sampled twice
        check(bool(np.all((values["input_hz"] > 0) & (values["input_hz"] <= nyquist))),
              "axes.input_hz", list(values["input_hz"]),
              f"frequencies in (0, {nyquist:g}] Hz (4 samples per cycle at "
              f"{self.input_rate_hz:g} Hz)")
        check(bool(np.all(values["I"] >= 0)), "axes.I", list(values["I"]),
              "amplitudes >= 0")
        return dataclasses.replace(self, group_size=int(np.prod(block_shape)))

    @property
    def bytes_per_point(self) -> int:
        """Memory a chunk holds per point: the runtime engines keep one input column each."""
        if self.engine == "standalone":
            return 64
        return int(8 * self.duration_s * self.input_rate_hz) + 64

    def parameters(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Every parameter per point, axes first, then this sweep's fixed values."""
        return _parameters(self, points, NEURON_AXES)

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        p = self.parameters(points)
        n = len(p["k"])
        if self.engine == "standalone":
            counts = _standalone_counts(self, p)
        else:
            counts = _runtime_counts(self, p)
        counts = counts[:n]
        return {"spike_count": counts.astype(np.int32),
                "rate_hz": counts / (self.duration_s - self.settle_s)}

    def initial_state(self, p: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Rest for the first input sample (+I), as ``neurons.simulate`` starts."""
        pairs = np.stack([p["b"], p["I"]], axis=1)
        unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
        rest = np.array([neurons.resting_state(self.preset, b, I) for b, I in unique])
        return rest[inverse.ravel(), 0], rest[inverse.ravel(), 1]


def _parameters(sweep, points: dict[str, np.ndarray], names) -> dict[str, np.ndarray]:
    n = len(next(iter(points.values())))
    preset = neurons.PRESETS[sweep.preset].params()
    out = {}
    for name in names:
        if name in points:
            out[name] = np.asarray(points[name], dtype=float)
        else:
            fixed = getattr(sweep, name)
            out[name] = np.full(n, preset[name] if fixed is None else fixed, dtype=float)
    return out


def _runtime_counts(sweep: NeuronSweep, p: dict[str, np.ndarray]) -> np.ndarray:
    """All points as one group through ``neurons.simulate`` (2-D input + input_index)."""
    from ..sources.stimuli import square

    pairs = np.stack([p["input_hz"], p["I"]], axis=1)
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    current = np.stack([square(f, sweep.duration_s, sweep.input_rate_hz, amplitude=I).samples
                        for f, I in unique], axis=1)
    return count_spikes(sweep, p, current, 1000.0 / sweep.input_rate_hz, inverse.ravel(),
                        sweep.settle_s)


def count_spikes(sweep, p: dict[str, np.ndarray], current: np.ndarray, input_dt_ms: float,
                 input_index: np.ndarray, count_from_s: float) -> np.ndarray:
    """Spikes per neuron from ``count_from_s`` on: one NeuronGroup, neuron i driven by
    column ``input_index[i]`` of ``current`` (runtime target ``sweep.engine``)."""
    import brian2 as b2

    # Brian2 answers Ctrl-C by ending the run early and returning: a chunk would be stored
    # with truncated counts and marked done. Raising KeyboardInterrupt leaves it unmarked.
    b2.prefs.core.stop_on_keyboard_interrupt = False
    result = neurons.simulate(sweep.preset, current, sweep.dt_ms, k=p["k"], method=sweep.method,
                              input_dt_ms=input_dt_ms, input_index=input_index,
                              target=sweep.engine, force=sweep.force,
                              a=p["a"], b=p["b"], c=p["c"], d=p["d"])
    counted = result.spike_t_ms >= count_from_s * 1000.0
    return np.bincount(result.spike_i[counted], minlength=len(p["k"]))


SCENE_PREFIXES = ("stimulus.", "preprocess.")


@dataclass(frozen=True)
class SceneSweep:
    """Spike counts of neurons driven by coded robot scenes; axes may be scene fields.

    Axes: neuron parameters (``k, a, b, c, d``), ``stimulus.FIELD`` (a ``RobotScene`` field,
    e.g. ``stimulus.speed_cm_s`` or ``stimulus.contacts.0.distance_cm``) and
    ``preprocess.FIELD`` (a ``make_chain`` argument, e.g. ``preprocess.threshold``). Each
    distinct scene is generated (seeded), preprocessed and coded once and becomes one column of
    a 2-D input; every point is a neuron reading its scene's column (``neurons.simulate`` with
    ``input_index``). Spikes are counted from ``count_from_s`` to the scene's end. Runtime
    engines only: a standalone TimedArray's shape is fixed at compile time.
    """
    stimulus: dict = dataclasses.field(default_factory=dict)
    preprocess: dict = dataclasses.field(default_factory=dict)
    seed: int = 0
    preset: str = "resonator"
    dt_ms: float = 0.1
    method: str = "euler"
    engine: str = "cython"
    count_from_s: float = 0.0
    k: float = 1.0
    a: float | None = None
    b: float | None = None
    c: float | None = None
    d: float | None = None
    force: bool = False

    OUTPUTS = {"spike_count": Output("i4", "1", "spikes counted from count_from_s")}

    def __post_init__(self):
        check(self.engine in ("cython", "numpy"), "engine", self.engine,
              "'cython' or 'numpy' (scene inputs need a runtime target)")
        NeuronSweep(preset=self.preset, dt_ms=self.dt_ms, method=self.method)  # same checks

    def _scene_and_chain(self, values: dict):
        from ..preprocess import make_chain
        from ..spec import set_field
        from ..sources.scenes import scene_from_spec

        spec = {"stimulus": copy.deepcopy(self.stimulus),
                "preprocess": copy.deepcopy(self.preprocess)}
        for name, value in values.items():
            set_field(spec, name, value.item() if hasattr(value, "item") else value)
        scene = scene_from_spec(spec["stimulus"])
        scene.validate()
        chain = make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g,
                           **spec["preprocess"])
        return scene, chain

    def for_grid(self, grid: Grid, block_shape) -> "SceneSweep":
        scene_axes = [d for d in grid.dims if d.startswith(SCENE_PREFIXES)]
        for name in grid.dims:
            check(name in NEURON_AXES and name not in ("input_hz", "I") or name in scene_axes,
                  f"axes.{name}", list(grid.axes[name]),
                  "k, a, b, c, d, stimulus.FIELD or preprocess.FIELD")
        # every value of every scene axis must make a valid scene and chain, before any work
        for name in scene_axes:
            for value in grid.axes[name]:
                try:
                    scene, chain = self._scene_and_chain({name: value})
                    for _, step in chain.steps:
                        getattr(step, "_validate_params_", lambda: None)()
                except SpecError as exc:
                    raise SpecError(f"axes.{name}", float(value), str(exc)) from None
                except (TypeError, KeyError, IndexError) as exc:
                    raise SpecError(f"axes.{name}", float(value),
                                    f"a field of the scene or the chain ({exc})") from None
        k = grid.axes.get("k", np.atleast_1d(self.k))
        check(bool(np.all(k > 0)), "axes.k", list(k), "time-scale factors > 0")
        limit = neurons.MAX_STABLE_K_DT[self.method]
        if not self.force and float(np.max(k)) * self.dt_ms > limit:
            raise SpecError("axes.k", list(k), f"k <= {limit / self.dt_ms:g} at dt = "
                            f"{self.dt_ms:g} ms (neurons.MAX_STABLE_K_DT[{self.method!r}] = "
                            f"{limit:g}), or a smaller dt_ms")
        return self

    @property
    def bytes_per_point(self) -> int:
        scene, _ = self._scene_and_chain({})
        return int(8 * scene.duration_s * scene.rate_hz) + 64

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        n = len(next(iter(points.values())))
        p = _parameters(self, {"k": np.full(n, float(self.k)), **points}, "kabcd")
        scene_names = [k for k in points if k.startswith(SCENE_PREFIXES)]
        if scene_names:
            combos = np.stack([points[k] for k in scene_names], axis=1)
            unique, inverse = np.unique(combos, axis=0, return_inverse=True)
        else:
            unique, inverse = np.zeros((1, 0)), np.zeros(n, int)
        columns, rate_hz = [], None
        for row in unique:
            scene, chain = self._scene_and_chain(dict(zip(scene_names, row)))
            rec = scene.generate(self.seed)
            columns.append(chain.fit(rec.samples).transform(rec.samples))
            rate_hz = scene.rate_hz
        current = np.stack(columns, axis=1)
        counts = count_spikes(self, p, current, 1000.0 / rate_hz, inverse.ravel(),
                              self.count_from_s)
        return {"spike_count": counts.astype(np.int32)}


# One compiled standalone project per process (Brian2's device is process-global); a worker
# keeps it across chunks, so only its first chunk pays for compiling.
_PROJECT: dict = {}


def _standalone_dir(key: str) -> tuple[Path, Any]:
    """A project directory this process holds alone (a lock per slot), kept across runs so
    an unchanged model is not recompiled next time."""
    import fcntl

    base = Path(os.environ.get("SNN_ANTENNA_CACHE", Path.home() / ".cache" / "snn_antenna"))
    base = base / "brian2_standalone"
    base.mkdir(parents=True, exist_ok=True)
    for slot in range(1024):
        lock = open(base / f"{key}-{slot}.lock", "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return base / f"{key}-{slot}", lock
    raise RuntimeError(f"no free Brian2 standalone directory under {base}")


SQUARE_INPUT = ("I_amp * (1 - 2*(int(floor((2*f_in)*(floor(t*input_rate + 1e-6)"
                "/input_rate_value))) % 2))")
SQUARE_INPUT_VARIABLES = "f_in : 1 (constant)\nI_amp : 1 (constant)\nspike_count : integer"


def _standalone_project(sweep: NeuronSweep, n: int):
    import brian2 as b2
    from brian2.devices.device import get_device, reset_device, set_device

    structure = (neurons.PRESETS[sweep.preset].quadratic, sweep.method, sweep.dt_ms,
                 sweep.duration_s, sweep.settle_s, sweep.input_rate_hz, n)
    if _PROJECT.get("structure") == structure:
        return _PROJECT
    key = hashlib.sha1(repr(structure).encode()).hexdigest()[:12]
    directory, lock = _standalone_dir(key)
    if _PROJECT:
        _PROJECT["device"].reinit()
        _PROJECT["lock"].close()
        _PROJECT.clear()
    set_device("cpp_standalone", build_on_run=False, directory=str(directory),
               with_output=False)
    device = get_device()
    try:
        # sample n of the coder's input holds from n/rate to (n+1)/rate: the square wave of
        # stimuli.square, evaluated with the same floating-point operations
        group = b2.NeuronGroup(
            n, neurons.equations(sweep.preset, SQUARE_INPUT, SQUARE_INPUT_VARIABLES),
            threshold=neurons.THRESHOLD, reset=neurons.reset("spike_count += int(t >= settle)"),
            method=neurons.brian_method(sweep.method), dt=sweep.dt_ms * b2.ms, name="neurons",
            namespace={"input_rate": sweep.input_rate_hz * b2.Hz,
                       "input_rate_value": float(sweep.input_rate_hz),
                       "settle": sweep.settle_s * b2.second})
        net = b2.Network(group)
        net.run(sweep.duration_s * b2.second, namespace={})
        device.build(run=False, directory=str(directory), with_output=False)
    finally:
        reset_device()  # runtime code elsewhere in this process keeps working
    _PROJECT.update(structure=structure, device=device, group=group, lock=lock)
    return _PROJECT


def _standalone_counts(sweep: NeuronSweep, p: dict[str, np.ndarray]) -> np.ndarray:
    n = len(p["k"])
    size = max(n, sweep.group_size or n)
    project = _standalone_project(sweep, size)
    group = project["group"]
    v0, u0 = sweep.initial_state(p)
    pad = size - n  # a short last chunk repeats its first point instead of recompiling
    values = {"k": p["k"], "a": p["a"], "b": p["b"], "c": p["c"], "d": p["d"],
              "f_in": p["input_hz"], "I_amp": p["I"], "v": v0, "u": u0}
    run_args = {getattr(group, name): np.r_[arr, np.repeat(arr[:1], pad)]
                for name, arr in values.items()}
    device = project["device"]
    device.run(run_args=run_args, with_output=False)
    for name in device.run_args_arrays:  # this chunk's parameter files: not needed again
        Path(device.project_dir, "static_arrays", name).unlink(missing_ok=True)
    v = np.asarray(group.v[:])
    u = np.asarray(group.u[:])
    ok = np.isfinite(v) & np.isfinite(u) & (np.abs(v) < neurons.RUNAWAY_LIMIT) \
        & (np.abs(u) < neurons.RUNAWAY_LIMIT)
    if not ok[:n].all():
        i = int(np.argmin(ok[:n]))
        raise NumericalInstabilityError(
            neuron=i, params={k: float(values[k][i]) for k in ("k", "a", "b", "c", "d")},
            dt_ms=sweep.dt_ms, method=sweep.method, t_ms=sweep.duration_s * 1000,
            safe_dt_ms=neurons.max_stable_dt_ms(values["k"][i], sweep.method))
    return np.asarray(group.spike_count[:], dtype=np.int64)
