"""What a live stream hands its handlers: one protocol each for the source loop and the online
pipeline, every method a no-op by default, as pyserial's ``serial.threaded.Protocol``.

:class:`BatchHandler` is the source loop's (bridge/wire/source.py's ``SourceLoop``): every batch
the source delivered, and a call when none came. :class:`WindowHandler` adds the online
pipeline's (bridge/online/pipeline.py's ``run_online``): the stream's start, each chunk as the
coder coded it, each of the network's windows once the network has integrated it, each change
of the live inputs the input schedule applied (bridge/online/schedule.py), and the stream's
end. A handler overrides what it uses: the recorder writes batches and journals the changes,
the view gathers all of it, the terminal prints the windows.

The network's windows are the array's own (``readout.window_s``); the rate map the pipeline
publishes sums one or more of them (the schedule's window length), so a window carries a
:class:`Published` rate-map window only where one ends.
"""
from __future__ import annotations

from dataclasses import dataclass

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


class BatchHandler:
    """What the source loop hands a handler."""

    def handle(self, batch) -> None:
        """A batch the source delivered (bridge/wire/source.py's ``Batch``)."""

    def idle(self) -> None:
        """No batch came within the loop's idle interval."""


class WindowHandler(BatchHandler):
    """What the online pipeline hands a handler, besides the source's batches."""

    def stream_started(self, parts, schedule) -> None:
        """The stream starts with ``parts`` (pipeline.OnlineParts); ``schedule`` (its
        InputSchedule) takes the changes a handler submits to the live inputs."""

    def coded(self, signal_g: np.ndarray, th_g: float, coded: np.ndarray) -> None:
        """The coder coded a chunk: its input (the conditioned signal its gate compares with
        Th), the Th in force, its output."""

    def window(self, window: Window) -> None:
        """A window of the network ended (with a published rate-map window, or not)."""

    def changed(self, event: dict) -> None:
        """The schedule applied a change of the live inputs (Th, the rate-map window, the
        speed command) at a sample index: ``event`` as the run report's ``controls`` lists
        it."""

    def stream_ended(self, final_event) -> None:
        """The stream ended; ``final_event``: the contact it closed (None: none open)."""
