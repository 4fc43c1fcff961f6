"""Reference solutions of the Izhikevich neurons, independent of Brian2's integrators.

The inputs this project feeds its neurons are piecewise constant (a ``TimedArray`` holds each
sample for one input interval), so between two input switches the model is an autonomous ODE.
``simulate`` integrates it with scipy's ``solve_ivp`` (DOP853, tight tolerances) from switch
to switch, locates every threshold crossing v = 30 as a root of the dense output (an
integration event) and applies the reset there exactly. No time grid is involved: spike
times are continuous, and the remaining error is the solver's tolerance, which
``tests/test_reference.py`` shows by tightening it (spike times move by < 1e-6 ms between
rtol 1e-9 and 1e-12).

It returns the same ``neurons.SimulationResult`` as ``neurons.simulate`` and takes the same
arguments, so any Brian2 run can be compared with its reference spike for spike; ``run_array``
does the same for a ``ResonatorArray`` on a coded recording. The price is speed: it runs
neuron by neuron in Python, about 10^4 times slower than Brian2 at dt = 0.1 ms.
"""
from __future__ import annotations

import time

import numpy as np

from ..core.errors import NumericalInstabilityError, SpecError, check
from ..core.signals import Recording, validate_samples
from . import neurons
from .resonators import ArrayResult

DEFAULT_RTOL = 1e-10
DEFAULT_ATOL = 1e-9


def _neuron_spikes(v0: float, u0: float, k: float, a: float, b: float, c: float, d: float,
                   quadratic: tuple[float, float, float], levels: np.ndarray,
                   switch_ms: np.ndarray, end_ms: float, rtol: float, atol: float) -> list:
    """Spike times (ms) of one neuron driven by ``levels[j]`` from ``switch_ms[j]`` on."""
    from scipy.integrate import solve_ivp

    p2, p1, p0 = quadratic
    threshold = neurons.V_PEAK
    spikes = []
    y = np.array([v0, u0], dtype=float)
    bounds = np.r_[switch_ms, end_ms]
    for j, level in enumerate(levels):
        t0, t1 = float(bounds[j]), float(bounds[j + 1])
        current = float(level)

        def rhs(_t, s, current=current):
            v, u = s
            return (k * (p2 * v * v + p1 * v + p0 - u + current), a * k * (b * v - u))

        def crossing(_t, s):
            return s[0] - threshold
        crossing.terminal = True
        crossing.direction = 1

        while t0 < t1:
            sol = solve_ivp(rhs, (t0, t1), y, method="DOP853", rtol=rtol, atol=atol,
                            events=crossing)
            if sol.status < 0 or not np.all(np.isfinite(sol.y[:, -1])):
                raise NumericalInstabilityError(
                    neuron=-1, params={"k": k, "a": a, "b": b, "c": c, "d": d}, dt_ms=0.0,
                    method="solve_ivp", t_ms=float(sol.t[-1]), safe_dt_ms=None)
            if sol.status == 1:  # threshold reached: exact reset at the crossing time
                t_spike = float(sol.t_events[0][0])
                v, u = sol.y_events[0][0]
                spikes.append(t_spike)
                y = np.array([c, u + d])
                # A reset that lands above threshold (d and drive strong enough) would fire
                # again at once; the model defines no such case, so it is refused.
                if c >= threshold:
                    raise SpecError("c", c, f"a reset value below the threshold {threshold}")
                t0 = t_spike
            else:
                y = sol.y[:, -1]
                t0 = t1
    return spikes


def simulate(preset: str = "resonator", current=None, k=1.0, *, input_dt_ms: float = 1.0,
             n_neurons: int | None = None, input_index=None, v0=None, u0=None,
             rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
             **params) -> neurons.SimulationResult:
    """The exact counterpart of ``neurons.simulate`` (same arguments, no dt or method).

    ``current`` holds one sample every ``input_dt_ms``, 1-D (all neurons) or 2-D with one
    column per input and ``input_index`` choosing each neuron's column.
    """
    check(preset in neurons.PRESETS, "preset", preset, f"one of {sorted(neurons.PRESETS)}")
    if current is None:
        raise SpecError("current", None, "an array of input samples")
    current = np.asarray(validate_samples(current, "current"), dtype=float)
    check(np.isfinite(input_dt_ms) and input_dt_ms > 0, "input_dt_ms", input_dt_ms,
          "a sample interval > 0 ms")
    check(1e-14 <= rtol <= 1e-3 and 0 < atol <= 1e-3, "rtol", rtol,
          "tolerances in [1e-14, 1e-3]")
    p = neurons.PRESETS[preset]
    unknown = set(params) - set(p.params())
    if unknown:
        raise SpecError("params", sorted(unknown), "only a, b, c, d beside k")
    columns = current[:, None] if current.ndim == 1 else current
    if n_neurons is None:
        sizes = [np.size(k)] + [np.size(v) for v in params.values()]
        sizes.append(np.size(input_index) if input_index is not None else
                     (columns.shape[1] if current.ndim == 2 else 1))
        n_neurons = max(sizes)
    values = {name: neurons._broadcast(name, params.get(name, default), n_neurons)
              for name, default in p.params().items()}
    values["k"] = neurons._broadcast("k", k, n_neurons)
    check(np.all(values["k"] > 0), "k", k, "time-scale factors > 0")
    if current.ndim == 1:
        index = np.zeros(n_neurons, dtype=int)
    else:
        index = np.arange(n_neurons) if input_index is None else np.asarray(input_index)
        if index.shape != (n_neurons,) or index.min() < 0 or index.max() >= columns.shape[1]:
            raise SpecError("input_index", f"array of shape {index.shape}",
                            f"one column index in [0, {columns.shape[1]}) per neuron")
    duration_ms = columns.shape[0] * input_dt_ms
    spike_i, spike_t = [], []
    for i in range(n_neurons):
        col = columns[:, index[i]]
        change = np.r_[0, np.flatnonzero(np.diff(col) != 0) + 1]
        rest = neurons.resting_state(p, values["b"][i], float(col[0]))
        start_v = rest[0] if v0 is None else float(np.broadcast_to(v0, (n_neurons,))[i])
        start_u = rest[1] if u0 is None else float(np.broadcast_to(u0, (n_neurons,))[i])
        times = _neuron_spikes(start_v, start_u, values["k"][i], values["a"][i],
                               values["b"][i], values["c"][i], values["d"][i], p.quadratic,
                               col[change], change * input_dt_ms, duration_ms, rtol, atol)
        spike_i.extend([i] * len(times))
        spike_t.extend(times)
    order = np.lexsort((np.asarray(spike_i), np.asarray(spike_t)))
    return neurons.SimulationResult(
        n_neurons=n_neurons, duration_ms=duration_ms, dt_ms=0.0,
        spike_i=np.asarray(spike_i, dtype=int)[order],
        spike_t_ms=np.asarray(spike_t, dtype=float)[order],
        params={name: arr.copy() for name, arr in values.items()})


def run_array(array, coded: Recording, window_s: float = 0.1, rtol: float = DEFAULT_RTOL,
              atol: float = DEFAULT_ATOL):
    """The reference of ``ResonatorArray.run``: the same ``ArrayResult`` from exact spikes."""
    samples = np.asarray(validate_samples(coded.samples, "coded.samples"), dtype=float)
    if samples.ndim != 1:
        raise SpecError("coded.samples", f"array of shape {samples.shape}", "one channel")
    array.check_rate(coded.rate_hz)
    t0 = time.perf_counter()
    # The array starts at rest for zero input (the coder's output for silence).
    v0, u0 = neurons.resting_state("resonator", array.b)
    result = simulate("resonator", samples, array.k, input_dt_ms=1000.0 / coded.rate_hz,
                      b=array.b, v0=v0, u0=u0, rtol=rtol, atol=atol)
    return ArrayResult(array.neuron_hz, result.spike_i, result.spike_t_ms / 1000.0,
                       coded.duration_s, window_s, wall_s=time.perf_counter() - t0,
                       extra={"rtol": rtol, "atol": atol})


