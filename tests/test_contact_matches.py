"""Per-contact matches of detections and the false-positive count's interval."""
import pytest

from snn_antenna.readout.contacts import ContactEstimate
from snn_antenna.evaluation.scoring import contact_rows, first_match
from snn_antenna.core.truth import Event
from snn_antenna.report.stats import poisson_interval


def test_poisson_interval_known_answers():
    assert poisson_interval(0) == pytest.approx((0.0, 3.689), abs=1e-3)
    assert poisson_interval(1) == pytest.approx((0.0253, 5.572), abs=1e-3)


def test_the_first_detection_within_the_hold_scores_the_contact():
    contact = Event("contact", 5.0, 0.5, 19.0, "wood")
    early, match, late = (ContactEstimate(t, t + 0.2, 17.0, 19.1) for t in (4.8, 5.2, 5.6))
    assert first_match([late, match, early], contact, 0.1) is match
    rows = contact_rows([match, late], [17.0, 18.0], [contact], 0.1, settle_s=2.0)
    assert rows[0]["dominant_hz"] == 17.0
    assert rows[0]["latency_s"] == pytest.approx(0.3)
    assert contact_rows([late], [18.0], [contact], 0.1, settle_s=2.0)[0]["detected_s"] is None
