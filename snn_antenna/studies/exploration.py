"""Active exploration: the closed loop of the paper's Fig. 3, run in Brian2 with Python in the loop.

The robot drives among posts; the CPG sweeps the antenna; where the rod meets a post the
antenna rings; the preprocessing chain codes the signal with the Th the speed gate recalls
from the speed command; the resonators feed the class-I control layer, whose motor unit
stops the robot (and the sweep). The network is what ``networks/exploration.toml`` lists
(``assembly.build``), in runtime mode, with two NetworkOperations:

- every ``chunk_ms``: read the CPG's angles and the motor unit, move the robot, generate the
  next chunk of antenna samples (``scenes.OnlineAntenna``), preprocess it
  (``preprocess.partial_transform``) and code it with the gate's current Th;
- every sample: write the next coded sample into the resonators' input.

The loop and its read-out (``close_loop``) use only what the robot has: the chain is fitted on
a separate calibration recording (driving, no obstacles), contacts are read from the
resonators' rate map and the motor unit stops the robot. The world's contacts are compared
with that afterwards (``score``: true and false positives, misses, latency, distance error).

Summary: ``cpg_period_s`` (measured while driving, and the spec's value at that speed),
``pan_tilt_phase_deg``, ``contact_distance_cm`` (true and decoded from the rate map),
``stopped_after_contact_s``, ``score``.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..sources import antenna
from .. import spec as specs
from ..networks.assembly import build as build_network, configure
from ..networks.cpg import cycle_periods, phase_lag_deg
from ..errors import SpecError, check
from ..networks.resonators import rate_map
from ..preprocess import make_chain
from ..readout.contacts import ContactDetector, detector_from_spec
from ..report import Calibrated, Predicted, Report, draw_rate_map
from ..sources.scenes import CourseScene, OnlineAntenna, scene_from_spec
from ..signals import Event

SECTIONS = ("network", "stimulus", "preprocess", "readout", "gate_training", "loop")


def _gate_training(speeds_cm_s=(0.0, 30.0), th_star_g=(0.1, 0.6), from_summary=None):
    return locals()


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


def _loop(speed_cm_s=15.0, duration_s=12.0, chunk_ms=10.0, calibration_s=2.0):
    return locals()


def build(spec: dict) -> dict:
    specs.check_top_level(spec, SECTIONS)
    parts = {}
    with specs.section("network"):
        table = spec.get("network", {})
        configured = configure(table)
        for need in ("resonators", "gate", "cpg", "control"):
            if need not in configured:
                raise SpecError("network.parts", table.get("parts"),
                                f"the exploration loop needs {need!r} among the parts")
        parts["network"] = table
        parts["configured"] = configured
    with specs.section("stimulus"):
        scene = scene_from_spec(spec.get("stimulus", {"kind": "course"}))
        check(isinstance(scene, CourseScene), "kind", "robot", "'course'")
        parts["scene"] = scene
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g", "threshold"])
        parts["chain"] = make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
    parts["detector"], parts["window_s"] = detector_from_spec(spec)
    with specs.section("gate_training"):
        gt = {**_gate_training(), **specs.check_section(spec, "gate_training", _gate_training)}
        if gt["from_summary"] is not None:       # replaces the spec's own list
            v, th = th_star_from_summary(gt["from_summary"])
        else:
            v, th = np.asarray(gt["speeds_cm_s"], float), np.asarray(gt["th_star_g"], float)
        check(v.shape == th.shape and len(v) >= 2, "th_star_g", gt["th_star_g"],
              "one threshold per speed, at least two")
        configured["gate"].check_speeds(v, "speeds_cm_s")
        parts["gate_training"] = (v, th)
    with specs.section("loop"):
        loop = {**_loop(), **specs.check_section(spec, "loop", _loop)}
        antenna.self_motion_rms_g(loop["speed_cm_s"])
        configured["gate"].check_speeds([loop["speed_cm_s"]], "speed_cm_s")
        check(loop["duration_s"] > 0 and loop["chunk_ms"] >= 1 and loop["calibration_s"] > 0,
              "loop", loop, "duration_s > 0, chunk_ms >= 1, calibration_s > 0")
        parts["loop"] = loop
    return parts


def close_loop(parts: dict, seed: int, log=print) -> tuple[dict, OnlineAntenna]:
    """Run the closed loop; return what the robot itself knows, and the world.

    The first value holds only what the robot has: its own log (speed, angles, Th), its
    resonators' rate map, the detections read from it and the motor unit's stop time. The
    world (``OnlineAntenna``) holds the ground truth (``world.contacts``) for scoring; nothing
    in the loop or the read-out reads it.
    """
    import brian2 as b2

    loop, scene, chain = parts["loop"], parts["scene"], parts["chain"]
    cfg = parts["configured"]
    speed_cmd = float(loop["speed_cm_s"])
    log("[1/5] training the speed gate on Th* at "
        + ", ".join(f"{v:g}" for v in parts["gate_training"][0]) + " cm/s")
    gate = cfg["gate"].fit(*parts["gate_training"])
    log(f"[2/5] calibrating the chain on a separate {loop['calibration_s']:g} s recording of "
        f"driving at {speed_cmd:g} cm/s, no obstacles")
    calib = replace(scene, obstacles=[], contacts=[], duration_s=float(loop["calibration_s"]),
                    speed=None, speed_cm_s=speed_cmd, stop_after_contact_s=None)
    chain.fit(calib.generate(seed + 1).samples)
    steps = [step for _, step in chain.steps]
    coder = steps[-1]

    log("[3/5] building " + ", ".join(cfg) + " in Brian2 and closing the loop")
    asm = build_network(parts["network"], fitted={"gate": gate})
    obj = asm.objects
    world = OnlineAntenna(replace(scene, stop_after_contact_s=None), seed)
    rate_hz = scene.rate_hz
    n_chunk = int(round(loop["chunk_ms"] * rate_hz / 1000.0))
    i_ext = obj["resonators"].variables["I_ext"].get_value()
    r_read = obj["readout"].variables["r_read"].get_value()
    x_ring = obj["cpg"].variables["x"].get_value()
    motor_spikes = b2.SpikeMonitor(obj["control_motor"], name="motor_spikes")
    res_spikes = b2.SpikeMonitor(obj["resonators"], name="resonator_spikes")
    state = {"buffer": np.zeros(n_chunk), "k": 0, "stopped_at": None, "log": []}
    cpg = cfg["cpg"]

    @b2.network_operation(dt=loop["chunk_ms"] * b2.ms, when="start", order=-1)
    def close_the_loop(t):
        t_s = float(t / b2.second)
        if state["stopped_at"] is None and motor_spikes.num_spikes > 0:
            state["stopped_at"] = t_s
        speed = 0.0 if state["stopped_at"] is not None else speed_cmd
        obj["cpg"].speed_cm_s = speed
        obj["speed_population"].speed_cm_s = speed
        obj["cpg"].hold_input = 0.0 if state["stopped_at"] is None else 5.0   # reflex: freeze
        pan, tilt = cpg.angles(x_ring.copy())
        counts = world.step(n_chunk, speed, float(pan), float(tilt))
        x = counts
        for step in steps[:-1]:
            x = step.partial_transform(x)
        th = float(gate.decode(r_read[0]))
        state["buffer"] = coder.partial_transform(x, threshold=th)
        state["k"] = 0
        state["log"].append((t_s, speed, float(pan), float(tilt), th, world.x_cm))

    @b2.network_operation(dt=b2.second / rate_hz, when="start", order=0)
    def feed(t):
        i_ext[:] = state["buffer"][state["k"]]
        state["k"] += 1

    net = asm.network
    net.add(motor_spikes, res_spikes, close_the_loop, feed)
    t0 = time.perf_counter()
    net.run(float(loop["duration_s"]) * b2.second, namespace={})
    wall = time.perf_counter() - t0
    log(f"      {loop['duration_s']:g} s simulated in {wall:.1f} s")

    log("[4/5] reading out from the robot's own record")
    t, speed, pan, tilt, th, x_cm = (np.array(c) for c in zip(*state["log"]))
    rates = rate_map(np.asarray(res_spikes.i[:]), np.asarray(res_spikes.t_[:]),
                     cfg["resonators"].neuron_hz, float(loop["duration_s"]), parts["window_s"])
    robot = {"t": t, "speed": speed, "pan": pan, "tilt": tilt, "th": th, "x_cm": x_cm,
             "rates": rates, "detections": parts["detector"].detect(rates),
             "stopped_at": state["stopped_at"], "wall_s": wall, "built": sorted(asm.names()),
             "cpg": cpg, "speed_cmd": speed_cmd}
    return robot, world


def score(robot: dict, contacts, parts: dict) -> dict:
    """The robot's detections and stop against the world's contacts, after the run."""
    from ..readout.scoring import score as score_detections
    from .quickstart import first_match

    array = parts["configured"]["resonators"]
    duration_s = float(parts["loop"]["duration_s"])
    contacts = sorted(contacts, key=lambda c: c.t_s)
    events = [Event("contact", c.t_s, c.hold_s, c.distance_cm, c.material) for c in contacts]
    s = score_detections(robot["detections"], events, duration_s, parts["detector"], array,
                         parts["window_s"], settle_s=0.0)
    first = events[0] if events else None
    match = first_match(robot["detections"], first, parts["window_s"]) if first else None
    f_first = float(antenna.low_mode_hz(first.distance_cm)) if first else None
    stopped = robot["stopped_at"]
    return {**s.as_dict(), "scored_minutes": s.minutes,
            "first_contact": None if first is None else {
                "t_s": first.t_s, "true_distance_cm": first.distance_cm,
                "material": first.material, "low_mode_hz": f_first,
                "within_array_band": bool(f_first <= float(array.band_hz[1])),
                "decoded_distance_cm": match.distance_cm if match else None,
                "distance_error_cm": (match.distance_cm - first.distance_cm) if match else None,
                "latency_s": (match.onset_s + parts["window_s"] - first.t_s) if match else None,
                "stopped_after_s": (stopped - first.t_s) if stopped is not None else None}}


def run(spec: dict, out_dir, quick: bool = False, log=print, **_) -> dict:
    parts = build(spec)
    seed = int(spec.get("seed", 0))
    t_start = time.perf_counter()
    robot, world = close_loop(parts, seed, log)
    log("[5/5] scoring against the world's contacts and writing the report")
    scored = score(robot, world.contacts, parts)
    t, speed, pan, tilt = robot["t"], robot["speed"], robot["pan"], robot["tilt"]
    cpg, speed_cmd, stopped = robot["cpg"], robot["speed_cmd"], robot["stopped_at"]
    driving = speed > 0
    periods = cycle_periods(t[driving], pan[driving]) if driving.sum() > 10 else np.array([])
    period = float(np.median(periods)) if len(periods) else None
    phase = (phase_lag_deg(t[driving], pan[driving], tilt[driving], period)
             if period else None)
    first = scored["first_contact"]
    array = parts["configured"]["resonators"]
    summary = {
        "cpg_period_s": {"measured": period, "spec": float(1 / cpg.frequency_hz(speed_cmd))},
        "pan_tilt_phase_deg": {"measured": phase, "spec": float(cpg.phase_offset_deg)},
        "contact_distance_cm": {"true": first["true_distance_cm"] if first else None,
                                "decoded": first["decoded_distance_cm"] if first else None},
        "contact_t_s": first["t_s"] if first else None,
        "stopped_at_s": stopped,
        "stopped_after_contact_s": first["stopped_after_s"] if first else None,
        "score": scored,
        "contacts": [{"t_s": c.t_s, "distance_cm": c.distance_cm, "material": c.material}
                     for c in world.contacts],
        "detections": [d.as_dict() for d in robot["detections"]],
        "pan_range_deg": [float(pan.min()), float(pan.max())],
        "tilt_range_deg": [float(tilt.min()), float(tilt.max())],
        "gate_th_g_while_driving": (float(np.median(robot["th"][driving]))
                                    if driving.any() else None),
        "simulation_wall_s": robot["wall_s"],
        "total_wall_s": time.perf_counter() - t_start,
        "built_objects": robot["built"],
    }
    rep = Report(out_dir, "snn-antenna: active exploration, closed loop", quick=quick,
                 quick_note="quick profile: a shorter loop, a briefly trained gate and the "
                            "numpy target; one contact at most, too few to compare")
    rep.text(spec.get("description", ""))
    _provenance_rows(rep, summary, parts)
    rows = [
        {"quantity": "CPG period while driving", "measured": period,
         "spec": summary["cpg_period_s"]["spec"], "unit": "s"},
        {"quantity": "pan-tilt phase lag", "measured": phase, "spec": float(cpg.phase_offset_deg),
         "unit": "deg"},
        {"quantity": "pan range, low", "measured": float(pan.min()),
         "spec": cpg.pan_centre_deg - cpg.pan_amplitude_deg, "unit": "deg"},
        {"quantity": "pan range, high", "measured": float(pan.max()),
         "spec": cpg.pan_centre_deg + cpg.pan_amplitude_deg, "unit": "deg"},
        {"quantity": "tilt range, low", "measured": float(tilt.min()),
         "spec": cpg.tilt_centre_deg - cpg.tilt_amplitude_deg, "unit": "deg"},
        {"quantity": "tilt range, high", "measured": float(tilt.max()),
         "spec": cpg.tilt_centre_deg + cpg.tilt_amplitude_deg, "unit": "deg"},
        {"quantity": "gate Th while driving (median)",
         "measured": summary["gate_th_g_while_driving"], "spec": None, "unit": "g"},
    ]
    rep.table(rows, "Closed loop: the robot's own record")
    rep.table([{"quantity": "true positives", "value": scored["tp"]},
               {"quantity": "misses", "value": scored["misses"]},
               {"quantity": "false positives", "value": scored["fp"]},
               {"quantity": "contacts outside the array's band (not scored)",
                "value": scored["out_of_band_contacts"]},
               {"quantity": "first contact: true distance (cm)",
                "value": first["true_distance_cm"] if first else None},
               {"quantity": "first contact: its low mode (Hz)",
                "value": first["low_mode_hz"] if first else None},
               {"quantity": "first contact: decoded distance (cm)",
                "value": first["decoded_distance_cm"] if first else None},
               {"quantity": "first contact: latency (s)",
                "value": first["latency_s"] if first else None},
               {"quantity": "robot stopped after the first contact (s)",
                "value": first["stopped_after_s"] if first else None}],
              "Score of the read-out against the world's contacts (after the run)")
    if first and not first["within_array_band"]:
        rep.text(f"The first contact, {first['true_distance_cm']:.1f} cm along the rod, rings "
                 f"at {first['low_mode_hz']:.1f} Hz: above the array's top neuron "
                 f"({float(array.band_hz[1]):g} Hz, the paper's 7–30 Hz array), so its decoded "
                 "distance saturates at the array's edge and it is not scored.")
    rep.table(summary["contacts"], "The world's contacts (ground truth)")
    rep.table(summary["detections"], "Every detection of the read-out (blind)")
    rep.figure(_figure(t, speed, pan, tilt, robot["th"], robot["x_cm"], robot["rates"],
                       parts["scene"], world, robot["detections"], stopped),
               "exploration", "Joint angles from the CPG, robot speed and the gate's Th, the "
               "rate map (dashed: true contacts, green: detections, red: stop) and the tip's "
               "path in the plane with the posts.")
    summary = rep.write(summary, spec, array.target)
    log(human_summary(summary, out_dir))
    return summary


def _provenance_rows(rep: Report, s: dict, parts: dict) -> None:
    cpg = parts["configured"]["cpg"]
    v, th = parts["gate_training"]
    sc = s["score"]
    first = sc["first_contact"]
    rep.calibrated(
        Calibrated("CPG period while driving", s["cpg_period_s"]["measured"],
                   s["cpg_period_s"]["spec"], "s", "docs/reference.md, robotic platform "
                   "(paper: 2 s limit cycle at rest; faster when driving is assumed)",
                   "cpg.CPG.drive_for sets the ring's drive for the period"),
        Calibrated("pan-tilt phase lag", s["pan_tilt_phase_deg"]["measured"],
                   float(cpg.phase_offset_deg), "deg", "assumed (the paper gives none)",
                   "network cpg.phase_offset_deg"),
        Calibrated("antenna action range (pan × tilt)",
                   f"{s['pan_range_deg'][1] - s['pan_range_deg'][0]:.0f} × "
                   f"{s['tilt_range_deg'][1] - s['tilt_range_deg'][0]:.0f}",
                   "80 × 90", "deg", "docs/reference.md, bionic antenna (paper: 80° "
                   "horizontal centred 40° to the side, 90° vertical centred 10° up)",
                   "network cpg pan/tilt centre and amplitude"),
        Calibrated("gate's Th*(speed) training examples",
                   ", ".join(f"{a:g}: {b:g}" for a, b in zip(v, th)), "Th* of the gating study",
                   "cm/s: g", "studies/gating_threshold.toml (seed 3), as listed in "
                   "studies/exploration.toml", "gate_training"),
    )
    rep.predicted(
        Predicted("scorable contacts detected", sc["tp"], "", None, "this run", None,
                  sc["tp"] + sc["misses"], f"{sc['misses']} missed; one closed-loop run"),
        Predicted("false positives while driving", sc["fp"], "", None, "this run", None, None,
                  f"over {sc['scored_minutes']:.2f} min"),
        Predicted("robot stopped after the first contact",
                  first["stopped_after_s"] if first else None, "s", None, "this run",
                  None, None, "the control layer's motor unit, one run"),
        Predicted("first contact's decoded distance error",
                  first["distance_error_cm"] if first else None, "cm", None, "this run",
                  None, None, "the read-out inverts the generator's own law: "
                  "self-consistency, not a reproduction"
                  + ("" if first is None or first["within_array_band"] else
                     "; the contact rings above the array's band (not scored)")),
    )


def human_summary(s: dict, out_dir) -> str:
    """Four lines a person reads at the end of a run (None where nothing happened)."""
    fmt = lambda v, spec=".2f": "none" if v is None else format(v, spec)
    d, p, sc = s["contact_distance_cm"], s["cpg_period_s"], s["score"]
    contact = "the antenna touched no post" if s["contact_t_s"] is None else (
        f"first contact at {s['contact_t_s']:.2f} s, {d['true']:.1f} cm along the rod, "
        f"decoded {fmt(d['decoded'], '.1f')} cm; robot stopped "
        f"{fmt(s['stopped_after_contact_s'])} s after it")
    return "\n".join([
        contact,
        f"{len(s['detections'])} detection(s): {sc['tp']} true positive(s), {sc['fp']} false "
        f"positive(s), {sc['misses']} miss(es), {sc['out_of_band_contacts']} contact(s) outside "
        "the array's band",
        f"CPG period {fmt(p['measured'], '.3f')} s (spec {p['spec']:.3f} s), pan-tilt phase "
        f"{fmt(s['pan_tilt_phase_deg']['measured'], '.1f')} deg",
        f"report in {out_dir}/report.html ({s['total_wall_s']:.0f} s)"])


def _figure(t, speed, pan, tilt, th, x_cm, rates, scene, world, detections, stopped):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(12, 9))
    gs = fig.add_gridspec(3, 2, width_ratios=[2, 1])
    a0 = fig.add_subplot(gs[0, 0])
    a0.plot(t, pan, label="pan")
    a0.plot(t, tilt, label="tilt")
    a0.set_ylabel("angle (deg)")
    a0.legend(fontsize=8)
    a1 = fig.add_subplot(gs[1, 0], sharex=a0)
    a1.plot(t, speed, color="k")
    a1.set_ylabel("speed (cm/s)")
    a1b = a1.twinx()
    a1b.plot(t, th, color="tab:red", lw=0.8)
    a1b.set_ylabel("gate Th (g)", color="tab:red")
    a2 = fig.add_subplot(gs[2, 0], sharex=a0)
    mesh = draw_rate_map(a2, rates)
    fig.colorbar(mesh, ax=a2, label="rate (Hz)", pad=0.01)
    a2.set_xlabel("time (s)")
    for c in world.contacts:
        a2.axvline(c.t_s, color="tab:cyan", ls="--")
    for d in detections:
        a2.axvline(d.onset_s, color="tab:green")
    if stopped is not None:
        for ax in (a0, a1, a2):
            ax.axvline(stopped, color="tab:red", lw=1)
    a3 = fig.add_subplot(gs[:, 1])
    reach = antenna.ROD_LENGTH_CM * np.cos(np.deg2rad(tilt))
    tip_x = x_cm + reach * np.cos(np.deg2rad(pan))
    tip_y = reach * np.sin(np.deg2rad(pan))
    a3.scatter(tip_y, tip_x, c=t, s=3, cmap="viridis")
    a3.plot(np.zeros_like(x_cm), x_cm, color="k", lw=2, label="robot path")
    for ob in scene.obstacles:
        a3.add_patch(plt.Circle((ob.y_cm, ob.x_cm), max(ob.radius_cm, 1.0), color="tab:brown"))
    a3.set_aspect("equal")
    a3.set_xlabel("left (cm)")
    a3.set_ylabel("forward (cm)")
    a3.set_title("tip path (colour: time)", fontsize=9)
    fig.tight_layout()
    return fig
