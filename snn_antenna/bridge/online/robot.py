"""The robot network, live: a composed network spec's speed gate, CPG and control layer in
Brian2 beside the resonator array, stepping with the stream (``networks/live_robot.toml``).

The parts are the ones ``assembly.build`` makes (``assembly.part_objects``), wired to the
array's own group and run in the same network as it (``ResonatorArray.stream(companions=...)``);
they are steered as the closed exploration loop steers them (``closed_loop.steer``). After
each of the network's windows, :meth:`LiveRobot.window` reads them:

- the speed command in force is the robot's own: ``--speed`` at the start, then each speed
  the page sets (the input schedule, bridge/online/schedule.py, applies it at a window boundary
  and announces it: journaled, replayed); once the control layer's motor unit fires the robot
  stops (speed 0, the CPG frozen: ``closed_loop.FREEZE_HOLD``) until the next speed command
  drives it on;
- the gate's recalled Th (``SpeedGate.decode`` of its read-out trace) codes the next window,
  submitted to the input schedule at the window's first sample: the paper's state-dependent
  modulation of the coder. A Th set from the page is a manual override: from the window
  boundary it applies at, the gate's Th is shown but no longer used (the schedule's
  ``th_source`` says which is in force) for the rest of the run;
- the CPG's phase and pan/tilt command (``CPG.phase``, ``CPG.angles`` of its ring's traces),
  the contact and motor units' spikes in the window.

The board streams the antenna only, so the gate learns Th*(speed) before the stream starts
(the spec's ``[gate_training]``, as in studies/exploration.toml) and its read-out starts at
the rate it settles to at the first speed (the motor command precedes the motion, as
``SpeedGate.thresholds``' warm-up).
"""
from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

from ...core.errors import SpecError
from ...networks.assembly import part_objects
from ...networks.control import CONTROL_UNITS, unit_spike_counts
from ...networks.gate import read_trace
from ...readout.closed_loop import steer
from ...sources.antenna import SPEED_LIMIT_CM_S
from ..wire.handler import WindowHandler
from .schedule import GATE, Change
from ...sources import bench

CACHE_DIR = "out/.cache"                # where a trained gate is kept (as the bench sets are)

# Parts the live stream cannot run, and why (named in the refusal).
NOT_LIVE = {"material": "its read-out is fit offline on bench contacts of the struck rods' "
                        "band (networks/bench_material.toml: 90-420 Hz at dt 0.005 ms), which "
                        "the board's 1 kHz stream cannot carry"}


def check_live_parts(parts) -> None:
    """A composed spec runs live when it has the array and no part in NOT_LIVE."""
    for name in parts:
        if name in NOT_LIVE:
            raise SpecError("network.parts", name, f"parts that run live (not {name!r}: "
                                                   f"{NOT_LIVE[name]})")
    if "resonators" not in parts:
        raise SpecError("network.parts", list(parts), "a list with 'resonators': the live "
                                                      "stream feeds the resonator array")


def speed_range(configured: dict) -> tuple[float, float] | None:
    """The speeds the running network accepts (the gate's range; else what the antenna model
    covers), or None when no part of it reads the speed command."""
    if "gate" in configured:
        return tuple(float(v) for v in configured["gate"].speed_range_cm_s)
    if "cpg" in configured:
        return (0.0, float(SPEED_LIMIT_CM_S))
    return None


def check_speed(value, accepted: tuple[float, float] | None, field: str = "speed") -> float:
    """The one check of a speed command (``--speed``, the page's speed, a replayed event)."""
    if accepted is None:
        raise SpecError(field, value, "no speed: the network has no part that reads the "
                                      "speed command (a gate or a CPG)")
    lo, hi = accepted
    number = value if isinstance(value, (int, float)) and not isinstance(value, bool) else None
    if number is None or not math.isfinite(number) or not lo <= number <= hi:
        raise SpecError(field, value, f"a speed in cm/s within [{lo:g}, {hi:g}] (what the "
                                      "running network's gate or CPG takes)")
    return float(number)


def trained_gate(gate, speeds_cm_s, th_star_g, cache_dir=CACHE_DIR):
    """``gate`` fitted on the examples (``SpeedGate.fit``), from the cache when the same gate
    learned the same examples before with the same code (``bench.cached``): its weights and Th
    range, all that recall uses. Learning takes ~5 s; every stream and replay starts with it."""
    import xarray as xr

    speeds, th = np.asarray(speeds_cm_s, float), np.asarray(th_star_g, float)
    fields = {"gate": dataclasses.asdict(gate), "speeds_cm_s": speeds.tolist(),
              "th_star_g": th.tolist()}
    path = Path(cache_dir) / f"gate-{bench.cache_key(fields, __name__)}.zarr"

    def learn():
        fitted = dataclasses.replace(gate).fit(speeds, th)
        return xr.Dataset({"weights": ("speed_neuron", fitted.weights_)},
                          attrs={"th_lo": fitted.th_range_[0], "th_hi": fitted.th_range_[1]})

    stored = bench.cached(path, learn, __name__, log=lambda text: print(text, file=sys.stderr))
    gate.weights_ = np.asarray(stored.weights.values, dtype=float)
    gate.th_range_ = (float(stored.attrs["th_lo"]), float(stored.attrs["th_hi"]))
    return gate


class LiveRobot(WindowHandler):
    """The composed network's other parts at run time. ``configured``: the spec's parts (the
    gate fitted); ``speed_cm_s``: the speed command at the start."""

    def __init__(self, configured: dict, speed_cm_s: float):
        self.configured = configured
        self.names = [name for name in configured if name != "resonators"]
        self.speed_range = speed_range(configured)
        # Without a part that reads it, there is no speed command (the page offers none).
        self.start_speed = (check_speed(speed_cm_s, self.speed_range) if self.speed_range
                            else 0.0)
        gate = configured.get("gate")
        # The read-out's settled rate at the first speed (its trace starts there, not at 0).
        self._settled_rate = (float(gate.encode(gate.predict([self.start_speed]))[0])
                              if gate is not None else None)
        self.schedule = None
        self.reset()

    def reset(self) -> None:
        """A run starts at the first speed command, driving, with the gate's Th."""
        self.commanded = self.start_speed
        self.objects: dict = {}
        self.stopped_since: float | None = None
        self.recalled_th: float | None = None
        self.decided: dict = {}
        self._counts, self._seen = None, {}

    # ---- in the stream's network -----------------------------------------------------------
    def build(self, group) -> list:
        """The parts' Brian2 objects wired to the array's ``group`` (a fresh run: state reset);
        ``ResonatorArray.stream`` runs them in its network."""
        self.reset()
        objects = part_objects(self.configured, group)
        if "readout" in objects:
            objects["readout"].r_read = self._settled_rate
        self.objects = objects
        # The control units count their own spikes (no monitor: one Python call less per step).
        self._counts = unit_spike_counts(objects) if "control_contact" in objects else None
        self._seen = dict.fromkeys(CONTROL_UNITS, 0)
        self._r_read = read_trace(objects) if "readout" in objects else None
        self._ring = objects["cpg"].variables["x"].get_value() if "cpg" in objects else None
        self.speed = steer(objects, self.commanded, moving=True)
        self.recalled_th = self._recall()
        return list(objects.values())

    def _recall(self) -> float | None:
        if self._r_read is None:
            return None
        return float(self.configured["gate"].decode(self._r_read[0]))

    # ---- a WindowHandler (bridge/wire/handler.py) -------------------------------------------
    def stream_started(self, parts, schedule) -> None:
        """The gate's Th for the first window: its recall of the read-out's settled rate at the
        first speed (where ``build`` starts the trace)."""
        self.schedule = schedule
        if self._settled_rate is not None:
            first = float(self.configured["gate"].decode(self._settled_rate))
            schedule.submit(Change("th_g", first), GATE, 0)

    def window(self, window) -> None:
        """A window of the network ended: the stop signal, the gate's Th for the next window,
        the CPG's command, all read from the parts."""
        end_s = window.end_s
        spikes = {}
        if self._counts is not None:
            for unit, total in zip(CONTROL_UNITS, self._counts.tolist()):
                spikes[unit], self._seen[unit] = total - self._seen[unit], total
        if spikes.get("motor") and self.stopped_since is None:
            self.stopped_since = round(float(end_s), 6)
            self.speed = steer(self.objects, self.commanded, moving=False)
        self.recalled_th = self._recall()
        decided = {}
        if "gate" in self.configured:
            decided["gate"] = {"speed_cm_s": self.speed, "commanded_cm_s": self.commanded,
                               "recalled_th_g": round(self.recalled_th, 6)}
        if "cpg" in self.configured:
            cpg = self.configured["cpg"]
            ring = self._ring.copy()
            pan, tilt = cpg.angles(ring)
            decided["cpg"] = {"phase_deg": round(float(np.degrees(cpg.phase(ring))) % 360, 2),
                              "pan_deg": round(float(pan), 2), "tilt_deg": round(float(tilt), 2),
                              "frozen": self.stopped_since is not None}
        if "control" in self.configured:
            decided["control"] = {"contact_unit_spikes": spikes.get("contact", 0),
                                  "motor_unit_spikes": spikes.get("motor", 0),
                                  "stopped_since_s": self.stopped_since}
        self.decided = decided
        if self.recalled_th is not None:        # it codes the next window
            self.schedule.submit(Change("th_g", self.recalled_th), GATE, window.end_index)

    def changed(self, event: dict) -> None:
        """A new speed command (the page's, at a window boundary): the robot drives at it,
        even after a stop."""
        if event["field"] == "speed_cm_s":
            self.commanded = float(event["value"])
            self.stopped_since = None
            self.speed = steer(self.objects, self.commanded, moving=True)
