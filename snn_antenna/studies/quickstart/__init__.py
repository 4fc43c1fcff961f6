"""Quickstart: a robot drives, its antenna touches obstacles, the resonator array shows it.

The paper's Fig. 10: self-motion keeps the 7–8 Hz neurons busy; on contact the activity
jumps to the neuron tuned near the clamped rod's low mode, which gives the distance.

Two stages, kept apart so the ground truth cannot reach the read-out:

- ``read_out(samples, rate_hz, parts)`` sees only the sensor's samples, as a robot would:
  the chain is fitted on the first ``preprocess.warmup_s`` (before that the robot is
  calibrating and nothing is read out), the array runs, and every detection it makes is kept.
- ``score(readout, contacts, ...)`` compares those detections with the scene's contacts
  afterwards: true and false positives (per minute), misses, latency and distance error.

The study's parts are built and checked in ``plan``, the read-out and the scoring run in
``run``, the page is written by ``report``.

The robot keeps driving through and after its contacts (the paper's robot stopped; here its
self-motion keeps competing with the contacts, so false positives can arise and are counted).
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
