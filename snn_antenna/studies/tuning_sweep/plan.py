"""The tuning sweep's parts: the neuron model, the grid, how to sweep it and where to read
it; the whole grid checked and sized before a worker starts."""
from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...core.errors import check
from ...engine.cost import check_memory, estimate as sweep_estimate
from ...engine.evaluators import NEURON_AXES, NeuronSweep
from ...engine.grid import Grid
from ...evaluation.tuning import ReadPoint
from ..contract import COMMON, Plan

SECTIONS = ("neuron", "axes", "sweep", "reference")
OPTIONS = (*COMMON, "fresh", "scheduler")


@dataclasses.dataclass
class SweepSettings:
    chunk_points: int = 4096
    workers: int = 0  # 0: one worker process per CPU core; 1: run in this process

    def __post_init__(self):
        bounds.declared(self)
        bounds.positive_integer("chunk_points", self.chunk_points)
        bounds.integer("workers", self.workers, 0)
        check(isinstance(self.workers, int) and self.workers >= 0, "workers", self.workers,
              "an integer >= 0 (0: one per CPU core)")


class Parts(NamedTuple):
    """The checked spec: the neuron model, the grid, how to sweep it, where to read it."""
    neuron: NeuronSweep
    grid: Grid
    settings: SweepSettings
    reference: ReadPoint


def plan(spec: dict) -> Plan:
    """Check the whole spec (the grid included) before any simulation runs; a grid whose
    results or chunks cannot fit in memory is refused here, before a worker starts."""
    specs.check_top_level(spec, SECTIONS)
    with specs.section("neuron"):
        neuron = NeuronSweep(**specs.check_section(spec, "neuron", NeuronSweep,
                                                   exclude=["group_size", "shared"]))
    with specs.section("axes"):
        grid = Grid.from_spec(spec.get("axes", {}), NEURON_AXES)
    check("input_hz" in grid.axes and len(grid.axes["input_hz"]) >= 3, "axes.input_hz",
          list(grid.axes.get("input_hz", [])),
          "an axis of at least 3 input frequencies (the tuning curve)")
    with specs.section("sweep"):
        settings = SweepSettings(**specs.check_section(spec, "sweep", SweepSettings))
    with specs.section("reference"):
        point = ReadPoint(**specs.check_section(spec, "reference", ReadPoint))
    block = grid.block_shape(settings.chunk_points)
    neuron.for_grid(grid, block)                    # refuse a bad grid now
    check_memory(grid, NeuronSweep.OUTPUTS, int(np.prod(block)), neuron.bytes_per_point)
    return Plan("tuning_sweep", spec, Parts(neuron, grid, settings, point), estimate)


def estimate(parts: Parts):
    """The sweep's points, neuron-steps, time and memory, from the grid's shape alone."""
    chunk = parts.settings.chunk_points
    # the sweep as the run sizes its compiled group (``for_grid``)
    neuron = parts.neuron.for_grid(parts.grid, parts.grid.block_shape(chunk))
    return sweep_estimate(parts.grid, neuron, chunk, parts.settings.workers)


