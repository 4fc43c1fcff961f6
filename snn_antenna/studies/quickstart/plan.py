"""The quickstart's parts: the array, the scene (generated or the first recorded drive), the
preprocessing chain fitted on the warm-up, the detector; checked before anything runs."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core import spec as specs
from ...core.errors import check
from ...engine.cost import Build, engine_of, job_estimate
from ...networks.resonators import ResonatorArray
from ...readout.contacts import ContactDetector, detector_from_spec
from ...sources.source import Scene
from ..contract import COMMON, Plan, data_folder
from ...networks.resonators import array_section, check_rates
from ...preprocess import chain_section
from ..sections import source_section

SECTIONS = ("network", "stimulus", "preprocess", "readout", "data")
OPTIONS = (*COMMON, "data")
WARMUP_S = 2.0     # the chain calibrates on the scene's first seconds unless the spec says


@dataclass
class Parts:
    array: ResonatorArray
    scene: Scene
    chain: object
    detector: ContactDetector
    window_s: float
    warmup_s: float


def plan(spec: dict) -> Plan:
    """Check the whole spec and build every part, before any simulation runs."""
    specs.check_top_level(spec, SECTIONS)
    data_folder(spec)
    array = array_section(spec)
    scene = source_section(spec)
    pre, own = chain_section(spec, [scene], extra=("warmup_s",))
    warmup_s = float(own.get("warmup_s", WARMUP_S))
    first = min((c.t_s for c in scene.contacts), default=scene.duration_s)
    with specs.section("preprocess"):
        check(np.isfinite(warmup_s) and 0 < warmup_s <= first, "warmup_s", warmup_s,
              f"a warm-up in (0, {first:g}] s: it must end before the scene's first contact")
    detector, window_s = detector_from_spec(spec)
    check_rates(array, [scene])
    return Plan("quickstart", spec,
                Parts(array, scene, pre.chain(scene), detector, window_s, warmup_s), estimate)


def estimate(parts: Parts):
    """The scene's one Brian2 run."""
    array = parts.array
    return job_estimate("the scene", [(parts.scene.duration_s, array.dt_ms, array.n_neurons,
                                       engine_of(array.target),
                                       Build("offline array", array.compiled()))],
                        "stimulus.duration_s")


