"""Study runners: ``snn-antenna run studies/NAME.toml`` looks up the spec's ``study`` here.

Each runner module defines ``run(spec, out_dir, quick=False) -> dict`` that validates the
whole spec before any long work, writes the report folder and returns the summary, and
``build(spec)`` that does the validating alone.

Before a runner starts, the command checks what the studies share
(``engine.spec_rules.check_spec``). For a sweep, :func:`plan` sizes the work from the grid's
shape alone.
"""
from __future__ import annotations

import importlib

import numpy as np

from ..core.errors import SpecError

STUDIES = {
    "quickstart": "snn_antenna.studies.quickstart",
    "gating_threshold": "snn_antenna.studies.gating_threshold",
    "exploration": "snn_antenna.studies.exploration",
    "tuning_sweep": "snn_antenna.studies.tuning_sweep",
    "speed_accuracy": "snn_antenna.studies.speed_accuracy",
    "baseline_comparison": "snn_antenna.studies.baseline_comparison",
    "model_selection": "snn_antenna.studies.model_selection",
}


def runner(name: str):
    if not isinstance(name, str) or name not in STUDIES:
        raise SpecError("study", name, f"one of {sorted(STUDIES)}")
    return importlib.import_module(STUDIES[name])


def plan(spec: dict):
    """The estimate of a study's work: a neuron sweep (``[neuron]`` + ``[axes]``), sized by
    its own ``build``, or the scenes, bench sets and sweeps of scenes of the other studies
    (``costs``), or None where a value of the wrong type leaves nothing to size.

    A grid whose results or chunks cannot fit in memory is refused here, before a worker starts.
    """
    if spec.get("study") != "tuning_sweep":
        from .costs import estimate as job

        return job(spec)
    from ..engine.cost import check_memory, estimate
    from ..engine.evaluators import NeuronSweep

    neuron, grid, settings, _ = runner("tuning_sweep").build(spec)
    block = grid.block_shape(settings.chunk_points)
    check_memory(grid, NeuronSweep.OUTPUTS, int(np.prod(block)), neuron.bytes_per_point)
    return estimate(grid, neuron, settings.chunk_points, settings.workers)
