"""What the online pipeline hands its handlers: one protocol for all of them.

``run_online`` (bridge/online/pipeline.py) drives the run report (report.py), a composed
network's other parts (robot.py), the page's controls (controls.py), the live view
(bridge/view/view.py, with the panels' decisions of live_state.py) and the terminal's lines
(terminal.py). Each is a :class:`WindowHandler`: told the parts when the stream starts, each
of the network's windows as the network has integrated it, and the stream's last contact
event when it ends.

The network's windows are the array's own (``readout.window_s``); the rate map the pipeline
publishes sums one or more of them (the page's window control), so a window carries a
:class:`Published` rate-map window only where one ends. A composed network's parts are read at
every window; the report, the view and the terminal act on the published ones.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class Published:
    """A rate-map window the pipeline published."""
    t_s: float                          # its start (stream time)
    window_s: float                     # its length: a whole number of the network's windows
    rates: np.ndarray                   # spikes/s per resonator
    event: tuple | None                 # the read-out's contact event on it, if any
    arrived: float | None               # host time its last sample arrived (live only)
    latency_ms: float | None            # from that arrival to its publication (live only)
    realtime_factor: float              # the run report's, this window counted


@dataclass(frozen=True)
class Window:
    """One of the network's windows, once the network has integrated it."""
    end_s: float                        # its end (stream time)
    end_index: int                      # the sample index at its end
    waiting_s: float                    # the time the pipeline waited for the port so far
    published: Published | None = None  # the rate-map window ending here, if one does


@runtime_checkable
class WindowHandler(Protocol):
    """What every handler of the online pipeline implements."""

    def stream_started(self, parts) -> None:
        """The stream starts with ``parts`` (pipeline.OnlineParts)."""

    def window(self, window: Window) -> None:
        """A window of the network ended (with a published rate-map window, or not)."""

    def stream_ended(self, final_event) -> None:
        """The stream ended; ``final_event``: the contact it closed (None: none open)."""
