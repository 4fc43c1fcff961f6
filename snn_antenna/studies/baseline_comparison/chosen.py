"""The chosen bank of the baseline comparison: the bank the bank-tuning study chose
(``chosen_bank = "../networks/chosen_bank.toml"``), its channels placed again from the
contacts that placed them in that study (the bench set's spec with the file's seed offset and
repetitions, never evaluated), run over every event and read like the study reads it: the
material by an MLP 51 on its read-out's codes, the distance by its distance read-out; its cost
per contact and the FFT pipeline's measured in turn in this run."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...engine.events import best_costs, cached_features
from ...readout.bank_design import distance_rows, material_rows, neuron_steps_per_event
from ...readout.spiking import recording_attrs
from ...readout.spiking_decoders import DISTANCE_READOUTS, distance_baseline, mlp_baseline
from ...sources import bench

MATERIAL = "spiking_chosen"
DISTANCE = "spiking_chosen_distance"
COST_REPEATS = 3            # the chosen bank's and the FFT's cost: the best of 3 runs in turn
COST_SAMPLE_EVENTS = 200    # ... on this many events, when the spec has no [spiking] section


def placement_spec(parts):
    """The spec of the contacts that place the chosen bank's channels: the bench set's with
    the file's seed offset and repetitions (the bank-tuning study's tuning contacts)."""
    placement = parts.chosen.placement
    return replace(parts.bench, seed=parts.bench.seed + placement["seed_offset"],
                   repetitions=placement["repetitions"])


def placement_contacts(parts, log, fresh: bool):
    """The placement contacts (``placement_spec``): (their spec, their data set)."""
    spec = placement_spec(parts)
    log(f"      chosen bank: placed on {spec.n_events} contacts (seed {spec.seed}), never "
        "evaluated")
    return spec, bench.load(spec, log, fresh)


def chosen_stage(parts, data, cmp, log, fresh: bool, client) -> list:
    """The chosen bank over every event (cached), its read-outs' inputs into
    ``cmp.features``, its cost beside the FFT's, ``cmp.chosen`` describing it; the read-outs
    to evaluate."""
    chosen = parts.chosen
    spec, placing = placement_contacts(parts, log, fresh)
    labels = np.asarray(placing["material"].values.astype(str))
    bank = chosen.bank(placing["counts"].values, labels, recording_attrs(placing))
    design, point = chosen.bank_design, chosen.point
    log(f"      chosen bank (trial {chosen.trial}): {bank.n_neurons} resonators in "
        f"{len(bank.bands)} bands, {point['readout']} ({point['scaling']})")
    spikes = cached_features(data, bank, parts.bench, log, fresh, client)
    ids = cmp.features["event"].values
    X = material_rows(spikes, ids, point["readout"], point["scaling"])
    cmp.features[MATERIAL] = (("event", f"{MATERIAL}_feature"), X)
    D = distance_rows(spikes, ids, design.distance_readout, X)
    cmp.features[DISTANCE] = (("event", f"{DISTANCE}_feature"), D)
    sample = parts.plan.cost_sample_events if parts.plan else COST_SAMPLE_EVENTS
    costs = best_costs(data, parts.processor, ids[:sample], {MATERIAL: bank}, COST_REPEATS,
                       log)
    cmp.costs[MATERIAL] = costs[MATERIAL]
    rate_hz = recording_attrs(data)[0]
    cmp.chosen = {
        "trial": chosen.trial, "resonators": int(bank.n_neurons),
        "bands": len(bank.bands), "readout": point["readout"], "scaling": point["scaling"],
        "distance_readout": design.distance_readout,
        "neuron_steps_per_event": neuron_steps_per_event(bank, rate_hz),
        "placement": {**chosen.placement, "seed": int(spec.seed), "events": int(spec.n_events)},
        "point": dict(point), "measured": chosen.measured,
        "cost": {"fft": costs["fft"], "chosen": costs[MATERIAL],
                 "ratio_to_fft": costs[MATERIAL]["features_us_per_event"]
                 / costs["fft"]["features_us_per_event"]}}
    cmp.chosen_bank = (bank, placing)
    return chosen_baselines(chosen, parts.evaluation)


def chosen_baselines(chosen, evaluation) -> list:
    """The chosen bank's read-outs: the material by an MLP 51 on its read-out's codes, the
    distance by its distance read-out."""
    readout, distance = chosen.point["readout"], chosen.bank_design.distance_readout
    return [mlp_baseline(MATERIAL, "material", MATERIAL, evaluation,
                         f"MLP 51 on the chosen bank's {readout} codes"),
            distance_baseline(DISTANCE, distance, DISTANCE, evaluation,
                              DISTANCE_READOUTS[distance])]
