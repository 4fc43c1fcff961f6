"""The quickstart's page: the scene, what was calibrated and what is predicted, the score,
every detection and the rate map."""
from __future__ import annotations

import re

from ...networks import neurons
from ...report.figures import draw_rate_map
from ...report.page import Calibrated, Predicted, Report
from ...sources import antenna
from .plan import Parts


def write_report(out_dir, spec: dict, parts: Parts, rec, out, scored: dict, summary: dict,
                 quick: bool) -> dict:
    """Write the page and ``summary.json``; the summary as written (with its provenance)."""
    report = Report(out_dir, "snn-antenna quickstart: contacts on a driving robot", quick=quick,
                    quick_note="quick profile: a shorter scene with fewer contacts; its "
                               "false-positive rate rests on too few minutes to compare")
    report.text(scene_text(parts.scene, spec.get("description", "")))
    report.table([{"what": w, "value": v} for w, v in parts.scene.provenance_rows()],
                 "Where the data came from")
    if (origin := parts.scene.summary_entry()) is not None:
        summary["data"] = origin
    calibrated_and_predicted(report, summary, parts)
    report.table([{"quantity": "true positives", "value": scored["tp"]},
                  {"quantity": "misses", "value": scored["misses"]},
                  {"quantity": "false positives", "value": scored["fp"]},
                  {"quantity": "false positives per minute", "value": scored["fp_per_min"]},
                  {"quantity": "minutes scored (after the warm-up)",
                   "value": scored["scored_minutes"]},
                  {"quantity": "mean latency (s)", "value": scored["latency_s"]},
                  {"quantity": "mean |distance error| (cm)",
                   "value": scored["mean_abs_distance_error_cm"]}],
                 "Score of the read-out against the scene's contacts (after it ran)")
    report.table(scored["contacts"], "Each contact")
    report.table(summary["detections"], "Every detection the read-out made (blind)")
    report.figure(_figure(rec, out, scored, parts), "rate_map",
                  "Top: the accelerometer's two axes (ADC counts) and the coded input "
                  f"(chain fitted on the grey warm-up, the first {parts.warmup_s:g} s). "
                  "Bottom: spike rate of each resonator per window (the paper's Fig. 10H); "
                  "dashed cyan: true contacts; solid: detections (green: true positive, "
                  "red: false positive), labelled with the decoded distance.")
    return report.write(summary, spec, parts.array.target)


def scene_text(scene, description: str) -> str:
    """The scene this run read (what its source says of it), then the spec's description
    after its first sentence (which tells the full profile's scene)."""
    rest = re.split(r"\.\s+(?=[A-Z])", description, maxsplit=1)
    return (f"{scene.describe()} The read-out sees only the sensor's samples; the contacts "
            "score it afterwards. " + (rest[1] if len(rest) > 1 else ""))


def calibrated_and_predicted(report: Report, s: dict, parts: Parts) -> None:
    """What the scene's source and the read-out were set to match, apart from what the run
    predicts."""
    sc = s["score"]
    law_19 = float(antenna.low_mode_hz(19.0))
    report.calibrated(
        *parts.scene.calibrated(),
        Calibrated("low-mode frequency law (read-out)",
                   f"log10 F = {antenna.LOW_LAW[0]} d + {antenna.LOW_LAW[1]}",
                   "log10 F = 0.0268 d + 0.69", "", "docs/reference.md, Fig. 2C",
                   "antenna.LOW_LAW; readout inverts the same law"),
        # set to this project's own measured tuning curve; the paper's 7 Hz neuron (k =
        # 0.3425, 20.4 Hz per k) is never its target: tuning_sweep sets it beside a prediction
        Calibrated("hertz per unit k of a resonator", neurons.DRIVEN_HZ_PER_K,
                   "centroid of the driven k = 1 tuning curve", "Hz",
                   "snn_antenna/networks/neurons.py (measured; re-measured by "
                   "studies/tuning_sweep.toml)",
                   "neurons.k_for_frequency places each neuron's k with it"),
        Calibrated("coder threshold Th at 12 cm/s", parts.chain.named_steps["coder"].threshold,
                   "above sensor noise (0.01 g), below self-motion (0.25 g rms)", "g",
                   "studies/quickstart.toml", "set by hand"),
    )
    interval = tuple(sc["fp_per_min_interval"])
    report.predicted(
        Predicted("false positives per minute while driving (12 cm/s)", sc["fp_per_min"],
                  "1/min", None, "this run (score after a blind read-out)", interval,
                  None, f"{sc['fp']} false positive(s) in {sc['scored_minutes']:.2f} min "
                  "of driving; exact Poisson interval; the paper gives no rate"),
        Predicted("contacts detected", sc["tp"], "", None, "this run", None,
                  sc["tp"] + sc["misses"], f"{sc['misses']} missed"),
        Predicted("mean detection latency", sc["latency_s"], "s", None, "this run", None,
                  sc["tp"], "from the contact to the end of the first detected window"),
        Predicted("array's self-motion centroid", s["motion_dominant_hz"], "Hz", None,
                  "this run, windows outside detections", None, None,
                  "the antenna's self-motion as the array reads it; where the scene's "
                  "self-oscillation was set (Calibrated to, above), this checks the array's "
                  "tuning, not the paper"),
    )
    fig10 = [c for c in sc["contacts"] if c["true_distance_cm"] == 19.0 and c["dominant_hz"]]
    if fig10:   # the paper's Fig. 10 contact
        report.predicted(Predicted(
            "most active neuron on the contact at 19 cm", fig10[0]["dominant_hz"], "Hz", 17.0,
            "docs/reference.md, Fig. 10E", None, None, f"the paper's own law gives "
            f"{law_19:.1f} Hz at 19 cm"))
    report.predicted(
        Predicted("mean |distance error|", sc["mean_abs_distance_error_cm"], "cm", None,
                  "this run", None, sc["tp"],
                  "against the scene's contacts; where the scene rings at the law the "
                  "read-out inverts (Calibrated to, above), this is self-consistency of the "
                  "array's frequency estimate, not a reproduction"),
    )


def human_summary(s: dict, out_dir) -> str:
    sc = s["score"]
    def fmt(v, spec=".2f"):
        return "none" if v is None else format(v, spec)
    lines = [f"self-motion activity centred at {fmt(s['motion_dominant_hz'], '.1f')} Hz "
             f"(windows outside detections, after a {s['warmup_s']:g} s warm-up)",
             f"{len(s['detections'])} detection(s): {sc['tp']} true positive(s), {sc['fp']} "
             f"false positive(s) ({fmt(sc['fp_per_min'], '.1f')} per minute over "
             f"{sc['scored_minutes']:.2f} min of driving), {sc['misses']} miss(es)"]
    for c in sc["contacts"]:
        if c["detected_s"] is None:
            lines.append(f"contact at {c['true_t_s']:.2f} s ({c['true_distance_cm']:.1f} cm): "
                         "missed")
        else:
            lines.append(f"contact at {c['true_t_s']:.2f} s detected at {c['detected_s']:.2f} s "
                         f"(latency {c['latency_s']:.2f} s); most active neuron "
                         f"{c['dominant_hz']:.1f} Hz; decoded distance {c['distance_cm']:.1f} "
                         f"cm (true {c['true_distance_cm']:.1f} cm)")
    lines.append(f"simulation {s['simulation_wall_s']:.1f} s wall; report in "
                 f"{out_dir}/report.html")
    return "\n".join(lines)


def _figure(rec, out, scored: dict, parts: Parts):
    import matplotlib      # the figures' backend is chosen before pyplot loads
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1, ax2) = plt.subplots(3, 1, figsize=(11, 7.5), sharex=True,
                                        gridspec_kw={"height_ratios": [1, 0.6, 2]})
    t = rec.t_s
    ax0.plot(t, rec.samples[:, 0], lw=0.5, label="x")
    ax0.plot(t, rec.samples[:, 1], lw=0.5, label="y")
    ax0.set_ylabel("ADC counts")
    ax0.legend(loc="upper right", fontsize=8)
    ax1.plot(t, out.coded, lw=0.5, color="k")
    ax1.set_ylabel("coded I")
    for ax in (ax0, ax1):
        ax.axvspan(0, parts.warmup_s, color="0.85", zorder=0)
    mesh = draw_rate_map(ax2, out.rates)
    ax2.set_xlabel("time (s)")
    fig.colorbar(mesh, ax=[ax0, ax1, ax2], label="spike rate (Hz)", shrink=0.5)
    for c in rec.truth.contacts:
        for ax in (ax0, ax1, ax2):
            ax.axvline(c.t_s, color="tab:cyan", ls="--", lw=1)
    true_onsets = {c["detected_s"] for c in scored["contacts"] if c["detected_s"] is not None}
    for d in out.detections:
        colour = "tab:green" if d.onset_s in true_onsets else "tab:red"
        ax2.axvline(d.onset_s, color=colour, lw=1.5)
        ax2.text(d.onset_s, ax2.get_ylim()[1], f" {d.distance_cm:.1f} cm", color=colour,
                 va="bottom", fontsize=8)
    return fig
