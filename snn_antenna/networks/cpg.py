"""A central pattern generator in Brian2 that sweeps the antenna's pan and tilt joints.

The paper's pan-tilt unit followed a limit cycle of 2 s, and speed could modulate the cycle
frequency "to reduce possible shadow areas" (Patanè et al. 2012, Fig. 3). Here the rhythm is a
ring of ``n_neurons`` leaky integrate-and-fire neurons passing one token of excitation around:

    dv/dt = (drive + token·S − hold − v) / τ,   spike at v ≥ 1, then v ← 0, token ← 0

A spike of neuron i gives the token to neuron i + 1 and takes it from every other neuron
(all-to-all synapses: excitation of the successor, inhibition of the rest), so exactly one
neuron integrates at a time and a stray token is wiped at the next spike: the ring recovers
its rhythm after a perturbation. Idle neurons rest at v = drive < 1; the token holder climbs
from there and fires after the latency τ·ln(S / (drive + S − 1)). The period is ``n_neurons``
latencies, so ``drive`` follows from the wanted frequency in closed form,
drive = 1 − S·(1 − e^(−latency/τ)), and the frequency rises with the robot's speed:
f = f₀ · (1 + speed_gain · v / 30 cm/s).

Joint angles are the ring's population vector, filtered: each neuron's spikes feed an
alpha-shaped trace x_j (two exponential stages of τ_x, so the vector turns smoothly between
spikes instead of jumping 360°/N at each); the phase φ = arg Σ x_j e^{2πij/N} drives pan = c_p +
A_p cos φ and
tilt = c_t + A_t cos(φ − offset), so the tip sweeps an area (offset 90° by default) and both
angles stay within their ranges (the paper's: pan 80° centred 40° to the side, tilt 90°
centred 10° above the horizon).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import bounds
from ..core.errors import check
from . import neurons


# A spike of neuron i writes every neuron's token (all-to-all synapses, so each neuron is the
# target of many). Brian2 cannot prove such a write independent of the synapses' order and
# warns "abstract code block may not be well-defined" when it generates the code. Each spike
# writes each token once, so the order only matters if two ring neurons fire in the same step,
# which the one-token ring does not do: the warning is filtered for this statement alone.
PASS_TOKEN = "token_post = int(j == (i + 1) % n_ring)"
ORDER_WARNING = ("abstract code block that may not be well-defined",
                 "token_post = int(j == ((i + 1) % n_ring))")   # as Brian2 prints the code


@dataclass
class CPG:
    period_s: float = 2.0              # at speed 0 (the paper's limit cycle)
    speed_gain: float = 1.0            # frequency × (1 + gain) at 30 cm/s
    n_neurons: int = 24
    tau_ms: float = 50.0
    token_drive: float = 1.0           # S
    trace_ms: float = 60.0             # τ_x of the angle read-out
    pan_centre_deg: float = 40.0
    pan_amplitude_deg: float = 40.0
    tilt_centre_deg: float = 10.0
    tilt_amplitude_deg: float = 45.0
    phase_offset_deg: float = 90.0     # tilt lags pan
    dt_ms: float = 0.5
    target: str = "numpy"

    def __post_init__(self):
        bounds.declared(self)
        bounds.choice("target", self.target, ("numpy", "cython"))
        for name in ("period_s", "tau_ms", "token_drive", "trace_ms", "dt_ms"):
            v = getattr(self, name)
            check(np.isfinite(v) and v > 0, name, v, "a finite value > 0")
        check(np.isfinite(self.speed_gain) and self.speed_gain >= 0, "speed_gain",
              self.speed_gain, "a gain >= 0")
        check(isinstance(self.n_neurons, int) and 3 <= self.n_neurons <= 1000, "n_neurons",
              self.n_neurons, "an integer in [3, 1000]")
        for name in ("pan_centre_deg", "pan_amplitude_deg", "tilt_centre_deg",
                     "tilt_amplitude_deg", "phase_offset_deg"):
            v = getattr(self, name)
            bounds.number(name, v, -360.0, 360.0, unit=" deg")
        check(self.drive_for(self.frequency_hz(0.0)) >= 0.0, "period_s", self.period_s,
              "a period the ring can reach with token_drive (lower token_drive, or raise "
              "tau_ms, for slower cycles)")

    def frequency_hz(self, speed_cm_s) -> np.ndarray:
        return (1 + self.speed_gain * np.asarray(speed_cm_s, float) / 30.0) / self.period_s

    def drive_for(self, frequency_hz) -> np.ndarray:
        """The tonic drive whose token latency gives this cycle frequency."""
        step_ms = 1000.0 / (self.n_neurons * np.asarray(frequency_hz, float))
        return 1.0 - self.token_drive * (1.0 - np.exp(-step_ms / self.tau_ms))

    def phase(self, traces: np.ndarray) -> np.ndarray:
        """The ring's phase φ (radians, in (−π, π]) from traces of shape (..., n_neurons):
        the angle of their population vector."""
        z = np.asarray(traces, float) @ np.exp(2j * np.pi * np.arange(self.n_neurons)
                                               / self.n_neurons)
        return np.angle(z)

    def angles(self, traces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(pan, tilt) in degrees from ring traces of shape (..., n_neurons)."""
        phi = self.phase(traces)
        pan = self.pan_centre_deg + self.pan_amplitude_deg * np.cos(phi)
        tilt = self.tilt_centre_deg + self.tilt_amplitude_deg * np.cos(
            phi - np.deg2rad(self.phase_offset_deg))
        return pan, tilt

    # -- Brian2 -----------------------------------------------------------------------------
    def objects(self, speed_expr: str = "speed_cm_s", hold_expr: str = "0",
                namespace: dict | None = None, extra: str = "speed_cm_s : 1 (shared)",
                clock=None):
        """The ring's NeuronGroup and Synapses (named ``cpg`` and ``cpg_ring``).

        ``speed_expr`` is the speed command (e.g. a TimedArray ``speed(t)`` or a shared
        variable written by the closed loop); ``hold_expr`` an inhibitory hold (perturbation).
        ``clock``: a Brian2 clock of step ``dt_ms`` to share (by default one of the ring's own).
        """
        import brian2 as b2

        ns = {"tau": self.tau_ms * b2.ms, "tau_x": self.trace_ms * b2.ms,
              "S": self.token_drive, "n_ring": self.n_neurons, "period": self.period_s,
              "gain": self.speed_gain, **(namespace or {})}
        eqs = f"""
        dv/dt = (drive + token * S - hold - v) / tau : 1
        dx/dt = (y - x) / tau_x : 1
        dy/dt = -y / tau_x : 1
        drive = 1 - S * (1 - exp(-step / tau)) : 1
        step = period / (n_ring * (1 + gain * speed / 30)) * second : second
        speed = {speed_expr} : 1
        hold = {hold_expr} : 1
        token : 1
        {extra}
        """
        if clock is None:
            clock = b2.Clock(dt=self.dt_ms * b2.ms, name="cpg_clock*")
        ring = b2.NeuronGroup(self.n_neurons, eqs, threshold="v >= 1",
                              reset="v = 0; token = 0; y += 1", method="euler",
                              namespace=ns, clock=clock, name="cpg")
        ring.token = 0
        ring.token[0] = 1
        pass_token = b2.Synapses(ring, ring, on_pre=PASS_TOKEN, namespace=ns, clock=clock,
                                 name="cpg_ring")
        neurons.quiet_known_warning("brian2.codegen.generators.base", *ORDER_WARNING)
        pass_token.connect()
        return ring, pass_token

    def run(self, speed_cm_s, duration_s: float, step_s: float = 0.01,
            hold: np.ndarray | None = None) -> dict:
        """Run the CPG alone on a speed command (held ``step_s`` per value); angles over time.

        ``hold`` (same length as the speed command) is an inhibitory input, e.g. a pulse that
        stalls the ring as a perturbation would.
        """
        import brian2 as b2

        v = np.broadcast_to(np.asarray(speed_cm_s, float), (int(round(duration_s / step_s)),))
        check(bool(np.all(np.isfinite(v))) and bool(np.all(v >= 0)), "speed_cm_s",
              "speeds", "finite speeds >= 0 cm/s")
        b2.start_scope()
        b2.prefs.codegen.target = self.target
        ns = {"speed_command": b2.TimedArray(np.ascontiguousarray(v), dt=step_s * b2.second),
              "hold_input": b2.TimedArray(np.zeros_like(v) if hold is None
                                          else np.asarray(hold, float), dt=step_s * b2.second)}
        ring, syn = self.objects("speed_command(t)", "hold_input(t)", ns, extra="")
        mon = b2.StateMonitor(ring, "x", record=True, dt=step_s * b2.second)
        spikes = b2.SpikeMonitor(ring)
        b2.Network(ring, syn, mon, spikes).run(duration_s * b2.second, namespace={})
        pan, tilt = self.angles(np.asarray(mon.x).T)
        return {"t_s": np.asarray(mon.t_), "pan_deg": pan, "tilt_deg": tilt,
                "spike_i": np.asarray(spikes.i[:]), "spike_t_s": np.asarray(spikes.t_[:])}


def cycle_periods(t_s: np.ndarray, angle_deg: np.ndarray) -> np.ndarray:
    """Periods between upward crossings of the angle's mean (linear interpolation)."""
    x = angle_deg - (angle_deg.max() + angle_deg.min()) / 2
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    t_cross = t_s[up] - x[up] * (t_s[up + 1] - t_s[up]) / (x[up + 1] - x[up])
    return np.diff(t_cross)


def phase_lag_deg(t_s: np.ndarray, lead: np.ndarray, lag: np.ndarray, period_s: float) -> float:
    """How far ``lag`` trails ``lead`` (degrees), from their mean-crossing times."""
    def crossings(a):
        x = a - (a.max() + a.min()) / 2
        up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
        return t_s[up] - x[up] * (t_s[up + 1] - t_s[up]) / (x[up + 1] - x[up])
    a, b = crossings(lead), crossings(lag)
    lags = [((bb - a[a <= bb].max()) / period_s * 360.0) % 360.0 for bb in b if (a <= bb).any()]
    return float(np.median(lags))
