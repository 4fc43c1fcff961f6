"""Th*(speed): the coder threshold that speed calls for, and how well each way of setting it does.

From a scored Th × speed sweep (``evaluation.scoring``'s counts with dims speed_cm_s × scene ×
threshold_g): each speed's best Th maximises F1 over the pooled scenes of that speed, smoothed
over neighbouring thresholds (``choose_th_star``), and Th*(speed) is their monotone fit
(``monotone_th_star``): the shaking that Th must hide only grows with speed, and a few
contacts per speed make a single speed's argmax noisy (``fit_th_star`` does both).

``LookupTable`` interpolates trained Th* in log Th. ``MethodScores`` holds the scores of
several ways of setting Th (fixed values, a lookup, a gate) on the same scenes, grouped in seed
slots: the unit of every comparison is the slot (F1 pooled over its scenes), paired between
methods (``interval``, ``difference``, ``compare``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..report.stats import MIN_N_TO_RESOLVE, mean_interval, paired_difference, seeds_needed
from .scoring import Score

F1_BOUNDS = (0.0, 1.0)
NON_NEGATIVE = (0.0, np.inf)
TIE_TOLERANCE = 1e-9   # smoothed F1s this close to the best count as tied


def choose_th_star(thresholds: np.ndarray, f1: np.ndarray) -> float:
    """The Th > 0 of best F1, smoothed over neighbouring thresholds.

    A few contacts per speed make F1 at one Th noisy; averaging each Th's F1 with its two
    neighbours on the (log-spaced) grid picks the middle of a robust plateau rather than a
    lucky point at its edge. Ties: the geometric centre of the tied thresholds.
    """
    candidates = np.flatnonzero(thresholds > 0)
    smooth = np.array([np.mean(f1[max(i - 1, candidates[0]):i + 2]) for i in candidates])
    tied = thresholds[candidates][smooth >= smooth.max() - TIE_TOLERANCE]
    centre = np.exp(np.mean(np.log(tied)))
    return float(tied[np.argmin(np.abs(np.log(tied) - np.log(centre)))])


def monotone_th_star(speeds: np.ndarray, best_th: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Th*(speed): the non-decreasing fit (in log Th) of each speed's best threshold.

    The self-motion Th must hide grows with speed, so a speed whose argmax falls below a slower
    speed's is noise of a few contacts; isotonic regression pools such neighbours, weighted by
    how many contacts each speed scored.
    """
    from sklearn.isotonic import IsotonicRegression

    fit = IsotonicRegression(increasing=True).fit(speeds, np.log(best_th),
                                                  sample_weight=np.maximum(weights, 1))
    return np.exp(fit.predict(speeds))


def pooled_f1(counts: xr.Dataset) -> xr.DataArray:
    """F1 of pooled counts (0 where there is nothing to score)."""
    return (2 * counts.tp / (2 * counts.tp + counts.fp + counts.misses)).fillna(0.0)


@dataclass
class ThStarFit:
    """Th*(speed) from a scored sweep, and the single Th a user would deploy without a gate."""
    speeds_cm_s: np.ndarray
    best_th_g: np.ndarray      # each speed's own best Th (smoothed argmax of F1)
    th_star_g: np.ndarray      # their monotone fit
    sweep_fixed_th_g: float    # best F1 over every speed of the sweep, chosen the same way

    def at(self, speeds) -> np.ndarray:
        """Th* at swept speeds (exact matches only)."""
        return np.array([self.th_star_g[int(np.flatnonzero(self.speeds_cm_s == v)[0])]
                         for v in np.atleast_1d(speeds)])


def fit_th_star(ds: xr.Dataset) -> ThStarFit:
    """Fit Th*(speed) on a sweep's counts; adds the pooled ``f1``, ``fp_per_min``,
    ``latency_s``, ``best_th_g`` and ``th_star_g`` to ``ds`` for the report's tables."""
    thresholds, speeds = ds.threshold_g.values, ds.speed_cm_s.values
    pooled = ds.sum("scene")
    ds["f1"] = pooled_f1(pooled)
    ds["fp_per_min"] = pooled.fp / pooled.minutes
    ds["latency_s"] = pooled.latency_sum_s / pooled.tp.where(pooled.tp > 0)
    best = np.array([choose_th_star(thresholds, ds.f1.isel(speed_cm_s=i).values)
                     for i in range(len(speeds))])
    scored = (pooled.tp + pooled.misses).max("threshold_g").values
    th_star = monotone_th_star(speeds, best, scored)
    ds["best_th_g"] = ("speed_cm_s", best, {"long_name": "argmax of smoothed F1 per speed"})
    ds["th_star_g"] = ("speed_cm_s", th_star, {"long_name": "monotone fit of best_th_g"})
    overall = pooled_f1(ds[["tp", "fp", "misses"]].sum(("speed_cm_s", "scene")))
    return ThStarFit(speeds, best, th_star, choose_th_star(thresholds, overall.values))


def f1_at(ds: xr.Dataset, speed: float, th: float) -> float:
    """Sweep F1 at ``speed`` for a Th between grid points (interpolated in log Th)."""
    grid = ds.threshold_g.values
    f1 = ds.f1.sel(speed_cm_s=speed).values
    positive = grid > 0
    return float(np.interp(np.log(th), np.log(grid[positive]), f1[positive]))


@dataclass(frozen=True)
class LookupTable:
    """Th at any speed from trained (speed, Th*) pairs, interpolated in log Th."""
    speeds_cm_s: np.ndarray
    th_g: np.ndarray

    def __call__(self, speeds) -> np.ndarray:
        return np.exp(np.interp(speeds, self.speeds_cm_s, np.log(self.th_g)))


def fixed_method(th: float) -> str:
    return f"fixed:{th:g}"


@dataclass
class MethodScores:
    """Scores of several Th methods on the same scenes, grouped in seed slots.

    ``categories[i]`` is the kind of a slot's i-th scene (every slot holds the same kinds).
    """
    categories: list[str]
    scores: dict = field(default_factory=dict)   # method -> slot -> scene index -> Score

    def add(self, method: str, slot: int, scene: int, score: Score) -> None:
        self.scores.setdefault(method, {}).setdefault(slot, {})[scene] = score

    @property
    def slots(self) -> list[int]:
        return sorted({slot for by_slot in self.scores.values() for slot in by_slot})

    def total(self, method: str, slot: int | None = None, category: str | None = None) -> Score:
        """Scores summed over a slot's scenes (every slot's when ``slot`` is None), optionally
        only those of one category."""
        slots = self.slots if slot is None else [slot]
        return sum((self.scores[method][s][i] for s in slots
                    for i, cat in enumerate(self.categories)
                    if category is None or cat == category), Score())

    def per_seed(self, method: str, category: str | None = None, what: str = "f1"
                 ) -> np.ndarray:
        """Per seed slot: F1 (or ``fp_per_min``, ``latency_s``) pooled over its scenes."""
        values = [getattr(self.total(method, slot, category), what) for slot in self.slots]
        return np.array([np.nan if v is None else v for v in values], dtype=float)

    def best_fixed(self, fixed_th: np.ndarray) -> float:
        """The fixed Th of best mean F1 on these scenes themselves: hindsight that no robot
        has, the strongest single threshold an adaptive method could be compared with."""
        means = [np.nanmean(self.per_seed(fixed_method(t))) for t in fixed_th]
        return float(fixed_th[int(np.argmax(means))])

    def seeds_needed(self, method: str, others: list[str], margin: float) -> int:
        """Seeds to resolve ``margin`` in F1 between ``method`` and each of ``others``, from the
        spread of the paired differences so far."""
        own = self.per_seed(method)
        if len(own) < 2:
            return len(own)
        needed = []
        for other in others:
            d = own - self.per_seed(other)
            d = d[np.isfinite(d)]
            needed.append(seeds_needed(d, margin) if len(d) >= 2 else len(own))
        return max(needed)


def interval(values, bounds: tuple | None = None) -> dict:
    """Mean with its 95 % interval over seeds (n < 2: no interval): Student t, or for a
    quantity with ``bounds`` (an F1, a rate ≥ 0) the bounded bootstrap of
    ``stats.mean_interval``, which never leaves the quantity's range (never a clipped t)."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) < 2:
        return {"mean": float(x.mean()) if len(x) else None, "low": None, "high": None,
                "n": int(len(x))}
    i = mean_interval(x, bounds=bounds)
    return {"mean": i.mean, "low": i.low, "high": i.high, "n": i.n}


def difference(a, b) -> dict:
    """a − b paired by seed: mean, 95 % CI, n, p and the verdict ("not resolved" when the
    interval spans zero)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    keep = np.isfinite(a) & np.isfinite(b)   # a seed without contacts or detections has no F1
    a, b = a[keep], b[keep]
    if len(a) < 2:
        return {"mean": float(np.mean(a - b)) if len(a) else None, "low": None, "high": None,
                "n": int(len(a)), "p_value": None, "resolved": False,
                "verdict": "n < 2: no interval"}
    return paired_difference(a, b).as_dict()


def compare(scores: MethodScores, fixed_th: np.ndarray, sweep_fixed_th: float) -> dict:
    """The gate against the lookup table, the best fixed Th in hindsight and the fixed Th
    chosen on the sweep: F1 with intervals, per-seed F1, paired differences, the same per
    scene category, and the F1 of every fixed Th evaluated."""
    oracle = scores.best_fixed(fixed_th)
    compared = {"gated": "gated", "lookup": "lookup",
                f"best fixed in hindsight ({oracle:g} g)": fixed_method(oracle),
                f"fixed from the sweep ({sweep_fixed_th:g} g)": fixed_method(sweep_fixed_th)}
    gated = scores.per_seed("gated")
    return {
        "f1": {label: interval(scores.per_seed(m), F1_BOUNDS) for label, m in compared.items()},
        "f1_per_seed": {label: [None if not np.isfinite(x) else float(x)
                                for x in scores.per_seed(m)] for label, m in compared.items()},
        "differences": {
            "gated − lookup": difference(gated, scores.per_seed("lookup")),
            "gated − best fixed in hindsight": difference(
                gated, scores.per_seed(fixed_method(oracle))),
            "gated − fixed from the sweep": difference(
                gated, scores.per_seed(fixed_method(sweep_fixed_th)))},
        "per_category": [_category_row(scores, cat, compared, fixed_method(oracle))
                         for cat in dict.fromkeys(scores.categories)],
        "fixed_curve": [{"threshold_g": float(t),
                         **interval(scores.per_seed(fixed_method(t)), F1_BOUNDS)}
                        for t in fixed_th],
        "oracle_th_g": oracle,
        "latency_gated_s": interval(scores.per_seed("gated", what="latency_s"), NON_NEGATIVE),
        "fp_per_min_gated": interval(scores.per_seed("gated", what="fp_per_min"),
                                     NON_NEGATIVE)}


def _category_row(scores: MethodScores, cat: str, compared: dict, oracle: str) -> dict:
    row = {"scenes": cat}
    for label, m in compared.items():
        row[f"F1 {label}"] = interval(scores.per_seed(m, cat), F1_BOUNDS)
    gated = scores.per_seed("gated", cat)
    row["gated − lookup"] = difference(gated, scores.per_seed("lookup", cat))
    row["gated − best fixed"] = difference(gated, scores.per_seed(oracle, cat))
    row["FP/min gated"] = interval(scores.per_seed("gated", cat, "fp_per_min"), NON_NEGATIVE)
    row["latency gated (s)"] = interval(scores.per_seed("gated", cat, "latency_s"),
                                        NON_NEGATIVE)
    total = scores.total("gated", category=cat)
    row["contacts scored"] = total.tp + total.misses
    return row


def describe_interval(d: dict, digits: int = 3) -> str:
    if d["mean"] is None:
        return "no seed with contacts"
    if d.get("low") is None:
        return f"{d['mean']:.{digits}f} (n = {d['n']}, no interval)"
    return (f"{d['mean']:.{digits}f} (95 % CI {d['low']:.{digits}f} to {d['high']:.{digits}f}, "
            f"n = {d['n']})")


def describe_difference(d: dict) -> str:
    if d["mean"] is None:
        return "no seed with contacts to compare"
    if d.get("low") is None:
        return f"{d['mean']:+.3f} (n = {d['n']}, no interval)"
    if d.get("p_value") is None:
        return f"{d['mean']:+.3f} (n = {d['n']}: {d['verdict']})"
    return (f"{d['mean']:+.3f} (95 % CI {d['low']:+.3f} to {d['high']:+.3f}, n = {d['n']}, "
            f"paired t p = {d['p_value']:.2g}: {d['verdict']})")


def table_cell(d):
    """A table cell for a mean with its interval (numbers, not a dict)."""
    if not isinstance(d, dict):
        return d
    if d.get("mean") is None:
        return None
    if d.get("low") is None:
        return f"{d['mean']:.3f} (n = {d['n']})"
    text = f"{d['mean']:.3f} ({d['low']:.3f} to {d['high']:.3f})"
    return f"{text}, {d['verdict']}" if "verdict" in d else text


@dataclass
class GateRecall:
    """What a trained speed gate recalls at every swept speed, against Th* and the table."""
    speeds_cm_s: np.ndarray
    th_star_g: np.ndarray
    recalled_g: np.ndarray
    held_out: np.ndarray             # True where the gate was not trained
    learning_curve: xr.DataArray     # recalled Th per epoch (epoch × speed)
    table: LookupTable               # the same training pairs, interpolated

    @property
    def ratio(self) -> np.ndarray:
        return self.recalled_g / self.th_star_g

    def error_factor(self, held_out: bool) -> float | None:
        """exp(mean |log(recalled / Th*)|) over the held-out (or the trained) speeds."""
        mask = self.held_out if held_out else ~self.held_out
        if not mask.any():
            return None
        return float(np.exp(np.mean(np.abs(np.log(self.ratio[mask])))))


def earns_its_place(s: dict) -> tuple[bool, str]:
    """An adaptive Th's bar, on a summary holding ``compare``'s differences and the gate's
    recall: resolved above the best fixed Th, and not resolved below the lookup; otherwise
    why not, in the summary's own numbers."""
    d_fixed = s["differences"]["gated − best fixed in hindsight"]
    d_lookup = s["differences"]["gated − lookup"]
    # "resolved" carries the documented rule (n ≥ stats.MIN_N_TO_RESOLVE and the interval
    # excludes zero): an interval over 2 seeds never decides either way
    above_fixed = bool(d_fixed.get("resolved")) and d_fixed["low"] > 0
    below_lookup = bool(d_lookup.get("resolved")) and d_lookup["high"] < 0
    too_few = [d["n"] for d in (d_fixed, d_lookup)
               if not d.get("resolved") and d.get("n", 0) < MIN_N_TO_RESOLVE]
    if too_few:
        return False, (f"too small to resolve (n = {min(too_few)} seeds; a verdict needs "
                       f"n ≥ {MIN_N_TO_RESOLVE})")
    if above_fixed and not below_lookup:
        return True, ("the gate is resolved above the best single threshold (even one chosen "
                      "in hindsight on these scenes) and not resolved below the lookup table")
    why = []
    if not above_fixed:
        ahead = d_fixed["mean"] is not None and d_fixed["mean"] > 0
        why.append("its lead over the best fixed Th in hindsight is not resolved" if ahead
                   else "it does not score above the best fixed Th in hindsight")
    if below_lookup:
        why.append(
            "it is resolved below the lookup table: both hold the same trained Th*, but the "
            "gate recalls it only within a factor "
            f"{s['recall_error_factor_trained']:.2f} on the trained speeds (the table is exact "
            f"there) and its read-out trace (τ = {s['gate_tau_read_s']:g} s) lags each speed "
            "step, so at best a spiking associative memory matches the table it learns")
    return False, "; ".join(why)
