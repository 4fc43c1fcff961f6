"""Study runners: ``snn-antenna run studies/NAME.toml`` looks up the spec's ``study`` here.

Each runner module defines ``run(spec, out_dir, quick=False) -> dict`` that validates the
whole spec before any long work, writes the report folder and returns the summary.
"""
from __future__ import annotations

import importlib

from ..errors import SpecError

STUDIES = {
    "quickstart": "snn_antenna.studies.quickstart",
    "gating_threshold": "snn_antenna.studies.gating_threshold",
    "exploration": "snn_antenna.studies.exploration",
    "tuning_sweep": "snn_antenna.studies.tuning_sweep",
    "speed_accuracy": "snn_antenna.studies.speed_accuracy",
    "baseline_comparison": "snn_antenna.studies.baseline_comparison",
}


def runner(name: str):
    if name not in STUDIES:
        raise SpecError("study", name, f"one of {sorted(STUDIES)}")
    return importlib.import_module(STUDIES[name])
