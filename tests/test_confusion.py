"""The confusion matrix's rates beside the paper's Fig. 6D: known answers."""
import numpy as np
import pytest

from snn_antenna.evaluation.confusion import confusion_sentence, error_rates, most_confused_pair

MATERIALS = ["aluminium", "brass", "pvc", "wood"]
# true × predicted: brass and wood taken for each other 10 and 5 times of 50 each
CM = np.array([[50, 0, 0, 0],
               [0, 40, 0, 10],
               [0, 0, 50, 0],
               [0, 5, 0, 45]])


def test_most_confused_pair_is_a_share_of_the_pairs_contacts():
    pair, rate = most_confused_pair(CM, MATERIALS)
    assert pair == ("brass", "wood") and rate == pytest.approx(15 / 100)


def test_error_rates_carry_wilson_intervals_and_counts():
    rates = {r.quantity: r for r in error_rates(CM, MATERIALS)}
    brass = rates["brass contacts misclassified"]
    assert brass.value == pytest.approx(20.0) and brass.n == 50
    assert brass.interval[0] < 20.0 < brass.interval[1]
    assert rates["aluminium ↔ PVC confused"].value == 0.0
    assert rates["most confused pair (share of the pair's contacts)"].value == \
        "brass ↔ wood (15.0 %)"


def test_the_sentence_says_where_it_agrees_with_the_paper():
    text = confusion_sentence(CM, MATERIALS)
    assert "agrees that brass ↔ wood is the most confused pair" in text
    assert "aluminium ↔ PVC is an easy pair" in text
