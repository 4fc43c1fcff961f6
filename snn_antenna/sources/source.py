"""What a study's data source answers, generated or recorded.

A study picks its source once, from its spec (a ``[stimulus]`` table: the generator; a
top-level ``data``: recordings imported by ``snn-antenna data import``), as xarray picks a
backend once in ``open_dataset``; from then on it asks every source the same questions and
never which kind it has. Every source answers (``Source``):

- ``describe()``: one sentence saying what the data is, for the run's log and report;
- ``provenance_rows()``: (what, value) rows saying where it came from, for the report (none
  for generated data: the spec and the code's version in every summary's provenance say it);
- ``summary_entry()``: what ``summary.json`` keeps of its origin (None for generated data,
  for the same reason).

A robot scene (``stimuli.RobotScene``, ``scenes.CourseScene``, ``recorded.RecordedScene``)
answers besides what it was itself set to match (``Scene.calibrated``: the generator's
constants, set to the paper's numbers; none for a recording), listed under "Calibrated to" in
a report, and gives its recording (``generate``). A bench set (``bench.BenchSpec``,
``recorded.RecordedBench``) gives its data set (``BenchSet.open_dataset``, behind
``bench.load``) and the repetitions it holds out of every split to calibrate on
(``BenchSet.calibration_repetitions``).
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

from ..report.page import Calibrated


@runtime_checkable
class Source(Protocol):
    """The questions every data source answers (see the module's docstring)."""

    def describe(self) -> str: ...

    def provenance_rows(self) -> list[tuple[str, str]]: ...

    def summary_entry(self) -> dict | None: ...


@runtime_checkable
class Scene(Source, Protocol):
    """A robot's drive: its sensor's recording, and what its source was set to match."""
    rate_hz: float
    adc_bits: int
    full_scale_g: float
    duration_s: float

    def calibrated(self) -> list[Calibrated]: ...

    def generate(self, seed: int = 0): ...


@runtime_checkable
class BenchSet(Source, Protocol):
    """Contacts on the bench, in the generator's data-set layout (``bench.generate``)."""
    rate_hz: float
    n_events: int

    def open_dataset(self, log=print, fresh: bool = False): ...

    def calibration_repetitions(self, n: int, field: str) -> list[int]: ...


class Generated:
    """The answers of a generated source about its origin: its spec and the code's version,
    kept in every summary's provenance, say where it came from."""

    def provenance_rows(self) -> list[tuple[str, str]]:
        return []

    def summary_entry(self) -> dict | None:
        return None


__all__ = ["Source", "Scene", "BenchSet", "Generated"]
