"""The read-outs of the bench data set side by side: summary, intervals, costs, tables.

A ``Comparison`` holds what one run produced (the processed events, their signal statistics,
every baseline's result over seeds, the measured feature costs and the spiking bank's
description); from it come the summary (every number mean ± sd over seeds, intervals where
two seeds or more allow one), every test prediction (so any number can be recomputed) and
the rows of the report's tables.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..report import stats
from ..report.labels import READOUTS
from .crossval import BaselineResult
from .signal import PAPER_SIGNAL
from ..readout.spiking_decoders import (
    CODER_READOUTS,
    TRAINING_FREE,
    TUNED_READOUTS,
    ceiling_input,
    coder_input,
    input_of,
)

LABELS = READOUTS      # the read-outs' names, shared with the results page
FULL_SPECTRUM = "mlp_spectrum_material"    # the material read-out the others are held to
# the chosen bank's material and distance read-outs (the baseline comparison's chosen bank)
CHOSEN = ("spiking_chosen", "spiking_chosen_distance")


def label(name: str) -> str:
    if name.startswith("nmf_"):
        return f"NMF-{name.split('_')[1]} → MLP"
    return LABELS.get(name, name.replace("_", " "))


def _interval(values, bounds=None) -> dict:
    """Mean of per-split values with its 95 % interval and n (just the mean below 2)."""
    values = np.asarray(values, dtype=float)
    if len(values) < 2:
        return {"mean": float(values.mean()), "n": len(values)}
    return stats.mean_interval(values, bounds=bounds).as_dict()


def _difference(a, b) -> dict:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if len(a) < 2:
        return {"mean": float((a - b).mean()), "n": len(a)}
    return stats.paired_difference(a, b).as_dict()


def _mean_sd(summary: dict, key: str, **more) -> dict:
    return {"mean": summary[key], "sd": summary[f"{key}_sd"], **more}


@dataclass
class Comparison:
    """What one run produced; ``spiking`` describes the bank (None: FFT baselines only)."""
    features: xr.Dataset
    signal: dict
    results: dict[str, BaselineResult]
    skipped: dict
    costs: dict
    data: dict
    spiking: dict | None = None
    designs: list = field(default_factory=list)
    tuned: dict | None = None      # the tuned bank: channels, calibration, curve
    coders: dict | None = None     # the coders compared: their settings, sizes and costs
    chosen: dict | None = None     # the chosen bank (bank tuning's): placement, point, costs
    # the chosen bank's SpikingBank and the contacts that placed it (its figure), not stored
    chosen_bank: tuple | None = None

    @property
    def materials(self) -> list[str]:
        return sorted(set(self.features["material"].values.astype(str)))

    def of_task(self, task: str) -> dict[str, dict]:
        return {k: r.summary for k, r in self.results.items() if r.baseline.task == task}

    def summary(self, timing: dict) -> dict:
        """Every number of the run (``timing``: wall times of its stages)."""
        dist, mat = self.of_task("distance"), self.of_task("material")
        nmf = [{"n": int(k.split("_")[1]), "accuracy": v["accuracy"],
                "accuracy_sd": v["accuracy_sd"]} for k, v in mat.items() if k.startswith("nmf_")]
        two = next(iter(self.of_task("two_material").values()), None)
        out = {
            "materials": self.materials,
            "calibration": {"ours": self.signal, "paper": PAPER_SIGNAL},
            "distance_rmse_mm": {k: _mean_sd(v, "rmse_mm", n_seeds=v["n_seeds"])
                                 for k, v in dist.items()},
            "material_accuracy": {**{k: _mean_sd(v, "accuracy", n_seeds=v["n_seeds"])
                                     for k, v in mat.items() if not k.startswith("nmf_")},
                                  "nmf_curve": sorted(nmf, key=lambda r: r["n"])},
            "two_material": ({k: two[k] for k in ("rmse_mm", "rmse_mm_sd", "accuracy",
                                                  "accuracy_sd")} if two else None),
            "timing": {**timing, **{k: {"fit_s": r.summary["fit_s"],
                                        "predict_us_per_event": r.summary["predict_us_per_event"]}
                                    for k, r in self.results.items()}},
            "data": {**self.data, "n_processed": int(self.features.sizes["event"]),
                     "skipped": self.skipped, "n_bins": int(self.features.sizes["freq_hz"])},
            "cost_us_per_event": self.cost_per_event(),
            "feature_costs": self.costs,
        }
        if self.spiking is not None:
            out["spiking"] = self._spiking_summary(dist, mat)
        if self.chosen is not None:
            out["chosen_bank"] = {**self.chosen, **self.against_fft_paired(CHOSEN)}
        return out

    def against_fft_paired(self, names: tuple[str, str]) -> dict:
        """A material and a distance read-out against the FFT's on the same splits (paired
        by split: the accuracy's ratio and difference, the rmse's difference; each with its
        interval, n and verdict)."""
        material, distance = (self.results.get(n) for n in names)
        fft, fft_distance = self.results.get(FULL_SPECTRUM), self.results.get("mlp_spectrum")
        out = {}
        if material is not None and fft is not None:
            acc, ref = material.values("accuracy"), fft.values("accuracy")
            out["accuracy"] = _interval(acc, (0.0, 1.0))
            out["fft_mlp_accuracy"] = _interval(ref, (0.0, 1.0))
            out["accuracy_to_fft_mlp"] = _interval(acc / ref)
            out["accuracy_minus_fft_mlp"] = _difference(acc, ref)
        if distance is not None and fft_distance is not None:
            rmse, ref = distance.values("rmse_mm"), fft_distance.values("rmse_mm")
            out["distance_rmse_mm"] = _interval(rmse, (0.0, np.inf))
            out["fft_mlp_distance_rmse_mm"] = _interval(ref, (0.0, np.inf))
            out["distance_rmse_minus_fft_mlp"] = _difference(rmse, ref)
        return out

    def _spiking_summary(self, dist: dict, mat: dict) -> dict:
        return {
            "distance_rmse_mm": {k: _mean_sd(v, "rmse_mm") for k, v in dist.items()
                                 if k.startswith("spiking_")},
            "material_accuracy": {k: _mean_sd(v, "accuracy") for k, v in mat.items()
                                  if k.startswith("spiking_")},
            "against_fft": self.against_fft(),
            # the default read-out's (the chosen bank's, else the tuned bank's) when there is one
            "cost": (self.costs.get(CHOSEN[0]) or self.costs.get("spiking_tuned")
                     or self.costs.get("spiking")),
            "cost_hand_set_bank": self.costs.get("spiking"), **self.spiking,
            "designs": list(self.designs), "tuned": self.tuned,
            "coders": self.coder_table()}

    def coder_table(self) -> list[dict]:
        """Per coder, size and read-out: accuracy over the splits (interval, n), its share
        of the full-spectrum MLP, the neuron-free ceiling of the coded input, what coding
        and the resonators each lose (paired by split), and the cost per event beside the
        FFT pipeline's, both measured in this run (best of n)."""
        if not self.coders:
            return []
        fft = self.results.get(FULL_SPECTRUM)
        fft_us = self.costs.get("fft", {}).get("features_us_per_event")
        rows = []
        for label, table in self.coders["coders"].items():
            for n in self.coders["sizes"]:
                ceiling = self.results.get(ceiling_input(label, n))
                cost = self.coders["costs"].get(f"coder_{label}_{n}", {})
                for readout in CODER_READOUTS:
                    r = self.results.get(coder_input(label, n, readout))
                    if r is None:
                        continue
                    acc = r.values("accuracy")
                    row = {"coder": label, "kind": table.get("coder", "square"),
                           "resonators": n, "readout": readout, "n_splits": len(acc),
                           "accuracy": _interval(acc, (0.0, 1.0)),
                           "cost_us_per_event": cost.get("features_us_per_event"),
                           "cost_best_of": cost.get("best_of"),
                           "cost_of_fft": (cost["features_us_per_event"] / fft_us
                                           if cost and fft_us else None)}
                    if fft is not None:
                        row["of_fft_mlp"] = _interval(acc / fft.values("accuracy"))
                    if ceiling is not None:
                        top = ceiling.values("accuracy")
                        row["ceiling"] = _interval(top, (0.0, 1.0))
                        row["lost_to_resonators"] = _difference(top, acc)
                        if fft is not None:
                            row["lost_to_coding"] = _difference(fft.values("accuracy"), top)
                    rows.append(row)
        return rows

    def cost_per_event(self) -> dict[str, float]:
        """Feature extraction + decoder, µs per event. The bank runs every band at once;
        each spiking read-out is charged its bands' share (the cost per neuron-step is the
        same across bands: they share one NeuronGroup)."""
        neurons = (self.spiking or {}).get("neurons", {})
        total = (self.spiking or {}).get("neurons_per_event", 1)
        out = {}
        for k, r in self.results.items():
            if k.startswith("ceiling_"):  # an analysis of the coded input, not a read-out
                continue
            kind = "spiking" if k.startswith("spiking_") else "fft"
            if k in TUNED_READOUTS:      # its own bank, charged whole
                kind = "spiking_tuned"
            if k in CHOSEN:              # the chosen bank, charged whole
                kind = CHOSEN[0]
            costs = self.costs
            if k.startswith("coder_"):   # a compared coder's bank, charged whole
                costs, kind = (self.coders or {}).get("costs", {}), k.rsplit("_", 1)[0]
            front = costs.get(kind, {}).get("features_us_per_event", 0.0)
            if kind == "spiking":
                front *= neurons.get(input_of(k), total) / total
            out[k] = front + r.summary["predict_us_per_event"]
        return out

    def against_fft(self) -> dict:
        """Each spiking material read-out as a fraction of the full-spectrum MLP (per seed,
        then mean and interval) and against NMF with as many filters as it has resonators
        (paired by seed: the difference, its interval and verdict)."""
        fft = self.results.get(FULL_SPECTRUM)
        neurons = (self.spiking or {}).get("neurons", {})
        out = {}
        for name, r in self.results.items():
            if not (name.startswith("spiking_") and r.baseline.task == "material") or not fft:
                continue
            acc = r.values("accuracy")
            chosen = name in CHOSEN and self.chosen is not None     # its own bank, whole
            row = {"input": name if chosen else input_of(name),
                   "neurons": self.chosen["resonators"] if chosen
                   else neurons.get(input_of(name)),
                   "accuracy": float(acc.mean())}
            ratio = acc / fft.values("accuracy")
            row["fraction_of_fft_mlp"] = float(ratio.mean())
            if len(acc) >= 2:
                row["fraction_interval"] = stats.mean_interval(ratio).as_dict()
            nmf = self.results.get(f"nmf_{row['neurons']}")
            if nmf is not None:
                row["nmf_same_n"] = float(nmf.values("accuracy").mean())
                if len(acc) >= 2:
                    row["minus_nmf_same_n"] = stats.paired_difference(
                        acc, nmf.values("accuracy")).as_dict()
            out[name] = row
        return out

    def predictions(self) -> dict:
        """Every test prediction, with each event's repetition, so a reader can recompute
        any number and check that no contact of a test repetition was trained on."""
        folds = {}
        for name, r in self.results.items():
            folds[name] = [{
                "seed": f.seed, "test_event": r.event[f.test_index].tolist(),
                "train_event": r.event[f.train_index].tolist(),
                "true": np.asarray(r.y[f.test_index]).tolist(),
                "predicted": np.asarray(f.prediction).tolist()} for f in r.folds]
        repetition = zip(self.features["event"].values.tolist(),
                         self.features["repetition"].values.tolist())
        return {"task": {n: r.baseline.task for n, r in self.results.items()}, "folds": folds,
                "repetition": {str(k): int(v) for k, v in repetition}}


# -- table rows -----------------------------------------------------------------------------
def result_rows(summary: dict) -> list[dict]:
    """Mean ± sd over seeds of every trained read-out."""
    rows = [{"pipeline": label(k), "task": "distance rmse (mm)",
             "ours": f"{v['mean']:.2f} ± {v['sd']:.2f}"}
            for k, v in summary["distance_rmse_mm"].items() if k not in TRAINING_FREE]
    task = f"{len(summary['materials'])} materials (%)"
    for k, v in summary["material_accuracy"].items():
        if k == "nmf_curve":
            rows += [{"pipeline": label(f"nmf_{r['n']}"), "task": task,
                      "ours": f"{100 * r['accuracy']:.1f} ± {100 * r['accuracy_sd']:.1f}"}
                     for r in v]
        else:
            rows.append({"pipeline": label(k), "task": task,
                         "ours": f"{100 * v['mean']:.1f} ± {100 * v['sd']:.1f}"})
    two = summary["two_material"]
    if two:
        pair = "/".join(two.get("materials", ["wood", "aluminium"]))
        rows.append({"pipeline": f"5-8-2 MLP, {pair}", "task": "distance (mm), material (%)",
                     "ours": f"{two['rmse_mm']:.2f}, {100 * two['accuracy']:.1f}"})
    return rows


def cost_items(summary: dict) -> list[tuple[str, dict]]:
    """(pipeline, its fit and predict times), in the order of the cost table's numbers."""
    return [(k, v) for k, v in summary["timing"].items()
            if isinstance(v, dict) and k in summary["cost_us_per_event"]]


def cost_rows(summary: dict) -> list[dict]:
    task = {k: "distance" for k in summary["distance_rmse_mm"]} | {"mlp_5_8_2": "wood/aluminium"}
    return [{"#": i + 1, "pipeline": label(k), "task": task.get(k, "material"),
             "features + decoder (µs/event)": summary["cost_us_per_event"][k],
             "fit (s)": v["fit_s"]} for i, (k, v) in enumerate(cost_items(summary))]


def spiking_rows(summary: dict) -> list[dict]:
    """Each spiking material read-out beside the full-spectrum MLP and NMF of its size."""
    rows, cost = [], summary["cost_us_per_event"]
    for k, row in summary["spiking"].get("against_fft", {}).items():
        diff, frac = row.get("minus_nmf_same_n"), row.get("fraction_interval")
        rows.append({
            "read-out": label(k), "resonators": row["neurons"],
            "accuracy (%)": f"{100 * row['accuracy']:.1f}",
            "of FFT-MLP": (f"{100 * row['fraction_of_fft_mlp']:.0f} %" + (
                f" ({100 * frac['low']:.0f}–{100 * frac['high']:.0f})" if frac else "")),
            "NMF, same n (%)": (f"{100 * row['nmf_same_n']:.1f}" if "nmf_same_n" in row
                                else "—"),
            "minus NMF": (f"{100 * diff['mean']:+.1f} ({diff['verdict']}, n {diff['n']})"
                          if diff else "—"),
            "µs/event": f"{cost.get(k, 0):.0f}"})
    return rows


def spiking_distance_rows(summary: dict) -> list[dict]:
    cost = summary["cost_us_per_event"]
    return [{"read-out": label(k), "distance rmse (mm)": f"{v['mean']:.2f} ± {v['sd']:.2f}",
             "µs/event": f"{cost.get(k, 0):.0f}"}
            for k, v in summary["spiking"]["distance_rmse_mm"].items() if k not in TRAINING_FREE]


def design_rows(designs: list[dict]) -> list[dict]:
    return [{"design": d["design"], "band": d["band"], "change": d["change"],
             "neurons": d["n_neurons"], "distance (mm)": f"{d['distance_rmse_mm']:.2f}",
             "material (%)": f"{100 * d['material_accuracy']:.1f}",
             "µs/event": f"{d['wall_us_per_event']:.0f}"} for d in designs]


def tuned_curve_rows(summary: dict) -> list[dict]:
    """The tuned bank's accuracy vs resonators beside NMF-n (same events and split)."""
    return [{"resonators": r["n"], "channels": r["channels"],
             "spiking (%)": f"{100 * r['spiking']:.1f}", "NMF-n (%)": f"{100 * r['nmf']:.1f}",
             "of FFT-MLP": f"{100 * r['spiking'] / r['fft_mlp']:.0f} %",
             "neuron-steps/event": f"{r['neuron_steps_per_event']:.3g}",
             "wall µs/event (with compiling)": f"{r['wall_us_per_event']:.0f}"}
            for r in summary["spiking"]["tuned"]["curve"]]


def tuned_text(summary: dict) -> str:
    t, curve = summary["spiking"]["tuned"], summary["spiking"]["tuned"]["curve"]
    c = summary["feature_costs"].get("spiking_tuned") or {}
    fft_us = summary["feature_costs"]["fft"]["features_us_per_event"]
    best = (f", best of {c['best_of']} runs taken in turn with the FFT's" if c.get("best_of")
            else "")
    channels = "; ".join(f"{ch['pass_hz'][0]:g}-{ch['pass_hz'][1]:g} Hz ×{ch['resonators']}"
                         for ch in t["channels"])
    return (f"Tuned bank: {t['neurons']} resonators in {len(t['channels'])} channels placed "
            f"from {t['calibration_events']} calibration contacts of seed "
            f"{t['calibration_seed']} (never evaluated), "
            f"{t.get('coder', {}).get('coder', 'square')} "
            f"coder: {channels}. Its cost (the default read-out's), measured in "
            f"this run on {c.get('events_measured')} events{best}: "
            f"{c.get('features_us_per_event', 0):.0f} µs per event (coding + Brian2 "
            f"{c.get('target')}), {c.get('features_us_per_event', 0) / fft_us:.1f} × the FFT "
            f"pipeline's {fft_us:.0f} µs; {c.get('neuron_steps_per_event', 0):.3g} "
            f"neuron-steps per event at {c.get('ns_per_neuron_step', 0):.1f} ns each. The "
            f"curve's {curve[0]['fft_mlp'] * 100:.1f} % full-spectrum MLP is on its own "
            f"events and split, not the table's.")


def spiking_cost_text(summary: dict) -> str:
    sp = summary["spiking"]
    c = sp.get("cost_hand_set_bank") or {}
    return (f"Cost of the hand-set bands, measured in this run on {c.get('events_measured')} "
            f"events: {c.get('features_us_per_event', 0):.0f} µs per event for the whole bank "
            f"({sp['neurons_per_event']} resonators, coding + Brian2 {c.get('target')}), "
            f"{c.get('neuron_steps_per_event', 0):.3g} neuron-steps per event, "
            f"{c.get('ns_per_neuron_step', 0):.1f} ns per neuron-step; dt {sp['dt_ms']} ms, "
            f"{sp['duration_s']} s per event. The default read-out (the tuned bank) is "
            f"costed below.")


def _pct(iv: dict | None, scale: float = 100.0) -> str:
    if not iv:
        return "—"
    if "low" not in iv:
        return f"{scale * iv['mean']:.1f} (n {iv['n']})"
    return f"{scale * iv['mean']:.1f} [{scale * iv['low']:.1f}–{scale * iv['high']:.1f}]"


def _lost(iv: dict | None) -> str:
    if not iv:
        return "—"
    if "low" not in iv:
        return f"{100 * iv['mean']:+.1f} (n {iv['n']}, too few to resolve)"
    return (f"{100 * iv['mean']:+.1f} [{100 * iv['low']:+.1f}–{100 * iv['high']:+.1f}]"
            + ("" if iv["resolved"] else ", not resolved"))


def coder_rows(summary: dict) -> list[dict]:
    """The coders side by side (``Comparison.coder_table``): each size and read-out."""
    return [{"coder": r["coder"], "resonators": r["resonators"], "read-out": r["readout"],
             "accuracy (%)": _pct(r["accuracy"]), "of FFT-MLP (%)": _pct(r.get("of_fft_mlp")),
             "ceiling, no neurons (%)": _pct(r.get("ceiling")),
             "lost to coding (points)": _lost(r.get("lost_to_coding")),
             "lost to resonators (points)": _lost(r.get("lost_to_resonators")),
             "µs/event": (f"{r['cost_us_per_event']:.0f}" if r["cost_us_per_event"] else "—"),
             "× FFT": f"{r['cost_of_fft']:.1f}" if r["cost_of_fft"] else "—",
             "n": r["n_splits"]}
            for r in summary["spiking"].get("coders", [])]


def data_text(summary: dict) -> str:
    d, sk = summary["data"], summary["data"]["skipped"]
    return (f"Data: {d['n_events']} generated events, {d['n_processed']} processed; "
            f"skipped: {sk.get('no_onset', 0)} without an onset, {sk.get('clipped', 0)} "
            f"clipped, {sk.get('no_decay_fit', 0)} without a decay fit; spectrum of "
            f"{d['n_bins']} bins at {d['rate_hz']:g} Hz.")
