"""Ground truth: what really happened in a recording, kept apart from what a robot can sense.

A read-out decides from samples and spikes alone, as a robot would at that moment. What a
source knows besides the samples — the contacts and their onsets, true distances and
materials; the bench set's material, distance, site and repetition of each event — is ground
truth, and it is reachable only here: a ``Recording`` carries it as ``truth`` (a
``GroundTruth``), a bench data set as the coordinates named in ``BENCH_LABELS`` (read them
with ``bench_labels``). ``tests/test_layout.py`` fails when a module of ``snn_antenna.readout``
imports this module, reads an attribute named ``truth`` or names a bench label, so a read-out
cannot peek by accident; ``snn_antenna.evaluation`` scores its decisions against the truth
afterwards.
"""
from __future__ import annotations

from dataclasses import dataclass

from . import bounds

# The labels of a bench data set (sources.bench): coordinates along its ``event`` dimension.
BENCH_LABELS = ("material", "distance_cm", "position", "repetition")


@dataclass(frozen=True)
class Event:
    """A labelled moment in a recording, e.g. a contact.

    ``kind`` is ``"contact"`` for contacts; ``t_s`` the onset, ``duration_s`` how long it is
    held; contacts carry ``distance_cm`` and ``material``.
    """
    kind: str
    t_s: float
    duration_s: float = 0.0
    distance_cm: float | None = None
    material: str | None = None

    def __post_init__(self):
        bounds.declared(self)
        bounds.number("t_s", self.t_s, 0.0, unit=" s")
        bounds.number("duration_s", self.duration_s, 0.0, unit=" s")
        if self.distance_cm is not None:
            bounds.number("distance_cm", self.distance_cm, 0.0, unit=" cm")

    def as_dict(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if v is not None}


@dataclass(frozen=True)
class GroundTruth:
    """The labelled events of one recording (empty when nothing is known, e.g. a live link)."""
    events: tuple[Event, ...] = ()

    def __post_init__(self):
        bounds.declared(self)
        object.__setattr__(self, "events", tuple(self.events))

    @property
    def contacts(self) -> tuple[Event, ...]:
        return tuple(e for e in self.events if e.kind == "contact")

    def __bool__(self) -> bool:
        return bool(self.events)


def bench_labels(data) -> dict:
    """The label coordinates of a bench data set (or of features that carry them), by name."""
    return {name: data[name] for name in BENCH_LABELS}
