"""Izhikevich neurons with a time-scale factor k, in Brian2.

The equations are the documentation (time in ms, v and u dimensionless as in Izhikevich 2003):

    dv/dt = k (0.04 v² + 5 v + 140 − u + I)
    du/dt = a k (b v − u)
    if v ≥ 30:  v ← c,  u ← u + d

k scales time, so a neuron with time scale k responds to an input of frequency f exactly as the
k = 1 neuron responds to f / k: its preferred frequency is proportional to k. That is what
``k_for_frequency`` uses.

Presets (parameters from the paper, Patanè et al. 2012, and Izhikevich 2003):

- ``resonator``: a = 0.1, b = 0.26, c = −60, d = −1 with 0.04 v² + 5 v + 140.
- ``class1``: a = 0.02, b = −0.1, c = −55, d = 6 with 0.04 v² + 5 v + 140, as the paper writes
  it for all its neurons (the default).
- ``class1_izhikevich``: the same a, b, c, d with 0.04 v² + 4.1 v + 108, as Izhikevich's own
  code pairs them (a class-I neuron with a lower rheobase).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..core import bounds
from ..core.errors import NumericalInstabilityError, SpecError, check, is_integer, is_number
from ..core.signals import validate_samples


@dataclass(frozen=True)
class Preset:
    a: float
    b: float
    c: float
    d: float
    quadratic: tuple[float, float, float] = (0.04, 5.0, 140.0)  # p2 v² + p1 v + p0
    description: str = ""

    def __post_init__(self):
        bounds.declared(self)

    def params(self) -> dict:
        return {"a": self.a, "b": self.b, "c": self.c, "d": self.d}


PRESETS: dict[str, Preset] = {
    "resonator": Preset(0.1, 0.26, -60.0, -1.0, description="resonate-and-fire (paper, Fig. 8)"),
    "class1": Preset(0.02, -0.1, -55.0, 6.0, description="class I, paper's 5v + 140 (default)"),
    "class1_izhikevich": Preset(0.02, -0.1, -55.0, 6.0, quadratic=(0.04, 4.1, 108.0),
                                description="class I, Izhikevich's 4.1v + 108"),
}

V_PEAK = 30.0  # spike cut-off, the model's threshold
# Every Brian2 group of Izhikevich neurons spikes and resets by these two (``reset`` adds
# what a group also does on a spike, e.g. count it).
THRESHOLD = f"v >= {V_PEAK}"


def reset(*also: str) -> str:
    """The model's reset (v → c, u → u + d), then ``also`` (Brian2 statements) in order."""
    return "; ".join(("v = c", "u = u + d") + also)


@dataclass(frozen=True)
class Class1Rows:
    """One role's rows in a group of class-I units (``class1_units``): ``n`` neurons driven by
    ``bias`` + an exponential synaptic current ``I_syn`` (time constant ``tau_syn_ms``)
    + ``input_terms``, at rest for the drive ``rest_current`` when a run starts.

    ``input_terms`` are added to every row's input, so they must vanish on other roles' rows
    (a term weighted by a parameter this role sets in ``values`` does: parameters start at 0);
    ``equations`` declares what they and ``on_spike`` (statements at every spike of any row)
    refer to; ``values`` sets this role's parameters on its own rows."""
    n: int
    bias: object
    tau_syn_ms: float
    rest_current: float = 0.0
    input_terms: str = ""
    equations: str = ""
    on_spike: tuple = ()
    namespace: dict = field(default_factory=dict)
    values: dict = field(default_factory=dict)


def class1_units(rows: dict, clock, name: str):
    """One Brian2 group of class-I neurons holding every role of ``rows`` (name →
    :class:`Class1Rows`), and a Subgroup per role, named by it. Brian2's runtime loop calls
    a group's state updater, thresholder and resetter at every step, whatever its size: the
    class-I units of a composed network (the speed gate's, the control layer's) in one group
    cost one group's calls. Every unit counts its spikes (``spike_count``)."""
    import brian2 as b2

    lines, statements, namespace = [], ["spike_count += 1"], {}
    for role in rows.values():
        lines += [line.strip() for line in role.equations.splitlines()
                  if line.strip() and line.strip() not in lines]
        statements += [s for s in role.on_spike if s not in statements]
        for key, value in role.namespace.items():
            if key in namespace and namespace[key] is not value and namespace[key] != value:
                raise ValueError(f"class-I roles disagree on {key!r}: {namespace[key]!r} "
                                 f"and {value!r}")
            namespace[key] = value
    inputs = "".join(role.input_terms for role in rows.values())
    eqs = equations("class1", "bias + I_syn" + inputs,
                    "dI_syn/dt = -I_syn / tau_syn : 1\ntau_syn : second (constant)\n"
                    "bias : 1 (constant)\nspike_count : integer\n" + "\n".join(lines))
    class1 = PRESETS["class1"]
    group = b2.NeuronGroup(sum(role.n for role in rows.values()), eqs, threshold=THRESHOLD,
                           reset=reset(*statements), method="euler", namespace=namespace,
                           clock=clock, name=name)
    group.k, group.a, group.b, group.c, group.d = 1.0, class1.a, class1.b, class1.c, class1.d
    subgroups, start = {}, 0
    for role_name, role in rows.items():
        sub = b2.Subgroup(group, start, start + role.n, name=role_name)
        sub.bias = role.bias
        sub.tau_syn = role.tau_syn_ms * b2.ms
        sub.v, sub.u = resting_state("class1", current=role.rest_current)
        for variable, value in role.values.items():
            setattr(sub, variable, value)
        subgroups[role_name] = sub
        start += role.n
    return group, subgroups

# Integration methods whose results this project has measured (studies/speed_accuracy.toml):
# Brian2's own, and "izhikevich", the update order of Izhikevich's published code (v in two
# half steps, then u from the new v), a Brian2 state updater defined below.
METHODS = ("euler", "rk2", "rk4", "izhikevich")

# Largest k·dt (model milliseconds per step) at which each method stays finite for every
# constant drive I in [-50, 50], started from the reset point: the stability map of
# studies/speed_accuracy.toml (``snn_antenna.evaluation.accuracy.stability_map``, 25 log-spaced
# k·dt from
# 0.01 to 50; the next grid point, 1.43x larger, went non-finite for some drive). Measured
# on the resonator; tests/test_stability.py re-checks both sides of each limit. Specs beyond
# it are refused unless forced. Finite is not accurate: see the study's map for that.
MAX_STABLE_K_DT = {"euler": 8.4, "rk2": 5.9, "rk4": 0.49, "izhikevich": 1.4}


def brian_method(method: str):
    """What to pass as a NeuronGroup's ``method`` for one of ``METHODS``."""
    check(method in METHODS, "method", method, f"one of {list(METHODS)}")
    return izhikevich_order if method == "izhikevich" else method


def izhikevich_order(equations, variables=None, method_options=None) -> str:
    """Brian2 state updater in the order of Izhikevich's own code (Izhikevich 2003).

    His MATLAB loop advances v in two Euler half steps "for numerical stability", then u by
    one Euler step from the new v, with I held over the step. Brian2's ``euler`` updates v
    and u together from the old values; at coarse dt the two differ.
    """
    from brian2.stateupdaters.base import UnsupportedEquationsException

    f = {var: str(expr) for var, expr in equations.get_substituted_expressions(variables)}
    if set(f) != {"v", "u"}:
        raise UnsupportedEquationsException("the Izhikevich order needs exactly dv/dt and du/dt")
    return (f"v = v + 0.5*dt*({f['v']})\n"
            f"v = v + 0.5*dt*({f['v']})\n"
            f"u = u + dt*({f['u']})")


# Preferred frequency of the k = 1 resonator. Linearising at rest gives a damped oscillation
# at 24.5 Hz (τ ≈ 19 ms). Driven by the coder's ±0.15 square wave the neuron fires once per
# cycle for 19–24.5 Hz (16–26 Hz at all); the rate-weighted geometric centroid of that tuning
# curve is 20.6 Hz (20.5 at dt 0.05 ms; 20.7 in studies/tuning_sweep.toml's finer grid; the
# paper's 7 Hz neuron with k = 0.3425 gives 20.4). tests/test_neurons.py re-measures it. The
# array uses the driven value: spike rates, not small oscillations, are what the read-out sees.
LINEAR_HZ_PER_K = 24.52
DRIVEN_HZ_PER_K = 20.6


def equations(preset: str | Preset = "resonator", input_expr: str = "I_ext",
              extra: str = "I_ext : 1") -> str:
    """Brian2 equations of an Izhikevich neuron.

    ``I = input_expr`` is the input current (e.g. ``drive(t)`` from a TimedArray, or a
    parameter ``I_ext`` written from outside); ``extra`` declares what it refers to.
    """
    p = PRESETS[preset] if isinstance(preset, str) else preset
    p2, p1, p0 = p.quadratic
    return f"""
    dv/dt = k * ({p2!r}*v**2 + {p1!r}*v + {p0!r} - u + I) / ms : 1
    du/dt = a * k * (b*v - u) / ms : 1
    I = {input_expr} : 1
    {extra}
    k : 1 (constant)
    a : 1 (constant)
    b : 1 (constant)
    c : 1 (constant)
    d : 1 (constant)
    """


def resting_state(preset: str | Preset = "resonator", b: float | None = None,
                  current: float = 0.0) -> tuple[float, float]:
    """The stable fixed point (v, u) for constant input ``current``; ``b`` and ``current``
    may be arrays of one shape (a population's), giving arrays.

    Where there is none (the neuron fires tonically), the reset point (c, b·c) is returned,
    so a run starts where the neuron would be right after a spike.
    """
    p = PRESETS[preset] if isinstance(preset, str) else preset
    b = np.asarray(p.b if b is None else b, dtype=float)
    p2, p1, p0 = p.quadratic
    disc = (p1 - b) ** 2 - 4 * p2 * (p0 + np.asarray(current, dtype=float))
    # the lower root is the stable one
    v = np.where(disc < 0, p.c, (-(p1 - b) - np.sqrt(np.maximum(disc, 0.0))) / (2 * p2))
    if v.ndim == 0:
        return float(v), float(b * v)
    return v, b * v


def raise_on_ctrl_c() -> None:
    """Make Ctrl-C raise ``KeyboardInterrupt`` inside a Brian2 run too. By default Brian2
    answers it by ending the current ``run`` early and returning, as if it had finished: a
    study that runs many short runs (the closed loop, a sweep's chunks) would go on with
    truncated results and write a report from them."""
    import brian2 as b2

    b2.prefs.core.stop_on_keyboard_interrupt = False


def k_for_frequency(freq_hz, hz_per_k: float = DRIVEN_HZ_PER_K):
    """The time-scale factor k whose resonator prefers ``freq_hz``.

    Exact by the model's time-scale invariance, given the k = 1 neuron's preferred frequency
    (``DRIVEN_HZ_PER_K`` by default; pass ``LINEAR_HZ_PER_K`` for the small-signal value).
    The paper's 7 Hz neuron has k = 0.3425, i.e. 20.4 Hz per unit k.
    """
    f = np.asarray(freq_hz, dtype=float)
    if not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise SpecError("freq_hz", freq_hz, "finite frequencies > 0 Hz")
    k = f / hz_per_k
    return float(k) if k.ndim == 0 else k


def max_stable_dt_ms(k, method: str = "euler") -> float:
    """Largest dt (ms) the stability limits allow for time scales ``k``."""
    check(isinstance(method, str) and method in MAX_STABLE_K_DT, "method", method,
          f"one of {sorted(MAX_STABLE_K_DT)}")
    raw = np.asarray(k) if not isinstance(k, str) else np.asarray([])
    ok = raw.size >= 1 and raw.dtype.kind in "iuf"
    values = raw.astype(float) if ok else raw
    check(ok and bool(np.all(np.isfinite(values) & (values >= bounds.MIN_NORMAL)
                             & (values <= bounds.MAX_MAGNITUDE))), "k", k,
          f"a time-scale factor in [{bounds.MIN_NORMAL:.3g}, {bounds.MAX_MAGNITUDE:g}], or one "
          "per neuron (not empty)")
    return MAX_STABLE_K_DT[method] / float(np.max(values))


@dataclass
class SimulationResult:
    """Spikes (and optionally traces) of a group of neurons.

    ``spike_i`` / ``spike_t_ms`` list every spike (neuron index, time); ``traces`` maps
    ``"v"`` and ``"u"`` to arrays of shape (n_records, n_neurons) at ``trace_dt_ms``.
    """
    n_neurons: int
    duration_ms: float
    dt_ms: float
    spike_i: np.ndarray
    spike_t_ms: np.ndarray
    params: dict
    traces: dict = field(default_factory=dict)
    trace_dt_ms: float | None = None

    @property
    def spike_counts(self) -> np.ndarray:
        return np.bincount(self.spike_i, minlength=self.n_neurons)

    def spike_times_ms(self, neuron: int) -> np.ndarray:
        return self.spike_t_ms[self.spike_i == neuron]


def _broadcast(name: str, value, n: int) -> np.ndarray:
    raw = np.asarray(value)
    if raw.size == 0 or raw.dtype.kind not in "iuf":
        raise SpecError(name, value, "a real number or one per neuron (not empty, not "
                                     "complex, not true/false, not text)")
    arr = np.broadcast_to(raw.astype(float), (n,)) if raw.ndim == 0 else raw.astype(float)
    if arr.shape != (n,):
        raise SpecError(name, f"array of shape {np.shape(value)}",
                        f"a scalar or one value per neuron (shape ({n},))")
    if not np.all(np.isfinite(arr)):
        raise SpecError(name, value, "finite values")
    return arr


def simulate(preset: str = "resonator", current=None, dt_ms: float = 0.1, k=1.0,
             method: str = "euler", *, n_neurons: int | None = None,
             input_dt_ms: float | None = None, input_index=None, v0=None, u0=None,
             record_traces: bool | str = False, trace_dt_ms: float | None = None,
             target: str = "numpy", force: bool = False, check_every_ms: float = 10.0,
             run_ms: float | None = None, **params) -> SimulationResult:
    """Run Izhikevich neurons on an input current; the building block of k/b/I tuning.

    ``current`` is an array of samples every ``input_dt_ms`` (default ``dt_ms``): shape
    (n_steps,) drives every neuron alike; shape (n_steps, n_inputs) drives neuron i with column
    ``input_index[i]`` (default: column i), so many events or grid points run as one group.
    ``k`` and preset parameters (``a``, ``b``, ``c``, ``d``) may be scalars or one value per
    neuron. Neurons start at their resting state for the first input sample unless ``v0`` /
    ``u0`` are given. ``record_traces`` records v and u (``True``) or only the named variable.
    ``run_ms`` runs only the input's first milliseconds: the same compiled code as the whole
    run (Brian2 compiles the input's length into it), e.g. to warm up before timing.

    Returns spike times in ms (and traces on request). Raises ``NumericalInstabilityError`` as
    soon as a neuron's state becomes non-finite, and refuses before running a k·dt beyond the
    method's stable limit unless ``force=True``.
    """
    # Every argument checked before Brian2 is imported: a bad one is a SpecError naming it.
    check(isinstance(preset, str) and preset in PRESETS, "preset", preset,
          f"one of {sorted(PRESETS)}")
    check(isinstance(method, str) and method in METHODS, "method", method,
          f"one of {list(METHODS)}")
    check(isinstance(target, str) and target in ("numpy", "cython"), "target", target,
          "'numpy' or 'cython' (runtime targets; cpp_standalone is used by the sweep engine)")
    check(is_number(dt_ms) and 0 < dt_ms <= 10, "dt_ms", dt_ms, "a step in (0, 10] ms")
    check(is_number(check_every_ms) and check_every_ms > 0, "check_every_ms", check_every_ms,
          "an interval > 0 ms between instability checks")
    check(isinstance(record_traces, (bool, str)) and record_traces in (False, True, "v", "u"),
          "record_traces", record_traces, "False, True (v and u), 'v' or 'u'")
    check(trace_dt_ms is None or (is_number(trace_dt_ms) and trace_dt_ms >= dt_ms),
          "trace_dt_ms", trace_dt_ms, f"None or an interval >= dt_ms ({dt_ms} ms)")
    check(isinstance(force, bool), "force", force, "True or False")
    check(n_neurons is None or (is_integer(n_neurons) and 1 <= n_neurons <= 10_000_000),
          "n_neurons", n_neurons, "None (from the inputs) or an integer in [1, 10000000]")
    if current is None:
        raise SpecError("current", None, "an array of input samples")
    if np.iscomplexobj(current):
        raise SpecError("current", "complex values", "real input samples")
    current = np.ascontiguousarray(validate_samples(current, "current"), dtype=float)
    input_dt_ms = dt_ms if input_dt_ms is None else input_dt_ms
    check(is_number(input_dt_ms) and input_dt_ms >= dt_ms * (1 - 1e-9), "input_dt_ms",
          input_dt_ms, f"a sample interval >= dt_ms ({dt_ms} ms)")
    if current.ndim == 2 and input_index is None and current.shape[0] < current.shape[1]:
        # Time runs along axis 0. Fewer steps than inputs looks like (inputs, steps): refused
        # rather than guessed, since either reading would run.
        raise SpecError("current", f"array of shape {current.shape}",
                        "shape (n_steps, n_inputs), time along the first axis; this one has "
                        "fewer steps than inputs and looks transposed: pass current.T, or "
                        "input_index to say which column drives each neuron")
    if input_index is not None:
        index_arr = np.asarray(input_index)
        check(index_arr.ndim == 1 and index_arr.size >= 1 and index_arr.dtype.kind in "iu",
              "input_index", input_index, "one integer column index per neuron")
        check(current.ndim == 2, "input_index", "given for a 1-D current",
              "None for a 1-D current (every neuron gets the same input)")
    if np.size(k) == 0:
        raise SpecError("k", k, "a time-scale factor > 0, or one per neuron (not empty)")
    n_inputs = 1 if current.ndim == 1 else current.shape[1]
    if n_neurons is None:
        sizes = [np.size(k)] + [np.size(v) for v in params.values()]
        if input_index is not None:
            sizes.append(np.size(input_index))
        elif current.ndim == 2:
            sizes.append(n_inputs)
        n_neurons = max(sizes)
    preset_obj = PRESETS[preset]
    unknown = set(params) - set(preset_obj.params())
    if unknown:
        raise SpecError("params", sorted(unknown), "only a, b, c, d beside k")
    values = {name: _broadcast(name, params.get(name, default), n_neurons)
              for name, default in preset_obj.params().items()}
    values["k"] = _broadcast("k", k, n_neurons)
    check(np.all(values["k"] > 0), "k", k, "time-scale factors > 0")
    k_dt = float(values["k"].max()) * dt_ms
    if not force and k_dt > MAX_STABLE_K_DT[method]:
        raise SpecError("dt_ms", dt_ms,
                        f"k·dt <= {MAX_STABLE_K_DT[method]} model-ms for method {method!r} "
                        f"(k up to {values['k'].max():g}: dt <= "
                        f"{max_stable_dt_ms(values['k'], method):.4g} ms), or force=True")

    if current.ndim == 1:
        input_expr, extra = "drive(t)", ""
        index = None
    else:
        index = np.arange(n_neurons) if input_index is None else np.asarray(input_index)
        if index.shape != (n_neurons,) or index.min() < 0 or index.max() >= n_inputs:
            raise SpecError("input_index", f"array of shape {index.shape}",
                            f"one column index in [0, {n_inputs}) per neuron")
        input_expr, extra = "drive(t, input_index)", "input_index : integer (constant)"

    import brian2 as b2

    b2.start_scope()
    b2.prefs.codegen.target = target
    b2.defaultclock.dt = dt_ms * b2.ms
    drive = b2.TimedArray(current, dt=input_dt_ms * b2.ms, name="drive")
    group = b2.NeuronGroup(n_neurons, equations(preset_obj, input_expr, extra),
                           threshold=THRESHOLD, reset=reset(),
                           method=brian_method(method), namespace={"drive": drive},
                           name="neurons")
    for name, arr in values.items():
        setattr(group, name, arr)
    if index is not None:
        group.input_index = index
    first = current[0] if current.ndim == 1 else current[0][index]
    v_rest, u_rest = resting_state(preset_obj, values["b"],
                                   np.broadcast_to(first, (n_neurons,)))
    group.v = v_rest if v0 is None else _broadcast("v0", v0, n_neurons)
    group.u = u_rest if u0 is None else _broadcast("u0", u0, n_neurons)

    spikes = b2.SpikeMonitor(group, name="spikes")
    objects = [group, spikes]
    if record_traces:
        variables = ["v", "u"] if record_traces is True else [record_traces]
        mon = b2.StateMonitor(group, variables, record=True,
                              dt=(trace_dt_ms or dt_ms) * b2.ms, name="traces")
        objects.append(mon)
    guard = instability_guard(group, preset, dt_ms, method, check_every_ms)
    objects.append(guard)

    duration_ms = current.shape[0] * input_dt_ms
    if run_ms is not None:
        check(is_number(run_ms) and 0 < run_ms <= duration_ms, "run_ms", run_ms,
              f"a duration in (0, {duration_ms:g}] ms (the input's length)")
        duration_ms = float(run_ms)
    net = b2.Network(*objects)
    net.run(duration_ms * b2.ms, namespace={})
    guard.function()  # the last partial interval
    result = SimulationResult(
        n_neurons=n_neurons, duration_ms=duration_ms, dt_ms=dt_ms,
        spike_i=np.asarray(spikes.i[:], dtype=int), spike_t_ms=np.asarray(spikes.t / b2.ms),
        params={name: arr.copy() for name, arr in values.items()})
    if record_traces:
        result.traces = {v: np.asarray(getattr(mon, v)).T for v in variables}
        result.trace_dt_ms = trace_dt_ms or dt_ms
    return result


RUNAWAY_LIMIT = 1e6  # |v| or |u| beyond this is divergence, not a spike


def instability_guard(group, preset: str, dt_ms: float, method: str,
                      every_ms: float = 10.0):
    """A NetworkOperation that raises NumericalInstabilityError during the run.

    Brian2 checks for NaN only after a run, as a warning; this stops the run within
    ``every_ms`` of simulated time and names the neuron (``instability_check``).
    """
    check(is_number(every_ms) and every_ms > 0, "check_every_ms", every_ms,
          "an interval > 0 ms between instability checks")
    import brian2 as b2

    return b2.NetworkOperation(instability_check(group, preset, dt_ms, method),
                               dt=every_ms * b2.ms, name="instability_guard")


def instability_check(group, preset: str, dt_ms: float, method: str):
    """A function that raises NumericalInstabilityError, naming the neuron, its parameters and
    a safe dt, when any neuron of ``group`` is non-finite or running away; for a caller that
    already runs Python on the group's clock (the live feed). It reads the arrays behind the
    variables directly (no unit handling), so it costs microseconds per call."""
    v_arr = group.variables["v"].get_value
    u_arr = group.variables["u"].get_value

    def check_state():
        v, u = v_arr(), u_arr()
        ok = np.isfinite(v) & np.isfinite(u) & (np.abs(v) < RUNAWAY_LIMIT) \
            & (np.abs(u) < RUNAWAY_LIMIT)
        if not ok.all():
            i = int(np.argmin(ok))
            params = {name: float(group.variables[name].get_value()[i])
                      for name in ("k", "a", "b", "c", "d")}
            raise NumericalInstabilityError(
                neuron=i, params=params, dt_ms=dt_ms, method=method,
                t_ms=float(group.t_[:] * 1000) if hasattr(group, "t_") else float("nan"),
                safe_dt_ms=max_stable_dt_ms(params["k"], method) if method in MAX_STABLE_K_DT
                else None)

    return check_state


def spike_summary(spike_i: np.ndarray, spike_t_s: np.ndarray, n_neurons: int,
                  duration_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per neuron: spike count, first spike time (``duration_s`` if none), last − first."""
    counts = np.bincount(spike_i, minlength=n_neurons)
    first = np.full(n_neurons, float(duration_s))
    np.minimum.at(first, spike_i, spike_t_s)
    last = first.copy()
    np.maximum.at(last, spike_i, spike_t_s)
    return counts, first, last - first


def binned_spike_counts(spike_i: np.ndarray, spike_t_s: np.ndarray, n_neurons: int,
                        inner_edges_s) -> np.ndarray:
    """(neurons, len(inner_edges_s) + 1): spikes before the first edge, between edges, and
    at or after the last."""
    bins = np.searchsorted(np.asarray(inner_edges_s, dtype=float), spike_t_s, side="right")
    n_bins = len(inner_edges_s) + 1
    flat = np.bincount(np.asarray(spike_i) * n_bins + bins, minlength=n_neurons * n_bins)
    return flat.reshape(n_neurons, n_bins)


class _KnownWarning(logging.Filter):
    """Drops a Brian2 log record whose message holds every one of ``parts``."""

    def __init__(self, parts: tuple[str, ...]):
        super().__init__()
        self.parts = parts

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        return not all(part in message for part in self.parts)


def quiet_known_warning(logger: str, *parts: str) -> None:
    """Drop Brian2's warnings on ``logger`` whose message holds all of ``parts`` (name the
    statement or object: a warning understood for it, and only for it; once per process)."""
    target = logging.getLogger(logger)
    if not any(isinstance(f, _KnownWarning) and f.parts == parts for f in target.filters):
        target.addFilter(_KnownWarning(parts))
