"""The baseline comparison on the shipped board's 1 kHz recordings: what the rate cannot carry is
left out or clipped and named, and the tuned bank places its channels on recorded contacts
that no split ever scores."""
import json
from pathlib import Path

import numpy as np
import pytest

from data_helpers import (RATE, import_board_bench, import_dir, ringing_counts, write_labels,
                          write_record)
from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError
from snn_antenna.networks.resonators import MIN_SAMPLES_PER_CYCLE
from snn_antenna.sources.recorded import RecordedBench
from snn_antenna.studies import baseline_comparison
from snn_antenna.studies.baseline_comparison.plan import fit_to_rate
from snn_antenna.studies.baseline_comparison.run import signal_stage

ROOT = Path(__file__).resolve().parents[1]
SITES = [("wood", 10.0), ("wood", 25.0), ("aluminium", 10.0), ("aluminium", 25.0)]


def shipped(*overrides) -> dict:
    return specs.load(ROOT / "studies" / "baseline_comparison.toml", list(overrides), quick=True)


@pytest.fixture(scope="module")
def board_set(tmp_path_factory):
    """Contacts at four sites, five repetitions each, one after another on one 1 kHz board
    recording, labelled with their repetitions and imported."""
    tmp = tmp_path_factory.mktemp("board")
    rows, onsets, distances = [], [], []
    for rep in range(5):
        for material, d in SITES:
            onsets.append(1.0 + 1.2 * len(onsets))
            distances.append(d)
            rows.append(("run1", onsets[-1], d, material, rep))
    write_record(tmp / "recs" / "run1", ringing_counts(onsets, distances, onsets[-1] + 1.5,
                                                         high=0.3))
    write_labels(tmp / "labels.csv", rows)
    return import_dir(tmp / "recs", tmp / "labels.csv", tmp / "data")


def test_the_shipped_comparison_fits_a_1khz_recording_and_names_each_part_it_drops():
    spec = shipped()
    fitted, notes = fit_to_rate(spec, RATE)
    limit = RATE / MIN_SAMPLES_PER_CYCLE
    assert fitted["events"]["max_hz"] == RATE / 2
    for name, band in fitted["spiking"]["bank"]["bands"].items():
        assert band["band_hz"][1] <= limit < band["lowpass_hz"] < RATE / 2 or name == "low"
    assert fitted["spiking"]["tuned"]["tuning"]["range_hz"][1] <= limit
    text = "\n".join(notes)
    for part in ("events.max_hz", "bands.high.band_hz", "bands.rod.band_hz",
                 "bands.high.lowpass_hz", "bands.rod.lowpass_hz", "tuned.tuning.range_hz"):
        assert text.count(part) == 1, part
    assert all("500 Hz" in line for line in notes if "lowpass_hz" not in line)
    assert spec == shipped()                      # the caller's spec is left as it was
    # the generated bench's 2 kHz carries every part: nothing changes, nothing is named
    assert fit_to_rate(spec, 2000.0) == (spec, [])


def test_a_band_wholly_above_the_limit_is_left_out_with_the_designs_on_it():
    spec = shipped()
    spec["spiking"]["bank"]["bands"]["ultra"] = {"n_neurons": 8, "band_hz": [300.0, 450.0]}
    spec["spiking"]["designs"] = [{"name": "ultra_16", "band": "ultra", "n_neurons": 16},
                                  {"name": "low_wide", "band": "low", "band_hz": [8.0, 400.0]}]
    fitted, notes = fit_to_rate(spec, RATE)
    assert "ultra" not in fitted["spiking"]["bank"]["bands"]
    assert [d["name"] for d in fitted["spiking"]["designs"]] == ["low_wide"]
    assert fitted["spiking"]["designs"][0]["band_hz"] == [8.0, RATE / MIN_SAMPLES_PER_CYCLE]
    assert any(line.startswith("left out: spiking.bank.bands.ultra") for line in notes)
    assert any("ultra_16" in line and line.startswith("left out") for line in notes)


def test_the_shipped_comparison_plans_on_a_1khz_board_recording(board_set):
    """The command a user of the shipped board runs is accepted: no part of the spec left
    refused, the rate's cuts listed, the tuned bank's calibration repetitions drawn."""
    plan = baseline_comparison.plan({**shipped(), "data": str(board_set)})
    parts = plan.parts
    assert isinstance(parts.bench, RecordedBench) and parts.bench.rate_hz == RATE
    cut = [line for line in plan.left_out if not line.startswith("fitted:")]
    assert cut and all(line.startswith(("left out", "clipped")) for line in cut)
    fitted = [line for line in plan.left_out if line.startswith("fitted:")]
    assert fitted == parts.fitted and any("events.split_hz" in line for line in fitted)
    tuned = parts.plan.tuned_plan()
    assert len(parts.calibration_repetitions) == tuned.calibration_repetitions
    assert set(parts.calibration_repetitions) <= set(range(5))
    again = baseline_comparison.plan({**shipped(), "data": str(board_set)}).parts
    assert again.calibration_repetitions == parts.calibration_repetitions
    draws = {tuple(baseline_comparison.plan({**shipped(), "seed": s, "data": str(board_set)})
                   .parts.calibration_repetitions) for s in range(6)}
    assert len(draws) > 1                          # the seed draws them


def test_check_prints_what_the_rate_leaves_out(board_set, tmp_path, capsys):
    """`run SPEC --data DIR --check` on a 1 kHz set says each part the run would leave out or
    clip, the lines the run logs; on the generated 2 kHz bench it names none."""
    from snn_antenna.cli import main

    study = str(ROOT / "studies" / "baseline_comparison.toml")
    left_out = baseline_comparison.plan({**shipped(), "data": str(board_set)}).left_out
    assert main(["run", study, "--quick", "--data", str(board_set), "--check",
                 "--out", str(tmp_path / "recorded")]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert [line.split(": ", 1)[1] for line in printed[:-1]] == left_out
    assert "nothing was run" in printed[-1]
    assert main(["run", study, "--quick", "--check", "--out", str(tmp_path / "bench")]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == 1 and "nothing was run" in printed[0]


def test_the_tuned_banks_calibration_contacts_leave_every_split(board_set):
    parts = baseline_comparison.plan({**shipped(), "data": str(board_set)}).parts
    _, cmp, _ = signal_stage(parts, 5, lambda *a: None, False)
    reps = set(cmp.features["repetition"].values.tolist())
    assert reps == set(range(5)) - set(parts.calibration_repetitions)
    assert cmp.features.sizes["event"] == len(SITES) * len(reps)


def test_a_recorded_set_too_small_to_hold_out_calibration_contacts_is_refused(board_set):
    with pytest.raises(SpecError) as refused:
        baseline_comparison.plan({**shipped("spiking.tuned.calibration_repetitions=4"),
                                  "data": str(board_set)})
    assert refused.value.field == "spiking.tuned.calibration_repetitions"
    assert "at most 3" in str(refused.value)


@pytest.mark.slow
def test_a_clipped_band_reads_tones_up_to_its_limit_at_their_own_channels():
    """The high band clipped for a 1 kHz recording, driven by the board's samples of decaying
    tones: the most active resonators sit at each tone, up to the band's new top (no mirror
    of a tone elsewhere, no silent top channel)."""
    from snn_antenna.engine.events import run_bank
    from snn_antenna.readout.spiking import SpikingBank
    from snn_antenna.sources.antenna import ADC

    band = {**fit_to_rate(shipped(), RATE)[0]["spiking"]["bank"]["bands"]["high"],
            "dt_ms": 0.02}
    bank = SpikingBank(bands={"high": band}, duration_s=0.2, target="numpy", batch_events=10)
    t = np.arange(int(0.4 * RATE)) / RATE
    tones = [80.0, 120.0, 170.0, 230.0]
    counts = []
    for f in tones:
        x = np.where(t >= 0.05, np.exp(-(t - 0.05) / 0.1) * np.sin(2 * np.pi * f * (t - 0.05)),
                     0.0)
        counts.append(ADC(10, 18.0).to_counts(np.stack([x * np.cos(0.5), x * np.sin(0.5)], 1)))
    spikes = run_bank(bank, np.stack(counts), RATE, 10, 18.0, progress=False)
    hz = bank.bands["high"].array(0.02, "rk4", "numpy").neuron_hz
    for f, c in zip(tones, spikes.counts):
        top = hz[np.argsort(c)[-3:]]               # the three most active resonators
        assert np.all(np.abs(np.log(top / f)) < np.log(1.3)), (f, top, c)


@pytest.mark.slow
def test_the_shipped_comparison_runs_on_the_boards_1khz_recordings(tmp_path):
    """`run studies/baseline_comparison.toml --data DIR --quick` on the shipped board's
    recordings, twice: the same numbers, the tuned bank among the read-outs, and a report
    that names the recordings' hashes, what the rate left out and which contacts placed the
    tuned channels."""
    from snn_antenna.cli import main

    table = {"kind": "bench", "materials": ["wood", "aluminium"],
             "positions_cm": [10.0, 16.0, 22.0, 28.0], "repetitions": 10, "n_jobs": 1,
             "cache_dir": str(tmp_path / "cache")}
    data = import_board_bench(tmp_path, table)
    args = ["run", str(ROOT / "studies" / "baseline_comparison.toml"), "--data", str(data),
            "--quick", "--set", f"stimulus.cache_dir=\"{tmp_path / 'cache'}\""]
    for out in ("one", "two"):
        assert main([*args, "--out", str(tmp_path / out)]) == 0
    one, two = (json.loads((tmp_path / o / "summary.json").read_text()) for o in ("one", "two"))
    assert one["material_accuracy"] == two["material_accuracy"]
    assert "spiking_tuned_bins" in one["material_accuracy"] or any(
        k.startswith("spiking_tuned") for k in one["material_accuracy"])
    assert len(one["left_out"]) == 6
    tuned = one["spiking"]["tuned"]
    assert len(tuned["calibration_repetitions"]) == 3
    page = (tmp_path / "one" / "report.html").read_text()
    meta = json.loads((data / "import.json").read_text())
    assert meta["recordings"][0]["files"][0]["sha256"] in page
    assert "above the 500 Hz Nyquist of the recordings" in page
    assert f"repetitions {', '.join(map(str, tuned['calibration_repetitions']))}" in page
    assert not one["calibrated"]


def test_nmf_sizes_a_small_split_cannot_fit_are_left_out_and_named():
    import numpy as np
    import xarray as xr

    from snn_antenna.evaluation.crossval import Evaluation
    from snn_antenna.readout.baselines import material_baselines
    from snn_antenna.studies.baseline_comparison.run import _fitting_nmf

    features = xr.Dataset(coords={"repetition": ("event", np.repeat(np.arange(10), 4))})
    evaluation = Evaluation(seeds=[0, 1], test_fraction=0.3, nmf_dims=[3, 24, 30, 45])
    kept, line = _fitting_nmf(material_baselines([3, 24, 30, 45]), features, evaluation)
    names = [b.name for b in kept]
    assert names == ["mlp_spectrum_material", "nmf_3", "nmf_24"], names
    assert "nmf_30, nmf_45" in line and "28 training events" in line, line
    everything, none = _fitting_nmf(material_baselines([3, 24]), features, evaluation)
    assert len(everything) == 3 and none is None


def test_tuned_channels_placed_at_the_top_of_a_1khz_range_stay_within_the_rate():
    """Channels placed from a lab's 1 kHz contacts whose material differences sit at the top
    of the clipped range: every channel the run would build passes the rate check the run
    makes, for every tuning of the shipped plan (so `--check` passing means the run does)."""
    from snn_antenna.readout.band_tuning import tune
    from snn_antenna.readout.spiking import SpikingBank
    from snn_antenna.readout.spiking_decoders import SpikingPlan

    fitted, _ = fit_to_rate(shipped(), RATE)
    plan = SpikingPlan(**fitted["spiking"])
    tuned = plan.tuned_plan()
    rng = np.random.default_rng(0)
    t = np.arange(int(0.5 * RATE)) / RATE
    events, labels = [], []
    for material, tau in (("rubber", 0.02), ("wood", 0.2)):     # they differ near 240 Hz
        for _ in range(6):
            ring = 2 * np.exp(-t / tau) * np.sin(2 * np.pi * rng.uniform(235, 249) * t)
            ring += 0.01 * rng.standard_normal(len(t))
            events.append(np.stack([512 + ring * 28, 512 + ring * 20], axis=1).round())
            labels.append(material)
    counts = np.asarray(events, dtype=np.int64)
    for tuning in tuned.tunings().values():
        bands = tune(counts, np.asarray(labels), RATE, 10, 18.0, tuning)
        assert max(b.band_hz[1] for b in bands.values()) <= RATE / MIN_SAMPLES_PER_CYCLE
        SpikingBank(bands=bands, duration_s=0.2, target="numpy").check_rate(RATE)
