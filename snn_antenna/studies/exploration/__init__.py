"""Active exploration: the closed loop of the paper's Fig. 3, run in Brian2 with Python in the
loop.

The network is what ``networks/exploration.toml`` lists (``assembly.build``); ``plan`` checks
the spec and builds the loop's parts; ``run`` trains the gate, calibrates the chain on a
separate drive, closes the loop (its freeze reflex: ``readout.closed_loop``) and keeps the
robot's blind record; the world's contacts are compared with that record afterwards
(``scoring.score_run``: true and false positives, misses, latency, distance error);
``report`` writes the page.

Summary: ``cpg_period_s`` (measured while driving, and the spec's value at that speed),
``pan_tilt_phase_deg``, ``contact_distance_cm`` (true and decoded from the rate map),
``stopped_after_contact_s``, ``score``.
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
