"""The tuning sweep's page: the calibration k → preferred frequency, the tuning curves, the
maps over k, b and I, what the sweep calibrates apart from what it predicts."""
from __future__ import annotations

from ...engine.evaluators import NeuronSweep
from ...evaluation import tuning
from ...evaluation.tuning import ReadPoint
from ...networks import neurons
from ...report.page import Calibrated, Predicted, Report, fmt


def quick_note(summary: dict, neuron: NeuronSweep) -> str:
    """What the quick profile's grid is too small for, from the grid that ran."""
    grid = summary["grid"]
    sizes = " × ".join(f"{len(v)} {name}" for name, v in
                       (("k", grid.get("k", [])), ("b", grid.get("b", [])),
                        ("I", grid.get("I", [])), ("frequencies", grid.get("input_hz", [])))
                       if v)
    step = summary.get("calibration", {}).get("input_hz_step")
    return (f"quick profile: too small to compare with the paper. A grid of {sizes}, "
            f"{neuron.duration_s:g} s per point ({neuron.engine}); frequency steps of "
            f"{fmt(step)} Hz limit the slope to a few per cent, and a b or I with one or two "
            "values draws no trend.")


PAPER_HZ_PER_K = 7.0 / 0.3425   # the paper's 7 Hz neuron has k = 0.3425 (docs/reference.md)


def _range_text(pair) -> str:
    return f"{fmt(pair[0])} to {fmt(pair[1])} Hz" if pair else "(none)"


def calibrated_and_predicted(report: Report, summary: dict) -> None:
    """What the sweep calibrates (the foundation's constant) apart from what it predicts."""
    cal = summary.get("calibration")
    if not cal or cal["hz_per_k_centroid"] is None:
        return
    used = fmt(summary["reference_used"])
    report.calibrated(Calibrated(
        "preferred frequency per unit k (tuning-curve centroid)",
        value=neurons.DRIVEN_HZ_PER_K, target=cal["hz_per_k_centroid"], unit="Hz",
        source=f"the centroid this sweep measures at {used}; the constant was set "
               "from the full profile's grid",
        how="neurons.DRIVEN_HZ_PER_K, the constant the array uses to place its neurons"))
    report.predicted(Predicted(
        "preferred frequency per unit k (tuning-curve peak)", value=cal["hz_per_k_peak"],
        unit="Hz", paper=PAPER_HZ_PER_K,
        source="paper: the 7 Hz neuron has k = 0.3425 (docs/reference.md)",
        # the spread of peak/k over k is a range, not a confidence interval: it goes in the
        # note, never in the table's "95 % interval" column
        n=cal["responding_k"],
        note=(f"peak/k ranges {_range_text(cal['hz_per_k_peak_range'])} over the "
              f"{cal['responding_k']} k values that fired; the paper codes with amplitude "
              f"0.085 in its scaling, "
              f"this sweep at {used}; the grid's frequency step is "
              f"{fmt(cal['input_hz_step'])} Hz")))
    if "fwhm_vs_I" in summary:
        w = summary["fwhm_vs_I"]
        report.predicted(Predicted(
            "band width (FWHM) at each input amplitude I",
            value={f"I = {fmt(i)}": f for i, f in zip(w["I"], w["fwhm_hz"])}, unit="Hz",
            source="the paper's Fig. 8G: the amplitude sets the band's width (no number)",
            note="widens with I as in the paper" if _increasing(w["fwhm_hz"])
            else "does not widen monotonically with I here"))


def _increasing(values) -> bool:
    v = [x for x in values if x is not None]
    return len(v) >= 2 and all(b > a for a, b in zip(v, v[1:]))


def _calibration_section(report: Report, summary: dict) -> None:
    cal = summary.get("calibration")
    if not cal or cal["hz_per_k_peak"] is None:
        return   # no k gave a single spike
    report.heading("Calibration: k → preferred frequency")
    report.text(
        f"Least-squares slope through the origin: {cal['hz_per_k_peak']:.3g} Hz per unit k "
        f"from the tuning curves' peaks, {cal['hz_per_k_centroid']:.3g} from their "
        f"geometric centroids; the array places its neurons with "
        f"{cal['foundation_driven_hz_per_k']:g} Hz per unit k (neurons.DRIVEN_HZ_PER_K, "
        f"defined as the centroid), which "
        f"{'holds' if cal['driven_hz_per_k_holds'] else 'does not hold'} within "
        f"{cal['tolerance'] * 100:.0f} %. Frequency step of the grid: "
        f"{cal['input_hz_step']:.3g} Hz.")
    kp = summary["k_to_peak_hz"]
    report.table([{"k": k, "peak_hz": p, "centroid_hz": c,
                   "peak/k (Hz per unit k)": (p / k if p else None)}
                  for k, p, c in zip(kp["k"], kp["peak_hz"], kp["centroid_hz"])],
                 f"Preferred frequency per k at {fmt(summary['reference_used'])}")


def write_report(report: Report, rate, maps, summary: dict, point: ReadPoint) -> None:
    _calibration_section(report, summary)
    report.figure(tuning.tuning_curves_figure(rate, point), "tuning_curves",
                  "Spike rate (after the settling time) against the input frequency of the "
                  "square-wave coder's output. Left: one curve per k at the reference b and I. "
                  "Right: one curve per input amplitude I: the amplitude sets the band width "
                  "(the paper's Fig. 8G).")
    cal = summary.get("calibration") or {}
    report.figure(tuning.heatmaps_figure(rate, maps, point, cal.get("hz_per_k_peak")),
                  "heatmaps",
                  "Left: spike rate over k and input frequency (reference b, I) with the "
                  "frequency per unit k the array uses and the one fitted to these peaks. "
                  "Middle: band width (FWHM) of each tuning curve over k and I. Right: peak "
                  "spike rate over k and b (the paper's Fig. 8H). Blank cells: the neuron "
                  "never fired.")
    report.figure(tuning.maps_figure(summary), "maps",
                  f"Calibration k → preferred frequency; band width vs I; peak rate vs b "
                  f"(at {fmt(summary['reference_used'])}; a b without a point never fired).")
