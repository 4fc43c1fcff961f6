"""The live pipeline's terminal output: a compact rate map per window (one character per
neuron) and a line per contact event (a WindowHandler of bridge/online/pipeline.py's
``run_online``)."""
from __future__ import annotations

import sys

import numpy as np

from ..wire.handler import WindowHandler

BARS = " ▁▂▃▄▅▆▇█"


def rate_bar(rates_hz: np.ndarray, full_scale_hz: float) -> str:
    levels = np.clip(np.round(rates_hz / full_scale_hz * (len(BARS) - 1)), 0, len(BARS) - 1)
    return "".join(BARS[int(v)] for v in levels)


class LiveDisplay(WindowHandler):
    """A compact live rate map: one character per neuron. On a terminal the line is redrawn in
    place every window; elsewhere (logs, pipes) one line per second. Events get their own line."""

    def __init__(self, out=None, full_scale_hz: float | None = None):
        self.out = out or sys.stdout
        self.tty = hasattr(self.out, "isatty") and self.out.isatty()
        self.fixed_scale_hz = full_scale_hz
        self.full_scale_hz = full_scale_hz or 10.0
        self._last_plain = -1.0
        self.neuron_hz = None

    # ---- a WindowHandler (bridge/wire/handler.py) -------------------------------------------
    def stream_started(self, parts, schedule) -> None:
        self.neuron_hz = parts.array.neuron_hz
        scale = (f"{self.fixed_scale_hz:g} spikes/s" if self.fixed_scale_hz
                 else "the highest rate so far")
        print(f"rate map: {len(self.neuron_hz)} resonators {self.neuron_hz[0]:.1f}–"
              f"{self.neuron_hz[-1]:.1f} Hz (low → high), full bar = {scale}", file=self.out,
              flush=True)

    def window(self, window) -> None:
        published = window.published
        if published is None:
            return
        show(self, published.event)
        rates, neuron_hz = published.rates, self.neuron_hz
        if not self.fixed_scale_hz:
            self.full_scale_hz = max(self.full_scale_hz, float(rates.max()))
        peak = f"{neuron_hz[int(np.argmax(rates))]:5.1f} Hz" if rates.max() > 0 else "  silent"
        lat = (f"  latency {published.latency_ms:5.1f} ms" if published.latency_ms is not None
               else "")
        t_s = published.t_s
        line = (f"{t_s:8.1f} s |{rate_bar(rates, self.full_scale_hz)}| peak {peak}  "
                f"rt x{published.realtime_factor:5.1f}{lat}")
        if self.tty:
            print("\r" + line, end="", file=self.out, flush=True)
        elif t_s - self._last_plain >= 1.0 - 1e-9:
            self._last_plain = t_s
            print(line, file=self.out, flush=True)

    def stream_ended(self, final_event) -> None:
        show(self, final_event)
        if self.tty:
            print(file=self.out)

    def event(self, text: str) -> None:
        print(("\r\n" if self.tty else "") + text, file=self.out, flush=True)


def show(display: LiveDisplay, event) -> None:
    if event is None:
        return
    kind, what = event
    if kind == "onset":
        display.event(f"contact onset at {what:.2f} s")
    else:
        display.event(f"contact {what.onset_s:.2f}–{what.end_s:.2f} s: ringing "
                      f"{what.frequency_hz:.1f} Hz → distance {what.distance_cm:.1f} cm")
