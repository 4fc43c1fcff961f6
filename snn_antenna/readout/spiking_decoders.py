"""Decoders of the spiking read-out, in the same framework as the FFT baselines.

The spiking features of a bench data set (``engine.events.cached_features``) become decoder inputs
(``decoder_inputs``): per resonator its spike count, first-spike latency and firing span, for
one band or several, and for ``spiking_rod`` also its counts in the time bins. Each input set
is read by an MLP (``spiking_baselines``), so the spiking and FFT pipelines are trained and
tested on the same contacts and splits by ``evaluation.crossval.evaluate``. Two decoders learn nothing
(``TRAINING_FREE``): they invert the generator's own frequency law.

Array designs (``Design``) change one band of the bank at a time and are run and decoded on
a subset of the events (``evaluation.crossval.run_designs``), to see what the number, spacing or input of the
resonators buys.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np
import xarray as xr

from .. import spec as specs
from ..errors import check
from . import baselines as bl
from .spiking import Band, CentroidDistance, DominantNeuronDistance, SpikingBank

# The spiking input sets: which bands, and whether the time-binned counts are included.
SPIKING_SETS = {
    "spiking_low": (("low",), False),
    "spiking_high": (("high",), False),
    "spiking_both": (("low", "high"), False),
    "spiking_rod": (("low", "high", "rod"), True),
}
# Decoders that learn nothing and invert the generator's own frequency law: they show the
# simulator agreeing with itself, not a result to set beside the paper's.
TRAINING_FREE = ("spiking_dominant", "spiking_centroid")
# The MLP decoders: (input set, task, description).
SPIKING_MLPS = {
    "spiking_mlp_distance_low": ("spiking_low", "distance",
                                 "MLP 20-5 on the low band's counts, latencies, spans"),
    "spiking_mlp_distance": ("spiking_both", "distance", "MLP 20-5 on the low and high band"),
    "spiking_mlp_material_high": ("spiking_high", "material", "MLP 51 on the high band only"),
    "spiking_mlp_material": ("spiking_both", "material", "MLP 51 on the low and high band"),
    "spiking_mlp_material_rod": ("spiking_rod", "material",
                                 "MLP 51 on low, high and rod band, with time bins"),
}


def input_of(name: str) -> str:
    """The input set a spiking decoder reads (the training-free ones: the low band)."""
    return SPIKING_MLPS[name][0] if name in SPIKING_MLPS else "spiking_low"


def _available(spikes: xr.Dataset) -> dict:
    bands = set(spikes["band"].values.astype(str))
    return {name: spec for name, spec in SPIKING_SETS.items() if set(spec[0]) <= bands}


def decoder_inputs(features: xr.Dataset, spikes: xr.Dataset) -> xr.Dataset:
    """The event features with the spiking input matrices added, on the same events, and
    ``spiking_low_counts`` (the low band's counts) for the training-free decoders."""
    sp = spikes.sel(event=features["event"].values)
    bands = sp["band"].values.astype(str)
    out = features.copy()
    for name, (wanted, binned) in _available(spikes).items():
        keep = np.isin(bands, wanted)
        parts = [sp[v].values[:, keep] for v in ("counts", "latency_s", "span_s")]
        if binned:
            parts.append(sp["binned_counts"].values[:, keep].reshape(len(sp["event"]), -1))
        out[name] = (("event", f"{name}_feature"), np.hstack(parts).astype(np.float32))
    if "low" in set(bands):
        out["spiking_low_counts"] = (("event", "low_neuron"), sp["counts"].values[:, bands == "low"])
    return out


def neurons_per_input(spikes: xr.Dataset) -> dict:
    """Resonators per event behind each spiking input set (its filters, as NMF's n)."""
    bands = spikes["band"].values.astype(str)
    return {name: int(np.isin(bands, wanted).sum())
            for name, (wanted, _) in _available(spikes).items()}


def spiking_baselines(spikes: xr.Dataset, evaluation) -> list[bl.Baseline]:
    """Every spiking decoder the bank's bands allow (``evaluation``: the MLP settings of an
    ``evaluation.crossval.Evaluation``)."""
    out = []
    bands = spikes["band"].values.astype(str)
    if "low" in set(bands):
        low_hz = spikes["neuron_hz"].values[bands == "low"]
        out.append(bl.Baseline("spiking_dominant", "distance", "spiking_low_counts",
                               lambda seed: DominantNeuronDistance(low_hz),
                               "dominant low-band resonator → inverse low-mode law "
                               "(Fig. 10E), no training"))
        out.append(bl.Baseline("spiking_centroid", "distance", "spiking_low_counts",
                               lambda seed: CentroidDistance(low_hz),
                               "rate-weighted centroid of the low band → inverse low-mode "
                               "law, no training"))
    available = _available(spikes)
    for name, (inputs, task, text) in SPIKING_MLPS.items():
        if inputs in available:
            out.append(mlp_baseline(name, task, inputs, evaluation, text))
    return out


def mlp_baseline(name: str, task: str, inputs: str, evaluation,
                 description: str = "") -> bl.Baseline:
    """An MLP on spiking features: 20-5 for distance, 51 hidden for material (the FFT
    pipelines' layers, with their epoch budgets)."""
    if task == "distance":
        mlp = evaluation.mlp
        return bl.Baseline(name, task, inputs, lambda seed: bl.regressor_pipeline(
            mlp, bl.DISTANCE_HIDDEN, seed), description)
    mlp = evaluation.material_mlp
    return bl.Baseline(name, task, inputs, lambda seed: bl.classifier_pipeline(
        mlp, bl.MATERIAL_HIDDEN, seed), description)


# -- array designs --------------------------------------------------------------------------
@dataclass
class Design:
    """One array variant: band ``band`` of the bank with ``changes`` (``Band`` fields)."""
    name: str
    band: str = "low"
    changes: dict = field(default_factory=dict)

    @classmethod
    def from_table(cls, table: dict, index: int, bank: SpikingBank) -> "Design":
        """A ``[[spiking.designs]]`` entry: ``{name, band, ...Band fields}``, checked."""
        changes = dict(table)
        name, band = changes.pop("name", f"design_{index}"), changes.pop("band", "low")
        check(band in bank.bands, f"designs[{index}].band", band,
              f"one of {list(bank.bands)}")
        base = asdict(bank.bands[band])
        unknown = set(changes) - set(base)
        check(not unknown, f"designs[{index}]", sorted(unknown),
              f"fields of a band: {sorted(base)}")
        check(isinstance(name, str), f"designs[{index}].name", name, "a string")
        design = cls(name, band, changes)
        design.bank(bank)     # the variant's own checks, before any work
        return design

    def band_of(self, bank: SpikingBank) -> Band:
        return Band(**{**asdict(bank.bands[self.band]), **self.changes})

    def bank(self, bank: SpikingBank) -> SpikingBank:
        """The bank with only this design's band."""
        return replace(bank, bands={self.band: self.band_of(bank)})


@dataclass
class SpikingPlan:
    """The spiking read-out to compare (a study's ``[spiking]`` table).

    ``bank`` holds ``spiking.SpikingBank`` fields (its bands as ``[spiking.bank.bands.NAME]``);
    ``designs`` is a list of array variants, each ``{name, band, ...Band fields}``, run on the
    events of the first ``design_repetitions`` repetitions and decoded on the first split;
    ``cost_sample_events`` events are timed for the cost per event. ``workers``: Dask worker
    processes for the bank's runs (0: one per core; 1: this process; ``--scheduler`` attaches
    to a running cluster instead).
    """
    bank: dict = field(default_factory=dict)
    designs: list = field(default_factory=list)
    design_repetitions: int = 10
    cost_sample_events: int = 400
    workers: int = 1

    def build(self, rate_hz: float) -> tuple[SpikingBank, list[Design]]:
        """The bank and its designs, checked (for input sampled at ``rate_hz``)."""
        with specs.section("bank"):
            bank = SpikingBank(**self.bank)
        designs = [Design.from_table(d, i, bank) for i, d in enumerate(self.designs)]
        check(isinstance(self.design_repetitions, int) and self.design_repetitions >= 2,
              "design_repetitions", self.design_repetitions, "an integer >= 2")
        check(isinstance(self.workers, int) and not isinstance(self.workers, bool)
              and self.workers >= 0, "workers", self.workers,
              "an integer >= 0 (0: one Dask worker per core; 1: this process)")
        bank.check_rate(rate_hz)
        return bank, designs
