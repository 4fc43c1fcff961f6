"""Each band of the bench's spiking read-out at an integration setting inside the accurate range.

At euler, dt 0.1 ms, k·dt reaches 2 model-ms in the high band, far outside the range where
the speed/accuracy study's stability map calls a method accurate (``ACCURATE_K_DT``). So each
band (``spiking.LOW_BAND``, ``HIGH_BAND``, the baseline study's ``ROD_BAND``) gets its own
setting (``BandSetting``: method, dt, Hz per unit k, simulated window), measured against the
exact reference (``networks.reference``) on sample bench events coded by the band's chain:

- ``measure``: spike-count, rate-map and spike-time error of every (event, neuron) against
  the reference, and the cost (CPU seconds per event, ns per neuron-step) of one batch of
  events in one NeuronGroup (the runtime path of ``engine.events.run_bank``), compiled before
  it is timed;
- ``accurate_dt_ms``: the largest step (from ``DT_STEPS_MS``, each dividing the bench's 0.5 ms
  input interval) that keeps the band's largest k·dt inside a method's accurate range;
- ``driven_tuning`` / ``peak_hz_per_k`` / ``peak_offsets``: square waves as the coder makes
  them, sampled at the bench's rate, through every neuron of a band (one group); each
  neuron's peak frequency, the Hz per unit k that puts the peaks on their targets, and how
  many channels each peak lands from its target.

The settings chosen from these measurements are ``CHOSEN`` (the numbers that justify them:
``studies/speed_accuracy``'s "bands" section).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..core import bounds, calibration
from ..core.errors import NumericalInstabilityError, check, is_number
from ..networks import neurons, reference
from ..networks.resonators import ResonatorArray
from .accuracy import rate_map_error, spike_count_error, spike_time_error_ms
from ..readout.spiking import HIGH_BAND, LOW_BAND, Band, SpikingBank
from ..sources import antenna
from ..sources import bench
from ..readout.spiking import recording_attrs
from ..sources.stimuli import square
from .tuning import derive

# Largest k·dt (model ms per step) up to which every constant drive of the full stability map
# (``accuracy.StabilityGrid().map``: 25 k·dt over 0.01-50, 20 drives in [-50, 50]) kept its
# steady rate within 5 % of the reference, per method; the next grid point (1.43x) failed for
# a drive. tests/test_bands.py re-checks both sides for euler.
ACCURATE_K_DT = {"euler": 0.02034, "rk2": 0.02034, "rk4": 0.02900, "izhikevich": 0.01426}

# Steps a band may take (ms): each divides the bench's 0.5 ms input interval.
DT_STEPS_MS = (0.1, 0.05, 0.025, 0.02, 0.01, 0.005, 0.0025, 0.002, 0.001, 0.0005, 0.00025)

# The rod band of studies/baseline_comparison.toml (tests/test_bands.py keeps the two equal).
ROD_BAND = Band(n_neurons=24, band_hz=(90.0, 420.0), coder_amplitude=0.2, threshold_g=0.006,
                lowpass_hz=500.0, highpass_hz=80.0, hz_per_k=calibration.value("rod_hz_per_k"),
                dt_ms=0.005, method="rk2")
BENCH_BANDS = {"low": LOW_BAND, "high": HIGH_BAND, "rod": ROD_BAND}


@dataclass(frozen=True)
class BandSetting:
    """How a band integrates: method, step, Hz per unit k (None: the band's own) and the
    simulated window per event (None: the bank's whole ``duration_s``)."""
    method: str = "euler"
    dt_ms: float = 0.1
    hz_per_k: float | None = None
    duration_s: float | None = None

    def __post_init__(self):
        bounds.declared(self)
        check(self.method in neurons.METHODS, "method", self.method,
              f"one of {list(neurons.METHODS)}")
        check(is_number(self.dt_ms) and 0 < self.dt_ms <= 1, "dt_ms", self.dt_ms,
              "a step in (0, 1] ms")
        check(self.hz_per_k is None or (is_number(self.hz_per_k) and self.hz_per_k > 0),
              "hz_per_k", self.hz_per_k, "None (the band's own) or Hz per unit k > 0")
        check(self.duration_s is None or (is_number(self.duration_s) and self.duration_s > 0),
              "duration_s", self.duration_s, "None (the whole event) or a window > 0 s")

    def tuned(self, band: Band) -> Band:
        """``band`` with this setting's Hz per unit k."""
        return band if self.hz_per_k is None else replace(band, hz_per_k=self.hz_per_k)

    def label(self) -> str:
        text = f"{self.method} dt {self.dt_ms:g} ms"
        if self.hz_per_k is not None:
            text += f", {self.hz_per_k:.4g} Hz/k"
        return text + (f", {self.duration_s:g} s" if self.duration_s is not None else "")


# The bank's own integration, euler at 0.1 ms, with the small-signal
# Hz per unit k (measured again each run, beside the candidates).
SMALL_SIGNAL_EULER = BandSetting("euler", 0.1, neurons.LINEAR_HZ_PER_K)

# Shipped (readout.spiking.HIGH_BAND, ROD_BAND above; low at the bank's): cheapest settings within
# 5 % of the exact reference's rate map on the study's sample events, with hz_per_k from the driven
# tuning sweep; benchmarks/bench_bands.py prints their error and cost beside the alternatives.
CHOSEN = {"high": BandSetting("rk4", 0.005, calibration.value("high_band_hz_per_k")),
          "rod": BandSetting("rk2", 0.005, calibration.value("rod_hz_per_k"))}


def array_of(band: Band, setting: BandSetting = SMALL_SIGNAL_EULER,
             target: str = "numpy") -> ResonatorArray:
    """The band's resonators at ``setting`` (forced: settings beyond the stable limit are
    measured on purpose)."""
    b = setting.tuned(band)
    return ResonatorArray(b.n_neurons, tuple(b.band_hz), b.spacing, b.b, setting.dt_ms,
                          setting.method, target, b.hz_per_k, force=True)


def k_dt_range(band: Band, setting: BandSetting) -> tuple[float, float]:
    """(smallest, largest) k·dt of the band's neurons at ``setting`` (model ms per step)."""
    k = array_of(band, setting).k
    return float(k.min() * setting.dt_ms), float(k.max() * setting.dt_ms)


def accurate_dt_ms(band: Band, method: str, hz_per_k: float | None = None,
                   accurate: dict = ACCURATE_K_DT) -> float:
    """The largest step of ``DT_STEPS_MS`` keeping the band's largest k·dt within
    ``accurate[method]``."""
    k_max = float(array_of(band, BandSetting(method, 0.1, hz_per_k)).k.max())
    fits = [dt for dt in DT_STEPS_MS if k_max * dt <= accurate[method]]
    check(bool(fits), "method", method, f"a method whose accurate k·dt allows a step of at "
                                        f"least {DT_STEPS_MS[-1]:g} ms at k up to {k_max:.3g}")
    return max(fits)


def candidate_steps(band: Band, method: str, hz_per_k: float | None, coarser: int) -> list:
    """The method's accurate step on the stability map, then ``coarser`` steps of
    ``DT_STEPS_MS`` above it: the map's limit holds for every constant drive, and the band's
    own coded input may stay accurate at a coarser step, which only the run against the
    reference can tell."""
    fine = accurate_dt_ms(band, method, hz_per_k)
    above = sorted(dt for dt in DT_STEPS_MS if dt > fine)
    return [fine] + above[:coarser]


# -- sample events and runs against the reference ------------------------------------------
@dataclass
class BandEvents:
    """Sample bench events coded through one band's chain: ``coded`` is (samples, events)."""
    name: str
    band: Band
    coded: np.ndarray
    rate_hz: float

    @property
    def n_events(self) -> int:
        return self.coded.shape[1]

    @property
    def duration_s(self) -> float:
        return self.coded.shape[0] / self.rate_hz


def sample_data(materials, positions_cm, repetitions: int = 1, seed: int = 0):
    """A small bench data set (``sources.bench``, the bench study's recording settings):
    every material × position × repetition, generated here, not cached."""
    spec = bench.BenchSpec(materials=tuple(materials), positions_cm=tuple(positions_cm),
                           repetitions=repetitions, seed=seed)
    return bench.generate(spec, log=lambda *a: None)


def code_events(name: str, band: Band, data, duration_s: float = 0.5) -> BandEvents:
    """The events of a bench data set through ``band``'s chain, ``duration_s`` each, as
    ``SpikingBank.code`` makes them for the bank."""
    bank = SpikingBank(bands={name: band}, duration_s=duration_s)
    rate_hz, bits, full_scale = recording_attrs(data)
    return BandEvents(name, band, bank.code(data["counts"].values, rate_hz, bits, full_scale),
                      rate_hz)


@dataclass
class Spikes:
    """Spikes of every (event, neuron) of a band run, neuron index = event × n + neuron, and
    what the run cost."""
    spike_i: np.ndarray
    spike_t_ms: np.ndarray
    cpu_s: float = 0.0
    wall_s: float = 0.0


def _inputs(events: BandEvents, array: ResonatorArray) -> dict:
    m = events.n_events
    return {"k": np.tile(array.k, m), "input_dt_ms": 1000.0 / events.rate_hz,
            "input_index": np.repeat(np.arange(m), array.n_neurons), "b": array.b}


def reference_spikes(events: BandEvents, hz_per_k: float | None = None,
                     rtol: float = reference.DEFAULT_RTOL,
                     atol: float = reference.DEFAULT_ATOL) -> Spikes:
    """The exact spikes of the band's neurons (at ``hz_per_k``) over the whole events."""
    array = array_of(events.band, BandSetting(hz_per_k=hz_per_k))
    t0, w0 = time.process_time(), time.perf_counter()
    res = reference.simulate("resonator", events.coded, rtol=rtol, atol=atol,
                             **_inputs(events, array))
    return Spikes(res.spike_i, res.spike_t_ms, time.process_time() - t0,
                  time.perf_counter() - w0)


def brian_spikes(events: BandEvents, setting: BandSetting, target: str = "cython",
                 repeat: int = 1) -> Spikes:
    """All events × neurons as ONE group through ``neurons.simulate`` (as ``engine.events``
    does), over the setting's window; compiled on a few steps first, then timed. With
    ``repeat`` > 1 the events run that many times over in the group (a batch of the bank's
    size, for its cost); the spikes returned are those of the first copy."""
    array = array_of(events.band, setting, target)
    n_samples = events.coded.shape[0]
    if setting.duration_s is not None:
        n_samples = min(n_samples, int(round(setting.duration_s * events.rate_hz)))
    coded = np.tile(events.coded[:n_samples], (1, repeat))
    kwargs = dict(_inputs(BandEvents(events.name, events.band, coded, events.rate_hz), array),
                  method=setting.method, target=target, force=True)
    neurons.simulate("resonator", coded, setting.dt_ms, run_ms=WARM_UP_MS, **kwargs)
    t0, w0 = time.process_time(), time.perf_counter()
    res = neurons.simulate("resonator", coded, setting.dt_ms, **kwargs)
    first = res.spike_i < events.n_events * array.n_neurons
    return Spikes(res.spike_i[first], res.spike_t_ms[first], time.process_time() - t0,
                  time.perf_counter() - w0)


WARM_UP_MS = 5.0          # compiles what the timed run runs; its spikes are unused
COST_SAMPLE_SHARE = 0.2   # the share of a window a compiled setting's cost is timed on


def sampled_cost(events: BandEvents, setting: BandSetting, target: str, repeat: int,
                 spikes: Spikes, timings: dict | None = None) -> Spikes:
    """``spikes`` (a compiled run's) with the cost of the setting on ``target``: the window's
    run (``repeat`` copies of the events in one group) compiled on its first ``WARM_UP_MS``,
    then timed over its first ``WARM_UP_MS`` and its first ``COST_SAMPLE_SHARE`` (the same
    code each time: the run stopped early), the run's own cost and its cost per step from
    the two, and the whole window's steps costed by them.

    ``timings``: the run's own cost and cost per step of each method timed so far in this
    group (filled in here); a setting whose method is in it is costed by its steps without
    running: the step's code is the method's, whatever the step."""
    window_s = min(setting.duration_s or events.duration_s, events.duration_s)
    key = (setting.method, window_s, repeat)
    if timings is not None and key in timings:
        steps = window_s * 1000.0 / setting.dt_ms
        return Spikes(spikes.spike_i, spikes.spike_t_ms,
                      *(fixed + per_step * steps for fixed, per_step in timings[key]))
    short = WARM_UP_MS / 1000.0
    sample = min(max(window_s * COST_SAMPLE_SHARE, 2 * short), window_s)
    array = array_of(events.band, setting, target)
    n_samples = min(events.coded.shape[0], int(round(window_s * events.rate_hz)))
    coded = np.tile(events.coded[:n_samples], (1, repeat))
    kwargs = dict(_inputs(BandEvents(events.name, events.band, coded, events.rate_hz), array),
                  method=setting.method, target=target, force=True)
    neurons.simulate("resonator", coded, setting.dt_ms, run_ms=WARM_UP_MS, **kwargs)
    timed = []
    for seconds in (short, sample):
        t0, w0 = time.process_time(), time.perf_counter()
        neurons.simulate("resonator", coded, setting.dt_ms, run_ms=seconds * 1000.0, **kwargs)
        timed.append((time.process_time() - t0, time.perf_counter() - w0))
    parts = []
    for a, b in zip(*timed):
        per_s = max(b - a, 0.0) / max(sample - short, 1e-9)
        parts.append((max(a - short * per_s, 0.0), per_s * setting.dt_ms / 1000.0))
    if timings is not None:
        timings[key] = parts
    steps = window_s * 1000.0 / setting.dt_ms
    return Spikes(spikes.spike_i, spikes.spike_t_ms,
                  *(fixed + per_step * steps for fixed, per_step in parts))


RATE_WINDOW_S = 0.05      # the rate map's window: the bank's time bins are 0.1 s and coarser


def band_errors(run: Spikes, ref: Spikes, n: int, duration_s: float,
                window_s: float = RATE_WINDOW_S) -> dict:
    """Errors of a band run against its reference (``n`` event-neurons): spike counts per
    event-neuron, the rate map (event-neuron × ``window_s`` windows over the whole events)
    and spike times (``accuracy``'s definitions)."""
    edges = np.arange(int(np.floor(duration_s / window_s + 1e-9)) + 1) * window_s * 1000.0
    bins = [np.arange(n + 1) - 0.5, edges]

    def rates(s):
        return np.histogram2d(s.spike_i, s.spike_t_ms, bins=bins)[0]

    return {"spike_count_error": spike_count_error(np.bincount(run.spike_i, minlength=n),
                                                   np.bincount(ref.spike_i, minlength=n)),
            "rate_map_error": rate_map_error(rates(run), rates(ref)),
            "spike_time_error_ms": spike_time_error_ms(run.spike_i, run.spike_t_ms,
                                                       ref.spike_i, ref.spike_t_ms, n),
            "n_spikes": int(len(run.spike_i)), "reference_spikes": int(len(ref.spike_i))}


def measure(events: BandEvents, setting: BandSetting, ref: Spikes, target: str = "cython",
            cost_events: int = 1, compiled=None, timings: dict | None = None) -> dict:
    """One band at one setting: where its k·dt lies, its errors against ``ref`` (the
    reference at the same Hz per unit k) and its cost per event, timed on a group of at
    least ``cost_events`` events (the sample's, repeated). ``compiled``: the setting's
    spikes from a compiled run of the same model (``Spikes``, or the
    ``NumericalInstabilityError`` it met): its errors are scored from them, and its cost is
    timed on ``target`` over the first ``COST_SAMPLE_SHARE`` of the window
    (``sampled_cost``)."""
    lo, hi = k_dt_range(events.band, setting)
    row = {"band": events.name, "setting": setting.label(), **asdict(setting),
           "hz_per_k": setting.tuned(events.band).hz_per_k, "k_dt_min": lo, "k_dt_max": hi,
           "accurate_k_dt": ACCURATE_K_DT[setting.method],
           "inside_accurate_range": hi <= ACCURATE_K_DT[setting.method],
           "n_events": events.n_events, "target": target}
    repeat = max(1, -(-cost_events // events.n_events))
    if isinstance(compiled, NumericalInstabilityError):
        return dict(row, status=f"non-finite: {compiled}", errors_from="compiled")
    try:
        run = (brian_spikes(events, setting, target, repeat) if compiled is None else
               sampled_cost(events, setting, target, repeat, compiled, timings))
    except NumericalInstabilityError as exc:
        return dict(row, status=f"non-finite: {exc}")
    if compiled is not None:
        row.update(errors_from="compiled", cost_from=f"{target}, {setting.method} timed once "
                   f"(its finest step that ran) on the first {COST_SAMPLE_SHARE:.0%} of the "
                   "window and costed by steps")
    n = events.n_events * events.band.n_neurons
    window_ms = 1000.0 * (setting.duration_s or events.duration_s)
    window_ms = min(window_ms, 1000.0 * events.duration_s)
    steps = repeat * n * window_ms / setting.dt_ms
    timed = repeat * events.n_events
    return dict(row, status="ok", **band_errors(run, ref, n, events.duration_s),
                events_timed=timed, cpu_ms_per_event=1000.0 * run.cpu_s / timed,
                wall_ms_per_event=1000.0 * run.wall_s / timed,
                ns_per_neuron_step=1e9 * run.cpu_s / steps)


def truncation_error(ref: Spikes, n: int, duration_s: float, window_s: float) -> float:
    """Rate-map error a run would have if it stopped at ``window_s`` and were otherwise
    exact: the reference's spikes after the window, over all of them."""
    cut = Spikes(ref.spike_i[ref.spike_t_ms < 1000.0 * window_s],
                 ref.spike_t_ms[ref.spike_t_ms < 1000.0 * window_s])
    return band_errors(cut, ref, n, duration_s)["rate_map_error"]


# -- driven tuning: where each neuron's peak lands -----------------------------------------
def driven_tuning(band: Band, setting: BandSetting, rate_hz: float, freqs_hz,
                  duration_s: float = 0.5, target: str = "cython", compiled=None):
    """Spike rate of every neuron of ``band`` at ``setting`` driven by square waves of the
    band's coder amplitude at each of ``freqs_hz``, sampled at ``rate_hz`` as the coder's
    output is (one group of neurons × frequencies). Dims (``neuron_hz``, ``input_hz``).
    ``compiled(current, rate_hz, k, input_index, b, method, dt_ms)``: the spike indices of
    the same run from a compiled project of the same model (None: ``target``)."""
    import xarray as xr

    array = array_of(band, setting, target)
    freqs = np.asarray(freqs_hz, dtype=float)
    current = np.column_stack([square(f, duration_s, rate_hz, band.coder_amplitude).samples
                               for f in freqs])
    k = np.repeat(array.k, len(freqs))
    index = np.tile(np.arange(len(freqs)), array.n_neurons)
    if compiled is not None:
        spike_i = compiled(current, rate_hz, k, index, array.b, setting.method, setting.dt_ms)
    else:
        spike_i = neurons.simulate("resonator", current, setting.dt_ms, k, setting.method,
                                   input_dt_ms=1000.0 / rate_hz, input_index=index,
                                   target=target, force=True, b=array.b).spike_i
    counts = np.bincount(spike_i, minlength=array.n_neurons * len(freqs))
    return xr.DataArray(counts.reshape(array.n_neurons, len(freqs)) / duration_s,
                        dims=("neuron_hz", "input_hz"),
                        coords={"neuron_hz": array.neuron_hz, "input_hz": freqs,
                                "k": ("neuron_hz", array.k)},
                        name="rate", attrs={"units": "Hz", "setting": setting.label(),
                                            "engine": "compiled" if compiled else target})


def peak_hz(rates) -> np.ndarray:
    """Each neuron's peak input frequency (``tuning.derive``: the geometric middle of a
    plateau of equal maxima; NaN for a silent neuron)."""
    return derive(rates.drop_vars("k"))["peak_hz"].values


def peak_hz_per_k(rates) -> float:
    """Hz per unit k that puts the peaks on their targets: the geometric mean of each
    neuron's peak / k, over neurons that fire and peak inside the frequency grid."""
    peak, f = peak_hz(rates), rates.input_hz.values
    inside = np.isfinite(peak) & (peak > f.min()) & (peak < f.max())
    check(inside.sum() >= 2, "rates", f"{int(inside.sum())} neuron(s) peaking inside the grid",
          "a frequency grid wide enough that most neurons peak inside it")
    return float(np.exp(np.mean(np.log(peak[inside] / rates.k.values[inside]))))


def peak_offsets(rates) -> np.ndarray:
    """How many channels (the band's spacing between neighbours) each neuron's peak lies
    above (+) or below (−) its target frequency; NaN for a silent neuron."""
    target = rates.neuron_hz.values
    channel = np.log(target[1] / target[0])
    return np.log(peak_hz(rates) / target) / channel


def tuning_summary(rates) -> dict:
    offsets = peak_offsets(rates)
    ok = np.isfinite(offsets)
    return {"setting": rates.attrs["setting"], "peak_hz_per_k": peak_hz_per_k(rates),
            "peak_offset_channels": [None if not np.isfinite(o) else float(o) for o in offsets],
            "mean_abs_offset_channels": float(np.mean(np.abs(offsets[ok]))),
            "max_abs_offset_channels": float(np.max(np.abs(offsets[ok]))),
            "within_one_channel": int(np.sum(np.abs(offsets[ok]) <= 1.0)),
            "within_half_channel": int(np.sum(np.abs(offsets[ok]) <= 0.5)),
            "silent": int(np.sum(~ok))}


# -- the whole measurement: before, candidates inside the accurate range, chosen -----------
@dataclass
class BandStudy:
    """What the speed/accuracy study's "bands" section measures (its ``[bands]`` table):
    sample events (materials × positions × repetitions), the methods tried, the bands whose
    Hz per unit k is recalibrated from a driven tuning sweep (``n_freqs`` log-spaced over
    the band widened by ``freq_margin`` each side, ``tuning_duration_s`` each) and the
    shorter windows whose truncation error is reported."""
    bands: list = field(default_factory=lambda: list(BENCH_BANDS))
    materials: list = field(default_factory=lambda: ["aluminium", "wood", "pvc", "brass"])
    positions_cm: list = field(default_factory=lambda: [10.0, 30.0])
    repetitions: int = 1
    duration_s: float = 0.5
    methods: list = field(default_factory=lambda: ["euler", "rk2", "rk4"])
    calibrate: list = field(default_factory=lambda: ["high", "rod"])
    n_freqs: int = 120
    freq_margin: float = 1.4
    tuning_duration_s: float = 1.0
    windows_s: list = field(default_factory=lambda: [0.3])
    rate_map_error: float = 0.05
    coarser_steps: int = 3    # also try each method this many DT_STEPS_MS above its map step
    cost_events: int = 48     # events per timed group: the sample's events, repeated
    target: str = "cython"

    def __post_init__(self):
        bounds.declared(self)
        bounds.choice("target", self.target, ("numpy", "cython"))
        bounds.number("freq_margin", self.freq_margin, 0.0)
        bounds.number("rate_map_error", self.rate_map_error, 0.0)
        bounds.positive_integer("cost_events", self.cost_events)
        for name in ("bands", "calibrate", "methods", "windows_s"):
            check(isinstance(getattr(self, name), list), name, getattr(self, name), "a list")
        for name in self.bands + self.calibrate:
            check(name in BENCH_BANDS, "bands", name, f"names from {list(BENCH_BANDS)}")
        for m in self.methods:
            check(m in ACCURATE_K_DT, "methods", self.methods, f"names from {list(ACCURATE_K_DT)}")
        check(isinstance(self.n_freqs, int) and self.n_freqs >= 4, "n_freqs", self.n_freqs,
              "an integer >= 4")
        check(isinstance(self.materials, list) and self.materials, "materials",
              self.materials, "a non-empty list of material names")
        for i, material in enumerate(self.materials):
            check(material in antenna.MATERIALS, f"materials.{i}", material,
                  f"one of {sorted(antenna.MATERIALS)}")
        check(isinstance(self.positions_cm, list) and self.positions_cm, "positions_cm",
              self.positions_cm, "a non-empty list of contact distances (cm)")
        for i, distance in enumerate(self.positions_cm):
            bounds.number(f"positions_cm.{i}", distance, 0.0, antenna.ROD_LENGTH_CM,
                          lo_open=True, hi_open=True, unit=" cm")
        bounds.integer("repetitions", self.repetitions, 1, 1000)
        bounds.integer("coarser_steps", self.coarser_steps, 0, 20)
        bounds.number("duration_s", self.duration_s, 0.0, 60.0, lo_open=True, unit=" s")
        bounds.number("tuning_duration_s", self.tuning_duration_s, 0.0, 60.0, lo_open=True,
                      unit=" s")

    def freqs_hz(self, band: Band, rate_hz: float) -> np.ndarray:
        lo = band.band_hz[0] / self.freq_margin
        hi = min(band.band_hz[1] * self.freq_margin, 0.45 * rate_hz)
        return np.geomspace(lo, hi, self.n_freqs)


def recalibrate(study: BandStudy, band: Band, rate_hz: float, log=print,
                compiled=None) -> tuple[float, dict]:
    """Tuning at ``SMALL_SIGNAL_EULER`` and at the most accurate method's accurate step (on
    ``compiled``, ``driven_tuning``'s, when given: its fine step is the costly run); the
    Hz per unit k that puts the latter's peaks on target."""
    freqs = study.freqs_hz(band, rate_hz)
    before = tuning_summary(driven_tuning(band, SMALL_SIGNAL_EULER, rate_hz, freqs,
                                          study.tuning_duration_s, study.target))
    fine = BandSetting("rk4", accurate_dt_ms(band, "rk4"))
    rates = driven_tuning(band, fine, rate_hz, freqs, study.tuning_duration_s, study.target,
                          compiled)
    hz_per_k = peak_hz_per_k(rates)
    log(f"    tuning: {before['mean_abs_offset_channels']:.2f} channels off at "
        f"{SMALL_SIGNAL_EULER.label()}; peaks at {hz_per_k:.4g} Hz per k at {fine.label()}")
    return hz_per_k, {"before": before, "calibration": tuning_summary(rates),
                      "freqs_hz": [float(f) for f in freqs]}


def study_band(study: BandStudy, name: str, data, log=print, compiled=None,
               compiled_tuning=None) -> dict:
    """A band's error and cost at ``SMALL_SIGNAL_EULER``, each method at ``candidate_steps`` (the
    recalibrated Hz per unit k), the cheapest of those within the rate-map tolerance, and the
    tuning at the chosen setting."""
    band = BENCH_BANDS[name]
    events = code_events(name, band, data, study.duration_s)
    n = events.n_events * band.n_neurons
    ref = reference_spikes(events)
    out = {"reference_cpu_s": ref.cpu_s,
           "truncation": [{"window_s": w, "rate_map_error": truncation_error(
               ref, n, events.duration_s, w)} for w in study.windows_s]}
    hz_per_k = band.hz_per_k
    before_ref = ref
    if name in study.calibrate:
        hz_per_k, out["tuning"] = recalibrate(study, band, events.rate_hz, log,
                                              compiled_tuning)
        ref = reference_spikes(events, hz_per_k)
        out["reference_cpu_s"] += ref.cpu_s
    candidates = [BandSetting(method, dt_ms, hz_per_k) for method in study.methods
                  for dt_ms in candidate_steps(band, method, hz_per_k, study.coarser_steps)]
    # every setting's spikes from one compiled run when the caller has the engine for it
    runs = compiled(events, [SMALL_SIGNAL_EULER] + candidates) if compiled else {}
    rows = [dict(measure(events, SMALL_SIGNAL_EULER, before_ref, study.target,
                         study.cost_events, runs.get(SMALL_SIGNAL_EULER)), role="before")]
    # each method timed once, at its finest candidate step (the first: the most steps in
    # its sample), the coarser ones costed by their steps from it
    timings = {}
    for setting in candidates:
        rows.append(dict(measure(events, setting, ref, study.target, study.cost_events,
                                 runs.get(setting), timings), role="candidate"))
        log(f"    {name}: {setting.label()}: rate-map error "
            f"{rows[-1].get('rate_map_error')}")
    chosen = choose(rows, study.rate_map_error)
    if chosen is not None:
        chosen["role"] = "chosen"
        if name in study.calibrate:
            after = BandSetting(chosen["method"], chosen["dt_ms"], hz_per_k)
            out["tuning"]["after"] = tuning_summary(driven_tuning(
                band, after, events.rate_hz, study.freqs_hz(band, events.rate_hz),
                study.tuning_duration_s, study.target, compiled_tuning))
    return dict(out, band=name, rows=rows, n_events=events.n_events, chosen=chosen,
                apply=apply_line(name, chosen))


def choose(rows: list[dict], tolerance: float) -> dict | None:
    """The cheapest candidate whose rate map, measured against the exact reference on the
    band's own events, is within ``tolerance`` (None if none is). Accuracy is what that run
    measures; the stability map's range (``inside_accurate_range``) is reported beside it."""
    return min((r for r in rows if r.get("status") == "ok" and r.get("role") != "before"
                and r["rate_map_error"] <= tolerance), key=lambda r: r["cpu_ms_per_event"],
               default=None)


def apply_line(name: str, chosen: dict | None) -> str:
    """In words, what to set for the chosen setting (the fields of the readout.spiking band)."""
    if chosen is None:
        return f"{name}: no candidate setting met the rate-map tolerance"
    return (f"{name} band: step {chosen['dt_ms']:g} ms, {chosen['method']} integration, "
            f"{chosen['hz_per_k']:.4g} Hz per unit k")


def run_study(study: BandStudy, seed: int = 0, log=print, compiled=None,
              compiled_tuning=None) -> dict:
    """Every band of ``study`` on one set of sample events. ``compiled(events, settings)``:
    each setting's spikes (``Spikes``, or the ``NumericalInstabilityError`` met) from one
    compiled run of the same model, for ``measure``; ``compiled_tuning``: the driven
    tunings' at the fine and the chosen step (``driven_tuning``). None: every run on the
    study's target."""
    data = sample_data(study.materials, study.positions_cm, study.repetitions, seed)
    out = {"accurate_k_dt": dict(ACCURATE_K_DT), "n_events": int(data.sizes["event"]),
           "bands": {}}
    for name in study.bands:
        log(f"  band {name}")
        out["bands"][name] = study_band(study, name, data, log, compiled, compiled_tuning)
    return out
