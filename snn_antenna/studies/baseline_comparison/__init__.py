"""Baseline comparison: the paper's FFT, parametric and NMF read-outs on the bench data set.

Generates (or reuses) the bench contacts, processes every event as the paper did, checks the
generated signal against the paper's measurements of the signal (calibration), then trains
and tests each scikit-learn pipeline, and the spiking read-out's decoders, on the same splits
by repetition for several seeds. The report puts every number beside the paper's.

On contacts a lab recorded (``data``), its antenna is fitted first, on the labels of the
calibration repetitions held out of every split (``evaluation.antenna_fit``: frequency law,
mode split, decay-fit window, bands), and the report describes the recordings.

The spec is checked, fitted to the data's rate and its parts built in ``plan``; the stages
run in ``run`` (the tuned bank's in ``tuned``); the page is written by ``report``.
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
