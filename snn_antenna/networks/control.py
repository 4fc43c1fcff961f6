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

- ``MaterialUnit``: one class-I neuron per material class, driven each window by a
  read-out of the resonators' spikes of the window just past, fit offline (scikit-learn
  ``LogisticRegression`` on the same network's spikes of bench contacts). Its input is
  ``bias + drive · p(class)``, so the most active neuron names the material; silent
  resonators leave every neuron at ``bias``, below rheobase (no spikes at rest). On the
  bench's contact physics the material sits in the struck rods' own bending modes
  (107–377 Hz, a few % of the impact; a metal rod rings for 0.5–1.2 s, wood and plastics for
  50–105 ms): feed the unit the rod band (``networks/bench_material.toml``: the baseline
  study's ``[spiking.bank.bands.rod]``) over whole 0.5 s contacts, and read each resonator's
  decay through its counts in time bins (``bin_edges_s``). Measured in
  ``tests/test_material.py`` (see there).

All use ``neurons.equations("class1", ...)``: rate grows with input current above rheobase.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import bounds
from ..core.errors import SpecError, check, is_number
from ..sources import antenna
from . import neurons
from .resonators import SELF_MOTION_BAND_HZ, tuned_above

# Time constant (ms) of the exponential synaptic current into every class-I unit (contact,
# motor, material): short against the read-out's 0.1 s window, so a unit follows the activity
# window by window as the read-out does, and long enough for the spikes of several resonators
# to add up.
CLASS1_TAU_SYN_MS = 20.0
# The control layer's units, in the order of its group's neurons.
CONTROL_UNITS = ("contact", "motor")


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
        bounds.declared(self)
        for name in ("w_above", "w_band", "w_motor", "tau_syn_ms", "dt_ms"):
            v = getattr(self, name)
            check(is_number(v) and v > 0, name, v, "a finite value > 0")
        bounds.pair("motion_band_hz", self.motion_band_hz, unit=" Hz")
        bounds.amplitude("bias", self.bias)

    def unit_rows(self) -> dict:
        """The contact and motor units (``neurons.Class1Rows``), in ``CONTROL_UNITS``' order."""
        return {f"control_{unit}": neurons.Class1Rows(1, self.bias, self.tau_syn_ms,
                                                      rest_current=self.bias)
                for unit in CONTROL_UNITS}

    def objects(self, resonators, neuron_hz: np.ndarray, clock=None, units=None) -> dict:
        """Contact and motor units wired to a resonator group (``resonators``). ``clock``: a
        Brian2 clock of step ``dt_ms`` to share (by default one of the layer's own).

        Both units are one two-neuron group (``control``; ``control_contact`` and
        ``control_motor`` are its Subgroups, for wiring): the same model, and Subgroups share
        their group's Brian2 code, so two units cost one group's calls per step. ``units``:
        the Subgroups ``control_contact`` and ``control_motor`` of a class-I group shared with
        other parts (``neurons.class1_units`` of ``unit_rows``) instead of a group of the
        layer's own. Each unit counts its spikes (``unit_spike_counts`` reads them)."""
        import brian2 as b2

        own = {}
        if units is None:
            if clock is None:
                clock = b2.Clock(dt=self.dt_ms * b2.ms, name="control_clock*")
            own["control"], units = neurons.class1_units(self.unit_rows(), clock, "control")
        contact, motor = (units[f"control_{unit}"] for unit in CONTROL_UNITS)
        clock = contact.source.clock
        is_above = tuned_above(neuron_hz, self.motion_band_hz)
        above, band = np.flatnonzero(is_above), np.flatnonzero(~is_above)
        # Its pathway steps with the array, whose spikes it carries (Brian2 runs a pathway
        # on its source's clock) and which runs at a finer dt than the units: Brian2 warns of
        # the mismatch at every build, which is this design; the pathway has no delay to round.
        neurons.quiet_known_warning("brian2.synapses.synapses.synapses_dt_mismatch",
                                    "synaptic pathway 'control_sense_pre'", "using a dt of")
        sense = b2.Synapses(resonators, contact, "w : 1", on_pre="I_syn_post += w",
                            clock=clock, name="control_sense")
        sense.connect(i=np.r_[above, band].astype(int), j=0)
        sense.w = np.r_[np.full(len(above), self.w_above), np.full(len(band), -self.w_band)]
        act = b2.Synapses(contact, motor, on_pre=f"I_syn_post += {self.w_motor!r}",
                          clock=clock, name="control_act")
        act.connect()
        return {**own, "control_contact": contact, "control_motor": motor,
                "control_sense": sense, "control_act": act}


def unit_spike_counts(objects: dict) -> np.ndarray:
    """The control units' spike counts (in ``CONTROL_UNITS``' order) of the parts'
    ``objects``, as a live view of the array Brian2 steps: a caller on the network's clock
    reads them without a monitor. (Brian2 hands out the whole group's array for a Subgroup's
    variable; the units are adjacent rows of it.)"""
    first, last = objects["control_contact"], objects["control_motor"]
    return first.variables["spike_count"].get_value()[first.start:last.stop]


METALS = ("stainless_steel", "brass", "copper", "aluminium")
MATERIAL_CLASSES = {"metal": list(METALS),
                    "non_metal": [m for m in antenna.MATERIALS if m not in METALS]}


@dataclass
class MaterialUnit:
    """Class-I neurons, one per material class, whose rates name the contacted material.

    ``classes`` maps a class name to its materials (default metal / non-metal; one class per
    material is ``{m: [m] for m in antenna.MATERIALS}``). ``fit(features, materials)`` trains
    the read-out (scikit-learn: standardised ``LogisticRegression``) on ``window_features`` of
    this network's resonators over bench contacts, one ``window_s`` each
    (``readout.spiking.window_features`` runs them). In the network, every ``window_s`` the
    read-out takes the resonators' spikes of the window just past through the same
    ``window_features`` and sets each material neuron's input to ``bias + drive · p(class)``:
    during the next window the most active neuron names the material; without resonator
    spikes every input stays at ``bias``, below rheobase, and the unit is silent.
    """
    classes: dict = field(default_factory=lambda: dict(MATERIAL_CLASSES))
    window_s: float = 0.5
    # Inner edges (s from the window's start) of the time bins whose spike counts trace each
    # resonator's decay, as the baseline study's bank (``SpikingBank.bin_edges_s``): a struck
    # metal rod still rings after 0.2 s, a wooden or plastic one has died away.
    bin_edges_s: tuple = (0.1, 0.2, 0.3)
    drive: float = 20.0
    bias: float = 20.0                    # just below the class-I rheobase (22.6)
    min_spikes: int = 1                   # resonator spikes in a window that make a contact
    regularisation_c: float = 1.0         # LogisticRegression's C
    dt_ms: float = 0.1

    def __post_init__(self):
        bounds.declared(self)
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
            check(is_number(v) and v > 0, name, v, "a finite value > 0")
        bounds.amplitude("bias", self.bias)
        check(isinstance(self.min_spikes, int) and self.min_spikes >= 1, "min_spikes",
              self.min_spikes, "an integer >= 1")
        edges = self.bin_edges_s
        check(isinstance(edges, (list, tuple)) and all(is_number(e) for e in edges)
              and all(0 < e < self.window_s for e in edges)
              and all(a < b for a, b in zip(edges, edges[1:])), "bin_edges_s", edges,
              f"increasing times inside the window (0 < t < window_s = {self.window_s:g} s), "
              "or [] for no time bins")
        self.bin_edges_s = tuple(float(e) for e in edges)

    def n_features(self, n_resonators: int) -> int:
        """Width of a ``window_features`` row for ``n_resonators`` resonators."""
        n_bins = len(self.bin_edges_s) + 1 if self.bin_edges_s else 0
        return n_resonators * (3 + n_bins)

    def window_features(self, spike_i, spike_t_s, n_resonators: int,
                        n_windows: int = 1) -> np.ndarray:
        """What the read-out sees: one row per window of ``window_s`` (spike times from the
        first window's start; later spikes count in the last), per resonator its spike count,
        first-spike latency and firing span (``neurons.spike_summary``, times from its
        window's start), then its counts in the time bins (``neurons.binned_spike_counts``),
        resonator by resonator: the baseline study's ``spiking_rod`` input, per window. The
        one definition for fitting (``readout.spiking.window_features``) and the network."""
        i = np.asarray(spike_i, dtype=int)
        t = np.asarray(spike_t_s, dtype=float)
        window = np.clip((t // self.window_s).astype(int), 0, n_windows - 1)
        neuron, t_in = window * n_resonators + i, t - window * self.window_s
        total = n_resonators * n_windows
        parts = [x.reshape(n_windows, -1)
                 for x in neurons.spike_summary(neuron, t_in, total, self.window_s)]
        if self.bin_edges_s:
            parts.append(neurons.binned_spike_counts(neuron, t_in, total, self.bin_edges_s)
                         .reshape(n_windows, -1))
        return np.hstack(parts).astype(float)

    @property
    def class_names(self) -> list[str]:
        return list(self.classes)

    def class_of(self, materials) -> np.ndarray:
        lookup = {m: name for name, members in self.classes.items() for m in members}
        for m in set(materials):
            check(m in lookup, "materials", m, f"a material of the classes: {sorted(lookup)}")
        return np.array([lookup[m] for m in materials])

    def fit(self, features: np.ndarray, materials) -> MaterialUnit:
        """Train the read-out: ``features``, one ``window_features`` row per contact, of this
        network's resonators; ``materials`` the contacts' materials (labels: fit only)."""
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
        check(self.readout_.n_features_in_ == self.n_features(n_res), "network.material",
              f"{self.readout_.n_features_in_} features",
              f"{self.n_features(n_res)} ({self.n_features(n_res) // n_res} per resonator): "
              "fit on window_features of this network's array")
        clock = b2.Clock(dt=self.dt_ms * b2.ms, name="material_clock*")
        unit, _ = neurons.class1_units(
            {"material_units": neurons.Class1Rows(
                len(self.classes), self.bias, CLASS1_TAU_SYN_MS, rest_current=self.bias,
                input_terms=" + drive * p", equations="p : 1",
                namespace={"drive": self.drive})}, clock, "material")
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
            unit.p = self.probabilities(self.window_features(i, t_s, n_res))[0]

        return {"material": unit, "material_listen": listen, "material_read": read}
