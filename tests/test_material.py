"""The control layer's material unit: class-I neurons whose rates name the contact's material."""
import tomllib
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from snn_antenna.core.errors import SpecError
from snn_antenna.networks import assembly
from snn_antenna.networks.control import MaterialUnit
from snn_antenna.readout.spiking import Band, SpikingBank, window_features
from snn_antenna.sources import bench
from snn_antenna.core import calibration
from snn_antenna.report.stats import binomial_interval

ROOT = Path(__file__).resolve().parents[1]
RATE_HZ = 2000.0
MATERIAL_OBJECTS = {"material", "material_listen", "material_read"}
# The unit's array is the baseline study's rod band: its input chain (band-pass, low
# threshold) codes the contacts here, and its resonators are the network's.
with open(ROOT / "studies" / "baseline_comparison.toml", "rb") as f:
    ROD_BAND = Band(**calibration.resolve(tomllib.load(f))["spiking"]["bank"]["bands"]["rod"])


def network_spec(name, runtime_target="numpy"):
    with open(ROOT / "networks" / f"{name}.toml", "rb") as f:
        table = calibration.resolve(tomllib.load(f))
    for part in ("resonators", "gate", "cpg"):
        if part in table:
            table[part]["target"] = runtime_target
    return table


def coded_contacts(seed, repetitions, positions_cm, window_s):
    """Bench contacts of all eight materials, ``window_s`` each, coded by the rod band's chain."""
    spec = bench.BenchSpec(positions_cm=positions_cm, repetitions=repetitions,
                           duration_s=window_s, rate_hz=RATE_HZ, seed=seed)
    counts = np.concatenate([bench._generate_block(spec, mi, pi)
                             for mi in range(len(spec.materials))
                             for pi in range(len(spec.positions_cm))])
    materials = np.repeat(spec.materials, len(spec.positions_cm) * repetitions)
    bank = SpikingBank(bands={"rod": ROD_BAND}, duration_s=window_s)
    return bank.code(counts, RATE_HZ, spec.adc_bits, spec.full_scale_g), materials


def material_unit_correct(train_seed: int, test_seed: int,
                          test_repetitions: int = 2) -> tuple[int, int]:
    """Train the unit on bench contacts of ``train_seed`` (12, 20, 28 cm, 6 repetitions), play
    unseen contacts of ``test_seed`` at unseen positions (16, 24 cm, ``test_repetitions`` of
    each material: 16 contacts per repetition)
    back to back through the network, and count how often its most active neuron names the
    contact's class (metal / non-metal). The resonators run compiled (cython): at the rod
    band's 0.005 ms step numpy's runtime is ~15 times slower."""
    import brian2 as b2

    table = network_spec("bench_material", runtime_target="cython")
    window_s = table["material"]["window_s"]
    coded, materials = coded_contacts(train_seed, 6, (12.0, 20.0, 28.0), window_s)
    unit = assembly.configure(table)["material"].fit(
        window_features(table, coded, RATE_HZ), materials)
    coded, materials = coded_contacts(test_seed, test_repetitions, (16.0, 24.0), window_s)
    n_samples, n_events = coded.shape
    asm = assembly.build(table, fitted={"material": unit})
    feed = b2.TimedArray(np.r_[coded.T.ravel(), np.zeros(n_samples)], dt=b2.second / RATE_HZ)
    asm.objects["resonators"].run_regularly("I_ext = coded_input(t)", dt=b2.second / RATE_HZ)
    spikes = b2.SpikeMonitor(asm.objects["material"])
    asm.network.add(spikes)
    asm.network.run((n_events + 1) * window_s * b2.second, namespace={"coded_input": feed})
    # The read-out of contact e drives the unit during window e + 1.
    event = (np.asarray(spikes.t_[:]) // window_s).astype(int) - 1
    rates = np.zeros((n_events + 1, len(unit.classes)))
    np.add.at(rates, (event, np.asarray(spikes.i[:])), 1)
    rates = rates[:n_events]
    decoded = np.array(unit.class_names)[np.argmax(rates, axis=1)]
    correct = (decoded == unit.class_of(materials)) & (rates.max(axis=1) > 0)
    return int(correct.sum()), int(n_events)


# Minutes of Brian2 (the rod band at 0.005 ms over 304 contacts of 0.5 s): a thorough check.
@pytest.mark.slow
def test_the_most_active_material_neuron_names_the_material_more_often_than_chance():
    # 160 unseen contacts (10 of each material at each of two unseen positions), trained on
    # 144 at three other positions. Measured on the rod band with time bins (2026-11-25):
    # 127 of 160 (79.4 %, Wilson 95 % interval 72.5-84.9 %, p = 1.7e-14 against chance; 16-19
    # min on two shared cores). The unit's old high-band read-out: 83 of 160 on this physics
    # (p = 0.35), 65.5 % before it. Fed the high band again (its chain and array) with the
    # same 0.5 s window and time bins: 95 of 160 (Wilson 51.6-66.7 %), so the rod band is
    # what pays and the 65.5 % bound fails; with the network's read given absolute spike times
    # instead of times from its window's start (fit and run features disagreeing): 85 of
    # 160, p = 0.24. What is resolved: above chance and, by its interval, above the old
    # 65.5 %; not how far below the baseline study's read-out it stays.
    correct, n = material_unit_correct(train_seed=0, test_seed=1, test_repetitions=10)
    assert n == 160
    p_chance = stats.binomtest(correct, n, 0.5, alternative="greater").pvalue
    assert p_chance < 0.01, f"{correct} of {n} correct: p = {p_chance:.3g} against chance"
    assert binomial_interval(correct, n)[0] > 0.655, "not resolved above the old 65.5 %"


@pytest.mark.slow
def test_over_many_seeds_the_material_unit_is_resolved_above_chance():
    # Measured 419 of 640 (61.7-69.1 %) on the high band with a simpler contact physics; not
    # re-measured since the unit moved onto the rod band (20 seed pairs of 176 contacts of
    # 0.5 s: about two hours of Brian2 on two shared cores). The threshold is that measurement's.
    results = [material_unit_correct(2 * seed, 2 * seed + 1) for seed in range(20)]
    correct, n = (sum(r[i] for r in results) for i in (0, 1))
    low, high = binomial_interval(correct, n)
    assert n == 640 and low > 0.55, (correct, n, low, high)


def test_networks_without_the_part_build_no_material_objects():
    for name in ("bench", "exploration"):
        assert not assembly.build(network_spec(name)).names() & MATERIAL_OBJECTS


def test_the_material_unit_needs_resonators_and_a_fit():
    with pytest.raises(SpecError, match="needs resonators"):
        assembly.build({"parts": ["material"], "inputs": ["antenna"]})
    with pytest.raises(SpecError, match="fitted MaterialUnit"):
        assembly.build(network_spec("bench_material"))
    with pytest.raises(SpecError, match="unobtainium"):
        assembly.configure({**network_spec("bench_material"),
                            "material": {"classes": {"metal": ["unobtainium"], "b": ["wood"]}}})
    unit = MaterialUnit().fit(np.random.default_rng(0).random((4, 3 * 24)),
                              ["brass", "wood", "copper", "pvc"])
    with pytest.raises(SpecError, match=r"168 \(7 per resonator\)"):   # 3 + 4 time bins
        assembly.build(network_spec("bench_material"), fitted={"material": unit})


def test_the_material_network_reads_the_baseline_studys_rod_band():
    spec = network_spec("bench_material", runtime_target="cython")["resonators"]
    band = asdict(ROD_BAND)
    for key in ("n_neurons", "b", "hz_per_k", "method", "dt_ms"):
        assert spec[key] == band[key], key
    assert tuple(spec["band_hz"]) == tuple(band["band_hz"])
    network_hz = assembly.configure(network_spec("bench_material"))["resonators"].neuron_hz
    assert np.allclose(network_hz, ROD_BAND.array(0.1, "euler", "numpy").neuron_hz)


def test_window_features_known_answer():
    unit = MaterialUnit(window_s=0.5, bin_edges_s=(0.1, 0.2, 0.3))
    # resonator 0: three spikes in window 0; resonator 1: one in window 1 (0.15 s into it)
    # and one after the last window, which counts in the last (0.45 s into it)
    rows = unit.window_features([0, 0, 0, 1, 1], [0.05, 0.15, 0.35, 0.65, 0.95], 2, n_windows=2)
    assert rows.shape == (2, unit.n_features(2)) == (2, 14)
    #         counts   latency      span       time bins r0  time bins r1
    assert np.allclose(rows[0], [3, 0, 0.05, 0.5, 0.3, 0, 1, 1, 0, 1, 0, 0, 0, 0])
    assert np.allclose(rows[1], [0, 2, 0.5, 0.15, 0, 0.3, 0, 0, 0, 0, 0, 1, 0, 1])
    plain = MaterialUnit(window_s=0.5, bin_edges_s=())
    assert np.allclose(plain.window_features([0, 0, 0], [0.05, 0.15, 0.35], 1),
                       [[3, 0.05, 0.3]])


def test_material_window_settings_are_checked_before_any_run():
    with pytest.raises(SpecError, match="bin_edges_s"):
        MaterialUnit(bin_edges_s=(0.2, 0.1))
    with pytest.raises(SpecError, match="bin_edges_s"):
        MaterialUnit(window_s=0.5, bin_edges_s=(0.1, 0.6))
    table = network_spec("bench_material")
    with pytest.raises(SpecError, match="window_s"):    # 0.15 s of coded input, 0.5 s window
        window_features(table, np.zeros((300, 2)), RATE_HZ)
    with pytest.raises(SpecError, match="material"):
        window_features({**table, "parts": ["resonators"]}, np.zeros((1000, 2)), RATE_HZ)
