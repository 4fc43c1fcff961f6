"""The read-outs' fits on Dask workers give the folds of the fits in this process: every fit is
seeded and runs on one BLAS thread, the workers only run them side by side."""
import numpy as np
import pytest
import xarray as xr

from snn_antenna.evaluation import crossval as cv


def _features(seed: int = 0) -> xr.Dataset:
    """4 materials (wood, aluminium among them) × 3 sites × 6 repetitions; a spectrum whose
    peak bin carries the material and the site, and parametric features."""
    rng = np.random.default_rng(seed)
    material = np.repeat(["wood", "aluminium", "brass", "pvc"], 18)
    y = np.unique(material, return_inverse=True)[1]
    site = np.tile(np.repeat([0, 1, 2], 6), 4)
    spectrum = np.abs(rng.normal(0.1, 0.05, (72, 30)))
    spectrum[np.arange(72), 3 * y + site] += 1.0
    params = np.abs(rng.normal(1.0, 0.1, (72, 6))) + y[:, None] + site[:, None]
    return xr.Dataset(
        {"spectrum": (("event", "freq_hz"), spectrum.astype(np.float32)),
         "params": (("event", "parameter"), params.astype(np.float32))},
        coords={"event": np.arange(72), "material": ("event", material),
                "repetition": ("event", np.tile(np.arange(6), 12)),
                "distance_cm": ("event", 10.0 + 5 * site)})


EVALUATION = cv.Evaluation(seeds=[0, 1], nmf_dims=[2, 3], nmf_max_iter=50, mlp_max_iter=10,
                           material_max_iter=10)


def _quiet(*_):
    pass


@pytest.fixture(scope="module")
def evaluated():
    feats = _features()
    chosen = EVALUATION.baselines(feats.sizes["freq_hz"])
    return chosen, EVALUATION, cv.evaluate(feats, chosen, EVALUATION, _quiet)


@pytest.mark.slow    # a local Dask cluster (the default suite's Dask checks: test_event_engine.py)
def test_workers_give_the_folds_of_this_process(evaluated):
    from snn_antenna.engine.executor import dask_client

    chosen, evaluation, here = evaluated
    with dask_client(workers=2) as client:
        there = cv.evaluate(_features(), chosen, evaluation, _quiet, client)
    assert list(there) == [b.name for b in chosen]          # the baselines' order
    for name, result in here.items():
        other = there[name]
        assert [f.seed for f in other.folds] == list(evaluation.seeds)
        assert other.scores == result.scores, name
        for a, b in zip(result.folds, other.folds):
            assert np.array_equal(a.test_index, b.test_index)
            assert np.array_equal(a.prediction, b.prediction), name
        assert np.array_equal(other.event, result.event) and np.array_equal(other.y, result.y)


def test_every_read_out_is_scored_on_its_own_contacts(evaluated):
    _, evaluation, here = evaluated
    pair = here["mlp_5_8_2"]
    # the two-material network sees only its pair's contacts, every other read-out all of them
    assert len(pair.event) == 36 and len(here["nmf_3"].event) == 72
    for name, result in here.items():
        for seed, fold in zip(evaluation.seeds, result.folds):
            _, test = cv.split_by_repetition(
                _features()["repetition"].values[result.event], evaluation.test_fraction, seed)
            assert np.array_equal(fold.test_index, np.flatnonzero(test)), name
