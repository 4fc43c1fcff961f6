"""Active exploration: the closed loop of the paper's Fig. 3, run in Brian2 with Python in the
loop.

The network is what ``networks/exploration.toml`` lists (``assembly.build``); the loop, its
freeze reflex and the robot's blind record are ``readout.closed_loop.ClosedLoop`` (how it
runs, and which seed each recording draws). The world's contacts are compared with the
robot's record afterwards (``scoring.score_run``: true and false positives, misses, latency,
distance error).

Summary: ``cpg_period_s`` (measured while driving, and the spec's value at that speed),
``pan_tilt_phase_deg``, ``contact_distance_cm`` (true and decoded from the rate map),
``stopped_after_contact_s``, ``score``.
"""
from __future__ import annotations

import time

import numpy as np

from ..core import bounds
from ..core import spec as specs
from ..core.logfile import CPG_TOKEN_ORDER, logged
from ..core.errors import SpecError, check
from ..engine.cost import engine_of, gate_training_runs, stages_estimate
from ..report.figures import draw_rate_map
from ..networks.assembly import configure
from ..networks.gate import GateTraining
from ..networks.cpg import cycle_periods, phase_lag_deg
from ..preprocess import make_chain
from ..readout.closed_loop import ClosedLoop, LoopSettings, RobotRecord
from ..readout.contacts import detector_from_spec
from ..evaluation.scoring import score_run
from ..readout.detection import BlindReadOut
from ..report.page import Calibrated, Predicted, Report, by_speed
from ..core.truth import Event
from ..sources import antenna
from ..sources.scenes import CourseScene, OnlineAntenna, scene_from_spec
from .contract import COMMON, Options, Plan

SECTIONS = ("network", "stimulus", "preprocess", "readout", "gate_training", "loop")
OPTIONS = COMMON


DISPLAY_MEAN_S = 0.5   # the rate map's running mean in the figure (not the read-out's)


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
    with specs.section("stimulus"):
        scene = scene_from_spec(spec.get("stimulus", {"kind": "course"}))
        check(isinstance(scene, CourseScene), "kind", "robot", "'course'")
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g", "threshold"])
        chain = make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
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
                ClosedLoop(table, configured, scene, chain, readout, examples, loop), estimate)


def estimate(parts: ClosedLoop):
    """The gate's training, then the closed loop for ``loop.duration_s``: every part of the
    network steps at the resonators' dt, each with its own groups (so its own per-step cost)."""
    gate, loop, cfg = parts.configured["gate"], parts.loop, parts.configured
    speeds = parts.gate_training[0]
    resonators = cfg["resonators"]
    loop_run = (float(loop.duration_s), resonators.dt_ms, resonators.n_neurons,
                engine_of(resonators.target))
    return stages_estimate("the gate's training and the closed loop", [
        ("network.gate", {"epochs": gate.epochs, "present_s": gate.present_s},
         gate_training_runs(gate, len(speeds), len(speeds))),
        ("loop.duration_s", loop.duration_s, [loop_run] * len(cfg))])


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick = plan.spec, plan.parts, options.quick
    t_start = time.perf_counter()
    with log.expected(CPG_TOKEN_ORDER):
        robot, world = parts.run(plan.seed, log)
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


def summarize(robot: RobotRecord, world: OnlineAntenna, scored: dict, parts: ClosedLoop) -> dict:
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


def _record_rows(s: dict, cpg) -> list[dict]:
    rows = [("CPG period while driving", s["cpg_period_s"]["measured"],
             s["cpg_period_s"]["spec"], "s"),
            ("pan-tilt phase lag", s["pan_tilt_phase_deg"]["measured"],
             float(cpg.phase_offset_deg), "deg")]
    for joint, (low, high) in (("pan", s["pan_range_deg"]), ("tilt", s["tilt_range_deg"])):
        centre = getattr(cpg, f"{joint}_centre_deg")
        amplitude = getattr(cpg, f"{joint}_amplitude_deg")
        rows += [(f"{joint} range, low", low, centre - amplitude, "deg"),
                 (f"{joint} range, high", high, centre + amplitude, "deg")]
    rows.append(("gate Th while driving (median)", s["gate_th_g_while_driving"], None, "g"))
    return [{"quantity": q, "measured": m, "spec": sp, "unit": u} for q, m, sp, u in rows]


def _score_rows(sc: dict) -> list[dict]:
    first = sc["first_contact"] or {}
    rows = [("true positives", sc["tp"]), ("misses", sc["misses"]),
            ("false positives", sc["fp"]),
            ("contacts outside the array's band (not scored)", sc["out_of_band_contacts"]),
            ("first contact: true distance (cm)", first.get("true_distance_cm")),
            ("first contact: its low mode (Hz)", first.get("low_mode_hz")),
            ("first contact: decoded distance (cm)", first.get("decoded_distance_cm")),
            ("first contact: latency (s)", first.get("latency_s")),
            ("robot stopped after the first contact (s)", first.get("stopped_after_s"))]
    return [{"quantity": q, "value": v} for q, v in rows]


def write_report(spec: dict, parts: ClosedLoop, robot: RobotRecord, summary: dict, out_dir,
                 quick: bool) -> dict:
    array, first = parts.configured["resonators"], summary["score"]["first_contact"]
    rep = Report(out_dir, "snn-antenna: active exploration, closed loop", quick=quick,
                 quick_note="quick profile: a shorter loop, a briefly trained gate and the "
                            "numpy target; one contact at most, too few to compare")
    rep.text(spec.get("description", ""))
    _provenance_rows(rep, summary, parts)
    rep.table(_record_rows(summary, parts.configured["cpg"]),
              "Closed loop: the robot's own record")
    rep.table(_score_rows(summary["score"]),
              "Score of the read-out against the world's contacts (after the run)")
    if first and not first["within_array_band"]:
        rep.text(f"The first contact, {first['true_distance_cm']:.1f} cm along the rod, rings "
                 f"at {first['low_mode_hz']:.1f} Hz: above the array's top neuron "
                 f"({float(array.band_hz[1]):g} Hz, the paper's 7–30 Hz array), so its decoded "
                 "distance saturates at the array's edge and it is not scored.")
    rep.table(summary["contacts"], "The world's contacts (ground truth)")
    rep.table(summary["detections"], "Every detection of the read-out (blind)")
    rep.figure(_figure(robot, parts.scene, [c["t_s"] for c in summary["contacts"]]),
               "exploration",
               "Joint angles from the CPG, robot speed and the gate's Th, the rate map (dashed: "
               "true contacts, green: detections, red: stop) and the tip's path in the plane "
               "with the posts.")
    return rep.write(summary, spec, array.target)


def _provenance_rows(rep: Report, s: dict, parts: ClosedLoop) -> None:
    cpg = parts.configured["cpg"]
    v, th = parts.gate_training
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
                   by_speed(dict(zip(v, th)), lambda t: f"{t:.3g} g"),
                   "Th* of the gating study", "",
                   "studies/gating_threshold.toml (seed 3), as listed in "
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
    def fmt(v, spec=".2f"):
        return "none" if v is None else format(v, spec)
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


def _figure(robot: RobotRecord, scene: CourseScene, contact_times_s: list):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, pan, tilt, stopped = robot.t, robot.pan, robot.tilt, robot.stopped_at
    fig = plt.figure(figsize=(12, 9))
    gs = fig.add_gridspec(3, 2, width_ratios=[2, 1])
    a0 = fig.add_subplot(gs[0, 0])
    a0.plot(t, pan, label="pan")
    a0.plot(t, tilt, label="tilt")
    a0.set_ylabel("angle (deg)")
    a0.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    a1 = fig.add_subplot(gs[1, 0], sharex=a0)
    a1.plot(t, robot.speed, color="k")
    a1.set_ylabel("speed (cm/s)")
    a1b = a1.twinx()
    a1b.plot(t, robot.th, color="tab:red", lw=0.8)
    a1b.set_ylabel("gate Th (g)", color="tab:red")
    a2 = fig.add_subplot(gs[2, 0], sharex=a0)
    # A read-out window of 0.1 s holds 0 or 1 spike of a slow neuron: drawn as it is, every
    # cell is 0 or 10 Hz and the colour scale saturates. The figure shows the running mean
    # over DISPLAY_MEAN_S, labelled so (the read-out itself keeps its own window).
    w = float(robot.rates.attrs["window_s"])
    n = max(1, int(round(DISPLAY_MEAN_S / w)))
    shown = robot.rates.rolling(window_s=n, center=True, min_periods=1).mean()
    shown.attrs = dict(robot.rates.attrs)
    mesh = draw_rate_map(a2, shown)
    fig.colorbar(mesh, ax=a2, label=f"rate (Hz), mean over {n * w:g} s", pad=0.01)
    a2.set_xlabel("time (s)")
    for t_s in contact_times_s:
        a2.axvline(t_s, color="tab:cyan", ls="--")
    for d in robot.detections:
        a2.axvline(d.onset_s, color="tab:green")
    if stopped is not None:
        for ax in (a0, a1, a2):
            ax.axvline(stopped, color="tab:red", lw=1)
    a3 = fig.add_subplot(gs[:, 1])
    reach = antenna.ROD_LENGTH_CM * np.cos(np.deg2rad(tilt))
    tip_x = robot.x_cm + reach * np.cos(np.deg2rad(pan))
    tip_y = reach * np.sin(np.deg2rad(pan))
    path = a3.scatter(tip_y, tip_x, c=t, s=3, cmap="viridis")
    fig.colorbar(path, ax=a3, label="time (s)", shrink=0.6, pad=0.02)
    a3.plot(np.zeros_like(robot.x_cm), robot.x_cm, color="k", lw=2, label="robot path")
    for ob in scene.obstacles:
        a3.add_patch(plt.Circle((ob.y_cm, ob.x_cm), max(ob.radius_cm, 1.0), color="tab:brown"))
    a3.set_aspect("equal")
    a3.set_xlabel("left (cm)")
    a3.set_ylabel("forward (cm)")
    a3.set_title("antenna tip path", fontsize=9)
    fig.tight_layout()
    return fig
