"""The closed exploration loop in Brian2 runtime mode, and the robot's own record of it.

The robot drives among posts; the CPG sweeps the antenna; where the rod meets a post the
antenna rings; the preprocessing chain codes the signal with the Th the speed gate recalls
from the speed command; the resonators feed the class-I control layer, whose motor unit stops
the robot (and, by ``FREEZE_HOLD``, the sweep). Two NetworkOperations close the loop:

- every ``chunk_ms``: read the CPG's angles and the motor unit, move the robot, generate the
  next chunk of antenna samples (``scenes.OnlineAntenna``), preprocess it and code it with
  the gate's current Th;
- every sample: write the next coded sample into the resonators' input.

The loop and its read-out use only what the robot has: the chain is fitted on a separate
calibration recording (driving, no obstacles; its seed is
``SeedSequence(seed, spawn_key=(CALIBRATION_STREAM,))``), contacts are read from the
resonators' rate map (``RobotRecord``). The world (``OnlineAntenna``) holds the ground truth
for scoring afterwards (``scoring.score_run``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..core import bounds
from ..networks.assembly import build as build_network
from ..networks.control import CONTROL_UNITS
from ..networks.gate import read_trace
from ..networks.resonators import rate_map
from ..sources import antenna
from ..sources.scenes import CourseScene, OnlineAntenna
from .detection import BlindReadOut

# The freeze reflex: once the motor unit fires, this inhibitory hold on the CPG ring pulls
# every neuron's rest (drive + token − hold) far below its threshold of 1, so the sweep stops.
FREEZE_HOLD = 5.0
CALIBRATION_STREAM = 0    # spawn key of the calibration recording's seed


@dataclass
class LoopSettings:
    speed_cm_s: float = 15.0
    duration_s: float = 12.0
    chunk_ms: float = 10.0
    calibration_s: float = 2.0

    def __post_init__(self):
        bounds.declared(self)
        antenna.self_motion_rms_g(self.speed_cm_s)
        bounds.positive_seconds("duration_s", self.duration_s)
        bounds.number("chunk_ms", self.chunk_ms, 1.0, 1e6, unit=" ms")
        bounds.positive_seconds("calibration_s", self.calibration_s)


@dataclass
class RobotRecord:
    """What the robot itself knows after the loop: no ground truth in here."""
    t: np.ndarray
    speed: np.ndarray
    pan: np.ndarray
    tilt: np.ndarray
    th: np.ndarray
    x_cm: np.ndarray
    rates: object
    detections: list
    stopped_at: float | None
    wall_s: float
    built: list


@dataclass
class ClosedLoop:
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

    def prepare(self, seed: int, log=print):
        """Train the gate and fit the chain on a separate calibration drive (no obstacles)."""
        loop = self.loop
        log("[1/5] training the speed gate on Th* at "
            + ", ".join(f"{v:g}" for v in self.gate_training[0]) + " cm/s")
        gate = self.configured["gate"].fit(*self.gate_training)
        log(f"[2/5] calibrating the chain on a separate {loop.calibration_s:g} s recording of "
            f"driving at {loop.speed_cm_s:g} cm/s, no obstacles")
        calib = replace(self.scene, obstacles=[], contacts=[],
                        duration_s=float(loop.calibration_s), speed=None,
                        speed_cm_s=float(loop.speed_cm_s), stop_after_contact_s=None)
        noise = np.random.SeedSequence(seed, spawn_key=(CALIBRATION_STREAM,))
        self.chain.fit(calib.generate(noise).samples)
        return gate

    def run(self, seed: int, log=print) -> tuple[RobotRecord, OnlineAntenna]:
        """Run the loop; return what the robot itself knows, and the world (the ground
        truth, ``world.contacts``: nothing in the loop or the read-out reads it)."""
        import brian2 as b2

        gate = self.prepare(seed, log)
        loop, cfg = self.loop, self.configured
        log("[3/5] building " + ", ".join(cfg) + " in Brian2 and closing the loop")
        asm = build_network(self.network, fitted={"gate": gate})
        world = OnlineAntenna(replace(self.scene, stop_after_contact_s=None), seed)
        res_spikes = b2.SpikeMonitor(asm.objects["resonators"], name="resonator_spikes")
        state = {"k": 0, "stopped_at": None, "log": []}
        asm.network.add(res_spikes, *_loop_operations(self, gate, asm.objects, world, state))
        t0 = time.perf_counter()
        asm.network.run(float(loop.duration_s) * b2.second, namespace={})
        wall = time.perf_counter() - t0
        log(f"      {loop.duration_s:g} s simulated in {wall:.1f} s")
        log("[4/5] reading out from the robot's own record")
        t, speed, pan, tilt, th, x_cm = (np.array(c) for c in zip(*state["log"]))
        rates = rate_map(np.asarray(res_spikes.i[:]), np.asarray(res_spikes.t_[:]),
                         cfg["resonators"].neuron_hz, float(loop.duration_s),
                         self.readout.window_s)
        return RobotRecord(t, speed, pan, tilt, th, x_cm, rates,
                           self.readout.detector.detect(rates), state["stopped_at"], wall,
                           sorted(asm.names())), world


def steer(objects: dict, speed_cm_s: float, moving: bool) -> float:
    """The speed command in force (0 once the motor unit stopped the robot) into the parts
    that read it, the speed gate and the CPG, and the freeze hold on the CPG once stopped.
    The closed loop here and the live stream (bridge/online/pipeline.py) steer with it."""
    speed = float(speed_cm_s) if moving else 0.0
    if "cpg" in objects:
        objects["cpg"].speed_cm_s = speed
        objects["cpg"].hold_input = 0.0 if moving else FREEZE_HOLD
    if "speed_population" in objects:
        objects["speed_population"].speed_cm_s = speed
    return speed


def _loop_operations(parts: ClosedLoop, gate, obj: dict, world: OnlineAntenna,
                     state: dict) -> list:
    """The two NetworkOperations: every chunk, move the robot and code the next samples with
    the gate's Th; every sample, feed the next coded value to the resonators."""
    import brian2 as b2

    loop, rate_hz, cpg = parts.loop, parts.scene.rate_hz, parts.configured["cpg"]
    steps = [step for _, step in parts.chain.steps]
    n_chunk = int(round(loop.chunk_ms * rate_hz / 1000.0))
    i_ext = obj["resonators"].variables["I_ext"].get_value()
    r_read = read_trace(obj)
    x_ring = obj["cpg"].variables["x"].get_value()
    unit_spikes = obj["control"].variables["spike_count"].get_value()   # the units count
    motor = CONTROL_UNITS.index("motor")
    state["buffer"] = np.zeros(n_chunk)

    @b2.network_operation(dt=loop.chunk_ms * b2.ms, when="start", order=-1)
    def close_the_loop(t):
        t_s = float(t / b2.second)
        if state["stopped_at"] is None and unit_spikes[motor] > 0:
            state["stopped_at"] = t_s
        speed = steer(obj, loop.speed_cm_s, moving=state["stopped_at"] is None)
        pan, tilt = cpg.angles(x_ring.copy())
        x = world.step(n_chunk, speed, float(pan), float(tilt))
        for step in steps[:-1]:
            x = step.partial_transform(x)
        th = float(gate.decode(r_read[0]))
        state["buffer"] = steps[-1].partial_transform(x, threshold=th)
        state["k"] = 0
        state["log"].append((t_s, speed, float(pan), float(tilt), th, world.x_cm))

    # no ``t`` argument: Brian2 would build a Quantity for it at every sample
    @b2.network_operation(dt=b2.second / rate_hz, when="start", order=0)
    def feed():
        i_ext[:] = state["buffer"][state["k"]]
        state["k"] += 1

    return [close_the_loop, feed]
