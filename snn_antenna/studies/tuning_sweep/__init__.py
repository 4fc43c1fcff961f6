"""Tuning sweep: spike count vs input frequency over grids of k, b and input amplitude I.

Every grid point is one resonator driven by the square-wave coder's output for a pure tone
(±I at ``input_hz``); all points of a chunk are neurons of one Brian2 NeuronGroup, chunks run
on Dask workers and land in ``OUT/results.zarr`` (resumable). From the tuning curves
(``evaluation.tuning``):

- peak frequency vs k: the calibration curve k → preferred frequency (``k_to_peak_hz``),
  checked against ``neurons.DRIVEN_HZ_PER_K`` (the foundation's constant);
- band width (FWHM of the tuning curve) vs I: the input amplitude sets the band (Fig. 8G);
- spike rate vs b: b sets the rate (Fig. 8H).

Stages: sweep the grid → derive the curves' maps (``run``) → report (``report``); the
spec is checked and the grid sized in ``plan``.
"""
from __future__ import annotations

from .plan import OPTIONS, SECTIONS, Parts, plan
from .run import run

# plan and run are the study contract's doors (studies.contract.Study); the API reference
# documents them on their modules' pages, which share their names
__all__ = ["SECTIONS", "OPTIONS", "Parts"]
