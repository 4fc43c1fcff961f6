"""The live path's inputs and their one owner: the coder's threshold Th, the rate-map window and
the robot's speed command.

Whatever changes an input submits the change to the :class:`InputSchedule` at a sample index:
the speed gate (bridge/online/robot.py) the Th it recalls for each next window of the network,
the page (bridge/view/view.py) what a person asked for, at the first boundary of a published
window the coder has not reached (and after calibration), a replay
(bridge/online/controls.py's ``RecordedChanges``) the changes a recording journaled, at the
samples they applied at. The schedule applies each where it is due: a Th as the coder reaches
its sample (the pipeline codes every piece with the schedule's Th), a window length at the end
of a published window, a speed command at the end of one of the network's windows. It is the
only writer of the three.

Every change it applies, but the gate's, is announced to the pipeline's handlers
(``WindowHandler.changed``): the recorder journals it in ``events.jsonl``, the view shows it,
the robot drives at a new speed, and a replay that submits the journal again applies the same
changes at the same samples, so it codes the same input. The gate's Th steps are not journaled:
the network recalls them again from the same input. A Th a person set overrides the gate's for
the rest of the run.

The rate-map window is a whole number of the network's own windows (the spec's
``readout.window_s``): the array keeps running as it was built, and each published window sums
``windows`` of its windows (rates are per second, so the read-out's thresholds keep their
meaning).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

from ...core.errors import SpecError

FIELDS = ("th_g", "windows", "speed_cm_s")      # what a change may change
GATE = "gate"                                   # the submitter whose Th a person overrides


@dataclass(frozen=True)
class Change:
    """One checked change: ``field`` is ``th_g``, ``windows`` (network windows per published
    window) or ``speed_cm_s``."""
    field: str
    value: float


@dataclass(frozen=True)
class _Pending:
    at: int                             # the sample index it is due at
    change: Change
    by: str                             # "gate", "page", "replay"
    asked: float                        # host time it was submitted


class InputSchedule:
    """The live inputs of one stream: ``th_g`` (the Th coding the coder's next sample, set by
    ``th_source``: None for the spec's, "gate" or "manual"), ``windows`` (network windows per
    published window, counted from sample ``origin``) and ``speed_cm_s`` (None: no part of the
    network reads a speed). ``position`` is the coder's next sample; ``events`` every change
    applied but the gate's, in order."""

    def __init__(self, th_g: float, base_window_s: float, rate_hz: float, n_calibration: int,
                 speed_cm_s: float | None = None):
        self.th_g, self.th_source = float(th_g), None
        self.windows, self.origin = 1, 0
        self.speed_cm_s = speed_cm_s
        self.position = 0
        self.base_window_s, self.rate_hz = base_window_s, rate_hz
        self.base_samples = int(round(base_window_s * rate_hz))
        self.n_calibration = n_calibration
        self.events: list[dict] = []
        self._pending: list[_Pending] = []
        self._gate_until: int | None = None     # the end of the window the gate's Th codes

    @property
    def window_s(self) -> float:
        """The length of the published rate-map windows."""
        return self.windows * self.base_window_s

    # ---- changes in ------------------------------------------------------------------------
    def submit(self, change: Change, by: str, at: int | None = None) -> None:
        """Schedule ``change`` at sample ``at`` (None: the first boundary of a published window
        at or after the coder's next sample and the end of calibration)."""
        if change.field not in FIELDS:
            raise SpecError("change", change.field, ", ".join(FIELDS))
        if change.field == "speed_cm_s" and self.speed_cm_s is None:
            raise SpecError("network", "no part that reads a speed", "a network whose speed "
                            "gate or CPG reads the speed command (networks/live_robot.toml)")
        if by == GATE:
            if change.field != "th_g":
                raise SpecError("change", change.field, "th_g from the gate")
            if self.th_source == "manual":      # a person's Th holds for the rest of the run
                return
        if at is None:
            at = self.next_boundary(max(self.position, self.n_calibration))
        elif change.field == "th_g" and at < self.position:
            raise SpecError("sample", at, f"a sample the coder has not coded yet (from "
                                          f"{self.position})")
        if by == GATE:
            self._gate_until = at + self.base_samples
        self._pending.append(_Pending(int(at), change, by, time.time()))
        # Due in sample order; where the gate and a person set Th at one sample, the person's
        # is applied last and holds.
        self._pending.sort(key=lambda p: (p.at, p.by != GATE))

    def next_boundary(self, index: int) -> int:
        """The first boundary of a published window at or after sample ``index``, taking the
        window changes already scheduled into account (they move the boundaries)."""
        origin, step = self.origin, self.windows * self.base_samples
        for p in self._pending:
            if p.change.field == "windows" and p.at <= index:
                origin, step = p.at, int(p.change.value) * self.base_samples
        return origin + max(0, math.ceil((index - origin) / step)) * step

    # ---- applied ---------------------------------------------------------------------------
    def coded_until(self) -> int | None:
        """The end of the samples whose Th is known: with the gate's Th in force, the end of
        the window it codes (the next window's is recalled once the network has integrated
        this one); None: no limit."""
        return None if self.th_source == "manual" else self._gate_until

    def code(self, n: int) -> tuple[list[tuple[int, float]], list[dict]]:
        """The coder codes its next ``n`` samples: the pieces to code them in, as (end offset,
        Th), each Th change applied as the coder reaches its sample; and the changes applied
        (to announce)."""
        start, stop = self.position, self.position + n
        pieces, events, at = [], [], start
        while True:
            for p in [p for p in self._pending if p.change.field == "th_g" and p.at <= at]:
                self._pending.remove(p)
                if p.by == GATE:
                    if self.th_source != "manual":
                        self.th_g, self.th_source = p.change.value, GATE
                    continue
                was, self.th_g, self.th_source = self.th_g, p.change.value, "manual"
                events.append(self._applied(p.at, p, was))
            cut = min((p.at for p in self._pending if p.change.field == "th_g" and p.at > at),
                      default=stop)
            cut = min(cut, stop)
            if cut > at:
                pieces.append((cut - start, self.th_g))
            if cut >= stop:
                break
            at = cut
        self.position = stop
        return pieces, events

    def window_ended(self, end_index: int, published: bool) -> list[dict]:
        """One of the network's windows ended at sample ``end_index`` (``published``: a
        rate-map window ended there too): the speed commands due there (the gate and CPG read
        the new speed from the next window on) and, at a published window's end, a window
        change due; the changes applied (to announce)."""
        events = []
        for p in [p for p in self._pending
                  if p.change.field == "speed_cm_s" and p.at <= end_index]:
            self._pending.remove(p)
            was, self.speed_cm_s = self.speed_cm_s, p.change.value
            events.append(self._applied(end_index, p, was))
        if published:
            for p in [p for p in self._pending
                      if p.change.field == "windows" and p.at <= end_index][:1]:
                self._pending.remove(p)
                was = self.window_s
                self.windows, self.origin = int(p.change.value), end_index
                events.append(self._applied(end_index, p, was))
        return events

    def _applied(self, index: int, p: _Pending, was: float) -> dict:
        change = p.change
        shown = (("window_s", change.value * self.base_window_s) if change.field == "windows"
                 else (change.field, change.value))
        event = {"sample": index, "t_s": round(index / self.rate_hz, 6), "field": change.field,
                 "value": change.value, "shown": {shown[0]: shown[1]}, "was": was, "by": p.by,
                 "requested_unix_s": round(p.asked, 6), "applied_unix_s": round(time.time(), 6)}
        self.events.append(event)
        return event
