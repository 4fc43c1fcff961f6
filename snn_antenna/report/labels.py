"""The words a reader sees for the keys results are stored under: a read-out's, a stage's, a
coder's bank and its ceiling (``coder_square_24_bins`` -> "square coder, 24 resonators: rate in
time bins"). Reports and the results page show these; the summaries keep the keys."""
from __future__ import annotations

import re

from .page import label as column_label

#: the read-outs of the baseline comparison, by the key its summary stores them under
READOUTS = {
    "linear_low_peak": "linear regression, low peak",
    "mlp_parametric": "MLP on 2 peaks (F, A)",
    "mlp_spectrum": "MLP, full spectrum",
    "mlp_spectrum_sub10": "MLP, spectrum in 10-bin bands",
    "mlp_low_half": "MLP, lower half of spectrum",
    "mlp_spectrum_material": "MLP 51, full spectrum",
    "mlp_parametric_material": "MLP 51 on 2 peaks (F, A, τ)",
    "mlp_5_8_2": "5-8-2 MLP, wood/aluminium",
    "spiking_dominant": "dominant resonator",
    "spiking_centroid": "rate centroid",
    "spiking_mlp_distance_low": "spiking MLP, low band",
    "spiking_mlp_distance": "spiking MLP, low + high",
    "spiking_mlp_material_high": "spiking MLP, high band",
    "spiking_mlp_material": "spiking MLP, low + high",
    "spiking_mlp_material_rod": "spiking MLP, + rod band, time bins",
    "spiking_tuned_rate": "tuned bank: rate",
    "spiking_tuned_timing": "tuned bank: latency + span",
    "spiking_tuned_bins": "tuned bank: rate in time bins",
    "spiking_tuned_decay": "tuned bank: rate + decay",
    "spiking_tuned_all": "tuned bank: rate, latency, span, bins",
    "spiking_tuned_late": "tuned bank: rate in the late time bins",
    "spiking_chosen": "chosen bank (bank tuning): its read-out",
    "spiking_chosen_distance": "chosen bank (bank tuning): its low band",
}

#: the stages of the input chain whose ceilings are measured (``evaluation.stage_ceilings``)
STAGE_TEXT = {
    "spectrum_2_axes": "window spectrum, both axes (no channels)",
    "spectrum_main_axis": "window spectrum, principal axis (after PCA 2→1)",
    "ideal_2_axes": "channels by ideal band-pass, both axes",
    "ideal_main_axis": "channels by ideal band-pass, principal axis",
    "band_pass": "after the chain's band-pass (Butterworth)",
    "centred": "after the centring (a band-pass chain has none: as band_pass)",
    "coded": "after the coder",
    "coded_statistics": "after the coder, read as the coder table's ceiling",
    "centred_2_axes": "after the band-pass (and centring, where the chain has it), both axes "
                      "(a bank per axis)",
    "coded_2_axes": "after the coder, both axes (a bank per axis)",
}

#: the read-out a coder's bank is compared on, by the short name its key ends with
CODER_READOUT_TEXT = {"bins": "rate in time bins", "decay": "rate + decay"}

_CODER = re.compile(r"coder_([a-z]+)_(\d+)_([a-z]+)")
_CEILING = re.compile(r"ceiling_([a-z]+)_(\d+)")


def readout_label(key) -> str:
    """A read-out's, a stage's or a coder's row as a reader names it; other keys as a column
    name is made (``report.page.label``)."""
    key = str(key)
    if key in READOUTS:
        return READOUTS[key]
    if key in STAGE_TEXT:
        return STAGE_TEXT[key]
    if key.startswith("nmf_") and key.split("_")[1].isdigit():
        return f"NMF-{key.split('_')[1]} → MLP"
    coder = _CODER.fullmatch(key)
    if coder and coder.group(3) in CODER_READOUT_TEXT:
        name, n, readout = coder.groups()
        return f"{name} coder, {n} resonators: {CODER_READOUT_TEXT[readout]}"
    ceiling = _CEILING.fullmatch(key)
    if ceiling:
        name, n = ceiling.groups()
        return f"{name} coder, {n} channels: ceiling of the coded input (no neurons)"
    return column_label(key)
