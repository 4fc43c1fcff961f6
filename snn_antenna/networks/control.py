"""The control layer in Brian2: class-I neurons that act on contacts (the paper's Fig. 3).

- ``contact`` unit: one class-I neuron excited by the resonators tuned above the self-motion
  band and inhibited by those in and below it, each through an exponential synaptic current.
  Self-motion alone keeps it below rheobase; a contact shifts activity above the band and it
  fires: the spiking form of the contact rule (``readout.contacts.ContactDetector``:
  above-band activity beating the rest). The decision is the neuron's, inside Brian2, so it
  shares the rule's definition rather than calling it: the same band
  (``resonators.SELF_MOTION_BAND_HZ``) and the same split of the array
  (``resonators.tuned_above``). The rule's ``min_rate_hz`` has no one-to-one counterpart: here
  the margin between ``bias`` and rheobase, over ``w_above`` and ``tau_syn_ms``, sets how much
  above-band activity it takes.
- ``motor`` unit: one class-I neuron excited by the contact unit; its first spike is the stop
  command to the wheels (the closed loop sets the speed command to 0). Once the robot stops
  its self-motion ends and the resonators fall silent (Fig. 10H).

- ``MaterialUnit``: one class-I neuron per material class, fed by the resonators through
  ``Synapses`` whose weights are a linear read-out of the resonators' rates fit offline
  (scikit-learn ``LogisticRegression`` on the filtered resonator spike trains of bench
  contacts). Its mean input is
  ``bias + gain · logit``, so the most active neuron names the material. The intercept is
  gated by the resonators' summed activity, so silent resonators leave every neuron at
  ``bias``, below rheobase (no spikes at rest). The material shows in the high mode (decay,
  stiffness): feed the unit a high-band array. Measured (``tests/test_material.py``,
  2026-11-23), metal vs non-metal on unseen bench contacts at unseen positions: 419 of 640
  correct over 20 train/test seed pairs (65.5 %, Wilson 95 % interval 61.7–69.1 %; one seed
  of 32 contacts ranged from 15 to 26 correct, too few to tell the unit from chance).

All use ``neurons.equations("class1", ...)``: rate grows with input current above rheobase.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import bounds
from ..errors import SpecError, check, is_number
from ..sources import antenna
from . import neurons
from .resonators import SELF_MOTION_BAND_HZ, tuned_above

# Time constant (ms) of the exponential synaptic current into every class-I unit (contact,
# motor, material): short against the read-out's 0.1 s window, so a unit follows the activity
# window by window as the read-out does, and long enough for the spikes of several resonators
# to add up.
CLASS1_TAU_SYN_MS = 20.0


@dataclass
class ControlLayer:
    motion_band_hz: tuple = SELF_MOTION_BAND_HZ   # the contact rule's band
    w_above: float = 2.0                  # current per above-band resonator spike
    w_band: float = 2.0                   # inhibition per in-band resonator spike
    w_motor: float = 40.0                 # contact unit → motor unit
    tau_syn_ms: float = CLASS1_TAU_SYN_MS
    bias: float = 20.0                    # just below the class-I rheobase (22.6)
    dt_ms: float = 0.1

    def __post_init__(self):
        for name in ("w_above", "w_band", "w_motor", "tau_syn_ms", "dt_ms"):
            v = getattr(self, name)
            check(is_number(v) and v > 0, name, v, "a finite value > 0")
        bounds.pair("motion_band_hz", self.motion_band_hz, unit=" Hz")

    def objects(self, resonators, neuron_hz: np.ndarray) -> dict:
        """Contact and motor units wired to a resonator group (``resonators``)."""
        import brian2 as b2

        dt = self.dt_ms * b2.ms
        units = {}
        for name in ("contact", "motor"):
            units[name] = class1_group(1, self.bias, self.tau_syn_ms, self.dt_ms,
                                       f"control_{name}")
        is_above = tuned_above(neuron_hz, self.motion_band_hz)
        above, band = np.flatnonzero(is_above), np.flatnonzero(~is_above)
        sense = b2.Synapses(resonators, units["contact"], "w : 1", on_pre="I_syn_post += w",
                            dt=dt, name="control_sense")
        sense.connect(i=np.r_[above, band].astype(int), j=0)
        sense.w = np.r_[np.full(len(above), self.w_above), np.full(len(band), -self.w_band)]
        act = b2.Synapses(units["contact"], units["motor"], on_pre=f"I_syn_post += {self.w_motor!r}",
                          dt=dt, name="control_act")
        act.connect()
        return {"control_contact": units["contact"], "control_motor": units["motor"],
                "control_sense": sense, "control_act": act}


def class1_group(n: int, bias, tau_syn_ms: float, dt_ms: float, name: str, *,
                 input_terms: str = "", extra: str = "", namespace: dict | None = None):
    """``n`` class-I neurons driven by ``bias`` + an exponential synaptic current ``I_syn``
    (+ ``input_terms``, whose variables ``extra`` declares)."""
    import brian2 as b2

    eqs = neurons.equations("class1", "bias + I_syn" + input_terms,
                            "dI_syn/dt = -I_syn / tau_syn : 1\nbias : 1 (constant)\n" + extra)
    class1 = neurons.PRESETS["class1"]
    g = b2.NeuronGroup(n, eqs, threshold=neurons.THRESHOLD, reset=neurons.reset(),
                       method="euler",
                       namespace={"tau_syn": tau_syn_ms * b2.ms, **(namespace or {})},
                       dt=dt_ms * b2.ms, name=name)
    g.k, g.a, g.b, g.c, g.d = 1.0, class1.a, class1.b, class1.c, class1.d
    g.bias = bias
    g.v, g.u = neurons.resting_state("class1", current=float(np.min(bias)))
    return g


METALS = ("stainless_steel", "brass", "copper", "aluminium")
MATERIAL_CLASSES = {"metal": list(METALS),
                    "non_metal": [m for m in antenna.MATERIALS if m not in METALS]}


@dataclass
class MaterialUnit:
    """Class-I neurons, one per material class, whose rates name the contacted material.

    ``classes`` maps a class name to its materials (default metal / non-metal; one class per
    material is ``{m: [m] for m in antenna.MATERIALS}``). ``fit(features, materials)`` trains
    the read-out (scikit-learn: standardised ``LogisticRegression``) on the resonators'
    ``spiking.SpikeFeatures.matrix()`` over bench contacts, one ``window_s`` each. In the
    network, every ``window_s`` the read-out takes the resonators' spikes of the window just
    past (count, first-spike latency, firing span per resonator) and sets each material
    neuron's input to ``bias + drive · p(class)``: during the next window the most active
    neuron names the material; without resonator spikes every input stays at ``bias``, below
    rheobase, and the unit is silent.
    """
    classes: dict = field(default_factory=lambda: dict(MATERIAL_CLASSES))
    window_s: float = 0.5
    drive: float = 20.0
    bias: float = 20.0                    # just below the class-I rheobase (22.6)
    min_spikes: int = 1                   # resonator spikes in a window that make a contact
    regularisation_c: float = 1.0         # LogisticRegression's C
    dt_ms: float = 0.1

    def __post_init__(self):
        check(isinstance(self.classes, dict) and len(self.classes) >= 2, "classes",
              self.classes, "a table of at least two classes, name = [materials]")
        seen = set()
        for name, members in self.classes.items():
            check(isinstance(members, (list, tuple)) and len(members) >= 1,
                  f"classes.{name}", members, "a non-empty list of materials")
            for m in members:
                antenna.check_material(m)
                check(m not in seen, f"classes.{name}", m, "each material in one class only")
                seen.add(m)
        for name in ("window_s", "drive", "regularisation_c", "dt_ms"):
            v = getattr(self, name)
            check(np.isfinite(v) and v > 0, name, v, "a finite value > 0")
        check(np.isfinite(self.bias), "bias", self.bias, "a finite value")
        check(isinstance(self.min_spikes, int) and self.min_spikes >= 1, "min_spikes",
              self.min_spikes, "an integer >= 1")

    @property
    def class_names(self) -> list[str]:
        return list(self.classes)

    def class_of(self, materials) -> np.ndarray:
        lookup = {m: name for name, members in self.classes.items() for m in members}
        for m in set(materials):
            check(m in lookup, "materials", m, f"a material of the classes: {sorted(lookup)}")
        return np.array([lookup[m] for m in materials])

    def fit(self, features: np.ndarray, materials) -> "MaterialUnit":
        """Train the read-out: ``features`` (events, 3 × resonators) as
        ``SpikeFeatures.matrix()`` of this network's resonators over ``window_s``."""
        from sklearn.linear_model import LogisticRegression
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        X = np.asarray(features, dtype=float)
        y = self.class_of(materials)
        check(X.ndim == 2 and len(X) == len(y) and np.isfinite(X).all(), "features",
              f"shape {X.shape}", "finite features, one row per material")
        check(set(y) == set(self.class_names), "materials", sorted(set(y)),
              f"contacts of every class {self.class_names}")
        self.readout_ = make_pipeline(
            StandardScaler(), LogisticRegression(C=self.regularisation_c, max_iter=5000)
        ).fit(X, y)
        self.order_ = [list(self.readout_.classes_).index(c) for c in self.class_names]
        return self

    def probabilities(self, features: np.ndarray) -> np.ndarray:
        """p(class) per event, columns in ``class_names`` order."""
        self._check_fitted()
        return self.readout_.predict_proba(np.asarray(features, dtype=float))[:, self.order_]

    def _check_fitted(self):
        if not hasattr(self, "readout_"):
            raise SpecError("network.material", "unfitted",
                            "a fitted MaterialUnit: build(..., fitted={'material': "
                            "MaterialUnit(...).fit(features, materials)})")

    def objects(self, resonators) -> dict:
        """The material neurons (``material``), a monitor of ``resonators`` and the read-out
        that turns each window's resonator spikes into the neurons' inputs."""
        import brian2 as b2

        self._check_fitted()
        n_res = len(resonators)
        check(self.readout_.n_features_in_ == 3 * n_res, "network.material",
              f"{self.readout_.n_features_in_} features", f"3 per resonator ({3 * n_res}): "
              "fit on SpikeFeatures of this network's array")
        unit = class1_group(len(self.classes), self.bias, CLASS1_TAU_SYN_MS, self.dt_ms,
                            "material", input_terms=" + drive * p", extra="p : 1",
                            namespace={"drive": self.drive})
        listen = b2.SpikeMonitor(resonators, name="material_listen")
        seen = {"n": 0}

        @b2.network_operation(dt=self.window_s * b2.second, when="start",
                              name="material_read")
        def read(t):
            end = float(t / b2.second)
            i = np.asarray(listen.i[seen["n"]:])
            t_s = np.asarray(listen.t_[seen["n"]:]) - (end - self.window_s)
            seen["n"] += len(i)
            if end <= 0 or len(i) < self.min_spikes:
                unit.p = 0.0
                return
            counts, latency, span = neurons.spike_summary(i, t_s, n_res, self.window_s)
            unit.p = self.probabilities(np.r_[counts, latency, span][None])[0]

        return {"material": unit, "material_listen": listen, "material_read": read}
