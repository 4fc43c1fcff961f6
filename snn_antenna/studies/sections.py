"""The spec sections several studies read the same way, read here once.

- the **source**: a robot scene, generated from a ``[stimulus]``-like table or, for a study
  that reads recordings, the first drive of the folder its ``data`` names
  (:func:`source_section`, :func:`scene_section`); from then on the study asks the scene what
  every source answers (``sources.source.Scene``) and never which kind it has;
- the **chain**: ``[preprocess]``, the settings of ``preprocess.make_chain`` besides the
  sensor's, which each source gives (``preprocess.chain_section``, which the live path
  shares);
- the **array**: ``[network]``, a ``ResonatorArray`` (``networks.resonators.array_section``,
  ``network_table``, ``check_rates``, which the live path shares);
- the **detector**: ``[readout]``, read by ``readout.contacts.detector_from_spec``, which the
  live path shares;
- the **bench set** and what reads it: the recorded contacts ``data`` names or the
  generator's ``[stimulus]`` (:func:`bench_section`), ``[events]`` (the paper's processing of
  each contact, :func:`events_section`) and ``[evaluation]`` (the splits and read-outs,
  :func:`evaluation_section`).

Every reader checks its section before anything runs and names the section in its refusals.
"""
from __future__ import annotations

from ..core import spec as specs
from ..core.errors import check
from ..evaluation import crossval as cv
from ..readout.events import EventProcessor
from ..sources import bench, recorded
from ..sources.scenes import CourseScene, scene_from_spec
from ..sources.source import BenchSet
from ..sources.stimuli import RobotScene
from .contract import cache_folder

def scene_section(spec: dict, table: str = "stimulus", course: bool = False):
    """The generated scene of ``[table]``: a ``RobotScene`` (``kind = "robot"``, the
    default), or for a study that needs posts to drive among (``course``) a ``CourseScene``."""
    with specs.section(table):
        if course:
            given = spec.get(table, {"kind": "course"})
            scene = scene_from_spec(given)
            check(isinstance(scene, CourseScene), "kind", given.get("kind", "robot"),
                  "'course' (scenes with posts)")
        else:
            specs.check_section(spec, table, RobotScene, extra=["kind"])
            scene = scene_from_spec(spec.get(table, {}))
        scene.validate()
    return scene


def source_section(spec: dict, table: str = "stimulus"):
    """The scene a study that reads recordings drives: the first drive of the folder the
    spec's ``data`` names, in place of ``[table]``'s scene, or that scene."""
    if spec.get("data") is not None:
        return recorded.open_drives(spec["data"]).scene(0)
    return scene_section(spec, table)


def bench_section(spec: dict) -> BenchSet:
    """The bench set a study reads: the recorded contacts of the folder the spec's ``data``
    names, or the generator's of its ``[stimulus]`` (whose cache folder must be usable)."""
    if spec.get("data") is not None:
        return bench.source_from_spec(spec)
    with specs.section("stimulus"):
        source = bench.source_from_spec(spec)
        source.validate()
        cache_folder("cache_dir", source.cache_dir)
    return source


def events_section(spec: dict, rate_hz: float) -> EventProcessor:
    """``[events]``: the paper's processing of each contact, at the bench set's rate."""
    with specs.section("events"):
        table = specs.check_section(spec, "events", EventProcessor, exclude=["rate_hz"])
        return EventProcessor(rate_hz=rate_hz, **table)


def evaluation_section(spec: dict) -> cv.Evaluation:
    """``[evaluation]``: the splits by repetition, their seeds and the read-outs to train."""
    with specs.section("evaluation"):
        return cv.Evaluation(**specs.check_section(spec, "evaluation", cv.Evaluation))


__all__ = ["scene_section", "source_section", "bench_section", "events_section",
           "evaluation_section"]
