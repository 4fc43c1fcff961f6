"""Coded scenes on the compiled engine: the resonator array over many codings per run.

    maps = compiled_rate_maps(array, coded, rate_hz, window_s, per_run=200)

The blind read-out (``readout.detection``) runs one copy of the array per coded column, all
copies in one NeuronGroup; on the runtime targets Brian2 builds and runs that group anew for
every batch. Here the group is a cpp_standalone project (``engine.standalone.project``),
compiled once per process and group size and re-run per batch of ``per_run`` codings with the
batch's columns, the array's tuning and each copy's resting state through ``run_args``; a
short batch is padded with copies of its first column. The model is the runtime path's (the
same equations, input ``drive(t, input_index)``, Brian2's threshold, reset and state updater,
spikes from a SpikeMonitor), so its spikes are the runtime path's up to the compiler's
rounding, and the rate maps come from them by the same rule (``detection.copy_rate_maps``).

Blow-ups: a neuron whose |v| or |u| left the finite range at any 10 ms check sets a flag of
the model (no Python during the run), and ``NumericalInstabilityError`` is raised after it.
"""
from __future__ import annotations

import numpy as np

from ..core.errors import NumericalInstabilityError, check
from ..networks import neurons
from ..networks.resonators import ResonatorArray
from ..readout.detection import copy_rate_maps
from .standalone import project, run_project, vectorising_flags

CHECK_EVERY_MS = 10.0
GUARD = (f"unstable = unstable or not (abs(v) < {neurons.RUNAWAY_LIMIT!r} and "
         f"abs(u) < {neurons.RUNAWAY_LIMIT!r})")
# The code targets a blind read-out may name: the runtime ones and this compiled engine.
COMPILED = "standalone"


def compiled_rate_maps(array: ResonatorArray, coded: np.ndarray, rate_hz: float,
                       window_s: float, per_run: int) -> list:
    """Rate maps of ``array`` driven by each column of ``coded`` (n_samples, n_codings), in
    runs of ``per_run`` codings of one compiled project (one per process, group size and
    scene length)."""
    coded = np.asarray(coded, dtype=float)
    if coded.ndim == 1:
        coded = coded[:, None]
    check(isinstance(per_run, int) and per_run >= 1, "codings_per_run", per_run,
          "an integer >= 1")
    array.check_rate(rate_hz)
    maps = []
    for start in range(0, coded.shape[1], per_run):
        maps += _one_run(array, coded[:, start:start + per_run], rate_hz, window_s, per_run)
    return maps


def structure(array: ResonatorArray, n_samples: int, rate_hz: float, per_run: int) -> tuple:
    """What the compiled project depends on; the inputs, k, b and the start are run args.
    An estimate asks ``engine.standalone.is_built`` about it."""
    return ("codings", neurons.PRESETS["resonator"].quadratic, array.n_neurons,
            float(array.dt_ms), array.method, n_samples, float(rate_hz), per_run,
            CHECK_EVERY_MS)


def _build(array: ResonatorArray, n_samples: int, rate_hz: float, per_run: int) -> dict:
    import brian2 as b2

    n = per_run * array.n_neurons
    drive = b2.TimedArray(np.zeros((n_samples, per_run)), dt=b2.second / rate_hz,
                          name="drive")
    group = b2.NeuronGroup(
        n, neurons.equations("resonator", "drive(t, input_index)",
                             "input_index : integer (constant)\nunstable : boolean"),
        threshold=neurons.THRESHOLD, reset=neurons.reset(),
        method=neurons.brian_method(array.method), namespace={"drive": drive},
        dt=array.dt_ms * b2.ms, name="codings")
    preset = neurons.PRESETS["resonator"]
    group.input_index = np.repeat(np.arange(per_run), array.n_neurons)
    group.a, group.c, group.d = preset.a, preset.c, preset.d
    group.run_regularly(GUARD, dt=CHECK_EVERY_MS * b2.ms, name="guard")
    spikes = b2.SpikeMonitor(group, name="coding_spikes")
    b2.Network(group, spikes).run(n_samples / rate_hz * b2.second, namespace={})
    return {"group": group, "drive": drive, "spikes": spikes}


def _one_run(array: ResonatorArray, coded: np.ndarray, rate_hz: float, window_s: float,
             per_run: int) -> list:
    n_samples, m = coded.shape
    with vectorising_flags("float64"):
        proj = project(structure(array, n_samples, rate_hz, per_run),
                       lambda: _build(array, n_samples, rate_hz, per_run))
    if m < per_run:   # a short batch: padded with copies of its first column
        coded = np.concatenate([coded, np.repeat(coded[:, :1], per_run - m, axis=1)], axis=1)
    # each copy at rest for its first input sample, as neurons.simulate starts
    v_rest, u_rest = neurons.resting_state("resonator", array.b, coded[0])
    group, n = proj["group"], array.n_neurons
    run_project(proj, {proj["drive"]: np.ascontiguousarray(coded),
                       group.k: np.tile(array.k, per_run),
                       group.b: np.full(per_run * n, float(array.b)),
                       group.v: np.repeat(v_rest, n), group.u: np.repeat(u_rest, n)})
    _check_stable(group, array, m * n, n_samples / rate_hz)
    spikes = proj["spikes"]
    spike_i = np.asarray(spikes.i[:], dtype=int)
    spike_t_s = np.asarray(spikes.t_[:], dtype=float)
    keep = spike_i < m * n
    return copy_rate_maps(array, spike_i[keep], spike_t_s[keep], m, n_samples / rate_hz,
                          window_s)


def _check_stable(group, array: ResonatorArray, n: int, duration_s: float) -> None:
    """``NumericalInstabilityError`` for the first of the group's ``n`` neurons whose |v|
    or |u| left the finite range during the run."""
    v, u = np.asarray(group.v_[:])[:n], np.asarray(group.u_[:])[:n]
    bad = np.asarray(group.unstable[:])[:n] | ~np.isfinite(v) | ~np.isfinite(u) \
        | (np.abs(v) >= neurons.RUNAWAY_LIMIT) | (np.abs(u) >= neurons.RUNAWAY_LIMIT)
    if bad.any():
        i = int(np.argmax(bad))
        k = float(array.k[i % array.n_neurons])
        raise NumericalInstabilityError(
            neuron=i, params={"k": k, "b": float(array.b)}, dt_ms=array.dt_ms,
            method=array.method, t_ms=1000.0 * duration_s,
            safe_dt_ms=neurons.max_stable_dt_ms(k, array.method))
