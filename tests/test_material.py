"""The control layer's material unit: class-I neurons whose rates name the contact's material."""
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from snn_antenna.errors import SpecError
from snn_antenna.networks import assembly
from snn_antenna.readout.spiking import HIGH_BAND, SpikingBank, window_features
from snn_antenna.sources import bench
from snn_antenna.stats import binomial_interval

ROOT = Path(__file__).resolve().parents[1]
WINDOW_S = 0.15          # one bench contact per read-out window
RATE_HZ = 2000.0
MATERIAL_OBJECTS = {"material", "material_listen", "material_read"}


def network_spec(name):
    with open(ROOT / "networks" / f"{name}.toml", "rb") as f:
        table = tomllib.load(f)
    for part in ("resonators", "gate", "cpg"):
        if part in table:
            table[part]["target"] = "numpy"
    if "material" in table:
        table["material"]["window_s"] = WINDOW_S
    return table


def coded_contacts(seed, repetitions, positions_cm):
    """Bench contacts of all eight materials, coded as the high band's chain codes them."""
    spec = bench.BenchSpec(positions_cm=positions_cm, repetitions=repetitions,
                           duration_s=WINDOW_S, rate_hz=RATE_HZ, seed=seed)
    counts = np.concatenate([bench._generate_block(spec, mi, pi)
                             for mi in range(len(spec.materials))
                             for pi in range(len(spec.positions_cm))])
    materials = np.repeat(spec.materials, len(spec.positions_cm) * repetitions)
    bank = SpikingBank(bands={"high": HIGH_BAND}, duration_s=WINDOW_S)
    return bank.code(counts, RATE_HZ, spec.adc_bits, spec.full_scale_g), materials


def material_unit_correct(train_seed: int, test_seed: int,
                          test_repetitions: int = 2) -> tuple[int, int]:
    """Train the unit on bench contacts of ``train_seed`` (12, 20, 28 cm, 6 repetitions), play
    unseen contacts of ``test_seed`` at unseen positions (16, 24 cm, ``test_repetitions`` of
    each material: 16 contacts per repetition)
    back to back through the network, and count how often its most active neuron names the
    contact's class (metal / non-metal)."""
    import brian2 as b2

    table = network_spec("bench_material")
    coded, materials = coded_contacts(train_seed, 6, (12.0, 20.0, 28.0))
    unit = assembly.configure(table)["material"].fit(
        window_features(table, coded, RATE_HZ), materials)
    coded, materials = coded_contacts(test_seed, test_repetitions, (16.0, 24.0))
    n_samples, n_events = coded.shape
    asm = assembly.build(table, fitted={"material": unit})
    feed = b2.TimedArray(np.r_[coded.T.ravel(), np.zeros(n_samples)], dt=b2.second / RATE_HZ)
    asm.objects["resonators"].run_regularly("I_ext = coded_input(t)", dt=b2.second / RATE_HZ)
    spikes = b2.SpikeMonitor(asm.objects["material"])
    asm.network.add(spikes)
    asm.network.run((n_events + 1) * WINDOW_S * b2.second, namespace={"coded_input": feed})
    # The read-out of contact e drives the unit during window e + 1.
    event = (np.asarray(spikes.t_[:]) // WINDOW_S).astype(int) - 1
    rates = np.zeros((n_events + 1, len(unit.classes)))
    np.add.at(rates, (event, np.asarray(spikes.i[:])), 1)
    rates = rates[:n_events]
    decoded = np.array(unit.class_names)[np.argmax(rates, axis=1)]
    correct = (decoded == unit.class_of(materials)) & (rates.max(axis=1) > 0)
    return int(correct.sum()), int(n_events)


# A known failure (strict xfail) that costs minutes of Brian2 runs: it is run with the thorough
# checks (-m slow), where it still fails loudly once the unit works again.
@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "on the bench's contact physics of issue 16 the material sits in the rods' own bending "
    "modes (107-377 Hz, a few % of the impact), which the high-band unit's 0.15 s count/latency "
    "features do not separate: 83 of 160 correct, p = 0.35 against chance (measured "
    "2026-11-23). The baseline study's rod band with time bins reads it (68 % of 8 classes); "
    "moving the unit onto that band is open work. strict: this fails loudly once the unit "
    "works again, so the marker cannot outlive the problem"))
def test_the_most_active_material_neuron_names_the_material_more_often_than_chance():
    # 160 unseen contacts (10 of each material at each of two unseen positions). Measured:
    # 100 of 160 (62.5 %); over 20 train/test seed pairs of 32 contacts, 419 of 640 (65.5 %,
    # Wilson 95 % interval 61.7-69.1 %; single seeds ranged 15-26 of 32, so 32 contacts
    # cannot resolve the unit from chance). What is resolved: above chance, not how far.
    correct, n = material_unit_correct(train_seed=0, test_seed=1, test_repetitions=10)
    assert n == 160
    p_chance = stats.binomtest(correct, n, 0.5, alternative="greater").pvalue
    assert p_chance < 0.01, f"{correct} of {n} correct: p = {p_chance:.3g} against chance"
    assert binomial_interval(correct, n)[0] > 0.5


@pytest.mark.slow
def test_over_many_seeds_the_material_unit_is_resolved_above_chance():
    results = [material_unit_correct(2 * seed, 2 * seed + 1) for seed in range(20)]
    correct, n = (sum(r[i] for r in results) for i in (0, 1))
    low, high = binomial_interval(correct, n)
    assert n == 640 and low > 0.55, (correct, n, low, high)   # measured 419 of 640, 61.7-69.1 %


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
