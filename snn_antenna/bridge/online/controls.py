"""Hands on the live pipeline: the input threshold Th, the rate-map window and (on a network
with a speed gate or CPG: bridge/online/robot.py) the robot's speed command, changed from the live
page (or ``POST /control``), applied at a window boundary, journaled into the recording and
replayed from it.

A request travels: the page (bridge/view/page.py) or ``/control`` → :func:`parse_control` in the
view process (the one parser: a bad value is refused there, naming the field, the value and the
accepted range) → a bounded queue → :class:`Controls` in the pipeline, which takes it without
waiting and schedules it at the first window boundary the coder has not reached yet (and
after calibration). The change is thus applied at a sample index, which the recording's
``events.jsonl`` keeps: a replay schedules the same changes at the same indices, so it codes
the same input and finds the same contacts.

The rate-map window is a whole number of the network's own windows (the spec's
``readout.window_s``): the array keeps running as it was built, and each published window sums
``windows`` of its windows (rates are per second, so the read-out's thresholds keep their
meaning).
"""
from __future__ import annotations

import json
import math
import queue
import time
from dataclasses import dataclass

from ...core.errors import SpecError
from ..wire.protocol import BOARD_FULL_SCALE_G
from ..wire.recorder import EVENTS_FILE

TH_MAX_G = BOARD_FULL_SCALE_G           # the filtered signal never exceeds the ADC's range
MAX_WINDOWS = 20                        # the longest rate-map window, in the network's windows
MAX_REQUEST_BYTES = 1024


FIELDS = ("th_g", "window_s", "speed_cm_s")     # what a request may change


@dataclass(frozen=True)
class Change:
    """One checked request: ``field`` is ``th_g``, ``windows`` or ``speed_cm_s``."""
    field: str
    value: float


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
        from .robot import check_speed

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


class Controls:
    """The pipeline's side. ``requests``: the queue the view process puts Changes in (None:
    no page); ``journal``: called with each applied event (the recorder's ``note_event``);
    ``scheduled``: recorded events to apply again (a replay). Then ``on_applied`` (the view)
    sees every applied event too."""

    def __init__(self, parts, *, requests=None, journal=None, scheduled=(), on_applied=None,
                 rate_hz: float):
        self.coder = parts.chain.named_steps["coder"]
        self.robot = parts.robot
        self.rate_hz = rate_hz
        self.base_samples = int(round(parts.window_s * rate_hz))
        self.base_window_s = parts.window_s
        self.requests, self.journal, self.on_applied = requests, journal, on_applied
        self.windows = 1                        # network windows per published window
        self.origin = 0                         # sample index where the window last changed
        self.pending: list[tuple[int, Change, str, float]] = []    # (index, change, by, asked)
        for event in scheduled:
            self.pending.append((int(event["sample"]), journaled_change(event, self.base_window_s),
                                 "replay", time.time()))
        self.pending.sort(key=lambda p: p[0])
        if self.robot is None and any(p[1].field == "speed_cm_s" for p in self.pending):
            raise SpecError("network", "no part that reads a speed", "a network whose speed "
                            "gate or CPG reads the speed command (networks/live_robot.toml): "
                            "the recording's events.jsonl changes the speed")
        self.events: list[dict] = []
        self._polled = 0.0

    # ---- requests in ----------------------------------------------------------------------
    def poll(self, position: int, n_calibration: int) -> None:
        """Take what the page asked for (never waiting) and schedule it at the first window
        boundary at or after ``position`` (the coder's next sample) and calibration's end."""
        if self.requests is None or time.monotonic() - self._polled < 0.02:
            return
        self._polled = time.monotonic()
        while True:
            try:
                change = self.requests.get_nowait()
            except (queue.Empty, OSError, ValueError):  # empty, or the view is gone
                return
            self.pending.append((self.next_boundary(max(position, n_calibration)), change,
                                 "page", time.time()))

    def next_boundary(self, index: int) -> int:
        """The first boundary of a published window at or after sample ``index``, taking the
        changes already scheduled into account (they move the boundaries)."""
        origin, step = self.origin, self.windows * self.base_samples
        for at, change, _, _ in self.pending:
            if change.field == "windows" and at <= index:
                origin, step = at, int(change.value) * self.base_samples
        return origin + max(0, math.ceil((index - origin) / step)) * step

    # ---- applied ---------------------------------------------------------------------------
    def due(self, start: int, stop: int) -> list[tuple[int, Change, str, float]]:
        """The Th changes scheduled in [start, stop) (samples the coder is about to code)."""
        return [p for p in self.pending if p[1].field == "th_g" and start <= p[0] < stop]

    def apply_th(self, item) -> None:
        """A Th change, at its sample: on a network with a speed gate, a manual override of
        the gate's Th from here on (bridge/online/robot.py)."""
        index, change, by, asked = item
        self.pending.remove(item)
        was = float(self.coder.threshold)
        self.coder.threshold = change.value
        if self.robot is not None and self.robot.th_source is not None:
            self.robot.th_source = "manual"
        self._applied(index, change, by, asked, was)

    # ---- a WindowHandler (bridge/online/handler.py) -----------------------------------------
    def stream_started(self, parts) -> None:
        pass

    def window(self, window) -> None:
        """At the end of each of the network's windows the speed commands due; at the end of a
        published one, a window change due."""
        self.speed_change(window.end_index)
        if window.published is not None:
            self.window_change(window.end_index)

    def stream_ended(self, final_event) -> None:
        pass

    def speed_change(self, end_index: int) -> None:
        """A window of the network ended at ``end_index``: apply the speed commands due there
        (the gate and CPG read the new speed from the next window on)."""
        for item in [p for p in self.pending if p[1].field == "speed_cm_s" and p[0] <= end_index]:
            index, change, by, asked = item
            self.pending.remove(item)
            was = self.robot.command(change.value)
            self._applied(end_index, change, by, asked, was)

    def window_change(self, end_index: int) -> bool:
        """A published window ended at ``end_index``: apply a window change due there (True
        when the length of the published windows changed)."""
        for item in [p for p in self.pending if p[1].field == "windows" and p[0] <= end_index]:
            index, change, by, asked = item
            self.pending.remove(item)
            was = self.windows * self.base_window_s
            self.windows, self.origin = int(change.value), end_index
            self._applied(end_index, change, by, asked, was)
            return True
        return False

    @property
    def window_s(self) -> float:
        return self.windows * self.base_window_s

    def _applied(self, index: int, change: Change, by: str, asked: float, was: float) -> None:
        shown = (("window_s", change.value * self.base_window_s) if change.field == "windows"
                 else (change.field, change.value))
        event = {"sample": index, "t_s": round(index / self.rate_hz, 6), "field": change.field,
                 "value": change.value, "shown": {shown[0]: shown[1]}, "was": was, "by": by,
                 "requested_unix_s": round(asked, 6), "applied_unix_s": round(time.time(), 6)}
        self.events.append(event)
        if self.journal is not None:        # the window in seconds, as the page showed it
            self.journal({**event, "field": shown[0], "value": shown[1]})
        if self.on_applied is not None:
            self.on_applied(event)


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
    from ..wire.recorder import read_events

    return read_events(recording_dir)
