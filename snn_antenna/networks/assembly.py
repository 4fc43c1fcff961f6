"""Scene composition: a network spec lists the parts a scene needs; only those are built.

``networks/*.toml`` name the parts and the inputs the scene provides:

- ``bench.toml``: ``parts = ["resonators"]`` (a bench contact: no robot, no motion),
- ``robot.toml``: ``+ "gate"`` (a driving robot: the speed command sets Th),
- ``exploration.toml``: ``+ "cpg", "control"`` (the antenna sweeps; contacts stop the robot).
- ``bench_material.toml``: a rod-band array ``+ "material"`` (class-I neurons naming the
  material; fitted offline, passed as ``fitted={"material": MaterialUnit().fit(...)}``).

Each part declares what it needs; a spec asking for a part whose inputs are missing is refused
before anything is built. ``build`` returns an ``Assembly`` whose Brian2 ``Network`` holds the
listed parts' objects and nothing else, so runtime and memory grow only with what is built.
The resonators take their input as ``I_ext`` written by the caller (runtime mode: the closed
loop writes each coded sample); the gate and CPG read the shared ``speed_cm_s`` it writes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..core import spec as specs
from ..core.errors import SpecError, check
from . import neurons
from .control import ControlLayer, MaterialUnit
from .cpg import CPG
from .gate import SpeedGate
from .resonators import ResonatorArray

INPUTS = ("antenna", "speed_command")
# part → (what it needs: scene inputs or other parts)
NEEDS = {
    "resonators": ("antenna",),
    "gate": ("speed_command",),
    "cpg": ("speed_command",),
    "control": ("resonators",),
    "material": ("resonators",),
}
SETTINGS = {"resonators": ResonatorArray, "gate": SpeedGate, "cpg": CPG,
            "control": ControlLayer, "material": MaterialUnit}


def check_parts(parts, inputs) -> None:
    for name in parts:
        check(name in NEEDS, "network.parts", name, f"parts among {sorted(NEEDS)}")
    for name in inputs:
        check(name in INPUTS, "network.inputs", name, f"inputs among {list(INPUTS)}")
    have = set(parts) | set(inputs)
    for name in parts:
        missing = [n for n in NEEDS[name] if n not in have]
        if missing:
            raise SpecError("network.parts", name,
                            f"{name!r} needs {' and '.join(missing)}: add "
                            f"{', '.join(repr(m) for m in missing)} to the network's "
                            f"{'parts' if missing[0] in NEEDS else 'inputs'}")


@dataclass
class Assembly:
    network: object                     # brian2.Network
    objects: dict = field(default_factory=dict)
    parts: dict = field(default_factory=dict)   # name → configured part (ResonatorArray, ...)

    def names(self) -> set[str]:
        return {obj.name for obj in self.network.objects}


def configure(table: dict) -> dict:
    """Check a network spec table and configure its parts (nothing built yet)."""
    allowed = {"parts", "inputs", "description", *SETTINGS}
    for key in table:
        check(key in allowed, f"network.{key}", table[key],
              f"a known key of a network spec: {', '.join(sorted(allowed))}")
    parts = list(table.get("parts", []))
    check(len(parts) > 0, "network.parts", parts, "a non-empty list of parts")
    check_parts(parts, table.get("inputs", []))
    configured = {}
    for name in parts:
        with specs.section("network"):
            settings = dict(specs.check_section(table, name, SETTINGS[name]))
            settings = {k: tuple(v) if isinstance(v, list) else v for k, v in settings.items()}
            configured[name] = SETTINGS[name](**settings)
    return configured


def build(table: dict, fitted: dict | None = None) -> Assembly:
    """Build the Brian2 objects of the listed parts into one Network (runtime mode).

    ``fitted`` replaces configured parts by trained ones (e.g. ``{"gate": SpeedGate().fit(...)}``:
    its learned weights go into the network's plastic synapses).
    """
    import brian2 as b2

    configured = configure(table)
    for name, part in (fitted or {}).items():
        check(name in configured, "fitted", name, f"a part listed in the spec: {list(configured)}")
        configured[name] = part
    b2.start_scope()
    objects = {}
    if "resonators" in configured:
        array = configured["resonators"]
        group = array.build_group("I_ext", "I_ext : 1", {})
        objects["resonators"] = group
        objects["resonator_guard"] = neurons.instability_guard(group, "resonator", array.dt_ms,
                                                               array.method)
    objects.update(part_objects(configured, objects.get("resonators")))
    return Assembly(b2.Network(*objects.values()), objects, configured)


def part_objects(configured: dict, resonators=None) -> dict:
    """The Brian2 objects of the configured parts other than the array, by name, wired to the
    array's group ``resonators``: ``build`` here, and the live stream, whose array is built by
    ``ResonatorArray.stream`` (bridge/online/pipeline.py). The gate and CPG read the shared
    ``speed_cm_s`` the caller writes; the CPG also ``hold_input`` (the freeze reflex). The gate
    recalls only (``SpeedGate.objects(learning=False)``): it learns in ``SpeedGate.fit``, and
    its weights (``weights_``, zero unfitted) go into the network.

    Parts with the same step share one Brian2 clock (the array's, where theirs is the same):
    Brian2's loop looks at every clock at every step of any, so in runtime mode each further
    clock costs a Python call per step (the live robot network had ten clocks for two step
    sizes)."""
    clock = _clocks(resonators, configured.get("resonators"))
    objects, units = {}, {}
    shared = _shared_units(configured, clock)
    if shared is not None:
        objects["class1_units"], units = shared
    if "gate" in configured:
        gate = configured["gate"]
        objects.update(gate.objects(weights=getattr(gate, "weights_", None), learning=False,
                                    clock=clock(gate.dt_ms), units=units or None))
    if "cpg" in configured:
        cpg = configured["cpg"]
        ring, syn = cpg.objects(
            hold_expr="hold_input", extra="speed_cm_s : 1 (shared)\nhold_input : 1 (shared)",
            clock=clock(cpg.dt_ms))
        objects.update({"cpg": ring, "cpg_ring": syn})
    if "control" in configured:
        control = configured["control"]
        objects.update(control.objects(resonators, configured["resonators"].neuron_hz,
                                       clock=clock(control.dt_ms), units=units or None))
    if "material" in configured:
        objects.update(configured["material"].objects(resonators))
    return objects


def _shared_units(configured: dict, clock):
    """The speed gate's and the control layer's class-I units in one group when they step
    together (``neurons.class1_units``: one group's Brian2 calls per step, not two groups'):
    the group and its Subgroups by role; None otherwise."""
    gate, control = configured.get("gate"), configured.get("control")
    if gate is None or control is None or float(gate.dt_ms) != float(control.dt_ms):
        return None
    return neurons.class1_units({**gate.unit_rows(), **control.unit_rows()},
                                clock(gate.dt_ms), "class1_units")


def _clocks(resonators, array):
    """``clock(dt_ms)``: one Brian2 clock per step size, the array's group's own for its step."""
    import brian2 as b2

    made = {} if resonators is None else {float(array.dt_ms): resonators.clock}

    def clock(dt_ms: float):
        if float(dt_ms) not in made:
            made[float(dt_ms)] = b2.Clock(dt=float(dt_ms) * b2.ms, name="parts_clock*")
        return made[float(dt_ms)]

    return clock
