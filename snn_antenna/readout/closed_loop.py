"""The closed exploration loop's reflexes and the robot's own record of a loop.

The robot drives among posts; the CPG sweeps the antenna; where the rod meets a post the
antenna rings; the resonators feed the class-I control layer, whose motor unit stops the robot
and, by ``FREEZE_HOLD``, the sweep (``steer``). The exploration study closes the loop
(``studies.exploration.run``), the live stream steers with the same ``steer``; what the robot
knows after a loop is a ``RobotRecord``, with no ground truth in it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import bounds
from ..sources import antenna

# The freeze reflex: once the motor unit fires, this inhibitory hold on the CPG ring pulls
# every neuron's rest (drive + token − hold) far below its threshold of 1, so the sweep stops.
FREEZE_HOLD = 5.0


@dataclass
class LoopSettings:
    speed_cm_s: float = 15.0
    duration_s: float = 12.0
    chunk_ms: float = 10.0
    calibration_s: float = 2.0

    def __post_init__(self):
        bounds.declared(self)
        antenna.self_motion_rms_g(self.speed_cm_s)
        bounds.positive_seconds("duration_s", self.duration_s)
        bounds.number("chunk_ms", self.chunk_ms, 1.0, 1e6, unit=" ms")
        bounds.positive_seconds("calibration_s", self.calibration_s)


@dataclass
class RobotRecord:
    """What the robot itself knows after the loop: no ground truth in here."""
    t: np.ndarray
    speed: np.ndarray
    pan: np.ndarray
    tilt: np.ndarray
    th: np.ndarray
    x_cm: np.ndarray
    rates: object
    detections: list
    stopped_at: float | None
    wall_s: float
    built: list


def steer(objects: dict, speed_cm_s: float, moving: bool) -> float:
    """The speed command in force (0 once the motor unit stopped the robot) into the parts
    that read it, the speed gate and the CPG, and the freeze hold on the CPG once stopped.
    The closed loop here and the live stream (bridge/online/pipeline.py) steer with it."""
    speed = float(speed_cm_s) if moving else 0.0
    if "cpg" in objects:
        objects["cpg"].speed_cm_s = speed
        objects["cpg"].hold_input = 0.0 if moving else FREEZE_HOLD
    if "speed_population" in objects:
        objects["speed_population"].speed_cm_s = speed
    return speed
