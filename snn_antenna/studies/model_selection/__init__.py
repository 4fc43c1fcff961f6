"""Model selection: which contact mechanism, chosen by what it predicts.

For every candidate (``[selection] candidates``: a mechanism of ``sources/contact_models.py``
or a ``+`` combination, with a small grid of its one free constant), the study generates a
bench set at each grid value, processes its events as the paper did and runs the paper's
read-outs on the same splits by repetition for several seeds. Two numbers of the paper are
calibration targets (``CALIBRATION_TARGETS``): the constant is the grid value that meets them
best. Everything else is predicted and never enters that choice (``PREDICTIONS``).
Leave-one-target-out: the constant is chosen again from one target alone, and the left-out
target becomes a prediction. Among the candidates that meet their calibration targets (within
their tolerances), the one whose predictions meet most of the acceptance criteria (then: falls
least short of them) is the one the study chooses; none, when nothing calibrates.

The spec is checked and its parts built in ``plan``; each grid point is measured in ``run``;
what is a target, a prediction and a choice is ``protocol``; the page is written by ``report``.
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
