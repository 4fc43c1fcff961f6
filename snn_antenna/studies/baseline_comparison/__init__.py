"""Baseline comparison: the paper's FFT, parametric and NMF read-outs on the bench data set.

Generates (or reuses) the bench contacts, processes every event as the paper did, checks the
generated signal against the paper's measurements of the signal (calibration), then trains
and tests each scikit-learn pipeline, and the spiking read-out's decoders, on the same splits
by repetition for several seeds. The report puts every number beside the paper's.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...core.logfile import logged
from ...engine.events import cached_features, run_bank, run_cost
from ...engine.executor import executor
from ...core.errors import SpecError
from ...engine.cost import bench_seconds, engine_of, max_workers, stages_estimate
from ...core.files import write_json
from ...evaluation import crossval as cv
from ...evaluation import signal as bench_signal
from ...readout import events
from ...evaluation.comparison import Comparison
from ...networks.resonators import MIN_SAMPLES_PER_CYCLE
from ...readout.spiking import SpikingBank
from ...readout.spiking_decoders import (
    Design,
    SpikingPlan,
    decoder_inputs,
    neurons_per_input,
    spiking_baselines,
)
from ...report.page import Report
from ...sources import bench
from ..contract import COMMON, Options, Plan, cache_folder, data_folder
from .report import write_report
from .tuned import tuned_stage

SECTIONS = ("stimulus", "events", "evaluation", "spiking", "data")
OPTIONS = (*COMMON, "fresh", "scheduler", "data")
# Events timed for the FFT's cost per event when the spec has no [spiking] section.
COST_SAMPLE_EVENTS = 200

QUICK_NOTE = ("Quick profile: 10 contacts per material and site, 2 seeds. The signal statistics "
              "(r², precision, CV of τ_low, wood/aluminium sites: ten contacts each, as the "
              "paper's test) are comparable with the full run; every classifier and regressor "
              "here trained on a tenth of the contacts, so accuracies, rmse and the confusion "
              "matrix are too small to compare with the paper or the full run.")


@dataclass
class StudySpec:
    """The whole spec, every part built and checked before any long work."""
    bench: bench.BenchSpec
    processor: events.EventProcessor
    evaluation: cv.Evaluation
    plan: SpikingPlan | None = None
    bank: SpikingBank | None = None
    designs: list[Design] = field(default_factory=list)
    # recorded repetitions that place the tuned bank's channels, out of every split
    calibration_repetitions: list[int] = field(default_factory=list)


def fit_to_rate(spec: dict, rate_hz: float) -> tuple[dict, list[str]]:
    """The spec with every part the data's rate cannot carry left out or clipped, and one
    line naming each: the spectrum's bins above Nyquist, spiking bands (and the designs on
    them) above the rate over ``MIN_SAMPLES_PER_CYCLE`` (the samples a resonator needs per
    cycle of its input), band edges clipped to it and their filters' cut-offs moved with
    them. A spec whose parts all fit comes back unchanged, with no line."""
    import copy

    nyquist = rate_hz / 2
    limit = rate_hz / MIN_SAMPLES_PER_CYCLE
    why = f"above the {nyquist:g} Hz Nyquist of the recordings"
    spec, notes = copy.deepcopy(spec), []
    ev = spec.setdefault("events", {})
    # the raw spec, before its sections are checked: a value of the wrong shape is refused here
    # by name (and any other is left to the checks that follow)
    max_hz = (bounds.number("events.max_hz", ev.get("max_hz", events.EventProcessor.max_hz),
                            0.0, lo_open=True, unit=" Hz") if isinstance(ev, dict) else 0.0)
    if max_hz > nyquist:
        ev["max_hz"] = nyquist
        notes.append(f"left out: the spectrum's bins from {nyquist:g} to {max_hz:g} Hz "
                     f"(events.max_hz {max_hz:g} → {nyquist:g}), {why}")
    spiking = spec.get("spiking")
    if not isinstance(spiking, dict):
        return spec, notes
    spiking_why = (f"above {limit:g} Hz: a resonator reads {MIN_SAMPLES_PER_CYCLE} samples "
                   f"per cycle, and the recordings' {rate_hz:g} Hz gives {limit:g} Hz at most "
                   f"(their Nyquist is {nyquist:g} Hz)")
    bank = spiking.get("bank")
    bands = bank.get("bands") if isinstance(bank, dict) else None
    bands = bands if isinstance(bands, dict) else {}
    for name in list(bands):
        if _fit_band(bands[name], f"spiking.bank.bands.{name}", limit, spiking_why, notes):
            del bands[name]
    designs = []
    given = spiking.get("designs")
    for i, design in enumerate(given if isinstance(given, list) else []):
        label = f"spiking.designs.{i}"
        if isinstance(design, dict) and design.get("band") not in (None, *bands):
            notes.append(f"left out: {label} ({design.get('name', i)}), on the band left out")
        elif not (isinstance(design, dict) and
                  _fit_band(design, label, limit, spiking_why, notes)):
            designs.append(design)
    if isinstance(given, list):
        spiking["designs"] = designs
    tuned = spiking.get("tuned")
    tuning = tuned.get("tuning") if isinstance(tuned, dict) else None
    if isinstance(tuning, dict) and "range_hz" in tuning:
        lo, hi = bounds.pair("spiking.tuned.tuning.range_hz", tuning["range_hz"], strict=True,
                             unit=" Hz")
        if hi > limit:
            tuning["range_hz"] = [lo, limit]
            notes.append(f"clipped: spiking.tuned.tuning.range_hz {lo:g}–{hi:g} → "
                         f"{lo:g}–{limit:g} Hz; left out: the channels {spiking_why}")
    return spec, notes


def _fit_band(band: dict, label: str, limit: float, why: str, notes: list) -> bool:
    """Clip one band table to ``limit`` in place (band edge, cut-offs), noting each change;
    True when the whole band lies above it (to be left out)."""
    if not isinstance(band, dict):
        return False
    if "band_hz" in band:
        lo, hi = bounds.pair(f"{label}.band_hz", band["band_hz"], strict=True, unit=" Hz")
        if lo >= limit:
            notes.append(f"left out: {label} ({lo:g}–{hi:g} Hz), {why}")
            return True
        if hi > limit:
            band["band_hz"] = [lo, limit]
            notes.append(f"clipped: {label}.band_hz {lo:g}–{hi:g} → {lo:g}–{limit:g} Hz; "
                         f"left out: its resonators {why}")
            for cut in ("lowpass_hz", "highpass_hz"):   # in the same place against the band
                if band.get(cut) is None:
                    continue
                hz = bounds.number(f"{label}.{cut}", band[cut], 0.0, lo_open=True, unit=" Hz")
                if hz > limit:
                    new = round(hz * limit / hi, 1)
                    if new <= lo:
                        notes.append(f"left out: {label} ({cut} {hz:g} Hz), {why}")
                        return True
                    notes.append(f"clipped: {label}.{cut} {hz:g} → {new:g} Hz, "
                                 f"as far above the band's top as before ({hi:g} → {limit:g} "
                                 "Hz)")
                    band[cut] = new
    return False


def _spiking_part(spec: dict, rate_hz: float) -> tuple:
    """(plan, bank, designs) of ``[spiking]``, or Nones when the spec has none."""
    if "spiking" not in spec:
        return None, None, []
    with specs.section("spiking"):
        plan = SpikingPlan(**specs.check_section(spec, "spiking", SpikingPlan))
        plan.tuned_plan()      # its checks, before any work
        return (plan, *plan.build(rate_hz))


def plan(spec: dict) -> Plan:
    """Check the whole spec before any long work; build its parts."""
    specs.check_top_level(spec, SECTIONS)
    data_folder(spec)
    if spec.get("data") is not None:            # contacts imported from recordings
        bench_spec = bench.source_from_spec(spec)
    else:
        with specs.section("stimulus"):
            bench_spec = bench.source_from_spec(spec)
            bench_spec.validate()
            cache_folder("cache_dir", bench_spec.cache_dir)
    spec, left_out = fit_to_rate(spec, bench_spec.rate_hz)
    with specs.section("events"):
        table = specs.check_section(spec, "events", events.EventProcessor, exclude=["rate_hz"])
        processor = events.EventProcessor(rate_hz=bench_spec.rate_hz, **table)
    with specs.section("evaluation"):
        evaluation = cv.Evaluation(**specs.check_section(spec, "evaluation", cv.Evaluation))
    if "two_material" in evaluation.pipelines and \
            not {"wood", "aluminium"} <= set(bench_spec.materials):
        raise SpecError("data" if spec.get("data") is not None else "stimulus.materials",
                        list(bench_spec.materials),
                        "a list that holds wood and aluminium for the two-material network")
    parts = StudySpec(bench_spec, processor, evaluation, *_spiking_part(spec, bench_spec.rate_hz))
    if parts.plan and parts.plan.tuned_plan():
        parts.calibration_repetitions = bench_spec.calibration_repetitions(
            parts.plan.tuned_plan().calibration_repetitions,
            "spiking.tuned.calibration_repetitions")
    return Plan("baseline_comparison", spec, parts, estimate, left_out)


def estimate(parts: StudySpec):
    """The bench set (made once, then cached) and the spiking read-out of its events: every
    band's bank over every event, ``batch_events`` events per Brian2 run, runs shared among
    the workers."""
    events = parts.bench.n_events
    stages = [("stimulus.repetitions", parts.bench.repetitions, [],
               bench_seconds(events, parts.bench.n_jobs))]
    bank = parts.bank
    if bank is not None:
        workers = parts.plan.workers or max_workers()
        chunks = -(-events // bank.batch_events)
        runs = []
        for band in bank.bands.values():
            runs += [(bank.duration_s, band.dt_ms or bank.dt_ms,
                      band.n_neurons * min(events, bank.batch_events),
                      engine_of(bank.target))] * -(-chunks // workers)
        stages.append(("stimulus.repetitions", parts.bench.repetitions, runs))
    return stages_estimate("the bench set and its spiking read-out", stages)


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
    stages = 5 if parts.bank is not None else 4
    for line in plan.left_out:
        log(f"      {line}")
    data, cmp, data_s = _signal_stage(parts, stages, log, fresh)
    extra = _spiking_stage(parts, data, cmp, f"[3/{stages}]", log, fresh, scheduler)
    log(f"[{stages - 1}/{stages}] baselines on {len(parts.evaluation.seeds)} split(s) by "
        "repetition")
    chosen, too_large = _fitting_nmf(parts.evaluation.baselines(cmp.features.sizes["freq_hz"]),
                                     cmp.features, parts.evaluation)
    if too_large:
        log(f"      {too_large}")
    cmp.results = cv.evaluate(cmp.features, chosen + extra, parts.evaluation, log)
    log(f"[{stages}/{stages}] report")
    summary = cmp.summary({"data_and_features_s": data_s,
                           "total_s": time.perf_counter() - t_start})
    summary["left_out"] = list(plan.left_out) + ([too_large] if too_large else [])
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "predictions.json", cmp.predictions(), indent=None)
    report = Report(out_dir, "Baseline comparison: FFT, parametric, NMF and spiking read-outs",
                    quick=quick, quick_note=QUICK_NOTE)
    write_report(report, spec, summary, cmp)
    summary = report.write(summary, spec, parts.bank.target if parts.bank
                           else "none (no spiking part)")
    log(f"report in {out_dir}/report.html ({summary['timing']['total_s']:.0f} s)")
    return summary


def _signal_stage(parts: StudySpec, stages: int, log, fresh) -> tuple:
    """The bench data set, its processed events and their statistics beside the paper's,
    and the FFT's cost per event: (data, a Comparison with no results yet, the seconds
    spent making or loading the data and its features)."""
    log(f"[1/{stages}] {parts.bench.describe()}")
    t0 = time.perf_counter()
    data, everything = bench_signal.load_features(parts.bench, parts.processor, log, fresh)
    data_s = time.perf_counter() - t0
    skipped = events.skip_counts(everything)
    evaluated = everything["skipped"].values == ""
    if parts.calibration_repetitions:      # they place the tuned channels: out of every split
        held = np.isin(everything["repetition"].values, parts.calibration_repetitions)
        log(f"      {int(held.sum())} contacts of repetitions {parts.calibration_repetitions} "
            "held out to place the tuned bank's channels, out of every split")
        evaluated &= ~held
    feats = everything.isel(event=np.flatnonzero(evaluated))
    log(f"      {feats.sizes['event']} events processed, skipped: {skipped}")
    log(f"[2/{stages}] calibration against the paper's signal measurements")
    signal = bench_signal.signal_statistics(feats)
    log(f"      r² low {signal['r2_low']:.4f} (paper 0.995), high {signal['r2_high']:.4f} "
        f"(0.987); precision {signal['single_contact_precision_mm']:.2f} mm (6.2)")
    n_cost = parts.plan.cost_sample_events if parts.plan else COST_SAMPLE_EVENTS
    costs = {"fft": events.extraction_cost(data, parts.processor, feats["event"].values[:n_cost])}
    return data, Comparison(feats, signal, {}, skipped, costs, data={
        "n_events": int(parts.bench.n_events), "rate_hz": parts.bench.rate_hz,
        "bench_key": parts.bench.key(),
        **({"recorded": origin} if (origin := parts.bench.summary_entry()) else {})}), data_s


def _spiking_stage(parts: StudySpec, data, cmp: Comparison, stage: str, log, fresh,
                   scheduler) -> list:
    """The bank over every event (cached) and the designs, on ``[spiking] workers`` or at
    ``scheduler``; decoder inputs into ``cmp.features``, cost; the spiking decoders."""
    bank = parts.bank
    if bank is None:
        return []
    log(f"{stage} spiking read-out: {bank.n_neurons} resonators per event "
        f"({', '.join(bank.bands)})"
        f", Brian2 {bank.target}, {bank.batch_events} events per chunk")
    with executor(parts.plan.workers, scheduler, log) as client:
        spikes = cached_features(data, bank, parts.bench, log, fresh, client)
        cmp.features = decoder_inputs(cmp.features, spikes)
        if parts.designs:
            cmp.designs = cv.run_designs(data, cmp.features, bank, parts.designs, log=log,
                                      run=partial(run_bank, client=client, progress=False),
                                      repetitions=parts.plan.design_repetitions,
                                      evaluation=parts.evaluation)
        tuned = (tuned_stage(parts, data, cmp, log, fresh, client)
                 if parts.plan.tuned_plan() else [])
    cmp.costs["spiking"] = run_cost(data, bank, parts.plan.cost_sample_events)
    neurons = neurons_per_input(spikes)
    neurons.update({b.name: cmp.tuned["neurons"] for b in tuned})
    cmp.spiking = {**bank.description(), "neurons": neurons}
    return spiking_baselines(spikes, parts.evaluation) + tuned


# -- report ---------------------------------------------------------------------------------
