"""The bank-tuning study's stages: the bench set and its FFT features, the tuning contacts,
the search on them, its front scored on the bench set's splits beside the FFT-MLP, the
chosen bank's distance rmse and cost; results in ``results.zarr``, the search's trials in
``trials.journal`` (Optuna's own storage), the page."""
from __future__ import annotations

import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import xarray as xr

from ...core import files
from ...core.files import remove_entry
from ...core.provenance import code_identity, git_commit
from ...core.store import write_dataset
from ...core.logfile import logged
from ...engine.events import best_costs, cached_features
from ...engine.executor import executor
from ...evaluation import crossval as cv
from ...evaluation import signal as bench_signal
from ...readout import baselines as bl
from ...readout.bank_design import ChosenBank, distance_rows, material_rows, write_chosen
from ...readout.spiking import recording_attrs
from ...readout.spiking_decoders import DISTANCE_READOUTS, distance_baseline, mlp_baseline
from ...report import stats
from ...report.page import Report
from ...sources import bench
from ..contract import Options, Plan
from .plan import Parts
from .report import QUICK_NOTE, write_report
from .search import (
    Scored,
    bank_of,
    check_unseen,
    neuron_steps_per_event,
    most_accurate,
    refine,
    run_search,
    start_params,
)

STORAGE = "trials.journal"
CHOSEN = "chosen_bank.toml"
SCORED = "scored_contacts.json"
REFINED = "refined_trials.json"
RESULTS = "results.zarr"


def low_band_summary(spikes: xr.Dataset, ids, bank, rate_hz: float) -> dict:
    """The chosen bank's low band: its resonator-steps per contact beside the channels', and
    how it fired on the evaluated contacts (a band that stays silent reads no distance)."""
    if "low" not in bank.bands:
        return {"resonators": 0}
    low = replace(bank, bands={"low": bank.bands["low"]})
    steps = neuron_steps_per_event(low, rate_hz)
    sp = spikes.sel(event=ids)
    counts = sp["counts"].values[:, np.asarray(sp["band"].values).astype(str) == "low"]
    return {"resonators": int(low.n_neurons), "neuron_steps_per_event": steps,
            "channels_neuron_steps_per_event": neuron_steps_per_event(bank, rate_hz) - steps,
            "contacts_with_a_spike": float(np.mean(counts.sum(axis=1) > 0)),
            "resonators_firing_per_contact": float(np.mean((counts > 0).sum(axis=1)))}


def interval(values, bounds=(0.0, np.inf)) -> dict:
    """Mean, 95 % interval and n of per-split values (no interval below 2 values)."""
    x = np.asarray(values, dtype=float)
    if len(x) < 2:
        return {"mean": float(x.mean()), "low": None, "high": None, "n": int(len(x))}
    iv = stats.mean_interval(x, bounds=bounds)
    out = {"mean": iv.mean, "low": iv.low, "high": iv.high, "n": iv.n}
    if bounds is None:      # a paired difference: its t-test against zero and its verdict
        out["p_value"] = iv.p_value
    if iv.n < stats.MIN_N_TO_RESOLVE or bounds is None:
        out["verdict"] = iv.verdict
    return out


# What the chosen bank must reach against the FFT-MLP on the same splits: its accuracy ratio's
# mean and the lower end of its interval, its cost per contact (measured in the same run) and
# its distance rmse (the paired difference's interval may not lie above zero).
ACCURACY_RATIO = 1.0
ACCURACY_RATIO_LOW = 0.99
COST_RATIO = 2.5


def marks(ratio: dict, cost_ratio: float, rmse_minus_fft: dict) -> dict:
    """Each mark the chosen bank is held to: the measured value, the bound and whether it
    holds (an interval over fewer than ``stats.MIN_N_TO_RESOLVE`` splits holds nothing)."""
    enough = min(ratio["n"], rmse_minus_fft["n"]) >= stats.MIN_N_TO_RESOLVE
    low = ratio["low"] if enough else None
    worse = rmse_minus_fft["low"] if enough else None
    return {
        "accuracy_ratio": {"value": ratio["mean"], "bound": f">= {ACCURACY_RATIO:g}",
                           "holds": bool(ratio["mean"] >= ACCURACY_RATIO)},
        "accuracy_ratio_low": {"value": ratio["low"], "bound": f">= {ACCURACY_RATIO_LOW:g}",
                               "holds": low is not None and bool(low >= ACCURACY_RATIO_LOW)},
        "cost_ratio": {"value": cost_ratio, "bound": f"<= {COST_RATIO:g}",
                       "holds": bool(cost_ratio <= COST_RATIO)},
        "distance_rmse_not_worse": {
            "value": rmse_minus_fft["mean"], "bound": "bank − FFT-MLP (mm): interval not above 0",
            "holds": worse is not None and bool(worse <= 0.0)}}


def front_of(study, budget_steps: float, limit: int) -> list:
    """The Pareto front's trials within the cost budget, most accurate first, at most
    ``limit``; the starting bank (trial 0) when none is within it."""
    done = [t for t in study.trials if t.state.name == "COMPLETE"]
    front = most_accurate(t for t in study.best_trials if t.values[1] <= budget_steps)
    return front[:limit] or done[:1]


def refined_front(study, refined: dict, limit: int) -> list:
    """The second stage's trials (``search.refine``: trial number → accuracies on the
    refining contacts), most accurate there first, at most ``limit``."""
    by_number = {t.number: t for t in study.trials}
    order = sorted(refined, key=lambda n: (-float(np.mean(refined[n])),
                                           by_number[n].values[1], n))
    return [by_number[n] for n in order[:limit]]


def trials_dataset(study, space: dict) -> xr.Dataset:
    """Every trial: its state, parameters and objectives (NaN where it has none)."""
    trials = study.trials
    keys = sorted(space)
    def value(t, i):
        return float(t.values[i]) if t.values is not None else np.nan
    states = ["COMPLETE", "PRUNED", "FAIL", "RUNNING", "WAITING"]
    data = {"state": ("trial", [states.index(t.state.name) for t in trials],
                      {"legend": ", ".join(f"{i}: {s}" for i, s in enumerate(states))}),
            "accuracy": ("trial", [value(t, 0) for t in trials]),
            "neuron_steps_per_event": ("trial", [value(t, 1) for t in trials]),
            "on_front": ("trial", [t.number in {b.number for b in study.best_trials}
                                   for t in trials])}
    for k in keys:     # a choice as its index into the space's list (zarr keeps numbers)
        vals = [t.params.get(k) for t in trials]
        choices = space[k] if all(isinstance(v, str) or v is None for v in vals) else None
        if choices is not None:
            data[k] = ("trial", [choices.index(v) if v in choices else -1 for v in vals],
                       {"legend": ", ".join(f"{i}: {c}" for i, c in enumerate(choices))})
        else:
            data[k] = ("trial", [np.nan if v is None else float(v) for v in vals])
    return xr.Dataset(data, coords={"trial": [t.number for t in trials]})


CHOSEN_HEADER = """The resonator bank the bank-tuning study chose: its design, the trial's point of
the search space and the contacts that placed its channels (readout.bank_design.ChosenBank).
Written by `snn-antenna run studies/bank_tuning.toml`; a study includes it by path
(chosen_bank = "../networks/chosen_bank.toml") and places the same channels from the same
contacts. `measured` is that run's record: its front, scored on the bench set's splits."""


def chosen_of(parts: Parts, point: dict, trial: int, summary: dict) -> ChosenBank:
    """The chosen bank as its file holds it: the starting bank's design, the trial's point,
    the tuning contacts that placed its channels and what this run measured on the front."""
    def shown(iv: dict) -> dict:
        return {k: iv[k] for k in ("mean", "low", "high", "n") if iv.get(k) is not None}
    front = [{"trial": r["trial"], "resonators": r["resonators"], "bands": r["bands"],
              "neuron_steps_per_event": r["neuron_steps_per_event"],
              "search_accuracy": r["search_accuracy"],
              **({} if r["refine_accuracy"] is None
                 else {"refine_accuracy": r["refine_accuracy"]}),
              "accuracy": shown(r["accuracy"]),
              "accuracy_to_fft_mlp": shown(r["accuracy_to_fft_mlp"])}
             for r in summary["front"]]
    return ChosenBank(
        design=parts.bank.design_fields(), point=point, trial=int(trial),
        placement={"seed_offset": parts.search.seed_offset,
                   "repetitions": parts.search.repetitions},
        measured={"commit": git_commit() or "unknown",
                  "code_sha256": code_identity()["code_sha256"],
                  "events": summary["events"], "seeds": summary["seeds"],
                  "fft_mlp_accuracy": shown(summary["fft_mlp_accuracy"]), "front": front})


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    parts: Parts = plan.parts
    out_dir, t_start = Path(out_dir), time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    if options.fresh:
        for name in (STORAGE, SCORED, REFINED):
            remove_entry(out_dir / name)
    log(f"[1/5] {parts.bench.describe()}")
    data, everything = bench_signal.load_features(parts.bench, parts.processor, log,
                                                  options.fresh)
    feats = everything.isel(event=np.flatnonzero(everything["skipped"].values == ""))
    ids = feats["event"].values
    tuning_spec = parts.tuning_bench()
    log(f"[2/5] tuning contacts: {tuning_spec.n_events} events (seed {tuning_spec.seed}), "
        "never evaluated")
    tuning = bench.load(tuning_spec, log, options.fresh)
    scored = Scored(out_dir / SCORED)
    log(f"[3/5] search: {parts.search.trials} trials over {sorted(parts.search.space)}")
    # Optuna appends to its journal itself: the file is the run's (journaled) and held open
    # while the search writes, so a killed search leaves it the toolkit's, to resume
    storage = files.open_append(out_dir / STORAGE)
    with executor(parts.bank.workers, options.scheduler, log) as client:
        try:
            study = run_search(parts, tuning, out_dir / STORAGE, scored, client, log)
        finally:
            storage.close()
        attrs = recording_attrs(tuning)
        counts = tuning["counts"].values
        labels = np.asarray(tuning["material"].values.astype(str))
        start = start_params(parts.bank)
        start_bank = bank_of(start, parts.bank, counts, labels, attrs)
        budget = parts.search.cost_budget * neuron_steps_per_event(start_bank, attrs[0])
        refined = {}
        if parts.search.refine_repetitions:
            refine_spec = parts.refine_bench()
            log(f"      second stage: the {parts.search.refine_top} most accurate bank(s) "
                f"within the budget on {refine_spec.n_events} refining contacts (seed "
                f"{refine_spec.seed}), never evaluated")
            refined = refine(study, parts, tuning, bench.load(refine_spec, log, options.fresh),
                             budget, scored, out_dir / REFINED, client, log)
            front = refined_front(study, refined, parts.search.front_limit)
        else:
            front = front_of(study, budget, parts.search.front_limit)
        check_unseen(scored, data["counts"].values[ids])
        log(f"[4/5] {len(front)} bank(s) within {budget:.0f} resonator-steps "
            f"per contact, on {len(ids)} evaluated contacts, "
            f"{len(parts.evaluation.seeds)} split(s) by repetition")
        banks, chosen, distance_X, low_band = {}, [], None, {}
        for t in front:
            params = {**start, **t.params}
            b = bank_of(params, parts.bank, counts, labels, attrs)
            name = f"trial_{t.number}"
            banks[name] = b
            spikes = cached_features(data, b, parts.bench, log, options.fresh, client)
            X = material_rows(spikes, ids, params["readout"], params["scaling"])
            feats[name] = (("event", f"{name}_feature"), X)
            chosen.append(mlp_baseline(name, "material", name, parts.evaluation,
                                       f"MLP 51 on trial {t.number}'s bank"))
            if distance_X is None:      # the chosen bank (the front's first)
                distance_X = distance_rows(spikes, ids, parts.bank.distance_readout, X)
                low_band = low_band_summary(spikes, ids, b, attrs[0])
        best = f"trial_{front[0].number}"
        distance_input = f"{best}_distance"
        feats[distance_input] = (("event", f"{distance_input}_feature"), distance_X)
        chosen.append(distance_baseline(distance_input, parts.bank.distance_readout,
                                        distance_input, parts.evaluation))
    fft = bl.material_baselines([], parts.evaluation.material_mlp,
                                parts.evaluation.nmf_max_iter)[0]
    fft_distance = next(b for b in bl.distance_baselines(feats.sizes["freq_hz"],
                                                         parts.evaluation.mlp)
                        if b.name == "mlp_spectrum")
    results = cv.evaluate(feats, [fft, fft_distance, *chosen], parts.evaluation, log)
    log("[5/5] cost per contact and report")
    costs = best_costs(data, parts.processor, ids[:parts.bank.cost_sample_events],
                       {"chosen": banks[best]}, parts.bank.cost_repeats, log)
    reference = results[fft.name].values("accuracy")
    rows = []
    for t in front:
        name = f"trial_{t.number}"
        acc = results[name].values("accuracy")
        rows.append({"trial": t.number, "resonators": banks[name].n_neurons,
                     "bands": len(banks[name].bands),
                     "neuron_steps_per_event": float(t.values[1]),
                     "search_accuracy": float(t.values[0]),
                     "refine_accuracy": (float(np.mean(refined[t.number]))
                                         if t.number in refined else None),
                     "accuracy": interval(acc, (0.0, 1.0)),
                     "accuracy_to_fft_mlp": interval(acc / reference),
                     # the lead as a paired difference (Student t, scipy.stats): its verdict
                     "accuracy_minus_fft_mlp": interval(acc - reference, None),
                     "params": {k: (v if isinstance(v, str) else float(v))
                                for k, v in t.params.items()}})
    rmse = results[f"{best}_distance"].values("rmse_mm")
    fft_rmse = results[fft_distance.name].values("rmse_mm")
    ratio = rows[0]["accuracy_to_fft_mlp"]
    verdict = ("not resolved" if ratio["low"] is None or ratio["low"] <= 1 <= ratio["high"]
               else "above the FFT-MLP" if ratio["low"] > 1 else "below the FFT-MLP")
    chosen_bank = banks[best]
    cost_ratio = costs["chosen"]["features_us_per_event"] / costs["fft"]["features_us_per_event"]
    summary = {
        "events": int(len(ids)), "tuning_events": int(tuning_spec.n_events),
        "tuning_seed": int(tuning_spec.seed), "seeds": list(parts.evaluation.seeds),
        "trials": len(study.trials), "budget_neuron_steps_per_event": budget,
        "refine_events": (int(parts.refine_bench().n_events)
                          if parts.search.refine_repetitions else 0),
        "start_neuron_steps_per_event": neuron_steps_per_event(start_bank, attrs[0]),
        "fft_mlp_accuracy": interval(reference, (0.0, 1.0)),
        "front": rows, "chosen": {
            "trial": front[0].number, "verdict": verdict,
            "distance_readout": {"name": parts.bank.distance_readout,
                                 "description": DISTANCE_READOUTS[parts.bank.distance_readout],
                                 "inputs": int(distance_X.shape[1])},
            "low_band": low_band,
            "distance_rmse_mm": interval(rmse), "fft_mlp_distance_rmse_mm": interval(fft_rmse),
            "distance_rmse_minus_fft": interval(rmse - fft_rmse, None),
            "marks": marks(ratio, cost_ratio, interval(rmse - fft_rmse, None)),
            "neuron_hz": [float(f) for f in chosen_bank.neuron_hz],
            "channel_edges_hz": [[float(b.highpass_hz or 0.0), float(b.lowpass_hz)]
                                 for b in chosen_bank.bands.values()]},
        # wall times: this machine under its load at the time (the load average beside them)
        "costs": {**costs, "ratio_chosen_to_fft": cost_ratio,
                  "load_average": list(os.getloadavg())},
        "total_s": time.perf_counter() - t_start}
    write_dataset(trials_dataset(study, parts.search.space), out_dir / RESULTS)
    write_chosen(out_dir / CHOSEN, chosen_of(parts, {**start, **front[0].params},
                                             front[0].number, summary), CHOSEN_HEADER)
    report = Report(out_dir, "Bank tuning: a resonator bank searched for the material",
                    quick=options.quick, quick_note=QUICK_NOTE)
    write_report(report, summary, study, tuning, chosen_bank, parts)
    summary = report.write(summary, plan.spec, parts.bank.target)
    log(f"report in {out_dir}/report.html")
    return summary
