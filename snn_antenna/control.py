"""The control layer in Brian2: class-I neurons that act on contacts (the paper's Fig. 3).

- ``contact`` unit: one class-I neuron excited by the resonators tuned above the self-motion
  band and inhibited by those in it, each through an exponential synaptic current. Self-motion
  alone keeps it below rheobase; a contact shifts activity above the band and it fires: the
  spiking form of ``readout.ContactDetector``'s rule (above-band activity beating the band).
- ``motor`` unit: one class-I neuron excited by the contact unit; its first spike is the stop
  command to the wheels (the closed loop sets the speed command to 0). Once the robot stops
  its self-motion ends and the resonators fall silent (Fig. 10H).

Both use ``neurons.equations("class1", ...)``: rate grows with input current above rheobase.
The material unit of the paper's control layer is not built here (see the report).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import neurons
from .errors import check


@dataclass
class ControlLayer:
    motion_band_hz: tuple = (7.0, 10.5)   # as readout.ContactDetector
    w_above: float = 2.0                  # current per above-band resonator spike
    w_band: float = 2.0                   # inhibition per in-band resonator spike
    w_motor: float = 40.0                 # contact unit → motor unit
    tau_syn_ms: float = 20.0
    bias: float = 20.0                    # just below the class-I rheobase (22.6)
    dt_ms: float = 0.1

    def __post_init__(self):
        for name in ("w_above", "w_band", "w_motor", "tau_syn_ms", "dt_ms"):
            v = getattr(self, name)
            check(np.isfinite(v) and v > 0, name, v, "a finite value > 0")
        lo, hi = self.motion_band_hz
        check(0 <= lo <= hi, "motion_band_hz", self.motion_band_hz, "[low, high] Hz")

    def objects(self, resonators, neuron_hz: np.ndarray) -> dict:
        """Contact and motor units wired to a resonator group (``resonators``)."""
        import brian2 as b2

        ns = {"tau_syn": self.tau_syn_ms * b2.ms}
        dt = self.dt_ms * b2.ms
        eqs = neurons.equations("class1", "bias + I_syn",
                                "dI_syn/dt = -I_syn / tau_syn : 1\nbias : 1 (constant)")
        class1 = neurons.PRESETS["class1"]
        units = {}
        for name in ("contact", "motor"):
            g = b2.NeuronGroup(1, eqs, threshold=f"v >= {neurons.V_PEAK}",
                               reset="v = c; u = u + d", method="euler", namespace=ns, dt=dt,
                               name=f"control_{name}")
            g.k, g.a, g.b, g.c, g.d = 1.0, class1.a, class1.b, class1.c, class1.d
            g.bias = self.bias
            g.v, g.u = neurons.resting_state("class1", current=self.bias)
            units[name] = g
        above = np.flatnonzero(np.asarray(neuron_hz) > self.motion_band_hz[1])
        band = np.flatnonzero(np.asarray(neuron_hz) <= self.motion_band_hz[1])
        sense = b2.Synapses(resonators, units["contact"], "w : 1", on_pre="I_syn_post += w",
                            dt=dt, name="control_sense")
        sense.connect(i=np.r_[above, band].astype(int), j=0)
        sense.w = np.r_[np.full(len(above), self.w_above), np.full(len(band), -self.w_band)]
        act = b2.Synapses(units["contact"], units["motor"], on_pre=f"I_syn_post += {self.w_motor!r}",
                          dt=dt, name="control_act")
        act.connect()
        return {"control_contact": units["contact"], "control_motor": units["motor"],
                "control_sense": sense, "control_act": act}
