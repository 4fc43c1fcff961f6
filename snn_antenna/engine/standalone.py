"""Compiled cpp_standalone projects of the sweep engine (engine ``"standalone"``).

Brian2 compiles a model once per process and structure (group sizes, dt, method, duration)
into a project directory kept on disk (``SNN_ANTENNA_CACHE``, default
``~/.cache/snn_antenna``); every chunk re-runs it with its own parameters and inputs
(``run_args``). ``project`` / ``run_project`` hold and run the process's one project;
``NeuronSweep``'s is here (its square-wave input is computed inside the model, so the project
does not depend on the chunk's values), ``EventSweep``'s in ``engine.events``.
"""
from __future__ import annotations

import hashlib
import math
import os
import re
import sys
import tempfile
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..core import bounds
from ..core.errors import NumericalInstabilityError
from ..core.files import atomic_write, cache_root, lock_folder, make_folder
from ..networks import neurons
from .devices import bounded_make
from .devices import float_precision

# One compiled standalone project per process (Brian2's device is process-global); a worker
# keeps it across chunks, so only its first chunk pays for compiling.
_PROJECT: dict = {}


def _standalone_dir(key: str) -> tuple[Path, int]:
    """A project directory this process holds alone (the folder's own lock, per slot), kept
    across runs so an unchanged model is not recompiled next time."""
    base = make_folder(cache_root() / "brian2_standalone")
    for slot in range(1024):
        directory = make_folder(base / f"{key}-{slot}")
        lock = lock_folder(directory)
        if lock is not None:
            return directory, lock
    raise RuntimeError(f"no free Brian2 standalone directory under {base}")


# sample n of the coder's input holds from n/rate to (n+1)/rate: the square wave of
# stimuli.square. Its sign is written in floating point, h - 2*floor(h/2) for "h is odd"
# (exact for every whole h below 2**52), where an int cast and an integer modulo would keep
# the compiler from vectorising the loop over neurons. The state updater computes it once per
# clock tick into I_held, which the equations read (``FusedUpdater``).
SQUARE_INPUT = ("I_amp * (1 - 2*(floor((2*f_in)*(floor(t*input_rate + 1e-6)/input_rate_value))"
                " - 2*floor(0.5*floor((2*f_in)*(floor(t*input_rate + 1e-6)/input_rate_value)))))")
# spike_count is a float: an integer would be converted to and from floating point at every
# step of the vectorised loop. Whole numbers are exact in it up to 2**24 (float32) spikes.
SQUARE_INPUT_VARIABLES = ("I_held : 1\nf_in : 1 (constant)\nI_amp : 1 (constant)\n"
                          "spike_count : 1")

# Threshold and reset inside the state update, branch-free: the step, the threshold test and
# the reset are one pass over the group's arrays, and selects (``where``: not a branch, not a
# list of spiking neurons) so the loop over neurons vectorises. Brian2's own threshold and
# reset are two more passes per step, the first a compaction that cannot vectorise. The
# result is the same: threshold after the step, reset in the same step (to exactly c).
SPIKED = f"v >= {neurons.V_PEAK}"   # the threshold test, written out in each select: as a
# boolean temporary, Brian2 would turn every select that reads it into a branch


def fused_reset(*on_spike: str) -> str:
    """The model's threshold and reset as state-update statements: ``on_spike`` (branch-free
    statements that test ``SPIKED``: what a run counts or times), then the reset
    (``neurons.reset``'s, as selects)."""
    return "\n".join((*on_spike, f"u = where({SPIKED}, u + d, u)", f"v = where({SPIKED}, c, v)"))


# The sweep's: spikes counted from settle.
FUSED_RESET = fused_reset(
    f"spike_count = where({SPIKED}, spike_count + int(t >= settle), spike_count)")


def _functions() -> dict:
    """Brian2 functions of the compiled model: ``where(condition, a, b)``, a select as
    numpy's ``where``; ``square(x)``, x*x in x's own type (Brian2 writes ``v**2`` as
    ``pow(v, 2)``, which C++ computes in double: in a float32 loop, two conversions); and
    ``held_input(x)``, x itself: a held input written as a function call, so Brian2 orders
    the equations' sums as with a TimedArray's call (the runtime path's input), and the
    compiled arithmetic rounds as the runtime path's does."""
    from brian2 import Function

    where = Function(np.where, arg_units=[None, None, None], arg_names=["condition", "a", "b"],
                     return_unit=lambda u_cond, u_a, u_b: u_a,
                     arg_types=["boolean", "any", "any"], return_type="highest")
    where.implementations.add_implementation("cpp", """
        template <typename A, typename B>
        inline A _where(const bool condition, const A a, const B b) { return condition ? a : (A)b; }
        """, name="_where")  # noqa: E501 (the C++ source is kept byte for byte)
    square = Function(np.square, arg_units=[None], arg_names=["x"],
                      return_unit=lambda u: u ** 2, arg_types=["float"], return_type="highest")
    square.implementations.add_implementation(
        "cpp", "template <typename T> inline T _square(const T x) { return x*x; }",
        name="_square")
    held = Function(lambda x: x, arg_units=[None], arg_names=["x"],
                    return_unit=lambda u: u, arg_types=["any"], return_type="highest")
    held.implementations.add_implementation(
        "cpp", "template <typename T> inline T _held_input(const T x) { return x; }",
        name="_held_input")
    return {"where": where, "square": square, "held_input": held}


class FusedUpdater:
    """A Brian2 state updater: ``tick`` (statements run once per clock tick, at its start:
    the input sample into ``I_held``), then ``substeps`` steps of ``method`` (one of
    ``neurons.METHODS``) at ``dt_sub`` (a namespace constant), each followed by ``step``
    (``fused_reset(...)``: threshold, what the run records, reset). ``held``: variables
    the tick assigns and the steps only read (the sweep's ``I_held``), kept in a temporary
    (a register) instead of the group's array: one array fewer read and written per tick.

    The group's clock ticks once per ``substeps`` model steps, and each tick advances every
    neuron through them all while its state sits in registers: the per-step cost of Brian2's
    scheduler (a clock query, the code object's call) and the reads and writes of the
    group's arrays are paid once per tick. Substep j is the same code at time
    ``t + j*dt_sub``, with ``substep`` standing for j (the model step of substep j is
    ``t_in_timesteps*substeps + substep``), so the numbers are those of ``method`` stepped
    at ``dt_sub`` with the input held over each tick, as the coder holds its samples. (rk4's
    last stage looks at ``t + dt``: at a sample's last step the runtime engines read the
    next sample there; the sweep's input holds the current one, docs/reference.md gives the
    difference; the event engine's equations read the next one, ``events.HELD_INPUT``.)
    """

    def __init__(self, method: str, substeps: int = 1, tick: str = f"I_held = {SQUARE_INPUT}",
                 step: str = FUSED_RESET, held=()):
        self.method = method
        self.substeps = substeps
        self.tick = tick
        self.step = step
        self.held = tuple(held)

    def __repr__(self):  # names the compiled code in a project's structure key
        code = hashlib.sha1(f"{self.tick}\n{self.step}\n{self.held}".encode()).hexdigest()[:8]
        return f"FusedUpdater({self.method!r}, {self.substeps}, code {code})"

    def __call__(self, equations, variables=None, method_options=None) -> str:
        from brian2.stateupdaters.base import StateUpdateMethod

        one = StateUpdateMethod.apply_stateupdater(
            equations, variables, neurons.brian_method(self.method))
        one = re.sub(r"\bdt\b", "dt_sub", f"{one}\n{self.step}")
        steps = [self.tick] if self.tick else []
        for j in range(self.substeps):  # temporaries renamed per substep: each assigned once
            step = re.sub(r"\bt\b", f"(t + {j}*dt_sub)" if j else "t", one)
            step = re.sub(r"\bsubstep\b", str(j), step)
            steps.append(re.sub(r"\b(_\w+)", rf"\1_s{j}", step))
        code = "\n".join(steps)
        for name in self.held:   # a temporary: Brian2 leaves the group's array alone
            code = re.sub(rf"\b{name}\b", f"tick_{name}", code)
        return code

    def can_integrate(self, equations, variables, method_options=None):
        return True


def tick_substeps(sample_ms: float, dt_ms: float, run_ms: float, at_most: int | None = None,
                  boundaries=()) -> int:
    """Model steps per clock tick of a fused group (``FusedUpdater``): the largest number,
    at most ``at_most``, that divides one input sample's steps, the run's steps and every
    step index in ``boundaries`` (where a tick must start), so the input holds over each
    tick; 1 when a sample does not last a whole number of steps."""
    for name, value in (("sample_ms", sample_ms), ("dt_ms", dt_ms), ("run_ms", run_ms)):
        bounds.number(name, value, 0.0, bounds.MAX_SECONDS * 1e3, lo_open=True, unit=" ms")
    per_sample, steps = sample_ms / dt_ms, run_ms / dt_ms
    whole = [round(x) for x in (per_sample, steps)]
    if any(w < 1 or abs(x - w) > 1e-6 * max(1.0, x) for x, w in zip((per_sample, steps), whole)):
        return 1
    common = math.gcd(*whole, *(int(b) for b in boundaries))
    cap = common if at_most is None else min(common, at_most)
    return max(s for s in range(1, cap + 1) if common % s == 0)


def substeps(sweep) -> int:
    """Model steps per clock tick of the sweep's compiled group: one input sample's, when a
    sample lasts a whole number of steps and the run a whole number of samples (the common
    case: 1 kHz input at dt 0.1 ms gives 10)."""
    return tick_substeps(1000.0 / sweep.input_rate_hz, sweep.dt_ms, sweep.duration_s * 1000.0)


# Brian2 allocates a project's arrays with new[], which glibc aligns to 16 bytes (an mmap'd
# block plus its header), so every 64-byte vector load of a vectorised loop spans two cache
# lines. This file, compiled into every project, replaces new[] (a replaceable allocation
# function of C++) by one aligned to the cache line; delete[] frees it as before (free).
# Measured on the sweep's 4-lane loop at 10^5 points, float64: 0.64 s -> 0.33 s per run.
ALIGNED_ARRAYS = "aligned_arrays.cpp"
ALIGNED_ARRAYS_SOURCE = """\
// snn_antenna: Brian2's arrays aligned to the cache line (engine/standalone.py)
#include <cstdlib>
#include <new>

void* operator new[](std::size_t size) {
    void* block = nullptr;
    if (posix_memalign(&block, 64, size ? size : 1) != 0) throw std::bad_alloc();
    return block;
}
"""


def project(structure: tuple, build) -> dict:
    """This process's compiled cpp_standalone project for ``structure`` (anything with a
    repr that names what the compiled code depends on: sizes, dt, method, duration).

    ``build()`` creates the Brian2 objects and runs the network once (nothing runs: the
    device defers it) and returns them as a dict; the project is then compiled into a
    directory this process holds alone. Brian2's device is process-global, so a process
    keeps ONE project: asking for another structure replaces it (the old directory stays on
    disk, so coming back regenerates code but recompiles nothing that did not change).
    ``NeuronSweep`` and ``EventSweep`` share this slot.
    """
    from brian2 import prefs
    from brian2.devices.device import get_device, reset_device, set_device

    # The compiler's flags make the binary as much as the structure does (another -march, the
    # float32 flags): a project built with other flags is another project, in this process and
    # on disk. So does the Python environment: Brian2 writes its include folder into the
    # project's makefile, on which every object file depends, so two environments sharing
    # one folder would each recompile the whole project after the other had built it.
    built_marker = BUILT_MARKER.format(structure_key(structure))
    structure = (structure, tuple(prefs.codegen.cpp.extra_compile_args_gcc), sys.prefix)
    if _PROJECT.get("structure") == structure and _still_built():
        return _PROJECT
    key = hashlib.sha1(repr(structure).encode()).hexdigest()[:12]
    directory, lock = _standalone_dir(key)
    if _PROJECT:
        _PROJECT["device"].reinit()
        os.close(_PROJECT["lock"])
        _PROJECT.clear()
    bounded_make()
    set_device("cpp_standalone", build_on_run=False, directory=str(directory),
               with_output=False)
    device = get_device()
    try:
        objects = build()
        directory.mkdir(exist_ok=True)
        source = directory / ALIGNED_ARRAYS
        if not source.is_file() or source.read_text() != ALIGNED_ARRAYS_SOURCE:
            atomic_write(source, ALIGNED_ARRAYS_SOURCE)   # unchanged: make keeps its object
        device.build(run=False, directory=str(directory), with_output=False,
                     additional_source_files=[ALIGNED_ARRAYS])
        marker = directory / built_marker
        if not marker.is_file():
            atomic_write(marker, repr(structure) + "\n")
    except BaseException:
        device.reinit()
        os.close(lock)
        raise
    finally:
        reset_device()  # runtime code elsewhere in this process keeps working
    _PROJECT.update(objects, structure=structure, device=device, lock=lock,
                    directory=str(directory))
    return _PROJECT


# A built project's directory holds this file (named by ``structure_key``), so an estimate
# can tell a compiled structure from a new one without Brian2 (``is_built``).
BUILT_MARKER = "built-{}"


def structure_key(structure: tuple) -> str:
    """A project structure's name on disk, without the compiler's flags (which Brian2's
    preferences hold: an estimate does not import Brian2), with the Python environment that
    builds it (a project built by another environment is rebuilt by this one)."""
    return hashlib.sha1(repr((structure, sys.prefix)).encode()).hexdigest()[:12]


def is_built(structure: tuple) -> bool:
    """Whether a project of ``structure`` is compiled on disk: a directory whose build
    finished (``project`` leaves ``BUILT_MARKER`` there) and whose binary is still there.
    A process that asks for it regenerates the code and recompiles nothing."""
    base = cache_root() / "brian2_standalone"
    marker = BUILT_MARKER.format(structure_key(structure))
    return any((found.parent / "main").is_file() for found in base.glob(f"*/{marker}"))


def _still_built() -> bool:
    """Whether the device still holds this process's project: Brian2 has one cpp_standalone
    device per process, and another user of it (``engine.devices.run_standalone``) builds
    elsewhere and re-initialises it."""
    return _PROJECT["device"].project_dir == _PROJECT["directory"]


def run_project(project: dict, run_args: dict) -> None:
    """One run of the compiled ``project`` with ``run_args`` (Brian2 ``device.run``): new
    values of group variables (``group.name``) and TimedArrays, no recompiling.

    Each array goes to the binary as its own file, in a temporary folder of this run (in
    memory where the machine has ``/dev/shm``), and Brian2 is handed the ``name=file``
    strings (its run arguments' documented list form). Given the arrays themselves, Brian2
    names each file in the project's folder by an md5 digest of its bytes (so that runs
    sharing a project never overwrite each other's values): hashing a chunk's inputs took
    about as long as writing them, and writing them to disk several times longer than to
    memory."""
    shm = "/dev/shm" if os.path.isdir("/dev/shm") else None
    with tempfile.TemporaryDirectory(prefix="snn_antenna_run_", dir=shm) as folder:
        project["device"].run(run_args=_run_strings(run_args, Path(folder)),
                              with_output=False)


def _run_strings(run_args: dict, folder: Path) -> list[str]:
    """Brian2's ``name=value`` run arguments for ``run_args``: a single value as itself, an
    array as a file written in ``folder``, each checked against the project's variable (the
    binary reads a file of another size as nothing, silently)."""
    from brian2 import TimedArray
    from brian2.units.fundamentalunits import fail_for_dimension_mismatch

    strings = []
    for key, value in run_args.items():
        if isinstance(key, TimedArray):
            name, dtype, shape = f"{key.name}.values", key.values.dtype, key.values.shape
        else:
            name, dtype, shape = f"{key.group_name}.{key.name}", key.dtype, key.shape
        fail_for_dimension_mismatch(key.dim, value)
        value = np.asarray(value, dtype=dtype)
        if value.size == 1:
            strings.append(f"{name}={value.item()!r}")
            continue
        if value.shape != tuple(shape) and not (value.ndim == 1 and value.size == shape[0]):
            raise TypeError(f"run argument {name}: shape {value.shape}, the project's is "
                            f"{tuple(shape)}")
        path = folder / f"{name}.dat"
        value.tofile(path)
        strings.append(f"{name}={path}")
    return strings


# Grid points per element of the sweep's compiled group. With one point per element, the
# loop over elements is one dependency chain per vector of points (a tick's substeps, each a
# few multiply-adds that wait on the last), and the core waits on those latencies; lanes
# give each iteration independent chains to interleave. Measured at 10^5 points (float64,
# AVX-512, loop written as Brian2 writes it): 0.38 / 0.32 / 0.28 / 0.27 / 0.37 ns per
# neuron-step with 1 / 2 / 3 / 4 / 8 lanes (8 run out of registers); float32 0.21 -> 0.13
# with 4. docs/reference.md has the table.
LANES = 4


def lane_model(one: str, shared=()) -> tuple[str, set]:
    """A model's equations ``one`` (written for one point) with ``LANES`` points per element:
    each name once per lane (``in_lanes``), except ``shared`` (declared in ``one``: one value
    for every point, kept once as a shared constant). Returns the equations and the names
    that have lanes."""
    from brian2 import Equations

    laned = "\n".join(line for line in one.splitlines()
                      if line.split(":")[0].strip() not in shared)
    names = set(Equations(one).names) - set(shared)
    return "\n".join([in_lanes(laned, names),
                      *(f"{name} : 1 (shared, constant)" for name in sorted(shared))]), names


def lane_points(values: np.ndarray, elements: int) -> np.ndarray:
    """Per-point ``values`` as (LANES, elements): point i in lane i // elements, element
    i % elements; a short last lane padded with the first point."""
    values = np.asarray(values)
    pad = elements * LANES - len(values)
    return np.r_[values, np.repeat(values[:1], pad)].reshape(LANES, elements)


def point_values(group, name: str, n: int) -> np.ndarray:
    """A laned variable ``name`` of ``group``, point by point (the first ``n``)."""
    return np.concatenate([np.asarray(getattr(group, f"{name}_{lane}")[:])
                           for lane in range(LANES)])[:n]


def in_lanes(text: str, names, lanes: int = LANES) -> str:
    """``text`` (equations or statements) once per lane, lane after lane, with each of
    ``names`` suffixed by its lane: ``v`` -> ``v_0``, ``dv/dt`` -> ``dv_0/dt``."""
    alternatives = "|".join(sorted(map(re.escape, names), key=len, reverse=True))
    derivative = re.compile(rf"\bd({alternatives})/dt\b")
    name = re.compile(rf"\b({alternatives})\b")
    return "\n".join(name.sub(rf"\1_{j}", derivative.sub(rf"d\1_{j}/dt", text))
                     for j in range(lanes))


# The sweep's parameters per point (model name: the sweep's name).
POINT_PARAMETERS = {"k": "k", "a": "a", "b": "b", "c": "c", "d": "d", "f_in": "input_hz",
                    "I_amp": "I"}


def sweep_structure(sweep, elements: int) -> tuple:
    """What the sweep's compiled project of ``elements`` elements depends on (an estimate
    asks ``is_built`` about it)."""
    shared = tuple(name for name, swept in POINT_PARAMETERS.items() if swept in sweep.shared)
    return (neurons.PRESETS[sweep.preset].quadratic, sweep.method, sweep.dtype, sweep.dt_ms,
            substeps(sweep), sweep.duration_s, sweep.settle_s, sweep.input_rate_hz, LANES,
            shared, elements)


def sweep_elements(sweep, points: int) -> int:
    """Elements of the compiled group a chunk of ``points`` runs in."""
    return -(-max(points, sweep.group_size or points) // LANES)


def _standalone_project(sweep, elements: int):
    """The compiled group of ``elements`` elements of ``LANES`` points each. Parameters the
    grid does not sweep (``sweep.shared``) are one shared value, not an array per lane: the
    loop over elements then streams only what varies (measured at 10^5 points, float64: a,
    b, c, d shared, 0.31 -> 0.25 s per run)."""
    import brian2 as b2

    steps = substeps(sweep)
    shared = tuple(name for name, swept in POINT_PARAMETERS.items() if swept in sweep.shared)
    structure = sweep_structure(sweep, elements)

    def build():
        model, names = lane_model(neurons.equations(sweep.preset, "I_held",
                                                    SQUARE_INPUT_VARIABLES)
                                  .replace("v**2", "square(v)"), shared)
        group = b2.NeuronGroup(
            elements, model,
            method=FusedUpdater(sweep.method, steps, in_lanes(f"I_held = {SQUARE_INPUT}", names),
                                in_lanes(FUSED_RESET, names),
                                held=[f"I_held_{lane}" for lane in range(LANES)]),
            dt=steps * sweep.dt_ms * b2.ms, name="neurons",
            namespace={"input_rate": sweep.input_rate_hz * b2.Hz,
                       "input_rate_value": float(sweep.input_rate_hz),
                       "settle": sweep.settle_s * b2.second, "dt_sub": sweep.dt_ms * b2.ms,
                       **_functions()})
        b2.Network(group).run(sweep.duration_s * b2.second, namespace={})
        return {"group": group, "shared": shared}

    with float_precision(sweep.dtype), vectorising_flags(sweep.dtype):
        return project(structure, build)


# The state update reads its arrays through pointers gcc cannot prove distinct (Brian2's
# __restrict on local copies of global pointers does not count), so it checks each pair for
# overlap at run time, but by default only up to 10 checks, above which it leaves the loop
# scalar. The sweep's four lanes read 44 arrays and write 16: gcc needs between 512 and
# 1024 checks (measured with -fopt-info-vec), done once per tick, not per neuron.
VECTORISING_FLAGS = ["--param=vect-max-version-for-alias-checks=1024"]
# In float32, Brian2 still writes constants as double literals (0.04, 140.0), and C++ then
# computes every expression that holds one in double, converting each float to double and
# back. This flag makes the literals float, so the loop stays float32 (8 lanes, not 4).
FLOAT32_FLAGS = ["-fsingle-precision-constant"]


@contextmanager
def vectorising_flags(dtype: str):
    """Brian2's compiler flags for projects built inside: its defaults (``-O3 -ffast-math
    -march=native``, ...) plus ``VECTORISING_FLAGS`` (and ``FLOAT32_FLAGS`` for float32),
    restored afterwards."""
    from brian2 import prefs

    before = list(prefs.codegen.cpp.extra_compile_args_gcc)
    prefs.codegen.cpp.extra_compile_args_gcc = before + VECTORISING_FLAGS + (
        FLOAT32_FLAGS if dtype == "float32" else [])
    try:
        yield
    finally:
        prefs.codegen.cpp.extra_compile_args_gcc = before


def standalone_counts(sweep, p: dict[str, np.ndarray]) -> np.ndarray:
    """Spike counts of ``sweep`` (a ``NeuronSweep``) at parameters ``p``: one run of the
    compiled project, padded to its group size."""
    n = len(p["k"])
    for name in sweep.shared:
        if not np.all(p[name] == p[name][0]):
            raise ValueError(f"{name} is declared shared (one value for every point) but "
                             f"varies: {np.unique(p[name])[:5]}")
    elements = sweep_elements(sweep, n)
    group = _standalone_project(sweep, elements)["group"]
    v0, u0 = sweep.initial_state(p)
    # a short last chunk repeats its first point instead of recompiling (lane_points)
    values = {**{name: p[swept] for name, swept in POINT_PARAMETERS.items()}, "v": v0, "u": u0}
    run_args = {}
    for name, arr in values.items():
        if name in _PROJECT["shared"]:
            run_args[getattr(group, name)] = arr[0]
            continue
        for lane, column in enumerate(lane_points(arr, elements)):
            run_args[getattr(group, f"{name}_{lane}")] = column
    with warnings.catch_warnings():
        # Brian2's after-run check compares float32 arrays with 1e50, which float32 cannot
        # hold: numpy warns of the cast, not of any value (ours are checked below)
        warnings.filterwarnings("ignore", "overflow encountered in cast", RuntimeWarning)
        run_project(_PROJECT, run_args)

    v, u = point_values(group, "v", n), point_values(group, "u", n)
    ok = np.isfinite(v) & np.isfinite(u) & (np.abs(v) < neurons.RUNAWAY_LIMIT) \
        & (np.abs(u) < neurons.RUNAWAY_LIMIT)
    if not ok.all():
        i = int(np.argmin(ok))
        raise NumericalInstabilityError(
            neuron=i, params={k: float(values[k][i]) for k in ("k", "a", "b", "c", "d")},
            dt_ms=sweep.dt_ms, method=sweep.method, t_ms=sweep.duration_s * 1000,
            safe_dt_ms=neurons.max_stable_dt_ms(values["k"][i], sweep.method))
    return np.rint(point_values(group, "spike_count", n)).astype(np.int64)
