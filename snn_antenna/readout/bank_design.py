"""A tuned resonator bank's design, the point of the bank-tuning search that sets it, and the
bank it makes once its channels are placed; the chosen bank as a file.

A design (``BankDesign``) is a recipe: ``band_tuning.Tuning`` fields for the channels, the
channels' b, the read-out that reads them, and a low-mode band for the distance. A point of the
bank-tuning search (``start_params`` gives the design's own) changes the channels' number,
placement, gains and step, b and the read-out. ``bank_of`` places the point's channels from
labelled contacts (``band_tuning.tune``) and returns the ``SpikingBank`` that runs.

``ChosenBank`` is the bank the bank-tuning study chose, as it writes it (``chosen_bank.toml``
in its output folder; ``networks/chosen_bank.toml`` is the one the baseline comparison reads):
the design, the trial's point and the contacts that placed its channels, so the same bank is
placed again from the same contacts, and what the study measured on it.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import tomli_w
import xarray as xr

from ..core import bounds, calibration
from ..core import spec as specs
from ..core.errors import SpecError, check
from ..core.files import atomic_write
from .band_tuning import Tuning, coarsest_dt_ms, tune
from .spiking import LOW_BAND, TARGETS, Band, SpikingBank
from .spiking_decoders import (
    DISTANCE_READOUTS,
    LOW_BAND_READOUTS,
    SCALINGS,
    TUNED_READOUTS,
    code_rows,
    codes_of,
    low_band_rows,
)


@dataclass
class BankDesign:
    """A tuned bank's recipe (the bank-tuning study's ``[bank]``).

    ``tuning``: ``band_tuning.Tuning`` fields; ``b``: the channels' b; ``readout``: a key
    of ``TUNED_READOUTS``, the counts seen as ``scaling`` (``SCALINGS``); ``filter_order``:
    each channel's Butterworth order.
    ``low_resonators`` resonators (0: none) read the antenna's low mode in a band of their
    own, spread in log over ``low_band_hz`` behind a ``low_lowpass_hz`` low-pass: the
    channels are placed where the *material* separates and never reach the low mode, whose
    frequency is where the contact's distance lives. The low band has its own b
    (``low_b``) and square-wave coder (``low_coder_amplitude`` above ``low_threshold_g``):
    at the channels' b a low resonator, once kicked, keeps firing near its own frequency
    whatever drives it; a little below, it fires only while the low mode drives it near its
    own, so which resonators fire in which time bin traces the mode's frequency.
    ``distance_readout`` (``spiking_decoders.DISTANCE_READOUTS``) reads the distance.
    ``duration_s``, ``bin_edges_s``, ``target`` and ``batch_events``: how the bank runs
    (``SpikingBank``)."""
    tuning: dict = field(default_factory=dict)
    b: float = 0.26
    readout: str = "spiking_tuned_bins"
    low_resonators: int = 0
    scaling: str = "counts"
    filter_order: int = 8
    low_band_hz: tuple = (7.0, 56.0)
    low_lowpass_hz: float = 60.0
    low_b: float = 0.26
    low_coder_amplitude: float = 0.15
    low_threshold_g: float = 0.2
    distance_readout: str = "spiking_bank_rows"
    duration_s: float = 0.5
    bin_edges_s: tuple = (0.075, 0.1, 0.15, 0.2, 0.3, 0.4)
    target: str = "standalone"
    batch_events: int = 400

    def __post_init__(self):
        bounds.declared(self)
        with specs.section("tuning"):
            self.base = Tuning(**specs.check_section({"tuning": self.tuning}, "tuning", Tuning))
        bounds.number("b", self.b, 0.0, 2.0, lo_open=True)
        bounds.choice("readout", self.readout, tuple(TUNED_READOUTS))
        bounds.choice("scaling", self.scaling, tuple(SCALINGS))
        bounds.integer("filter_order", self.filter_order, 1, 8)
        bounds.positive_seconds("duration_s", self.duration_s)
        lo, hi = bounds.pair("low_band_hz", self.low_band_hz, strict=True, unit=" in Hz")
        check(lo > 0, "low_band_hz", self.low_band_hz, "[low, high] in Hz, 0 < low < high")
        bounds.number("low_lowpass_hz", self.low_lowpass_hz, hi, bounds.MAX_RATE_HZ,
                      unit=" Hz")
        bounds.number("low_b", self.low_b, 0.0, 2.0, lo_open=True)
        bounds.number("low_coder_amplitude", self.low_coder_amplitude, 0.0, lo_open=True)
        bounds.number("low_threshold_g", self.low_threshold_g, 0.0, unit=" g")
        bounds.choice("distance_readout", self.distance_readout, tuple(DISTANCE_READOUTS))
        bounds.choice("target", self.target, TARGETS)
        for name, lo in (("batch_events", 1), ("low_resonators", 0)):
            value = getattr(self, name)
            check(isinstance(value, int) and not isinstance(value, bool) and value >= lo,
                  name, value, f"an integer >= {lo}")
        check(self.low_resonators >= 1 or self.distance_readout not in LOW_BAND_READOUTS,
              "low_resonators", self.low_resonators,
              f"an integer >= 1: distance_readout '{self.distance_readout}' reads the low "
              "band")

    def design_fields(self) -> dict:
        """The design's own fields (``BankDesign``'s, not a subclass's), as a spec table."""
        return {f.name: getattr(self, f.name) for f in fields(BankDesign)}


def start_params(design: BankDesign) -> dict:
    """The design as a point of the search space (the search's first trial)."""
    t = design.base
    return {"channels": t.n_channels,
            "per_channel": t.resonators_per_channel // max(1, len(t.gains)),
            "range_low_hz": float(t.range_hz[0]), "range_high_hz": float(t.range_hz[1]),
            "quantile": float(t.quantile), "spread": float(t.spread), "b": float(design.b),
            "gain": float(np.sqrt(t.gains[0] * t.gains[-1]) if t.gains
                          else t.coder_options.get("gain", 150.0)),
            "gain_levels": max(1, len(t.gains)),
            "gain_ratio": float((t.gains[-1] / t.gains[0]) ** (1 / (len(t.gains) - 1)))
                          if len(t.gains) > 1 else 7.0,
            "k_dt_factor": 1.0,
            "coder_amplitude": float(t.coder_amplitude), "threshold_g": float(t.threshold_g),
            "low_resonators": int(design.low_resonators), "readout": design.readout,
            "scaling": design.scaling, "filter_order": int(design.filter_order)}


# A point's keys: every one ``bank_of`` reads; those that count, with their least value
POINT_KEYS = tuple(start_params(BankDesign()))
POINT_INTEGERS = {"channels": 1, "per_channel": 1, "gain_levels": 1, "low_resonators": 0,
                  "filter_order": 1}


def bank_of(params: dict, design: BankDesign, counts, labels, attrs) -> SpikingBank:
    """The bank of a point of the space, its channels placed from ``counts`` and ``labels``
    (labelled contacts recorded at ``attrs``: rate, ADC bits, full scale)."""
    t = design.base
    lo, hi = params["range_low_hz"], params["range_high_hz"]
    if hi <= lo:
        raise SpecError("range_high_hz", hi, f"above range_low_hz {lo:g} Hz")
    options = dict(t.coder_options)
    if t.coder == "analog":
        options["gain"] = float(params["gain"])
    levels = int(params["gain_levels"])
    gains = tuple(options["gain"] * float(params["gain_ratio"]) ** (i - (levels - 1) / 2)
                  for i in range(levels)) if levels > 1 else ()
    per_channel = params["per_channel"] * levels
    tuning = replace(t, n_resonators=params["channels"] * per_channel, gains=gains,
                     max_k_dt=float(t.max_k_dt * params["k_dt_factor"]),
                     per_channel=per_channel, max_channels=params["channels"],
                     range_hz=(lo, hi), quantile=params["quantile"], spread=params["spread"],
                     coder_amplitude=params["coder_amplitude"],
                     threshold_g=params["threshold_g"], coder_options=options)
    n_samples = int(round(design.duration_s * attrs[0]))
    bands = tune(counts[:, :n_samples], labels, *attrs, tuning)
    order = int(params.get("filter_order", design.filter_order))
    bands = {k: replace(b, filter_order=order, b=float(params["b"])) for k, b in bands.items()}
    if params.get("low_resonators", 0) > 0:
        bands["low"] = low_band(int(params["low_resonators"]), design, tuning)
    return SpikingBank(bands=bands, duration_s=design.duration_s, target=design.target,
                       batch_events=design.batch_events, bin_edges_s=design.bin_edges_s)


def low_band(n: int, design: BankDesign, tuning: Tuning) -> Band:
    """``n`` resonators in log over ``design.low_band_hz`` behind a low-pass (the antenna's
    low mode, whose frequency carries the contact's distance), with the low band's own b and
    square-wave coder (``BankDesign``), at the coarsest step the channels' k·dt allows
    (``LOW_BAND``'s driven Hz per unit k)."""
    lo, hi = (float(f) for f in design.low_band_hz)
    return Band(n_neurons=n, band_hz=(lo, hi), spacing="log", b=float(design.low_b),
                coder_amplitude=float(design.low_coder_amplitude),
                threshold_g=float(design.low_threshold_g),
                lowpass_hz=float(design.low_lowpass_hz), highpass_hz=None,
                hz_per_k=LOW_BAND.hz_per_k, method=tuning.method,
                dt_ms=coarsest_dt_ms(hi, LOW_BAND.hz_per_k, tuning.max_k_dt),
                filter_order=LOW_BAND.filter_order, coder="square")


def neuron_steps_per_event(bank: SpikingBank, rate_hz: float) -> float:
    """Resonator-steps a contact costs the bank: each channel's resonators × its steps."""
    return float(sum(b.n_neurons * round(bank.duration_s * 1000.0 / (b.dt_ms or bank.dt_ms))
                     for b in bank.bands.values()))


def material_rows(spikes: xr.Dataset, ids, readout: str, scaling: str) -> np.ndarray:
    """A read-out's input rows (``spiking_decoders.code_rows``) from a bank's stored spikes."""
    sp = spikes.sel(event=ids)
    codes = codes_of(sp["counts"].values, sp["latency_s"].values, sp["span_s"].values,
                     sp["binned_counts"].values, sp["bin_start_s"].values)
    return code_rows(codes, readout, scaling)


def distance_rows(spikes: xr.Dataset, ids, readout: str, material_rows: np.ndarray
                    ) -> np.ndarray:
    """The distance read-out's input rows (``DISTANCE_READOUTS``): the low band's counts in
    every time bin, or the bank's material read-out rows ``material_rows``."""
    if readout == "spiking_bank_rows":
        return material_rows
    sp = spikes.sel(event=ids)
    return low_band_rows(sp["binned_counts"].values, sp["band"].values)


@dataclass
class ChosenBank:
    """The bank the bank-tuning study chose (``chosen_bank.toml``): ``design``
    (``BankDesign`` fields), the trial's ``point`` (every key of ``POINT_KEYS``),
    ``placement``: the contacts that placed its channels (the bench set's spec with seed +
    ``seed_offset`` and ``repetitions`` repetitions), ``trial``: its number in the search;
    ``measured``: what the study's run measured (its command, commit and front), kept as the
    record of where the bank came from."""
    design: dict = field(default_factory=dict)
    point: dict = field(default_factory=dict)
    placement: dict = field(default_factory=lambda: {"seed_offset": 1000, "repetitions": 10})
    trial: int = 0
    measured: dict = field(default_factory=dict)

    def __post_init__(self):
        bounds.declared(self)
        with specs.section("design"):
            self.bank_design = BankDesign(**specs.check_section(
                {"design": self.design}, "design", BankDesign))
        check(isinstance(self.point, dict) and set(self.point) == set(POINT_KEYS), "point",
              sorted(self.point) if isinstance(self.point, dict) else self.point,
              f"a table of every key of {list(POINT_KEYS)}")
        with specs.section("point"):
            for key in ("readout", "scaling"):
                bounds.choice(key, self.point[key], tuple(TUNED_READOUTS if key == "readout"
                                                          else SCALINGS))
            for key, lo in POINT_INTEGERS.items():
                bounds.integer(key, self.point[key], lo, 8 if key == "filter_order" else 10**6)
            for key in set(POINT_KEYS) - set(POINT_INTEGERS) - {"readout", "scaling"}:
                bounds.number(key, self.point[key], 0.0, lo_open=key != "threshold_g")
        with specs.section("placement"):
            check(isinstance(self.placement, dict)
                  and set(self.placement) == {"seed_offset", "repetitions"}, "placement",
                  self.placement, "a table of seed_offset and repetitions")
            for key, lo in (("seed_offset", 1), ("repetitions", 2)):
                value = self.placement[key]
                check(isinstance(value, int) and not isinstance(value, bool) and value >= lo,
                      key, value, f"an integer >= {lo}")
        bounds.integer("trial", self.trial, 0, 10**9)

    def bank(self, counts, labels, attrs) -> SpikingBank:
        """The bank, its channels placed from the placement contacts' ``counts``, ``labels``
        (recorded at ``attrs``)."""
        return bank_of(self.point, self.bank_design, counts, labels, attrs)

    def table(self) -> dict:
        """The file's table (TOML has no null: a field that is None is left out)."""
        def plain(value):
            if isinstance(value, dict):
                return {k: plain(v) for k, v in value.items() if v is not None}
            if isinstance(value, (list, tuple)):
                return [plain(v) for v in value]
            if isinstance(value, np.generic):
                return value.item()
            return value
        return plain({k: v for k, v in asdict(self).items()})


def write_chosen(path: Path, chosen: ChosenBank, header: str) -> None:
    """``chosen`` as TOML at ``path`` (atomically), under ``header``'s comment lines."""
    comment = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    table = chosen.table()
    table["design"] = calibration.referenced(table["design"])
    atomic_write(path, comment + tomli_w.dumps(table))
