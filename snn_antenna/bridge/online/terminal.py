"""The live pipeline's terminal output: a compact rate map per window (one character per
neuron) and a line per contact event (bridge/online.py's ``run_online`` writes them)."""
from __future__ import annotations

import sys

import numpy as np

BARS = " ▁▂▃▄▅▆▇█"


def rate_bar(rates_hz: np.ndarray, full_scale_hz: float) -> str:
    levels = np.clip(np.round(rates_hz / full_scale_hz * (len(BARS) - 1)), 0, len(BARS) - 1)
    return "".join(BARS[int(v)] for v in levels)


class LiveDisplay:
    """A compact live rate map: one character per neuron. On a terminal the line is redrawn in
    place every window; elsewhere (logs, pipes) one line per second. Events get their own line."""

    def __init__(self, out=None, full_scale_hz: float | None = None):
        self.out = out or sys.stdout
        self.tty = hasattr(self.out, "isatty") and self.out.isatty()
        self.fixed_scale_hz = full_scale_hz
        self.full_scale_hz = full_scale_hz or 10.0
        self._last_plain = -1.0

    def header(self, neuron_hz: np.ndarray) -> None:
        scale = (f"{self.fixed_scale_hz:g} spikes/s" if self.fixed_scale_hz
                 else "the highest rate so far")
        print(f"rate map: {len(neuron_hz)} resonators {neuron_hz[0]:.1f}–{neuron_hz[-1]:.1f} Hz "
              f"(low → high), full bar = {scale}", file=self.out, flush=True)

    def window(self, t_s: float, rates: np.ndarray, neuron_hz: np.ndarray, rtf: float,
               latency_ms: float | None) -> None:
        if not self.fixed_scale_hz:
            self.full_scale_hz = max(self.full_scale_hz, float(rates.max()))
        peak = f"{neuron_hz[int(np.argmax(rates))]:5.1f} Hz" if rates.max() > 0 else "  silent"
        lat = f"  latency {latency_ms:5.1f} ms" if latency_ms is not None else ""
        line = (f"{t_s:8.1f} s |{rate_bar(rates, self.full_scale_hz)}| peak {peak}  "
                f"rt x{rtf:5.1f}{lat}")
        if self.tty:
            print("\r" + line, end="", file=self.out, flush=True)
        elif t_s - self._last_plain >= 1.0 - 1e-9:
            self._last_plain = t_s
            print(line, file=self.out, flush=True)

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
