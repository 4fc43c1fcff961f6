"""Bank tuning: a resonator bank's k placement, b, coder and read-out searched for the task.

The search (Optuna, multi-objective: material accuracy up, neuron-steps per contact down)
scores every trial's bank by running it on the event engine over *tuning contacts*: the
robot's own session on the bench's rods, generated with another seed, never evaluated. The
Pareto front it finds is then scored on the bench set's splits by repetition, beside the
full-spectrum FFT-MLP on the same splits: the reported accuracy comes from contacts the
search never saw (``search.check_unseen`` refuses a search that scored any of them).

The spec is checked and its parts built in ``plan``; the search runs in ``search``, the
stages in ``run``; the page is written by ``report``.
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
