"""Detections scored against the ground truth, after the read-out, per contact.

The read-out (``readout.detection``: ``run_codings`` then ``ContactDetector.detect``, together
``BlindReadOut``) sees only the coded signal, as a robot would; ``score`` compares its
detections with a recording's ground truth (``truth.GroundTruth``) afterwards, and is the only
place contacts enter (``score_with`` scores a ``BlindReadOut``'s detections, ``score_run`` adds
the first contact's decoded distance, latency and the robot's stop; ``score_columns`` turns
scores into the counts of ``SCORE_OUTPUTS`` that a sweep's store holds).

Scoring, per contact: a detection whose first window starts between one window before the
contact and the end of its hold is a true positive (latency: from the contact to the end of
that first window, when the detection is known); further detections within the same hold
are duplicates (neither right nor wrong); other detections are false positives; contacts
without a detection are misses. A contact whose low mode lies below the self-motion band or
beyond the array's band (a post touched near the tip rings above 30 Hz, beyond the paper's
7–30 Hz array) cannot be told by frequency: it is its own category, decided here at scoring
time from the true distance: ``out_of_band_contacts`` counts them, ``out_of_band_hits`` the
detections that fell on one (neither true nor false positives: the contact was real, but
the array was not built to see it). The first ``settle_s`` of a scene (filters and
self-motion building up) is not scored.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.errors import check
from ..networks.resonators import ResonatorArray
from ..readout.contacts import ContactDetector, ContactEstimate
from ..readout.detection import BlindReadOut
from ..sources import antenna
from ..core.store import Output
from ..core.truth import Event


@dataclass
class Score:
    """Detection counts; add scores of several scenes with ``+``."""
    tp: int = 0
    fp: int = 0
    misses: int = 0
    duplicates: int = 0
    out_of_band_contacts: int = 0
    out_of_band_hits: int = 0
    minutes: float = 0.0
    latencies_s: list = field(default_factory=list)

    def __add__(self, other: Score) -> Score:
        return Score(self.tp + other.tp, self.fp + other.fp, self.misses + other.misses,
                     self.duplicates + other.duplicates,
                     self.out_of_band_contacts + other.out_of_band_contacts,
                     self.out_of_band_hits + other.out_of_band_hits,
                     self.minutes + other.minutes, self.latencies_s + other.latencies_s)

    @property
    def f1(self) -> float | None:
        denominator = 2 * self.tp + self.fp + self.misses
        return 2 * self.tp / denominator if denominator else None

    @property
    def fp_per_min(self) -> float | None:
        return self.fp / self.minutes if self.minutes > 0 else None

    @property
    def latency_s(self) -> float | None:
        return float(np.mean(self.latencies_s)) if self.latencies_s else None

    def as_dict(self) -> dict:
        return {"tp": self.tp, "fp": self.fp, "misses": self.misses,
                "duplicates": self.duplicates, "out_of_band_contacts": self.out_of_band_contacts,
                "out_of_band_hits": self.out_of_band_hits,
                "f1": self.f1, "fp_per_min": self.fp_per_min, "latency_s": self.latency_s}


SCORE_OUTPUTS = {
    "tp": Output("i4", "1", "contacts detected (true positives)"),
    "fp": Output("i4", "1", "detections away from any contact (false positives)"),
    "misses": Output("i4", "1", "scored contacts without a detection"),
    "duplicates": Output("i4", "1", "further detections within a detected contact"),
    "out_of_band_contacts": Output("i4", "1", "contacts outside the array's band"),
    "out_of_band_hits": Output("i4", "1", "detections on contacts outside the array's band"),
    "latency_sum_s": Output("f8", "s", "summed latency of the true positives"),
    "minutes": Output("f8", "min", "scored time"),
}


def score_columns(scores: list[Score]) -> dict[str, np.ndarray]:
    """Scores as the columns of ``SCORE_OUTPUTS`` (a sweep's store holds counts, not lists)."""
    out = {name: np.array([getattr(s, name) for s in scores], dtype=o.dtype)
           for name, o in SCORE_OUTPUTS.items() if name != "latency_sum_s"}
    out["latency_sum_s"] = np.array([float(np.sum(s.latencies_s)) for s in scores])
    return out


def first_match(detections: list[ContactEstimate], contact, window_s: float):
    """The detection that scores ``contact`` under ``score``'s rule (the first one starting
    between one window before the contact and the end of its hold), or None."""
    hits = [d for d in detections if _falls_on(d, contact, window_s)]
    return min(hits, key=lambda d: d.onset_s) if hits else None


def _falls_on(detection: ContactEstimate, contact, window_s: float) -> bool:
    return (contact.t_s - window_s <= detection.onset_s
            < contact.t_s + max(contact.duration_s, window_s))


def contact_rows(detections: list[ContactEstimate], dominant_hz: list[float], contacts,
                 window_s: float, settle_s: float) -> list[dict]:
    """One row per contact after ``settle_s``, first to last: its truth beside its match
    (``dominant_hz``: each detection's dominant neuron; None where the contact was missed)."""
    rows = []
    for c in sorted(contacts, key=lambda c: c.t_s):
        if c.t_s < settle_s:
            continue
        m = first_match(detections, c, window_s)
        rows.append({
            "true_t_s": c.t_s, "true_distance_cm": c.distance_cm, "material": c.material,
            "detected_s": m.onset_s if m else None,
            "latency_s": (m.onset_s + window_s - c.t_s) if m else None,
            "frequency_hz": m.frequency_hz if m else None,
            "distance_cm": m.distance_cm if m else None,
            "distance_error_cm": (m.distance_cm - c.distance_cm) if m else None,
            "dominant_hz": dominant_hz[detections.index(m)] if m else None})
    return rows


def visible(contact: Event, detector: ContactDetector, array: ResonatorArray) -> bool:
    """Can the array see this contact at all (its low mode in the band above self-motion)?

    A scoring-time category from the true distance: never used to filter detections."""
    f = float(antenna.low_mode_hz(contact.distance_cm))
    return detector.motion_band_hz[1] < f <= float(array.band_hz[1])


def score(detections: list[ContactEstimate], contacts, duration_s: float,
          detector: ContactDetector, array: ResonatorArray, window_s: float,
          settle_s: float = 1.0) -> Score:
    check(0 <= settle_s < duration_s, "settle_s", settle_s, f"a time in [0, {duration_s}) s")
    contacts = sorted((c for c in contacts if c.t_s >= settle_s), key=lambda c: c.t_s)
    seen = [visible(c, detector, array) for c in contacts]
    matched = [False] * len(contacts)
    s = Score(minutes=(duration_s - settle_s) / 60.0,
              out_of_band_contacts=int(len(contacts) - sum(seen)))
    for d in sorted(detections, key=lambda d: d.onset_s):
        if d.onset_s < settle_s:
            continue
        hits = [i for i, c in enumerate(contacts) if _falls_on(d, c, window_s)]
        if not hits:
            s.fp += 1
            continue
        i = hits[0]
        if matched[i]:
            s.duplicates += 1
            continue
        matched[i] = True
        if not seen[i]:
            s.out_of_band_hits += 1
            continue
        s.tp += 1
        s.latencies_s.append(d.onset_s + window_s - contacts[i].t_s)
    s.misses = int(sum(1 for m, v in zip(matched, seen) if v and not m))
    return s


def score_with(readout: BlindReadOut, detections: list, contacts, duration_s: float) -> Score:
    """``score`` with a blind read-out's own detector, array, window and settling time."""
    return score(detections, contacts, duration_s, readout.detector, readout.array,
                 readout.window_s, readout.settle_s)


def score_run(readout: BlindReadOut, detections: list, contacts, duration_s: float,
              stopped_at_s: float | None = None) -> dict:
    """One run's detections (and the robot's stop) against its contacts, after the run: the
    counts of ``score`` and, for the first contact, its decoded distance, latency and how
    long after it the robot stopped."""
    s = score_with(readout, detections, contacts, duration_s)
    first = min(contacts, key=lambda c: c.t_s) if contacts else None
    out = {**s.as_dict(), "scored_minutes": s.minutes, "first_contact": None}
    if first is None:
        return out
    match = first_match(detections, first, readout.window_s)
    f_first = float(antenna.low_mode_hz(first.distance_cm))
    out["first_contact"] = {
        "t_s": first.t_s, "true_distance_cm": first.distance_cm, "material": first.material,
        "low_mode_hz": f_first,
        "within_array_band": bool(f_first <= float(readout.array.band_hz[1])),
        "decoded_distance_cm": match.distance_cm if match else None,
        "distance_error_cm": (match.distance_cm - first.distance_cm) if match else None,
        "latency_s": (match.onset_s + readout.window_s - first.t_s) if match else None,
        "stopped_after_s": (stopped_at_s - first.t_s) if stopped_at_s is not None else None}
    return out
