"""The gating study's report: calibrated and predicted rows, headline, figures, summary line."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...report.figures import draw_rate_map
from ...evaluation import threshold_figures as figures
from ...evaluation.scoring import visible
from ...evaluation.thresholds import (
    describe_difference,
    describe_interval,
    earns_its_place,
    f1_at,
    table_cell,
)
from ...evaluation.thresholds import GateRecall, ThStarFit
from ...report.page import Calibrated, Predicted, Report, by_speed
from .plan import Parts
from .recorded import report_section as recorded_section


# -- what the stages return ----------------------------------------------------------------
@dataclass
class Fig9Row:
    """One speed of Fig. 9: Th = 0, Th* and 2·Th*, pooled over the sweep's scenes."""
    thresholds: list
    rec: object                # the first scene's recording (drawn)
    scores: list | None = None
    maps: list | None = None   # the first scene's rate maps


@dataclass
class SeedPlan:
    pilot: int
    needed: int
    used: int
    budget: int
    margin_f1: float


@dataclass
class Results:
    """Every stage's output: what the summary and the report are made from."""
    outcome: object           # the sweep's ``SweepOutcome``; ``outcome.data`` is fitted
    fit: ThStarFit
    fig9: dict
    recall: GateRecall
    seeds: SeedPlan
    comparison: dict
    example: dict | None      # a ramp scene's online Th and rate map


# -- report --------------------------------------------------------------------------------
def human_summary(s: dict, out_dir) -> str:
    ok, why = earns_its_place(s)
    return "\n".join([
        "Th*: " + by_speed(s["th_star"], lambda t: f"{t:.3g} g"),
        *(f"F1 {label}: {describe_interval(v)}" for label, v in s["f1"].items()),
        *(f"{label}: {describe_difference(v)}" for label, v in s["differences"].items()),
        f"the gate {'earns' if ok else 'does not earn'} its place: {why}",
        f"report in {out_dir}/report.html ({s['total_wall_s']:.0f} s)"])


def quick_note(parts: Parts) -> str:
    sw = parts.sweep
    if parts.data is not None:
        return (f"Quick profile on recorded drives: {len(sw.speeds_cm_s)} speeds × "
                f"{len(sw.thresholds_g)} thresholds over {len(parts.data.training)} training "
                f"drive(s), gate trained {parts.gate.epochs} epoch(s), "
                f"{len(parts.data.held_out)} held-out drive(s). Too small to compare: Th* "
                "rests on a handful of contacts per speed on a coarse grid, the gate is barely "
                "trained, and the F1 intervals over so few drives are wide or missing. Run the "
                "full profile for any number worth reading.")
    return (f"Quick profile: {len(sw.speeds_cm_s)} speeds × {len(sw.thresholds_g)} "
            f"thresholds × {sw.n_scenes} scene(s) of {sw.scene_s:g} s, gate trained "
            f"{parts.gate.epochs} epoch(s), {parts.evaluation.max_seeds} evaluation seed(s) at "
            "most. Too small to compare: Th* rests on a handful of contacts per speed on a "
            "coarse grid (it may sit at one threshold at every speed), the gate is barely "
            "trained, and the F1 intervals over so few seeds are wide or missing. Run the full "
            "profile for any number worth reading.")


def _ci(d):
    return None if d.get("low") is None else (d["low"], d["high"])


def _calibrated(s: dict, parts: Parts) -> list:
    if parts.data is not None:
        return _calibrated_on_recordings(s)
    checks, cal = s["calibration_checks"], parts.calibration
    tp = checks["tp_at_th_star_vs_double"]
    return [
        Calibrated("Th*(27 cm/s) / Th*(12 cm/s)", round(checks["th_star_ratio_27_to_12"], 2),
                   "> 5 (Fig. 9)", "", "docs/reference.md (Fig. 9)",
                   "self-motion grows with speed² (antenna.self_motion_rms_g, "
                   "SELF_MOTION_G_AT_12) so that this ratio lands near 5: built in, not found"),
        Calibrated("true positives at Th* → 2·Th* (12 and 27 cm/s)",
                   by_speed(tp, lambda ab: f"{ab[0]} → {ab[1]}"),
                   "doubling Th* loses contacts (Fig. 9)", "", "docs/reference.md (Fig. 9)",
                   "antenna.IMPACT_TRANSFER, chosen so that impacts sit between the self-motion "
                   "at 12 and at 27 cm/s: built in, not found"),
        Calibrated("preprocessing (PCA axis of the two accelerometer axes)", "fitted",
                   "a separate calibration drive", "", "this study's [calibration] section",
                   f"{cal.duration_s:g} s at {cal.speed_cm_s:g} cm/s in the open, no posts; "
                   "never fitted on a scene that is scored"),
        Calibrated("Th*(speed)", by_speed(s["th_star"], lambda t: f"{t:.3g} g"),
                   "best F1 per speed on the sweep's scenes", "", "this study's sweep",
                   "the training data of the gate and the lookup table (monotone fit of each "
                   "speed's best Th); the evaluation uses other seeds")]


def _calibrated_on_recordings(s: dict) -> list:
    """Only what the recordings fitted: no generator constant enters a recorded run."""
    rec = s["recorded"]
    return [
        Calibrated("preprocessing (PCA axis of the two accelerometer axes)", "fitted",
                   "the recordings' calibration drive", "", rec["data"]["path"],
                   f"{rec['calibration drive']}: no labelled contact; never a scored drive"),
        Calibrated("Th*(speed)", by_speed(s["th_star"], lambda t: f"{t:.3g} g"),
                   "best F1 per logged speed on the training drives", "", rec["data"]["path"],
                   "the training data of the gate and the lookup table (monotone fit of each "
                   "speed's best Th) from " + ", ".join(rec["training drives"]) +
                   "; the evaluation scores only the held-out drives")]


def _predicted(s: dict, parts: Parts) -> list:
    d_lu, d_fx, d_sw = (s["differences"][k] for k in (
        "gated − lookup", "gated − best fixed in hindsight", "gated − fixed from the sweep"))
    gated, lat, fpm = s["f1"]["gated"], s["latency_gated_s"], s["fp_per_min_gated"]
    terrain = parts.evaluation.other_terrain
    where = ("held-out recorded drives (" + ", ".join(s["recorded"]["held-out drives"]) + ")"
             if parts.data is not None else
             f"new scenes (held-out speeds, ramps, steps, {terrain} ground)")
    return [
        Predicted(f"F1 of the gate on {where}", gated["mean"], "", None, "evaluation", _ci(gated),
                  gated["n"], "F1 pooled per seed over its scenes; mean over seeds"),
        *(Predicted(f"F1 of the gate: {row['scenes']}", row["F1 gated"]["mean"], "", None,
                    "evaluation", _ci(row["F1 gated"]), row["F1 gated"]["n"],
                    f"{row['contacts scored']} contacts scored") for row in s["per_category"]),
        Predicted("latency of the gate's detections", lat["mean"], "s", None, "evaluation",
                  _ci(lat), lat["n"], "contact onset to the end of the first detected window"),
        Predicted("false positives per minute under the gate", fpm["mean"], "1/min", None,
                  "evaluation", _ci(fpm), fpm["n"]),
        Predicted("F1 gated − lookup table", d_lu["mean"], "", None, "evaluation", _ci(d_lu),
                  d_lu["n"], d_lu["verdict"]),
        Predicted("F1 gated − best fixed Th in hindsight", d_fx["mean"], "", None,
                  "evaluation", _ci(d_fx), d_fx["n"],
                  f"{d_fx['verdict']}; the fixed Th ({s['oracle_th_g']:g} g) is chosen on the "
                  "evaluation scenes themselves: an oracle"),
        Predicted("F1 gated − fixed Th chosen on the sweep", d_sw["mean"], "", None,
                  "evaluation", _ci(d_sw), d_sw["n"],
                  f"{d_sw['verdict']}; the Th ({s['sweep_fixed_th_g']:g} g) a user would "
                  "deploy without a gate"),
        Predicted("false positives per minute at Th = 0 while driving (sweep)",
                  s["fp_per_min_at_th0_while_driving"], "1/min", None, "sweep", None, None,
                  "pooled over the sweep's scenes; the paper shows spurious spikes, no rate"),
        Predicted("gate recall error factor on held-out speeds",
                  s["recall_error_factor_held_out"], "×", None, "gate", None,
                  int(np.sum(~np.isin(parts.sweep.speeds_cm_s, parts.train_speeds))),
                  "exp(mean |log(recalled / Th*)|) over the sweep's speeds the gate was not "
                  "trained on")]


def _headline(s: dict, parts: Parts) -> str:
    if parts.data is not None:
        return _headline_recorded(s)
    d, seeds, ev = s["differences"], s["seeds"], parts.evaluation
    return (
        f"On scenes with new seeds — constant speeds the gate was not trained on "
        f"({', '.join(f'{v:g}' for v in parts.held_out_speeds)} cm/s), ramps over the whole "
        f"speed range, random speed steps, and the ramp and the steps on {ev.other_terrain} "
        f"ground — the learned gate's F1 is {describe_interval(s['f1']['gated'])}. Against the "
        f"lookup table of the same trained Th*: {describe_difference(d['gated − lookup'])}. "
        f"Against the best single fixed Th in hindsight ({s['oracle_th_g']:g} g, chosen on "
        f"these very scenes: an oracle no robot has): "
        f"{describe_difference(d['gated − best fixed in hindsight'])}. Against the fixed Th a "
        f"user would deploy, chosen on the sweep ({s['sweep_fixed_th_g']:g} g): "
        f"{describe_difference(d['gated − fixed from the sweep'])}. Seeds: a pilot of "
        f"{seeds['pilot']} gave the spread; resolving a difference of {seeds['margin_f1']:g} in "
        f"F1 (α = 0.05, power 0.8) needs {seeds['needed']}, {seeds['used']} were run (budget "
        f"{seeds['budget']}).")


def _headline_recorded(s: dict) -> str:
    d, rec, seeds = s["differences"], s["recorded"], s["seeds"]
    return (
        f"On the held-out recorded drives ({', '.join(rec['held-out drives'])}: never swept, "
        f"never trained on), the gate's F1 is {describe_interval(s['f1']['gated'])}. Against "
        f"the lookup table of the same Th*: {describe_difference(d['gated − lookup'])}. "
        f"Against the best single fixed Th in hindsight ({s['oracle_th_g']:g} g, chosen on "
        f"these very drives: an oracle): "
        f"{describe_difference(d['gated − best fixed in hindsight'])}. Against the fixed Th "
        f"chosen on the training drives ({s['sweep_fixed_th_g']:g} g): "
        f"{describe_difference(d['gated − fixed from the sweep'])}. Each held-out drive is one "
        f"paired unit (n = {seeds['used']}); resolving a difference of {seeds['margin_f1']:g} "
        f"in F1 at this spread needs {seeds['needed']}.")


def write_report(out_dir: Path, spec: dict, parts: Parts, r: Results, s: dict,
                 quick: bool) -> None:
    ds = r.outcome.data
    rep = Report(out_dir, "snn-antenna: gating threshold and the learned speed gate",
                 quick=quick, quick_note=quick_note(parts))
    ok, why = earns_its_place(s)
    rep.calibrated(*_calibrated(s, parts))
    rep.predicted(*_predicted(s, parts))
    rep.text(spec.get("description", ""))
    recorded_section(rep, s)
    rep.heading("Headline: the gate on " + ("held-out recorded drives" if parts.data is not None
                                            else "new scenes"))
    rep.text(_headline(s, parts))
    rep.text(f"Verdict: the gate {'earns' if ok else 'does not earn'} its place — {why}.")
    rep.text("The read-out never sees the ground truth: the preprocessing is fitted on a "
             "separate calibration drive, the gate and the lookup table read only the speed "
             "command, the resonator array and the detector read only the coded signal; every "
             "detection (true or false positive, duplicate, detection of an out-of-band "
             "contact) is scored against the labelled contacts afterwards.")
    rep.table([{"scenes": r["scenes"], "contacts scored": r["contacts scored"],
                **{k: table_cell(v) for k, v in r.items()
                   if k not in ("scenes", "contacts scored")}}
               for r in s["per_category"]],
              "Per scene type: mean over seeds (95 % CI); differences paired by seed")
    if s.get("coders"):
        rep.table(coder_rows(s, parts), "Coders with the gate's Th on the same evaluation "
                  "scenes: F1 over seeds (95 % CI, n) and its difference from the study's own "
                  "coder, paired by seed (\"not resolved\" when the interval spans zero)")
    rep.figure(figures.f1_per_category(s), "f1_per_category",
               "F1 per scene type, mean over seeds with 95 % CI (clipped to [0, 1]): the gate, "
               "the lookup table, the best fixed Th in hindsight and the fixed Th chosen on "
               "the sweep.")
    rep.figure(figures.f1_methods(s), "f1_methods",
               "F1 over all evaluation scenes for each fixed Th evaluated (mean over seeds, "
               "95 % CI), with the gate and the lookup table (line: mean, band: 95 % CI).")
    if r.example is not None and "map" in r.example:
        rep.figure(_fig_ramp(r.example, parts), "ramp_example",
                   ("A held-out recorded drive" if parts.data is not None else "A ramp scene")
                   + ": speed command, the gate's online Th (and the lookup), and "
                   "the rate map under the gated Th; dashed lines: true contacts (cyan: in the "
                   "array's band, grey: outside it), green: detections.")
    rep.heading("Th × speed sweep (the gate's training data)")
    rep.figure(figures.f1_curves(ds), "f1_vs_threshold",
               "F1, false positives per minute and mean latency against Th, one line per speed "
               "(pooled over the sweep's scenes); dots mark Th*(speed), crosses each speed's "
               "own best Th before the monotone fit. Th = 0 is drawn at the left edge.")
    rep.table([_sweep_row(ds, v, b, t) for v, b, t in
               zip(ds.speed_cm_s.values, ds.best_th_g.values, ds.th_star_g.values)],
              "Th*(speed) from the sweep: each speed's best Th and their monotone fit")
    if r.fig9:
        _fig9_section(rep, r, parts)
    rep.heading("The speed gate (Brian2 associative memory)")
    rep.figure(figures.gate_recall(r.recall), "gate",
               "Left: learning curves, recall error factor exp(mean |log(recalled/Th*)|) on "
               "trained and held-out speeds. Right: Th* from the sweep, the gate's recall and "
               "the lookup table.")
    rep.write(s, spec, parts.array.target)


def _fig9_section(rep, r: Results, parts: Parts) -> None:
    rep.heading("Fig. 9 in kind (calibrated: see above)")
    rep.figure(_fig9(r.fig9, parts), "fig9_rate_maps",
               "Rate maps of one scene at low and high speed for Th = 0, Th* and 2·Th*; "
               "dashed lines mark true contacts (cyan: in the array's band, grey: outside it), "
               "green lines detections.")
    rep.table([{"speed (cm/s)": v, "Th": lab, "Th (g)": th, **sc.as_dict()}
               for v, row in r.fig9.items()
               for lab, th, sc in zip(("0", "Th*", "2·Th*"), row.thresholds, row.scores)],
              "Detections pooled over the sweep's scenes")


def coder_rows(s: dict, parts: Parts) -> list[dict]:
    """The study's own coder (``[preprocess] coder``) and each of ``evaluation.coders``."""
    own = parts.preprocess.settings.get("coder", "square")
    rows = [{"coder": f"{own} (the study's)", "F1": table_cell(s["f1"]["gated"]),
             "minus the study's coder": "—"}]
    return rows + [{"coder": f"{label} ({v['coder']})", "F1": table_cell(v["f1"]),
                    "minus the study's coder": f"{table_cell(v['minus_own_coder'])}, "
                                               f"n = {v['minus_own_coder']['n']}"}
                   for label, v in s["coders"].items()]


def _sweep_row(ds, v, best, th_star) -> dict:
    at_zero = ds.sel(speed_cm_s=v).isel(threshold_g=0)
    return {"speed (cm/s)": float(v), "best Th (g)": float(best), "Th* (g)": float(th_star),
            "F1 at Th*": f1_at(ds, v, th_star), "FP/min at Th = 0": float(at_zero.fp_per_min),
            # every scored contact is a hit or a miss, whatever the threshold
            "contacts scored": int((at_zero.tp + at_zero.misses).sum()),
            "out of the array's band": int(at_zero.out_of_band_contacts.sum())}


def _draw_map(ax, rates, rec, parts: Parts, title: str, **mesh_kwargs):
    """A rate map with the true contacts (cyan: in the array's band, grey: outside it) and
    the detections (green); returns the mesh for its colour bar."""
    mesh = draw_rate_map(ax, rates, **mesh_kwargs)
    for c in rec.truth.contacts:
        ok = visible(c, parts.readout.detector, parts.array)
        ax.axvline(c.t_s, color="tab:cyan" if ok else "0.6", ls="--", lw=0.8)
    for d in parts.readout.detector.detect(rates):
        ax.axvline(d.onset_s, color="tab:green", lw=1.2)
    ax.set_title(title, fontsize=9)
    return mesh


def _fig9(fig9: dict, parts: Parts):
    """Rows: speeds; columns: Th = 0, Th*, 2·Th*. One colour scale for all panels (so a
    brighter cell is a higher rate anywhere), sized to stay readable in the report's column."""
    from matplotlib.lines import Line2D

    vmax = max(1.0, *(float(np.nanmax(m.values)) for row in fig9.values() for m in row.maps))
    fig, axes = figures.pyplot().subplots(len(fig9), 3, figsize=(10, 2.6 * len(fig9) + 0.9),
                                          squeeze=False, sharex=True, sharey=True,
                                          layout="constrained")
    for r, (v, row) in enumerate(fig9.items()):
        for c, (lab, th, rates) in enumerate(zip(("Th", "Th*", "2·Th*"), row.thresholds,
                                                 row.maps)):
            mesh = _draw_map(axes[r, c], rates, row.rec, parts, f"{lab} = {th:.3g} g",
                             vmin=0.0, vmax=vmax)
            if c:
                axes[r, c].set_ylabel("")
        axes[r, 0].set_ylabel(f"{v:g} cm/s\nneuron (Hz)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.colorbar(mesh, ax=axes, label="spike rate (Hz)", shrink=0.8)
    fig.legend(handles=[Line2D([], [], color="tab:cyan", ls="--", label="contact in the band"),
                        Line2D([], [], color="0.6", ls="--", label="contact outside the band"),
                        Line2D([], [], color="tab:green", label="detection")],
               loc="outside lower center", ncols=3, frameon=False)
    return fig


def _fig_ramp(example: dict, parts: Parts):
    rec = example["rec"]
    # A narrow column holds the rate map's colour bar, so the three time axes stay aligned.
    fig, axes = figures.pyplot().subplots(3, 2, figsize=(11, 7.5), sharex="col", gridspec_kw={
        "height_ratios": [0.6, 0.8, 1.6], "width_ratios": [1, 0.02]})
    (a0, a1, a2), cax = axes[:, 0], axes[2, 1]
    axes[0, 1].set_visible(False)
    axes[1, 1].set_visible(False)
    a0.plot(rec.t_s, rec.meta["speed_cm_s"], color="k")
    a0.set_ylabel("speed (cm/s)")
    a1.plot(rec.t_s, example["gated_th"], color="tab:red", label="gate (online)")
    a1.plot(rec.t_s, example["lookup_th"], color="tab:blue", ls="--", label="lookup")
    figures.th_axis(a1, np.r_[example["gated_th"], example["lookup_th"]])
    a1.set_ylabel("Th (g)")
    a1.legend(fontsize=8)
    fig.colorbar(_draw_map(a2, example["map"], rec, parts, "gated"), cax=cax, label="rate (Hz)")
    a2.set_ylabel("neuron (Hz)")
    a2.set_xlabel("time (s)")
    fig.tight_layout()
    return fig
