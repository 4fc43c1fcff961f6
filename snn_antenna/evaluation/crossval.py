"""The baselines trained and tested on labelled bench events, split by repetition.

The pipelines themselves (``readout.baselines``, ``readout.spiking_decoders``) are ordinary
scikit-learn estimators that map an event's features to a decision; here they meet the ground
truth: ``targets_of`` reads each event's true distance and material (``truth.BENCH_LABELS``),
``evaluate`` fits every pipeline on the training repetitions of each seed's split and scores
it on the rest.

Splits are by repetition: the repetitions 0…R−1 are shuffled with the split's seed and
``test_fraction`` of them form the test set for every material and position, so a contact is
never in both sets and every class and position is in both. Several seeds give mean and spread.

Reproducibility. Data, splits and MLP initialisation are seeded and the fits run on
one BLAS thread, yet a fit's result still depends on which OpenBLAS kernel the CPU selects:
its summation order changes the float32 gradients in the last bits, and 300 epochs of
mini-batch training carry that to the end. Measured on the full bench set (12,799 events),
spectrum MLP distance rmse for seeds 0, 1, 2: 3.35, 2.79, 3.81 mm with the Haswell kernel
(this machine's default), 3.24, 2.79, 4.11 with OPENBLAS_CORETYPE=SandyBridge, 3.24, 2.81,
4.10 with Prescott (means 3.32, 3.38, 3.38). The spread over seeds (sd ≈ 0.5 mm, so ≈ 0.3 mm
on a 3-seed mean) is the honest interval; a README number is comparable only within it.
Repeated with one kernel (full set, twice; quick set, three times): identical numbers.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from sklearn.exceptions import ConvergenceWarning

from ..core import bounds
from ..core.errors import SpecError, check
from ..readout.baselines import (
    NMF_DIMENSIONS,
    TASKS,
    Baseline,
    Mlp,
    distance_baselines,
    inputs_of,
    material_baselines,
    parametric_material_baseline,
    two_material_baseline,
    sized_for,
)
from ..readout.spiking import SpikingBank, recording_attrs
from ..readout.spiking_decoders import mlp_baseline


@dataclass
class Evaluation:
    """How the baselines are trained and tested (keys of a study's ``[evaluation]``)."""
    seeds: list = field(default_factory=lambda: [0, 1, 2])
    test_fraction: float = 0.3
    nmf_dims: list = field(default_factory=lambda: list(NMF_DIMENSIONS))
    nmf_max_iter: int = 400
    mlp_max_iter: int = 300
    # The 8-material MLPs stop improving early and cost most per epoch, so they get their
    # own, smaller epoch budget (the study's spec says where it was measured).
    material_max_iter: int = 60
    pipelines: list = field(default_factory=lambda: list(TASKS))
    # the paper's pair for its 5-8-2 network; a lab names any two of its materials
    two_materials: list = field(default_factory=lambda: ["wood", "aluminium"])

    def __post_init__(self):
        bounds.declared(self)
        check(isinstance(self.two_materials, list) and len(self.two_materials) == 2 and
              all(isinstance(m, str) and m for m in self.two_materials) and
              self.two_materials[0] != self.two_materials[1], "two_materials",
              self.two_materials, "two different material names, e.g. [\"wood\", "
              "\"aluminium\"] (the second is the network's material output 1)")
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
        check(set(self.pipelines) <= set(TASKS), "pipelines", self.pipelines,
              f"a list of task groups out of {sorted(TASKS)}")

    @property
    def mlp(self) -> Mlp:
        return Mlp(max_iter=self.mlp_max_iter)

    @property
    def material_mlp(self) -> Mlp:
        return Mlp(max_iter=self.material_max_iter)

    def baselines(self, n_bins: int) -> list[Baseline]:
        """The FFT and parametric pipelines of the chosen task groups."""
        chosen = []
        if "distance" in self.pipelines:
            chosen += distance_baselines(n_bins, self.mlp)
        if "material" in self.pipelines:
            chosen += material_baselines(self.nmf_dims, self.material_mlp, self.nmf_max_iter)
            # the distance MLPs' epoch budget: material_max_iter was set for the 509-bin
            # spectrum's cost per epoch; on six inputs an epoch costs little, and on a small
            # recorded set it is a single batch (60 of them left it far from trained)
            chosen.append(parametric_material_baseline(self.mlp))
        if "two_material" in self.pipelines:
            chosen.append(two_material_baseline(self.mlp))
        return chosen


# -- splits ---------------------------------------------------------------------------------
def split_by_repetition(repetition: np.ndarray, test_fraction: float, seed: int
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Boolean (train, test) masks: whole repetitions go to one side."""
    check(0 < test_fraction < 1, "test_fraction", test_fraction, "a fraction in (0, 1)")
    reps = np.unique(repetition)
    check(len(reps) >= 2, "repetitions", len(reps), "at least 2 repetitions to split")
    n_test = min(len(reps) - 1, max(1, int(round(test_fraction * len(reps)))))
    test_reps = np.random.default_rng(seed).permutation(reps)[:n_test]
    test = np.isin(repetition, test_reps)
    return ~test, test


# -- evaluation -----------------------------------------------------------------------------
@dataclass
class Fold:
    """One baseline on one split: predictions for the test events and the costs."""
    seed: int
    test_index: np.ndarray
    prediction: np.ndarray
    fit_s: float
    predict_s_per_event: float
    estimator: object = field(repr=False, default=None)
    train_index: np.ndarray | None = field(repr=False, default=None)


def targets_of(features: xr.Dataset, task: str, materials: list[str]) -> np.ndarray:
    d = features["distance_cm"].values.astype(float)
    m = features["material"].values.astype(str)
    if task == "distance":
        return d
    if task == "material":
        index = {name: i for i, name in enumerate(materials)}
        unknown = sorted(set(m) - set(index))
        if unknown:
            raise SpecError("material", unknown, f"one of {materials}")
        return np.array([index[x] for x in m])
    if task == "two_material":      # materials: the pair, the second read as 1
        return np.column_stack([d, (m == materials[-1]).astype(float)])
    raise SpecError("task", task, "'distance', 'material' or 'two_material'")


def fit_fold(baseline: Baseline, X, y, train, test, seed) -> Fold:
    est = sized_for(baseline.build(seed), int(np.count_nonzero(train)))
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        # A fixed epoch budget is the design (see Mlp); its end is not a failure.
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings("ignore", message=".*batch_size.*clipped")  # tiny data sets
        est.fit(X[train], y[train])
    fit_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    pred = np.asarray(est.predict(X[test]))
    predict_s = (time.perf_counter() - t0) / max(1, int(test.sum()))
    if not np.all(np.isfinite(pred)):
        raise ArithmeticError(f"{baseline.name} predicted non-finite values")
    return Fold(seed, np.flatnonzero(test), pred, fit_s, predict_s, est, np.flatnonzero(train))


def score(task: str, y_true, y_pred) -> dict:
    """The numbers of one fold: rmse (mm) for distance, accuracy for material, both for 2."""
    if task == "distance":
        return {"rmse_mm": float(10 * np.sqrt(np.mean((y_pred - y_true) ** 2)))}
    if task == "material":
        return {"accuracy": float(np.mean(y_pred == y_true))}
    return {"rmse_mm": float(10 * np.sqrt(np.mean((y_pred[:, 0] - y_true[:, 0]) ** 2))),
            "accuracy": float(np.mean((y_pred[:, 1] > 0.5) == (y_true[:, 1] > 0.5)))}


def summarise(folds: list[dict]) -> dict:
    """Mean and standard deviation over seeds of every number in the folds' scores."""
    keys = folds[0].keys()
    out = {}
    for k in keys:
        vals = np.array([f[k] for f in folds], dtype=float)
        out[k] = float(vals.mean())
        out[f"{k}_sd"] = float(vals.std(ddof=1)) if len(vals) > 1 else 0.0
    out["n_seeds"] = len(folds)
    return out


@dataclass
class BaselineResult:
    """One baseline over every seed's split: its folds, their scores and their summary;
    ``event`` and ``y`` are the event ids and targets the folds index into."""
    baseline: Baseline
    folds: list[Fold]
    scores: list[dict]
    summary: dict
    event: np.ndarray
    y: np.ndarray

    def values(self, key: str) -> np.ndarray:
        """One score (``rmse_mm`` or ``accuracy``) per seed."""
        return np.array([s[key] for s in self.scores], dtype=float)


def evaluate(features: xr.Dataset, baselines: list[Baseline], evaluation: Evaluation,
             log=print, client=None) -> dict[str, BaselineResult]:
    """Train and test every baseline on every seed's split by repetition: in this process, or
    with a Dask ``client`` one task per (baseline, seed) on its workers. Every fit is seeded
    and runs on one BLAS thread either way, so both give the same folds; the workers only run
    them side by side (the full comparison's fits are hundreds of seconds of one core)."""
    from threadpoolctl import threadpool_limits
    from tqdm.auto import tqdm

    materials = sorted(set(features["material"].values.astype(str)))
    shared: dict = {}
    prepared = {b.name: _prepared(b, features, materials, evaluation, shared)
                for b in baselines}
    bar = tqdm(total=len(baselines) * len(evaluation.seeds), desc="baselines", unit="fit")
    if client is None:
        # One BLAS thread: on a shared machine, threads spin against other processes (the
        # material MLP ran several times slower with the default thread count).
        with threadpool_limits(1):
            done = {(b.name, seed): _fit_scored(b, *prepared[b.name][1:], seed, evaluation)
                    for b in baselines for seed in _ticking(evaluation.seeds, bar)}
    else:
        done = _evaluate_on(client, baselines, prepared, evaluation, bar)
    bar.close()
    results = {}
    for b in baselines:
        sub, _, y, _ = prepared[b.name]
        pairs = [done[b.name, seed] for seed in evaluation.seeds]
        results[b.name] = _result(b, [f for f, _ in pairs], [s for _, s in pairs], sub, y)
        log(f"  {b.name:24s} " + ", ".join(
            f"{k} {v:.4g}" for k, v in results[b.name].summary.items()
            if not k.endswith("_sd") and k != "n_seeds"))
    return results


def _ticking(seeds, bar):
    for seed in seeds:
        yield seed
        bar.update()


def _prepared(b: Baseline, features: xr.Dataset, materials: list[str], evaluation: Evaluation,
              shared: dict) -> tuple:
    """(the events ``b`` is scored on, its input matrix, targets, repetitions): the two-material
    network sees only its pair's contacts. Read-outs of the same input on the same events share
    one matrix (``shared``), so it is made, and sent to workers, once."""
    pair = b.task == "two_material"
    if pair:
        materials = list(evaluation.two_materials)
    if (b.inputs, pair) not in shared:
        # the one input and the labels, not every matrix of the features, are copied
        labels = [v for v in ("material", "distance_cm", "repetition") if v in features.data_vars]
        sub = features[[b.inputs, *labels]] if b.inputs in features.data_vars else features
        if pair:
            keep = np.isin(features["material"].values.astype(str), materials)
            sub = sub.isel(event=np.flatnonzero(keep))
        shared[b.inputs, pair] = sub, inputs_of(sub, b.inputs)
    sub, X = shared[b.inputs, pair]
    return sub, X, targets_of(sub, b.task, materials), sub["repetition"].values


def _fit_scored(b: Baseline, X, y, repetition, seed: int, evaluation: Evaluation
                ) -> tuple[Fold, dict]:
    """One baseline on one seed's split: its fold and its scores."""
    train, test = split_by_repetition(repetition, evaluation.test_fraction, seed)
    fold = fit_fold(b, X, y, train, test, seed)
    return fold, score(b.task, y[test], fold.prediction)


def _fit_task(b: Baseline, X, y, repetition, seed: int, evaluation: Evaluation):
    """``_fit_scored`` on a Dask worker, on one BLAS thread as in this process."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        return _fit_scored(b, X, y, repetition, seed, evaluation)


def _evaluate_on(client, baselines: list[Baseline], prepared: dict, evaluation: Evaluation,
                 bar) -> dict:
    """Every (baseline, seed) fit as a task on ``client``'s workers; each distinct input
    matrix is sent to the workers once."""
    from distributed import as_completed

    sent: dict = {}

    def scattered(a: np.ndarray):
        key = (id(a), a.shape)
        if key not in sent:
            sent[key] = client.scatter(a)
        return sent[key]

    futures = {}
    for b in baselines:
        _, X, y, repetition = prepared[b.name]
        X_f = scattered(X)
        for seed in evaluation.seeds:
            futures[client.submit(_fit_task, b, X_f, y, repetition, seed, evaluation,
                                  pure=False)] = (b.name, seed)
    done = {}
    for future in as_completed(futures):
        done[futures[future]] = future.result()
        bar.update()
    return done


def _result(b: Baseline, folds: list[Fold], scores: list[dict], sub: xr.Dataset, y
            ) -> BaselineResult:
    summary = summarise(scores)
    summary["fit_s"] = float(np.mean([f.fit_s for f in folds]))
    summary["predict_us_per_event"] = float(1e6 * np.mean([f.predict_s_per_event
                                                           for f in folds]))
    return BaselineResult(b, folds, scores, summary, sub["event"].values, y)


# -- array designs of the spiking read-out, scored on one split --------------------------
def run_designs(data: xr.Dataset, features: xr.Dataset, bank: SpikingBank, designs: list, *,
                run, repetitions: int, evaluation: Evaluation, log=print) -> list[dict]:
    """Each design on the events of the first ``repetitions`` repetitions: distance rmse and
    material accuracy on the first seed's split, and its cost per event. ``run(bank, counts,
    rate_hz, adc_bits, full_scale_g) -> SpikeFeatures`` runs a bank over events (the sweep
    engine's ``engine.events.run_bank``, which this stage comes before)."""
    from threadpoolctl import threadpool_limits

    subset = features.isel(event=np.flatnonzero(features["repetition"].values < repetitions))
    ids = subset["event"].values
    seed = evaluation.seeds[0]
    split = split_by_repetition(subset["repetition"].values, evaluation.test_fraction, seed)
    targets = {"distance": subset["distance_cm"].values.astype(float),
               "material": targets_of(subset, "material",
                                         sorted(set(subset["material"].values.astype(str))))}
    log(f"      array designs on {len(ids)} events (repetitions < {repetitions})")
    rows = []
    with threadpool_limits(1):   # as in evaluate
        for design in designs:
            t0 = time.perf_counter()
            f = run(design.bank(bank), data["counts"].values[ids], *recording_attrs(data))
            row = {"design": design.name, "band": design.band,
                   "change": ", ".join(f"{k} = {v}" for k, v in design.changes.items()),
                   "n_neurons": design.band_of(bank).n_neurons,
                   "wall_us_per_event": 1e6 * (time.perf_counter() - t0) / len(ids),
                   "neuron_steps_per_event": f.neuron_steps / len(ids)}
            row.update(_design_scores(f.matrix().astype(np.float32), targets, split,
                                      evaluation, seed))
            log(f"      {design.name:22s} {row['n_neurons']:3d} neurons: "
                f"{row['distance_rmse_mm']:.2f} mm, {100 * row['material_accuracy']:.1f} %, "
                f"{row['wall_us_per_event']:.0f} µs/event")
            rows.append(row)
    return rows


def _design_scores(X, targets: dict, split, evaluation: Evaluation, seed: int) -> dict:
    train, test = split
    out = {}
    for task, key in (("distance", "distance_rmse_mm"), ("material", "material_accuracy")):
        y = targets[task]
        base = mlp_baseline(f"design_{task}", task, "spiking", evaluation)
        fold = fit_fold(base, X, y, train, test, seed)
        out[key] = next(iter(score(task, y[test], fold.prediction).values()))
    return out
