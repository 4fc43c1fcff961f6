"""What the running network decides, window by window, for the live view's panels.

A panel per part the running network contains, and none for a part it does not. The live
pipeline (bridge/online.py's ``build_online``) runs one part, the resonator array, fed by the
coder whose gate compares the filtered signal with the input threshold Th, and read out by the
contact episode logic; the speed gate, CPG and control layer of ``networks/robot.toml`` and
``exploration.toml`` are not run live (the board streams the antenna only, no speed command),
so they have no panel.

Each window the pipeline publishes (``LiveView.window``) gathers one ``decided`` dict here,
``{panel: {field: value}}`` of plain numbers and strings; it travels in the same frame as the
window's rates and the view shows the latest (bridge/view_process.py, bridge/page.py).
"""
from __future__ import annotations

import numpy as np

from ..readout.contacts import tuned_above

# The parts the live pipeline runs: the coder and contact read-out belong to the resonators'.
LIVE_PARTS = ("resonators",)
# panel → (title, the part it belongs to)
PANELS = {"threshold": ("Gate: input threshold Th", "resonators"),
          "readout": ("Contact read-out", "resonators")}


class Decisions:
    """Per window: the Th in force and where it came from, and the read-out's decision on the
    window (a contact window or not, the episode it keeps open, the last contact's distance)."""

    def __init__(self, parts):
        self.coder = parts.chain.named_steps["coder"]
        self.detector = parts.detector
        self.neuron_hz = np.asarray(parts.array.neuron_hz, dtype=float)
        self._above = tuned_above(self.neuron_hz, self.detector.motion_band_hz)
        self.parts = LIVE_PARTS
        self.panels = {name: title for name, (title, part) in PANELS.items()
                       if part in self.parts}
        self._open_since: float | None = None
        self._last: dict | None = None

    def window(self, t_s: float, rates: np.ndarray, event) -> dict:
        """What was decided on the window starting at ``t_s`` (``event``: the tracker's)."""
        self.event(event)
        contact_window = bool(self.detector.is_contact_window(rates, self._above))
        peak = int(np.argmax(rates))
        return {
            "threshold": {"th_g": float(self.coder.threshold),
                          "set_by": "preprocess.threshold (fixed: no speed gate runs live)"},
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
