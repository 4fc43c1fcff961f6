"""The baseline comparison's plan: the bench source (generated or recorded), the spec fitted
to its rate, the event processor, the evaluation and the spiking read-out's parts, checked
before any long work; its cost."""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError, check
from ...engine.cost import (bench_seconds, compile_seconds, engine_of, max_workers,
                             stages_estimate)
from ...evaluation import antenna_fit
from ...evaluation import crossval as cv
from ...networks.resonators import MIN_SAMPLES_PER_CYCLE
from ...readout import events
from ...readout.bank_design import ChosenBank
from ...readout.spiking import SpikingBank
from ...readout.spiking_decoders import (CODER_READOUTS, SPIKING_MLPS, SPIKING_SETS,
                                          TUNED_READOUTS, Design, SpikingPlan)
from ...sources.source import BenchSet
from ..contract import COMMON, Plan, data_folder
from ..sections import bench_section, evaluation_section, events_section

# recorded repetitions that fit the lab's antenna when the spec names none (no tuned bank)
RECORDED_CALIBRATION_REPETITIONS = 1
SECTIONS = ("stimulus", "events", "evaluation", "spiking", "chosen_bank", "data")
OPTIONS = (*COMMON, "fresh", "scheduler", "data")


@dataclass
class Parts:
    """The whole spec, every part built and checked before any long work."""
    bench: BenchSet                      # bench.BenchSpec or recorded.RecordedBench
    processor: events.EventProcessor
    evaluation: cv.Evaluation
    plan: SpikingPlan | None = None
    bank: SpikingBank | None = None
    designs: list[Design] = field(default_factory=list)
    # recorded repetitions that fit the lab's antenna and place the tuned bank's channels,
    # out of every split
    calibration_repetitions: list[int] = field(default_factory=list)
    antenna: antenna_fit.FittedAntenna | None = None    # recorded data: fitted from its labels
    fitted: list[str] = field(default_factory=list)     # one line per spec value it replaced
    # the bank-tuning study's chosen bank (``chosen_bank``), placed on generated contacts
    chosen: ChosenBank | None = None


def fit_to_rate(spec: dict, rate_hz: float) -> tuple[dict, list[str]]:
    """The spec with every part the data's rate cannot carry left out or clipped, and one
    line naming each: the spectrum's bins above Nyquist, spiking bands (and the designs on
    them) above the rate over ``MIN_SAMPLES_PER_CYCLE`` (the samples a resonator needs per
    cycle of its input), band edges clipped to it and their filters' cut-offs moved with
    them. A spec whose parts all fit comes back unchanged, with no line."""
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


def _chosen_part(spec: dict, recorded: bool) -> tuple[ChosenBank | None, list[str]]:
    """The chosen bank (``chosen_bank``, checked), or None and the line that says why it is
    left out: on recorded data, whose antenna is not the one its design was searched for
    (its channels' range and gains are this project's rods'; the tuned bank of
    ``[spiking.tuned]`` is placed on the lab's own calibration contacts instead)."""
    if spec.get("chosen_bank") is None:
        return None, []
    with specs.section("chosen_bank"):
        chosen = ChosenBank(**specs.check_section(spec, "chosen_bank", ChosenBank))
    if recorded:
        return None, ["left out: the chosen bank (chosen_bank), searched for this project's "
                      "antenna and placed on its contacts; the tuned bank ([spiking.tuned]) is "
                      "placed on the recorded calibration contacts"]
    return chosen, []


def plan(spec: dict) -> Plan:
    """Check the whole spec before any long work; build its parts. On recorded data the
    lab's antenna is fitted first, on the labels of the calibration repetitions
    (``fit_antenna``), and every check below sees the fitted spec."""
    specs.check_top_level(spec, SECTIONS)
    data_folder(spec)
    bench_spec = bench_section(spec)
    recorded = spec.get("data") is not None
    held, antenna, fitted = [], None, []
    if recorded:
        spec, held, antenna, fitted = fit_antenna(spec, bench_spec)
    spec, left_out = fit_to_rate(spec, bench_spec.rate_hz)
    processor = events_section(spec, bench_spec.rate_hz)
    evaluation = evaluation_section(spec)
    if "two_material" in evaluation.pipelines and \
            not set(evaluation.two_materials) <= set(bench_spec.materials):
        raise SpecError("evaluation.two_materials", list(evaluation.two_materials),
                        f"two of the {'recorded' if recorded else 'generated'} set's materials "
                        f"{list(bench_spec.materials)} for the two-material network")
    chosen, why = _chosen_part(spec, recorded)
    left_out += why
    parts = Parts(bench_spec, processor, evaluation, *_spiking_part(spec, bench_spec.rate_hz),
                  calibration_repetitions=held, antenna=antenna, fitted=fitted, chosen=chosen)
    check_splits(parts)
    # the fitted values first: --check prints them with what the rate leaves out
    return Plan("baseline_comparison", spec, parts, estimate, fitted + left_out)


def calibration_count(spec: dict) -> tuple[int, str]:
    """How many recorded repetitions calibrate, and the field that says so."""
    field = "spiking.tuned.calibration_repetitions"
    tuned = (spec.get("spiking") or {}).get("tuned") if isinstance(spec.get("spiking"),
                                                                     dict) else None
    if isinstance(tuned, dict) and "calibration_repetitions" in tuned:
        return bounds.integer(field, tuned["calibration_repetitions"], 1), field
    return RECORDED_CALIBRATION_REPETITIONS, "data"


def fit_antenna(spec: dict, bench_spec) -> tuple[dict, list[int], object, list[str]]:
    """(the spec with the fitted values, the calibration repetitions, the fitted antenna,
    one line per value fitted): the law, mode split, decay-fit window and bands of a recorded
    set's antenna from the labels of its calibration repetitions, the hand-set bands'
    thresholds and the tuned bank's coder levels from their recordings (``antenna_fit``)."""
    n, field = calibration_count(spec)
    have = len(set(bench_spec.dataset["repetition"].values.tolist()))
    if field == "data" and have < n + 2:
        raise SpecError("data", str(bench_spec.path),
                        f"a recorded set of {n + 2} repetitions or more ({n} to fit the lab's "
                        f"antenna on, two to split by); this one holds {have}")
    held = bench_spec.calibration_repetitions(n, field)
    typed, _ = fit_to_rate(spec, bench_spec.rate_hz)
    like = events_section(typed, bench_spec.rate_hz)
    data = bench_spec.dataset
    antenna = antenna_fit.fit(data, np.isin(data["repetition"].values, held), like,
                              str(bench_spec.path))
    spec, fitted = antenna.applied(spec)
    calibration = np.isin(data["repetition"].values, held)
    at_rate, _ = fit_to_rate(spec, bench_spec.rate_hz)   # the bands as the run builds them
    _, bank, _ = _spiking_part(at_rate, bench_spec.rate_hz)
    if bank is not None:
        spec, levels = antenna_fit.fit_band_thresholds(data, calibration, spec, bank,
                                                       antenna.source)
        fitted += levels
    antenna, spec, levels = antenna_fit.fit_coder(antenna, data, calibration, spec, at_rate)
    fitted += levels
    spec["description"] = (
        "The paper's read-outs (linear regression on the low peak, MLPs on parametric features "
        "and on the FFT amplitude spectrum, NMF band-pass filters) and the spiking read-outs "
        f"on contacts a lab recorded with its own antenna ({bench_spec.path}): its frequency "
        "law, mode split, decay-fit window, bands, band thresholds and the tuned bank's coder "
        "levels fitted on the labels and recordings of its calibration "
        f"repetitions {held}, held out of every split; splits by repetition of the rest.")
    return spec, held, antenna, fitted


def first_scored(features, n: int) -> int:
    """The repetition bound (``repetition < bound``) that takes the first ``n`` repetitions
    of ``features``: with calibration repetitions held out, the first ``n`` scored ones (the
    array designs' and the tuned curve's contacts)."""
    reps = np.unique(features["repetition"].values)
    return int(reps[min(n, len(reps)) - 1]) + 1


def check_splits(parts: Parts) -> None:
    """Every seed's split by repetition of the recorded contacts left for scoring trains and
    tests on contacts of every material (so every read-out can be fitted and scored), and the
    designs' and the tuned curve's first repetitions hold two scored ones to split: checked
    here, so ``--check`` fails where the run would."""
    if not hasattr(parts.bench, "dataset"):        # generated: every split holds every material
        return
    data = parts.bench.dataset
    keep = ~np.isin(data["repetition"].values, parts.calibration_repetitions)
    repetition = data["repetition"].values[keep]
    material = data["material"].values.astype(str)[keep]
    field = "evaluation.test_fraction"
    check(len(np.unique(repetition)) >= 2, "data", parts.bench.path,
          "a recorded set with two repetitions or more besides the calibration ones "
          f"{parts.calibration_repetitions}")
    # the designs and the tuned curve split the contacts of the first scored repetitions
    subsets = []
    if parts.designs:
        subsets.append(("spiking.design_repetitions", parts.plan.design_repetitions))
    if parts.plan and parts.plan.tuned_plan():
        subsets.append(("spiking.tuned.curve_repetitions",
                        parts.plan.tuned_plan().curve_repetitions))
    scored = sorted(set(repetition.tolist()))
    for name, n in subsets:
        check(min(n, len(scored)) >= 2, name, n, "a number of first scored repetitions >= 2 "
              f"(two to split; the recorded set scores repetitions {scored})")
    for seed in parts.evaluation.seeds:
        train, test = cv.split_by_repetition(repetition, parts.evaluation.test_fraction, seed)
        for side, mask in (("training", train), ("test", test)):
            missing = sorted(set(material) - set(material[mask]))
            check(not missing, field, parts.evaluation.test_fraction,
                  f"a fraction whose split of seed {seed} leaves contacts of every material "
                  f"on its {side} side (none of {missing} there)")


def estimate(parts: Parts):
    """The bench set (made once, then cached) and the spiking read-out of its events: every
    band's bank over every event, ``batch_events`` events per Brian2 run, runs shared among
    the workers; each array design, the tuned bank, its coders and its accuracy curve, each
    a compiled project of its own over its events; every bank's cost sample; and the
    read-outs' fits on every split."""
    events = parts.bench.n_events
    per_repetition = events // max(1, parts.bench.repetitions)
    ev = parts.evaluation
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
        stages += _more_banks(parts, events, per_repetition)
    if parts.chosen is not None:
        stages += _chosen_stages(parts, events)
    stages.append(("evaluation.seeds", list(ev.seeds), [], readout_seconds(parts)))
    return stages_estimate("the bench set and its spiking read-out", stages)


def _chosen_stages(parts: Parts, events: int) -> list:
    """The chosen bank: its placement contacts (generated), its bank over every event (one
    project: a compile) and its cost sample, on the spiking part's workers; its two
    read-outs' fits are counted with the others (``readout_fits``)."""
    chosen, point = parts.chosen, parts.chosen.point
    design = chosen.bank_design
    engine = engine_of(design.target)
    workers = (parts.plan.workers if parts.plan else 1) or max_workers()
    channel_resonators = point["channels"] * point["per_channel"] * point["gain_levels"]
    # the channels' step: the largest k·dt the design allows at the top of their range
    dt_ms = min(0.1, design.base.max_k_dt * point["k_dt_factor"] * design.base.hz_per_k
                / point["range_high_hz"])
    runs = [(design.duration_s, dt_ms, channel_resonators * events / workers, engine),
            (design.duration_s, 0.1, point["low_resonators"] * events / workers, engine)]
    placing = chosen.placement["repetitions"] * parts.bench.n_events // max(
        1, parts.bench.repetitions)
    return [("chosen_bank.placement.repetitions", chosen.placement["repetitions"], runs,
             bench_seconds(placing, parts.bench.n_jobs) + 2 * compile_seconds(engine))]


# CPU seconds of one read-out's fit per training event (the mean over the 46 read-outs
# ``readout_fits`` counts, NMF's filters apart), and of NMF's per filter and training event:
# measured with the full profile's 48 read-outs (the two training-free ones ~0 s) on the split of
# seed 0 (8,959 training events), each fit on one BLAS thread, in CPU time (AMD EPYC Zen 5,
# AVX-512, 2 cores, load average 16-18): 114.6 s in all, NMF-n 1.47 s + 0.095 s per filter (NMF-3
# 1.46 s, NMF-72 8.47 s), the others 0.01-6.1 s each (the 300-epoch parametric material MLP the
# longest, the 60-epoch material MLPs 1.3-3.1 s).
READOUT_FIT_EVENT_S = 2.06e-4
NMF_FILTER_EVENT_S = 1.06e-5


def readout_fits(parts: Parts) -> tuple[int, int]:
    """(read-outs fitted on each split, NMF filters among them): every FFT, parametric,
    spiking MLP, tuned and coder read-out (not the two training-free spiking decoders, which
    learn nothing), and the sum of ``nmf_dims``."""
    ev = parts.evaluation
    fits = len(ev.baselines(int(parts.processor.max_hz) + 1)) + 2 * (parts.chosen is not None)
    filters = sum(ev.nmf_dims) if "material" in ev.pipelines else 0
    if parts.bank is not None:
        fits += sum(set(SPIKING_SETS[inputs][0]) <= set(parts.bank.bands)
                    for inputs, _, _ in SPIKING_MLPS.values())
        tuned = parts.plan.tuned_plan()
        if tuned is not None:
            fits += len(TUNED_READOUTS) + (len(tuned.coders) * len(tuned.coder_sizes)
                                           * (len(CODER_READOUTS) + 1))
    return fits, filters


def readout_seconds(parts: Parts) -> float:
    """The read-outs' fits (``readout_fits``) on the training events of every split of
    ``evaluation.seeds``, shared among the workers (``[spiking] workers``; in this process
    without a spiking part)."""
    ev = parts.evaluation
    fits, filters = readout_fits(parts)
    workers = (parts.plan.workers or max_workers()) if parts.bank is not None else 1
    n_train = parts.bench.n_events * (1 - ev.test_fraction)
    cpu = n_train * (fits * READOUT_FIT_EVENT_S + filters * NMF_FILTER_EVENT_S)
    return len(ev.seeds) * cpu / max(1, min(workers, fits * len(ev.seeds)))


def _more_banks(parts: Parts, events: int, per_repetition: int) -> list:
    """The stages beside the main bank: each design over ``design_repetitions``, the tuned
    bank, its coders at each size and its curve, and each bank's cost sample (a warm-up and
    ``cost_repeats`` runs of ``cost_sample_events`` in one chunk). Every bank is a project
    of its own: one compile each (``compile_s``, in the job estimate once per engine, added
    here for the others)."""
    plan, bank = parts.plan, parts.bank
    engine = engine_of(bank.target)
    # the designs', the tuned banks' and the curve's chunks run on the Dask workers
    workers = plan.workers or max_workers()
    compiles = len(parts.designs)
    stages = []
    design_events = min(events, plan.design_repetitions * per_repetition)
    design_runs = []
    for design in parts.designs:
        band = design.band_of(bank)
        design_runs.append((bank.duration_s, band.dt_ms or bank.dt_ms,
                            band.n_neurons * design_events / workers, engine))
    if design_runs:
        stages.append(("spiking.design_repetitions", plan.design_repetitions, design_runs))
    tuned = plan.tuned_plan()
    if tuned is not None:
        base = tuned.base
        # the tuned channels' step: the largest k·dt the template allows at the top of range
        dt_ms = base.max_k_dt * base.hz_per_k / base.range_hz[1]
        calibration = tuned.calibration_repetitions * per_repetition
        sizes = [base.n_resonators] + [n for _ in tuned.coders for n in tuned.coder_sizes]
        curve_events = min(events, tuned.curve_repetitions * per_repetition)
        every_event = [(tuned.duration_s, dt_ms, n * events / workers, engine) for n in sizes]
        runs = [(tuned.duration_s, dt_ms, n * curve_events / workers, engine)
                for n in tuned.curve]
        # a bank's project is its size's (the channels' tuning is a run argument): one build
        # per distinct size, the cost samples' (one chunk of the sample) apart
        compiles += 2 * len(set(sizes) | set(tuned.curve)) - len(set(tuned.curve) - set(sizes))
        # each tuned bank's cost: the best of cost_repeats runs of the sample
        cost_runs = [(tuned.duration_s, dt_ms, n * plan.cost_sample_events, engine)
                     for n in sizes] * tuned.cost_repeats
        # per size the tuned bank's MLP and NMF-n's on the first split, and the FFT MLP once
        curve_fits = (curve_events * (1 - parts.evaluation.test_fraction)
                      * ((2 * len(tuned.curve) + 1) * READOUT_FIT_EVENT_S
                         + sum(tuned.curve) * NMF_FILTER_EVENT_S))
        stages.append(("stimulus.repetitions", parts.bench.repetitions, every_event,
                       bench_seconds(calibration, parts.bench.n_jobs)))
        stages.append(("spiking.tuned.curve", tuned.curve, runs, curve_fits))
    # the main bank's cost: one run of the sample (after a warm-up on two events)
    sample = [(bank.duration_s, band.dt_ms or bank.dt_ms,
               band.n_neurons * plan.cost_sample_events, engine)
              for band in bank.bands.values()] + (cost_runs if tuned is not None else [])
    compiles += 1          # the main bank's cost sample
    stages.append(("spiking.cost_sample_events", plan.cost_sample_events, sample,
                   compiles * compile_seconds(engine)))
    return stages
