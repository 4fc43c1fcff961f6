"""What a run will cost before it starts: memory, worker processes, wall time.

A grid whose results (loaded for the report) or chunks would not fit in memory is refused
(``check_memory``); ``estimate`` sizes a neuron sweep from the grid's shape alone and
``job_estimate`` a study's Brian2 runs (scenes, bench sets, training), so a study's plan can
say how long it will take (and the command ask for ``--yes`` beyond ``LONG_SWEEP_S``). The
arithmetic is here, once; what each study runs is its plan's (``studies.contract.Plan``).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..core.store import Output
from ..core.bounds import memory_budget_bytes
from . import rates
from .grid import Grid, fits_in_memory
from .standalone import is_built, structure_key, sweep_elements, sweep_structure


def check_memory(grid: Grid, outputs: dict[str, Output], chunk_points: int,
                 bytes_per_point_in_chunk: int = 0, budget: int | None = None) -> None:
    """Refuse a grid whose results (loaded for the report) or chunks would not fit."""
    budget = memory_budget_bytes() if budget is None else budget
    per_point = sum(np.dtype(o.dtype).itemsize for o in outputs.values())
    fits_in_memory("axes", grid.describe(), grid.size * per_point, "a grid whose results fit",
                   "shrink an axis or split the sweep", budget)
    fits_in_memory("sweep.chunk_points", chunk_points,
                   min(chunk_points, grid.size) * bytes_per_point_in_chunk, "chunks that fit",
                   "lower chunk_points", budget)



WORKER_MEMORY_BYTES = 500 * 2**20  # one worker process with Brian2 and Dask imported
LONG_SWEEP_S = 3600.0              # beyond this the CLI asks for --yes
ENGINES = {"cpp_standalone": "standalone"}   # Brian2 target -> the rate table's engine


def engine_of(target) -> str:
    """The engine of the rate tables for a Brian2 code target (None: Brian2's default)."""
    if target is None:
        return "cython"
    return ENGINES.get(target, target) if target in (*ENGINES, *rates.ENGINES) else "numpy"


def codings_engine(target) -> str:
    """The engine of a blind read-out's codings (``engine.batches.DetectColumns``):
    ``"codings"`` (the compiled codings group of ``engine.codings``) for ``"standalone"``,
    else the runtime target's."""
    return "codings" if target == "standalone" else engine_of(target)


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
    rate: rates.Rate = rates.Rate(0.0, "")
    parts: dict = field(default_factory=dict)   # its seconds by what they pay for

    def scale(self, factor: float) -> None:
        self.seconds *= factor
        self.parts = {name: s * factor for name, s in self.parts.items()}

    def describe(self) -> str:
        return (f"{self.points:,} points, {self.neuron_steps:.3g} neuron-steps on "
                f"{self.workers} worker(s) ({self.engine}): about {_duration(self.seconds)} "
                f"[{describe_parts(self.parts)}] at "
                f"{self.rate.value:.3g} neuron-steps/s per worker, "
                f"{self.result_bytes / 1e6:.3g} MB of results, "
                f"{self.chunk_bytes / 1e6:.3g} MB per chunk (rate: {self.rate.source})")


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def estimate(grid: Grid, sweep, chunk_points: int, workers: int) -> Estimate:
    """Points, neuron-steps, expected wall time and memory of ``sweep`` (an
    ``evaluators.NeuronSweep``) over ``grid``."""
    workers = min(workers or os.cpu_count() or 1, max_workers())
    steps = int(round(sweep.duration_s * 1000 / sweep.dt_ms))
    neuron_steps = grid.size * steps
    table = rates.rates()
    rate = table["neuron_steps_per_s"][sweep.engine]
    seconds = neuron_steps / (rate.value * workers)
    # every chunk is a run of its own: its steps' cost beside its neurons' (a runtime
    # engine's per-step overhead) and the run's own
    chunks = -(-grid.size // max(1, min(chunk_points, grid.size)))
    per_chunk = steps / table["steps_per_s"][sweep.engine].value
    if sweep.engine in table["run_s"]:
        per_chunk += table["run_s"][sweep.engine].value
    seconds += per_chunk * -(-chunks // workers)
    # the sweep's Dask workers start together, each a new process importing what a study's
    # process imports (measured: 14 s from the cluster's start to its first chunk's work
    # beside the compile, tuning sweep at load 15)
    parts = {"neurons": neuron_steps / (rate.value * workers),
             "chunks' steps and starts": per_chunk * -(-chunks // workers)}
    if workers > 1:     # one worker: the sweep runs in the study's own process
        parts["the workers' start"] = table["python_s"]["study_start"].value
        seconds += parts["the workers' start"]
    build = None
    if sweep.engine == "standalone":
        # a chunk holds the grid's block (``group_size``, set by ``for_grid``) at most
        build = standalone_build(sweep_structure(sweep, sweep_elements(
            sweep, sweep.group_size or min(chunk_points, grid.size))))
    compiling = build_seconds(sweep.engine, build, table)
    if compiling:
        parts["code generation (compiled before)" if build and build.built
              else "compiling"] = compiling
    seconds += compiling
    per_point = sum(np.dtype(o.dtype).itemsize for o in sweep.OUTPUTS.values())
    chunk = min(chunk_points, grid.size) * sweep.bytes_per_point
    return Estimate(grid.size, neuron_steps, workers, seconds, grid.size * per_point, chunk,
                    sweep.engine, rate, parts)


def describe_parts(parts: dict[str, float]) -> str:
    """``parts`` (what costs what, seconds each) as one clause, the costliest first; parts
    under half a second are left out."""
    shown = [f"{name} {_duration(s)}" for name, s in
             sorted(parts.items(), key=lambda p: -p[1]) if s >= 0.5]
    return "; ".join(shown) if shown else "nothing above a second"


def add_parts(parts: dict[str, float], more: dict[str, float], factor: float = 1.0) -> None:
    for name, s in more.items():
        parts[name] = parts.get(name, 0.0) + factor * s


@dataclass
class JobEstimate:
    """A study's simulated work (scenes, bench sets, streams) and its expected wall time,
    with ``parts``: its seconds by what they pay for (they sum to ``seconds``)."""
    what: str
    steps: float
    neuron_steps: float
    seconds: float
    engine: str
    key: str = ""          # the spec key that sets the job's length, named when it is refused
    value: object = None   # that key's value, as the spec holds it

    sources: str = ""      # where the rates come from (``rates.sources``)
    parts: dict = field(default_factory=dict)

    def scale(self, factor: float) -> None:
        self.seconds *= factor
        self.parts = {name: s * factor for name, s in self.parts.items()}

    def describe(self) -> str:
        parts = f" [{describe_parts(self.parts)}]" if self.parts else ""
        if not self.steps:          # no Brian2 run: measured work alone
            return f"{self.what}: about {_duration(self.seconds)}{parts}"
        return (f"{self.what}: {self.steps:.3g} steps, {self.neuron_steps:.3g} neuron-steps "
                f"({self.engine}): about {_duration(self.seconds)}{parts} ({self.sources})")


@dataclass(frozen=True)
class Build:
    """A compiled network a run needs: its name (runs of one name share one build),
    whether it is compiled already (Brian2's caches on disk) and its size in compiles of
    the probe's network (``rates.probe``: the offline array's, or one codings project)."""
    name: str
    built: bool
    compiles: float = 1.0


def standalone_build(structure: tuple) -> Build:
    """The build of an ``engine.standalone.project`` of ``structure``."""
    return Build(f"project {structure_key(structure)}", is_built(structure))


def build_seconds(engine: str, build: Build | None = None, table=None) -> float:
    """One build of ``engine``'s network: a compiled network costs its code generation
    alone (``rebuild_s``), a new or unknown one (``build`` None) a whole compile
    (``compile_s``); numpy compiles nothing."""
    table = rates.rates() if table is None else table
    if engine not in table["compile_s"]:
        return 0.0
    size = build.compiles if build is not None else 1.0
    if build is not None and build.built:
        return size * table["rebuild_s"].get(engine, rates.Rate(0.0, "")).value
    return size * table["compile_s"][engine].value


def job_estimate(what: str, runs: list[tuple], key: str = "") -> JobEstimate:
    """Wall time of Brian2 runs, each ``(simulated_s, dt_ms, n_neurons, engine[, build])``:
    the step overhead of a small network plus the neuron-steps of a large one, at the rates
    of ``rates.rates()`` (this machine's probe, else the table), and each network's build
    once (``build_seconds``: a worker builds its project once, cached on disk; the runs of
    an engine that name no ``Build`` share one whole compile)."""
    table = rates.rates()
    steps = neuron_steps = 0.0
    engine = runs[0][3] if runs else "numpy"
    used = set()
    builds: dict[tuple, Build | None] = {}
    parts = {"stepping": 0.0, "neurons": 0.0, "runs' starts": 0.0}
    for simulated_s, dt_ms, n_neurons, eng, *build in runs:
        eng = eng if eng in table["neuron_steps_per_s"] else "numpy"
        used.add(eng)
        try:
            n = float(simulated_s) * 1000.0 / float(dt_ms)
            size = float(n_neurons)
        except OverflowError:           # a size beyond any float: beyond any limit too
            n = size = math.inf
        steps += n
        neuron_steps += n * size
        parts["stepping"] += n / table["steps_per_s"][eng].value
        parts["neurons"] += n * size / table["neuron_steps_per_s"][eng].value
        if eng in table["run_s"]:       # a compiled run's own start and files
            parts["runs' starts"] += table["run_s"][eng].value
        one = build[0] if build else None
        builds[eng, one.name if one else None] = one
    for (eng, _), one in builds.items():
        name = "code generation (compiled before)" if one and one.built else "compiling"
        parts[name] = parts.get(name, 0.0) + build_seconds(eng, one, table)
    used_rates = {k: {e: r for e, r in v.items() if e in used} for k, v in table.items()}
    return JobEstimate(what, steps, neuron_steps, sum(parts.values()), engine, key,
                       sources=rates.sources(used_rates), parts=parts)


def compile_seconds(engine: str, build: Build | None = None) -> float:
    """One build of ``engine``'s network (``build_seconds``)."""
    return build_seconds(engine, build)


def study_overhead_s() -> float:
    """What every study run costs beside its work: the process's start (imports) and its
    report (``rates.rates()``)."""
    python = rates.rates()["python_s"]
    return python["study_start"].value + python["report"].value


def readout_seconds(n_maps: float, windows: float, workers: int = 1) -> float:
    """Python's time for the contact rule over ``n_maps`` rate maps of ``windows`` windows,
    shared among ``workers`` processes (``rates.rates()``)."""
    per_window = rates.rates()["python_s"]["readout_window"].value
    return n_maps * windows * per_window / max(1, workers)


def stages_estimate(what: str, stages: list[tuple]) -> JobEstimate:
    """A study of several stages, each ``(key, value, runs)`` or ``(key, value, runs,
    seconds)`` (``seconds``: measured work that is not Brian2, such as making a bench set):
    the time of all of them, and the key (with its value) of the stage that costs most,
    which a refusal names."""
    sized = []
    whole = job_estimate(what, [r for _, _, runs, *_ in stages for r in runs])
    for key, value, runs, *other in stages:
        one = job_estimate(what, runs, key)
        one.seconds += sum(other)
        if sum(other):
            add_parts(whole.parts, {f"{key}: work beside Brian2": sum(other)})
        sized.append((one, value))
    # a network the stages share is built once (``whole``, from all their runs)
    whole.seconds = sum(whole.parts.values())
    longest, whole.value = max(sized, key=lambda s: s[0].seconds)
    whole.key = longest.key
    return whole


def gate_training_runs(gate, n_train: int, n_test: int, copies: int = 1) -> list:
    """The Brian2 run that trains a ``networks.gate.SpeedGate``: every epoch presents each
    training speed for ``present_s``, and ``curve_points + 1`` recall blocks present each test
    speed (its learning curve); its steps cost ``GATE_GROUPS`` small networks' each."""
    presented = (gate.epochs * n_train + (gate.curve_points + 1) * n_test) * gate.present_s
    return [(presented * GATE_GROUPS, gate.dt_ms, (gate.n_speed_neurons + 2) * copies,
             engine_of(gate.target), Build("speed gate", gate.compiled()))]


# The gate's network steps its groups, synapses and monitors each, every one at a small
# network's per-step cost: its training took 3.6 s in the exploration's quick profile and
# about 9 s in the gating study's full one (beside its Dask workers' codings), at this
# machine's idle rates 1.9 and 4.6 times one small network's steps.
GATE_GROUPS = 2.5


# A bench set's cost: generating its contact events and extracting their features, per event
# on one process; then the read-outs' fits, per event, per split (seed) and per training
# iteration summed over the read-outs (``Evaluation``'s mlp, NMF and material iterations).
# Measured with `snn-antenna run studies/model_selection.toml --quick --set
# 'selection.candidates=[{physics="current", strengths=[1.0]}]'` at stimulus.repetitions 4 and
# 40 (128 and 1,280 events, 2.2 and 7.6 s), and at 40 with the full profile's evaluation
# (3 seeds, 760 iterations: 12.3 s), AMD EPYC 2 cores, load average 3.5.
BENCH_EVENT_S = 4.4e-3
FIT_EVENT_ITERATION_S = 1.8e-6


def bench_seconds(n_events: int, n_jobs: int = 1) -> float:
    """Time to make a bench set of ``n_events`` and extract its events' features on
    ``n_jobs`` processes."""
    jobs = max(1, min(n_jobs, os.cpu_count() or 1))
    return n_events * BENCH_EVENT_S / jobs


def fit_seconds(n_events: int, seeds: int, iterations: int) -> float:
    """Time to fit read-outs of ``iterations`` training iterations in all on ``n_events``
    events, once per split of ``seeds``."""
    return n_events * seeds * iterations * FIT_EVENT_ITERATION_S
