"""The model-selection protocol: the paper's targets and predictions, how a candidate's one
constant is calibrated (and calibrated again with one target left out), and how candidates
are ranked. Pure functions of the grid points' numbers, so they are tested without a run."""
from __future__ import annotations

import numpy as np

PAPER_PAIR = ("brass", "wood")

# name -> (paper's value, tolerance that normalises the residual, what it is)
CALIBRATION_TARGETS = {
    "material_accuracy_spectrum": (0.942, 0.05, "8 materials, full-spectrum MLP accuracy"),
    "wood_aluminium_sites": (12.0, 4.0, "sites where wood and aluminium τ_low differ "
                                        "(t-test, 10 contacts each, of 16)"),
}
# name -> (paper's value, the bound a candidate must meet, True if larger is better, what)
PREDICTIONS = {
    "nmf30_accuracy": (0.86, 0.80, True, "8 materials, NMF-30 accuracy"),
    "two_material_accuracy": (0.87, 0.80, True, "5-8-2 network, wood/aluminium accuracy"),
    "rmse_spectrum_mm": (1.71, 1.3 * 1.71, False, "distance rmse, full-spectrum MLP"),
    "rmse_two_peaks_mm": (2.93, 1.3 * 2.93, False, "distance rmse, MLP on the two peaks"),
    "brass_wood_rank": (1, 3, False, "rank of brass ↔ wood among the most confused pairs"),
}

# Per-seed numbers: name -> (baseline, its score)
SCORES = {"material_accuracy_spectrum": ("mlp_spectrum_material", "accuracy"),
          "nmf30_accuracy": ("nmf_30", "accuracy"),
          "two_material_accuracy": ("mlp_5_8_2", "accuracy"),
          "rmse_spectrum_mm": ("mlp_spectrum", "rmse_mm"),
          "rmse_two_peaks_mm": ("mlp_parametric", "rmse_mm")}


def confused_pairs(cm: np.ndarray, materials) -> list:
    """Every pair of classes with the share of their contacts taken for each other, most
    confused first (ties in the order of the materials)."""
    rates = []
    for i in range(len(materials)):
        for j in range(i + 1, len(materials)):
            r = (cm[i, j] + cm[j, i]) / max(1, cm[i].sum() + cm[j].sum())
            rates.append(((materials[i], materials[j]), float(r)))
    return sorted(rates, key=lambda x: -x[1])


def value(point: dict, name: str) -> float:
    """A grid point's number: the mean over seeds, or the data set's own statistic."""
    if name in point["per_seed"]:
        return float(np.mean(point["per_seed"][name]))
    return float(point[name])


def measured(point: dict, name: str) -> bool:
    """Whether the point holds ``name`` (the predictions are read at calibrated points)."""
    return name in point["per_seed"] or name in point


def residual(point: dict, targets) -> float:
    """Sum of the normalised calibration residuals over ``targets``."""
    return float(sum(abs(value(point, t) - CALIBRATION_TARGETS[t][0])
                     / CALIBRATION_TARGETS[t][1] for t in targets))


def meets_calibration(point: dict) -> bool:
    """Every calibration target within its tolerance: the candidate reproduces what it was
    fitted to. A candidate that cannot is not the physics, whatever it predicts."""
    return all(abs(value(point, t) - paper) <= tol
               for t, (paper, tol, _) in CALIBRATION_TARGETS.items())


def calibrated_point(points: list[dict]) -> dict | None:
    """The readable grid point that meets all calibration targets best (None: no point is
    readable). It reads the calibration targets alone: the predictions are measured there,
    and only there, once it is chosen."""
    readable = [p for p in points if "unreadable" not in p]
    if not readable:
        return None
    return min(readable, key=lambda p: residual(p, list(CALIBRATION_TARGETS)))


def choose(physics: str, points: list[dict]) -> dict:
    """The candidate's calibration (all targets) and its leave-one-target-out checks; the
    predictions are read at the calibrated point (``calibrated_point``)."""
    targets = list(CALIBRATION_TARGETS)
    unreadable = [p["strength"] for p in points if "unreadable" in p]
    best = calibrated_point(points)
    points = [p for p in points if "unreadable" not in p]
    if best is None:
        return {"physics": physics, "strength": None, "grid": unreadable,
                "unreadable": unreadable, "residual": None, "point": None, "loto": {},
                "calibrated": False, "criteria_met": {}, "n_met": 0, "shortfall": None}
    loto = {}
    for left_out in targets:
        others = [t for t in targets if t != left_out]
        pick = min(points, key=lambda p: residual(p, others))
        paper, tol, _ = CALIBRATION_TARGETS[left_out]
        loto[left_out] = {"strength": pick["strength"], "predicted": value(pick, left_out),
                          "paper": paper, "residual": (value(pick, left_out) - paper) / tol,
                          "same_strength_as_full": pick["strength"] == best["strength"]}
    met = criteria(best)
    return {"physics": physics, "strength": best["strength"],
            "grid": sorted([p["strength"] for p in points] + unreadable),
            "unreadable": unreadable,
            "residual": residual(best, targets), "point": best, "loto": loto,
            "calibrated": meets_calibration(best), "criteria_met": met,
            "n_met": sum(met.values()), "shortfall": shortfall(best)}


def criteria(point: dict) -> dict:
    """The acceptance bounds, one verdict per predicted quantity."""
    out = {}
    for name, (_, bound, larger, _) in PREDICTIONS.items():
        v = value(point, name)
        out[name] = bool(v >= bound if larger else v <= bound)
    return out


def shortfall(point: dict) -> float:
    """How far the predictions fall short of the bounds, summed as fractions of the bound."""
    total = 0.0
    for name, (_, bound, larger, _) in PREDICTIONS.items():
        v = value(point, name)
        total += max(0.0, (bound - v) / bound) if larger else max(0.0, v / bound - 1)
    return float(total)


def select(candidates: dict) -> dict:
    """Among the candidates that meet their calibration: most criteria met, then least
    shortfall. A candidate that misses its calibration is not eligible, however well it
    predicts (a model that gets its fitted numbers wrong has not earned its predictions).
    A candidate 'wins clearly' only if it meets every criterion and the default does not."""
    readable = [c for c in candidates.values() if c["point"] is not None]
    ranked = sorted((c for c in readable if c["calibrated"]),
                    key=lambda c: (-c["n_met"], c["shortfall"]))
    missed = sorted(c["physics"] for c in readable if not c["calibrated"])
    if not ranked:
        return {"chosen": None, "strength": None, "wins_clearly": False, "ranking": [],
                "not_calibrated": missed,
                "reason": "no candidate meets its calibration targets within their "
                          "tolerances" if readable else
                          "no candidate gave a signal the paper's processing could read"}
    chosen = ranked[0]
    default = candidates.get("current")
    clear = chosen["n_met"] == len(PREDICTIONS) and \
        (default is None or default["n_met"] < len(PREDICTIONS))
    reason = (f"meets its calibration and {chosen['n_met']} of {len(PREDICTIONS)} predicted "
              f"criteria, shortfall {chosen['shortfall']:.2f}")
    if default is not None and chosen is not default:
        reason += (f"; the current model meets {default['n_met']}, shortfall "
                   f"{default['shortfall']:.2f}")
    if missed:
        reason += f"; not eligible (calibration missed): {', '.join(missed)}"
    return {"chosen": chosen["physics"], "strength": chosen["strength"],
            "wins_clearly": bool(clear), "ranking": [c["physics"] for c in ranked],
            "not_calibrated": missed, "reason": reason}
