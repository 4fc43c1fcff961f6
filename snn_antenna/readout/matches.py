"""Which detection scores which contact, contact by contact, and the false-positive rate's
interval: the per-contact view of ``scoring.score``'s rule.

A detection scores a contact when it starts between one window before the contact and the
end of its hold (at least one window); the first such detection is the contact's match.
"""
from __future__ import annotations

from scipy import stats

from .contacts import ContactEstimate


def first_match(detections: list[ContactEstimate], contact, window_s: float):
    """The detection that scores ``contact`` (``scoring.score``'s rule), or None."""
    hits = [d for d in detections
            if contact.t_s - window_s <= d.onset_s < contact.t_s + max(contact.duration_s,
                                                                       window_s)]
    return min(hits, key=lambda d: d.onset_s) if hits else None


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


def poisson_interval(count: int, alpha: float = 0.05) -> tuple[float, float]:
    """Exact (Garwood) 1 − ``alpha`` interval of a Poisson count, from scipy's chi²
    quantiles."""
    low = stats.chi2.ppf(alpha / 2, 2 * count) / 2 if count else 0.0
    return float(low), float(stats.chi2.ppf(1 - alpha / 2, 2 * count + 2) / 2)
