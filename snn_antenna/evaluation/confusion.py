"""The 8-material confusion matrix beside the paper's Fig. 6D: error rates with intervals.

Counts are summed over every seed's test contacts (``baselines.BaselineResult``); every rate
carries its Wilson interval (``stats.binomial_interval``) and its number of contacts.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..report.stats import binomial_interval

PLASTICS = ("pom", "pvc", "acrylic_glass")
# Below this share of the pair's contacts taken for each other, a pair counts as easy.
EASY_PAIR_RATE = 0.01

WHY = ("Why: in this generator a rod's material reaches the spectrum mainly through its own "
       "bending mode, f₁ ∝ √(E/ρ), so classes that share a mode are confused: the three "
       "plastics (107–123 Hz), brass and copper (256–271 Hz), aluminium and steel "
       "(369–377 Hz: equal √(E/ρ)); wood (334 Hz, light and lossy) rings apart from brass. "
       "Whatever made brass sound like wood on the real bench (its mounting, rod lengths, "
       "surface finish) is not in the model.")


def confusion(result, n_classes: int) -> np.ndarray:
    """Confusion counts (true × predicted) over all seeds' test contacts of a result."""
    cm = np.zeros((n_classes, n_classes), dtype=int)
    for f in result.folds:
        np.add.at(cm, (result.y[f.test_index], f.prediction.astype(int)), 1)
    return cm


@dataclass
class ErrorRate:
    """A share of contacts (``unit`` %) with its 95 % Wilson interval over ``n`` contacts,
    beside the paper's number or word for it."""
    quantity: str
    value: object
    paper: object
    interval: tuple[float, float] | None = None
    n: int | None = None
    note: str = ""
    unit: str = "%"


def _rate(quantity: str, errors: int, n: int, paper, note: str = "") -> ErrorRate:
    lo, hi = binomial_interval(int(errors), int(n))
    return ErrorRate(quantity, 100 * errors / n, paper, (100 * lo, 100 * hi), int(n), note)


def error_rates(cm: np.ndarray, materials) -> list[ErrorRate]:
    """The rates the paper names: brass and wood misclassified, the most confused pair
    (paper: brass ↔ wood), aluminium ↔ PVC (an easy pair), plastics taken for another
    plastic (hard pairs)."""
    index = {m: i for i, m in enumerate(materials)}
    out = []
    for m, paper in (("brass", 9.4), ("wood", 8.4)):
        if m in index:
            i = index[m]
            out.append(_rate(f"{m} contacts misclassified", cm[i].sum() - cm[i, i],
                             cm[i].sum(), paper, "Wilson interval"))
    (a, b), rate = most_confused_pair(cm, materials)
    out.append(ErrorRate("most confused pair (share of the pair's contacts)",
                         f"{a} ↔ {b} ({100 * rate:.1f} %)", "brass ↔ wood", unit=""))
    if {"aluminium", "pvc"} <= set(index):
        a, b = index["aluminium"], index["pvc"]
        out.append(_rate("aluminium ↔ PVC confused", cm[a, b] + cm[b, a],
                         cm[a].sum() + cm[b].sum(), "easy pair"))
    plastics = [index[m] for m in PLASTICS if m in index]
    if len(plastics) >= 2:
        block = cm[np.ix_(plastics, plastics)]
        out.append(_rate("plastics taken for another plastic", block.sum() - np.trace(block),
                         cm[plastics].sum(), "hard pairs"))
    return out


def most_confused_pair(cm: np.ndarray, materials) -> tuple[tuple[str, str], float]:
    """The pair of classes most often taken for each other, as a share of their contacts."""
    best, rate = ("", ""), -1.0
    for i in range(len(materials)):
        for j in range(i + 1, len(materials)):
            r = (cm[i, j] + cm[j, i]) / max(1, cm[i].sum() + cm[j].sum())
            if r > rate:
                best, rate = (materials[i], materials[j]), float(r)
    return best, rate


def confusion_sentence(cm: np.ndarray, materials) -> str:
    """Where the confusion matrix agrees with the paper's Fig. 6D and where not, and why."""
    index = {m: i for i, m in enumerate(materials)}
    (a, b), rate = most_confused_pair(cm, materials)
    agree, differ = [], []
    if {a, b} == {"brass", "wood"}:
        agree.append("brass ↔ wood is the most confused pair")
    else:
        differ.append(f"the most confused pair is {a} ↔ {b} ({100 * rate:.1f} % of their "
                      "contacts), not brass ↔ wood")
    plastics = [index[m] for m in PLASTICS if m in index]
    if len(plastics) >= 2:
        block = cm[np.ix_(plastics, plastics)]
        within = (block.sum() - np.trace(block)) / max(1, cm[plastics].sum())
        overall = (cm.sum() - np.trace(cm)) / max(1, cm.sum())
        (agree if within > overall else differ).append(
            f"the plastics are {'among the hardest' if within > overall else 'not the hardest'}"
            f" ({100 * within:.1f} % taken for another plastic, {100 * overall:.1f} % errors "
            "overall)")
    if {"aluminium", "pvc"} <= set(index):
        i, j = index["aluminium"], index["pvc"]
        pair = (cm[i, j] + cm[j, i]) / max(1, cm[i].sum() + cm[j].sum())
        easy = pair < EASY_PAIR_RATE
        (agree if easy else differ).append(
            f"aluminium ↔ PVC {'is an easy pair' if easy else 'is not an easy pair'} "
            f"({100 * pair:.1f} %)")
    text = "Beside the paper's Fig. 6D: "
    if agree:
        text += "it agrees that " + "; ".join(agree) + ". "
    if differ:
        text += "It differs in that " + "; ".join(differ) + ". "
    return text + WHY
