"""How far a Brian2 run is from the reference, and where each integration method stays sane.

Errors of a run against its reference (``snn_antenna.networks.reference``) on the same input:

- ``spike_time_error_ms``: mean distance from each spike to the nearest spike of the same
  neuron in the other train, both ways, capped at ``cap_ms`` (a missing or extra spike costs
  the cap). Brian2 records a spike at the start of the step in which v crossed 30, so even a
  perfect integrator shows about dt/2 here.
- ``spike_count_error``: total |Δ count| per neuron over the reference's total count.
- ``rate_map_error``: L1 distance of the rate maps over the reference's L1 norm.

``compare_array`` and ``compare_tuning`` score a whole run against its reference read-out
(``Match`` says when a read-out counts as the reference's); ``reference_shift`` measures how
far the reference itself moves when its tolerance is tightened.

``stability_map`` classifies (method, k·dt, constant drive I) as accurate, inaccurate but
finite, or non-finite. It uses the model's time-scale invariance: the discrete update
depends on k and dt only through k·dt, so one group per method at dt = 1 ms with k set to
each k·dt value covers the whole axis in one vectorised run.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..core import bounds
from ..core.errors import check
from ..networks import neurons, reference
from ..networks.resonators import rate_map

ACCURATE, INACCURATE, NON_FINITE = 0, 1, 2
CLASSES = {ACCURATE: "accurate", INACCURATE: "inaccurate but finite",
           NON_FINITE: "non-finite or runaway"}


@dataclass
class SpikeTrains:
    """Every spike of a group: neuron index and time (ms)."""
    spike_i: np.ndarray
    spike_t_ms: np.ndarray

    def counts(self, n_neurons: int) -> np.ndarray:
        return np.bincount(self.spike_i, minlength=n_neurons)


def spike_time_error_ms(spike_i, spike_t_ms, ref_i, ref_t_ms, n_neurons: int,
                        cap_ms: float = 10.0) -> float:
    """Mean nearest-spike distance (ms, both directions, capped at ``cap_ms``)."""
    spike_i, ref_i = np.asarray(spike_i), np.asarray(ref_i)
    spike_t, ref_t = np.asarray(spike_t_ms, float), np.asarray(ref_t_ms, float)
    total, count = 0.0, 0
    for j in range(n_neurons):
        a, b = np.sort(spike_t[spike_i == j]), np.sort(ref_t[ref_i == j])
        for x, y in ((a, b), (b, a)):
            if len(x) == 0:
                continue
            count += len(x)
            if len(y) == 0:
                total += cap_ms * len(x)
                continue
            pos = np.clip(np.searchsorted(y, x), 1, len(y) - 1) if len(y) > 1 else \
                np.zeros(len(x), int)
            near = np.abs(x - y[pos])
            if len(y) > 1:
                near = np.minimum(near, np.abs(x - y[pos - 1]))
            total += float(np.minimum(near, cap_ms).sum())
    return total / count if count else 0.0


def spike_count_error(counts, ref_counts) -> float:
    """Σ |count − reference count| over the reference's total (0 when both are silent)."""
    counts, ref_counts = np.asarray(counts, float), np.asarray(ref_counts, float)
    diff = float(np.abs(counts - ref_counts).sum())
    return diff / max(float(ref_counts.sum()), 1.0)


def rate_map_error(rates, ref_rates) -> float:
    """Relative L1 distance of two rate maps (same shape)."""
    r, ref = np.asarray(rates, float), np.asarray(ref_rates, float)
    check(r.shape == ref.shape, "rates", r.shape, f"the reference's shape {ref.shape}")
    norm = float(np.abs(ref).sum())
    diff = float(np.abs(r - ref).sum())
    return diff / norm if norm > 0 else (0.0 if diff == 0 else 1.0)


def window_f1(hit, ref_hit) -> float:
    """F1 of detected windows against the reference's (1 when neither detects anything)."""
    hit, ref_hit = np.asarray(hit, bool), np.asarray(ref_hit, bool)
    tp = int((hit & ref_hit).sum())
    fp, fn = int((hit & ~ref_hit).sum()), int((~hit & ref_hit).sum())
    return 1.0 if tp + fp + fn == 0 else 2 * tp / (2 * tp + fp + fn)


@dataclass
class Match:
    """When a run's read-out counts as the reference's."""
    distance_cm: float = 0.1       # decoded distances within this
    detection_f1: float = 1.0      # contact windows identical
    rate_map_error: float = 0.05   # for the "rate map within" recommendation

    def __post_init__(self):
        bounds.declared(self)
        bounds.number("distance_cm", self.distance_cm, 0.0, unit=" cm")
        bounds.number("detection_f1", self.detection_f1, 0.0, 1.0)
        bounds.number("rate_map_error", self.rate_map_error, 0.0)


@dataclass
class ArrayReadout:
    """What the quickstart read-out makes of an array run: rates, contact windows and the
    distance decoded for the scene's true contact (None without one or without a detection)."""
    rates: np.ndarray
    windows: np.ndarray
    distance_cm: float | None


def array_readout(spikes: SpikeTrains, neuron_hz, duration_s: float, window_s: float,
                  detector, true_contact=None) -> ArrayReadout:
    """Rate map, contact windows and decoded distance (the detection nearest the true
    contact's onset among those that end after it) of one array run."""
    rates = rate_map(spikes.spike_i, spikes.spike_t_ms / 1000.0, neuron_hz, duration_s,
                     window_s)
    decoded = None
    if true_contact is not None:
        after = [d for d in detector.detect(rates) if d.end_s > true_contact.t_s]
        if after:
            decoded = min(after, key=lambda d: abs(d.onset_s - true_contact.t_s)).distance_cm
    return ArrayReadout(rates.values, detector.contact_windows(rates).values, decoded)


def compare_array(run: SpikeTrains, ref: SpikeTrains, out: ArrayReadout, ref_out: ArrayReadout,
                  n_neurons: int, match: Match) -> dict:
    """Every error of an array run against its reference, and whether its read-out (decoded
    distance and contact windows) matches the reference's."""
    row = {
        "spike_time_error_ms": spike_time_error_ms(run.spike_i, run.spike_t_ms, ref.spike_i,
                                                   ref.spike_t_ms, n_neurons),
        "spike_count_error": spike_count_error(run.counts(n_neurons), ref.counts(n_neurons)),
        "rate_map_error": rate_map_error(out.rates, ref_out.rates),
        "detection_f1": window_f1(out.windows, ref_out.windows),
        "distance_cm": out.distance_cm,
    }
    d, d_ref = out.distance_cm, ref_out.distance_cm
    row["distance_error_cm"] = abs(d - d_ref) if d is not None and d_ref is not None else None
    same_distance = (d is None and d_ref is None) or (
        row["distance_error_cm"] is not None and row["distance_error_cm"] <= match.distance_cm)
    row["readout_matches"] = bool(same_distance and row["detection_f1"] >= match.detection_f1)
    return row


@dataclass
class TuningReadout:
    """Rates (neuron × stimulus frequency) and each neuron's preferred stimulus (-1: silent)."""
    rates: np.ndarray
    preferred: np.ndarray


def tuning_readout(spikes: SpikeTrains, n_neurons: int, n_freqs: int,
                   duration_s: float) -> TuningReadout:
    """Neuron j × n_freqs + f of the run is neuron j driven at stimulus frequency f."""
    counts = spikes.counts(n_neurons * n_freqs).reshape(n_neurons, n_freqs)
    preferred = np.where(counts.max(axis=1) > 0, np.argmax(counts, axis=1), -1)
    return TuningReadout(counts / duration_s, preferred)


def compare_tuning(run: SpikeTrains, ref: SpikeTrains, out: TuningReadout,
                   ref_out: TuningReadout) -> dict:
    """Errors of a tuning run; its read-out matches when every neuron prefers the same
    stimulus as in the reference."""
    return {
        "spike_time_error_ms": spike_time_error_ms(run.spike_i, run.spike_t_ms, ref.spike_i,
                                                   ref.spike_t_ms, out.rates.size),
        "spike_count_error": spike_count_error(out.rates, ref_out.rates),
        "rate_map_error": rate_map_error(out.rates, ref_out.rates),
        "detection_f1": None, "distance_error_cm": None, "distance_cm": None,
        "readout_matches": bool(np.array_equal(out.preferred, ref_out.preferred)),
    }


def reference_shift(ref: SpikeTrains, tight: SpikeTrains, n_neurons: int) -> dict:
    """How far a reference moves at a tighter tolerance: whether every neuron fires the same
    number of spikes, and the largest spike-time shift (the capped spike-time error when the
    counts differ)."""
    same_counts = np.array_equal(ref.counts(n_neurons), tight.counts(n_neurons))
    shift = 0.0
    if same_counts:
        for j in range(n_neurons):
            a = np.sort(ref.spike_t_ms[ref.spike_i == j])
            b = np.sort(tight.spike_t_ms[tight.spike_i == j])
            if len(a):
                shift = max(shift, float(np.max(np.abs(a - b))))
    else:
        shift = spike_time_error_ms(ref.spike_i, ref.spike_t_ms, tight.spike_i,
                                    tight.spike_t_ms, n_neurons)
    return {"same_spike_counts": bool(same_counts), "max_shift_ms": shift}


# -- stability map ---------------------------------------------------------------------------
def _steady_rates(spike_i, spike_t_ms, k_dt, duration_ms, n) -> np.ndarray:
    """Spike rate (per model-second) of each neuron over the second half of its run."""
    model_t = spike_t_ms * k_dt[spike_i]           # model-ms: t × k with dt = 1 ms
    half = duration_ms * k_dt / 2
    late = model_t >= half[spike_i]
    counts = np.bincount(spike_i[late], minlength=n)
    return counts / (half / 1000.0)


def run_drives(method: str, k_dt, drives, steps: int, *, preset: str = "resonator",
               b: float | None = None, target: str = "numpy"):
    """Every (k·dt, drive) pair as one neuron of ONE group, ``steps`` steps from the reset point.

    dt is 1 ms and k carries k·dt (the update depends on their product only). Returns
    ``(runaway, spike_i, spike_t_ms, k_of, drive_of)``: ``runaway[j]`` is True when neuron
    j's |v| or |u| passed ``neurons.RUNAWAY_LIMIT`` or became NaN at ANY step (latched right
    after each state update, before a reset can hide it).
    """
    import brian2 as b2

    k_dt, drives = np.asarray(k_dt, float), np.asarray(drives, float)
    check(np.all(k_dt > 0) and np.all(np.isfinite(k_dt)), "k_dt", k_dt, "values > 0")
    check(np.all(np.isfinite(drives)), "drives", drives, "finite currents")
    check(isinstance(steps, int) and steps >= 1, "steps", steps, "an integer >= 1")
    p = neurons.PRESETS[preset]
    b = p.b if b is None else b
    kk, ii = np.meshgrid(k_dt, np.arange(len(drives)), indexing="ij")
    kk, ii = kk.ravel(), ii.ravel()
    b2.start_scope()
    b2.prefs.codegen.target = target
    drive = b2.TimedArray(drives[None, :], dt=steps * b2.ms, name="drive")
    group = b2.NeuronGroup(
        kk.size, neurons.equations(p, "drive(t, input_index)",
                                   "input_index : integer (constant)\nblown : boolean"),
        threshold=neurons.THRESHOLD, reset=neurons.reset(),
        method=neurons.brian_method(method), namespace={"drive": drive},
        dt=1 * b2.ms, name="neurons")
    group.k, group.a, group.b, group.c, group.d = kk, p.a, b, p.c, p.d
    group.input_index = ii
    group.v, group.u = p.c, b * p.c
    # NaN fails every comparison, so "not (|v| < limit)" catches it too.
    limit = neurons.RUNAWAY_LIMIT
    group.run_regularly(f"blown = blown or not (abs(v) < {limit} and abs(u) < {limit})",
                        when="after_groups")
    spikes = b2.SpikeMonitor(group)
    with np.errstate(all="ignore"):
        b2.Network(group, spikes).run(steps * b2.ms, namespace={})
    return (np.asarray(group.blown[:], bool), np.asarray(spikes.i[:], int),
            np.asarray(spikes.t / b2.ms), kk, drives[ii])


def stability_map(methods=neurons.METHODS, k_dt=None, drives=None, *,
                  preset: str = "resonator", b: float | None = None,
                  model_ms: float = 400.0, rate_tolerance: float = 0.05,
                  target: str = "numpy", progress=None, compiled=None) -> xr.Dataset:
    """Classify each (method, k·dt, constant drive I) run from the reset point.

    Every neuron runs ``model_ms / min(k_dt)`` steps (so the finest k·dt covers ``model_ms``
    model milliseconds and coarser ones more). A run is non-finite when it ran away
    (``run_drives``); accurate when its steady spike rate (second half of the run) is within
    ``rate_tolerance`` (relative, plus one spike) of the reference's. Returns a Dataset with
    ``status`` (0 accurate, 1 inaccurate, 2 non-finite), ``rate_hz`` and
    ``reference_rate_hz`` over (integrator, k_dt, I), and per method the measured
    ``max_stable_k_dt`` (largest k·dt up to which no drive went non-finite) and
    ``max_accurate_k_dt`` (up to which every drive was accurate).

    ``compiled(methods, k_dt, drives, steps, preset=, b=)``: every method's ``run_drives``
    result ({method: tuple}) from one run of a compiled project of the same model
    (``engine.settings_runs.drives_runs``); None: each method runs on ``target``.
    """
    k_dt = np.geomspace(0.01, 50, 25) if k_dt is None else np.asarray(k_dt, float)
    drives = np.linspace(-50, 50, 21) if drives is None else np.asarray(drives, float)
    check(np.all(k_dt > 0) and np.all(np.isfinite(k_dt)), "k_dt", k_dt, "values > 0")
    check(np.all(np.isfinite(drives)), "drives", drives, "finite currents")
    p = neurons.PRESETS[preset]
    b = p.b if b is None else b

    # The reference rate of each drive (k = 1, exact), over the same model-time window.
    ref = reference.simulate(preset, drives[None, :], k=1.0, input_dt_ms=model_ms, b=b,
                             v0=p.c, u0=b * p.c)
    late = ref.spike_t_ms >= model_ms / 2
    ref_rate = np.bincount(ref.spike_i[late], minlength=len(drives)) / (model_ms / 2000.0)

    steps = int(np.ceil(model_ms / float(k_dt.min())))
    status = np.empty((len(methods), len(k_dt), len(drives)), dtype=np.int8)
    rates = np.empty(status.shape)
    ref_r = np.tile(ref_rate, len(k_dt))
    runs = compiled(list(methods), k_dt, drives, steps, preset=preset, b=b) if compiled \
        else {}
    for m_idx, method in enumerate(methods):
        if progress and not compiled:
            progress(f"stability map: {method} ({k_dt.size * drives.size} neurons, "
                     f"{steps} steps)")
        blown, spike_i, spike_t, kk, _ = runs[method] if compiled else run_drives(
            method, k_dt, drives, steps, preset=preset, b=b, target=target)
        r = _steady_rates(spike_i, spike_t, kk, steps, kk.size)
        one_spike = 1000.0 / (kk * steps / 2)   # one spike in the window, per second
        ok = np.abs(r - ref_r) <= rate_tolerance * ref_r + one_spike
        st = np.where(blown, NON_FINITE, np.where(ok, ACCURATE, INACCURATE))
        status[m_idx] = st.reshape(len(k_dt), len(drives))
        rates[m_idx] = np.where(blown, -1.0, r).reshape(len(k_dt), len(drives))

    ds = xr.Dataset(
        {"status": (("integrator", "k_dt", "I"), status,
                    {"meaning": "; ".join(f"{k} {v}" for k, v in CLASSES.items())}),
         "rate_hz": (("integrator", "k_dt", "I"), rates,
                     {"units": "Hz (model time)", "note": "-1 where non-finite"}),
         "reference_rate_hz": (("I",), ref_rate, {"units": "Hz (model time)"})},
        coords={"integrator": list(methods),
                "k_dt": ("k_dt", k_dt, {"units": "model ms per step"}),
                "I": ("I", drives, {"long_name": "constant drive"})},
        attrs={"preset": preset, "b": b, "model_ms": model_ms, "steps": steps,
               "rate_tolerance": rate_tolerance,
               "engine": "cpp_standalone, every method in one compiled run" if compiled
               else f"{target}, one run per method"})
    ds["max_stable_k_dt"] = ("integrator", [_largest_passing(k_dt, status[m] != NON_FINITE)
                                            for m in range(len(methods))])
    ds["max_accurate_k_dt"] = ("integrator", [_largest_accurate(k_dt, status[m])
                                              for m in range(len(methods))])
    return ds


def _largest_passing(k_dt: np.ndarray, passing: np.ndarray) -> float:
    """Largest k·dt such that it and every smaller one pass for every drive (0 if none)."""
    good = passing.all(axis=1)
    order = np.argsort(k_dt)
    best = 0.0
    for j in order:
        if not good[j]:
            break
        best = float(k_dt[j])
    return best


def _largest_accurate(k_dt: np.ndarray, status: np.ndarray) -> float:
    """Largest k·dt up to which every drive accurate at the finest step stays accurate.

    A drive that misses the reference rate even at the finest step (one near the firing
    threshold, where a 5 % rate window cannot settle) says nothing about the step size;
    requiring it too made the limit 0 for every method while the map showed accurate cells."""
    finest = status[int(np.argmin(k_dt))] == ACCURATE
    if not finest.any():
        return 0.0
    return _largest_passing(k_dt, (status == ACCURATE)[:, finest])


@dataclass
class StabilityGrid:
    """The stability map's grid: ``n_k_dt`` log-spaced k·dt × constant ``drives``, each run
    for ``model_ms`` of model time at the finest k·dt; accurate within ``rate_tolerance``."""
    k_dt_min: float = 0.01
    k_dt_max: float = 50.0
    n_k_dt: int = 25
    drives: list = field(default_factory=lambda: [
        -50, -40, -30, -20, -10, -5, -1, -0.5, -0.15, 0, 0.15, 0.5, 1, 2, 5, 10, 20, 30, 40,
        50])
    model_ms: float = 400.0
    rate_tolerance: float = 0.05

    def __post_init__(self):
        bounds.declared(self)
        low = bounds.number("k_dt_min", self.k_dt_min, 0.0, lo_open=True)
        bounds.number("k_dt_max", self.k_dt_max, low, lo_open=True)
        bounds.integer("n_k_dt", self.n_k_dt, 2, 1000)
        check(isinstance(self.drives, list) and 1 <= len(self.drives) <= 1000, "drives",
              self.drives, "a list of 1 to 1000 constant drives")
        for i, drive in enumerate(self.drives):
            bounds.amplitude(f"drives.{i}", drive)
        bounds.number("model_ms", self.model_ms, 0.0, lo_open=True, unit=" ms")
        bounds.number("rate_tolerance", self.rate_tolerance, 0.0, 1.0, lo_open=True)

    def map(self, methods, b: float | None = None, compiled=None) -> xr.Dataset:
        return stability_map(methods, np.geomspace(self.k_dt_min, self.k_dt_max, self.n_k_dt),
                             np.asarray(self.drives, float), b=b, model_ms=self.model_ms,
                             rate_tolerance=self.rate_tolerance, compiled=compiled)


def stability_limits(smap: xr.Dataset, k_max: float) -> dict:
    """Per method: the shipped largest stable k·dt beside the measured ones, and the largest
    dt the shipped limit allows for a band whose fastest neuron has ``k_max``."""
    return {m: {"shipped_max_stable_k_dt": neurons.MAX_STABLE_K_DT[m],
                "measured_max_stable_k_dt": float(smap.max_stable_k_dt.sel(integrator=m)),
                "measured_max_accurate_k_dt": float(smap.max_accurate_k_dt.sel(integrator=m)),
                "max_dt_ms_for_band": neurons.MAX_STABLE_K_DT[m] / k_max}
            for m in smap.integrator.values}


STATUS_COLOURS = ("#4caf50", "#ffc107", "#d32f2f")   # accurate, inaccurate, non-finite


def stability_figure(smap: xr.Dataset):
    """One panel per method: the status of every (constant drive, k·dt) cell."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    methods = list(smap.integrator.values)
    fig, axes = plt.subplots(1, len(methods), figsize=(3.3 * len(methods) + 0.8, 4.0),
                             sharey=True, squeeze=False, layout="constrained")
    k_dt, drives = smap.k_dt.values, smap.I.values
    for ax, m in zip(axes[0], methods):
        ax.pcolormesh(np.arange(len(drives) + 1), np.arange(len(k_dt) + 1),
                      smap.status.sel(integrator=m).values, cmap=ListedColormap(STATUS_COLOURS),
                      vmin=ACCURATE, vmax=NON_FINITE, edgecolors="white", linewidth=0.3)
        limit = float(smap.max_stable_k_dt.sel(integrator=m))
        ax.set_title(f"{m} (finite to k·dt {limit:.3g})", fontsize=9)
        _cell_ticks(ax.set_xticks, ax.set_xticklabels, drives, most=7)
        ax.set_xlabel("constant drive I")
        _cell_ticks(ax.set_yticks, ax.set_yticklabels, k_dt, most=13)
    axes[0][0].set_ylabel("k·dt (model ms per step)")
    fig.legend(handles=[Patch(color=c, label=CLASSES[status])
                        for status, c in enumerate(STATUS_COLOURS)],
               loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    return fig


def _cell_ticks(set_ticks, set_labels, values, most: int) -> None:
    """A tick at the centre of every cell, or of every few cells when there are many."""
    step = max(1, int(np.ceil(len(values) / most)))
    idx = np.arange(0, len(values), step)
    set_ticks(idx + 0.5)
    set_labels([f"{values[i]:.3g}" for i in idx], fontsize=7)
