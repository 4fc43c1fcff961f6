"""The speed gate: an associative memory in Brian2 that maps the speed command to Th.

The paper's forward model (Patanè et al. 2012, Fig. 3 and Discussion): the robot's own motion
shakes the antenna, so the square-wave coder's threshold must rise with speed, and the
motor command predicts by how much. Here that prediction is learned by spiking neurons:

    speed command ──► speed population ──(plastic w)──► read-out ──► Th = decode(rate)
                      class-I, Gaussian-tuned             class-I       ▲
                                                           ▲            │ during learning only
                                              teacher (Poisson, rate = encode(Th*(speed)))

- Speed population: ``n_speed_neurons`` class-I neurons (``neurons.equations("class1")``) with
  preferred speeds evenly spread over ``speed_range_cm_s`` (and one spacing beyond); neuron j
  receives ``speed_offset + peak_current · exp(−(v − v_j)² / 2σ²)``. The offset sits just below the
  rheobase, where the class-I rate grows about linearly with the drive, so each rate follows
  its Gaussian and, with σ equal to the spacing, the population's summed rate is nearly the
  same at every speed: the read-out then interpolates linearly between trained speeds
  instead of overshooting where two tuning curves overlap.
- Read-out: one class-I neuron with exponential synaptic current, biased just below its
  rheobase so that without input it is silent. Its rate codes Th on a log scale:
  ``Th = th_lo · (th_hi / th_lo) ** (rate / max_rate_hz)`` (equal relative precision from
  slow to fast driving; ``th_lo``/``th_hi`` span the trained values with a factor 2 margin).
- Learning (a spike-driven delta rule): at every presynaptic spike,
  ``w += eta · (r_teacher − r_out)``, where r_teacher and r_out are exponential traces (Hz) of
  the teacher's and the read-out's spikes. The teacher fires at the rate that encodes Th* for
  the speed presented; it only talks to the plasticity, never drives the read-out. Learning
  is switched off and the teacher is silent during recall.

``fit(speeds, th_star)`` trains (one Brian2 run over the whole schedule, recall blocks
interleaved to record the learning curve), ``predict(speeds)`` recalls Th for constant
speeds, and ``thresholds(speed_per_sample, rate_hz)`` runs recall online along a scene's
speed profile and returns the Th the coder uses at every sample
(``SquareWaveCoder.partial_transform(X, threshold=...)``). Many scenes run as copies of the
gate in the same groups.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..core import bounds
from ..core.errors import SpecError, check
from . import neurons, runtime_cache

CLASS1_RHEOBASE = 22.56  # class1 preset (5v + 140, b = -0.1): the fixed point vanishes above


def read_trace(objects: dict) -> np.ndarray:
    """The read-outs' rate traces (``r_read``, one per copy; Th is ``decode`` of it) of the
    gate's ``objects``, as a live view of the array Brian2 steps: a caller on the network's
    clock reads it without a monitor. (The read-outs are a Subgroup, and Brian2 hands out the
    whole group's array for a Subgroup's variable.)"""
    readout = objects["readout"]
    return readout.variables["r_read"].get_value()[readout.start:readout.stop]


MAX_EPOCHS = 10_000


# the gate's network (training and recall), as ``runtime_cache`` names it
NETWORK = "speed gate"

@dataclass
class SpeedGate:
    n_speed_neurons: int = 7
    speed_range_cm_s: tuple = (0.0, 30.0)
    tuning_width: float = 1.0        # σ of the tuning, in units of the preferred-speed spacing
    peak_current: float = 30.0       # tuned drive at the preferred speed, above the offset
    speed_offset: float = 21.0       # untuned drive just below the rheobase (see below)
    max_rate_hz: float = 200.0       # read-out rate that codes th_hi
    readout_bias: float = 20.0       # just below the rheobase: silent without input
    tau_syn_ms: float = 10.0
    tau_trace_s: float = 0.1         # rate traces used by the learning rule
    tau_read_s: float = 0.3          # rate trace read online as Th
    eta: float = 0.004
    w_max: float = 60.0
    epochs: int = 12
    present_s: float = 0.6           # each speed is shown this long (half settling)
    curve_points: int = 5            # recall blocks recorded during training
    dt_ms: float = 1.0
    target: str = "numpy"
    seed: int = 0

    def __post_init__(self):
        bounds.declared(self)
        check(isinstance(self.n_speed_neurons, int) and 4 <= self.n_speed_neurons <= 1000,
              "n_speed_neurons", self.n_speed_neurons, "an integer in [4, 1000]")
        bounds.pair("speed_range_cm_s", self.speed_range_cm_s, strict=True, unit=" cm/s")
        for name in ("tuning_width", "peak_current", "max_rate_hz", "tau_syn_ms", "tau_trace_s",
                     "tau_read_s", "eta", "w_max", "present_s", "dt_ms"):
            value = getattr(self, name)
            check(np.isfinite(value) and value > 0, name, value, "a finite value > 0")
        check(np.isfinite(self.speed_offset) and 0 <= self.speed_offset < CLASS1_RHEOBASE,
              "speed_offset", self.speed_offset,
              f"a drive in [0, {CLASS1_RHEOBASE}) (below the class-I rheobase)")
        # the recall converges within tens of epochs; thousands only repeat it for hours
        bounds.integer("epochs", self.epochs, 1, MAX_EPOCHS)
        bounds.integer("curve_points", self.curve_points, 1, MAX_EPOCHS)
        bounds.dt_ms("dt_ms", self.dt_ms)
        check(self.target in ("numpy", "cython"), "target", self.target, "'numpy' or 'cython'")
        bounds.amplitude("readout_bias", self.readout_bias)
        bounds.seed("seed", self.seed)

    # -- codes ------------------------------------------------------------------------------
    @property
    def preferred_cm_s(self) -> np.ndarray:
        """Preferred speeds: evenly spaced, one spacing beyond each end of the range, so the
        population's summed rate is as flat at the range's edges as inside it (otherwise the
        edge weights grow to make up for the missing neighbour and overshoot inside)."""
        lo, hi = (float(v) for v in self.speed_range_cm_s)
        step = (hi - lo) / max(self.n_speed_neurons - 3, 1)
        return np.linspace(lo - step, hi + step, self.n_speed_neurons)

    @property
    def sigma_cm_s(self) -> float:
        p = self.preferred_cm_s
        return float(self.tuning_width * (p[1] - p[0]))

    def encode(self, th) -> np.ndarray:
        """Th → teacher rate (Hz)."""
        lo, hi = self.th_range_
        return self.max_rate_hz * np.log(np.asarray(th, float) / lo) / np.log(hi / lo)

    def decode(self, rate_hz) -> np.ndarray:
        """Read-out rate (Hz) → Th."""
        lo, hi = self.th_range_
        return lo * (hi / lo) ** (np.asarray(rate_hz, float) / self.max_rate_hz)

    def check_speeds(self, speeds, name: str = "speed_cm_s") -> np.ndarray:
        v = np.asarray(speeds, dtype=float)
        lo, hi = (float(x) for x in self.speed_range_cm_s)
        if v.size == 0 or not np.all(np.isfinite(v)) or np.any(v < 0):
            raise SpecError(name, speeds, "finite speeds >= 0 cm/s")
        if np.any(v < lo) or np.any(v > hi):
            raise SpecError(name, speeds, f"speeds within the gate's range [{lo:g}, {hi:g}] cm/s")
        return v

    # -- the network ------------------------------------------------------------------------
    def objects(self, n_copies: int = 1, speed_expr: str = "speed_cm_s",
                extra: str = "speed_cm_s : 1 (shared)", weights=None,
                namespace: dict | None = None, teacher_expr: str = "0*Hz",
                learning_expr: str = "0", learning: bool = True, clock=None, units=None):
        """The gate's Brian2 objects: speed population, read-out, plastic synapses, teacher.

        ``speed_expr`` is the speed command seen by the speed population (``extra`` declares what
        it refers to: by default a shared variable the closed loop writes). Returned as a dict of
        named objects (``gate``: the group, when it is the gate's own; ``speed_population``,
        ``readout``, ``plastic``, ``teacher``, ``teaching``); Th is ``decode(readout.r_read)``.
        ``learning=False``: recall only, reduced to what recall uses (no teacher, no learning
        traces, synapses that only transmit; the same recall, with fewer Brian2 calls per step).
        ``clock``: a Brian2 clock of step ``dt_ms`` to share (by default one of its own for all the
        gate's objects:
        Brian2's loop pays for every clock at every step of any). ``units``: the Subgroups
        ``speed_population`` and ``readout`` of a class-I group shared with other parts
        (``neurons.class1_units`` of ``unit_rows``), instead of a group of the gate's own.
        """
        import brian2 as b2

        n_in = self.n_speed_neurons
        own = {}
        if units is None:
            if clock is None:
                clock = b2.Clock(dt=self.dt_ms * b2.ms, name="gate_clock*")
            own["gate"], units = neurons.class1_units(
                self.unit_rows(n_copies, speed_expr, extra, namespace, learning), clock, "gate")
        speed_pop, readout = units["speed_population"], units["readout"]
        clock = speed_pop.source.clock
        learn = (f"\nw = clip(w + {self.eta!r} * ({learning_expr}) * (r_teacher_post - "
                 f"r_out_post), -{self.w_max!r}, {self.w_max!r})") if learning else ""
        plastic = b2.Synapses(speed_pop, readout, model="w : 1", on_pre="I_syn_post += w" + learn,
                              namespace=namespace or {}, clock=clock, name="plastic")
        plastic.connect(i=np.arange(n_in * n_copies), j=np.repeat(np.arange(n_copies), n_in))
        plastic.w = np.tile(np.zeros(n_in) if weights is None else weights, n_copies)
        recall = {**own, "speed_population": speed_pop, "readout": readout,
                  "plastic": plastic}
        if not learning:
            return recall
        # A pacemaker fires exactly at the teacher rate: the rule sees the target, not the
        # counting noise of a Poisson train.
        teacher = b2.NeuronGroup(n_copies, f"dphase/dt = {teacher_expr} : 1",
                                 threshold="phase >= 1", reset="phase -= 1", method="euler",
                                 namespace=namespace or {}, clock=clock, name="teacher")
        teaching = b2.Synapses(teacher, readout,
                               on_pre=f"r_teacher_post += {1 / self.tau_trace_s!r}",
                               clock=clock, name="teaching")
        teaching.connect(j="i")
        return {**recall, "teacher": teacher, "teaching": teaching}

    def unit_rows(self, n_copies: int = 1, speed_expr: str = "speed_cm_s",
                  extra: str = "speed_cm_s : 1 (shared)", namespace: dict | None = None,
                  learning: bool = False) -> dict:
        """The gate's class-I units (``neurons.Class1Rows``): its speed neurons (``tuned`` = 1,
        ``bias`` = the speed offset), which take the drive tuned to their preferred speed, and
        its read-outs (silent ``bias``), which take the synaptic current from them; every unit
        keeps the rate trace the online Th reads (``r_read``: the read-outs') and, when the
        gate learns, those of the learning rule (``r_out``, ``r_teacher``)."""
        import brian2 as b2

        n_speed = self.n_speed_neurons * n_copies
        traces = ("dr_out/dt = -r_out / tau_trace : 1\n"
                  "dr_teacher/dt = -r_teacher / tau_trace : 1\n") if learning else ""
        common = dict(
            tau_syn_ms=self.tau_syn_ms,
            equations=f"""{traces}dr_read/dt = -r_read / tau_read : 1
                tuned : 1 (constant)
                preferred : 1 (constant)
                copy : integer (constant)
                {extra}""",
            on_spike=(*([f"r_out += {1 / self.tau_trace_s!r}"] if learning else []),
                      f"r_read += {1 / self.tau_read_s!r}"),
            namespace={"tau_trace": self.tau_trace_s * b2.second,
                       "tau_read": self.tau_read_s * b2.second,
                       "peak_current": self.peak_current, "sigma": self.sigma_cm_s,
                       **(namespace or {})})
        tuned_drive = f"peak_current * exp(-(({speed_expr}) - preferred)**2 / (2*sigma**2))"
        return {
            "speed_population": neurons.Class1Rows(
                n_speed, self.speed_offset, input_terms=f" + tuned * {tuned_drive}",
                values={"tuned": 1.0, "preferred": np.tile(self.preferred_cm_s, n_copies),
                        "copy": np.repeat(np.arange(n_copies), self.n_speed_neurons)},
                **common),
            "readout": neurons.Class1Rows(
                n_copies, self.readout_bias, rest_current=self.readout_bias,
                values={"copy": np.arange(n_copies)}, **common)}

    def _network(self, speed_cm_s: np.ndarray, teacher_hz: np.ndarray, learning: np.ndarray,
                 step_s: float, weights: np.ndarray, record_read_every_s: float | None = None):
        """Build and run ``n_copies`` gates (columns of ``speed_cm_s``); return spikes/traces.

        ``speed_cm_s`` (n_steps, n_copies), ``teacher_hz`` and ``learning`` (n_steps,) are
        held for ``step_s`` each. Returns (readout spike indices, times in s, final weights,
        read trace (n_records, n_copies) or None).
        """
        import brian2 as b2

        n_steps, n_copies = speed_cm_s.shape
        b2.start_scope()
        b2.prefs.codegen.target = self.target
        b2.seed(self.seed)
        step = step_s * b2.second
        namespace = {
            "speed_command": b2.TimedArray(speed_cm_s, dt=step, name="speed_command"),
            "teacher_rate": b2.TimedArray(np.asarray(teacher_hz, float) * b2.Hz, dt=step,
                                          name="teacher_rate"),
            "learning": b2.TimedArray(np.asarray(learning, float), dt=step, name="learning")}
        # Recall alone (predict, thresholds) runs the recall-only gate: the same recall.
        parts = self.objects(n_copies, "speed_command(t, copy)", "", weights, namespace,
                             teacher_expr="teacher_rate(t)", learning_expr="learning(t)",
                             learning=bool(np.any(learning)))
        spikes = b2.SpikeMonitor(parts["readout"], name="readout_spikes")
        objects = [*parts.values(), spikes,
                   neurons.instability_guard(parts["gate"], "class1", self.dt_ms, "euler")]
        trace = None
        if record_read_every_s is not None:
            trace = b2.StateMonitor(parts["readout"], "r_read", record=True,
                                    dt=record_read_every_s * b2.second, name="read_trace")
            objects.append(trace)
        net = b2.Network(*objects)
        net.run(n_steps * step, namespace={})
        runtime_cache.note(NETWORK, __name__, self.target)
        w = np.asarray(parts["plastic"].w[:], float).reshape(n_copies, -1)[0]
        read = np.asarray(trace.r_read[:], float).T if trace is not None else None
        return (np.asarray(spikes.i[:], int), np.asarray(spikes.t_[:], float), w, read)

    # -- learning ---------------------------------------------------------------------------
    def compiled(self) -> bool:
        """Whether the gate's network is compiled for this interpreter (cython; numpy
        compiles nothing): an estimate charges its compile otherwise."""
        return self.target != "cython" or runtime_cache.compiled(NETWORK, __name__)

    def fit(self, speeds, th_star, test_speeds=None) -> SpeedGate:
        """Learn Th*(speed) from examples; record recall on ``test_speeds`` while learning."""
        speeds = self.check_speeds(speeds, "speeds")
        th = np.asarray(th_star, dtype=float)
        if th.shape != speeds.shape or not np.all(np.isfinite(th)) or np.any(th <= 0):
            raise SpecError("th_star", th_star, "one finite threshold > 0 per training speed")
        test = speeds if test_speeds is None else self.check_speeds(test_speeds, "test_speeds")
        self.th_range_ = (float(th.min()) / 2, float(th.max()) * 2)
        rng = np.random.default_rng(self.seed)
        # Schedule, in presentation steps: training epochs (shuffled speeds, teacher on,
        # learning on) with a recall block (every test speed, both off) after some epochs.
        curve_after = set(np.unique(np.linspace(0, self.epochs, self.curve_points + 1)
                                    .round().astype(int))[1:]) | {0}
        speed_col, teach, learn, blocks = [], [], [], []
        for epoch in range(self.epochs + 1):
            if epoch in curve_after:
                blocks.append((epoch, len(speed_col) // 2))
                speed_col += list(np.repeat(test, 2))
                teach += [0.0] * (2 * len(test))
                learn += [0.0] * (2 * len(test))
            if epoch == self.epochs:
                break
            order = rng.permutation(len(speeds))
            speed_col += list(np.repeat(speeds[order], 2))
            teach += list(np.repeat(np.clip(self.encode(th[order]), 0, None), 2))
            # Each presentation: the first half lets the rates settle on the new speed, the
            # second half learns (stale rate traces would teach the previous speed's error).
            learn += [0.0, 1.0] * len(speeds)
        spike_i, spike_t, w, _ = self._network(
            np.asarray(speed_col, float)[:, None], np.asarray(teach), np.asarray(learn),
            self.present_s / 2, np.zeros(self.n_speed_neurons))
        self.weights_ = w
        rates = self._block_rates(spike_t, [start for _, start in blocks], len(test))
        self.learning_curve_ = xr.DataArray(
            self.decode(rates), dims=("epoch", "speed_cm_s"),
            coords={"epoch": [e for e, _ in blocks], "speed_cm_s": test},
            name="recalled_th", attrs={"units": "g", "long_name": "recalled threshold"})
        self.trained_speeds_ = speeds
        self.trained_th_ = th
        return self

    def _block_rates(self, spike_t: np.ndarray, starts: list[int], n: int) -> np.ndarray:
        """Read-out rate over the second half of each presentation of each block."""
        out = np.zeros((len(starts), n))
        for b, start in enumerate(starts):
            for j in range(n):
                t0 = (start + j + 0.5) * self.present_s
                t1 = (start + j + 1) * self.present_s
                out[b, j] = np.count_nonzero((spike_t >= t0) & (spike_t < t1)) / (t1 - t0)
        return out

    def _require_fit(self) -> None:
        if not hasattr(self, "weights_"):
            raise SpecError("SpeedGate", "not fitted", "call fit(speeds, th_star) first")

    def predict(self, speeds) -> np.ndarray:
        """Recall Th for each constant speed (no teacher, no learning)."""
        self._require_fit()
        v = self.check_speeds(speeds)
        n = len(np.atleast_1d(v))
        _, spike_t, _, _ = self._network(np.atleast_1d(v)[:, None], np.zeros(n), np.zeros(n),
                                         self.present_s, self.weights_)
        return self.decode(self._block_rates(spike_t, [0], n)[0])

    def thresholds(self, speed_cm_s: np.ndarray, rate_hz: float,
                   warmup_s: float = 1.0) -> np.ndarray:
        """Th at every sample of one or more scenes, recalled online from their speed.

        ``speed_cm_s`` is (n_samples,) or (n_samples, n_scenes). The gate runs ``warmup_s``
        at each scene's first speed before it starts (the motor command precedes the
        motion); the read-out's slow rate trace (``tau_read_s``) is decoded at each sample.
        """
        self._require_fit()
        v = np.asarray(speed_cm_s, dtype=float)
        single = v.ndim == 1
        v = v[:, None] if single else v
        self.check_speeds(v)
        check(np.isfinite(rate_hz) and rate_hz > 0, "rate_hz", rate_hz, "a rate > 0 Hz")
        warm = int(round(warmup_s * rate_hz))
        padded = np.r_[np.repeat(v[:1], warm, axis=0), v]
        n = len(padded)
        _, _, _, read = self._network(padded, np.zeros(n), np.zeros(n), 1.0 / rate_hz,
                                      self.weights_, record_read_every_s=1.0 / rate_hz)
        th = self.decode(read[warm:warm + len(v)])
        return th[:, 0] if single else th


# -- what the gate learns ------------------------------------------------------------------------
def th_star_from_summary(path) -> tuple[np.ndarray, np.ndarray]:
    """The training speeds and their Th* from a gating study's ``summary.json``: the same
    examples that study taught its own gate."""
    import json
    from pathlib import Path

    accepted = "the summary.json of a studies/gating_threshold.toml run"
    try:
        summary = json.loads(Path(path).read_text())
        th_star = {float(v): float(t) for v, t in summary["th_star"].items()}
        speeds = np.asarray(summary["train_speeds_cm_s"], dtype=float)
        return speeds, np.array([th_star[float(v)] for v in speeds])
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise SpecError("from_summary", str(path), accepted) from None


@dataclass
class GateTraining:
    """Th*(speed) examples the gate learns: the spec's lists, or a gating run's summary."""
    speeds_cm_s: list = (0.0, 30.0)
    th_star_g: list = (0.1, 0.6)
    from_summary: str | None = None     # replaces the lists above

    def __post_init__(self):
        bounds.declared(self)

    def examples(self) -> tuple[np.ndarray, np.ndarray]:
        if self.from_summary is not None:
            return th_star_from_summary(self.from_summary)
        v, th = np.asarray(self.speeds_cm_s, float), np.asarray(self.th_star_g, float)
        check(v.shape == th.shape and len(v) >= 2, "th_star_g", self.th_star_g,
              "one threshold per speed, at least two")
        return v, th
