"""The baseline comparison study: a tiny run end to end; its numbers are the computed ones.

The default suite runs the FFT/parametric half of the study (``fft_run``: no ``[spiking]``
table, 10 s); the whole study with its spiking bank at the bands' own steps (``tiny_run``,
``tiny_quick_run``: minutes of Brian2 at 0.005 ms) runs under ``-m slow``. The spiking read-out's
parts are covered in the default suite by test_event_engine, test_spiking and test_blind."""
import json

import numpy as np
import pytest

from snn_antenna.core import spec as specs
from snn_antenna.cli import main
from snn_antenna.core.errors import SpecError
from snn_antenna.readout.spiking_decoders import TRAINING_FREE
from snn_antenna.studies import baseline_comparison as study
from snn_antenna.studies.contract import Options

SPEC = "studies/baseline_comparison.toml"
TINY = ["stimulus.materials=['wood','aluminium','brass']",
        "stimulus.positions_cm=[10.0,20.0,30.0]",
        "stimulus.repetitions=6", "stimulus.n_jobs=1", "evaluation.seeds=[0,1]",
        "evaluation.nmf_dims=[3,24,30]", "evaluation.mlp_max_iter=30",
        "evaluation.nmf_max_iter=50",
        "evaluation.material_max_iter=30", "spiking.bank.target=numpy", "spiking.workers=1",
        "spiking.bank.duration_s=0.3",
        "spiking.design_repetitions=3",
        "spiking.cost_sample_events=6",
        "spiking.designs=[{name='low_8', band='low', n_neurons=8}]",
        "spiking.tuned.curve=[4,8]", "spiking.tuned.tuning.n_resonators=4",
        "spiking.tuned.curve_repetitions=3", "spiking.tuned.calibration_repetitions=2",
        "spiking.tuned.duration_s=0.3", "spiking.tuned.bin_edges_s=[0.1,0.2]",
        "spiking.tuned.coder_sizes=[4]", "spiking.tuned.cost_repeats=1"]

# The shipped chosen bank at a few resonators (its design and point otherwise), on numpy
CHOSEN_SMALL = ["chosen_bank.placement.repetitions=2", "chosen_bank.point.channels=2",
                "chosen_bank.point.per_channel=1", "chosen_bank.point.gain_levels=1",
                "chosen_bank.point.low_resonators=4", "chosen_bank.design.target=numpy",
                "chosen_bank.design.duration_s=0.3", "chosen_bank.design.bin_edges_s=[0.1,0.2]"]
TINY += CHOSEN_SMALL


@pytest.fixture(scope="module")
def fft_run(tmp_path_factory):
    """The study without its spiking read-out: the FFT and parametric pipelines only."""
    out = tmp_path_factory.mktemp("baseline_fft")
    spec = specs.load(SPEC, [o for o in TINY if not o.startswith("spiking.")]
                      + [f"stimulus.cache_dir={out / 'cache'}"])
    del spec["spiking"], spec["chosen_bank"]
    summary = study.run(study.plan(spec), out / "report", log=lambda *_: None)
    return out / "report", summary


@pytest.fixture(scope="module")
def chosen_run(tmp_path_factory):
    """The FFT half of the study with the chosen bank beside it."""
    out = tmp_path_factory.mktemp("baseline_chosen")
    spec = specs.load(SPEC, [o for o in TINY if not o.startswith("spiking.")]
                      + [f"stimulus.cache_dir={out / 'cache'}"])
    del spec["spiking"]
    summary = study.run(study.plan(spec), out / "report", log=lambda *_: None)
    return out / "report", summary


def test_the_chosen_bank_is_scored_beside_the_fft_on_the_same_splits(chosen_run):
    """The chosen bank's accuracy and distance, their ratio and difference to the FFT
    pipeline's, are the ones its predictions give split by split; placed on contacts of
    another seed; its section, table and figure are in the report."""
    out, summary = chosen_run
    c = summary["chosen_bank"]
    preds = json.loads((out / "predictions.json").read_text())

    def per_split(name, score):
        return np.array([score(np.array(f["true"]), np.array(f["predicted"]))
                         for f in preds["folds"][name]])
    accuracy = lambda t, p: np.mean(t == p)                       # noqa: E731
    rmse = lambda t, p: 10 * np.sqrt(np.mean((t - p) ** 2))       # noqa: E731 (cm -> mm)
    acc = per_split("spiking_chosen", accuracy)
    fft = per_split("mlp_spectrum_material", accuracy)
    assert c["accuracy"]["mean"] == pytest.approx(acc.mean())
    assert c["accuracy_to_fft_mlp"]["mean"] == pytest.approx(np.mean(acc / fft))
    assert c["accuracy_minus_fft_mlp"]["mean"] == pytest.approx(np.mean(acc - fft))
    d = per_split("spiking_chosen_distance", rmse)
    d_fft = per_split("mlp_spectrum", rmse)
    assert c["distance_rmse_mm"]["mean"] == pytest.approx(d.mean(), rel=1e-6)
    assert c["distance_rmse_minus_fft_mlp"]["mean"] == pytest.approx(np.mean(d - d_fft),
                                                                       rel=1e-6)
    assert c["placement"]["seed"] != summary["provenance"]["spec"]["seed"]
    assert c["resonators"] == 2 + 4 and c["cost"]["ratio_to_fft"] > 0
    assert "spiking_chosen" in summary["cost_us_per_event"]
    page = (out / "report.html").read_text()
    assert "The chosen bank beside the FFT" in page and 'alt="chosen_bank_on_spectra"' in page
    assert (out / "chosen_bank_on_spectra.png").is_file()


@pytest.fixture(params=["fft_run", pytest.param("tiny_run", marks=pytest.mark.slow)])
def any_run(request):
    return request.getfixturevalue(request.param)


@pytest.fixture(scope="module")
def bench_cache(tmp_path_factory):
    """One bench cache for both runs: the quick run reuses the data the full run generated
    when its stimulus is the same (the cache key covers the spec, so a differing one is not)."""
    return tmp_path_factory.mktemp("baseline_cache")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory, bench_cache):
    out = tmp_path_factory.mktemp("baseline")
    spec = specs.load(SPEC, TINY + [f"stimulus.cache_dir={bench_cache}"])
    summary = study.run(study.plan(spec), out / "report", log=lambda *_: None)
    return out / "report", summary


@pytest.fixture(scope="module")
def tiny_quick_run(tmp_path_factory, bench_cache):
    """The spec's quick profile on the same tiny data (its own NMF sizes and designs)."""
    out = tmp_path_factory.mktemp("baseline_quick")
    keep = [o for o in TINY if not o.startswith(("evaluation.nmf_dims", "spiking.designs"))]
    spec = specs.load(SPEC, keep + [f"stimulus.cache_dir={bench_cache}"], quick=True)
    summary = study.run(study.plan(spec), out / "report", Options(quick=True),
                        log=lambda *_: None)
    return out / "report", summary


def test_the_quick_profile_changes_values_not_the_kind_of_spec():
    """Fast twin of the slow end-to-end check below: the quick profile sets only keys the
    full spec has, so both profiles run the same parts and report the same quantities."""
    full, quick = specs.load(SPEC), specs.load(SPEC, quick=True)

    def keys(tree, prefix=""):
        return {prefix + k for k, v in tree.items()} | {
            x for k, v in tree.items() if isinstance(v, dict) for x in keys(v, prefix + k + ".")}

    assert keys(quick) == keys(full)
    assert quick != full


@pytest.mark.slow
def test_quick_and_full_profiles_report_the_same_kinds_of_numbers(tiny_run, tiny_quick_run):
    (full_dir, _), (quick_dir, _) = tiny_run, tiny_quick_run
    full = json.loads((full_dir / "summary.json").read_text())
    quick = json.loads((quick_dir / "summary.json").read_text())
    assert (full["quick"], quick["quick"]) == (False, True)
    for key in ("calibrated", "predicted"):
        assert [r["quantity"] for r in quick[key]] == [r["quantity"] for r in full[key]], key
    assert set(quick["spiking"]["against_fft"]) == set(full["spiking"]["against_fft"])
    assert set(quick) == set(full)
    assert "Quick profile" in (quick_dir / "report.html").read_text()
    assert "Quick profile" not in (full_dir / "report.html").read_text()


def test_fft_half_writes_its_report_and_keys(fft_run):
    out, _ = fft_run
    for name in ("report.html", "summary.json", "fig2c_frequency_laws.png",
                 "fig4b_predicted_distance.png", "fig6d_confusion.png", "fig7a_nmf_basis.png",
                 "fig7b_nmf_accuracy.png", "predictions.json", "pareto_cost_accuracy.png"):
        assert (out / name).is_file(), name
    stored = json.loads((out / "summary.json").read_text())
    for key in ("calibration", "distance_rmse_mm", "material_accuracy", "two_material", "timing",
                "cost_us_per_event"):
        assert key in stored
    assert not stored.get("spiking")
    assert [r["n"] for r in stored["material_accuracy"]["nmf_curve"]] == [3, 24, 30]
    assert stored["data"]["n_events"] == 54


@pytest.mark.slow
def test_report_folder_and_summary_keys(tiny_run):
    out, summary = tiny_run
    for name in ("report.html", "summary.json", "fig2c_frequency_laws.png",
                 "fig4b_predicted_distance.png", "fig6d_confusion.png", "fig7a_nmf_basis.png",
                 "fig7b_nmf_accuracy.png", "predictions.json"):
        assert (out / name).is_file(), name
    stored = json.loads((out / "summary.json").read_text())
    for key in ("calibration", "distance_rmse_mm", "material_accuracy", "two_material", "timing",
                "spiking", "cost_us_per_event"):
        assert key in stored
    spiking = stored["spiking"]
    assert ({"spiking_dominant", "spiking_centroid", "spiking_mlp_distance"}
            <= set(spiking["distance_rmse_mm"]))
    assert "spiking_mlp_material" in spiking["material_accuracy"]
    # 0.3 s per event: the low band at the bank's 0.1 ms, the high and rod bands at their own
    # 0.005 ms
    assert spiking["cost"]["neuron_steps_per_event"] == pytest.approx(
        24 * 0.3 / 1e-4 + 2 * 24 * 0.3 / 5e-6)
    assert [d["design"] for d in spiking["designs"]] == ["low_8"]
    # the tuned bank: its read-outs scored on every split, its curve at the asked sizes
    assert {"spiking_tuned_rate", "spiking_tuned_all"} <= set(spiking["material_accuracy"])
    assert [r["n"] for r in spiking["tuned"]["curve"]] == [4, 8]
    assert spiking["tuned"]["calibration_seed"] == 1000
    assert (out / "tuned_curve.png").is_file()
    assert (out / "pareto_cost_accuracy.png").is_file()
    assert [r["n"] for r in stored["material_accuracy"]["nmf_curve"]] == [3, 24, 30]
    assert stored["data"]["n_events"] == 54
    assert sum(stored["data"]["skipped"].values()) + stored["data"]["n_processed"] == 54


def test_report_numbers_are_recomputed_from_the_predictions(any_run):
    out, _ = any_run
    stored = json.loads((out / "summary.json").read_text())
    preds = json.loads((out / "predictions.json").read_text())
    html = (out / "report.html").read_text()
    for name, folds in preds["folds"].items():
        task = preds["task"][name]
        if task == "distance":
            rmse = [10 * np.sqrt(np.mean((np.array(f["predicted"]) - f["true"]) ** 2))
                    for f in folds]
            assert stored["distance_rmse_mm"][name]["mean"] == pytest.approx(np.mean(rmse))
            if name in TRAINING_FREE:   # shown once, as a self-consistency check
                table = html[html.index("Self-consistency"):][:3000]
                assert f"{np.mean(rmse):.2f}" in table
            else:
                assert f"{np.mean(rmse):.2f} ± {np.std(rmse, ddof=1):.2f}" in html
        elif task == "material" and not name.startswith("nmf_"):
            acc = [np.mean(np.array(f["predicted"]) == f["true"]) for f in folds]
            assert stored["material_accuracy"][name]["mean"] == pytest.approx(np.mean(acc))
        if name.startswith("spiking_") and task == "distance":
            assert stored["spiking"]["distance_rmse_mm"][name]["mean"] == pytest.approx(
                np.mean(rmse))


def test_no_test_repetition_was_trained_on(any_run):
    """Per fold, the repetitions of the training contacts and of the test contacts are
    disjoint (so no contact, nor its repetition's twin at another site, leaks), and every
    contact of the pipeline's events is on one side."""
    out, _ = any_run
    preds = json.loads((out / "predictions.json").read_text())
    rep = {int(k): v for k, v in preds["repetition"].items()}
    for name, folds in preds["folds"].items():
        for f in folds:
            train, test = set(f["train_event"]), set(f["test_event"])
            assert train and test and not train & test, name
            assert not {rep[e] for e in train} & {rep[e] for e in test}, name


def test_bad_spec_keys_and_materials_are_refused_before_work(tmp_path, capsys):
    with pytest.raises(SpecError, match="evaluation.bogus"):
        study.plan(specs.load(SPEC, ["evaluation.bogus=1"]))
    with pytest.raises(SpecError, match="spiking.bank.bin_edges_s"):
        study.plan(specs.load(SPEC, ["spiking.bank.bin_edges_s=[0.3,0.1]"]))
    with pytest.raises(SpecError, match="stimulus.material"):
        study.plan(specs.load(SPEC, ["stimulus.materials=['wood','granite']"]))
    with pytest.raises(SpecError, match=r"spiking.designs\[0\]"):
        study.plan(specs.load(SPEC, ["spiking.designs=[{name='x', band='low', bogus=1}]"]))
    with pytest.raises(SpecError, match="spiking.tuned.curve"):
        study.plan(specs.load(SPEC, ["spiking.tuned.curve=[24,25]"]))
    with pytest.raises(SpecError, match="spiking.tuned.tuning.n_resonators"):
        study.plan(specs.load(SPEC, ["spiking.tuned.tuning.n_resonators=7"]))
    assert main(["run", SPEC, "--out", str(tmp_path), "--set", "events.split_hz=5000"]) == 2
    assert "events.split_hz" in capsys.readouterr().err


def test_the_chosen_bank_is_held_to_nmf_with_as_many_filters_as_its_own_resonators():
    """Against the FFT, a read-out is paired with NMF-n at its own number of resonators: the
    chosen bank's are its whole bank's, not the hand-set band its name would map to."""
    from types import SimpleNamespace

    from snn_antenna.evaluation.comparison import Comparison

    def result(task, accuracy):
        return SimpleNamespace(baseline=SimpleNamespace(task=task),
                               values=lambda key: np.array(accuracy))
    results = {"mlp_spectrum_material": result("material", [0.9, 0.92]),
               "spiking_chosen": result("material", [0.95, 0.96]),
               "spiking_mlp_material_high": result("material", [0.5, 0.52]),
               "nmf_24": result("material", [0.7, 0.72]),
               "nmf_6": result("material", [0.6, 0.61])}
    cmp = Comparison(None, {}, results, {}, {}, {},
                     spiking={"neurons": {"spiking_high": 24, "spiking_low": 24}},
                     chosen={"resonators": 6})
    rows = cmp.against_fft()
    assert rows["spiking_chosen"]["neurons"] == 6
    assert rows["spiking_chosen"]["nmf_same_n"] == pytest.approx(0.605)
    assert rows["spiking_mlp_material_high"]["neurons"] == 24
    assert rows["spiking_chosen"]["fraction_of_fft_mlp"] == pytest.approx(
        np.mean([0.95 / 0.9, 0.96 / 0.92]))
