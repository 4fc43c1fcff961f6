"""Quickstart: a robot drives, its antenna touches an obstacle, the resonator array shows it.

The paper's Fig. 10: self-motion keeps the 7–8 Hz neurons busy; on contact the activity
jumps to the neuron tuned near the clamped rod's low mode, which gives the distance.
"""
from __future__ import annotations

import time

from .. import spec as specs
from ..network import ResonatorArray
from ..preprocess import make_chain
from ..readout import ContactDetector, band_activity_hz, dominant_hz
from ..report import Report, draw_rate_map
from ..stimuli import RobotScene, scene_from_spec

SECTIONS = ("network", "stimulus", "preprocess", "readout")


def build(spec: dict):
    """Check the whole spec and build every part, before any simulation runs."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("network"):
        net_table = specs.check_section(spec, "network", ResonatorArray)
        array = ResonatorArray(**net_table)
    with specs.section("stimulus"):
        stim = specs.check_section(spec, "stimulus", RobotScene, extra=["kind"])
        scene = scene_from_spec(stim)
        scene.validate()
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g"])
        chain = make_chain(scene.rate_hz, scene.adc_bits, scene.full_scale_g, **pre)
    with specs.section("readout"):
        read = dict(specs.check_section(spec, "readout", ContactDetector, extra=["window_s"]))
        window_s = float(read.pop("window_s", 0.1))
        detector = ContactDetector(**{k: tuple(v) if isinstance(v, list) else v
                                      for k, v in read.items()})
    with specs.section("network"):
        array.check_rate(scene.rate_hz)
    return array, scene, chain, detector, window_s


def run(spec: dict, out_dir, quick: bool = False, log=print) -> dict:
    array, scene, chain, detector, window_s = build(spec)
    seed = int(spec.get("seed", 0))
    t_start = time.perf_counter()
    log(f"[1/4] generating the scene ({scene.duration_s:g} s at {scene.rate_hz:g} Hz, "
        f"{scene.speed_cm_s:g} cm/s, {len(scene.contacts)} contact(s), seed {seed})")
    rec = scene.generate(seed)
    log("[2/4] preprocessing: PCA alignment, low-pass, centring, square-wave coder")
    chain.fit(rec.samples)
    coded = rec.with_samples(chain.transform(rec.samples), "coded")
    log(f"[3/4] running {array.n_neurons} resonators ({array.band_hz[0]:g}–"
        f"{array.band_hz[1]:g} Hz) in Brian2 ({array.target}, dt {array.dt_ms:g} ms)")
    result = array.run(coded, window_s=window_s)
    rates = result.rate_map
    log("[4/4] reading out and writing the report")

    contacts = rec.contacts
    first_contact = contacts[0].t_s if contacts else scene.duration_s
    motion_hz = band_activity_hz(rates, min(1.0, first_contact / 2), first_contact)
    detections = detector.detect(rates)
    true = contacts[0] if contacts else None
    match = None
    if true is not None:
        after = [d for d in detections if d.end_s > true.t_s]
        match = min(after, key=lambda d: abs(d.onset_s - true.t_s)) if after else None
    contact_dominant = None
    if match is not None:
        episode = rates.sel(window_s=slice(match.onset_s, match.end_s - 1e-9)).sum("window_s")
        contact_dominant = float(dominant_hz(episode))
    summary = {
        "motion_dominant_hz": motion_hz,
        "contact_dominant_hz": contact_dominant,
        "contact_detected_s": match.onset_s if match else None,
        "contact_frequency_hz": match.frequency_hz if match else None,
        "distance_cm": match.distance_cm if match else None,
        "true_contact_s": true.t_s if true else None,
        "true_distance_cm": true.distance_cm if true else None,
        "detection_latency_s": (match.onset_s - true.t_s) if match and true else None,
        "distance_error_cm": (match.distance_cm - true.distance_cm) if match and true else None,
        "detections": [d.as_dict() for d in detections],
        "n_spikes": int(len(result.spike_i)),
        "simulation_wall_s": result.wall_s,
        "total_wall_s": time.perf_counter() - t_start,
    }
    report = Report(out_dir, "snn-antenna quickstart: contact on a driving robot")
    report.text(spec.get("description", ""))
    report.table([{"quantity": k, "value": v} for k, v in summary.items()
                  if not isinstance(v, list)], "Read-out")
    report.figure(_figure(rec, coded, rates, detections), "rate_map",
                  "Top: the accelerometer's two axes (ADC counts) and the coded input. "
                  "Bottom: spike rate of each resonator per window (the paper's Fig. 10H); "
                  "the dashed line marks the true contact, the solid one the detection.")
    summary = report.write(summary, spec, array.target)
    log(human_summary(summary, out_dir))
    return summary


def human_summary(s: dict, out_dir) -> str:
    lines = [f"self-motion activity centred at {s['motion_dominant_hz']:.1f} Hz"]
    if s["contact_detected_s"] is None:
        lines.append("no contact detected")
    else:
        lines.append(f"contact detected at {s['contact_detected_s']:.2f} s "
                     f"(true {s['true_contact_s']:.2f} s); most active neuron "
                     f"{s['contact_dominant_hz']:.1f} Hz")
        lines.append(f"decoded distance {s['distance_cm']:.1f} cm "
                     f"(true {s['true_distance_cm']:.1f} cm)")
    lines.append(f"simulation {s['simulation_wall_s']:.1f} s wall; report in {out_dir}/report.html")
    return "\n".join(lines)


def _figure(rec, coded, rates, detections):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1, ax2) = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True,
                                        gridspec_kw={"height_ratios": [1, 0.6, 2]})
    t = rec.t_s
    ax0.plot(t, rec.samples[:, 0], lw=0.5, label="x")
    ax0.plot(t, rec.samples[:, 1], lw=0.5, label="y")
    ax0.set_ylabel("ADC counts")
    ax0.legend(loc="upper left", fontsize=8)
    ax1.plot(t, coded.samples, lw=0.5, color="k")
    ax1.set_ylabel("coded I")
    mesh = draw_rate_map(ax2, rates)
    ax2.set_xlabel("time (s)")
    fig.colorbar(mesh, ax=[ax0, ax1, ax2], label="spike rate (Hz)", shrink=0.5)
    for c in rec.contacts:
        for ax in (ax0, ax1, ax2):
            ax.axvline(c.t_s, color="tab:cyan", ls="--", lw=1)
    for d in detections:
        ax2.axvline(d.onset_s, color="tab:green", lw=1.5)
        ax2.text(d.onset_s, ax2.get_ylim()[1], f" {d.distance_cm:.1f} cm", color="tab:green",
                 va="bottom", fontsize=8)
    return fig
