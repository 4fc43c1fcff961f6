"""The engines' rates that every estimate multiplies by, and where each one comes from.

    table = rates()          # this machine's probe when one is stored for this code, else TABLE
    table = probe()          # measure now (small Brian2 runs, about a minute) and store

A ``Rate`` is a value with its source. ``TABLE`` holds rates measured once and written down
(each with the command that measured it); ``probe`` measures the per-step and per-neuron-step
cost of each Brian2 engine on this machine, now, with small runs of the same kind of group
the studies run (``neurons.simulate`` for the runtime targets; ``engine.codings``' compiled
group for ``"codings"``), and stores them in ``cache_root()/rates/KEY.json``, KEY hashing the
probing code with its imports (``provenance.code_hash``), Brian2's version and the CPU: a
probe of other code or another machine is never used. A probe measures the machine as it is
(other processes included), so re-probe when the load changes.
"""
from __future__ import annotations

import datetime as dt
import hashlib
import json
import os
import platform
import tempfile
import time
from dataclasses import asdict, dataclass

import numpy as np

from ..core.files import atomic_write, cache_root, make_folder
from ..core.provenance import code_hash
from ..networks import neurons
from ..networks.resonators import ResonatorArray, rate_map
from ..readout.contacts import ContactDetector
from .codings import compiled_rate_maps


@dataclass(frozen=True)
class Rate:
    value: float
    source: str


# The rates of this machine class as its probe (``probe``, below) measured them, for a
# machine without a probe of its own: AMD EPYC (Zen 5, AVX-512), 2 cores, as idle (the probe
# ran in a session the scheduler weighed ten times the other work on the machine, all of it
# niced; ``TABLE_LOAD``: none competing, ``competing_load``; every estimate scales the rates
# from it to the load it meets), probed with
# `SNN_ANTENNA_CACHE=/tmp/p python -c "from snn_antenna.engine import rates; rates.probe()"`
# on 2026-11-29; on the idle machine (load 1.8) the same probe measured each within 30 % (compiles
# 3.2 and 11.0 s, a rebuild 1.2 s: the table errs long; its contact rule's 0.11 ms per window is
# the table's). neuron_steps_per_s: per ONE worker process (points x steps / wall time, compile
# excluded); steps_per_s: time steps per second of ONE small network (tens of neurons, spike
# monitor), where the per-step overhead rather than the neurons sets the pace.
_WRITTEN = "engine/rates.py TABLE (measured once, see its comment)"
TABLE = {
    # standalone (the fused sweep and event engines, float64), not probed: `python
    # benchmarks/bench_sweep.py --sizes 1000000 --runtime-max 0 --naive-sample 1` measured
    # 9.3e8 idle on one core
    "neuron_steps_per_s": {"numpy": 9.6e7, "cython": 1.3e8, "standalone": 9.3e8,
                           "codings": 1.7e8},
    # (codings, standalone: the compiled loop's own cost per step, about a microsecond; a
    # run's own cost is its binary's start, in run_s)
    "steps_per_s": {"numpy": 2.3e4, "cython": 1.1e5, "standalone": 1.0e6, "codings": 1.0e6},
    # a project compiled from scratch (the probe's codings project, in an empty cache) and
    # the offline array's network on cython
    "compile_s": {"standalone": 4.6, "codings": 4.6, "cython": 11.1},
    # a compiled project found on disk by a new process: its code generated again and its
    # main file recompiled
    "rebuild_s": {"standalone": 2.3, "codings": 2.3},
    # a run's own cost beside its steps: building the network and its code objects (runtime
    # targets); the binary's start, its inputs written and its results read (compiled;
    # standalone not probed: 0.5 s at load 12.9, scaled)
    "run_s": {"numpy": 0.11, "cython": 0.15, "codings": 0.01, "standalone": 0.2},
    # Python's own work, seconds each: a study process's start (Python, Brian2, matplotlib
    # and the package imported) and its report; one window of a rate map through the contact
    # rule (``ContactDetector.detect``)
    # closed_loop_chunk: the exploration loop's Python per chunk of 10 ms (moving the robot,
    # coding its samples, feeding them): the full profile's loop ran 12 s in 3.5 s idle,
    # steps included. report: a study's whole report (its figures, pages, summary and
    # stores): 6 to 11 s at load 15; the quickstart's whole quick run took 3.9 s idle, its
    # process's start (2.9 s in the idle probe) included
    "python_s": {"study_start": 3.1, "report": 1.0, "readout_window": 1.1e-4,
                 "closed_loop_chunk": 0.002},
}
ENGINES = ("numpy", "cython", "standalone", "codings")   # the Brian2 engines
# the load average the table was measured at (its rates are scaled from it, ``load_factor``)
TABLE_LOAD = 0.0


def table() -> dict[str, dict[str, Rate]]:
    return {kind: {engine: Rate(v, _WRITTEN) for engine, v in values.items()}
            for kind, values in TABLE.items()}


def machine() -> str:
    """The CPU this machine reports, and its core count."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as info:
            model = next((line.split(":", 1)[1].strip() for line in info
                          if line.startswith("model name")), model)
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def probe_key() -> str:
    """The probe's cache key: the probing code and its imports, Brian2's version, the CPU."""
    from importlib.metadata import version

    # Brian2's version from its metadata: a --check imports no Brian2
    text = json.dumps([code_hash(__name__), version("brian2"), machine()])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _path():
    return cache_root() / "rates" / f"{probe_key()}.json"


def rates() -> dict[str, dict[str, Rate]]:
    """The rates to estimate with: the table, with every rate this machine's stored probe
    (for this code) measured in its place."""
    out = table()
    try:
        stored = json.loads(_path().read_text())
    except (OSError, ValueError):
        return out
    for kind, values in stored.get("rates", {}).items():
        for engine, value in values.items():
            if kind in out and isinstance(value, (int, float)) and np.isfinite(value) \
                    and value > 0:
                out[kind][engine] = Rate(float(value), f"probe of {stored.get('when', '?')} "
                                                       f"on this machine ({_path()})")
    return out


# Two probes of this machine (2 cores), at load averages 0.75 and 12.9, found numpy's,
# cython's and the contact rule's rates 2.9 to 3.5 times slower at 12.9 (a study's start 4.4
# times), where an equal share of the cores among the load's processes predicts 7: the others
# are partly niced and partly waiting. This power of the equal share fits both.
SLOWDOWN_POWER = 0.6


def slowdown(load: float) -> float:
    """How much slower a new process runs at ``load`` (``competing_load``) than on an idle
    machine: the share of the cores each of the ``load`` + 1 runnable processes would get,
    none more than one core, to the power ``SLOWDOWN_POWER`` (measured)."""
    return max(1.0, (float(load) + 1.0) / (os.cpu_count() or 1)) ** SLOWDOWN_POWER


# How long ``competing_load`` watches the CPU's time split (a --check's cost)
LOAD_SAMPLE_S = 0.3


def _cpu_times() -> tuple[float, float, float] | None:
    """(busy at nice 0 or below, busy niced, idle) jiffies of all CPUs since boot, from
    /proc/stat; None where there is none."""
    try:
        with open("/proc/stat") as stat:
            fields = [float(v) for v in stat.readline().split()[1:8]]
    except (OSError, ValueError):
        return None
    user, nice, system, idle, iowait, irq, softirq = fields
    return user + system + irq + softirq, nice, idle + iowait


_watched: list = []    # [(monotonic time, competing load)] of the last watch


def _autogroups() -> bool:
    """Whether the kernel shares the CPU among sessions first (``sched_autogroup``): then
    a process's nice weighs only against its own session's, and another session's niced
    work competes in full."""
    try:
        with open("/proc/sys/kernel/sched_autogroup_enabled") as flag:
            return flag.read().strip() == "1"
    except OSError:
        return False


# Busier than this share of its cores, a machine's demand is its run queue (the load average)
SATURATED = 0.9


def competing_load(sample_s: float = LOAD_SAMPLE_S) -> float:
    """The CPU demand a new process of ordinary priority shares the cores with, watched for
    ``sample_s`` in /proc/stat: the cores busy, or on a machine busy beyond ``SATURATED`` of
    them the 1-minute load average (its queue), whichever is more. The load average alone
    counts tasks that wait without computing (a virtual machine's kernel threads keep it
    near 1.5 on an idle 2-core machine) and trails a run that has just ended by a minute.
    Processes under ``nice`` yield their cores to it (a nice-10 process weighs a tenth of a
    nice-0 one): only the busy time at nice 0 or below counts, except where the kernel
    groups processes by session (``_autogroups``), where nice yields nothing across
    sessions. One estimate asks several times: a watch serves for ``LOAD_SAMPLE_S`` × 10."""
    if _watched and time.monotonic() - _watched[0][0] < 10 * sample_s:
        return _watched[0][1]
    load = os.getloadavg()[0]
    before = _cpu_times()
    if before is not None:
        time.sleep(sample_s)
        ordinary, niced, idle = (a - b for a, b in zip(_cpu_times(), before))
        cores = os.cpu_count() or 1
        if ordinary + niced + idle > 0:
            busy = cores * (ordinary + niced) / (ordinary + niced + idle)
            load = busy if busy < SATURATED * cores else max(busy, load)
            if not _autogroups() and ordinary + niced > 0:
                load *= ordinary / (ordinary + niced)
    _watched[:] = [(time.monotonic(), load)]
    return load


def rates_load() -> float:
    """The load the rates in use were measured at: the stored probe's, else the table's."""
    try:
        return float(json.loads(_path().read_text())["load_average"])
    except (OSError, ValueError, KeyError, TypeError):
        return TABLE_LOAD


def measured_at(seconds: float, load: float) -> float:
    """``seconds`` of work measured at ``load``, in the terms of the rates in use (measured at
    ``rates_load``): what ``load_factor`` then scales to the load now. A study's own constant
    (a reference solver's CPU per neuron, a bench event's making) states the load it was
    measured at through this."""
    return seconds * slowdown(rates_load()) / slowdown(load)


def load_factor() -> tuple[float, str]:
    """The factor from the load the rates were measured at (the stored probe's, else the
    table's ``TABLE_LOAD``) to the load a run would compete with now (``competing_load``),
    and a line saying so."""
    try:
        stored = json.loads(_path().read_text())
        then, what = float(stored["load_average"]), "probe"
    except (OSError, ValueError, KeyError, TypeError):
        then, what = TABLE_LOAD, "table"
    now = competing_load()
    factor = slowdown(now) / slowdown(then)
    return factor, (f"at load {now:.1f} (not niced; {what} at {then:.1f}, "
                    f"{os.cpu_count()} cores): ×{factor:.2f}")


def sources(table_: dict[str, dict[str, Rate]]) -> str:
    """One line naming where the rates come from."""
    found = sorted({r.source for values in table_.values() for r in values.values()})
    return "rates: " + "; ".join(found)


# -- the probe ----------------------------------------------------------------------------
PROBE_S = 0.2           # simulated per probe run, dt 0.1 ms: 2,000 steps
# neurons: the step overhead, then the neurons' own cost (numpy's per-step overhead of
# milliseconds under load hides 2,400 neurons' work; 24,000 stand out of it)
PROBE_SIZES = (24, 24000)
PROBE_LONGER = 5        # the small size's second run: this many times PROBE_S
PROBE_CODINGS = (10, 100)   # codings (of 24 neurons) in the compiled probe groups ...
CODINGS_PROBE_S = 0.5       # ... each coding this long (5,000 steps)


def _square(n_samples: int, columns: int, rate_hz: float) -> np.ndarray:
    t = np.arange(n_samples) / rate_hz
    hz = np.linspace(6.0, 30.0, columns)
    return 0.15 * np.sign(np.sin(2 * np.pi * t[:, None] * hz[None, :]))


def _best_of(run, repeats: int = 2) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t0)
    return best


def _runtime(target: str) -> tuple[float, float, float]:
    """(steps/s, neuron-steps/s, s per run) of ``neurons.simulate`` on ``target``: two sizes
    over ``PROBE_S``, and the small size over ``PROBE_LONGER`` times as long. A run's own
    cost (building the network, preparing its code objects) is not a step's: a short run
    alone would charge it to every step and make a long run look many times slower."""
    rate_hz, n_samples = 1000.0, int(PROBE_S * PROBE_LONGER * 1000)
    steps = PROBE_S * 1000 / 0.1
    # one input of 24 columns for every run: its shape is compiled in, the group's size
    # and the run's length (run_ms) not
    current = _square(n_samples, PROBE_SIZES[0], rate_hz)
    times = {}
    for n, longer in ((PROBE_SIZES[0], 1), (PROBE_SIZES[0], PROBE_LONGER), (PROBE_SIZES[1], 1)):
        def run(n=n, longer=longer):
            neurons.simulate("resonator", current, 0.1, k=np.linspace(0.3, 1.5, n),
                             method="rk2", input_dt_ms=1.0, target=target,
                             input_index=np.arange(n) % current.shape[1],
                             run_ms=PROBE_S * longer * 1000)
        run()                               # code generation, compiling
        times[n, longer] = _best_of(run)
    small, big = PROBE_SIZES
    per_neuron = (times[big, 1] - times[small, 1]) / (steps * (big - small))
    per_step = ((times[small, PROBE_LONGER] - times[small, 1]) / ((PROBE_LONGER - 1) * steps)
                - small * per_neuron)
    per_run = times[small, 1] - steps * (max(per_step, 0.0) + small * max(per_neuron, 0.0))
    return _inverse(per_step), _inverse(per_neuron), max(per_run, 0.0)


def _inverse(seconds: float) -> float:
    """A rate from seconds per unit; 0 (not stored: the table's rate stays) when the
    difference it came from was lost in the machine's noise."""
    return 1.0 / seconds if seconds > 0 else 0.0


def _codings() -> tuple[float, float]:
    """(s per run, neuron-steps/s) of the compiled codings group (``engine.codings``), from
    two group sizes (two projects, each built once on disk)."""
    array = ResonatorArray(n_neurons=24, method="rk2", dt_ms=0.1)
    rate_hz = 1000.0
    steps = CODINGS_PROBE_S * 1000 / array.dt_ms
    walls = []
    for size in PROBE_CODINGS:
        coded = _square(int(CODINGS_PROBE_S * 1000), size, rate_hz)

        def run(coded=coded, size=size):
            compiled_rate_maps(array, coded, rate_hz, 0.1, size)
        run()                               # built, or found built on disk
        walls.append(_best_of(run))
    neuron_steps = [steps * array.n_neurons * size for size in PROBE_CODINGS]
    per_neuron = (walls[1] - walls[0]) / (neuron_steps[1] - neuron_steps[0])
    if per_neuron <= 0:          # lost in the noise: every second charged to the neurons
        return 0.0, neuron_steps[1] / walls[1]
    return walls[0] - neuron_steps[0] * per_neuron, 1.0 / per_neuron


# A new process builds (or finds) the small codings project and runs it twice: the first
# run's time less the second's is the build. Brian2 names a process's code objects in the
# order it creates them, so a project is found compiled by a process that creates its
# objects in the same order, as a study's run does each time: a second process finds the
# first one's project and regenerates its code and its main file alone.
_CODINGS_BUILD = f"""
import time
from snn_antenna.engine.codings import compiled_rate_maps
from snn_antenna.engine.rates import _square
from snn_antenna.networks.resonators import ResonatorArray
array = ResonatorArray(n_neurons=24, method="rk2", dt_ms=0.1)
coded = _square({int(CODINGS_PROBE_S * 1000)}, {PROBE_CODINGS[0]}, 1000.0)
times = []
for _ in range(2):
    t0 = time.perf_counter()
    compiled_rate_maps(array, coded, 1000.0, 0.1, {PROBE_CODINGS[0]})
    times.append(time.perf_counter() - t0)
print(times[0] - times[1])
"""


def _in_process(code: str, *args: str, env: dict | None = None) -> float:
    """The last number a new Python process running ``code`` prints."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", code, *args], check=True,
                          capture_output=True, text=True,
                          env=None if env is None else {**os.environ, **env})
    return float(done.stdout.split()[-1])


def _builds() -> tuple[float, float]:
    """(compile s, found-compiled s) of a codings project: built in an empty cache, and
    found on disk by a second process."""
    with tempfile.TemporaryDirectory(prefix="snn_antenna_probe_") as empty:
        cold = _in_process(_CODINGS_BUILD, env={"SNN_ANTENNA_CACHE": empty})
    _in_process(_CODINGS_BUILD)             # the project on disk, named as a process names it
    warm = _in_process(_CODINGS_BUILD)
    return max(cold, 0.0), max(warm, 0.0)


FIGURES_PER_REPORT = 6   # the gating study's report draws 6, the others 2 to 8


def _start() -> tuple[float, float]:
    """Seconds for a new process to import what a study imports (Python, Brian2, matplotlib,
    the package's command and the studies' stages), and for its report
    (``FIGURES_PER_REPORT`` rate-map figures drawn and saved as PNG)."""
    import subprocess
    import sys

    figure = ("import io, time, numpy as np, matplotlib; matplotlib.use('Agg'); "
              "import matplotlib.pyplot as plt; t0 = time.perf_counter(); "
              "fig, ax = plt.subplots(figsize=(8, 3)); "
              "ax.imshow(np.random.default_rng(0).random((24, 150)), aspect='auto'); "
              "fig.savefig(io.BytesIO(), format='png', dpi=110); "
              "print(time.perf_counter() - t0)")
    # every study's stages imported, as a study's run imports its own (scikit-learn, Dask,
    # xarray, zarr); the best of two: the first start may read the files from disk
    imports = ("import brian2, importlib, snn_antenna.cli; "
               "from snn_antenna.studies import STUDIES; "
               "[importlib.import_module(f'snn_antenna.studies.{s}.run') for s in STUDIES]")
    best = (np.inf, 0.0)
    for _ in range(2):
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", f"{imports}; {figure}"],
                              check=True, capture_output=True, text=True)
        whole = time.perf_counter() - t0
        one_figure = float(done.stdout.split()[-1])
        best = min(best, (whole - one_figure, one_figure))
    return best[0], FIGURES_PER_REPORT * best[1]


def _readout_window() -> float:
    """Seconds per window of ``ContactDetector.detect`` on a 15 s rate map of 24 neurons
    where every 15th window is a contact episode of its own: an episode's estimate costs
    most, and the quick gating run's maps average about that (91 maps of 80 windows in 63 s
    against 24 ms a window with one episode per 5 windows, under the same load)."""
    array = ResonatorArray()
    duration_s, window_s = 15.0, 0.1
    windows = int(duration_s / window_s)
    starts = np.arange(0, windows, 15) * window_s
    spike_t = (starts[:, None] + np.array([0.01, 0.03, 0.05])[None, :]).ravel()
    spike_i = np.full(spike_t.size, array.n_neurons - 1)    # the top neuron: 30 Hz
    rates = rate_map(spike_i, spike_t, array.neuron_hz, duration_s, window_s)
    detector = ContactDetector()
    return _best_of(lambda: detector.detect(rates)) / windows


# a new process runs the offline array on a short recording, its cython cache empty or as
# it is; the difference is the network's compile (``networks.runtime_cache``)
_CYTHON_RUN = """
import sys, time
from brian2 import prefs
if sys.argv[1]:
    prefs.codegen.runtime.cython.cache_dir = sys.argv[1]
import numpy as np
from snn_antenna.core.signals import Recording
from snn_antenna.networks.resonators import ResonatorArray
array = ResonatorArray(n_neurons=24, target="cython")
coded = Recording(0.15 * np.sign(np.sin(np.arange(500) / 1000 * 2 * np.pi * 10)), 1000.0)
t0 = time.perf_counter()
array.run(coded)
print(time.perf_counter() - t0)
"""


def _cython_compile() -> float:
    """Seconds to compile the offline array's network on the cython target: its run in an
    empty cython cache less its run with the network compiled (the best of two each)."""
    def run(cache: str) -> float:
        return _in_process(_CYTHON_RUN, cache)

    warm = min(run("") for _ in range(2))
    colds = []
    for _ in range(2):
        with tempfile.TemporaryDirectory(prefix="snn_antenna_probe_cython_") as empty:
            colds.append(run(empty))
    return max(min(colds) - warm, 0.0)


def probe(log=print) -> dict[str, dict[str, Rate]]:
    """Measure the probed rates on this machine now, store them, and return ``rates()``."""
    measured = {"neuron_steps_per_s": {}, "steps_per_s": {}, "run_s": {}}
    for target in ("numpy", "cython"):
        per_step, per_neuron, per_run = _runtime(target)
        measured["steps_per_s"][target] = per_step
        measured["neuron_steps_per_s"][target] = per_neuron
        measured["run_s"][target] = per_run
        log(f"      {target}: {per_step:.3g} steps/s, {per_neuron:.3g} neuron-steps/s, "
            f"{per_run:.2f} s per run (0: not resolved, the table's stays)")
    start, report = _start()
    # (the report's figures alone: a study's whole report takes longer, the table's stays)
    measured["python_s"] = {"study_start": start, "readout_window": _readout_window()}
    log(f"      a study's start: {start:.1f} s, its report {report:.1f} s; the contact "
        f"rule: {1e3 * measured['python_s']['readout_window']:.2f} ms per window")
    per_run, per_neuron = _codings()
    build, rebuild = _builds()
    measured["run_s"]["codings"] = per_run
    measured["neuron_steps_per_s"]["codings"] = per_neuron
    # a compiled engine's project: the same build steps for the codings and the sweep
    measured["compile_s"] = {"codings": build, "standalone": build}
    measured["rebuild_s"] = {"codings": rebuild, "standalone": rebuild}
    log(f"      codings (compiled): {per_neuron:.3g} neuron-steps/s and {per_run:.2f} s per "
        f"run; a project compiled in {build:.1f} s, found compiled in {rebuild:.1f} s")
    measured["compile_s"]["cython"] = _cython_compile()
    log(f"      cython: a network compiled in {measured['compile_s']['cython']:.1f} s")
    path = _path()
    make_folder(path.parent)
    atomic_write(path, json.dumps({
        "rates": measured, "when": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": machine(), "load_average": competing_load()}, indent=1) + "\n")
    return rates()


def as_json(table_: dict[str, dict[str, Rate]]) -> dict:
    return {kind: {engine: asdict(r) for engine, r in values.items()}
            for kind, values in table_.items()}
