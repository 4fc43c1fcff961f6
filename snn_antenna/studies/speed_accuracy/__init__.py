"""Speed vs accuracy: every integration knob measured against an exact reference.

For each scene (the array's tuning stimuli, the quickstart robot scene, a bench contact) the
resonator array runs in Brian2 for every integration method × dt (the main sweep), and for
a few settings across code targets × float precision × array size (the cost sweep). Each run
is timed and compared with the scene's reference (``networks.reference``): spike-time,
spike-count and rate-map error and, for contact scenes, decoded-distance error and detection
F1 of the quickstart read-out. The report shows the Pareto fronts (error vs CPU time), a
recommendation per scene, and the stability map (method × k·dt × drive).

Stages: workloads → references → main sweep → cost sweep → stability map → bench bands
(``evaluation.bands``: each band of the bench's spiking read-out before and at a setting inside
the accurate range, against the reference, with its cost) → the sweep engine's float precision
(``precision``: float32 against float64 on a tuning grid, with a rounding baseline) → report.
Settings
loop in this process (``engine.devices``): timing needs the machine to itself, and the knobs
(method, target, dtype) are build settings rather than the numeric axes of a sweep grid.
The spec is checked and the parts built in ``plan``; the stages run in ``run``; the page is
written by ``report``. Finished runs are kept in ``OUT/runs.jsonl`` (``engine.runlog``): an
interrupted run resumes.
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
