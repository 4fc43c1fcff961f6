"""The model selection's plan: the bench set (its mechanism left to ``[selection]``), the
event processor, the evaluation and the candidates with their grids, checked before any long
work; its cost."""
from __future__ import annotations

from dataclasses import dataclass, field

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError, check, is_number
from ...evaluation import crossval as cv
from ...readout import events
from ...sources.bench import BenchSpec
from ...sources.contact_models import ContactPhysics
from ..contract import COMMON, Plan
from ..sections import bench_section, evaluation_section, events_section
from . import cost
from .protocol import PAPER_PAIR

SECTIONS = ("stimulus", "events", "evaluation", "selection")
OPTIONS = (*COMMON, "fresh", "scheduler")


@dataclass
class Candidate:
    physics: str
    strengths: list

    def __post_init__(self):
        bounds.declared(self)
        check(isinstance(self.strengths, list) and len(self.strengths) >= 1
              and all(is_number(s) for s in self.strengths), "selection.candidates.strengths",
              self.strengths, "a non-empty list of factors on the mechanism's constant")
        for s in self.strengths:
            ContactPhysics(self.physics, float(s))    # names a bad mechanism or strength


@dataclass
class Selection:
    """``[selection]``: the candidates and their grids."""
    candidates: list = field(default_factory=list)

    def __post_init__(self):
        check(isinstance(self.candidates, list) and len(self.candidates) >= 1 and
              all(isinstance(c, dict) and set(c) == {"physics", "strengths"}
                  for c in self.candidates), "selection.candidates", self.candidates,
              "a non-empty list of {physics = NAME, strengths = [factors]} tables")
        self.candidates = [c if isinstance(c, Candidate) else Candidate(**c)
                           for c in self.candidates]
        names = [c.physics for c in self.candidates]
        check(len(set(names)) == len(names), "selection.candidates", names,
              "distinct mechanisms")


@dataclass
class Parts:
    bench: BenchSpec
    processor: events.EventProcessor
    evaluation: cv.Evaluation
    selection: Selection


def plan(spec: dict) -> Plan:
    """Check the whole spec before any long work; build its parts."""
    specs.check_top_level(spec, SECTIONS)
    for key in ("physics", "physics_strength"):
        if key in spec.get("stimulus", {}):
            raise SpecError(f"stimulus.{key}", spec["stimulus"][key],
                            "no value here: [selection] sets the mechanism for every run")
    bench_spec = bench_section(spec)
    check({"wood", "aluminium", *PAPER_PAIR} <= set(bench_spec.materials),
          "stimulus.materials", list(bench_spec.materials),
          "a list holding wood, aluminium and brass (the targets and the paper's pair)")
    processor = events_section(spec, bench_spec.rate_hz)
    evaluation = evaluation_section(spec)
    with specs.section("selection"):
        selection = Selection(**specs.check_section(spec, "selection", Selection))
    return Plan("model_selection", spec,
                Parts(bench_spec, processor, evaluation, selection), estimate)


def point_workers(parts: Parts, points: int) -> int:
    """Processes the grid points run on: ``stimulus.n_jobs``, no more than there are points
    (1: the study's own process)."""
    return max(1, min(parts.bench.n_jobs, points))


def estimate(parts: Parts):
    """Every grid point's bench set, features and calibration read-out, each candidate's
    predicted read-outs, on the points' workers (``cost``)."""
    points = sum(len(c.strengths) for c in parts.selection.candidates)
    return cost.estimate(parts, point_workers(parts, points))
