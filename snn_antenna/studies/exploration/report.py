"""The exploration loop's page: the robot's own record, the score against the world's
contacts, what was calibrated and what is predicted, and the loop's figure."""
from __future__ import annotations

import numpy as np

from ...readout.closed_loop import RobotRecord
from ...report.figures import draw_rate_map
from ...report.page import Calibrated, Predicted, Report, by_speed
from ...sources import antenna
from ...sources.scenes import CourseScene
from .plan import Parts

DISPLAY_MEAN_S = 0.5   # the rate map's running mean in the figure (not the read-out's)


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


def write_report(spec: dict, parts: Parts, robot: RobotRecord, summary: dict, out_dir,
                 quick: bool) -> dict:
    array, first = parts.configured["resonators"], summary["score"]["first_contact"]
    rep = Report(out_dir, "snn-antenna: active exploration, closed loop", quick=quick,
                 quick_note="quick profile: a shorter loop, a briefly trained gate and the "
                            "numpy target; one contact at most, too few to compare")
    rep.text(spec.get("description", ""))
    calibrated_and_predicted(rep, summary, parts)
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


def calibrated_and_predicted(rep: Report, s: dict, parts: Parts) -> None:
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
