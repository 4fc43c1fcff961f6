"""The baseline comparison's stages: the bench data set and its processed events beside the
paper's signal statistics, the spiking read-out (and the tuned bank), the baselines on splits
by repetition; the summary and the report."""
from __future__ import annotations

import time
from functools import partial
from pathlib import Path

import numpy as np
import xarray as xr

from ...core.files import write_json
from ...core.logfile import logged
from ...engine.events import cached_features, run_bank, run_cost
from ...engine.executor import executor
from ...evaluation import antenna_fit
from ...evaluation import crossval as cv
from ...evaluation import signal as bench_signal
from ...evaluation.comparison import Comparison
from ...readout import events
from ...readout.spiking_decoders import (SPIKING_MLPS, decoder_inputs, neurons_per_input,
                                          spiking_baselines)
from ...report.page import Report
from ..contract import Options, Plan
from .plan import Parts, first_scored
from .report import QUICK_NOTE, RECORDED_QUICK_NOTE, write_report
from .chosen import chosen_stage
from .tuned import tuned_stage

# Events timed for the FFT's cost per event when the spec has no [spiking] section.
COST_SAMPLE_EVENTS = 200


def _fitting_nmf(baselines: list, features, evaluation) -> tuple[list, str | None]:
    """The baselines without the NMF sizes a split cannot fit (NMF-n needs at least n training
    events: a small recorded set), and the line that names those left out."""
    repetition = features["repetition"].values
    n_train = min(int(cv.split_by_repetition(repetition, evaluation.test_fraction, seed)[0].sum())
                  for seed in evaluation.seeds)
    kept = [b for b in baselines if not (b.name.startswith("nmf_")
                                         and int(b.name.split("_")[1]) > n_train)]
    dropped = [b.name for b in baselines if b not in kept]
    return kept, (f"left out: {', '.join(dropped)} (NMF-n needs n <= the {n_train} training "
                  "events of the smallest split)" if dropped else None)


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick = plan.spec, plan.parts, options.quick
    fresh, scheduler = options.fresh, options.scheduler
    out_dir, t_start = Path(out_dir), time.perf_counter()
    stages = 5 if parts.bank is not None or parts.chosen is not None else 4
    for line in plan.left_out:
        log(f"      {line}")
    data, cmp, data_s = signal_stage(parts, stages, log, fresh)
    # one set of workers for the spiking runs and the read-outs' fits (``[spiking] workers``;
    # a spec without a spiking part fits in this process)
    with executor(parts.plan.workers if parts.plan else 1, scheduler, log) as client:
        extra = spiking_stage(parts, data, cmp, f"[3/{stages}]", log, fresh, client)
        if parts.chosen is not None:
            if parts.bank is None:
                log(f"[3/{stages}] the chosen bank")
            extra += chosen_stage(parts, data, cmp, log, fresh, client)
        log(f"[{stages - 1}/{stages}] baselines on {len(parts.evaluation.seeds)} split(s) by "
            "repetition")
        chosen, too_large = _fitting_nmf(
            parts.evaluation.baselines(cmp.features.sizes["freq_hz"]), cmp.features,
            parts.evaluation)
        if too_large:
            log(f"      {too_large}")
        cmp.results = cv.evaluate(cmp.features, chosen + extra, parts.evaluation, log, client)
    log(f"[{stages}/{stages}] report")
    summary = cmp.summary({"data_and_features_s": data_s,
                           "total_s": time.perf_counter() - t_start})
    summary["left_out"] = list(plan.left_out) + ([too_large] if too_large else [])
    if summary["two_material"]:
        summary["two_material"]["materials"] = list(parts.evaluation.two_materials)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "predictions.json", cmp.predictions(), indent=None)
    report = Report(out_dir, "Baseline comparison: FFT, parametric, NMF and spiking read-outs",
                    quick=quick, quick_note=RECORDED_QUICK_NOTE if parts.antenna else QUICK_NOTE)
    write_report(report, spec, summary, cmp)
    summary = report.write(summary, spec, parts.bank.target if parts.bank
                           else "none (no spiking part)")
    log(f"report in {out_dir}/report.html ({summary['timing']['total_s']:.0f} s)")
    return summary


def signal_stage(parts: Parts, stages: int, log, fresh) -> tuple:
    """The bench data set, its processed events and their statistics beside the paper's,
    and the FFT's cost per event: (data, a Comparison with no results yet, the seconds
    spent making or loading the data and its features)."""
    log(f"[1/{stages}] {parts.bench.describe()}")
    t0 = time.perf_counter()
    data, everything = bench_signal.load_features(parts.bench, parts.processor, log, fresh)
    data_s = time.perf_counter() - t0
    skipped = events.skip_counts(everything)
    evaluated = everything["skipped"].values == ""
    held = np.isin(everything["repetition"].values, parts.calibration_repetitions)
    if parts.calibration_repetitions:      # they calibrate: out of every split
        log(f"      {int(held.sum())} contacts of repetitions {parts.calibration_repetitions} "
            "held out to " + ("fit the antenna and " if parts.antenna else "")
            + "place the tuned bank's channels, out of every split")
        evaluated &= ~held
    feats = everything.isel(event=np.flatnonzero(evaluated))
    log(f"      {feats.sizes['event']} events processed, skipped: {skipped}")
    log(f"[2/{stages}] " + ("the signal's statistics" if parts.antenna else
                            "calibration against the paper's signal measurements"))
    signal = bench_signal.signal_statistics(feats)
    log(f"      r² low {_shown(signal['r2_low'], '.4f')} (paper 0.995), high "
        f"{_shown(signal['r2_high'], '.4f')} (0.987); precision "
        f"{_shown(signal['single_contact_precision_mm'], '.2f')} mm (6.2)")
    n_cost = parts.plan.cost_sample_events if parts.plan else COST_SAMPLE_EVENTS
    costs = {"fft": events.extraction_cost(data, parts.processor, feats["event"].values[:n_cost])}
    return data, Comparison(feats, signal, {}, skipped, costs, data={
        "n_events": int(parts.bench.n_events), "rate_hz": parts.bench.rate_hz,
        "bench_key": parts.bench.key(),
        **({"recorded": origin} if (origin := parts.bench.summary_entry()) else {}),
        **({"antenna": parts.antenna.description(), "fitted": list(parts.fitted),
            "left_out_by_position": left_out_by_position(everything, held)}
           if parts.antenna else {})}), data_s


def _shown(value, spec: str) -> str:
    """A statistic as logged; one with no finite value (``evaluation.signal``) as 'none'."""
    return "none" if value is None else format(value, spec)


def left_out_by_position(everything, held) -> dict:
    """Every contact the scoring leaves out, by reason and distance (cm): skipped by the
    event processing (``events.SKIP_REASONS``) or held out to calibrate."""
    distance = everything["distance_cm"].values.astype(float)
    reasons = np.where(held, "calibration", everything["skipped"].values.astype(str))
    return {reason: {f"{d:g}": int(np.sum((reasons == reason) & (distance == d)))
                     for d in sorted(set(distance))}
            for reason in ("calibration", *events.SKIP_REASONS) if np.any(reasons == reason)}


def spiking_stage(parts: Parts, data, cmp: Comparison, stage: str, log, fresh,
                  client) -> list:
    """The bank over every event (cached) and the designs, on the Dask ``client``'s workers
    (None: this process); decoder inputs into ``cmp.features``, cost; the spiking decoders."""
    bank = parts.bank
    if bank is None:
        return []
    log(f"{stage} spiking read-out: {bank.n_neurons} resonators per event "
        f"({', '.join(bank.bands)})"
        f", Brian2 {bank.target}, {bank.batch_events} events per chunk")
    spikes = cached_features(data, bank, parts.bench, log, fresh, client)
    cmp.features = decoder_inputs(cmp.features, spikes)
    if parts.designs:
        cmp.designs = cv.run_designs(data, cmp.features, bank, parts.designs, log=log,
                                  run=partial(run_bank, client=client, progress=False),
                                  repetitions=first_scored(
                                      cmp.features, parts.plan.design_repetitions),
                                  evaluation=parts.evaluation)
    tuned = (tuned_stage(parts, data, cmp, log, fresh, client)
             if parts.plan.tuned_plan() else [])
    cmp.costs["spiking"] = run_cost(data, bank, parts.plan.cost_sample_events)
    neurons = neurons_per_input(spikes)
    neurons.update({b.name: cmp.tuned["neurons"] for b in tuned})
    cmp.spiking = {**bank.description(), "neurons": neurons}
    fitted = {}
    if parts.antenna:
        fitted, lines = _law(parts, data, spikes, log)
        cmp.data["fitted"].extend(lines)          # the report's and summary's fitted values
    return spiking_baselines(spikes, parts.evaluation, **fitted) + tuned


def _law(parts: Parts, data, spikes, log) -> tuple[dict, list[str]]:
    """What the spiking decoders take from the calibration contacts, as
    ``spiking_baselines``' keywords: the fitted low-mode law the training-free decoders
    invert, with the distance a silent low band reads, the rate centroid's neighbourhood of
    the dominant resonator (``antenna_fit.centroid_around``), the dominant resonator's law
    with its bias (``antenna_fit.dominant_bias``) and the spiking distance MLPs' L2 penalties
    (``antenna_fit.distance_alpha``); and the lines saying so."""
    events = spikes["event"].values
    held = spikes.sel(event=events[np.isin(data["repetition"].sel(event=events).values,
                                           parts.calibration_repetitions)])
    low = held["band"].values.astype(str) == "low"
    silent = held["counts"].values[:, low].sum(axis=1) == 0
    distance = data["distance_cm"].sel(event=held["event"].values).values
    silent_cm, line = parts.antenna.silent_cm(silent, distance)
    law = (*parts.antenna.low_law, silent_cm)
    around, centroid_line = antenna_fit.centroid_around(
        held["counts"].values[:, low], held["neuron_hz"].values[low], distance, law)
    dominant_law, dominant_line = antenna_fit.dominant_bias(
        held["counts"].values[:, low], held["neuron_hz"].values[low], distance, law)
    lines = [line, centroid_line, dominant_line]
    inputs = decoder_inputs(xr.Dataset(coords={"event": held["event"].values}), held)
    repetition = data["repetition"].sel(event=held["event"].values).values
    alphas = {}
    for name, (input_set, task, _) in SPIKING_MLPS.items():
        if task == "distance" and input_set in inputs.data_vars:
            alphas[name], alpha_line = antenna_fit.distance_alpha(
                inputs[input_set].values, distance, repetition, parts.evaluation.mlp,
                label=name)
            lines.append(alpha_line)
    for text in lines:
        log(f"      {text}")
    return {"law": law, "around": around, "dominant_law": dominant_law,
            "alphas": alphas}, lines
