"""The bank-tuning study's page: the search's trials and front, the front scored on the
bench set beside the FFT-MLP, the chosen bank and where its resonators sit on the spectra."""
from __future__ import annotations

from ...evaluation.comparison_figures import bank_on_spectra
from ...report.page import Predicted, Report

QUICK_NOTE = ("Quick profile: a few trials on a few hundred tuning contacts, the front scored "
              "on 2 repetitions per material and site and 2 splits: it checks the pipeline; "
              "its accuracies, ratios and costs are too small to compare.")
SOURCE = "this run (bench set, splits by repetition)"


def _pct(iv: dict) -> tuple:
    return (None if iv["low"] is None else (100 * iv["low"], 100 * iv["high"]))


def write_report(report: Report, summary: dict, study, tuning, bank, parts) -> None:
    chosen = summary["chosen"]
    first = summary["front"][0]
    within = (f"within {summary['budget_neuron_steps_per_event']:.0f} resonator-steps per "
              f"contact (the starting bank's {summary['start_neuron_steps_per_event']:.0f} × "
              "the budget)")
    stage = (f"The front's banks {within} were then scored"
             if not summary.get("refine_events") else
             f"The most accurate banks {within} were scored again on "
             f"{summary['refine_events']} refining contacts (another seed, never evaluated), "
             "and the best of them by that score were then scored")
    report.text(
        f"{summary['trials']} trials of a seeded multi-objective TPE (Optuna) scored banks "
        f"on {summary['tuning_events']} tuning contacts (seed {summary['tuning_seed']}, "
        f"never evaluated), by the material MLP's accuracy over splits by repetition of "
        f"them and by resonator-steps per contact. {stage} on {summary['events']} evaluated "
        "contacts, beside the full-spectrum FFT-MLP on the same splits.")
    ratio = first["accuracy_to_fft_mlp"]
    report.predicted(
        Predicted("8 materials, chosen bank's accuracy", 100 * first["accuracy"]["mean"], "%",
                  None, SOURCE, _pct(first["accuracy"]), first["accuracy"]["n"]),
        Predicted("8 materials, FFT-MLP accuracy (same splits)",
                  100 * summary["fft_mlp_accuracy"]["mean"], "%", 94.2, SOURCE,
                  _pct(summary["fft_mlp_accuracy"]), summary["fft_mlp_accuracy"]["n"]),
        Predicted("chosen bank's accuracy ÷ FFT-MLP's", ratio["mean"], "", None, SOURCE,
                  None if ratio["low"] is None else (ratio["low"], ratio["high"]),
                  ratio["n"], chosen["verdict"]),
        Predicted("distance rmse, MLP on the chosen bank", chosen["distance_rmse_mm"]["mean"],
                  "mm", None, SOURCE, None if chosen["distance_rmse_mm"]["low"] is None else
                  (chosen["distance_rmse_mm"]["low"], chosen["distance_rmse_mm"]["high"]),
                  chosen["distance_rmse_mm"]["n"]),
        Predicted("distance rmse, full-spectrum MLP (same splits)",
                  chosen["fft_mlp_distance_rmse_mm"]["mean"], "mm", 1.71, SOURCE,
                  None if chosen["fft_mlp_distance_rmse_mm"]["low"] is None else
                  (chosen["fft_mlp_distance_rmse_mm"]["low"],
                   chosen["fft_mlp_distance_rmse_mm"]["high"]),
                  chosen["fft_mlp_distance_rmse_mm"]["n"]))
    read = chosen["distance_readout"]
    low = chosen["low_band"]
    report.text(f"The chosen bank's distance read-out ({read['name']}): {read['description']}, "
                f"{read['inputs']} inputs per contact." + (
                    f" Its low band: {low['resonators']} resonators, "
                    f"{low['neuron_steps_per_event']:.0f} resonator-steps per contact against "
                    f"the channels' {low['channels_neuron_steps_per_event']:.0f}; it fired on "
                    f"{100 * low['contacts_with_a_spike']:.1f} % of the evaluated contacts, "
                    f"{low['resonators_firing_per_contact']:.1f} of its resonators per contact."
                    if low["resonators"] else ""))
    lead = first["accuracy_minus_fft_mlp"]
    report.text(
        f"The chosen bank's accuracy minus the FFT-MLP's, paired by split (Student t, "
        f"n = {lead['n']}): {lead.get('verdict', 'no interval')}.")
    report.table([{"mark": k, "measured": m["value"], "bound": m["bound"],
                   "holds": "yes" if m["holds"] else "no"}
                  for k, m in chosen["marks"].items()],
                 "The chosen bank against the FFT-MLP, on the same splits and in the same run")
    costs = summary["costs"]
    report.table([{"read-out": k, "µs per contact": costs[k]["features_us_per_event"],
                   "best of": costs[k]["best_of"]} for k in ("fft", "chosen")] +
                 [{"read-out": "chosen ÷ FFT", "µs per contact": costs["ratio_chosen_to_fft"],
                   "best of": costs["fft"]["best_of"]}],
                 "Wall time per contact on this machine, taken in turn (load average "
                 f"{costs['load_average'][0]:.1f}): a measurement of this run, not a result")
    report.table([{"trial": r["trial"], "resonators": r["resonators"],
                   "bands": r["bands"], "resonator-steps per contact":
                   r["neuron_steps_per_event"], "search accuracy %": 100 * r["search_accuracy"],
                   **({} if r.get("refine_accuracy") is None else
                      {"refining accuracy %": 100 * r["refine_accuracy"]}),
                   "accuracy %": 100 * r["accuracy"]["mean"],
                   "95 % interval": _pct(r["accuracy"]),
                   "÷ FFT-MLP": r["accuracy_to_fft_mlp"]["mean"],
                   "n": r["accuracy"]["n"], **r["params"]} for r in summary["front"]],
                 "The banks within the budget scored on the evaluated contacts")
    report.figure(_front_figure(study, summary), "pareto_front",
                  "Every trial: accuracy on the tuning contacts' splits against resonator-"
                  "steps per contact; the Pareto front in colour, the starting bank ringed.")
    report.figure(bank_on_spectra(tuning, bank, parts.processor.max_hz), "resonators_on_spectra",
                  "Top: mean log amplitude spectrum of the tuning contacts per material (the "
                  "window each bank reads). Below: one row per band of the chosen bank (a "
                  "channel at one of its gains, and the low band): its pass band as a bar, "
                  "its resonators' preferred frequencies as ticks.")


def _front_figure(study, summary):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    done = [t for t in study.trials if t.state.name == "COMPLETE"]
    front = {t.number for t in study.best_trials}
    for t in done:
        on = t.number in front
        ax.plot(t.values[1], 100 * t.values[0], "o", color="C1" if on else "0.7",
                mfc="C1" if on else "none")
        if t.number == 0:
            ax.plot(t.values[1], 100 * t.values[0], "o", ms=12, mfc="none", color="k")
    ax.axvline(summary["budget_neuron_steps_per_event"], color="k", ls=":", lw=1)
    ax.set_xlabel("resonator-steps per contact")
    ax.set_ylabel("accuracy on tuning contacts (%)")
    return fig
