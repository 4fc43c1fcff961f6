"""The baseline comparison's report: what was calibrated, what is predicted, tables, figures."""
from __future__ import annotations

import numpy as np

from ...evaluation import comparison_figures as figures
from ...evaluation import signal as bench_signal
from ...evaluation.antenna_fit import FittedAntenna
from ...evaluation.comparison import (
    Comparison,
    coder_rows,
    cost_rows,
    data_text,
    design_rows,
    label,
    result_rows,
    spiking_cost_text,
    spiking_distance_rows,
    spiking_rows,
    tuned_curve_rows,
    tuned_text,
)
from ...evaluation.confusion import (
    confusion,
    confusion_sentence,
    error_rates,
    most_confused_pair,
)
from ...readout.spiking_decoders import TRAINING_FREE
from ...report import stats
from ...report.page import Calibrated, Predicted, Report

SOURCE = "paper (docs/reference.md)"
RECORDED_QUICK_NOTE = ("Quick profile on recorded contacts: every imported contact, 2 seeds, "
                       "fewer NMF sizes, designs and epochs; accuracies, rmse and the confusion "
                       "matrix are too small to compare with the paper or the full run.")
QUICK_NOTE = ("Quick profile: 10 contacts per material and site, 2 seeds. The signal statistics "
              "(r², precision, CV of τ_low, wood/aluminium sites: ten contacts each, as the "
              "paper's test) are comparable with the full run; every classifier and regressor "
              "here trained on a tenth of the contacts, so accuracies, rmse and the confusion "
              "matrix are too small to compare with the paper or the full run.")
_pair = "{0[0]:.4f}, {0[1]:.3f}".format  # a law's (slope, intercept)
def _calibrated(report: Report, cmp: Comparison, summary: dict) -> None:
    """What the generator was set to match, apart from what it predicts."""
    s, paper = cmp.signal, bench_signal.PAPER_SIGNAL
    rows = [
        Calibrated("r² of the low-mode law", s["r2_low"], 0.995, "", SOURCE,
                   "low-mode scatter LOW_SCATTER_DEX; antenna.py, see docs/materials.md"),
        Calibrated("r² of the high-mode law", s["r2_high"], 0.987, "", SOURCE,
                   "high-mode scatter HIGH_SCATTER_DEX"),
        Calibrated("single-contact precision, low peak", s["single_contact_precision_mm"],
                   6.2, "mm", SOURCE, "LOW_SCATTER_DEX"),
        Calibrated("low law (slope, intercept)", _pair(s["low_law"]), _pair(paper["low_law"]),
                   "", SOURCE, "the generator uses the paper's law"),
        Calibrated("high law (slope, intercept)", _pair(s["high_law"]),
                   _pair(paper["high_law"]), "", SOURCE, "the generator uses the paper's law"),
        Calibrated("CV of τ_low within a site (median)", 100 * s["tau_low_cv_median"],
                   "< 1", "%", SOURCE, "TAU_LOW_CV and the decay fit (readout/events.py)")]
    if "wood_aluminium_sites" in s:
        rows.append(Calibrated(
            "sites where wood and aluminium τ_low differ (t-test, 10 each)",
            f"{s['wood_aluminium_sites_differing']} of {s['wood_aluminium_sites']}",
            "12 of 16", "", SOURCE, "ANTENNA_CONTACT_STIFFNESS_N_M (energy into the rod)"))
    if "linear_low_peak" in cmp.results:
        rows.append(Calibrated(
            "distance rmse, linear regression on the low peak",
            summary["distance_rmse_mm"]["linear_low_peak"]["mean"], 6.2, "mm", SOURCE,
            "LOW_SCATTER_DEX (the same statistic as the precision above, on test contacts)"))
    if "mlp_spectrum_material" in cmp.results:
        rows.append(Calibrated(
            f"{len(cmp.materials)} materials, full-spectrum MLP accuracy",
            100 * summary["material_accuracy"]["mlp_spectrum_material"]["mean"], 94.2, "%",
            SOURCE, "ROD_COUPLING: how much of the rod's own mode reaches the tip "
            "(benchmarks/calibrate_rod_coupling.py)"))
    report.calibrated(*rows)


def _measured(quantity: str, values, unit: str, paper, scale: float = 1.0, *,
              source: str = SOURCE, note: str = "") -> Predicted:
    """A prediction from per-seed values: ``scale`` × their mean, with its interval. Every
    quantity here (an rmse, an accuracy) is ≥ 0: its interval is the bounded one
    (docs/reference.md, "Statistics rules"), and below the rule's n it carries no verdict."""
    values = scale * np.asarray(values, dtype=float)
    if len(values) < 2:
        return Predicted(quantity, float(values.mean()), unit, paper, source, None,
                         len(values), note)
    iv = stats.mean_interval(values, bounds=(0.0, np.inf))
    if iv.n < stats.MIN_N_TO_RESOLVE:
        note = "; ".join(filter(None, [note, iv.verdict]))
    return Predicted(quantity, iv.mean, unit, paper, source, (iv.low, iv.high), iv.n, note)


def _predicted(report: Report, cmp: Comparison, summary: dict) -> None:
    results = cmp.results
    pred = [Predicted("spread of the high / low peak (residual, dex)",
                      cmp.signal["spread_ratio_high_to_low"], "", "≈ 3", SOURCE,
                      note="lowered by the high-mode scatter that r² = 0.987 needs")]
    pred = [r for r in pred if r.value is not None]
    papers = {"mlp_parametric": 2.93, "mlp_spectrum": 1.71,
              "mlp_spectrum_sub10": "≈ full spectrum", "mlp_low_half": "≈ 2 peaks"}
    pred += [_measured(f"distance rmse, {label(name)}", results[name].values("rmse_mm"), "mm",
                       paper) for name, paper in papers.items() if name in results]
    if "nmf_30" in results:
        pred.append(_measured(f"{len(cmp.materials)} materials, NMF-30 → MLP accuracy",
                              results["nmf_30"].values("accuracy"), "%", "≥ 86", 100))
    if "mlp_5_8_2" in results:
        two = results["mlp_5_8_2"]
        pair = "/".join((summary.get("two_material") or {}).get("materials",
                                                                 ["wood", "aluminium"]))
        pred += [_measured(f"5-8-2 {pair} network, rmse", two.values("rmse_mm"), "mm",
                           "±4"),
                 _measured(f"5-8-2 {pair} network, accuracy",
                           100 * two.values("accuracy"), "%", 87)]
    if "mlp_spectrum_material" in results:
        cm = confusion(results["mlp_spectrum_material"], len(cmp.materials))
        pred += [Predicted(r.quantity, r.value, r.unit, r.paper, SOURCE, r.interval, r.n,
                           r.note) for r in error_rates(cm, cmp.materials)]
    pred += _chosen_predicted(summary)
    for name, row in (summary.get("spiking") or {}).get("against_fft", {}).items():
        pred.append(_measured(f"{len(cmp.materials)} materials, {label(name)}",
                              results[name].values("accuracy"),
                              "%", None, 100, source="this run (no spiking material result in "
                              "the paper)", note=f"{100 * row['fraction_of_fft_mlp']:.0f} % of "
                              "the full-spectrum MLP"))
    report.predicted(*pred)


CODER_CAPTION = (
    "Coders side by side, on the same channels, contacts and splits: {n}-material accuracy "
    "(mean [95 % interval] over the splits, n), its share of the full-spectrum MLP per "
    "split, the ceiling of the coded input (an MLP 51 on each channel's half-cycles, mean "
    "|current| and changes of value per time bin, no neurons), what coding loses (FFT-MLP − "
    "ceiling) and what the resonators lose (ceiling − read-out), paired by split; cost per "
    "event (coding + Brian2) and its ratio to the FFT pipeline's, both measured in this run, "
    "best of n runs taken in turn.")


def write_report(report: Report, spec: dict, summary: dict, cmp: Comparison) -> None:
    recorded = summary["data"].get("recorded")
    antenna = summary["data"].get("antenna")
    if recorded:
        if antenna:
            _fitted(report, summary, recorded)
        report.predicted(*_recorded_results(cmp, summary))
    else:
        _calibrated(report, cmp, summary)
    _predicted(report, cmp, summary)
    results, feats = cmp.results, cmp.features
    report.text(recorded_description(summary, recorded) if recorded
                else spec.get("description", ""))
    cut = [line for line in summary.get("left_out", []) if not line.startswith("fitted:")]
    if cut:
        report.table([{"left out or clipped": line} for line in cut],
                     "Parts of the spec the data cannot carry (its rate: "
                     f"{summary['data']['rate_hz']:g} Hz)")
    if recorded:
        _write_recorded(report, cmp, recorded)
    else:
        report.text("How the generator makes materials differ (antenna.py, docs/materials.md): "
                    "each rod's own bending mode rings along while the antenna rests on it "
                    "(Euler–Bernoulli, from textbook E, ρ and loss factor, 12 mm × 15 cm), the "
                    "impact lasts Hertz's contact time, and the rod takes energy out of the "
                    "antenna's modes by its loss factor and compliance. The calibrated numbers "
                    "above were set; the predicted ones were not, and only those stand beside "
                    "the paper's results.")
    report.heading("The signal")
    if antenna:
        report.figure(figures.frequency_laws(feats, cmp.signal, antenna),
                      "fig2c_frequency_laws",
                      "Peak frequency vs contact distance, low and high mode of the scored "
                      "contacts; lines: their fit (solid) and the laws fitted on the "
                      "calibration contacts (dashed).")
        report.figure(figures.decay_times(feats, cmp.materials), "fig5d_decay_times",
                      "Decay time of the low mode vs distance per material, mean ± sd per "
                      "distance, scored contacts.")
    else:
        report.figure(figures.frequency_laws(feats, cmp.signal), "fig2c_frequency_laws",
                      "Peak frequency vs contact distance, low and high mode (paper's Fig. "
                      "2C); lines: our fit (solid) and the paper's law (dashed).")
        report.figure(figures.decay_times(feats), "fig5d_decay_times",
                      "Decay time of the low mode vs distance for wood and aluminium (Fig. "
                      "5D).")
    report.heading("Distance and material read-outs")
    report.table(result_rows(summary), "Mean ± sd over seeds, test contacts only; the "
                                       "calibrated and predicted tables above carry the "
                                       "intervals and the paper's values.")
    dist = [k for k, r in results.items() if r.baseline.task == "distance"
            and k not in TRAINING_FREE]
    if dist:
        report.figure(figures.predicted_distance(results, dist), "fig4b_predicted_distance",
                      "Predicted vs true distance per pipeline, first seed (Fig. 4B).")
    free = [k for k in TRAINING_FREE if k in results]
    if free and antenna:
        report.table([{"decoder": label(k), "distance rmse (mm)":
                       f"{summary['distance_rmse_mm'][k]['mean']:.2f}"} for k in free],
                     "Training-free decoders: each inverts the low-mode law fitted on the "
                     "calibration contacts (never scored) and learns nothing from the "
                     "training split; test contacts of every split.")
    elif free:
        report.table([{"decoder": label(k), "distance rmse (mm)":
                       f"{summary['distance_rmse_mm'][k]['mean']:.2f}"} for k in free],
                     "Self-consistency, not a result: these decoders learn nothing and invert "
                     "the generator's own frequency law, so they show the simulator agreeing "
                     "with itself; they are not compared with the paper.")
    _write_materials(report, summary, cmp)
    if "spiking" in summary:
        _write_spiking(report, summary)
    if "chosen_bank" in summary:
        _write_chosen(report, summary, cmp)
    report.figure(figures.pareto(summary), "pareto_cost_accuracy",
                  "Accuracy vs cost per event (feature extraction + decoder, wall time measured "
                  "in this run) of every pipeline; the line joins the Pareto front; numbers "
                  "are keyed in the table below.")
    report.table(cost_rows(summary), "Cost: inference per event and training wall time "
                                     "(mean over seeds)")
    if not recorded:
        report.text(data_text(summary))


def _recorded_results(cmp: Comparison, summary: dict) -> list[Predicted]:
    """On recordings nothing was calibrated: the generator's calibration targets are results
    like any other (the contacts' own statistics, the read-outs' scores)."""
    s, source = cmp.signal, SOURCE
    rows = [Predicted("r² of the low-mode law", s["r2_low"], "", 0.995, source),
            Predicted("r² of the high-mode law", s["r2_high"], "", 0.987, source),
            Predicted("single-contact precision, low peak", s["single_contact_precision_mm"],
                      "mm", 6.2, source),
            Predicted("CV of τ_low within a site (median)", 100 * s["tau_low_cv_median"], "%",
                      "< 1", source)]
    # a statistic with no finite value on these contacts (a peak that never moved) is not shown
    rows = [r for r in rows if r.value is not None]
    if "linear_low_peak" in cmp.results:
        rows.append(_measured("distance rmse, linear regression on the low peak",
                              cmp.results["linear_low_peak"].values("rmse_mm"), "mm", 6.2))
    if "mlp_spectrum_material" in cmp.results:
        rows.append(_measured("materials, full-spectrum MLP accuracy",
                              cmp.results["mlp_spectrum_material"].values("accuracy"), "%",
                              94.2, 100))
    if "mlp_parametric_material" in cmp.results:
        rows.append(_measured("materials, MLP on both peaks' F, A and τ",
                              cmp.results["mlp_parametric_material"].values("accuracy"), "%",
                              None, 100))
    return rows


def recorded_description(summary: dict, recorded: dict) -> str:
    """What the data is: recorded contacts, their materials, distances and repetitions."""
    ds = summary["data"]
    antenna = ds.get("antenna") or {}
    distances = ", ".join(f"{d:g}" for d in antenna.get("distances_cm", []))
    return (f"The paper's read-outs (linear regression on the low peak, MLPs on parametric "
            f"features and on the FFT amplitude spectrum, NMF band-pass filters) and the "
            f"spiking read-outs on {recorded['counts']['events']} contacts recorded by a lab "
            f"and imported from {recorded['path']} at {ds['rate_hz']:g} Hz: "
            f"{len(summary['materials'])} materials named by its labels "
            f"({', '.join(summary['materials'])})"
            + (f", contacts at {distances} cm" if distances else "")
            + ". Splits are by repetition, after the calibration repetitions are held out; "
            "every number is the mean over splits on test contacts with its 95 % interval.")


def _fitted(report: Report, summary: dict, recorded: dict) -> None:
    """What was fitted on the calibration contacts' labels: each value and its source."""
    antenna = summary["data"]["antenna"]
    labels = recorded["labels"]
    source = (f"labels {labels['file']} (sha256 {labels['sha256'][:16]}…), repetitions "
              f"{antenna['repetitions']}")
    target = f"the labels of {antenna['n_contacts']} calibration contacts"
    report.calibrated(*[Calibrated(quantity, value, target, unit, source, how)
                        for quantity, value, unit, how in FittedAntenna.rows_of(antenna)])


def _write_recorded(report: Report, cmp: Comparison, recorded: dict) -> None:
    """Where the contacts came from: the import's folder, hashes and counts; every contact
    left out, by reason and distance."""
    counts = recorded["counts"]
    left_out = ", ".join(f"{n} {r.replace('_', ' ')}" for r, n in counts["excluded"].items()
                         if n) or "none"
    data = cmp.data
    fitted = ("; what was fitted on the held-out calibration contacts' labels is listed as "
              "calibrated above, the rest is predicted" if data.get("antenna") else
              "; nothing above is calibrated")
    report.text(f"Data: {counts['events']} recorded contacts imported "
                f"from {recorded['path']} ({counts['labels']} labelled; left out at import: "
                f"{left_out}){fitted}.")
    by_position = counts.get("excluded_by_position") or {}
    rows = []
    for reason, n in counts["excluded"].items():
        by_d = {d: row[reason] for d, row in by_position.items() if row.get(reason)}
        if n:                  # a contact found without a label has no distance
            rows.append({"left out": f"at import: {reason.replace('_', ' ')}", **by_d,
                         **({"no label": n - sum(by_d.values())}
                            if n > sum(by_d.values()) else {})})
    rows += [{"left out": ("held out to calibrate" if reason == "calibration" else
                           f"event processing: {reason.replace('_', ' ')}"), **by_d}
             for reason, by_d in data.get("left_out_by_position", {}).items()]
    if rows:
        columns = sorted({k for r in rows for k in r if k not in ("left out", "no label")},
                         key=float)
        extra = ["no label"] if any("no label" in r for r in rows) else []
        report.table([{"left out": r["left out"],
                       **{f"{d} cm": r.get(d, 0) for d in columns},
                       **{k: r.get(k, 0) for k in extra},
                       "total": sum(r.get(d, 0) for d in [*columns, *extra])} for r in rows],
                     "Every contact left out of the scoring, by reason and distance (the "
                     "import's exclusions are listed one by one in its exclusions.csv)")
    if data.get("fitted"):
        report.table([{"fitted on the calibration labels": line} for line in data["fitted"]],
                     "The lab's antenna as fitted, and the study's typed values it replaced")
    report.table([{"file": f"{r['name']}/{f['file']}" if r["kind"] in ("record", "rosbag")
                   else f["file"], "bytes": f["bytes"], "sha256": f["sha256"]}
                  for r in recorded["recordings"] for f in r["files"]]
                 + [{"file": recorded["labels"]["file"], "bytes": recorded["labels"]["bytes"],
                     "sha256": recorded["labels"]["sha256"]}],
                 f"The recordings and the labels table (data set {recorded['key']})")


def _tuned_text(summary: dict) -> str:
    """The tuned bank's account; on recordings, which recorded contacts placed its channels."""
    t = summary["spiking"]["tuned"]
    if "calibration_repetitions" not in t:
        return tuned_text(summary)
    reps = ", ".join(map(str, t["calibration_repetitions"]))
    where = (f"{t['calibration_seed']}: the recorded contacts of repetitions {reps} "
             f"in {t['calibration_source']}, held out of every split")
    return tuned_text({**summary, "spiking": {**summary["spiking"],
                                              "tuned": {**t, "calibration_seed": where}}})


def _write_materials(report: Report, summary: dict, cmp: Comparison) -> None:
    results = cmp.results
    if "mlp_spectrum_material" in results:
        report.figure(figures.confusion_matrix(results["mlp_spectrum_material"], cmp.materials),
                      "fig6d_confusion", f"{len(cmp.materials)}-material confusion matrix "
                      "of the full-spectrum "
                      "MLP, all seeds' test contacts, rows normalised (Fig. 6D).")
        cm = confusion(results["mlp_spectrum_material"], len(cmp.materials))
        if summary["data"].get("recorded"):
            (a, b), rate = most_confused_pair(cm, cmp.materials)
            report.text(f"The most confused pair: {a} ↔ {b} ({100 * rate:.1f} % of their "
                        "contacts taken for each other).")
        else:
            report.text(confusion_sentence(cm, cmp.materials))
    nmf_names = [k for k in results if k.startswith("nmf_")]
    if nmf_names:
        shown = "nmf_9" if "nmf_9" in results else nmf_names[0]
        report.figure(figures.nmf_basis(results[shown], cmp.features), "fig7a_nmf_basis",
                      f"The {shown.split('_')[1]} NMF basis vectors as band-pass filters "
                      "(first seed; Fig. 7A).")
        report.figure(figures.nmf_accuracy(summary), "fig7b_nmf_accuracy",
                      "Material accuracy vs NMF dimension (mean ± sd over seeds), the "
                      "full-spectrum MLP (dashed) and the spiking read-outs at their number "
                      "of resonators (red; Fig. 7B).")


def _write_spiking(report: Report, summary: dict) -> None:
    report.heading("Spiking read-out beside the FFT")
    report.table(spiking_rows(summary),
                 f"{len(summary['materials'])}-material accuracy on the same contacts and "
                 "splits; fraction of the "
                 "full-spectrum MLP per seed (95 % interval); NMF with as many filters "
                 "as resonators, paired by seed. Cost: coding + Brian2, charged by the "
                 "read-out's share of the bank's resonators.")
    report.table(spiking_distance_rows(summary), "Distance from spiking features (MLP 20-5)")
    report.text(spiking_cost_text(summary))
    # a recorded set whose split trains on fewer events than the curve's smallest bank
    # has no curve (the run logged the sizes it left out)
    if (summary["spiking"].get("tuned") or {}).get("curve"):
        report.figure(figures.tuned_curve(summary), "tuned_curve",
                      f"Left: {len(summary['materials'])}-material accuracy of the tuned "
                      "spiking bank (every read-out "
                      "code, MLP 51) against its resonators, and NMF-n with as many filters, "
                      "on the same events and split; dashed: the full-spectrum MLP and 0.9 of "
                      "it. Below: the bank's neuron-steps per event and the budget of 5 × the "
                      "FFT pipeline's cost at the ns per neuron-step measured in this run.")
        report.table(tuned_curve_rows(summary), "Accuracy vs resonators (first split, events "
                     "of the first repetitions): the curve above")
        report.text(_tuned_text(summary))
    if summary["spiking"].get("coders"):
        report.table(coder_rows(summary), CODER_CAPTION.format(n=len(summary["materials"])))
    if summary["spiking"].get("designs"):
        report.table(design_rows(summary["spiking"]["designs"]), "Array designs (one band "
                     "changed at a time, first split, events of the first repetitions only)")


CHOSEN_SOURCE = "this run (chosen bank and FFT-MLP on the same splits)"


def _iv(row: dict, scale: float = 1.0):
    return None if row.get("low") is None else (scale * row["low"], scale * row["high"])


def _chosen_predicted(summary: dict) -> list[Predicted]:
    """The chosen bank's accuracy ratio to the FFT-MLP (paired by split, with its verdict)
    and its distance rmse beside the full-spectrum MLP's."""
    c = summary.get("chosen_bank") or {}
    out = []
    if "accuracy_to_fft_mlp" in c:
        ratio, lead = c["accuracy_to_fft_mlp"], c["accuracy_minus_fft_mlp"]
        out.append(Predicted("chosen bank's material accuracy ÷ FFT-MLP's", ratio["mean"], "",
                             None, CHOSEN_SOURCE, _iv(ratio), ratio["n"],
                             f"accuracy − FFT-MLP's, paired by split: "
                             f"{lead.get('verdict', 'no interval (one split)')}"))
    if "distance_rmse_mm" in c:
        rmse, diff = c["distance_rmse_mm"], c["distance_rmse_minus_fft_mlp"]
        out.append(Predicted("distance rmse, chosen bank's low band", rmse["mean"], "mm", None,
                             CHOSEN_SOURCE, _iv(rmse), rmse["n"],
                             f"− full-spectrum MLP's, paired by split: "
                             f"{diff.get('verdict', 'no interval (one split)')}"))
    return out


def chosen_rows(c: dict) -> list[dict]:
    """The chosen bank against the FFT pipeline in this run: accuracy, distance and cost."""
    rows = []
    for what, mine, ref, diff, scale, unit in (
            ("material accuracy", "accuracy", "fft_mlp_accuracy", "accuracy_minus_fft_mlp",
             100.0, "%"),
            ("distance rmse", "distance_rmse_mm", "fft_mlp_distance_rmse_mm",
             "distance_rmse_minus_fft_mlp", 1.0, "mm")):
        if mine in c:
            rows.append({"quantity": f"{what} ({unit})", "chosen bank": scale * c[mine]["mean"],
                         "95 % interval": _iv(c[mine], scale),
                         "FFT pipeline": scale * c[ref]["mean"],
                         "chosen − FFT (paired)": scale * c[diff]["mean"],
                         "its 95 % interval": _iv(c[diff], scale), "n": c[diff]["n"],
                         "verdict": c[diff].get("verdict", "no interval")})
    cost = c["cost"]
    rows.append({"quantity": "cost per contact (µs)",
                 "chosen bank": cost["chosen"]["features_us_per_event"],
                 "FFT pipeline": cost["fft"]["features_us_per_event"],
                 "chosen − FFT (paired)": None, "n": cost["fft"]["best_of"],
                 "verdict": f"ratio {cost['ratio_to_fft']:.2f} (best of "
                            f"{cost['fft']['best_of']} runs taken in turn)"})
    return rows


FRONT_PERCENT = ("search_accuracy", "refine_accuracy", "accuracy")


def front_rows(measured: dict) -> list[dict]:
    """The bank-tuning run's front as its chosen_bank.toml records it: every field of each
    row, accuracies in %, an interval as its mean and its [low, high]."""
    rows = []
    for r in measured.get("front", []):
        row = {}
        for key, value in r.items():
            scale = 100.0 if key in FRONT_PERCENT else 1.0
            name = f"{key} %" if key in FRONT_PERCENT else key
            if isinstance(value, dict):
                row[name] = scale * value["mean"] if "mean" in value else None
                row[f"{key} interval"] = _iv(value, scale)
            else:
                row[name] = scale * value if isinstance(value, float) else value
        rows.append(row)
    return rows


def _write_chosen(report: Report, summary: dict, cmp: Comparison) -> None:
    c = summary["chosen_bank"]
    report.heading("The chosen bank beside the FFT")
    placement, measured = c["placement"], c["measured"]
    report.text(
        f"The bank the bank-tuning study chose (chosen_bank: trial {c['trial']} of its search, "
        f"commit {measured.get('commit', 'unknown')[:12]}): {c['resonators']} resonators in "
        f"{c['bands']} bands, {c['neuron_steps_per_event']:.0f} resonator-steps per contact; "
        f"the material read by an MLP 51 on its {label(c['readout'])} codes ({c['scaling']}), "
        f"the distance by {c['distance_readout']}. Its channels were placed again here from "
        f"the contacts that placed them in that study: {placement['events']} contacts "
        f"generated like the bench set with seed {placement['seed']}, never evaluated. It is "
        "scored on this run's contacts and splits, beside the FFT pipeline.")
    report.table(chosen_rows(c), "The chosen bank and the FFT pipeline (full-spectrum MLP 51 "
                 "for the material, MLP 20-5 for the distance) on the same splits, paired by "
                 "split (Student t); the cost per contact measured in this run on this machine "
                 "(a measurement, not a result).")
    rows = front_rows(measured)
    if rows:
        report.table(rows, "The front of the bank-tuning run that chose it, as its "
                     "chosen_bank.toml records it: each bank scored there on "
                     f"{measured.get('events', '?')} evaluated contacts of the bench set "
                     f"(splits of seeds {measured.get('seeds', '?')}), the first row chosen by "
                     "the search's own contacts; that run's predictions, not this run's.")
    if cmp.chosen_bank is not None:
        bank, placing = cmp.chosen_bank
        report.figure(figures.bank_on_spectra(placing, bank, float(cmp.features["freq_hz"]
                                                                    .values.max())),
                      "chosen_bank_on_spectra",
                      "Top: mean log amplitude spectrum per material of the contacts that "
                      "placed the chosen bank (the window it reads). Below: one row per band "
                      "of the bank (a channel at one of its gains, and the low band): its pass "
                      "band as a bar, its resonators' preferred frequencies as ticks.")
