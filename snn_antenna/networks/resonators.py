"""The resonator array in Brian2: offline (whole recordings) and streaming (sample by sample).

One ``NeuronGroup`` of Izhikevich resonators, neuron j tuned to ``neuron_hz[j]`` through its
time scale k_j. Both forms build the same group from the same equations and drive it with
the coded signal held constant over each input sample, so they give the same spikes on the
same data: offline reads the samples from a ``TimedArray`` of the whole recording, streaming
from a ring ``TimedArray`` that a ``NetworkOperation`` refills block by block (runtime mode
only). Both evaluate the same arithmetic on the same values, bit for bit.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from collections.abc import Callable, Iterable, Iterator
from typing import Protocol, runtime_checkable

import numpy as np
import xarray as xr

from ..core import bounds
from ..core import spec as specs
from ..core.errors import PipelineError, SpecError, check, is_integer, is_number
from ..core.signals import Recording, validate_samples
from . import neurons, runtime_cache

MIN_SAMPLES_PER_CYCLE = 4  # the square-wave coder needs both half-cycles sampled twice
# Streaming hands Brian2 this much input per Python call (25 samples at 1 kHz): a window is
# published at most one block's computing time after its last sample came.
STREAM_BLOCK_S = 0.025
# the network ``ResonatorArray.run`` builds, as ``runtime_cache`` names it
OFFLINE_NETWORK = "resonator array, offline"

# The band of preferred frequencies that a driving robot's self-motion keeps busy: the probe's
# free self-oscillation (``antenna.NATURAL_HZ``) and the neighbours that its tuning plateau
# reaches. A contact clamps the rod and shifts activity above it. The contact rule reads the
# array through this split twice, offline and live (``readout.contacts.ContactDetector``) and as
# spiking synapses (``networks.control.ControlLayer``): both take the band and the split here.
SELF_MOTION_BAND_HZ = (7.0, 10.5)


def tuned_above(neuron_hz, band_hz=SELF_MOTION_BAND_HZ) -> np.ndarray:
    """Which resonators are tuned above ``band_hz`` (a bool per neuron): the ones a contact
    drives and self-motion does not."""
    return np.asarray(neuron_hz, dtype=float) > band_hz[1]


@dataclass
class ResonatorArray:
    """``n_neurons`` resonators tuned across ``band_hz`` (log or linear spacing).

    ``b`` sets the spike rate (Fig. 8H); the coder's amplitude sets the bandwidth (Fig. 8G);
    ``hz_per_k`` maps tuning to k (see ``neurons.k_for_frequency``).
    """
    n_neurons: int = 24
    band_hz: tuple[float, float] = (7.0, 30.0)
    spacing: str = "log"
    b: float = 0.26
    dt_ms: float = 0.1
    method: str = "rk2"  # studies/speed_accuracy.toml: same cost as euler, half the error
    target: str = "cython"
    hz_per_k: float = neurons.DRIVEN_HZ_PER_K
    force: bool = False

    def __post_init__(self):
        bounds.declared(self)
        check(is_integer(self.n_neurons) and 1 <= self.n_neurons <= 100_000, "n_neurons",
              self.n_neurons, "an integer in [1, 100000]")
        band_ok = (isinstance(self.band_hz, (list, tuple, np.ndarray)) and len(self.band_hz) == 2
                   and all(is_number(x) for x in self.band_hz))
        check(band_ok and 0 < self.band_hz[0] <= self.band_hz[1], "band_hz", self.band_hz,
              "[low, high] in Hz with 0 < low <= high")
        lo, hi = (float(x) for x in self.band_hz)
        check(isinstance(self.spacing, str) and self.spacing in ("log", "linear"), "spacing",
              self.spacing, "'log' or 'linear'")
        bounds.amplitude("b", self.b)
        check(is_number(self.hz_per_k) and self.hz_per_k > 0, "hz_per_k", self.hz_per_k,
              "Hz per unit k > 0")
        check(isinstance(self.method, str) and self.method in neurons.METHODS, "method",
              self.method, f"one of {list(neurons.METHODS)}")
        check(isinstance(self.target, str) and self.target in ("numpy", "cython"), "target",
              self.target, "'numpy' or 'cython'")
        bounds.dt_ms("dt_ms", self.dt_ms)
        check(isinstance(self.force, bool), "force", self.force, "true or false")
        k_dt = float(self.k.max()) * self.dt_ms
        if not self.force and k_dt > neurons.MAX_STABLE_K_DT[self.method]:
            raise SpecError("dt_ms", self.dt_ms,
                            f"at most {neurons.max_stable_dt_ms(self.k, self.method):.4g} ms "
                            f"for a band up to {hi:g} Hz with method {self.method!r} "
                            f"(k·dt <= {neurons.MAX_STABLE_K_DT[self.method]}), or force=True")

    @property
    def neuron_hz(self) -> np.ndarray:
        lo, hi = (float(x) for x in self.band_hz)
        space = np.geomspace if self.spacing == "log" else np.linspace
        return space(lo, hi, self.n_neurons)

    @property
    def k(self) -> np.ndarray:
        return np.atleast_1d(neurons.k_for_frequency(self.neuron_hz, self.hz_per_k))

    def check_rate(self, rate_hz: float) -> None:
        need = MIN_SAMPLES_PER_CYCLE * float(self.band_hz[1])
        check(rate_hz >= need, "rate_hz", rate_hz,
              f"an input sample rate of at least {need:g} Hz for a band up to "
              f"{self.band_hz[1]:g} Hz ({MIN_SAMPLES_PER_CYCLE} samples per cycle)")

    # -- building ---------------------------------------------------------------------------
    def build_group(self, input_expr: str, extra: str = "", namespace: dict | None = None):
        """The array as one Brian2 NeuronGroup named "resonators", tuned and at rest, driven by
        ``input_expr`` (``extra``: further variable definitions; ``namespace``: what the
        expression refers to). ``run``, ``stream``, ``assembly.build`` and the speed/accuracy
        drivers all build it here."""
        import brian2 as b2

        b2.prefs.codegen.target = self.target
        group = b2.NeuronGroup(
            self.n_neurons,
            neurons.equations("resonator", input_expr, extra) + "\nspike_count : integer",
            threshold=neurons.THRESHOLD, reset=neurons.reset("spike_count += 1"),
            method=neurons.brian_method(self.method), namespace=namespace or {},
            dt=self.dt_ms * b2.ms,
            name="resonators")
        preset = neurons.PRESETS["resonator"]
        group.k = self.k
        group.a, group.c, group.d = preset.a, preset.c, preset.d
        group.b = self.b
        # At rest for zero input, the coder's output for silence, in both forms: a stream's
        # first sample is not known when the group is built.
        v0, u0 = neurons.resting_state("resonator", self.b)
        group.v, group.u = v0, u0
        return group

    # -- offline ----------------------------------------------------------------------------
    def compiled(self) -> bool:
        """Whether ``run``'s network is compiled for this interpreter already (cython; numpy
        compiles nothing): an estimate charges its compile otherwise."""
        return self.target != "cython" or runtime_cache.compiled(OFFLINE_NETWORK, __name__)

    def run(self, coded: Recording, window_s: float = 0.1,
            check_every_ms: float = 10.0) -> ArrayResult:
        """Drive the array with a coded recording (one channel); spikes and a rate map."""
        if not isinstance(coded, Recording):
            raise SpecError("coded", type(coded).__name__,
                            "a signals.Recording of coded samples (rec.with_samples(...))")
        # a window holds one input sample at least: a rate map never outgrows the input
        bounds.number("window_s", window_s, 1.0 / bounds.rate_hz("rate_hz", coded.rate_hz),
                      unit=" s (one input sample)")
        bounds.number("check_every_ms", check_every_ms, self.dt_ms, unit=" ms (one step)")
        import brian2 as b2

        # Contiguous: Brian2's cython TimedArray refuses a strided view (e.g. a column slice).
        samples = np.ascontiguousarray(validate_samples(coded.samples, "coded.samples"),
                                       dtype=float)
        if samples.ndim != 1:
            raise SpecError("coded.samples", f"array of shape {samples.shape}",
                            "one channel (run the preprocessing chain first)")
        self.check_rate(coded.rate_hz)
        b2.start_scope()
        drive = b2.TimedArray(held_samples(samples), dt=b2.second / coded.rate_hz, name="drive")
        group = self.build_group("drive(t)", "", {"drive": drive})
        spikes = b2.SpikeMonitor(group, name="spikes")
        guard = neurons.instability_guard(group, "resonator", self.dt_ms, self.method,
                                          check_every_ms)
        net = b2.Network(group, spikes, guard)
        t0 = time.perf_counter()
        net.run(coded.duration_s * b2.second, namespace={})
        wall = time.perf_counter() - t0
        runtime_cache.note(OFFLINE_NETWORK, __name__, self.target)
        guard.function()
        return ArrayResult(self.neuron_hz, np.asarray(spikes.i[:], dtype=int),
                           np.asarray(spikes.t_[:], dtype=float), coded.duration_s,
                           window_s, wall_s=wall)

    # -- streaming --------------------------------------------------------------------------
    def steps_per_sample(self, rate_hz: float) -> int:
        """Integration steps per input sample: the stream needs a whole number of them."""
        steps = 1.0 / (rate_hz * self.dt_ms * 1e-3)
        check(steps >= 1 - 1e-9 and abs(steps - round(steps)) < 1e-6, "dt_ms", self.dt_ms,
              f"a step that divides the sample interval ({1e3 / rate_hz:g} ms) for streaming")
        return int(round(steps))

    def stream(self, port: StreamPort, rate_hz: float, window_s: float = 0.1,
               max_duration_s: float = 365 * 86400.0,
               block_s: float = STREAM_BLOCK_S,
               companions: Callable[[object], Iterable] | None = None) -> StreamStats:
        """Run the array live on coded samples as they arrive, through ``port`` (a
        :class:`StreamPort`: the stream's two calls out of the network).

        At each block boundary (at most ``block_s``, dividing the window) the network has
        integrated every sample before it: when a window of ``window_s`` ends there,
        ``port.window(t_s, counts)`` receives its spike counts per neuron (memory stays
        bounded however long the stream runs); then ``port.fill(block)`` writes the next block
        of coded samples (waiting for them) into the ring ``TimedArray`` the group reads at its
        own steps, fewer than asked once the stream ends. The same arithmetic as ``run``'s
        ``drive(t)``, so the same spikes. Runtime mode only (NetworkOperation).

        ``companions(group)``, when given, returns further Brian2 objects that run in the same
        network as the array (the other parts of a composed network, wired to the array's
        group); ``port.window`` may read and steer them.
        """
        import brian2 as b2

        check(isinstance(port, StreamPort), "port", type(port).__name__,
              "a StreamPort (fill and window), e.g. ChunkFeed(chunks)")
        check(is_number(rate_hz) and rate_hz > 0, "rate_hz", rate_hz, "a sample rate > 0 Hz")
        check(is_number(window_s) and window_s > 0, "window_s", window_s, "a window > 0 s")
        check(is_number(block_s) and block_s > 0, "block_s", block_s, "a block > 0 s")
        self.check_rate(rate_hz)
        samples_per_window = int(round(window_s * rate_hz))
        check(samples_per_window >= 1, "window_s", window_s,
              f"a window of at least one sample (1/{rate_hz:g} s)")
        block = _block_samples(samples_per_window, block_s * rate_hz)
        b2.start_scope()
        # The ring holds the current block; the group reads slot (step // steps) % block.
        ring = b2.TimedArray(np.zeros(block), dt=b2.second / rate_hz, name="drive")
        period = self.steps_per_sample(rate_hz) * block
        group = self.build_group(f"drive((t_in_timesteps % {period}) * dt)", "",
                                 {"drive": ring})
        # One clock for everything: Brian2's loop pays for every further clock at every step
        # (a third of the run at dt 0.5 ms). The feed runs on the group's clock and returns at
        # once except at block boundaries, where it also calls the instability check.
        check_state = neurons.instability_check(group, "resonator", self.dt_ms, self.method)
        feeder = _BlockFeeder(port, ring.values, group, samples_per_window, rate_hz, period,
                              check_state)
        feed = b2.NetworkOperation(feeder, clock=group.clock, when="start", name="feed")
        net = b2.Network(group, feed, *(companions(group) if companions else ()))
        feeder.net = net
        t0 = time.perf_counter()
        net.run(max_duration_s * b2.second, namespace={})
        # A last, partial block: its first step ran when the feed stopped the network.
        rest = feeder.tail * self.steps_per_sample(rate_hz) - 1
        if rest > 0 and not feeder.failed:
            feed.active = False
            net.run(rest * self.dt_ms * b2.ms, namespace={})
            check_state()
        stats = feeder.stats
        stats.wall_s = time.perf_counter() - t0
        stats.simulated_s = stats.samples / rate_hz
        if feeder.failed:
            raise _as_project_error(feeder.failed[0], stats.samples / rate_hz)
        return stats


def network_table(spec: dict) -> dict:
    """``[network]``, checked: the ``ResonatorArray``'s keyword arguments."""
    with specs.section("network"):
        return dict(specs.check_section(spec, "network", ResonatorArray))


def array_section(spec: dict) -> ResonatorArray:
    """The resonator array of ``[network]``."""
    table = network_table(spec)
    with specs.section("network"):
        return ResonatorArray(**table)


def check_rates(array: ResonatorArray, scenes: Iterable) -> None:
    """Every scene's sample rate carries the array's band (refused as ``network.rate_hz``)."""
    with specs.section("network"):
        for scene in scenes:
            array.check_rate(scene.rate_hz)


def held_samples(samples: np.ndarray) -> np.ndarray:
    """``samples`` (1-D, at least one) padded with their last value to a power of two.

    Brian2 writes a TimedArray's length into the code that reads it, so every recording length
    would compile its own state update; padded, all recordings of 4,097 to 8,192 samples (at one
    rate, dt and method) share one compiled group. The group never reads past the recording
    (the run lasts its duration), and where rounding puts a read at its end, the padding holds
    the last value, as Brian2's clamp to the last sample does: the same spikes."""
    n = len(samples)
    size = 1 << (n - 1).bit_length()
    return np.concatenate([samples, np.full(size - n, samples[-1])]) if size > n else samples


@runtime_checkable
class StreamPort(Protocol):
    """The streaming array's two calls out of the network, each at a block boundary: the
    window that just ended, then the next block of input."""

    def window(self, t_s: float, counts: np.ndarray) -> None:
        """A window starting at ``t_s`` ended: ``counts``, spikes per neuron in it (a copy)."""

    def fill(self, block: np.ndarray) -> int:
        """Write the next coded samples into ``block`` (waiting for them); how many, fewer
        only when the stream ended."""


def _as_project_error(exc: Exception, t_s: float) -> Exception:
    """The project's own errors (bad input, a lost port, instability) pass unchanged; anything
    else from the port becomes a PipelineError naming where it broke."""
    if type(exc).__module__.startswith("snn_antenna") or isinstance(exc, SpecError):
        return exc
    error = PipelineError("the live pipeline", f"{type(exc).__name__} at {t_s:.2f} s of "
                                               f"input: {exc}")
    error.__cause__ = exc
    return error


def _block_samples(samples_per_window: int, most: float) -> int:
    """The largest divisor of the window (in samples) not above ``most`` (at least 1)."""
    return max(b for b in range(1, samples_per_window + 1)
               if samples_per_window % b == 0 and b <= max(most, 1))


class _BlockFeeder:
    """The stream's NetworkOperation, called at every step and busy only at block boundaries
    (every ``period`` steps): it hands the port the window that just ended (every step before
    this one has been integrated), checks the state, then has the port fill the ring with the
    next block. Errors are kept and re-raised once Brian2 has stopped cleanly."""

    def __init__(self, port, ring, group, samples_per_window, rate_hz, period, check_state):
        self.port, self.ring, self.net = port, ring, None
        self.counts = group.variables["spike_count"].get_value()
        self.samples_per_window, self.rate_hz = samples_per_window, rate_hz
        self.period, self.check_state = period, check_state
        self.stats = StreamStats()
        self.failed: list[BaseException] = []
        self.tail = 0
        self._wait = 0

    def __call__(self):  # no ``t`` argument: Brian2 would build a Quantity for it each call
        if self._wait:
            self._wait -= 1
            return
        self._wait = self.period - 1
        stats = self.stats
        try:
            if stats.samples and stats.samples % self.samples_per_window == 0:
                stats.windows += 1
                self.port.window(stats.samples / self.rate_hz
                                 - self.samples_per_window / self.rate_hz, self.counts.copy())
                self.counts[:] = 0
            self.check_state()
            n = self.port.fill(self.ring)
            if n and not np.all(np.isfinite(self.ring[:n])):
                raise SpecError("stream sample", "non-finite value",
                                "finite coded samples (the preprocessing chain never "
                                "produces NaN; check the source)")
        except Exception as exc:
            self.failed.append(exc)
            n = 0
        stats.samples += n
        if n < len(self.ring):        # the stream ended: integrate what came, then stop
            self.tail = n
            self.net.stop()


class ChunkFeed:
    """A :class:`StreamPort` on an iterable of coded chunks (1-D arrays of any length): blocks
    cut from them in order; the windows' ``(t_s, counts)`` collected in ``windows``, or handed
    to ``on_window`` when given."""

    def __init__(self, chunks: Iterable[np.ndarray],
                 on_window: Callable[[float, np.ndarray], None] | None = None):
        self._chunks: Iterator = iter(chunks)
        self._buf = np.empty(0)
        self._pos = 0
        self.on_window = on_window
        self.windows: list[tuple[float, np.ndarray]] = []

    def window(self, t_s: float, counts: np.ndarray) -> None:
        if self.on_window is not None:
            self.on_window(t_s, counts)
        else:
            self.windows.append((t_s, counts))

    def fill(self, block: np.ndarray) -> int:
        n = 0
        while n < len(block):
            if self._pos >= len(self._buf) and not self._next_chunk():
                return n
            m = min(len(block) - n, len(self._buf) - self._pos)
            block[n:n + m] = self._buf[self._pos:self._pos + m]
            n += m
            self._pos += m
        return n

    def _next_chunk(self) -> bool:
        try:
            self._buf = np.asarray(next(self._chunks), dtype=float).ravel()
        except StopIteration:
            return False
        self._pos = 0
        return True


@dataclass
class StreamStats:
    samples: int = 0
    windows: int = 0
    wall_s: float = 0.0
    simulated_s: float = 0.0

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second (> 1: faster than real time)."""
        return self.simulated_s / self.wall_s if self.wall_s > 0 else float("inf")


@dataclass
class ArrayResult:
    neuron_hz: np.ndarray
    spike_i: np.ndarray
    spike_t_s: np.ndarray
    duration_s: float
    window_s: float = 0.1
    wall_s: float = 0.0
    extra: dict = field(default_factory=dict)

    @property
    def rate_map(self) -> xr.DataArray:
        return rate_map(self.spike_i, self.spike_t_s, self.neuron_hz, self.duration_s,
                        self.window_s)


def rate_map(spike_i, spike_t_s, neuron_hz, duration_s: float,
             window_s: float = 0.1) -> xr.DataArray:
    """Spike rates (Hz) per neuron and window: the paper's frequency map (Fig. 10H)."""
    check(is_number(window_s) and 0 < window_s <= duration_s, "window_s", window_s,
          f"a window in (0, {duration_s:g}] s")
    n_windows = int(np.floor(duration_s / window_s + 1e-9))
    bounds.n_samples("window_s", n_windows * window_s, 1.0 / window_s,
                     8 * max(1, len(neuron_hz)))   # the map's windows x neurons must fit
    edges = np.arange(n_windows + 1) * window_s
    # A spike belongs to the window its step starts in, counted as the stream counts it: a
    # spike at exactly 5.3 s is in [5.3, 5.4) although 53 * 0.1 > 5.3 in floating point.
    window = np.floor(np.asarray(spike_t_s, dtype=float) / window_s + 1e-9).astype(int)
    neuron = np.asarray(spike_i, dtype=int)
    keep = (window >= 0) & (window < n_windows) & (neuron >= 0) & (neuron < len(neuron_hz))
    counts = np.zeros((len(neuron_hz), n_windows))
    np.add.at(counts, (neuron[keep], window[keep]), 1)
    return xr.DataArray(
        counts / window_s, dims=("neuron_hz", "window_s"),
        coords={"neuron_hz": ("neuron_hz", np.asarray(neuron_hz, dtype=float),
                              {"units": "Hz", "long_name": "preferred frequency"}),
                "window_s": ("window_s", edges[:-1],
                             {"units": "s", "long_name": "window start"})},
        name="rate", attrs={"units": "Hz", "window_s": window_s})
