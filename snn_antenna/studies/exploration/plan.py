"""The exploration loop's parts: the network table and its configured parts, the course,
the preprocessing chain, the blind read-out, the gate's training examples and the loop's
settings; checked before anything runs."""
from __future__ import annotations

from dataclasses import dataclass

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError
from ...engine import rates
from ...engine.cost import Build, engine_of, gate_training_runs, stages_estimate
from ...networks import runtime_cache
from ...networks.assembly import configure
from ...networks.gate import GateTraining
from ...readout.closed_loop import LoopSettings
from ...readout.contacts import detector_from_spec
from ...readout.detection import BlindReadOut
from ...sources.scenes import CourseScene
from ..contract import COMMON, Plan
from ...preprocess import chain_section
from ..sections import scene_section

SECTIONS = ("network", "stimulus", "preprocess", "readout", "gate_training", "loop")
OPTIONS = COMMON


@dataclass
class Parts:
    """Everything the loop is built from: the network table (``assembly``) and its
    configured parts, the course, the preprocessing chain, the blind read-out, the gate's
    training examples (speeds, Th*) and the loop's settings."""
    network: dict
    configured: dict
    scene: CourseScene
    chain: object
    readout: BlindReadOut
    gate_training: tuple
    loop: LoopSettings


def plan(spec: dict) -> Plan:
    """Check the whole spec and build every part of the loop before anything runs."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("network"):
        table = spec.get("network", {})
        configured = configure(table)
        for need in ("resonators", "gate", "cpg", "control"):
            if need not in configured:
                raise SpecError("network.parts", table.get("parts"),
                                f"the exploration loop needs {need!r} among the parts")
    scene = scene_section(spec, course=True)
    pre, _ = chain_section(spec, [scene], gated=True)
    detector, window_s = detector_from_spec(spec)
    with specs.section("gate_training"):
        examples = GateTraining(**specs.check_section(spec, "gate_training",
                                                      GateTraining)).examples()
        configured["gate"].check_speeds(examples[0], "speeds_cm_s")
    with specs.section("loop"):
        loop = LoopSettings(**specs.check_section(spec, "loop", LoopSettings))
        for name in ("duration_s", "calibration_s"):
            bounds.positive_seconds(name, getattr(loop, name))
        bounds.number("chunk_ms", loop.chunk_ms, 1.0, bounds.MAX_SECONDS * 1000, unit=" ms")
        configured["gate"].check_speeds([loop.speed_cm_s], "speed_cm_s")
    readout = BlindReadOut(configured["resonators"], detector, window_s, scene.rate_hz,
                           settle_s=0.0)
    return Plan("exploration", spec,
                Parts(table, configured, scene, pre.chain(scene), readout, examples, loop),
                estimate)


def estimate(parts: Parts):
    """The gate's training, then the closed loop for ``loop.duration_s``: one network whose
    parts step together at the resonators' dt (a small network's per-step cost), each part
    compiled on its own, and Python's work per chunk."""
    gate, loop, cfg = parts.configured["gate"], parts.loop, parts.configured
    speeds = parts.gate_training[0]
    resonators = cfg["resonators"]
    engine = engine_of(resonators.target)

    # one Brian2 network: a part on cython makes every part's code objects cython ones
    cython = loop_target(cfg) == "cython"

    def part_build(name: str) -> Build:
        return Build(loop_network(name), not cython
                     or runtime_cache.compiled(loop_network(name), LOOP_MODULE),
                     LOOP_PART_COMPILES)
    # the parts step together, one network at the resonators' dt: its steps once, each
    # part's build its own
    first, *others = cfg
    loop_runs = [(float(loop.duration_s), resonators.dt_ms, resonators.n_neurons, engine,
                  part_build(first))] + [(0.0, resonators.dt_ms, 0, engine, part_build(name))
                                         for name in others]
    return stages_estimate("the gate's training and the closed loop", [
        ("network.gate", {"epochs": gate.epochs, "present_s": gate.present_s},
         gate_training_runs(gate, len(speeds), len(speeds))),
        ("loop.duration_s", loop.duration_s, loop_runs,
         float(loop.duration_s) * 1000.0 / float(loop.chunk_ms)
         * rates.rates()["python_s"]["closed_loop_chunk"].value)])


# the closed loop's parts as ``networks.runtime_cache`` names them: built by the assembly
LOOP_MODULE = "snn_antenna.networks.assembly"
# A part of the loop on cython costs this many compiles of the offline array's network (its
# synapses, monitors and operations are code objects too): the full profile in a new
# environment took 59 s at load 2 (2 cores), about 29 s of it compiling its four parts,
# 0.65 of the probe's compile each.
LOOP_PART_COMPILES = 0.65


def loop_network(part: str) -> str:
    return f"closed loop: {part}"


def loop_target(configured: dict) -> str:
    """The closed loop's code target: cython when any part runs on it."""
    targets = {getattr(part, "target", None) for part in configured.values()}
    return "cython" if "cython" in targets else "numpy"


