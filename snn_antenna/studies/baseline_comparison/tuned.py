"""The tuned spiking bank of the baseline comparison: channels from calibration
contacts, the bank over every event, its read-outs, and accuracy against resonators.

Calibration contacts are generated like the bench set but with another seed (the study's
seed + ``calibration_seed_offset``) and a few repetitions: the robot's own session on the
bench's rods, whose spectra and labels place the channels (``readout.band_tuning``). The
evaluated events never enter the placement, so no test split can leak into it, for any seed.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ...engine.events import cached_features, run_bank, run_cost
from ...evaluation import crossval as cv
from ...readout import baselines as bl
from ...readout.band_tuning import tune
from ...readout.spiking import recording_attrs
from ...readout.spiking_decoders import TunedPlan, decay_code, tuned_baselines, tuned_inputs
from ...sources import bench
from ...core.truth import bench_labels


def calibration_bands(bench_spec, plan: TunedPlan, log, fresh: bool) -> dict:
    """The channels of every tuning of ``plan`` (by number of resonators), placed from the
    calibration contacts, and a description of where they came from."""
    spec = replace(bench_spec, seed=bench_spec.seed + plan.calibration_seed_offset,
                   repetitions=plan.calibration_repetitions)
    log(f"      calibration contacts: {spec.n_events} events (seed {spec.seed}), "
        "never evaluated")
    data = bench.load(spec, log, fresh)
    attrs = recording_attrs(data)
    n_samples = int(round(plan.duration_s * attrs[0]))
    counts = data["counts"].values[:, :n_samples]
    labels = np.asarray([str(m) for m in bench_labels(data)["material"].values])
    return ({n: tune(counts, labels, *attrs, tuning) for n, tuning in plan.tunings().items()},
            {"calibration_events": int(spec.n_events), "calibration_seed": int(spec.seed)})


def tuned_stage(parts, data, cmp, log, fresh: bool, client) -> list:
    """The tuned bank over every event (cached), its read-outs' inputs into ``cmp.features``,
    its cost, and the accuracy-vs-resonators curve; the read-outs to evaluate."""
    plan: TunedPlan = parts.plan.tuned_plan()
    bands, where = calibration_bands(parts.bench, plan, log, fresh)
    main = plan.bank(bands[plan.base.n_resonators], parts.bank)
    log(f"      tuned bank: {main.n_neurons} resonators in {len(main.bands)} channels "
        f"({_hz_text(main)})")
    spikes = cached_features(data, main, parts.bench, log, fresh, client)
    cmp.features = tuned_inputs(cmp.features, spikes)
    cmp.costs["spiking_tuned"] = run_cost(data, main, parts.plan.cost_sample_events)
    curve = run_curve(data, cmp.features, plan, bands, parts, log, client)
    cmp.tuned = {**where, "neurons": main.n_neurons, "channels": _channels(main),
                 "duration_s": plan.duration_s, "bin_edges_s": list(plan.bin_edges_s),
                 "curve": curve}
    return tuned_baselines(parts.evaluation)


def run_curve(data, features, plan: TunedPlan, bands: dict, parts, log, client) -> list[dict]:
    """Per number of resonators: the tuned bank's accuracy (every read-out code, MLP 51)
    and NMF-n's, on the events of the first ``curve_repetitions`` repetitions, first seed's
    split; the full-spectrum MLP on the same split as the reference."""
    from threadpoolctl import threadpool_limits

    evaluation = parts.evaluation
    sub = features.isel(event=np.flatnonzero(features["repetition"].values
                                             < plan.curve_repetitions))
    seed = evaluation.seeds[0]
    train, test = cv.split_by_repetition(sub["repetition"].values, evaluation.test_fraction,
                                         seed)
    y = cv.targets_of(sub, "material", sorted(set(sub["material"].values.astype(str))))
    spectrum = bl.inputs_of(sub, "spectrum")
    ids = sub["event"].values
    log(f"      accuracy vs resonators on {len(ids)} events (repetitions < "
        f"{plan.curve_repetitions}), split of seed {seed}")
    fft = bl.material_baselines([], evaluation.material_mlp, evaluation.nmf_max_iter)[0]
    with threadpool_limits(1):
        reference = _accuracy(fft, spectrum, y, train, test, seed)
        rows = []
        for n in plan.curve:
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
