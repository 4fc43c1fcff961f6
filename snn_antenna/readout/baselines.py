"""The paper's non-spiking read-outs as scikit-learn pipelines (how they are trained and
tested on labelled events is ``evaluation.crossval``).

Inputs are the event features of ``events.py``: the amplitude spectrum (509 bins of 1 Hz by
default) and the six parametric features (F, A, τ of the low and high mode). Each pipeline is
an ordinary scikit-learn estimator (column selection, scaling, NMF, MLP), so it can be
cross-validated or reused with the tools a user already knows.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from collections.abc import Callable

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.compose import TransformedTargetRegressor
from sklearn.decomposition import NMF
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LinearRegression
from sklearn.neural_network import MLPClassifier, MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import FunctionTransformer, StandardScaler

from ..core import bounds
from ..core.errors import SpecError, check
from .events import PARAMETERS

NMF_DIMENSIONS = (3, 5, 9, 15, 30, 45, 60)
# The paper's hidden layers: 20-5 for distance, 51 for the eight materials, 8 for its
# two-output (distance, wood/aluminium) network.
DISTANCE_HIDDEN = (20, 5)
MATERIAL_HIDDEN = (51,)
TWO_MATERIAL_HIDDEN = (8,)
TASKS = ("distance", "material", "two_material")


def columns(index) -> FunctionTransformer:
    """Select columns of X (a list of indices or a slice) as a pipeline step."""
    return FunctionTransformer(_take, kw_args={"index": index})


def _take(X, index):
    return np.asarray(X)[:, index]


class NMFFilterBank(TransformerMixin, BaseEstimator):
    """NMF basis vectors used as band-pass filters (the paper's Fig. 7A).

    ``fit`` learns ``n_components`` non-negative spectra with scikit-learn's NMF (on at most
    ``max_fit_samples`` rows, drawn with ``random_state``, to bound its cost); ``transform``
    is, as in the paper, the dot product of each spectrum with each basis vector, a fixed
    linear filter bank rather than NMF's per-sample optimisation. The filter outputs are then
    unmixed by the inverse of the basis's Gram matrix (W Wᵀ)⁻¹, a fixed linear map: broad,
    overlapping basis vectors give strongly correlated outputs, and the unmixed ones are the
    least-squares amplitudes of the parts (X ≈ H W gives H back), the same information
    conditioned for the MLP. On the full bench set (12,799 events, split by repetition,
    seed 0, 30 parts, 60 epochs) that took NMF-30 from 45 % to 65 % (72 % at 300 epochs;
    NMF's own per-sample activations 69 %).

    Each spectrum is first scaled to its own peak (fit and transform alike; it uses that
    event's spectrum only). Unscaled, the peak amplitude varies 3× between events (impact
    strength, distance) and is common to every filter's output, so the basis spent its parts
    on the loudness and the filter outputs on one shared factor: on the quick bench set
    (1,280 events, split by repetition, 30 parts, the 51-hidden MLP) the 8-material accuracy
    reads 19 % unscaled and 36 % scaled at 60 epochs, 22 % and 40 % at 300.
    """

    def __init__(self, n_components: int = 9, max_iter: int = 400,
                 max_fit_samples: int = 3000, random_state=None):
        self.n_components = n_components
        self.max_iter = max_iter
        self.max_fit_samples = max_fit_samples
        self.random_state = random_state

    def fit(self, X, y=None):
        bounds.declared(self, **self.get_params())
        X = np.asarray(X, dtype=float)
        check(X.ndim == 2 and len(X) >= 1, "X", f"shape {X.shape}",
              "amplitude spectra, one row per event")
        bounds.integer("max_iter", self.max_iter, 1, 1_000_000)
        bounds.integer("max_fit_samples", self.max_fit_samples, 1, 10**9)
        if self.random_state is not None:
            bounds.seed("random_state", self.random_state)
        check(isinstance(self.n_components, int) and 1 <= self.n_components <= X.shape[1],
              "n_components", self.n_components, f"an integer in [1, {X.shape[1]}]")
        check(np.all(np.isfinite(X)) and X.min() >= 0, "X", "negative or non-finite values",
              "non-negative amplitude spectra")
        X = peak_scaled(X)
        rng = np.random.default_rng(self.random_state)
        rows = rng.permutation(len(X))[:self.max_fit_samples]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            self.nmf_ = NMF(n_components=self.n_components, init="nndsvda",
                            max_iter=self.max_iter, random_state=self.random_state).fit(X[rows])
        self.components_ = self.nmf_.components_
        self.unmix_ = np.linalg.pinv(self.components_ @ self.components_.T)
        return self

    def transform(self, X):
        return peak_scaled(np.asarray(X, dtype=float)) @ self.components_.T @ self.unmix_


def band_means(spectra, width: int) -> np.ndarray:
    """Each row's bins averaged in consecutive bands of ``width`` (a remainder dropped): a
    spectrum at a tenth of the resolution for ``width`` 10. Taking every 10th bin instead
    misses a peak narrower than 10 bins: on a lab's rod whose low peak moves with distance
    (``tests/lab_antenna.py``, 2 kHz, quick profile) the distance MLP erred by 32 mm on every
    10th bin and 5.1 mm on 10-bin bands; on the quick bench set 6.3 and 6.8 mm."""
    spectra = np.asarray(spectra, dtype=float)
    n = spectra.shape[1] // width * width
    return spectra[:, :n].reshape(len(spectra), -1, width).mean(axis=2)


def peak_scaled(spectra: np.ndarray) -> np.ndarray:
    """Each row divided by its largest value (an all-zero row stays zero)."""
    peak = spectra.max(axis=1, keepdims=True)
    return spectra / np.where(peak > 0, peak, 1.0)


def _param(*names) -> list[int]:
    return [PARAMETERS.index(n) for n in names]


@dataclass
class Mlp:
    """MLP settings shared by every pipeline (scikit-learn's names and meaning).

    No early stopping: on the bench data it (10 % held out, 20 epochs' patience) stopped the
    spectrum MLP at about half the epochs with 1.5× the error. Mini-batches of 64 in float32:
    measured on the full bench spectra, 3.5 mm in 9 s against 5.2 mm in 7 s with batches of
    256 (training ends when the loss stops improving, scikit-learn's ``tol``).
    """
    max_iter: int = 300
    batch_size: int = 64
    learning_rate_init: float = 1e-3
    alpha: float = 1e-4
    early_stopping: bool = False

    def __post_init__(self):
        bounds.declared(self)
        bounds.integer("max_iter", self.max_iter, 1, 1_000_000)
        bounds.integer("batch_size", self.batch_size, 1, 1_000_000)
        bounds.number("learning_rate_init", self.learning_rate_init, 0.0, 10.0, lo_open=True)
        bounds.number("alpha", self.alpha, 0.0, 1e6)

    def regressor(self, hidden, seed) -> MLPRegressor:
        return MLPRegressor(hidden_layer_sizes=tuple(hidden), random_state=seed, **self.__dict__)

    def classifier(self, hidden, seed) -> MLPClassifier:
        return MLPClassifier(hidden_layer_sizes=tuple(hidden), random_state=seed, **self.__dict__)


# The MLPs' Adam settings and epoch budgets (``Mlp``, a study's ``material_max_iter``) were
# measured on sets of many mini-batches per epoch (the quick bench set's ~900 training
# contacts make 14). On a lab's small recorded set (~50-80 training contacts):
# - a classifier's 64-contact batches make an epoch two updates, a fifth of the training the
#   budget stands for; smaller batches restore the updates (``MIN_BATCHES_PER_EPOCH``);
# - a regressor's budget ends far from a fit even so: on a lab's rod (``tests/lab_antenna.py``,
#   2 kHz, quick profile) the low band's spiking distance MLP erred by 29.5 mm on its own
#   training contacts. scikit-learn's advice for small sets is its full-batch L-BFGS solver,
#   run to convergence: the same MLP then fits its training contacts to 0.4 mm and reads the
#   test contacts to 8.8 mm (31 mm with Adam). The classifiers stay with Adam: L-BFGS fitted
#   them too, and read the tuned bank's rate, latency and time bins together at 83 % where
#   Adam reads 92 %.
# Sets of SMALL_SET rows or more keep their MLPs as they are. On the quick bench set two
# regressors train on fewer (``snn-antenna run studies/baseline_comparison.toml --quick``):
# the two-material network (its pair's ~220 contacts: 6.8 → 5.6 mm, 55 → 60 %) and the array
# design low_8's distance MLP (~360: 7.0 → 4.3 mm).
SMALL_SET = 512
MIN_BATCHES_PER_EPOCH = 8
MIN_BATCH = 8
LBFGS_MAX_ITER = 500


def sized_for(estimator, n_train: int):
    """``estimator`` for a training set of ``n_train`` rows: below ``SMALL_SET``, every MLP
    regressor trained by L-BFGS (at most ``LBFGS_MAX_ITER`` iterations) and every other
    MLP's ``batch_size`` cut so an epoch holds at least ``MIN_BATCHES_PER_EPOCH`` batches (of
    at least ``MIN_BATCH`` rows); a larger set keeps its MLPs as they are."""
    if n_train >= SMALL_SET:
        return estimator
    params = estimator.get_params(deep=True)
    floor = max(MIN_BATCH, n_train // MIN_BATCHES_PER_EPOCH)
    changes = {}
    for key, value in params.items():
        name = key.split("__")[-1]
        if name not in ("solver", "batch_size"):
            continue
        prefix = key[:-len(name)]
        mlp = params[prefix[:-2]] if prefix else estimator
        if isinstance(mlp, MLPRegressor) and name == "solver" and value != "lbfgs":
            changes.update({key: "lbfgs", prefix + "max_iter": LBFGS_MAX_ITER})
        elif not isinstance(mlp, MLPRegressor) and name == "batch_size" \
                and isinstance(value, int) and value > floor:
            changes[key] = floor
    return estimator.set_params(**changes) if changes else estimator


@dataclass
class Baseline:
    """A named pipeline: which input it reads, what it predicts, how to build it."""
    name: str
    task: str            # "distance", "material" or "two_material"
    inputs: str          # "spectrum" or "params"
    build: Callable[[int], object]   # seed -> unfitted estimator
    description: str = ""
    paper: float | None = None       # the paper's number for this pipeline (mm or fraction)


def regressor_pipeline(mlp: Mlp, hidden, seed: int, *steps) -> TransformedTargetRegressor:
    """``steps`` (e.g. a column selection), scaled inputs, an MLP regressor; the target is
    scaled too, so the MLP learns at one rate across cm and %."""
    return TransformedTargetRegressor(
        make_pipeline(*steps, StandardScaler(), mlp.regressor(hidden, seed)),
        transformer=StandardScaler())


def classifier_pipeline(mlp: Mlp, hidden, seed: int, *steps):
    """``steps`` (e.g. an NMF filter bank), scaled inputs, an MLP classifier."""
    return make_pipeline(*steps, StandardScaler(), mlp.classifier(hidden, seed))


def spectrum_regressor(mlp: Mlp, hidden, seed: int, select) -> TransformedTargetRegressor:
    """``select``'s bins of each spectrum scaled to its own peak and centred, an MLP
    regressor, the target scaled. The bins keep one common scale: standardising each bin to
    unit variance lifts the bins where nothing rings (noise) to the weight of the ringing
    ones, and the loudness every bin shares (impact, distance) hides where the peak sits. Measured
    with the quick profile's 2 splits (20-5 MLP, 200 epochs): on the bench set (``snn-antenna run
    studies/baseline_comparison.toml --quick``'s spectra, ~900 training contacts) 9.2 → 4.2 mm
    (full spectrum), 12.1 → 6.8 (every 10th bin → 10-bin bands), 10.1 → 4.0 (lower half); on a
    lab's rod whose peak moves with distance (``tests/lab_antenna.py``, 2 kHz, ~80 training
    contacts) 21.0 → 3.1 mm for the full spectrum, where the peak frequency's one-feature read-out
    errs by 5.4 mm."""
    return TransformedTargetRegressor(
        make_pipeline(select, FunctionTransformer(peak_scaled), StandardScaler(with_std=False),
                      mlp.regressor(hidden, seed)),
        transformer=StandardScaler())


def distance_baselines(n_bins: int, mlp: Mlp = Mlp()) -> list[Baseline]:
    def scaled_mlp(select):
        return lambda seed: regressor_pipeline(mlp, DISTANCE_HIDDEN, seed, select)

    def spectrum_mlp(select):
        return lambda seed: spectrum_regressor(mlp, DISTANCE_HIDDEN, seed, select)
    return [
        Baseline("linear_low_peak", "distance", "params",
                 lambda seed: make_pipeline(columns(_param("F_low")),
                                            FunctionTransformer(np.log10), LinearRegression()),
                 "linear regression of distance on log10 of the low peak frequency", 6.2),
        Baseline("mlp_parametric", "distance", "params",
                 scaled_mlp(columns(_param("F_low", "A_low", "F_high", "A_high"))),
                 "MLP 4-20-5-1 on both peaks' frequency and amplitude", 2.93),
        Baseline("mlp_spectrum", "distance", "spectrum", spectrum_mlp(columns(slice(None))),
                 f"MLP {n_bins}-20-5-1 on the full amplitude spectrum scaled to its peak", 1.71),
        Baseline("mlp_spectrum_sub10", "distance", "spectrum",
                 spectrum_mlp(FunctionTransformer(band_means, kw_args={"width": 10})),
                 "MLP on the spectrum in bands of 10 bins (a tenth of the input), scaled to "
                 "its peak", 1.71),
        Baseline("mlp_low_half", "distance", "spectrum",
                 spectrum_mlp(columns(slice(0, n_bins // 2))),
                 "MLP on the lower half of the spectrum scaled to its peak (half the input)",
                 2.93),
    ]


def material_baselines(nmf_dims=NMF_DIMENSIONS, mlp: Mlp = Mlp(),
                       nmf_max_iter: int = 400) -> list[Baseline]:
    """The full-spectrum MLP and the NMF filter banks, each on spectra scaled to their own
    peak (as ``NMFFilterBank``): the material is in the spectrum's shape, and the loudness
    every bin shares varies with the impact and the distance. Unscaled, the per-bin
    standardisation lets that common factor and the bins where nothing rings (noise scaled
    up to unit variance) fill the inputs: on a lab's rod whose materials differ only in
    decay time and whose peak moves with distance (``tests/lab_antenna.py``, 2 kHz, 4 × 4 ×
    10, quick profile, ~80 training contacts) the MLP read 64 % unscaled and 100 % scaled,
    where a one-feature decay read-out reads 95 %; on the quick bench set 75 % and 77 %
    (``benchmarks/bench_lab_readouts.py``, 2 splits)."""
    out = [Baseline("mlp_spectrum_material", "material", "spectrum",
                    lambda seed: classifier_pipeline(mlp, MATERIAL_HIDDEN, seed,
                                                     FunctionTransformer(peak_scaled)),
                    "MLP with 51 hidden on the full spectrum scaled to its peak, 8 materials",
                    0.942)]
    for n in nmf_dims:
        out.append(Baseline(
            f"nmf_{n}", "material", "spectrum",
            lambda seed, n=n: classifier_pipeline(
                mlp, MATERIAL_HIDDEN, seed, NMFFilterBank(n, nmf_max_iter, random_state=seed)),
            f"NMF to {n} band-pass filters, then the 51-hidden MLP",
            0.86 if n == 30 else None))
    return out


def parametric_material_baseline(mlp: Mlp = Mlp()) -> Baseline:
    """The 51-hidden MLP on log of both peaks' F, A and τ: the decay the paper's fit reads,
    for an antenna whose materials differ in their decay (a decay time and an amplitude are
    read on a log scale: a material multiplies them)."""
    return Baseline("mlp_parametric_material", "material", "params",
                    lambda seed: classifier_pipeline(mlp, MATERIAL_HIDDEN, seed,
                                                     FunctionTransformer(_log_positive)),
                    "MLP with 51 hidden on log of both peaks' frequency, amplitude and decay "
                    "time")


def _log_positive(X):
    """log of parametric features (each > 0 where an event was processed)."""
    return np.log(np.maximum(np.asarray(X, dtype=float), 1e-12))


def two_material_baseline(mlp: Mlp = Mlp()) -> Baseline:
    """The paper's 5-8-2 network: parametric inputs, outputs distance and material."""
    return Baseline(
        "mlp_5_8_2", "two_material", "params",
        lambda seed: regressor_pipeline(
            mlp, TWO_MATERIAL_HIDDEN, seed,
            columns(_param("A_low", "F_low", "A_high", "F_high", "tau_low"))),
        "MLP 5-8-2 (A, F of both modes and τ_low) → distance and wood/aluminium")


def inputs_of(features: xr.Dataset, kind: str) -> np.ndarray:
    """The input matrix ``kind``: ``"spectrum"``, ``"params"`` or any other (event, feature)
    variable of the features (e.g. spiking features added by a study)."""
    if kind in features.data_vars and features[kind].ndim == 2:
        return np.asarray(features[kind].values, dtype=np.float32)
    raise SpecError("inputs", kind, f"one of the feature matrices "
                                    f"{[v for v in features.data_vars if features[v].ndim == 2]}")


__all__ = ["Baseline", "Mlp", "distance_baselines", "material_baselines",
           "parametric_material_baseline",
           "two_material_baseline", "regressor_pipeline", "classifier_pipeline", "inputs_of",
           "columns", "NMF_DIMENSIONS", "NMFFilterBank", "TASKS", "sized_for", "SMALL_SET"]
