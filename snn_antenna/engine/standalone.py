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
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NumericalInstabilityError
from ..networks import neurons

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
        # never truncated, never through a link (a lock file holds nothing, only its flock)
        lock = os.fdopen(os.open(base / f"{key}-{slot}.lock",
                                 os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC,
                                 0o666), "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return base / f"{key}-{slot}", lock
    raise RuntimeError(f"no free Brian2 standalone directory under {base}")


# sample n of the coder's input holds from n/rate to (n+1)/rate: the square wave of
# stimuli.square. Its sign is written in floating point, h - 2*floor(h/2) for "h is odd"
# (exact for every whole h below 2**52), where an int cast and an integer modulo would keep
# the compiler from vectorising the loop over neurons.
SQUARE_INPUT = ("I_amp * (1 - 2*(floor((2*f_in)*(floor(t*input_rate + 1e-6)/input_rate_value))"
                " - 2*floor(0.5*floor((2*f_in)*(floor(t*input_rate + 1e-6)/input_rate_value)))))")
SQUARE_INPUT_VARIABLES = "f_in : 1 (constant)\nI_amp : 1 (constant)\nspike_count : integer"

# Threshold, reset and count inside the state update, branch-free: the step, the threshold
# test and the reset are one pass over the group's arrays, and selects (not a branch, not a
# list of spiking neurons) so the loop over neurons vectorises. Brian2's own threshold and
# reset are two more passes per step, the first a compaction that cannot vectorise. The
# result is the same: threshold after the step, reset in the same step, counted from settle.
FUSED_RESET = (f"_fired = 1.0*int(v >= {neurons.V_PEAK})\n"
               "v = _fired*c + (1 - _fired)*v\n"
               "u = u + _fired*d\n"
               "spike_count += _fired*int(t >= settle)")


class FusedUpdater:
    """A Brian2 state updater: ``method``'s step (one of ``neurons.METHODS``), then
    ``FUSED_RESET``."""

    def __init__(self, method: str):
        self.method = method

    def __repr__(self):  # names the compiled code in a project's structure key
        return f"FusedUpdater({self.method!r})"

    def __call__(self, equations, variables=None, method_options=None) -> str:
        from brian2.stateupdaters.base import StateUpdateMethod

        step = StateUpdateMethod.apply_stateupdater(
            equations, variables, neurons.brian_method(self.method))
        return f"{step}\n{FUSED_RESET}"

    def can_integrate(self, equations, variables, method_options=None):
        return True


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
    from brian2.devices.device import get_device, reset_device, set_device

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
        objects = build()
        device.build(run=False, directory=str(directory), with_output=False)
    except BaseException:
        device.reinit()
        lock.close()
        raise
    finally:
        reset_device()  # runtime code elsewhere in this process keeps working
    _PROJECT.update(objects, structure=structure, device=device, lock=lock)
    return _PROJECT


def run_project(project: dict, run_args: dict) -> None:
    """One run of the compiled ``project`` with ``run_args`` (Brian2 ``device.run``): new
    values of group variables and TimedArrays, no recompiling."""
    device = project["device"]
    device.run(run_args=run_args, with_output=False)
    for name in device.run_args_arrays:  # this run's value files: not needed again
        Path(device.project_dir, "static_arrays", name).unlink(missing_ok=True)


def _standalone_project(sweep, n: int):
    import brian2 as b2

    from .devices import float_precision

    structure = (neurons.PRESETS[sweep.preset].quadratic, sweep.method, sweep.dtype,
                 sweep.dt_ms, sweep.duration_s, sweep.settle_s, sweep.input_rate_hz, n)

    def build():
        group = b2.NeuronGroup(
            n, neurons.equations(sweep.preset, SQUARE_INPUT, SQUARE_INPUT_VARIABLES),
            method=FusedUpdater(sweep.method), dt=sweep.dt_ms * b2.ms, name="neurons",
            namespace={"input_rate": sweep.input_rate_hz * b2.Hz,
                       "input_rate_value": float(sweep.input_rate_hz),
                       "settle": sweep.settle_s * b2.second})
        b2.Network(group).run(sweep.duration_s * b2.second, namespace={})
        return {"group": group}

    with float_precision(sweep.dtype), vectorising_flags():
        return project(structure, build)


# The state update reads ten arrays through pointers the compiler cannot prove distinct; gcc
# then checks each pair for overlap at run time, but by default only up to 10 checks, above
# which it leaves the loop scalar. Allowing more lets the one fused loop vectorise.
VECTORISING_FLAGS = ["--param=vect-max-version-for-alias-checks=64"]


@contextmanager
def vectorising_flags():
    """Brian2's compiler flags for projects built inside: its defaults (``-O3 -ffast-math
    -march=native``, ...) plus ``VECTORISING_FLAGS`` (restored afterwards)."""
    from brian2 import prefs

    before = list(prefs.codegen.cpp.extra_compile_args_gcc)
    prefs.codegen.cpp.extra_compile_args_gcc = before + VECTORISING_FLAGS
    try:
        yield
    finally:
        prefs.codegen.cpp.extra_compile_args_gcc = before


def standalone_counts(sweep, p: dict[str, np.ndarray]) -> np.ndarray:
    """Spike counts of ``sweep`` (a ``NeuronSweep``) at parameters ``p``: one run of the
    compiled project, padded to its group size."""
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
    run_project(project, run_args)
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
