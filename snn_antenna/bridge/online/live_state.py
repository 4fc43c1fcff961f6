"""What the running network decides, window by window, for the live view's panels.

A panel per part the running network contains, and none for a part it does not. The live
pipeline (bridge/online/pipeline.py's ``build_online``) always runs the resonator array, fed by the
coder whose gate compares the filtered signal with the input threshold Th, and read out by the
contact episode logic (panels ``threshold`` and ``readout``). A composed network
(``networks/live_robot.toml``) also runs its speed gate, CPG and control layer beside it
(bridge/online/robot.py), each with its panel; with a speed gate, the gate's panel shows the Th in
force and where it came from, in place of ``threshold``.

Each window the pipeline publishes (``LiveView.window``) gathers one ``decided`` dict here,
``{panel: {field: value}}`` of plain numbers and strings; it travels in the same frame as the
window's rates and the view shows the latest (bridge/view/process.py, bridge/view/page.py).
"""
from __future__ import annotations

import numpy as np

from ...readout.contacts import tuned_above
from ..wire.handler import WindowHandler

# panel → (title, the part it belongs to, a part whose panel replaces it)
PANELS = {"threshold": ("Gate: input threshold Th", "resonators", "gate"),
          "gate": ("Speed gate: Th from the speed command", "gate", None),
          "cpg": ("CPG: pan-tilt sweep", "cpg", None),
          "control": ("Control layer: stop signal", "control", None),
          "readout": ("Contact read-out", "resonators", None)}


class Decisions(WindowHandler):
    """Per window: the Th in force and where it came from, the read-out's decision on the
    window (a contact window or not, the episode it keeps open, the last contact's distance),
    and what a composed network's other parts decided (bridge/online/robot.py)."""

    def __init__(self, parts):
        self.schedule = None                # the stream's input schedule: Th and its source
        self.detector = parts.detector
        self.neuron_hz = np.asarray(parts.array.neuron_hz, dtype=float)
        self._above = tuned_above(self.neuron_hz, self.detector.motion_band_hz)
        self.robot = parts.robot
        self.parts = ("resonators", *(self.robot.names if self.robot else ()))
        self.panels = {name: title for name, (title, part, unless) in PANELS.items()
                       if part in self.parts and unless not in self.parts}
        self._open_since: float | None = None
        self._last: dict | None = None
        self.latest: dict = {}              # what was decided on the latest window

    # ---- a WindowHandler (bridge/wire/handler.py), held by the view ---------------------------
    def stream_started(self, parts, schedule) -> None:
        self.schedule = schedule

    def window(self, window) -> None:
        """What was decided on a published window: ``latest``."""
        if window.published is not None:
            published = window.published
            self.latest = self.decided(published.t_s, published.rates, published.event)

    def stream_ended(self, final_event) -> None:
        self.event(final_event)

    def decided(self, t_s: float, rates: np.ndarray, event) -> dict:
        """What was decided on the window starting at ``t_s`` (``event``: the tracker's)."""
        self.event(event)
        contact_window = bool(self.detector.is_contact_window(rates, self._above))
        peak = int(np.argmax(rates))
        decided = dict(self.robot.decided) if self.robot else {}
        if "gate" in decided:           # the Th that coded this window, and its source
            decided["gate"] = {**decided["gate"], "th_g": self.schedule.th_g,
                               "th_source": self.schedule.th_source}
        else:
            decided["threshold"] = {"th_g": self.schedule.th_g,
                                    "set_by": "preprocess.threshold (fixed: the network has "
                                              "no speed gate)"}
        return {
            **decided,
            "readout": {"t_s": round(float(t_s), 6), "contact_window": contact_window,
                        "peak_hz": round(float(self.neuron_hz[peak]), 3) if rates[peak] > 0
                        else None,
                        "contact_open_since_s": self._open_since,
                        "last_distance_cm": self._last and self._last["distance_cm"],
                        "last_material": self._last and self._last.get("material")},
        }

    def event(self, event) -> None:
        if event is None:
            return
        kind, what = event
        if kind == "onset":
            self._open_since = float(what)
        else:
            self._open_since, self._last = None, what.as_dict()
