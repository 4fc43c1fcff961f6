"""The coder comparison's table: one row per coder × size × read-out, its numbers recomputed
from the run's per-split results, and the ceiling of a coded input computed from the coding."""
import numpy as np
import pytest
import xarray as xr

from snn_antenna.evaluation import crossval as cv
from snn_antenna.evaluation.comparison import Comparison, coder_rows
from snn_antenna.readout import baselines as bl
from snn_antenna.readout.spiking import Band, SpikingBank, coded_features
from snn_antenna.readout.spiking_decoders import (
    CODER_READOUTS,
    ceiling_input,
    coder_baselines,
    coder_input,
)

LABELS, SIZES = ("square", "delta"), (4, 8)


def _features(seed: int = 0) -> xr.Dataset:
    """3 materials × 4 sites × 6 repetitions; each input carries the material with its own
    noise, so the read-outs score differently."""
    rng = np.random.default_rng(seed)
    material = np.repeat(["a", "b", "c"], 24)
    repetition = np.tile(np.arange(6), 12)
    y = np.unique(material, return_inverse=True)[1]
    ds = xr.Dataset(coords={"event": np.arange(72), "material": ("event", material),
                            "repetition": ("event", repetition),
                            "distance_cm": ("event",
                                            np.tile(np.repeat([10.0, 20, 30, 40], 6), 3))})
    names = ["spectrum"] + [ceiling_input(lab, n) for lab in LABELS for n in SIZES] + [
        coder_input(lab, n, r) for lab in LABELS for n in SIZES for r in CODER_READOUTS]
    for k, name in enumerate(names):
        x = rng.normal(0, 0.5 + 0.3 * (k % 4), (72, 5))
        x[:, 0] += y
        ds[name] = (("event", f"{name}_feature"), x.astype(np.float32))
    return ds


@pytest.fixture(scope="module")
def compared():
    feats = _features()
    evaluation = cv.Evaluation(seeds=[0, 1, 2], material_max_iter=30, nmf_dims=[])
    fft = bl.material_baselines([], evaluation.material_mlp)[0]
    chosen = [fft, *coder_baselines(LABELS, SIZES, evaluation)]
    results = cv.evaluate(feats, chosen, evaluation, log=lambda *_: None)
    costs = {f"coder_{lab}_{n}": {"features_us_per_event": 100.0 * n + (lab == "delta"),
                                  "best_of": 3} for lab in LABELS for n in SIZES}
    cmp = Comparison(feats, {}, results, {}, {"fft": {"features_us_per_event": 50.0}}, {},
                     coders={"coders": {lab: {"coder": lab} for lab in LABELS},
                             "sizes": list(SIZES), "costs": costs})
    return cmp, results


def test_one_row_per_coder_size_and_readout(compared):
    cmp, _ = compared
    rows = cmp.coder_table()
    assert {(r["coder"], r["resonators"], r["readout"]) for r in rows} == {
        (lab, n, r) for lab in LABELS for n in SIZES for r in CODER_READOUTS}
    text = coder_rows({"spiking": {"coders": rows}})
    assert len(text) == len(rows) and all(t["n"] == 3 for t in text)


def test_numbers_come_from_the_runs_results(compared):
    cmp, results = compared
    fft = results["mlp_spectrum_material"].values("accuracy")
    for row in cmp.coder_table():
        acc = results[coder_input(row["coder"], row["resonators"], row["readout"])
                      ].values("accuracy")
        top = results[ceiling_input(row["coder"], row["resonators"])].values("accuracy")
        assert row["accuracy"]["mean"] == pytest.approx(acc.mean())
        assert row["accuracy"]["n"] == len(acc) == 3
        assert row["of_fft_mlp"]["mean"] == pytest.approx(np.mean(acc / fft))
        assert row["ceiling"]["mean"] == pytest.approx(top.mean())
        assert row["lost_to_resonators"]["mean"] == pytest.approx(np.mean(top - acc))
        assert row["lost_to_coding"]["mean"] == pytest.approx(np.mean(fft - top))
        assert row["lost_to_resonators"]["low"] <= row["lost_to_resonators"]["mean"]
        assert row["cost_of_fft"] == pytest.approx(
            (100.0 * row["resonators"] + (row["coder"] == "delta")) / 50.0)
        assert row["cost_best_of"] == 3


def test_ceiling_features_are_the_coded_inputs_own():
    """The ceiling counts a coded channel's half-cycles, mean |current| and value changes
    per time bin: for a steady ring through the square wave, known numbers."""
    rate, n = 2000.0, 1000
    t = np.arange(n) / rate
    g = 0.5 * np.sin(2 * np.pi * 100 * t)                  # 100 Hz, well above the noise
    counts = 512 + np.stack([g, 0.2 * g], axis=1) / (18.0 / 512)   # ADC counts, 2 axes
    band = Band(n_neurons=1, band_hz=(100.0, 100.0), coder_amplitude=0.2, threshold_g=0.01,
                lowpass_hz=400.0, highpass_hz=20.0, filter_order=4)
    bank = SpikingBank(bands={"ch": band}, duration_s=0.5, bin_edges_s=(0.25,))
    f = coded_features(bank, counts[None], rate, 10, 18.0)
    onsets, level, changes = f.reshape(1, 2, 3)[0, 1]       # the second bin: steady state
    # 100 Hz over 0.25 s: 25 cycles, two half-cycles each, in 500 samples
    assert onsets * 500 == pytest.approx(50, abs=1)
    assert level == pytest.approx(1.0, abs=0.1)             # |±amplitude| / amplitude
    assert changes * 500 == pytest.approx(50, abs=1)
    delta = SpikingBank(bands={"ch": Band(**{**band.__dict__, "coder": "delta",
                                             "coder_options": {"levels": 4, "step_g": 0.1}})},
                        duration_s=0.5, bin_edges_s=(0.25,))
    more = coded_features(delta, counts[None], rate, 10, 18.0).reshape(1, 2, 3)[0, 1]
    assert more[2] > 2 * changes          # a staircase changes at every level it crosses
