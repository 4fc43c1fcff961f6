"""The exploration loop's stages, in Brian2 runtime mode: the gate learns, the chain is
fitted on a separate calibration drive, then the loop runs with the robot deciding as it
drives; the world's contacts score the robot's own record afterwards.

Two NetworkOperations close the loop:

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
from dataclasses import replace

import numpy as np

from ...core.logfile import CPG_TOKEN_ORDER, logged
from ...core.truth import Event
from ...evaluation.scoring import score_run
from ...networks.assembly import build as build_network
from ...networks.control import CONTROL_UNITS, unit_spike_counts
from ...networks.cpg import cycle_periods, phase_lag_deg
from ...networks.gate import read_trace
from ...networks import runtime_cache
from ...networks.resonators import rate_map
from ...readout.closed_loop import RobotRecord, steer
from ...sources.scenes import OnlineAntenna
from ..contract import Options, Plan
from .plan import LOOP_MODULE, Parts, loop_network, loop_target
from .report import human_summary, write_report

CALIBRATION_STREAM = 0    # spawn key of the calibration recording's seed


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick = plan.spec, plan.parts, options.quick
    t_start = time.perf_counter()
    with log.expected(CPG_TOKEN_ORDER):
        robot, world = run_loop(parts, plan.seed, log)
    log("[5/5] scoring against the world's contacts and writing the report")
    contacts = [Event("contact", c.t_s, c.hold_s, c.distance_cm, c.material)
                for c in world.contacts]
    scored = score_run(parts.readout, robot.detections, contacts, float(parts.loop.duration_s),
                       robot.stopped_at)
    summary = summarize(robot, world, scored, parts)
    summary["total_wall_s"] = time.perf_counter() - t_start
    summary["built_objects"] = robot.built
    summary = write_report(spec, parts, robot, summary, out_dir, quick)
    log(human_summary(summary, out_dir))
    return summary


def prepare(parts: Parts, seed: int, log=print):
    """Train the gate and fit the chain on a separate calibration drive (no obstacles)."""
    loop = parts.loop
    log("[1/5] training the speed gate on Th* at "
        + ", ".join(f"{v:g}" for v in parts.gate_training[0]) + " cm/s")
    gate = parts.configured["gate"].fit(*parts.gate_training)
    log(f"[2/5] calibrating the chain on a separate {loop.calibration_s:g} s recording of "
        f"driving at {loop.speed_cm_s:g} cm/s, no obstacles")
    calib = replace(parts.scene, obstacles=[], contacts=[],
                    duration_s=float(loop.calibration_s), speed=None,
                    speed_cm_s=float(loop.speed_cm_s), stop_after_contact_s=None)
    noise = np.random.SeedSequence(seed, spawn_key=(CALIBRATION_STREAM,))
    parts.chain.fit(calib.generate(noise).samples)
    return gate


def run_loop(parts: Parts, seed: int, log=print) -> tuple[RobotRecord, OnlineAntenna]:
    """Run the loop; return what the robot itself knows, and the world (the ground
    truth, ``world.contacts``: nothing in the loop or the read-out reads it)."""
    import brian2 as b2

    gate = prepare(parts, seed, log)
    loop, cfg = parts.loop, parts.configured
    log("[3/5] building " + ", ".join(cfg) + " in Brian2 and closing the loop")
    asm = build_network(parts.network, fitted={"gate": gate})
    world = OnlineAntenna(replace(parts.scene, stop_after_contact_s=None), seed)
    res_spikes = b2.SpikeMonitor(asm.objects["resonators"], name="resonator_spikes")
    state = {"k": 0, "stopped_at": None, "log": []}
    asm.network.add(res_spikes, *_loop_operations(parts, gate, asm.objects, world, state))
    t0 = time.perf_counter()
    asm.network.run(float(loop.duration_s) * b2.second, namespace={})
    wall = time.perf_counter() - t0
    for name in cfg:                    # what an estimate finds compiled next time
        runtime_cache.note(loop_network(name), LOOP_MODULE, loop_target(cfg))
    log(f"      {loop.duration_s:g} s simulated in {wall:.1f} s")
    log("[4/5] reading out from the robot's own record")
    t, speed, pan, tilt, th, x_cm = (np.array(c) for c in zip(*state["log"]))
    rates = rate_map(np.asarray(res_spikes.i[:]), np.asarray(res_spikes.t_[:]),
                     cfg["resonators"].neuron_hz, float(loop.duration_s),
                     parts.readout.window_s)
    return RobotRecord(t, speed, pan, tilt, th, x_cm, rates,
                       parts.readout.detector.detect(rates), state["stopped_at"], wall,
                       sorted(asm.names())), world


def _loop_operations(parts: Parts, gate, obj: dict, world: OnlineAntenna,
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
    unit_spikes = unit_spike_counts(obj)          # the units count their own spikes
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


def summarize(robot: RobotRecord, world: OnlineAntenna, scored: dict, parts: Parts) -> dict:
    """The CPG's rhythm while driving, the first contact and the stop, and the score."""
    cpg, speed_cmd = parts.configured["cpg"], float(parts.loop.speed_cm_s)
    t, pan, tilt, driving = robot.t, robot.pan, robot.tilt, robot.speed > 0
    periods = cycle_periods(t[driving], pan[driving]) if driving.sum() > 10 else np.array([])
    period = float(np.median(periods)) if len(periods) else None
    phase = (phase_lag_deg(t[driving], pan[driving], tilt[driving], period)
             if period else None)
    first = scored["first_contact"] or {}
    return {
        "cpg_period_s": {"measured": period, "spec": float(1 / cpg.frequency_hz(speed_cmd))},
        "pan_tilt_phase_deg": {"measured": phase, "spec": float(cpg.phase_offset_deg)},
        "contact_distance_cm": {"true": first.get("true_distance_cm"),
                                "decoded": first.get("decoded_distance_cm")},
        "contact_t_s": first.get("t_s"),
        "stopped_at_s": robot.stopped_at,
        "stopped_after_contact_s": first.get("stopped_after_s"),
        "score": scored,
        "contacts": [{"t_s": c.t_s, "distance_cm": c.distance_cm, "material": c.material}
                     for c in world.contacts],
        "detections": [d.as_dict() for d in robot.detections],
        "pan_range_deg": [float(pan.min()), float(pan.max())],
        "tilt_range_deg": [float(tilt.min()), float(tilt.max())],
        "gate_th_g_while_driving": (float(np.median(robot.th[driving]))
                                    if driving.any() else None),
        "simulation_wall_s": robot.wall_s,
    }


