"""Hands on the live pipeline: the input threshold Th, the rate-map window and (on a network
with a speed gate or CPG: bridge/online/robot.py) the robot's speed command, changed from the live
page (or ``POST /control``), applied at a window boundary, journaled into the recording and
replayed from it.

A request travels: the page (bridge/view/page.py) or ``/control`` → :func:`parse_control` in the
view process (the one parser: a bad value is refused there, naming the field, the value and the
accepted range) → a bounded queue → the view's handler in the pipeline
(bridge/view/view.py's ``LiveView``), which takes it without waiting and submits it to the input
schedule (bridge/online/schedule.py): applied at the first window boundary the coder has not
reached yet (and after calibration). The change is thus applied at a sample index, which the
recording's ``events.jsonl`` keeps: a replay submits the same changes at the same indices
(:class:`RecordedChanges`), so it codes the same input and finds the same contacts.
"""
from __future__ import annotations

import json
import math

from ...core.errors import SpecError
from ..wire.handler import WindowHandler
from ..wire.protocol import BOARD_FULL_SCALE_G
from ..wire.recorder import EVENTS_FILE, read_events
from .robot import check_speed
from .schedule import Change

TH_MAX_G = BOARD_FULL_SCALE_G           # the filtered signal never exceeds the ADC's range
MAX_WINDOWS = 20                        # the longest rate-map window, in the network's windows
MAX_REQUEST_BYTES = 1024


FIELDS = ("th_g", "window_s", "speed_cm_s")     # what a request may change (window in seconds)


def accepted_range(field: str, base_window_s: float) -> str:
    if field == "th_g":
        return f"a number of g in [0, {TH_MAX_G:g}] (the coder's input threshold Th)"
    return (f"a window in seconds, a whole multiple of the network's window "
            f"{base_window_s:g} s, from {base_window_s:g} to {MAX_WINDOWS * base_window_s:g} s")


def parse_control(body, base_window_s: float,
                  speed_range_cm_s: tuple[float, float] | None = None) -> Change:
    """The one parser of control requests: JSON (bytes, text or a dict) with exactly one of
    ``{"th_g": number}``, ``{"window_s": number}`` or ``{"speed_cm_s": number}`` (within
    ``speed_range_cm_s``, the running network's: None when no part of it reads a speed).
    Anything else raises SpecError naming the field, the value and what is accepted."""
    if isinstance(body, (bytes, bytearray)):
        if len(body) > MAX_REQUEST_BYTES:
            raise SpecError("control", f"{len(body)} bytes", f"a request of at most "
                                                             f"{MAX_REQUEST_BYTES} bytes")
        try:
            body = body.decode("utf-8")
        except UnicodeDecodeError:
            raise SpecError("control", repr(bytes(body[:40])), "UTF-8 JSON text") from None
    if isinstance(body, str):
        try:
            body = json.loads(body)
        except ValueError:
            raise SpecError("control", body[:60], 'JSON such as {"th_g": 0.05} or '
                                                  '{"window_s": 0.1}') from None
    if not isinstance(body, dict) or len(body) != 1:
        raise SpecError("control", body, 'one field: {"th_g": number}, {"window_s": number} '
                                         'or {"speed_cm_s": number}')
    (field, value), = body.items()
    if field not in FIELDS:
        raise SpecError("control", field, ", ".join(FIELDS))
    if field == "speed_cm_s":
        return Change("speed_cm_s", check_speed(value, speed_range_cm_s, "speed_cm_s"))
    number = value if isinstance(value, (int, float)) and not isinstance(value, bool) else None
    if field == "th_g":
        if number is None or not math.isfinite(number) or not 0 <= number <= TH_MAX_G:
            raise SpecError("th_g", value, accepted_range("th_g", base_window_s))
        return Change("th_g", float(number))
    windows = None if number is None or not math.isfinite(number) else number / base_window_s
    # A finite but huge number of seconds overflows to an infinite number of windows.
    if windows is None or not math.isfinite(windows) \
            or abs(windows - round(windows)) > 1e-6 * max(1.0, windows) \
            or not 1 <= round(windows) <= MAX_WINDOWS:
        raise SpecError("window_s", value, accepted_range("window_s", base_window_s))
    return Change("windows", float(round(windows)))


class RecordedChanges(WindowHandler):
    """A replay's hands: the changes a recording journaled (``recorded_events``), submitted to
    the input schedule at the samples they applied at, so the replay codes the same input and
    finds the same contacts. Each is checked against ``parts`` here, before the stream starts:
    a value this network cannot take is refused, never applied as another."""

    def __init__(self, parts, events):
        self.changes = [(int(event["sample"]), journaled_change(event, parts.window_s))
                        for event in events]
        if parts.speed_cm_s is None and any(c.field == "speed_cm_s" for _, c in self.changes):
            raise SpecError("network", "no part that reads a speed", "a network whose speed "
                            "gate or CPG reads the speed command (networks/live_robot.toml): "
                            "the recording's events.jsonl changes the speed")

    def stream_started(self, parts, schedule) -> None:
        for at, change in self.changes:
            schedule.submit(change, "replay", at)


def journaled_change(event: dict, base_window_s: float) -> Change:
    """A journaled change as this run applies it: Th and the window (in seconds) through the one
    parser, so that a value this network cannot take is refused, never applied as another."""
    field, value = event["field"], event["value"]
    if field not in ("th_g", "window_s"):
        return Change(field, float(value))
    try:
        return parse_control({field: value}, base_window_s)
    except SpecError as exc:
        raise SpecError(f"{EVENTS_FILE} sample {event['sample']} {exc.field}", exc.value,
                        exc.accepted) from None


def recorded_events(recording_dir) -> list[dict]:
    """The control events a recording holds (``events.jsonl``, checked by the recording's
    reader; a torn last line, from a killed process, is dropped), in the order they were
    applied."""
    return read_events(recording_dir)
