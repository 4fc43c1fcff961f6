"""The tuned spiking bank of the baseline comparison: channels from calibration
contacts, the bank over every event, its read-outs, and accuracy against resonators.

Calibration contacts are generated like the bench set but with another seed (the study's
seed + ``calibration_seed_offset``) and a few repetitions: the robot's own session on the
bench's rods, whose spectra and labels place the channels (``readout.band_tuning``). The
evaluated events never enter the placement, so no test split can leak into it, for any seed.

On recorded contacts nothing is generated: ``calibration_repetitions`` of the recorded
repetitions, drawn with the study's seed (``RecordedBench.calibration_repetitions``), place the
channels, and the study removes their contacts from every split before any read-out is scored.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ...engine.events import best_costs as events_best_costs
from ...engine.events import cached_features, run_bank
from ...evaluation import crossval as cv
from ...readout import baselines as bl
from ...readout.band_tuning import tune
from ...readout.spiking import coded_features, recording_attrs
from ...readout.spiking_decoders import (
    CODER_KEYS,
    TunedPlan,
    coder_baselines,
    coder_inputs,
    decay_code,
    tuned_baselines,
    tuned_inputs,
)
from ...sources import bench
from ...core.truth import bench_labels
from .plan import first_scored


def calibration_bands(parts, data, plan: TunedPlan, log, fresh: bool) -> dict:
    """The channels of every tuning of ``plan`` (by number of resonators), placed from the
    calibration contacts (generated with another seed, or the recorded ones held out of every
    split), and a description of where they came from."""
    if parts.calibration_repetitions:
        keep = np.isin(data["repetition"].values, parts.calibration_repetitions)
        data = data.isel(event=np.flatnonzero(keep))
        where = {"calibration_events": int(keep.sum()),
                 "calibration_seed": int(parts.bench.seed),
                 "calibration_repetitions": list(parts.calibration_repetitions),
                 "calibration_source": str(parts.bench.path)}
        log(f"      calibration contacts: {where['calibration_events']} recorded events of "
            f"repetitions {where['calibration_repetitions']}, never evaluated")
    else:
        spec = replace(parts.bench, seed=parts.bench.seed + plan.calibration_seed_offset,
                       repetitions=plan.calibration_repetitions)
        where = {"calibration_events": int(spec.n_events), "calibration_seed": int(spec.seed)}
        log(f"      calibration contacts: {spec.n_events} events (seed {spec.seed}), "
            "never evaluated")
        data = bench.load(spec, log, fresh)
    attrs = recording_attrs(data)
    n_samples = int(round(plan.duration_s * attrs[0]))
    counts = data["counts"].values[:, :n_samples]
    labels = np.asarray([str(m) for m in bench_labels(data)["material"].values])
    return {n: tune(counts, labels, *attrs, tuning) for n, tuning in plan.tunings().items()}, where


def tuned_stage(parts, data, cmp, log, fresh: bool, client) -> list:
    """The tuned bank over every event (cached), its read-outs' inputs into ``cmp.features``,
    its cost, and the accuracy-vs-resonators curve; the read-outs to evaluate."""
    plan: TunedPlan = parts.plan.tuned_plan()
    bands, where = calibration_bands(parts, data, plan, log, fresh)
    main = plan.bank(bands[plan.base.n_resonators], parts.bank)
    log(f"      tuned bank: {main.n_neurons} resonators in {len(main.bands)} channels "
        f"({_hz_text(main)})")
    spikes = cached_features(data, main, parts.bench, log, fresh, client)
    cmp.features = tuned_inputs(cmp.features, spikes)
    coders = coder_stage(parts, data, cmp, bands, plan, log, fresh, client)
    # the default read-out's cost and the FFT's, best of n runs taken in turn
    costs = best_costs(data, parts, cmp.features["event"].values,
                       {"spiking_tuned": main, **(cmp.coders or {}).get("banks", {})},
                       plan.cost_repeats, log)
    cmp.costs.update(costs)
    if cmp.coders:
        cmp.coders["costs"] = {k: costs[k] for k in cmp.coders.pop("banks")}
    curve = run_curve(data, cmp.features, plan, bands, parts, log, client)
    cmp.tuned = {**where, "neurons": main.n_neurons, "channels": _channels(main),
                 "duration_s": plan.duration_s, "bin_edges_s": list(plan.bin_edges_s),
                 "coder": {"coder": plan.base.coder, "coder_amplitude": plan.base.coder_amplitude,
                           "threshold_g": plan.base.threshold_g,
                           "coder_options": dict(plan.base.coder_options)},
                 "curve": curve}
    return tuned_baselines(parts.evaluation) + coders


def coder_stage(parts, data, cmp, bands: dict, plan: TunedPlan, log, fresh: bool, client
                ) -> list:
    """Each coder of ``plan.coders`` at each of ``plan.coder_sizes``, on the channels placed
    for that size: the bank over every event (cached), its read-outs' inputs and its coded
    input's neuron-free ceiling into ``cmp.features``; ``cmp.coders`` describes them (with
    the banks, for the cost measurement). The MLPs to evaluate."""
    if not plan.coders:
        return []
    ids = cmp.features["event"].values
    attrs = recording_attrs(data)
    banks = coder_banks(plan, bands, parts.bank)
    for (label, n), tuning in plan.coder_tunings().items():
        bank = banks[coder_key(label, n)]
        log(f"      coder {label} ({tuning.coder}), {n} resonators")
        spikes = cached_features(data, bank, parts.bench, log, fresh, client)
        ceiling = coded_features(bank, data["counts"].values[ids], *attrs)
        cmp.features = coder_inputs(cmp.features, spikes, label, n, ceiling)
    cmp.coders = {"coders": {k: dict(v) for k, v in plan.coders.items()},
                  "sizes": list(plan.coder_sizes), "banks": banks,
                  "default": next((coder_key(label, n) for (label, n), t
                                   in plan.coder_tunings().items()
                                   if n == plan.base.n_resonators and _same_coder(t, plan.base)),
                                  None)}
    return coder_baselines(plan.coders, plan.coder_sizes, parts.evaluation)


def coder_banks(plan: TunedPlan, bands: dict, like) -> dict:
    """The bank of each coder and size (``coder_key``): the size's channels, the coder's
    fields, ``like``'s target and batching."""
    return {coder_key(label, n): plan.bank(
        {k: replace(b, coder=t.coder, coder_options=dict(t.coder_options),
                    coder_amplitude=t.coder_amplitude, threshold_g=t.threshold_g)
         for k, b in bands[n].items()}, like)
        for (label, n), t in plan.coder_tunings().items()}


def coder_key(label: str, n: int) -> str:
    return f"coder_{label}_{n}"


def _same_coder(a, b) -> bool:
    return all(getattr(a, k) == getattr(b, k) for k in CODER_KEYS)


def best_costs(data, parts, event_ids, banks: dict, repeats: int, log) -> dict:
    """The FFT pipeline's and each bank's wall time per event (``engine.events.best_costs``)
    on the study's first ``cost_sample_events`` events."""
    return events_best_costs(data, parts.processor,
                             np.asarray(event_ids)[:parts.plan.cost_sample_events], banks,
                             repeats, log)


def run_curve(data, features, plan: TunedPlan, bands: dict, parts, log, client) -> list[dict]:
    """Per number of resonators: the tuned bank's accuracy (every read-out code, MLP 51)
    and NMF-n's, on the events of the first ``curve_repetitions`` scored repetitions, first
    seed's split; the full-spectrum MLP on the same split as the reference."""
    from threadpoolctl import threadpool_limits

    evaluation = parts.evaluation
    bound = first_scored(features, plan.curve_repetitions)
    sub = features.isel(event=np.flatnonzero(features["repetition"].values < bound))
    seed = evaluation.seeds[0]
    train, test = cv.split_by_repetition(sub["repetition"].values, evaluation.test_fraction,
                                         seed)
    y = cv.targets_of(sub, "material", sorted(set(sub["material"].values.astype(str))))
    spectrum = bl.inputs_of(sub, "spectrum")
    ids = sub["event"].values
    log(f"      accuracy vs resonators on {len(ids)} events (repetitions < "
        f"{bound}), split of seed {seed}")
    fft = bl.material_baselines([], evaluation.material_mlp, evaluation.nmf_max_iter)[0]
    # NMF-n needs n <= its training events: a small recorded set leaves the larger sizes out
    n_train = int(np.sum(train))
    sizes = [n for n in plan.curve if n <= n_train]
    if len(sizes) < len(plan.curve):
        log(f"      left out of the curve: {[n for n in plan.curve if n not in sizes]} "
            f"resonators (NMF-n needs n <= the split's {n_train} training events)")
    with threadpool_limits(1):
        reference = _accuracy(fft, spectrum, y, train, test, seed)
        rows = []
        for n in sizes:
            t0 = time.perf_counter()
            f = run_bank(plan.bank(bands[n], parts.bank), data["counts"].values[ids],
                         *recording_attrs(data), client=client, progress=False)
            wall = time.perf_counter() - t0
            X = np.hstack([f.counts, f.latency_s, f.span_s,
                           f.binned_counts.reshape(len(ids), -1),
                           decay_code(f.binned_counts)]).astype(np.float32)
            mlp = bl.Baseline("tuned", "material", "", lambda s: bl.classifier_pipeline(
                evaluation.material_mlp, bl.MATERIAL_HIDDEN, s))
            nmf = bl.material_baselines([n], evaluation.material_mlp,
                                        evaluation.nmf_max_iter)[1]
            row = {"n": n, "channels": len(bands[n]),
                   "spiking": _accuracy(mlp, X, y, train, test, seed),
                   "nmf": _accuracy(nmf, spectrum, y, train, test, seed),
                   "fft_mlp": reference, "wall_us_per_event": 1e6 * wall / len(ids),
                   "neuron_steps_per_event": f.neuron_steps / len(ids)}
            log(f"      {n:4d} resonators ({row['channels']} channels): spiking "
                f"{100 * row['spiking']:.1f} %, NMF-{n} {100 * row['nmf']:.1f} %, "
                f"FFT-MLP {100 * reference:.1f} %")
            rows.append(row)
    return rows


def _accuracy(baseline, X, y, train, test, seed) -> float:
    fold = cv.fit_fold(baseline, X, y, train, test, seed)
    return float(np.mean(fold.prediction == y[test]))


def _channels(bank) -> list[dict]:
    return [{"name": k, "pass_hz": [round(b.highpass_hz, 1), round(b.lowpass_hz, 1)],
             "resonators": b.n_neurons, "dt_ms": b.dt_ms} for k, b in bank.bands.items()]


def _hz_text(bank) -> str:
    return ", ".join(f"{b.highpass_hz:.0f}-{b.lowpass_hz:.0f}" for b in bank.bands.values())
