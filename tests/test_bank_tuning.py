"""The bank-tuning study: its search never scores an evaluated contact (a planted search
that peeks is refused), its space is checked before any work, and the stage ceilings read
each step of the bank's own chain."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.evaluation import crossval as cv
from snn_antenna.evaluation import stage_ceilings as sc
from snn_antenna.readout.spiking import Band, SpikingBank
from snn_antenna.studies.bank_tuning.plan import SPACE_KEYS, SearchPlan, check_space_entry
from snn_antenna.studies.bank_tuning.search import Scored, check_unseen

ROOT = Path(__file__).resolve().parents[1]


def _contacts(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 2 ** 16, (n, 50, 2), dtype=np.uint16)


def test_a_search_scored_on_tuning_contacts_passes_and_one_that_peeks_is_refused():
    evaluated = _contacts(40, 0)
    repetition = np.repeat(np.arange(10), 4)
    _, test = cv.split_by_repetition(repetition, 0.3, seed=0)
    honest = Scored()
    honest.add(_contacts(30, 1))              # another seed's contacts
    check_unseen(honest, evaluated)
    peeking = Scored()
    peeking.add(_contacts(30, 1))
    peeking.add(evaluated[test][:1])          # one held-out contact is enough
    with pytest.raises(SpecError) as refused:
        check_unseen(peeking, evaluated)
    assert refused.value.field == "search" and "1 evaluated contact" in str(refused.value)


def test_the_scored_contacts_survive_a_resumed_search(tmp_path):
    first = Scored(tmp_path / "scored.json")
    first.add(_contacts(5, 3))
    again = Scored(tmp_path / "scored.json")
    assert again.digests == first.digests and len(again.digests) == 5


@settings(max_examples=40, deadline=None)
@given(key=st.text(min_size=1, max_size=12).filter(lambda k: k not in SPACE_KEYS))
def test_an_unknown_key_of_the_space_is_refused_naming_it(key):
    with pytest.raises(SpecError) as refused:
        SearchPlan(space={key: [1, 2]})
    assert refused.value.field == f"space.{key}"


@settings(max_examples=60, deadline=None)
@given(key=st.sampled_from(sorted(SPACE_KEYS)),
       value=st.one_of(st.floats(allow_nan=True), st.lists(st.floats(), max_size=3),
                       st.lists(st.integers(-3, 30), min_size=2, max_size=2)))
def test_a_space_entry_is_a_range_or_choices_of_its_kind(key, value):
    kind = SPACE_KEYS[key][0]
    try:
        check_space_entry(key, value)
    except SpecError as exc:
        assert exc.field == f"space.{key}"
        return
    assert isinstance(value, list)          # accepted: a [low, high] of its kind
    if kind != "choice":
        assert len(value) == 2 and 0 <= value[0] <= value[1]
    if kind == "int":
        assert all(isinstance(v, int) and v >= 1 for v in value)
    if kind == "count":
        assert all(isinstance(v, int) and v >= 0 for v in value)


def test_the_low_mode_band_joins_the_channels_only_when_asked_and_steps_coarser():
    from snn_antenna.studies.bank_tuning.plan import BankPlan
    from snn_antenna.studies.bank_tuning.search import bank_of, start_params

    plan = BankPlan(tuning={"n_resonators": 4, "per_channel": 1, "max_channels": 4,
                            "coder": "analog", "coder_amplitude": 1.0,
                            "coder_options": {"gain": 150.0}},
                    low_resonators=6, low_band_hz=(7.0, 56.0))
    rng = np.random.default_rng(0)
    counts = np.concatenate([_tones(150.0, 4), _tones(300.0, 4)]).astype(float)
    counts = (counts + rng.normal(0, 20, counts.shape)).astype(np.uint16)
    labels = np.array(["a"] * 4 + ["b"] * 4)
    params = start_params(plan)
    with_low = bank_of(params, plan, counts, labels, (2000.0, 16, 10.0))
    low = with_low.bands["low"]
    assert low.n_neurons == 6 and low.band_hz == (7.0, 56.0) and low.highpass_hz is None
    assert low.lowpass_hz == plan.low_lowpass_hz
    channels = [b for k, b in with_low.bands.items() if k != "low"]
    assert all(low.dt_ms > b.dt_ms for b in channels)
    assert all(b.highpass_hz > 56.0 for b in channels)
    without = bank_of({**params, "low_resonators": 0}, plan, counts, labels,
                      (2000.0, 16, 10.0))
    assert "low" not in without.bands and without.n_neurons == with_low.n_neurons - 6


def test_the_study_spec_and_its_quick_profile_plan():
    from snn_antenna.studies import runner

    for quick in (False, True):
        spec = specs.load(ROOT / "studies" / "bank_tuning.toml", [], quick=quick)
        parts = runner("bank_tuning").plan(spec).parts
        assert parts.tuning_bench().seed != parts.bench.seed     # never the evaluated contacts
        assert parts.search.trials >= 1
        seeds = {parts.bench.seed, parts.tuning_bench().seed, parts.refine_bench().seed}
        assert len(seeds) == 3 and parts.search.refine_repetitions >= 2


def test_the_second_stage_ranks_its_banks_by_the_refining_contacts():
    from types import SimpleNamespace

    from snn_antenna.studies.bank_tuning.run import refined_front

    trials = [SimpleNamespace(number=n, values=(acc, steps))
              for n, acc, steps in ((0, 0.80, 1e6), (1, 0.82, 2e6), (2, 0.81, 5e5))]
    study = SimpleNamespace(trials=trials)
    # the tuning contacts ranked 1, 2, 0; the refining contacts rank 2 first
    refined = {1: [0.90, 0.88], 2: [0.93, 0.91], 0: [0.89, 0.89]}
    assert [t.number for t in refined_front(study, refined, 2)] == [2, 0]
    assert [t.number for t in refined_front(study, {1: [0.9], 0: [0.9]}, 5)] == [0, 1]
    with pytest.raises(SpecError) as refused:
        SearchPlan(refine_repetitions=1)
    assert refused.value.field == "refine_repetitions"


def _bank() -> SpikingBank:
    channel = dict(n_neurons=1, band_hz=(150.0, 150.0), threshold_g=0.001, lowpass_hz=170.0,
                   highpass_hz=130.0, filter_order=8, coder="analog",
                   coder_amplitude=1.0, coder_options={"gain": 150.0}, dt_ms=0.01)
    return SpikingBank(bands={"a": Band(**channel),
                              "b": Band(**{**channel, "band_hz": (300.0, 300.0),
                                           "lowpass_hz": 320.0, "highpass_hz": 280.0})},
                       bin_edges_s=(0.1, 0.2), batch_events=3)


def _tones(hz: float, n: int = 4, rate: float = 2000.0) -> np.ndarray:
    t = np.arange(1100) / rate
    g = 0.05 * np.sin(2 * np.pi * hz * t) * np.exp(-t / 0.2)
    counts = np.stack([g, 0.5 * g], axis=1) / 10.0 * 2 ** 15 + 2 ** 15
    return np.repeat(counts[None].astype(np.uint16), n, axis=0)


def test_the_stages_read_the_banks_own_chain_and_see_which_channel_rings():
    bank = _bank()
    counts = _tones(150.0)
    feats = sc.stage_features(bank, counts, 2000.0, 16, 10.0)
    assert set(feats) == set(sc.STAGES)
    assert all(np.all(np.isfinite(x)) for x in feats.values())
    # per channel, 3 bins, (log power, sign changes): channel a's power above channel b's
    ideal = feats["ideal_main_axis"].reshape(len(counts), 2, 3, 2)
    assert np.all(ideal[:, 0, :, 0] > ideal[:, 1, :, 0] + 3)
    assert feats["ideal_2_axes"].shape[1] == 2 * feats["ideal_main_axis"].shape[1]
    # the coded stage is the bank's own coded input (SpikingBank.code), read the same way
    n = int(round(bank.duration_s * 2000.0))
    coded = bank.code(counts, 2000.0, 16, 10.0).reshape(n, len(counts), 2)
    cuts = sc.bin_cuts(bank, 2000.0, n)
    assert np.allclose(feats["coded"], sc.channel_features(coded, cuts), atol=1e-5)
    # a 300 Hz tone rings channel b instead
    other = sc.stage_features(bank, _tones(300.0), 2000.0, 16, 10.0, stages=["band_pass"])
    bp = other["band_pass"].reshape(4, 2, 3, 2)
    assert np.all(bp[:, 1, 0, 0] > bp[:, 0, 0, 0])


def test_an_unknown_stage_is_refused():
    with pytest.raises(SpecError) as refused:
        sc.stage_features(_bank(), _tones(150.0), 2000.0, 16, 10.0, stages=["raw"])
    assert refused.value.field == "stages"


@pytest.mark.slow
@pytest.mark.parametrize("stage", ["search", "second stage"])
def test_the_study_refuses_a_planted_search_that_peeks(tmp_path, monkeypatch, stage):
    """The quick profile (with its second stage), with the contacts of the search or of its
    second stage alone swapped for the evaluated ones (a search that peeks at every split):
    the run stops before reporting any number."""
    from snn_antenna.sources import bench
    from snn_antenna.studies import runner
    from snn_antenna.studies.contract import Options

    study = runner("bank_tuning")
    spec = specs.load(ROOT / "studies" / "bank_tuning.toml", [], quick=True)
    monkeypatch.chdir(tmp_path)
    plan = study.plan(spec)
    evaluated_spec = plan.parts.bench
    load = bench.load

    swapped = (plan.parts.tuning_bench() if stage == "search" else
               plan.parts.refine_bench()).seed
    assert plan.parts.search.refine_repetitions >= 2

    def peeking(source, *args, **kwargs):
        if getattr(source, "seed", None) == swapped:
            source = evaluated_spec
        return load(source, *args, **kwargs)

    monkeypatch.setattr(bench, "load", peeking)
    with pytest.raises(SpecError) as refused:
        study.run(plan, tmp_path / "out", Options(quick=True), log=lambda *a: None)
    assert refused.value.field == "search"
    assert not (tmp_path / "out" / "report.html").exists()


def test_the_marks_hold_only_when_every_bound_is_met():
    from snn_antenna.studies.bank_tuning.run import marks

    at = {"mean": 1.004, "low": 0.995, "high": 1.01, "n": 5}
    closer = {"mean": -0.4, "low": -0.9, "high": 0.1, "n": 5}
    held = marks(at, 2.4, closer)
    assert all(m["holds"] for m in held.values())
    assert not marks({**at, "low": 0.985}, 2.4, closer)["accuracy_ratio_low"]["holds"]
    assert not marks({**at, "mean": 0.999}, 2.4, closer)["accuracy_ratio"]["holds"]
    assert not marks(at, 2.6, closer)["cost_ratio"]["holds"]
    assert not marks(at, 2.4, {**closer, "low": 0.2})["distance_rmse_not_worse"]["holds"]
    assert not marks({**at, "low": None, "high": None, "n": 1}, 2.4,
                     closer)["accuracy_ratio_low"]["holds"]
    few = marks({**at, "n": 2}, 2.4, {**closer, "n": 2})      # too few splits to hold
    assert not few["accuracy_ratio_low"]["holds"]
    assert not few["distance_rmse_not_worse"]["holds"]


def test_shared_counts_read_the_activitys_shape_apart_from_its_loudness():
    from snn_antenna.readout.spiking_decoders import code_rows, codes_of

    rng = np.random.default_rng(1)
    binned = rng.integers(0, 9, (5, 3, 4)).astype(float)
    binned[0] = 0.0                                  # a silent event stays finite

    def codes(b):
        return codes_of(b.sum(axis=2), np.zeros((5, 3)), np.zeros((5, 3)), b,
                        [0.0, 0.05, 0.1, 0.2])

    plain = code_rows(codes(binned), "spiking_tuned_bins", "counts")
    assert np.array_equal(plain, binned.reshape(5, -1))
    # the late read-out: the bins from LATE_S (0.1 s) on, the impact's ringing left out
    late = code_rows(codes(binned), "spiking_tuned_late", "counts")
    assert np.array_equal(late, binned[:, :, 2:].reshape(5, -1))
    once, twice = (code_rows(codes(k * binned), "spiking_tuned_bins", "share")
                   for k in (1.0, 2.0))
    assert once.shape == (5, 13) and np.all(np.isfinite(once))
    assert np.allclose(once[1:, :-1], twice[1:, :-1])             # the shape: loudness apart
    assert np.all(twice[1:, -1] > once[1:, -1])                   # the loudness beside it
    assert np.allclose(once[1:, :-1].sum(axis=1), 1.0)
    with pytest.raises(SpecError) as refused:
        code_rows(codes(binned), "spiking_tuned_bins", "peak")
    assert refused.value.field == "scaling"


def test_a_searched_point_grades_each_channels_gains_and_coarsens_its_step():
    from snn_antenna.studies.bank_tuning.plan import BankPlan
    from snn_antenna.studies.bank_tuning.search import bank_of, start_params

    plan = BankPlan(tuning={"n_resonators": 2, "per_channel": 1, "max_channels": 2,
                            "coder": "analog", "coder_amplitude": 1.0,
                            "coder_options": {"gain": 150.0}})
    counts = np.concatenate([_tones(150.0, 4), _tones(300.0, 4)])
    labels = np.array(["a"] * 4 + ["b"] * 4)
    params = start_params(plan)
    assert params["gain_levels"] == 1 and params["k_dt_factor"] == 1.0
    start = bank_of(params, plan, counts, labels, (2000.0, 16, 10.0))
    graded = bank_of({**params, "gain_levels": 3, "gain_ratio": 4.0, "k_dt_factor": 8.0},
                     plan, counts, labels, (2000.0, 16, 10.0))
    assert sorted(graded.bands) == ["ch00g0", "ch00g1", "ch00g2", "ch01g0", "ch01g1", "ch01g2"]
    assert [graded.bands[f"ch00g{i}"].coder_options["gain"] for i in range(3)] == pytest.approx(
        [37.5, 150.0, 600.0])
    assert graded.n_neurons == 3 * start.n_neurons       # per_channel resonators per gain
    for j in range(2):                                   # a coarser step for every channel
        assert graded.bands[f"ch{j:02d}g0"].dt_ms > start.bands[f"ch{j:02d}"].dt_ms


def test_the_channels_take_the_searched_filter_order_and_the_space_bounds_it():
    from snn_antenna.readout.spiking import LOW_BAND
    from snn_antenna.studies.bank_tuning.plan import BankPlan
    from snn_antenna.studies.bank_tuning.search import bank_of, start_params

    plan = BankPlan(tuning={"n_resonators": 2, "per_channel": 1, "max_channels": 2,
                            "coder": "analog", "coder_amplitude": 1.0,
                            "coder_options": {"gain": 150.0}}, low_resonators=2)
    counts = np.concatenate([_tones(150.0, 4), _tones(300.0, 4)])
    labels = np.array(["a"] * 4 + ["b"] * 4)
    params = start_params(plan)
    assert params["filter_order"] == 8 and params["scaling"] == "counts"
    bank = bank_of({**params, "filter_order": 6}, plan, counts, labels, (2000.0, 16, 10.0))
    assert {k: b.filter_order for k, b in bank.bands.items() if k != "low"} == {
        "ch00": 6, "ch01": 6}
    assert bank.bands["low"].filter_order == LOW_BAND.filter_order
    for bad in ([4, 9], [0, 4]):
        with pytest.raises(SpecError) as refused:
            check_space_entry("filter_order", bad)
        assert refused.value.field == "space.filter_order"
    check_space_entry("scaling", ["counts", "share"])
    with pytest.raises(SpecError):
        check_space_entry("scaling", ["spiking_tuned_bins"])
    with pytest.raises(SpecError):
        BankPlan(scaling="peak")


def _spikes(binned: np.ndarray, band) -> xr.Dataset:
    n, m, k = binned.shape
    return xr.Dataset({"binned_counts": (("event", "neuron", "time_bin"), binned)},
                      coords={"event": np.arange(n), "band": ("neuron", np.asarray(band)),
                              "bin_start_s": ("time_bin", np.linspace(0.0, 0.3, k))})


def test_the_distance_read_out_rows_are_the_low_bands_binned_counts_only():
    from snn_antenna.readout.bank_design import distance_rows

    rng = np.random.default_rng(2)
    band = np.array(["ch00", "low", "ch01", "low", "low"])
    binned = rng.integers(0, 9, (6, 5, 4))
    rows = distance_rows(_spikes(binned, band), np.arange(6), "spiking_low_peak_bins", None)
    assert np.array_equal(rows, binned[:, [1, 3, 4]].reshape(6, -1))   # every bin, early too
    loud_channels = binned.copy()
    loud_channels[:, [0, 2]] += 50                  # the channels' code: not read
    assert np.array_equal(rows, distance_rows(_spikes(loud_channels, band), np.arange(6),
                                                "spiking_low_peak_bins", None))
    material = rng.normal(size=(6, 3)).astype(np.float32)
    assert distance_rows(_spikes(binned, band), np.arange(6), "spiking_bank_rows",
                           material) is material
    with pytest.raises(SpecError) as refused:        # a bank without a low band
        distance_rows(_spikes(binned, ["ch00"] * 5), np.arange(6),
                        "spiking_low_peak_bins", None)
    assert refused.value.field == "band"


def test_the_low_band_read_out_sees_the_bins_shape_apart_from_their_loudness():
    from snn_antenna.readout.spiking_decoders import distance_baseline

    rng = np.random.default_rng(3)
    X = rng.integers(0, 6, (200, 12)).astype(float)
    X[:, 0] += 1.0
    y = X[:, :6].argmax(axis=1) * 2.0 + 8.0          # where the peak sits, not how loud
    evaluation = cv.Evaluation(mlp_max_iter=30, seeds=[0])
    model = distance_baseline("d", "spiking_low_peak_bins", "d", evaluation).build(0)
    model.fit(X, y)
    assert np.allclose(model.predict(3.0 * X), model.predict(X), atol=1e-6)
    plain = distance_baseline("d", "spiking_bank_rows", "d", evaluation).build(0).fit(X, y)
    assert not np.allclose(plain.predict(3.0 * X), plain.predict(X), atol=1e-3)
    with pytest.raises(SpecError) as refused:
        distance_baseline("d", "spiking_low_counts", "d", evaluation)
    assert refused.value.field == "distance_readout"


def test_the_low_band_takes_its_own_b_and_coder_and_a_read_out_of_it_needs_one():
    from snn_antenna.studies import runner
    from snn_antenna.studies.bank_tuning.plan import BankPlan
    from snn_antenna.studies.bank_tuning.search import bank_of, start_params

    plan = BankPlan(tuning={"n_resonators": 2, "per_channel": 1, "max_channels": 2,
                            "coder": "analog", "coder_amplitude": 1.0,
                            "coder_options": {"gain": 150.0}}, b=0.2645,
                    low_resonators=3, low_b=0.255, low_coder_amplitude=0.15,
                    low_threshold_g=0.2, distance_readout="spiking_low_peak_bins")
    counts = np.concatenate([_tones(150.0, 4), _tones(300.0, 4)])
    labels = np.array(["a"] * 4 + ["b"] * 4)
    bank = bank_of(start_params(plan), plan, counts, labels, (2000.0, 16, 10.0))
    low = bank.bands["low"]
    assert (low.b, low.coder, low.coder_amplitude, low.threshold_g) == (
        0.255, "square", 0.15, 0.2)
    assert {b.b for k, b in bank.bands.items() if k != "low"} == {0.2645}
    for field, bad in (("low_b", 0.0), ("low_coder_amplitude", -1.0), ("low_threshold_g", -0.1),
                       ("distance_readout", "spiking_tuned_late")):
        with pytest.raises(SpecError) as refused:
            BankPlan(**{field: bad})
        assert refused.value.field == field
    with pytest.raises(SpecError) as refused:
        BankPlan(low_resonators=0, distance_readout="spiking_low_peak_bins")
    assert refused.value.field == "low_resonators"
    spec = specs.load(ROOT / "studies" / "bank_tuning.toml",
                      ["search.space.low_resonators=[0, 8]"])
    with pytest.raises(SpecError) as refused:
        runner("bank_tuning").plan(spec)
    assert refused.value.field == "search.space.low_resonators"


def test_the_low_band_summary_weighs_its_steps_against_the_channels_and_sees_it_fire():
    from dataclasses import replace

    from snn_antenna.studies.bank_tuning.run import low_band_summary
    from snn_antenna.studies.bank_tuning.search import neuron_steps_per_event

    bank = _bank()
    bank = replace(bank, bands={**bank.bands, "low": Band(n_neurons=2, band_hz=(8.0, 50.0),
                                                          dt_ms=0.1)})
    band = ["a", "b", "low", "low"]
    spikes = _spikes(np.zeros((4, 4, 3), dtype=int), band)
    spikes["counts"] = (("event", "neuron"), np.array([[3, 1, 0, 0], [0, 0, 2, 0],
                                                       [1, 1, 1, 4], [0, 0, 0, 0]]))
    low = low_band_summary(spikes, np.arange(4), bank, 2000.0)
    assert low["resonators"] == 2 and low["neuron_steps_per_event"] == 2 * 5000
    assert low["channels_neuron_steps_per_event"] == neuron_steps_per_event(
        bank, 2000.0) - 2 * 5000 == 2 * 50000
    assert low["contacts_with_a_spike"] == 0.5                 # the channels' spikes apart
    assert low["resonators_firing_per_contact"] == 0.75
    assert low_band_summary(spikes, np.arange(4), _bank(), 2000.0) == {"resonators": 0}


def test_the_chosen_bank_file_places_the_trials_bank_again_from_the_same_contacts(tmp_path):
    """The study writes the chosen trial as its design, point and placement; the file, read
    back as a study includes it, places the very bank the study scored (every band's fields),
    and a point that lost a key is refused naming the keys it needs."""
    from snn_antenna.readout.bank_design import ChosenBank, bank_of, start_params, write_chosen
    from snn_antenna.studies.bank_tuning.plan import BankPlan, Parts
    from snn_antenna.studies.bank_tuning.run import chosen_of

    plan = BankPlan(tuning={"n_resonators": 2, "per_channel": 1, "max_channels": 2,
                            "coder": "analog", "coder_amplitude": 1.0,
                            "coder_options": {"gain": 150.0}}, low_resonators=2,
                    distance_readout="spiking_low_peak_bins")
    counts = np.concatenate([_tones(150.0, 4), _tones(300.0, 4)])
    labels = np.array(["a"] * 4 + ["b"] * 4)
    attrs = (2000.0, 16, 10.0)
    point = {**start_params(plan), "gain_levels": 3, "gain_ratio": 4.0, "b": 0.27,
             "filter_order": 6}
    scored = bank_of(point, plan, counts, labels, attrs)
    iv = {"mean": 0.9, "low": 0.85, "high": 0.95, "n": 5}
    summary = {"events": 40, "seeds": [0, 1], "fft_mlp_accuracy": iv,
               "front": [{"trial": 7, "resonators": scored.n_neurons, "bands": 2,
                          "neuron_steps_per_event": 1e5, "search_accuracy": 0.8,
                          "refine_accuracy": None, "accuracy": iv,
                          "accuracy_to_fft_mlp": {**iv, "low": None}}]}
    parts = Parts(None, None, None, plan, SearchPlan(seed_offset=1000, repetitions=4))
    write_chosen(tmp_path / "chosen_bank.toml", chosen_of(parts, point, 7, summary), "a bank")
    (tmp_path / "study.toml").write_text('chosen_bank = "chosen_bank.toml"\n')
    table = specs.load(tmp_path / "study.toml")["chosen_bank"]
    chosen = ChosenBank(**table)
    assert chosen.trial == 7 and chosen.placement == {"seed_offset": 1000, "repetitions": 4}
    assert chosen.measured["front"][0]["accuracy_to_fft_mlp"] == {"mean": 0.9, "high": 0.95,
                                                                  "n": 5}
    again = chosen.bank(counts, labels, attrs)
    assert again == scored and again.n_neurons == 3 * 2 + 2
    with pytest.raises(SpecError) as refused:
        ChosenBank(**{**table, "point": {k: v for k, v in table["point"].items()
                                         if k != "gain_ratio"}})
    assert refused.value.field == "point" and "gain_ratio" in refused.value.accepted
    for key, bad in (("channels", 2.5), ("gain_levels", 0), ("filter_order", 9), ("b", -0.2)):
        with pytest.raises(SpecError) as refused:
            ChosenBank(**{**table, "point": {**table["point"], key: bad}})
        assert refused.value.field == f"point.{key}", (key, refused.value.field)


def test_the_baseline_comparison_places_the_chosen_bank_on_the_bank_tuning_contacts():
    """The comparison's placement contacts for the shipped chosen bank are the bank-tuning
    study's tuning contacts (same bench spec, seed and repetitions), never its evaluated
    ones."""
    from snn_antenna.studies import runner
    from snn_antenna.studies.baseline_comparison.chosen import placement_spec

    tuning = runner("bank_tuning").plan(specs.load(ROOT / "studies" / "bank_tuning.toml"))
    comparison = runner("baseline_comparison").plan(
        specs.load(ROOT / "studies" / "baseline_comparison.toml"))
    spec = placement_spec(comparison.parts)
    assert spec.key() == tuning.parts.tuning_bench().key()
    assert spec.seed != comparison.parts.bench.seed
