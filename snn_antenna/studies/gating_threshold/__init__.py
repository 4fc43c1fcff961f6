"""Gating threshold: how the coder's Th must follow speed, and a spiking gate that learns it.

Every read-out is blind: the preprocessing chain is fitted once on a separate calibration
drive without posts (``calibrated_chain``), the coder's Th is fixed or comes from the speed
command only, and the array and detector see only the coded signal
(``readout.detection.BlindReadOut``); detections are scored against the labelled contacts
afterwards.

Stages (each prints a progress line):

1. ``sweep``: Th × speed over seeded course scenes, every scene coded at every Th, all codings
   of a chunk as copies of the array in ONE Brian2 group (``ThresholdSweep``, on
   ``engine.sweep.run_sweep``: resumable, reused when only the gate or evaluation change);
   Th*(speed) is fitted on it (``thresholds.fit_th_star``).
2. ``fig9``: rate maps at 12 and 27 cm/s for Th = 0, Th* and 2·Th*. Both Fig. 9 numbers (the
   Th* ratio and the true positives lost by doubling Th*) were built into the generator by
   calibration: the report lists them under "Calibrated to", never as findings.
3. ``train_gate``: the speed gate (``networks.gate.SpeedGate``) learns Th* at a few speeds;
   its learning curve and recall at every swept speed (held-out ones too).
4. ``Evaluation``: new scenes per seed slot (held-out constant speeds, a ramp, random steps,
   and both on the other terrain); the gate's online Th against fixed thresholds around Th*'s
   range and the lookup table of the same trained Th*. A pilot's spread sets how many seeds
   resolve ``evaluation.margin_f1`` (``stats.seeds_needed``), up to ``evaluation.max_seeds``;
   every comparison is a paired difference with its 95 % CI (``thresholds.compare``).

Every Brian2 stage uses one Dask client (``sweep.workers``, ``--scheduler``; none with
``workers = 1``): Fig. 9 and the fixed-Th evaluation run on the workers while this process
trains the gate (``Codings`` over ``engine.batches.Batches``).

Seeds: every draw comes from ``numpy.random.SeedSequence(seed, spawn_key=(stream, ...))``, one
stream per sweep scene (shared by all speeds, so speeds are compared on the same courses) and
per evaluation scene (``evaluation.scene_stream`` picks another family of them: validation
scenes), so no two scenes share a seed whatever the counts.

With recorded drives (``data = "DIR"``, ``--data DIR``) every stage reads recordings instead
(``recorded``): the chain is fitted on the recordings' drive in the open, the sweep and the
gate's targets come from the training drives, the evaluation scores only the held-out drives
(split by drive, seeded); Fig. 9, a check of the generator's calibration, is left out.

The spec is checked and the parts built in ``plan``; the scenes, their conditioning and the
sweep's evaluator are ``scenes``; the stages run in ``run``; the page is written by ``report``.

Outputs: report.html, summary.json, figures, and ``sweep.zarr`` (the scored grid, dims
speed_cm_s × scene × threshold_g; with recorded drives a scene is a training drive).
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
