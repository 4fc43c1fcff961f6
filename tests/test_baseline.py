"""Baselines: split discipline, the NMF filter bank, scoring."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.core.errors import SpecError
from snn_antenna.evaluation import crossval as cv
from snn_antenna.readout import baselines as bl


@settings(max_examples=30, deadline=None)
@given(reps=st.integers(2, 40), fraction=st.floats(0.05, 0.95), seed=st.integers(0, 10_000))
def test_no_repetition_is_in_both_train_and_test(reps, fraction, seed):
    # Every (material, position) has the same repetitions 0..reps-1.
    repetition = np.tile(np.arange(reps), 6)
    group = np.repeat(np.arange(6), reps)
    train, test = cv.split_by_repetition(repetition, fraction, seed)
    assert not (train & test).any() and (train | test).all()
    assert not set(repetition[train]) & set(repetition[test])
    for g in range(6):   # every class and position is on both sides
        assert train[group == g].any() and test[group == g].any()
    again = cv.split_by_repetition(repetition, fraction, seed)
    assert np.array_equal(again[1], test)


def test_nmf_filter_bank_is_a_dot_product_with_non_negative_filters():
    rng = np.random.default_rng(0)
    X = np.abs(rng.normal(size=(200, 40)))
    bank = bl.NMFFilterBank(5, random_state=0).fit(X)
    assert bank.components_.shape == (5, 40) and bank.components_.min() >= 0
    scaled = X[:3] / X[:3].max(axis=1, keepdims=True)
    W = bank.components_
    assert np.allclose(bank.transform(X[:3]), scaled @ W.T @ np.linalg.inv(W @ W.T))


def test_nmf_filter_outputs_are_the_parts_amplitudes():
    # The raw dot products of broad, overlapping basis vectors are strongly
    # correlated; unmixed by the basis's Gram matrix they give the parts' amplitudes back
    # (NMF-30 45 % -> 65 % of 8 materials on the full bench set).
    rng = np.random.default_rng(2)
    bank = bl.NMFFilterBank(4, random_state=0).fit(np.abs(rng.normal(size=(100, 30))))
    H = rng.uniform(0.1, 1, (20, 4))
    X = H @ bank.components_
    peak = X.max(axis=1, keepdims=True)
    assert np.allclose(bank.transform(X), H / peak, atol=1e-8)
    with pytest.raises(SpecError, match="non-negative"):
        bl.NMFFilterBank(5).fit(X - 1)


def test_nmf_filters_read_the_spectrum_s_shape_not_its_loudness():
    # Unscaled, the events' loudness (3x between impacts) took the NMF parts and
    # every filter output, and NMF-30 read 19 % of the 8 materials where a peak-scaled one
    # reads 36 % (quick bench set). Classes here differ only in the ratio of two lines.
    rng = np.random.default_rng(1)
    f = np.arange(60)
    def line(at):
        return np.exp(-0.5 * ((f - at) / 1.5) ** 2)
    label = rng.integers(0, 2, 400)
    shape = line(15)[None] + np.where(label[:, None] == 1, 0.6, 0.3) * line(40)[None]
    loudness = rng.uniform(1, 3, (400, 1))
    X = loudness * shape + 0.01 * np.abs(rng.normal(size=(400, 60)))
    bank = bl.NMFFilterBank(2, random_state=0).fit(X)
    out = bank.transform(X)
    assert np.allclose(out, bank.transform(X * 7.0))          # loudness does not reach it
    ratio = out[:, 1] / out[:, 0]
    lo, hi = sorted([ratio[label == 0], ratio[label == 1]], key=np.median)
    assert lo.max() < hi.min()                               # the shape does, cleanly


def test_scores_are_computed_from_predictions():
    assert cv.score("distance", np.array([10.0, 20.0]), np.array([10.3, 19.6]))["rmse_mm"] \
        == pytest.approx(10 * np.sqrt((0.09 + 0.16) / 2))
    assert cv.score("material", np.array([0, 1, 2, 2]), np.array([0, 1, 1, 2]))["accuracy"] == 0.75
    s = cv.summarise([{"accuracy": 0.5}, {"accuracy": 0.7}])
    assert s["accuracy"] == pytest.approx(0.6) and s["accuracy_sd"] == pytest.approx(0.1414, 1e-3)


def test_a_material_not_in_the_table_is_refused():
    import xarray as xr
    feats = xr.Dataset(coords={"material": ("event", ["wood", "granite"]),
                               "distance_cm": ("event", [10.0, 12.0])})
    with pytest.raises(SpecError, match="granite"):
        cv.targets_of(feats, "material", ["wood", "aluminium"])


def test_the_full_spectrum_mlp_reads_the_spectrum_s_shape_not_its_loudness():
    """A spectrum scaled by any factor reads the same material."""
    rng = np.random.default_rng(2)
    f = np.arange(80)
    width = rng.choice([1.0, 3.0], 120)                      # the material: a peak's width
    at = rng.uniform(15, 60, 120)                            # the peak moves (distance)
    X = np.exp(-0.5 * ((f[None] - at[:, None]) / width[:, None]) ** 2)
    (spectrum_mlp,) = [b for b in bl.material_baselines([]) if b.inputs == "spectrum"]
    model = spectrum_mlp.build(0).fit(X, width)
    assert np.array_equal(model.predict(X), model.predict(X * rng.uniform(0.2, 5.0, (120, 1))))


def test_a_small_training_set_trains_its_classifiers_in_more_batches_and_regressors_by_lbfgs():
    """~80 training contacts: 64-row batches would make a classifier's epoch two updates; the
    batches shrink so it holds at least MIN_BATCHES_PER_EPOCH. A regressor is trained by
    L-BFGS to convergence, and fits what Adam's epoch budget leaves unfitted. A large set
    keeps its MLPs as they are."""
    def params(model, name):
        return [v for k, v in model.get_params(deep=True).items() if k.endswith(name)]
    small = bl.sized_for(bl.classifier_pipeline(bl.Mlp(), bl.MATERIAL_HIDDEN, 0), 80)
    assert params(small, "batch_size") == [max(bl.MIN_BATCH, 80 // bl.MIN_BATCHES_PER_EPOCH)]
    assert -(-80 // params(small, "batch_size")[0]) >= bl.MIN_BATCHES_PER_EPOCH
    assert params(small, "solver") == ["adam"]
    tiny = bl.sized_for(bl.classifier_pipeline(bl.Mlp(), bl.MATERIAL_HIDDEN, 0), 20)
    assert params(tiny, "batch_size") == [bl.MIN_BATCH]
    regressor = bl.sized_for(bl.regressor_pipeline(bl.Mlp(), bl.DISTANCE_HIDDEN, 0), 80)
    assert params(regressor, "solver") == ["lbfgs"]
    assert params(regressor, "__max_iter") == [bl.LBFGS_MAX_ITER]
    for build in (bl.classifier_pipeline, bl.regressor_pipeline):
        large = bl.sized_for(build(bl.Mlp(), bl.MATERIAL_HIDDEN, 0), bl.SMALL_SET)
        assert params(large, "batch_size") == [64] and params(large, "solver") == ["adam"]
    X = np.random.default_rng(0).normal(size=(80, 3))
    fold = cv.fit_fold(bl.Baseline("m", "material", "x", lambda seed: bl.classifier_pipeline(
        bl.Mlp(max_iter=2), bl.MATERIAL_HIDDEN, seed)), X, (X[:, 0] > 0).astype(int),
        np.arange(80) < 60, np.arange(80) >= 60, 0)
    assert params(fold.estimator, "batch_size") == [bl.MIN_BATCH]
    # a smooth target on 60 contacts: a few Adam epochs leave it unfitted, L-BFGS fits it
    y = 10 + 5 * np.tanh(X[:, 0]) + 3 * X[:, 1]
    fold = cv.fit_fold(bl.Baseline("d", "distance", "x", lambda seed: bl.regressor_pipeline(
        bl.Mlp(max_iter=20), bl.DISTANCE_HIDDEN, seed)), X, y,
        np.arange(80) < 60, np.arange(80) >= 60, 0)
    assert np.sqrt(np.mean((fold.prediction - y[60:]) ** 2)) < 0.4 * np.std(y)   # Adam: 1.07
