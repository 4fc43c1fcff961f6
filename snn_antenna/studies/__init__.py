"""The studies: ``snn-antenna run studies/NAME.toml`` looks up the spec's ``study`` here.

Every study module keeps one contract (``contract``): it declares its spec's ``SECTIONS`` and
the command-line ``OPTIONS`` it takes; ``plan(spec)`` checks the whole spec and builds every
part that needs no simulation, and the plan sizes its own work (``Plan.estimate``);
``run(plan, out_dir, options)`` runs the study on those parts and returns its summary.
Before a plan is made, the command checks what the studies share
(``engine.spec_rules.check_spec``).

Every study is a package of the same shape: ``plan`` (its sections, its parts, named
``Parts``, and its cost), ``run`` (its stages and summary) and ``report`` (its page), and
modules of its own beside them where it has more to say; its ``__init__`` names the contract's
parts. The sections several studies share (the source, the preprocessing chain, the
resonator array) are read once, in ``sections``.
"""
from __future__ import annotations

import importlib

from ..core.errors import SpecError

STUDIES = {
    "quickstart": "snn_antenna.studies.quickstart",
    "gating_threshold": "snn_antenna.studies.gating_threshold",
    "exploration": "snn_antenna.studies.exploration",
    "tuning_sweep": "snn_antenna.studies.tuning_sweep",
    "speed_accuracy": "snn_antenna.studies.speed_accuracy",
    "baseline_comparison": "snn_antenna.studies.baseline_comparison",
    "model_selection": "snn_antenna.studies.model_selection",
    "bank_tuning": "snn_antenna.studies.bank_tuning",
}


def runner(name: str):
    """The module of study ``name`` (a SpecError naming the known ones otherwise)."""
    if not isinstance(name, str) or name not in STUDIES:
        raise SpecError("study", name, f"one of {sorted(STUDIES)}")
    return importlib.import_module(STUDIES[name])
