"""The calibration of ``antenna.ROD_COUPLING``: the share of the struck rod's own mode that
reaches the tip, set so that the baseline comparison's full-spectrum FFT-MLP classifies the
eight materials of the whole bench set as well as the paper's (94.2 %, docs/reference.md).

The baseline study's bench set, events and evaluation (its spec, whole: 100 repetitions, the
five splits by repetition of ``[evaluation] seeds``) with the coupling as its one free value:
each coupling is the default contact physics (``current``) at ``physics_strength`` = coupling
/ ``ROD_COUPLING``, so each bench set and its features are cached like the study's own
(``bench.cache_key``), and only the full-spectrum MLP is fitted on them (the comparison's
other read-outs take no part in the calibration). The accuracy rises with the coupling (a
louder rod line is an easier material feature), so the coupling that meets the target is
the root of mean accuracy − target, found with ``scipy.optimize.brentq`` on a bracket whose
ends lie on either side of it (``calibrate``), or, where the splits' noise makes single
crossings wander, where a line through the couplings measured near it meets the target
(``fitted_root``). ``benchmarks/calibrate_rod_coupling.py`` is the command."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...core.errors import SpecError, check
from ...evaluation import crossval as cv
from ...evaluation import signal as bench_signal
from ...readout.baselines import material_baselines
from ...report import stats
from ...sources import antenna
from .plan import Parts

PAPER_ACCURACY = 0.942      # 8 materials, full-spectrum MLP (paper, docs/reference.md)
READOUT = "mlp_spectrum_material"


def curve_rows(points: dict) -> list[dict]:
    """One row per coupling of ``points`` (coupling -> per-split accuracies), ascending: the
    mean accuracy, its 95 % interval (bounded to [0, 1]) and n."""
    rows = []
    for c in sorted(points):
        iv = stats.mean_interval(points[c], bounds=(0.0, 1.0))
        rows.append({"coupling": c, "accuracy": iv.mean, "interval": [iv.low, iv.high],
                     "n": iv.n, "per_split": [float(a) for a in points[c]]})
    return rows


def fitted_root(points: dict, target: float = PAPER_ACCURACY,
                within: tuple[float, float] = (0.0, 1.0)) -> tuple[float, float]:
    """(coupling, slope per unit coupling) where the least-squares line through the mean
    accuracies of the couplings ``within`` meets ``target``. Near the target the split-to-split
    noise of one coupling's mean (a few tenths of a point) exceeds the rise between close
    couplings, so the line through several of them places the root where one crossing
    (``calibrate``) cannot. Refused when fewer than three couplings lie ``within`` or the line
    does not rise."""
    lo, hi = within
    xs = np.array(sorted(c for c in points if lo <= c <= hi))
    check(len(xs) >= 3, "fit", [lo, hi], f"a range holding 3 measured couplings or more "
                                        f"(it holds {len(xs)})")
    ys = np.array([np.mean(points[c]) for c in xs])
    slope, intercept = np.polyfit(xs, ys, 1)
    check(slope > 0, "fit", [lo, hi], "a range where the accuracy rises with the coupling "
                                      f"(its line falls: {slope:.3g} per unit)")
    return float((target - intercept) / slope), float(slope)


def accuracy(parts: Parts, coupling: float, log=print) -> np.ndarray:
    """The full-spectrum MLP's 8-material accuracy on each split of ``parts``' bench set
    generated with ``coupling`` (the share of the rod's mode, aluminium) in place of
    ``ROD_COUPLING``."""
    check(getattr(parts.bench, "physics", None) == "current", "stimulus.physics",
          getattr(parts.bench, "physics", None),
          "'current' (the generated bench set whose rod line ROD_COUPLING scales)")
    check(isinstance(coupling, float) and 0 < coupling <= 1, "coupling", coupling,
          "a share of the impact in (0, 1]")
    spec = replace(parts.bench, physics_strength=coupling / antenna.ROD_COUPLING)
    _, everything = bench_signal.load_features(spec, parts.processor, log)
    feats = everything.isel(event=np.flatnonzero(everything["skipped"].values == ""))
    ev = parts.evaluation
    mlp = [b for b in material_baselines([], ev.material_mlp, ev.nmf_max_iter)
           if b.name == READOUT]
    return cv.evaluate(feats, mlp, ev, log)[READOUT].values("accuracy")


def calibrate(parts: Parts, bracket: tuple[float, float], target: float = PAPER_ACCURACY,
              xtol: float = 2e-4, points: dict | None = None, log=print
              ) -> tuple[float, dict]:
    """The coupling in ``bracket`` whose mean accuracy over the splits is ``target``
    (``brentq`` to ``xtol``), and every coupling measured on the way. A bracket whose ends
    do not lie on either side of the target is refused: the accuracy does not reach it there.
    ``points`` (coupling -> per-split accuracies) are reused and filled in."""
    from scipy.optimize import brentq

    points = {} if points is None else points

    def miss(coupling: float) -> float:
        coupling = float(coupling)
        if coupling not in points:
            points[coupling] = accuracy(parts, coupling, log)
            log(f"coupling {coupling:.5f}: accuracy {100 * np.mean(points[coupling]):.2f} % "
                f"(target {100 * target:.1f} %)")
        return float(np.mean(points[coupling])) - target

    lo, hi = map(float, bracket)
    below, above = miss(lo), miss(hi)
    if below * above > 0:
        raise SpecError("bracket", [lo, hi],
                        f"couplings on either side of the target {100 * target:.1f} % (their "
                        f"accuracies: {100 * (below + target):.2f} and "
                        f"{100 * (above + target):.2f} %)")
    return float(brentq(miss, lo, hi, xtol=xtol)), points


__all__ = ["PAPER_ACCURACY", "curve_rows", "fitted_root", "accuracy", "calibrate"]
