"""Baseline comparison: the paper's FFT, parametric and NMF read-outs on the bench data set.

Generates (or reuses) the bench contacts, processes every event as the paper did, checks the
generated signal against the paper's measurements of the signal (calibration), then trains
and tests each scikit-learn pipeline on the same splits by repetition for several seeds.
The report puts every number beside the paper's.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from ..readout import baselines as bl
from ..sources import bench
from ..readout import events
from .. import spec as specs
from .. import stats
from ..errors import SpecError, check
from ..files import atomic_write
from ..report import Calibrated, Predicted, Report

SECTIONS = ("stimulus", "events", "evaluation", "spiking")

QUICK_NOTE = ("Quick profile: 10 contacts per material and site, 2 seeds. The signal statistics "
              "(r², precision, CV of τ_low, wood/aluminium sites: ten contacts each, as the "
              "paper's test) are comparable with the full run; every classifier and regressor "
              "here trained on a tenth of the contacts, so accuracies, rmse and the confusion "
              "matrix are too small to compare with the paper or the full run.")

PAPER = {
    "r2_low": 0.995, "r2_high": 0.987, "spread_ratio_high_to_low": 3.0,
    "single_contact_precision_mm": 6.2, "tau_low_cv_max": 0.01,
    "wood_aluminium_sites_differing": 12, "wood_aluminium_sites": 16,
    "low_law": [0.0268, 0.69], "high_law": [0.0305, 1.52],
}


@dataclass
class Evaluation:
    """How the baselines are trained and tested (keys of ``[evaluation]``)."""
    seeds: list = field(default_factory=lambda: [0, 1, 2])
    test_fraction: float = 0.3
    nmf_dims: list = field(default_factory=lambda: list(bl.NMF_DIMENSIONS))
    nmf_max_iter: int = 400
    mlp_max_iter: int = 300
    # The 8-material MLPs stop improving early (full-spectrum MLP: 36.8 % after 25 epochs,
    # 36.3 % at convergence) and cost 0.5 s per epoch: they get their own, smaller budget.
    material_max_iter: int = 60
    pipelines: list = field(default_factory=lambda: ["distance", "material", "two_material"])

    def __post_init__(self):
        check(isinstance(self.seeds, list) and len(self.seeds) >= 1 and
              all(isinstance(s, int) and s >= 0 for s in self.seeds), "seeds", self.seeds,
              "a non-empty list of integer seeds >= 0")
        check(0 < self.test_fraction < 1, "test_fraction", self.test_fraction,
              "a fraction in (0, 1)")
        check(isinstance(self.nmf_dims, list) and all(isinstance(n, int) and n >= 1
                                                      for n in self.nmf_dims),
              "nmf_dims", self.nmf_dims, "a list of integers >= 1")
        for name in ("nmf_max_iter", "mlp_max_iter", "material_max_iter"):
            value = getattr(self, name)
            check(isinstance(value, int) and value >= 1, name, value, "an integer >= 1")
        known = {"distance", "material", "two_material"}
        check(set(self.pipelines) <= known, "pipelines", self.pipelines,
              f"a list of task groups out of {sorted(known)}")


@dataclass
class SpikingPlan:
    """The spiking read-out to compare (``[spiking]``; absent: FFT baselines only).

    ``bank`` holds ``spiking.SpikingBank`` fields (its bands as ``[spiking.bank.bands.NAME]``);
    ``designs`` is a list of array variants, each ``{name, band, ...Band fields}``, run on the
    events of the first ``design_repetitions`` repetitions and decoded on the first split.
    """
    bank: dict = field(default_factory=dict)
    designs: list = field(default_factory=list)
    design_repetitions: int = 10
    cost_sample_events: int = 400


def build_spiking(spec: dict):
    from ..readout.spiking import Band, SpikingBank

    if "spiking" not in spec:
        return None, None
    with specs.section("spiking"):
        plan = SpikingPlan(**specs.check_section(spec, "spiking", SpikingPlan))
        with specs.section("bank"):
            bank = SpikingBank(**plan.bank)
        for i, design in enumerate(plan.designs):
            design = dict(design)
            name, band = design.pop("name", f"design_{i}"), design.pop("band", "low")
            check(band in bank.bands, f"designs[{i}].band", band, f"one of {list(bank.bands)}")
            base = asdict(bank.bands[band])
            unknown = set(design) - set(base)
            check(not unknown, f"designs[{i}]", sorted(unknown),
                  f"fields of a band: {sorted(base)}")
            SpikingBank(**{**plan.bank, "bands": {band: Band(**{**base, **design})}})
            check(isinstance(name, str), f"designs[{i}].name", name, "a string")
        check(isinstance(plan.design_repetitions, int) and plan.design_repetitions >= 2,
              "design_repetitions", plan.design_repetitions, "an integer >= 2")
    return plan, bank


def build(spec: dict):
    """Check the whole spec before any long work; return its parts."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("stimulus"):
        bench_spec = bench.spec_from_table(spec.get("stimulus", {}), int(spec.get("seed", 0)))
        bench_spec.validate()
    with specs.section("events"):
        table = specs.check_section(spec, "events", events.EventProcessor, exclude=["rate_hz"])
        processor = events.EventProcessor(rate_hz=bench_spec.rate_hz, **table)
    with specs.section("evaluation"):
        evaluation = Evaluation(**specs.check_section(spec, "evaluation", Evaluation))
    if "wood" not in bench_spec.materials or "aluminium" not in bench_spec.materials:
        if "two_material" in evaluation.pipelines:
            raise SpecError("stimulus.materials", list(bench_spec.materials),
                            "a list that holds wood and aluminium for the two-material network")
    plan, bank = build_spiking(spec)
    if bank is not None:
        with specs.section("spiking"):
            bank.check_rate(bench_spec.rate_hz)
    return bench_spec, processor, evaluation, plan, bank


def load_features(bench_spec: bench.BenchSpec, processor: events.EventProcessor, log=print,
                  fresh: bool = False) -> tuple[xr.Dataset, xr.Dataset]:
    """The bench data set and its event features, both cached on disk by their specs."""
    data = bench.load(bench_spec, log, fresh)
    key = bench.source_hash({"bench": bench_spec.key(), "events": asdict(processor)}, events)
    path = Path(bench_spec.cache_dir) / f"features-{key}.zarr"
    feats = bench.cached(path, lambda: events.process(data, processor, bench_spec.n_jobs,
                                                      log=log), log, fresh)
    return data, feats


# -- calibration ----------------------------------------------------------------------------
def calibration(feats: xr.Dataset) -> dict:
    """The generated signal's measurements beside the paper's (docs/reference.md)."""
    from scipy import stats

    p = feats["params"]
    d = feats["distance_cm"].values.astype(float)
    out = {}
    residual_sd = {}
    for mode in ("low", "high"):
        logf = np.log10(p.sel(parameter=f"F_{mode}").values)
        fit = stats.linregress(d, logf)
        res = logf - (fit.slope * d + fit.intercept)
        out[f"{mode}_law"] = [float(fit.slope), float(fit.intercept)]
        out[f"r2_{mode}"] = float(fit.rvalue ** 2)
        residual_sd[mode] = float(res.std(ddof=2))
    out["residual_sd_dex"] = residual_sd
    out["spread_ratio_high_to_low"] = residual_sd["high"] / residual_sd["low"]
    f_low, f_high = (p.sel(parameter=n).values for n in ("F_low", "F_high"))
    groups = _groups(feats)
    hz_sd = [(f_high[g].std(ddof=1), f_low[g].std(ddof=1)) for g in groups if len(g) > 1]
    out["spread_ratio_high_to_low_hz"] = float(np.mean([h / lo for h, lo in hz_sd]))
    out["single_contact_precision_mm"] = 10 * residual_sd["low"] / out["low_law"][0]
    tau = p.sel(parameter="tau_low").values
    out["tau_low_cv_median"] = float(np.median([tau[g].std(ddof=1) / tau[g].mean()
                                                for g in groups if len(g) > 1]))
    materials = feats["material"].values.astype(str)
    out["tau_low_slope_s_per_cm"] = {}
    for m in np.unique(materials):
        sel = materials == m
        out["tau_low_slope_s_per_cm"][str(m)] = float(stats.linregress(d[sel], tau[sel]).slope)
    out.update(_wood_vs_aluminium(feats, tau))
    return out


def _groups(feats: xr.Dataset) -> list[np.ndarray]:
    m = feats["material"].values.astype(str)
    pos = feats["position"].values
    return [np.flatnonzero((m == a) & (pos == b)) for a in np.unique(m) for b in np.unique(pos)]


def _wood_vs_aluminium(feats: xr.Dataset, tau: np.ndarray, per_group: int = 10) -> dict:
    """Sites where wood and aluminium τ_low differ (t-test, p < 0.05) with the paper's ten
    contacts per material and site (its t = 3.14 at p = 0.0057 means 18 degrees of freedom)."""
    from scipy import stats

    m = feats["material"].values.astype(str)
    if not {"wood", "aluminium"} <= set(m):
        return {}
    pos = feats["position"].values
    differing, sites, t_values = 0, 0, []
    for site in np.unique(pos):
        a = tau[(m == "wood") & (pos == site)][:per_group]
        b = tau[(m == "aluminium") & (pos == site)][:per_group]
        if len(a) < 3 or len(b) < 3:
            continue
        t, pval = stats.ttest_ind(a, b)
        sites += 1
        differing += int(pval < 0.05)
        t_values.append(float(t))
    return {"wood_aluminium_sites_differing": differing, "wood_aluminium_sites": sites,
            "wood_aluminium_t": t_values, "contacts_per_site_in_test": per_group}


# -- baselines ------------------------------------------------------------------------------
def run_baselines(feats: xr.Dataset, evaluation: Evaluation, log=print,
                  extra: list | None = None) -> dict:
    """Train and test every baseline (and ``extra`` ones) on every seed's split."""
    from tqdm.auto import tqdm

    materials = sorted(set(feats["material"].values.astype(str)))
    mlp = bl.Mlp(max_iter=evaluation.mlp_max_iter)
    n_bins = feats.sizes["freq_hz"]
    chosen = []
    if "distance" in evaluation.pipelines:
        chosen += bl.distance_baselines(n_bins, mlp)
    if "material" in evaluation.pipelines:
        chosen += bl.material_baselines(evaluation.nmf_dims,
                                        bl.Mlp(max_iter=evaluation.material_max_iter),
                                        evaluation.nmf_max_iter)
    if "two_material" in evaluation.pipelines:
        chosen.append(bl.two_material_baseline(mlp))
    chosen += extra or []
    results = {}
    bar = tqdm(total=len(chosen) * len(evaluation.seeds), desc="baselines", unit="fit")
    # One BLAS thread: on this shared 2-core machine, 5 epochs of the material MLP took 44 s
    # with the default threads and 5 s with one (threads spin against other processes).
    limit = threadpool_limits(1)
    for b in chosen:
        keep = np.ones(feats.sizes["event"], dtype=bool)
        if b.task == "two_material":
            keep = np.isin(feats["material"].values.astype(str), ["wood", "aluminium"])
        sub = feats.isel(event=np.flatnonzero(keep))
        X, y = bl.inputs_of(sub, b.inputs), bl.targets_of(sub, b.task, materials)
        folds, scores = [], []
        for seed in evaluation.seeds:
            train, test = bl.split_by_repetition(sub["repetition"].values,
                                                 evaluation.test_fraction, seed)
            fold = bl.fit_fold(b, X, y, train, test, seed)
            folds.append(fold)
            scores.append(bl.score(b.task, y[test], fold.prediction))
            bar.update()
        summary = bl.summarise(scores)
        summary["fit_s"] = float(np.mean([f.fit_s for f in folds]))
        summary["predict_us_per_event"] = float(1e6 * np.mean([f.predict_s_per_event
                                                               for f in folds]))
        log(f"  {b.name:24s} " + ", ".join(f"{k} {v:.4g}" for k, v in summary.items()
                                           if not k.endswith("_sd") and k != "n_seeds"))
        results[b.name] = {"baseline": b, "folds": folds, "summary": summary,
                           "scores": scores, "event": sub["event"].values, "y": y}
    bar.close()
    limit.restore_original_limits()
    return results


def run(spec: dict, out_dir, quick: bool = False, fresh: bool = False, log=print) -> dict:
    bench_spec, processor, evaluation, plan, bank = build(spec)
    out_dir = Path(out_dir)
    t_start = time.perf_counter()
    stages = 5 if bank is not None else 4
    log(f"[1/{stages}] bench data set: {bench_spec.n_events} events at {bench_spec.rate_hz:g} Hz")
    t0 = time.perf_counter()
    data, feats_all = load_features(bench_spec, processor, log, fresh)
    data_s = time.perf_counter() - t0
    skipped = events.skip_counts(feats_all)
    valid = feats_all["skipped"].values == ""
    feats = feats_all.isel(event=np.flatnonzero(valid))
    log(f"      {int(valid.sum())} events processed, skipped: {skipped}")
    log(f"[2/{stages}] calibration against the paper's signal measurements")
    cal = calibration(feats)
    log(f"      r² low {cal['r2_low']:.4f} (paper 0.995), high {cal['r2_high']:.4f} (0.987); "
        f"precision {cal['single_contact_precision_mm']:.2f} mm (6.2)")
    costs = {"fft": fft_cost(data, processor, feats, plan.cost_sample_events if plan else 200)}
    extra, spiking_info = [], None
    if bank is not None:
        log(f"[3/{stages}] spiking read-out: {bank.n_neurons} resonators per event "
            f"({', '.join(bank.bands)}), Brian2 {bank.target}, dt {bank.dt_ms:g} ms, "
            f"{bank.batch_events} events per NeuronGroup")
        spikes = load_spiking(data, bank, bench_spec, log, fresh)
        feats = add_spiking_inputs(feats, spikes)
        costs["spiking"] = spiking_cost(data, bank, plan.cost_sample_events)
        extra = spiking_baselines(spikes, bl.Mlp(max_iter=evaluation.mlp_max_iter),
                                  bl.Mlp(max_iter=evaluation.material_max_iter))
        spiking_info = {"neurons_per_event": bank.n_neurons,
                        "neurons": spiking_neurons(spikes), "bands": {
            k: asdict(v) for k, v in bank.bands.items()}, "target": bank.target,
            "dt_ms": bank.dt_ms, "duration_s": bank.duration_s}
    log(f"[{stages - 1}/{stages}] baselines on {len(evaluation.seeds)} split(s) by repetition")
    results = run_baselines(feats, evaluation, log, extra)
    designs = []
    if plan is not None and plan.designs:
        designs = run_designs(data, feats, bank, plan, evaluation, log)
    log(f"[{stages}/{stages}] report")
    summary = _summary(cal, results, skipped, feats, bench_spec, data_s,
                       time.perf_counter() - t_start, costs, spiking_info, designs)
    _save_predictions(out_dir, feats, results)
    report = Report(out_dir, "Baseline comparison: FFT, parametric, NMF and spiking read-outs",
                    quick=quick, quick_note=QUICK_NOTE)
    _write_report(report, spec, summary, cal, feats, results, processor)
    summary = report.write(summary, spec, bank.target if bank else "none (no spiking part)")
    log(f"report in {out_dir}/report.html ({summary['timing']['total_s']:.0f} s)")
    return summary


# -- spiking --------------------------------------------------------------------------------
SPIKING_TASKS = {"distance", "material"}


def load_spiking(data: xr.Dataset, bank, bench_spec, log=print, fresh: bool = False
                 ) -> xr.Dataset:
    """Spiking features of every event, cached by the data set and the bank's spec."""
    from ..networks import neurons
    from .. import preprocess
    from ..readout import spiking

    key = bench.source_hash({"bench": bench_spec.key(), "bank": _bank_dict(bank)},
                            spiking, neurons, preprocess)
    path = Path(bench_spec.cache_dir) / f"spiking-{key}.zarr"

    def compute():
        f = bank.run(data["counts"].values, float(data.attrs["rate_hz"]),
                     int(data.attrs["adc_bits"]), float(data.attrs["full_scale_g"]))
        log(f"      {data.sizes['event']} events: {f.neuron_steps:.3g} neuron-steps in "
            f"{f.wall_s:.1f} s of simulation")
        return xr.Dataset(
            {"counts": (("event", "neuron"), f.counts.astype(np.int32)),
             "latency_s": (("event", "neuron"), f.latency_s),
             "span_s": (("event", "neuron"), f.span_s),
             "binned_counts": (("event", "neuron", "time_bin"),
                               f.binned_counts.astype(np.int32))},
            coords={"event": data["event"].values, "neuron_hz": ("neuron", f.neuron_hz),
                    "band": ("neuron", f.band.astype(str)),
                    "bin_start_s": ("time_bin", [0.0, *bank.bin_edges_s])},
            attrs={"simulation_wall_s": f.wall_s, "neuron_steps": f.neuron_steps})
    return bench.cached(path, compute, log, fresh)


def _bank_dict(bank) -> dict:
    d = asdict(bank)
    d["bands"] = {k: {kk: (list(vv) if isinstance(vv, tuple) else vv) for kk, vv in v.items()}
                  for k, v in d["bands"].items()}
    return d


# The spiking input sets: which bands, and whether the time-binned counts are included.
SPIKING_SETS = {
    "spiking_low": (("low",), False),
    "spiking_high": (("high",), False),
    "spiking_both": (("low", "high"), False),
    "spiking_rod": (("low", "high", "rod"), True),
}


def add_spiking_inputs(feats: xr.Dataset, spikes: xr.Dataset) -> xr.Dataset:
    """Spiking input matrices for the decoders, on the same events as the FFT features:
    per neuron its count, first-spike latency and firing span, and for ``spiking_rod`` also
    its counts in the time bins (how its firing decays)."""
    sp = spikes.sel(event=feats["event"].values)
    bands = sp["band"].values.astype(str)
    out = feats.copy()
    for name, (wanted, binned) in SPIKING_SETS.items():
        if not set(wanted) <= set(bands):
            continue
        keep = np.isin(bands, wanted)
        parts = [sp[v].values[:, keep] for v in ("counts", "latency_s", "span_s")]
        if binned:
            parts.append(sp["binned_counts"].values[:, keep].reshape(len(sp["event"]), -1))
        out[name] = (("event", f"{name}_feature"), np.hstack(parts).astype(np.float32))
    if "low" in set(bands):
        out["spiking_low_counts"] = (("event", "low_neuron"), sp["counts"].values[:, bands == "low"])
    return out


def spiking_neurons(spikes: xr.Dataset) -> dict:
    """Resonators per event behind each spiking input set (its filters, as NMF's n)."""
    bands = spikes["band"].values.astype(str)
    return {name: int(np.isin(bands, wanted).sum()) for name, (wanted, _) in SPIKING_SETS.items()
            if set(wanted) <= set(bands)}


# Decoders that learn nothing and invert the generator's own frequency law: they show the
# simulator agreeing with itself, not a result to set beside the paper's.
TRAINING_FREE = ("spiking_dominant", "spiking_centroid")
SPIKING_INPUT_OF = {"spiking_mlp_distance_low": "spiking_low",
                    "spiking_mlp_distance": "spiking_both",
                    "spiking_mlp_material_high": "spiking_high",
                    "spiking_mlp_material": "spiking_both",
                    "spiking_mlp_material_rod": "spiking_rod"}


def spiking_baselines(spikes: xr.Dataset, mlp: bl.Mlp, material_mlp: bl.Mlp) -> list:
    """Decoders of the spiking features, in the same framework as the FFT baselines."""
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    from ..readout.spiking import CentroidDistance, DominantNeuronDistance

    bands = set(spikes["band"].values.astype(str))
    out = []

    def regressor(seed):
        return TransformedTargetRegressor(make_pipeline(StandardScaler(),
                                                        mlp.regressor((20, 5), seed)),
                                          transformer=StandardScaler())

    def classifier(seed):
        return make_pipeline(StandardScaler(), material_mlp.classifier((51,), seed))

    available = {name for name, (wanted, _) in SPIKING_SETS.items() if set(wanted) <= bands}
    if "low" in bands:
        low_hz = spikes["neuron_hz"].values[spikes["band"].values.astype(str) == "low"]
        out.append(bl.Baseline("spiking_dominant", "distance", "spiking_low_counts",
                               lambda seed: DominantNeuronDistance(low_hz),
                               "most active low-band resonator → inverse low-mode law "
                               "(Fig. 10E), no training"))
        out.append(bl.Baseline("spiking_centroid", "distance", "spiking_low_counts",
                               lambda seed: CentroidDistance(low_hz),
                               "rate-weighted centroid of the low band → inverse low-mode "
                               "law, no training"))
    described = {
        "spiking_mlp_distance_low": ("distance", regressor,
                                     "MLP 20-5 on the low band's counts, latencies, spans"),
        "spiking_mlp_distance": ("distance", regressor, "MLP 20-5 on the low and high band"),
        "spiking_mlp_material_high": ("material", classifier, "MLP 51 on the high band only"),
        "spiking_mlp_material": ("material", classifier, "MLP 51 on the low and high band"),
        "spiking_mlp_material_rod": ("material", classifier,
                                     "MLP 51 on low, high and rod band, with time bins"),
    }
    for name, (task, build, text) in described.items():
        if SPIKING_INPUT_OF[name] in available:
            out.append(bl.Baseline(name, task, SPIKING_INPUT_OF[name], build, text))
    return out


def fft_cost(data: xr.Dataset, processor, feats: xr.Dataset, n: int) -> dict:
    """Wall time per event of the FFT feature extraction, measured now on ``n`` events."""
    ids = feats["event"].values[:n]
    args = (processor, int(data.attrs["adc_bits"]), float(data.attrs["full_scale_g"]))
    events.process_block(data["counts"].values[ids[:2]], *args)   # warm-up: imports, caches
    t0 = time.perf_counter()
    events.process_block(data["counts"].values[ids], *args)
    return {"features_us_per_event": 1e6 * (time.perf_counter() - t0) / len(ids)}


def spiking_cost(data: xr.Dataset, bank, n: int) -> dict:
    """Wall time (coding + Brian2) and neuron-steps per event, measured now on one batch."""
    from dataclasses import replace

    ids = np.linspace(0, data.sizes["event"] - 1, n).astype(int)
    sample = data["counts"].values[ids]
    one = replace(bank, batch_events=max(bank.batch_events, n))
    rate, bits, fs = (float(data.attrs["rate_hz"]), int(data.attrs["adc_bits"]),
                      float(data.attrs["full_scale_g"]))
    one.run(sample[:2], rate, bits, fs, progress=False)   # warm-up: code generation, compiling
    t0 = time.perf_counter()
    f = one.run(sample, rate, bits, fs, progress=False)
    total = time.perf_counter() - t0
    return {"features_us_per_event": 1e6 * total / n,
            "simulation_us_per_event": 1e6 * f.wall_s / n,
            "neuron_steps_per_event": f.neuron_steps / n,
            "ns_per_neuron_step": 1e9 * f.wall_s / f.neuron_steps, "events_measured": n,
            "target": bank.target}


def run_designs(data, feats, bank, plan, evaluation, log=print) -> list[dict]:
    """Array variants (one band changed at a time) on a subset: accuracy and cost of each."""
    from dataclasses import replace

    from ..readout.spiking import Band

    subset = feats.isel(event=np.flatnonzero(feats["repetition"].values
                                             < plan.design_repetitions))
    ids = subset["event"].values
    counts = data["counts"].values[ids]
    materials = sorted(set(subset["material"].values.astype(str)))
    mlp = bl.Mlp(max_iter=evaluation.mlp_max_iter)
    material_mlp = bl.Mlp(max_iter=evaluation.material_max_iter)
    seed = evaluation.seeds[0]
    train, test = bl.split_by_repetition(subset["repetition"].values, evaluation.test_fraction,
                                         seed)
    rows = []
    log(f"      array designs on {len(ids)} events (repetitions < {plan.design_repetitions})")
    limit = threadpool_limits(1)   # as in run_baselines
    for i, design in enumerate(plan.designs):
        design = dict(design)
        name, band = design.pop("name", f"design_{i}"), design.pop("band", "low")
        variant = Band(**{**asdict(bank.bands[band]), **design})
        one = replace(bank, bands={band: variant})
        t0 = time.perf_counter()
        f = one.run(counts, float(data.attrs["rate_hz"]), int(data.attrs["adc_bits"]),
                    float(data.attrs["full_scale_g"]), progress=False)
        wall = time.perf_counter() - t0
        X = f.matrix().astype(np.float32)
        row = {"design": name, "band": band,
               "change": ", ".join(f"{k} = {v}" for k, v in design.items()),
               "n_neurons": variant.n_neurons,
               "wall_us_per_event": 1e6 * wall / len(ids),
               "neuron_steps_per_event": f.neuron_steps / len(ids)}
        for task, y, base in (
                ("distance", subset["distance_cm"].values.astype(float),
                 spiking_baselines_for(task="distance", mlp=mlp)),
                ("material", bl.targets_of(subset, "material", materials),
                 spiking_baselines_for(task="material", mlp=material_mlp))):
            fold = bl.fit_fold(base, X, y, train, test, seed)
            row.update({("distance_rmse_mm" if task == "distance" else "material_accuracy"):
                        next(iter(bl.score(task, y[test], fold.prediction).values()))})
        log(f"      {name:22s} {variant.n_neurons:3d} neurons: {row['distance_rmse_mm']:.2f} mm, "
            f"{100 * row['material_accuracy']:.1f} %, {row['wall_us_per_event']:.0f} µs/event")
        rows.append(row)
    limit.restore_original_limits()
    return rows


def spiking_baselines_for(task: str, mlp: bl.Mlp) -> bl.Baseline:
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    if task == "distance":
        return bl.Baseline("design_distance", "distance", "spiking", lambda seed:
                           TransformedTargetRegressor(make_pipeline(
                               StandardScaler(), mlp.regressor((20, 5), seed)),
                               transformer=StandardScaler()))
    return bl.Baseline("design_material", "material", "spiking", lambda seed: make_pipeline(
        StandardScaler(), mlp.classifier((51,), seed)))


def _summary(cal, results, skipped, feats, bench_spec, data_s, total_s, costs=None,
             spiking_info=None, designs=()) -> dict:
    dist = {k: r["summary"] for k, r in results.items() if r["baseline"].task == "distance"}
    mat = {k: r["summary"] for k, r in results.items() if r["baseline"].task == "material"}
    nmf = [{"n": int(k.split("_")[1]), "accuracy": v["accuracy"], "accuracy_sd": v["accuracy_sd"]}
           for k, v in mat.items() if k.startswith("nmf_")]
    two = next((r["summary"] for r in results.values()
                if r["baseline"].task == "two_material"), None)
    costs = costs or {}
    per_event = {}
    neurons = (spiking_info or {}).get("neurons", {})
    total_neurons = (spiking_info or {}).get("neurons_per_event", 1)
    for k, r in results.items():
        kind = "spiking" if k.startswith("spiking_") else "fft"
        front = costs.get(kind, {}).get("features_us_per_event", 0.0)
        if kind == "spiking":
            # the bank runs every band at once; each read-out is charged its bands' share
            # (cost per neuron-step is the same across bands, measured: one NeuronGroup)
            used = neurons.get(SPIKING_INPUT_OF.get(k, "spiking_low"), total_neurons)
            front *= used / total_neurons
        per_event[k] = front + r["summary"]["predict_us_per_event"]
    spiking = None
    if spiking_info is not None:
        spiking = {
            "distance_rmse_mm": {k: {"mean": v["rmse_mm"], "sd": v["rmse_mm_sd"]}
                                 for k, v in dist.items() if k.startswith("spiking_")},
            "material_accuracy": {k: {"mean": v["accuracy"], "sd": v["accuracy_sd"]}
                                  for k, v in mat.items() if k.startswith("spiking_")},
            "against_fft": _spiking_against_fft(results, neurons),
            "cost": costs.get("spiking"), **spiking_info,
            "designs": list(designs)}
    out = {
        "materials": sorted(set(feats["material"].values.astype(str))),
        "calibration": {"ours": cal, "paper": PAPER},
        "distance_rmse_mm": {k: {"mean": v["rmse_mm"], "sd": v["rmse_mm_sd"],
                                 "n_seeds": v["n_seeds"]} for k, v in dist.items()},
        "material_accuracy": {**{k: {"mean": v["accuracy"], "sd": v["accuracy_sd"],
                                     "n_seeds": v["n_seeds"]}
                                 for k, v in mat.items() if not k.startswith("nmf_")},
                              "nmf_curve": sorted(nmf, key=lambda r: r["n"])},
        "two_material": ({"rmse_mm": two["rmse_mm"], "rmse_mm_sd": two["rmse_mm_sd"],
                          "accuracy": two["accuracy"], "accuracy_sd": two["accuracy_sd"]}
                         if two else None),
        "timing": {"data_and_features_s": data_s, "total_s": total_s,
                   **{k: {"fit_s": r["summary"]["fit_s"],
                          "predict_us_per_event": r["summary"]["predict_us_per_event"]}
                      for k, r in results.items()}},
        "data": {"n_events": int(bench_spec.n_events), "n_processed": int(feats.sizes["event"]),
                 "skipped": skipped, "rate_hz": bench_spec.rate_hz,
                 "n_bins": int(feats.sizes["freq_hz"]), "bench_key": bench_spec.key()},
        "cost_us_per_event": per_event,
        "feature_costs": costs,
    }
    if spiking is not None:
        out["spiking"] = spiking
    return out


def _spiking_against_fft(results: dict, neurons: dict) -> dict:
    """Each spiking material read-out as a fraction of the full-spectrum MLP (per seed, then
    mean and interval) and against NMF with as many filters as it has resonators (paired by
    seed: the difference, its interval and verdict)."""
    fft = results.get("mlp_spectrum_material")
    out = {}
    for name, r in results.items():
        if not (name.startswith("spiking_") and r["baseline"].task == "material") or not fft:
            continue
        acc = np.array([x["accuracy"] for x in r["scores"]])
        row = {"input": SPIKING_INPUT_OF.get(name), "neurons": neurons.get(
            SPIKING_INPUT_OF.get(name)), "accuracy": float(acc.mean())}
        ratio = acc / np.array([x["accuracy"] for x in fft["scores"]])
        row["fraction_of_fft_mlp"] = float(ratio.mean())
        if len(acc) >= 2:
            row["fraction_interval"] = stats.mean_interval(ratio).as_dict()
        nmf = results.get(f"nmf_{row['neurons']}")
        if nmf is not None:
            other = np.array([x["accuracy"] for x in nmf["scores"]])
            row["nmf_same_n"] = float(other.mean())
            if len(acc) >= 2:
                row["minus_nmf_same_n"] = stats.paired_difference(acc, other).as_dict()
        out[name] = row
    return out


def _save_predictions(out_dir: Path, feats: xr.Dataset, results: dict) -> None:
    """Every test prediction, so any number of the report can be recomputed from them."""
    rows = {}
    for name, r in results.items():
        for f in r["folds"]:
            y = r["y"][f.test_index]
            rows.setdefault(name, []).append({
                "seed": f.seed, "test_event": r["event"][f.test_index].tolist(),
                "train_event": r["event"][f.train_index].tolist(),
                "true": np.asarray(y).tolist(), "predicted": np.asarray(f.prediction).tolist()})
    out_dir.mkdir(parents=True, exist_ok=True)
    # each event's repetition, so a reader can check that no contact of a test repetition
    # was trained on
    repetition = dict(zip(feats["event"].values.tolist(), feats["repetition"].values.tolist()))
    atomic_write(out_dir / "predictions.json", json.dumps({"task": {
        n: r["baseline"].task for n, r in results.items()}, "folds": rows,
        "repetition": {str(k): int(v) for k, v in repetition.items()}}))


# -- report ---------------------------------------------------------------------------------
SOURCE = "paper (docs/reference.md)"
LABELS = {
    "linear_low_peak": "linear regression, low peak",
    "mlp_parametric": "MLP on 2 peaks (F, A)",
    "mlp_spectrum": "MLP, full spectrum",
    "mlp_spectrum_sub10": "MLP, every 10th bin",
    "mlp_low_half": "MLP, lower half of spectrum",
    "mlp_spectrum_material": "MLP 51, full spectrum",
    "mlp_5_8_2": "5-8-2 MLP, wood/aluminium",
    "spiking_dominant": "most active resonator",
    "spiking_centroid": "rate centroid",
    "spiking_mlp_distance_low": "spiking MLP, low band",
    "spiking_mlp_distance": "spiking MLP, low + high",
    "spiking_mlp_material_high": "spiking MLP, high band",
    "spiking_mlp_material": "spiking MLP, low + high",
    "spiking_mlp_material_rod": "spiking MLP, + rod band, time bins",
}


def label(name: str) -> str:
    if name.startswith("nmf_"):
        return f"NMF-{name.split('_')[1]} → MLP"
    return LABELS.get(name, name.replace("_", " "))


def _interval(values) -> tuple[tuple | None, int]:
    values = np.asarray(values, dtype=float)
    if len(values) < 2:
        return None, len(values)
    iv = stats.mean_interval(values)
    return (iv.low, iv.high), iv.n


def _scores(results, name, key):
    return [x[key] for x in results[name]["scores"]]


def _declare(report, cal, results, summary) -> None:
    """What the generator was set to match (calibrated) apart from what it predicts."""
    how = "antenna.py, see docs/materials.md"
    rows = [
        Calibrated("r² of the low-mode law", cal["r2_low"], 0.995, "", SOURCE,
                   "low-mode scatter LOW_SCATTER_DEX; " + how),
        Calibrated("r² of the high-mode law", cal["r2_high"], 0.987, "", SOURCE,
                   "high-mode scatter HIGH_SCATTER_DEX"),
        Calibrated("single-contact precision, low peak", cal["single_contact_precision_mm"],
                   6.2, "mm", SOURCE, "LOW_SCATTER_DEX"),
        Calibrated("low law (slope, intercept)", _pair(cal["low_law"]), _pair(PAPER["low_law"]),
                   "", SOURCE, "the generator uses the paper's law"),
        Calibrated("high law (slope, intercept)", _pair(cal["high_law"]),
                   _pair(PAPER["high_law"]), "", SOURCE, "the generator uses the paper's law"),
        Calibrated("CV of τ_low within a site (median)", 100 * cal["tau_low_cv_median"],
                   "< 1", "%", SOURCE, "TAU_LOW_CV and the decay fit (events.py)"),
    ]
    if "wood_aluminium_sites" in cal:
        rows.append(Calibrated(
            "sites where wood and aluminium τ_low differ (t-test, 10 each)",
            f"{cal['wood_aluminium_sites_differing']} of {cal['wood_aluminium_sites']}",
            "12 of 16", "", SOURCE, "ANTENNA_CONTACT_STIFFNESS_N_M (energy into the rod)"))
    if "linear_low_peak" in results:
        rows.append(Calibrated(
            "distance rmse, linear regression on the low peak",
            summary["distance_rmse_mm"]["linear_low_peak"]["mean"], 6.2, "mm", SOURCE,
            "LOW_SCATTER_DEX (the same statistic as the precision above, on test contacts)"))
    if "mlp_spectrum_material" in results:
        rows.append(Calibrated(
            "8 materials, full-spectrum MLP accuracy",
            100 * summary["material_accuracy"]["mlp_spectrum_material"]["mean"], 94.2, "%",
            SOURCE, "ROD_COUPLING: how much of the rod's own mode reaches the tip"))
    report.calibrated(*rows)

    pred = [Predicted("spread of the high / low peak (residual, dex)",
                      cal["spread_ratio_high_to_low"], "", "≈ 3", SOURCE,
                      note="lowered by the high-mode scatter that r² = 0.987 needs")]
    for name in ("mlp_parametric", "mlp_spectrum", "mlp_spectrum_sub10", "mlp_low_half"):
        if name in results:
            ci, n = _interval(_scores(results, name, "rmse_mm"))
            paper = {"mlp_parametric": 2.93, "mlp_spectrum": 1.71,
                     "mlp_spectrum_sub10": "≈ full spectrum",
                     "mlp_low_half": "≈ 2 peaks"}[name]
            pred.append(Predicted(f"distance rmse, {label(name)}",
                                  summary["distance_rmse_mm"][name]["mean"], "mm", paper,
                                  SOURCE, ci, n))
    if "nmf_30" in results:
        ci, n = _interval(100 * np.array(_scores(results, "nmf_30", "accuracy")))
        pred.append(Predicted("8 materials, NMF-30 → MLP accuracy",
                              100 * np.mean(_scores(results, "nmf_30", "accuracy")), "%",
                              "≥ 86", SOURCE, ci, n))
    if "mlp_5_8_2" in results:
        for key, unit, paper, scale in (("rmse_mm", "mm", "±4", 1), ("accuracy", "%", 87, 100)):
            vals = scale * np.array(_scores(results, "mlp_5_8_2", key))
            ci, n = _interval(vals)
            pred.append(Predicted(f"5-8-2 wood/aluminium network, {key.split('_')[0]}",
                                  float(vals.mean()), unit, paper, SOURCE, ci, n))
    if "mlp_spectrum_material" in results:
        pred += _confusion_predictions(results["mlp_spectrum_material"], summary["materials"])
    for name, row in (summary.get("spiking") or {}).get("against_fft", {}).items():
        ci, n = _interval(100 * np.array(_scores(results, name, "accuracy")))
        frac = row["fraction_of_fft_mlp"]
        pred.append(Predicted(f"8 materials, {label(name)}", 100 * row["accuracy"], "%", None,
                              "this run (no spiking material result in the paper)", ci, n,
                              f"{100 * frac:.0f} % of the full-spectrum MLP"))
    report.predicted(*pred)


def _confusion_predictions(result, materials) -> list:
    cm = confusion(result, len(materials))
    index = {m: i for i, m in enumerate(materials)}
    out = []

    def error(m):
        i = index[m]
        return cm[i].sum() - cm[i, i], cm[i].sum()

    for m, paper in (("brass", 9.4), ("wood", 8.4)):
        if m in index:
            k, n = error(m)
            lo, hi = stats.binomial_interval(int(k), int(n))
            out.append(Predicted(f"{m} contacts misclassified", 100 * k / n, "%", paper,
                                 SOURCE, (100 * lo, 100 * hi), int(n), "Wilson interval"))
    pair, rate = most_confused_pair(cm, materials)
    out.append(Predicted("most confused pair (share of the pair's contacts)",
                         f"{pair[0]} ↔ {pair[1]} ({100 * rate:.1f} %)", "", "brass ↔ wood",
                         SOURCE))
    if {"aluminium", "pvc"} <= set(index):
        a, b = index["aluminium"], index["pvc"]
        k, n = cm[a, b] + cm[b, a], cm[a].sum() + cm[b].sum()
        lo, hi = stats.binomial_interval(int(k), int(n))
        out.append(Predicted("aluminium ↔ PVC confused", 100 * k / n, "%", "easy pair",
                             SOURCE, (100 * lo, 100 * hi), int(n)))
    plastics = [index[m] for m in ("pom", "pvc", "acrylic_glass") if m in index]
    if len(plastics) >= 2:
        block = cm[np.ix_(plastics, plastics)]
        k, n = block.sum() - np.trace(block), cm[plastics].sum()
        lo, hi = stats.binomial_interval(int(k), int(n))
        out.append(Predicted("plastics taken for another plastic", 100 * k / n, "%",
                             "hard pairs", SOURCE, (100 * lo, 100 * hi), int(n)))
    return out


def most_confused_pair(cm: np.ndarray, materials) -> tuple[tuple[str, str], float]:
    """The pair of classes most often taken for each other, as a share of their contacts."""
    best, rate = ("", ""), -1.0
    for i in range(len(materials)):
        for j in range(i + 1, len(materials)):
            r = (cm[i, j] + cm[j, i]) / max(1, cm[i].sum() + cm[j].sum())
            if r > rate:
                best, rate = (materials[i], materials[j]), float(r)
    return best, rate


def confusion_sentence(cm: np.ndarray, materials) -> str:
    """Where the confusion matrix agrees with the paper's Fig. 6D and where not, and why."""
    index = {m: i for i, m in enumerate(materials)}
    (a, b), rate = most_confused_pair(cm, materials)
    agree, differ = [], []
    if {a, b} == {"brass", "wood"}:
        agree.append("brass ↔ wood is the most confused pair")
    else:
        differ.append(f"the most confused pair is {a} ↔ {b} ({100 * rate:.1f} % of their "
                      "contacts), not brass ↔ wood")
    plastics = [index[m] for m in ("pom", "pvc", "acrylic_glass") if m in index]
    if len(plastics) >= 2:
        block = cm[np.ix_(plastics, plastics)]
        within = (block.sum() - np.trace(block)) / max(1, cm[plastics].sum())
        overall = (cm.sum() - np.trace(cm)) / max(1, cm.sum())
        (agree if within > overall else differ).append(
            f"the plastics are {'among the hardest' if within > overall else 'not the hardest'}"
            f" ({100 * within:.1f} % taken for another plastic, {100 * overall:.1f} % errors "
            "overall)")
    if {"aluminium", "pvc"} <= set(index):
        i, j = index["aluminium"], index["pvc"]
        pair = (cm[i, j] + cm[j, i]) / max(1, cm[i].sum() + cm[j].sum())
        (agree if pair < 0.01 else differ).append(
            f"aluminium ↔ PVC {'is an easy pair' if pair < 0.01 else 'is not an easy pair'} "
            f"({100 * pair:.1f} %)")
    text = "Beside the paper's Fig. 6D: "
    if agree:
        text += "it agrees that " + "; ".join(agree) + ". "
    if differ:
        text += "It differs in that " + "; ".join(differ) + ". "
    return text + (
        "Why: in this generator a rod's material reaches the spectrum mainly through its own "
        "bending mode, f₁ ∝ √(E/ρ), so classes that share a mode are confused: the three "
        "plastics (107–123 Hz), brass and copper (256–271 Hz), aluminium and steel "
        "(369–377 Hz: equal √(E/ρ)); wood (334 Hz, light and lossy) rings apart from brass. "
        "Whatever made brass sound like wood on the real bench (its mounting, rod lengths, "
        "surface finish) is not in the model.")


def _write_report(report, spec, summary, cal, feats, results, processor) -> None:
    _declare(report, cal, results, summary)
    report.text(spec.get("description", ""))
    report.text("How the generator makes materials differ (antenna.py, docs/materials.md): "
                "each rod's own bending mode rings along while the antenna rests on it "
                "(Euler–Bernoulli, from textbook E, ρ and loss factor, 12 mm × 15 cm), the "
                "impact lasts Hertz's contact time, and the rod takes energy out of the "
                "antenna's modes by its loss factor and compliance. The calibrated numbers "
                "above were set; the predicted ones were not, and only those stand beside "
                "the paper's results.")
    report.heading("The signal")
    report.figure(_fig_laws(feats, cal), "fig2c_frequency_laws",
                  "Peak frequency vs contact distance, low and high mode (paper's Fig. 2C); "
                  "lines: our fit (solid) and the paper's law (dashed).")
    report.figure(_fig_tau(feats), "fig5d_decay_times",
                  "Decay time of the low mode vs distance for wood and aluminium (Fig. 5D).")
    report.heading("Distance and material read-outs")
    report.table(_result_rows(summary), "Mean ± sd over seeds, test contacts only; the "
                                        "calibrated and predicted tables above carry the "
                                        "intervals and the paper's values.")
    dist = [k for k, r in results.items() if r["baseline"].task == "distance"
            and k not in TRAINING_FREE]
    if dist:
        report.figure(_fig_predictions(feats, results, dist), "fig4b_predicted_distance",
                      "Predicted vs true distance per pipeline, first seed (Fig. 4B).")
    free = [k for k in TRAINING_FREE if k in results]
    if free:
        report.table([{"decoder": label(k), "distance rmse (mm)":
                       f"{results[k]['summary']['rmse_mm']:.2f}"} for k in free],
                     "Self-consistency, not a result: these decoders learn nothing and invert "
                     "the generator's own frequency law, so they show the simulator agreeing "
                     "with itself; they are not compared with the paper.")
    if "mlp_spectrum_material" in results:
        materials = summary["materials"]
        report.figure(_fig_confusion(results["mlp_spectrum_material"], materials),
                      "fig6d_confusion", "8-material confusion matrix of the full-spectrum "
                      "MLP, all seeds' test contacts, rows normalised (Fig. 6D).")
        report.text(confusion_sentence(confusion(results["mlp_spectrum_material"],
                                                 len(materials)), materials))
    nmf_names = [k for k in results if k.startswith("nmf_")]
    if nmf_names:
        shown = "nmf_9" if "nmf_9" in results else nmf_names[0]
        report.figure(_fig_nmf_basis(results[shown], feats), "fig7a_nmf_basis",
                      f"The {shown.split('_')[1]} NMF basis vectors as band-pass filters "
                      "(first seed; Fig. 7A).")
        report.figure(_fig_nmf_curve(summary), "fig7b_nmf_accuracy",
                      "Material accuracy vs NMF dimension (mean ± sd over seeds), the "
                      "full-spectrum MLP (dashed) and the spiking read-outs at their number "
                      "of resonators (red; Fig. 7B).")
    if "spiking" in summary:
        _write_spiking(report, summary)
    report.figure(_fig_pareto(summary), "pareto_cost_accuracy",
                  "Accuracy vs cost per event (feature extraction + decoder, wall time measured "
                  "in this run) of every pipeline; the line joins the Pareto front; numbers "
                  "are keyed in the table below.")
    report.table([{"#": i + 1, "pipeline": label(k),
                   "task": ("distance" if k in summary["distance_rmse_mm"] else
                            "wood/aluminium" if k == "mlp_5_8_2" else "material"),
                   "features + decoder (µs/event)": summary["cost_us_per_event"][k],
                   "fit (s)": v["fit_s"]}
                  for i, (k, v) in enumerate(_cost_items(summary))],
                 "Cost: inference per event and training wall time (mean over seeds)")
    d = summary["data"]
    sk = d["skipped"]
    report.text(f"Data: {d['n_events']} generated events, {d['n_processed']} processed; "
                f"skipped: {sk.get('no_onset', 0)} without an onset, {sk.get('clipped', 0)} "
                f"clipped, {sk.get('no_decay_fit', 0)} without a decay fit; spectrum of "
                f"{d['n_bins']} bins at {processor.rate_hz:g} Hz.")


def _cost_items(summary):
    return [(k, v) for k, v in summary["timing"].items() if isinstance(v, dict)]


def _write_spiking(report, summary) -> None:
    sp = summary["spiking"]
    report.heading("Spiking read-out beside the FFT")
    rows = []
    cost = summary["cost_us_per_event"]
    for k, row in sp.get("against_fft", {}).items():
        diff = row.get("minus_nmf_same_n")
        frac = row.get("fraction_interval")
        rows.append({
            "read-out": label(k), "resonators": row["neurons"],
            "accuracy (%)": f"{100 * row['accuracy']:.1f}",
            "of FFT-MLP": (f"{100 * row['fraction_of_fft_mlp']:.0f} %" + (
                f" ({100 * frac['low']:.0f}–{100 * frac['high']:.0f})" if frac else "")),
            "NMF, same n (%)": (f"{100 * row['nmf_same_n']:.1f}" if "nmf_same_n" in row
                                else "—"),
            "minus NMF": (f"{100 * diff['mean']:+.1f} ({diff['verdict']}, n {diff['n']})"
                          if diff else "—"),
            "µs/event": f"{cost.get(k, 0):.0f}"})
    report.table(rows, "8-material accuracy on the same contacts and splits; fraction of the "
                       "full-spectrum MLP per seed (95 % interval); NMF with as many filters "
                       "as resonators, paired by seed. Cost: coding + Brian2, charged by the "
                       "read-out's share of the bank's resonators.")
    rows = []
    for k, v in sp["distance_rmse_mm"].items():
        if k not in TRAINING_FREE:
            rows.append({"read-out": label(k), "distance rmse (mm)":
                         f"{v['mean']:.2f} ± {v['sd']:.2f}", "µs/event": f"{cost.get(k, 0):.0f}"})
    report.table(rows, "Distance from spiking features (MLP 20-5)")
    c = sp.get("cost") or {}
    report.text(f"Spiking cost, measured in this run on {c.get('events_measured')} events: "
                f"{c.get('features_us_per_event', 0):.0f} µs per event for the whole bank "
                f"({sp['neurons_per_event']} resonators, coding + Brian2 {c.get('target')}), "
                f"{c.get('neuron_steps_per_event', 0):.3g} neuron-steps per event, "
                f"{c.get('ns_per_neuron_step', 0):.1f} ns per neuron-step; dt {sp['dt_ms']} ms, "
                f"{sp['duration_s']} s per event.")
    if sp.get("designs"):
        report.table([{"design": d["design"], "band": d["band"], "change": d["change"],
                       "neurons": d["n_neurons"],
                       "distance (mm)": f"{d['distance_rmse_mm']:.2f}",
                       "material (%)": f"{100 * d['material_accuracy']:.1f}",
                       "µs/event": f"{d['wall_us_per_event']:.0f}"} for d in sp["designs"]],
                     "Array designs (one band changed at a time, first split, events of the "
                     "first repetitions only)")


def _fig_pareto(summary):
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    cost = summary["cost_us_per_event"]
    number = {k: i + 1 for i, (k, _) in enumerate(_cost_items(summary))}
    panels = ((axes[0], summary["distance_rmse_mm"], "distance rmse (mm)", False),
              (axes[1], {k: v for k, v in summary["material_accuracy"].items()
                         if k != "nmf_curve"} | {f"nmf_{r['n']}": {"mean": r["accuracy"]}
                                                 for r in summary["material_accuracy"]
                                                 ["nmf_curve"]},
               "8-material accuracy", True))
    for ax, table, ylabel, higher in panels:
        pts = sorted((cost[k], v["mean"], k) for k, v in table.items()
                     if k in cost and k not in TRAINING_FREE)
        if not pts:
            continue
        # Pipelines sharing a front end share a cost: their labels alternate sides, in
        # order of the y value, so neighbours do not print over each other.
        for rank, (c, a, k) in enumerate(sorted(pts, key=lambda p: (round(p[0], -1), p[1]))):
            colour = "tab:red" if k.startswith("spiking_") else "tab:blue"
            ax.scatter(c, a, color=colour, s=22, zorder=3)
            ax.annotate(str(number.get(k, "")), (c, a), fontsize=7,
                        xytext=(5, -3) if rank % 2 == 0 else (-15, -3),
                        textcoords="offset points", color=colour)
        front, best = [], None
        for c, a, k in pts:
            if best is None or (a > best if higher else a < best):
                front.append((c, a))
                best = a
        ax.plot(*zip(*front), color="k", lw=0.8, drawstyle="steps-post")
        ax.set_xscale("log")
        ax.margins(x=0.12)   # room for the labels on the left of the cheapest points
        costs = [c for c, _, _ in pts]
        if max(costs) / min(costs) > 10:   # within one decade the minor ticks are the labels
            ax.xaxis.set_minor_formatter(plt.NullFormatter())
        ax.set_xlabel("cost per event (µs: features + decoder)")
        ax.set_ylabel(ylabel)
    axes[0].set_title("blue: FFT pipelines, red: spiking; numbers: cost table", fontsize=8)
    fig.tight_layout()
    return fig


def _pair(x) -> str:
    return f"{x[0]:.4f}, {x[1]:.3f}"


def _result_rows(summary: dict) -> list[dict]:
    rows = []
    for k, v in summary["distance_rmse_mm"].items():
        if k not in TRAINING_FREE:
            rows.append({"pipeline": label(k), "task": "distance rmse (mm)",
                         "ours": f"{v['mean']:.2f} ± {v['sd']:.2f}"})
    for k, v in summary["material_accuracy"].items():
        if k == "nmf_curve":
            for r in v:
                rows.append({"pipeline": label(f"nmf_{r['n']}"), "task": "8 materials (%)",
                             "ours": f"{100 * r['accuracy']:.1f} ± {100 * r['accuracy_sd']:.1f}"})
        else:
            rows.append({"pipeline": label(k), "task": "8 materials (%)",
                         "ours": f"{100 * v['mean']:.1f} ± {100 * v['sd']:.1f}"})
    two = summary["two_material"]
    if two:
        rows.append({"pipeline": label("mlp_5_8_2"), "task": "distance (mm), material (%)",
                     "ours": f"{two['rmse_mm']:.2f}, {100 * two['accuracy']:.1f}"})
    return rows


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _fig_laws(feats, cal):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    d = feats["distance_cm"].values
    dd = np.linspace(d.min(), d.max(), 50)
    for mode, colour in (("low", "tab:blue"), ("high", "tab:red")):
        f = feats["params"].sel(parameter=f"F_{mode}").values
        ax.scatter(d + np.random.default_rng(0).uniform(-0.3, 0.3, len(d)), f, s=2,
                   alpha=0.25, color=colour, label=f"{mode} peak")
        s, i = cal[f"{mode}_law"]
        ax.plot(dd, 10 ** (s * dd + i), color=colour)
        ps, pi = PAPER[f"{mode}_law"]
        ax.plot(dd, 10 ** (ps * dd + pi), color="k", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("contact distance (cm)")
    ax.set_ylabel("peak frequency (Hz)")
    ax.legend(markerscale=5)
    return fig


def _fig_tau(feats):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    m = feats["material"].values.astype(str)
    tau = feats["params"].sel(parameter="tau_low").values
    d = feats["distance_cm"].values
    for name, colour in (("wood", "tab:brown"), ("aluminium", "tab:gray")):
        sel = m == name
        if not sel.any():
            continue
        sites = np.unique(d[sel])
        mean = [tau[sel & (d == s)].mean() for s in sites]
        sd = [tau[sel & (d == s)].std() for s in sites]
        ax.errorbar(sites, 1e3 * np.array(mean), 1e3 * np.array(sd), color=colour,
                    marker="o", ms=3, capsize=2, label=name)
    ax.set_xlabel("contact distance (cm)")
    ax.set_ylabel("τ_low (ms)")
    ax.legend()
    return fig


def _fig_predictions(feats, results, names):
    """Small multiples, three to a row, so the page keeps its width (Fig. 4B)."""
    plt = _plt()
    cols = min(3, len(names))
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols, 2.8 * rows), sharex=True,
                             sharey=True, squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        r = results[name]
        f = r["folds"][0]
        y = r["y"][f.test_index]
        ax.scatter(y, f.prediction, s=2, alpha=0.3,
                   color="tab:red" if name.startswith("spiking_") else "tab:blue")
        ax.plot([8, 38], [8, 38], "k--", lw=0.8)
        ax.set_title(f"{label(name)}: {r['summary']['rmse_mm']:.2f} mm", fontsize=8)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("true (cm)")
    for ax in axes[:, 0]:
        ax.set_ylabel("predicted (cm)")
    fig.tight_layout()
    return fig


def confusion(result, n_classes: int) -> np.ndarray:
    """Confusion counts (true × predicted) over all seeds' test contacts."""
    cm = np.zeros((n_classes, n_classes), dtype=int)
    for f in result["folds"]:
        np.add.at(cm, (result["y"][f.test_index], f.prediction.astype(int)), 1)
    return cm


def _fig_confusion(result, materials):
    plt = _plt()
    cm = confusion(result, len(materials))
    frac = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
    fig, ax = plt.subplots(figsize=(6, 5))
    im = ax.imshow(frac, cmap="Blues", vmin=0, vmax=1)
    for i in range(len(materials)):
        for j in range(len(materials)):
            ax.text(j, i, f"{100 * frac[i, j]:.0f}", ha="center", va="center", fontsize=7,
                    color="w" if frac[i, j] > 0.5 else "k")
    ax.set_xticks(range(len(materials)), materials, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(materials)), materials, fontsize=8)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    fig.colorbar(im, label="fraction of true class")
    return fig


def _fig_nmf_basis(result, feats):
    plt = _plt()
    nmf = result["folds"][0].estimator.steps[0][1]  # the NMFFilterBank
    freq = feats["freq_hz"].values
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for k, comp in enumerate(nmf.components_):
        ax.plot(freq, comp / comp.max(), lw=0.8, label=f"{k + 1}")
    ax.set_xscale("log")
    ax.set_xlim(2, freq.max())
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("weight (normalised)")
    ax.legend(fontsize=6, ncol=3)
    return fig


def _fig_nmf_curve(summary):
    plt = _plt()
    curve = summary["material_accuracy"]["nmf_curve"]
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    ax.errorbar([r["n"] for r in curve], [100 * r["accuracy"] for r in curve],
                [100 * r["accuracy_sd"] for r in curve], marker="o", capsize=3, label="NMF → MLP")
    full = summary["material_accuracy"].get("mlp_spectrum_material")
    if full:
        ax.axhline(100 * full["mean"], color="k", ls="--", label="full spectrum")
    spiking = (summary.get("spiking") or {}).get("against_fft", {})
    for name, row in spiking.items():
        if row.get("neurons"):
            ax.scatter(row["neurons"], 100 * row["accuracy"], color="tab:red", zorder=3)
            ax.annotate(label(name).replace("spiking MLP, ", ""), (row["neurons"],
                        100 * row["accuracy"]), fontsize=7, xytext=(4, -10),
                        textcoords="offset points", color="tab:red")
    if spiking:
        ax.scatter([], [], color="tab:red", label="spiking (x: resonators)")
    ax.set_xlabel("filters: NMF dimension, or resonators (spiking)")
    ax.set_ylabel("8-material accuracy (%)")
    ax.legend()
    return fig
