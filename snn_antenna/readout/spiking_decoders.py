"""Decoders of the spiking read-out, in the same framework as the FFT baselines.

The spiking features of a bench data set (``engine.events.cached_features``) become decoder inputs
(``decoder_inputs``): per resonator its spike count, first-spike latency and firing span, for
one band or several, and for ``spiking_rod`` also its counts in the time bins. Each input set
is read by an MLP (``spiking_baselines``), so the spiking and FFT pipelines are trained and
tested on the same contacts and splits by ``evaluation.crossval.evaluate``. Two decoders learn
nothing (``TRAINING_FREE``): they invert the generator's own frequency law.

Array designs (``Design``) change one band of the bank at a time and are run and decoded on
a subset of the events (``evaluation.crossval.run_designs``), to see what the number, spacing or
input of the resonators buys.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np
import xarray as xr

from ..core import bounds
from ..core import spec as specs
from ..core.errors import check
from . import baselines as bl
from .band_tuning import Tuning
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
# Read-outs of the tuned bank (``band_tuning``; bands named ``ch00``…), each an MLP 51 on one
# code of the same spikes: which part of the spike train carries the material.
TUNED_READOUTS = {
    "spiking_tuned_rate": (("counts",), "rate: spike counts"),
    "spiking_tuned_timing": (("latency_s", "span_s"),
                             "latency code: first-spike latency and firing span"),
    "spiking_tuned_bins": (("binned_counts",), "rate in time bins (the decay of activity)"),
    "spiking_tuned_decay": (("counts", "decay"),
                            "rate + decay: log ratio of successive time bins' counts"),
    "spiking_tuned_all": (("counts", "latency_s", "span_s", "binned_counts"),
                          "rate, latency, span and time bins"),
    "spiking_tuned_late": (("late_binned_counts",),
                           f"rate in the time bins from {1000 * 0.1:.0f} ms on (the lines "
                           "after the impact)"),
}
# The impact is broadband: it rings every narrow channel at the channel's own frequency for a
# few times 1 / bandwidth (~0.1 s for a 3 % channel at 110 Hz), whatever the material; from
# then on only the lines the contact left ring in a channel. The late read-out counts those.
LATE_S = 0.1


# Distance read-outs of a tuned bank, each an MLP 20-5 (the FFT-MLP's distance layers). The
# contact's distance lives in the low mode's frequency, which the low-mode band reads (band
# ``low``); the channels are placed where the material separates. ``spiking_low_peak_bins``:
# the low band's counts in every time bin (the early ones too: a far contact's low mode rings
# for only a few cycles), each event's row scaled to its largest count and centred, not
# standardised per column (the FFT-MLP's spectrum scaling: standardising lifts the resonators
# that stay silent to the weight of the driven ones). ``spiking_bank_rows``: the bank's
# material read-out rows (every band, ``code_rows``), standardised per column.
DISTANCE_READOUTS = {
    "spiking_low_peak_bins": "MLP 20-5 on the low band's counts in time bins, scaled to their "
                             "peak (as the FFT-MLP's spectrum)",
    "spiking_bank_rows": "MLP 20-5 on the bank's material read-out rows",
}
# the distance read-outs that read the low band (a bank without one is refused for them)
LOW_BAND_READOUTS = ("spiking_low_peak_bins",)


def low_band_rows(binned, band) -> np.ndarray:
    """The low band's spike counts in every time bin, one row per event (``binned``: events ×
    neurons × time bins; ``band``: each neuron's band name), refused for a bank without one."""
    band = np.asarray(band).astype(str)
    check(bool(np.any(band == "low")), "band", sorted(set(band)),
          "a bank with a low-mode band ('low') for the low band's read-out")
    binned = np.asarray(binned)
    return binned[:, band == "low"].reshape(len(binned), -1).astype(np.float32)


def distance_baseline(name: str, readout: str, inputs: str, evaluation,
                      description: str = "") -> bl.Baseline:
    """The distance read-out ``readout`` (``DISTANCE_READOUTS``) on the input ``inputs``."""
    check(readout in DISTANCE_READOUTS, "distance_readout", readout,
          f"one of {sorted(DISTANCE_READOUTS)}")
    if readout == "spiking_bank_rows":
        return mlp_baseline(name, "distance", inputs, evaluation,
                            description or DISTANCE_READOUTS[readout])
    mlp = evaluation.mlp
    return bl.Baseline(name, "distance", inputs, lambda seed: bl.spectrum_regressor(
        mlp, bl.DISTANCE_HIDDEN, seed, bl.columns(slice(None))),
        description or DISTANCE_READOUTS[readout])


# How a tuned read-out sees the spike counts: as they are, or each event's counts as shares
# of its total over the bank, with log(1 + total) beside them: the activity's shape apart from
# its loudness, which varies with the impact and the distance (the FFT-MLP scales each
# spectrum to its peak for the same reason). Latencies, spans and the decay code are left.
SCALINGS = {"counts": "spike counts as they are",
            "share": "each count as a share of the event's total, and log(1 + total)"}


def code_rows(codes: dict, readout: str, scaling: str = "counts") -> np.ndarray:
    """A tuned read-out's input rows (``TUNED_READOUTS``) from a bank's codes (``counts``,
    ``latency_s``, ``span_s``, ``binned_counts`` flattened, ``decay``; one row per event),
    the counts scaled by ``scaling`` (``SCALINGS``)."""
    check(scaling in SCALINGS, "scaling", scaling, f"one of {sorted(SCALINGS)}")
    parts, extra = dict(codes), []
    if scaling == "share":
        total = np.asarray(codes["counts"], dtype=float).sum(axis=1, keepdims=True)
        for name in ("counts", "binned_counts", "late_binned_counts"):
            parts[name] = np.asarray(codes[name], dtype=float) / np.maximum(total, 1.0)
        extra = [np.log1p(total)]
    return np.hstack([parts[c] for c in TUNED_READOUTS[readout][0]] + extra).astype(
        np.float32)


def input_of(name: str) -> str:
    """The input set a spiking decoder reads (the training-free ones: the low band)."""
    if name in TUNED_READOUTS:
        return name
    return SPIKING_MLPS[name][0] if name in SPIKING_MLPS else "spiking_low"


def decay_code(binned: np.ndarray) -> np.ndarray:
    """Per neuron, log((n_{b+1} + 1) / (n_b + 1)) of successive time bins' spike counts
    (events, neurons, bins → events, neurons × (bins − 1)): how fast activity dies after the
    onset, the damping a rate averages away."""
    logs = np.log1p(np.asarray(binned, dtype=float))
    return np.diff(logs, axis=2).reshape(len(logs), -1)


def codes_of(counts, latency_s, span_s, binned, bin_starts_s) -> dict[str, np.ndarray]:
    """Every code of a tuned bank's spikes (``counts``, ``latency_s``, ``span_s``: events ×
    neurons; ``binned``: events × neurons × time bins starting at ``bin_starts_s``), one row
    per event: what ``code_rows`` reads."""
    binned = np.asarray(binned)
    n = len(binned)
    late = np.asarray(bin_starts_s) >= LATE_S - 1e-9
    return {"counts": np.asarray(counts), "latency_s": np.asarray(latency_s),
            "span_s": np.asarray(span_s), "binned_counts": binned.reshape(n, -1),
            "late_binned_counts": binned[:, :, late].reshape(n, -1),
            "decay": decay_code(binned)}


def _codes(spikes: xr.Dataset, events) -> dict[str, np.ndarray]:
    """Every code of a tuned bank's ``spikes`` on ``events``, one row per event."""
    sp = spikes.sel(event=events)
    return codes_of(sp["counts"].values, sp["latency_s"].values, sp["span_s"].values,
                    sp["binned_counts"].values, sp["bin_start_s"].values)


def tuned_inputs(features: xr.Dataset, spikes: xr.Dataset) -> xr.Dataset:
    """The event features with one input matrix per tuned read-out (``TUNED_READOUTS``), from
    the tuned bank's ``spikes`` on the same events."""
    parts = _codes(spikes, features["event"].values)
    out = features.copy()
    for name, (codes, _) in TUNED_READOUTS.items():
        out[name] = (("event", f"{name}_feature"),
                     np.hstack([parts[c] for c in codes]).astype(np.float32))
    return out


# The read-outs every coder is compared on (``TUNED_READOUTS``' codes, by short name), and
# the names of the comparison's inputs: a coder's bank of n resonators read one way, and the
# neuron-free ceiling of its coded input (``spiking.coded_features``).
CODER_READOUTS = {"bins": "spiking_tuned_bins", "decay": "spiking_tuned_decay"}


def coder_input(label: str, n: int, readout: str) -> str:
    return f"coder_{label}_{n}_{readout}"


def ceiling_input(label: str, n: int) -> str:
    return f"ceiling_{label}_{n}"


def coder_inputs(features: xr.Dataset, spikes: xr.Dataset, label: str, n: int,
                 ceiling: np.ndarray) -> xr.Dataset:
    """The event features with coder ``label``'s bank of ``n`` resonators read each way of
    ``CODER_READOUTS`` and its coded input's ``ceiling`` features (rows: the same events)."""
    parts = _codes(spikes, features["event"].values)
    out = features.copy()
    for readout, tuned in CODER_READOUTS.items():
        name = coder_input(label, n, readout)
        out[name] = (("event", f"{name}_feature"), np.hstack(
            [parts[c] for c in TUNED_READOUTS[tuned][0]]).astype(np.float32))
    name = ceiling_input(label, n)
    out[name] = (("event", f"{name}_feature"), np.asarray(ceiling, dtype=np.float32))
    return out


def coder_baselines(labels, sizes, evaluation) -> list[bl.Baseline]:
    """An MLP 51 per coder, size and read-out, and one on each coding's ceiling features."""
    out = []
    for label in labels:
        for n in sizes:
            out += [mlp_baseline(coder_input(label, n, r), "material", coder_input(label, n, r),
                                 evaluation, f"MLP 51, {label} coder, {n} resonators: "
                                             f"{TUNED_READOUTS[t][1]}")
                    for r, t in CODER_READOUTS.items()]
            out.append(mlp_baseline(ceiling_input(label, n), "material",
                                    ceiling_input(label, n), evaluation,
                                    f"MLP 51 on the {label}-coded channels of the {n}-"
                                    "resonator bank, no neurons (the coding's ceiling)"))
    return out


def tuned_baselines(evaluation) -> list[bl.Baseline]:
    """An MLP 51 per tuned read-out."""
    return [mlp_baseline(name, "material", name, evaluation, f"MLP 51, tuned bank: {text}")
            for name, (_, text) in TUNED_READOUTS.items()]


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
        out["spiking_low_counts"] = (("event", "low_neuron"),
                                     sp["counts"].values[:, bands == "low"])
    return out


def neurons_per_input(spikes: xr.Dataset) -> dict:
    """Resonators per event behind each spiking input set (its filters, as NMF's n)."""
    bands = spikes["band"].values.astype(str)
    return {name: int(np.isin(bands, wanted).sum())
            for name, (wanted, _) in _available(spikes).items()}


def spiking_baselines(spikes: xr.Dataset, evaluation, law=None, around=None,
                      dominant_law=None, alphas: dict | None = None) -> list[bl.Baseline]:
    """Every spiking decoder the bank's bands allow (``evaluation``: the MLP settings of an
    ``evaluation.crossval.Evaluation``; ``law``: the low-mode law the training-free decoders
    invert, see ``spiking.DominantNeuronDistance``; None: this project's antenna's;
    ``dominant_law``: the dominant resonator's own (None: ``law``); ``around``: the
    centroid's neighbourhood of the dominant neuron, see ``spiking.CentroidDistance``;
    ``alphas``: an L2 penalty per MLP decoder's name in place of ``evaluation``'s)."""
    out = []
    bands = spikes["band"].values.astype(str)
    if "low" in set(bands):
        low_hz = spikes["neuron_hz"].values[bands == "low"]
        out.append(bl.Baseline("spiking_dominant", "distance", "spiking_low_counts",
                               lambda seed: DominantNeuronDistance(
                                   low_hz, law if dominant_law is None else dominant_law),
                               "dominant low-band resonator → inverse low-mode law "
                               "(Fig. 10E), no training"))
        out.append(bl.Baseline("spiking_centroid", "distance", "spiking_low_counts",
                               lambda seed: CentroidDistance(low_hz, law, around),
                               "rate-weighted centroid of the low band → inverse low-mode "
                               "law, no training"))
    available = _available(spikes)
    for name, (inputs, task, text) in SPIKING_MLPS.items():
        if inputs in available:
            out.append(mlp_baseline(name, task, inputs, evaluation, text,
                                    (alphas or {}).get(name)))
    return out


def mlp_baseline(name: str, task: str, inputs: str, evaluation,
                 description: str = "", alpha: float | None = None) -> bl.Baseline:
    """An MLP on spiking features: 20-5 for distance, 51 hidden for material (the FFT
    pipelines' layers, with their epoch budgets); ``alpha``: its L2 penalty in place of
    ``evaluation``'s (None: as set there)."""
    if task == "distance":
        mlp = evaluation.mlp if alpha is None else replace(evaluation.mlp, alpha=alpha)
        return bl.Baseline(name, task, inputs, lambda seed: bl.regressor_pipeline(
            mlp, bl.DISTANCE_HIDDEN, seed), description)
    mlp = evaluation.material_mlp if alpha is None else replace(evaluation.material_mlp,
                                                                 alpha=alpha)
    return bl.Baseline(name, task, inputs, lambda seed: bl.classifier_pipeline(
        mlp, bl.MATERIAL_HIDDEN, seed), description)


# -- array designs --------------------------------------------------------------------------
@dataclass
class Design:
    """One array variant: band ``band`` of the bank with ``changes`` (``Band`` fields)."""
    name: str
    band: str = "low"
    changes: dict = field(default_factory=dict)

    def __post_init__(self):
        bounds.declared(self)

    @classmethod
    def from_table(cls, table: dict, index: int, bank: SpikingBank) -> Design:
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
    processes for the bank's runs and the read-outs' fits (0: one per core; 1: this process;
    ``--scheduler`` attaches to a running cluster instead). ``tuned``: a ``TunedPlan`` table
    (empty: no tuned bank).
    """
    bank: dict = field(default_factory=dict)
    designs: list = field(default_factory=list)
    design_repetitions: int = 10
    cost_sample_events: int = 400
    workers: int = 1
    tuned: dict = field(default_factory=dict)

    def __post_init__(self):
        bounds.declared(self)
        bounds.positive_integer("design_repetitions", self.design_repetitions)
        bounds.positive_integer("cost_sample_events", self.cost_sample_events)
        bounds.integer("workers", self.workers, 0)

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

    def tuned_plan(self) -> TunedPlan | None:
        if not self.tuned:
            return None
        with specs.section("tuned"):
            return TunedPlan(**self.tuned)


# What a coder of the comparison may set (``[spiking.tuned.coders.LABEL]``): a tuning's coder
# fields; the channels' placement is the same for every coder.
CODER_KEYS = ("coder", "coder_options", "coder_amplitude", "threshold_g")


@dataclass
class TunedPlan:
    """The tuned bank (``[spiking.tuned]``): ``band_tuning.Tuning`` fields (``tuning``) for
    the bank every seed is scored on, tuned on ``calibration_repetitions`` repetitions of
    contacts generated with the study's seed + ``calibration_seed_offset`` (never the
    evaluated events, so never a test split); ``curve``: the numbers of resonators of the
    accuracy curve, each tuned the same way and scored on the events of the first
    ``curve_repetitions`` repetitions (first split) beside NMF with as many filters;
    ``duration_s`` and ``bin_edges_s``: the window each event is simulated for and its time
    bins. ``coders``: the coders compared side by side (label → ``CODER_KEYS`` fields of the
    tuning), each at every size of ``coder_sizes`` on the same channels, read as
    ``CODER_READOUTS`` and beside its coded input's neuron-free ceiling; their cost and the
    FFT pipeline's are the best of ``cost_repeats`` runs taken in turn."""
    tuning: dict = field(default_factory=dict)
    calibration_repetitions: int = 5
    calibration_seed_offset: int = 1000
    curve: list = field(default_factory=lambda: [24, 48, 72, 96, 144])
    curve_repetitions: int = 20
    duration_s: float = 0.5
    bin_edges_s: tuple = (0.075, 0.1, 0.15, 0.2, 0.3, 0.4)
    coders: dict = field(default_factory=dict)
    coder_sizes: list = field(default_factory=lambda: [24, 48])
    cost_repeats: int = 3

    def __post_init__(self):
        bounds.declared(self)
        bounds.positive_seconds("duration_s", self.duration_s)
        with specs.section("tuning"):
            self.base = Tuning(**specs.check_section({"tuning": self.tuning}, "tuning", Tuning))
        for name in ("calibration_repetitions", "curve_repetitions"):
            value = getattr(self, name)
            check(isinstance(value, int) and not isinstance(value, bool) and value >= 2, name,
                  value, "an integer >= 2")
        check(isinstance(self.calibration_seed_offset, int)
              and self.calibration_seed_offset >= 1, "calibration_seed_offset",
              self.calibration_seed_offset, "an integer >= 1 (the evaluated events' seed "
                                            "+ this: other contacts)")
        check(isinstance(self.curve, list) and all(
            isinstance(n, int) and n >= 1 for n in self.curve), "curve", self.curve,
            "a list of numbers of resonators")
        for n in self.curve:      # each point's own checks, before any work
            with specs.section("curve"):
                replace(self.base, n_resonators=n)
        check(isinstance(self.coders, dict) and all(
            isinstance(k, str) and k.isidentifier() for k in self.coders), "coders",
            self.coders, "a table of named coders, e.g. {delta = {coder = \"delta\"}}")
        check(isinstance(self.coder_sizes, list) and len(self.coder_sizes) >= 1 and all(
            isinstance(n, int) and not isinstance(n, bool) for n in self.coder_sizes),
            "coder_sizes", self.coder_sizes, "a list of numbers of resonators")
        check(isinstance(self.cost_repeats, int) and not isinstance(self.cost_repeats, bool)
              and 1 <= self.cost_repeats <= 20, "cost_repeats", self.cost_repeats,
              "an integer in [1, 20] (the cost is the best of these runs)")
        for label, table in self.coders.items():
            with specs.section(f"coders.{label}"):
                check(isinstance(table, dict) and set(table) <= set(CODER_KEYS), "coder",
                      table, f"a table of {', '.join(CODER_KEYS)}")
                for n in self.coder_sizes:
                    replace(self.base, n_resonators=n, **table)

    def coder_tunings(self) -> dict[tuple[str, int], Tuning]:
        """The tuning of each coder (by label) at each of ``coder_sizes``."""
        return {(label, n): replace(self.base, n_resonators=n, **table)
                for label, table in self.coders.items() for n in self.coder_sizes}

    def tunings(self) -> dict[int, Tuning]:
        """The main bank's tuning and one per curve point, by number of resonators."""
        sizes = {self.base.n_resonators, *self.curve, *(self.coder_sizes if self.coders else ())}
        return {n: replace(self.base, n_resonators=n) for n in sorted(sizes)}

    def bank(self, bands: dict, like: SpikingBank) -> SpikingBank:
        """A bank of ``bands`` with ``like``'s target and batching."""
        return SpikingBank(bands=bands, duration_s=self.duration_s, target=like.target,
                           batch_events=like.batch_events, bin_edges_s=self.bin_edges_s)
