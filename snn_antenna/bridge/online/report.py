"""What a live or replayed stream did (bridge/online/pipeline.py's ``run_online``): samples,
windows, the real-time factors (wall clock, compute-only, per CPU second) and the latency from a
sample's arrival to its rate-map window; ``as_dict`` is the run's JSON report."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..wire.handler import WindowHandler

CPU_EVERY_WINDOWS = 10


@dataclass
class OnlineReport(WindowHandler):
    samples: int = 0
    windows: int = 0
    simulated_s: float = 0.0
    wall_s: float = 0.0
    waiting_s: float = 0.0
    started: float = 0.0                # perf_counter when the pipeline started
    latencies_ms: list[float] = field(default_factory=list)
    contacts: list[dict] = field(default_factory=list)
    # (perf_counter, waiting_s, simulated_s) at the first and the latest published window
    first_window: tuple | None = None
    last_window: tuple | None = None
    caught_up_at: int = 0               # index of the first window after the start-up backlog
    origin: float | None = None         # host clock (time.time) when the stream began, live
    last_published: float = 0.0         # host clock when the latest window was published
    # (simulated_s, process_time) at the first window and every CPU_EVERY_WINDOWS after it:
    # reading the process's CPU clock costs ~0.7 ms here while other threads run.
    cpu_marks: list[tuple[float, float]] = field(default_factory=list)
    published: int = 0

    @property
    def realtime_factor(self) -> float:
        """Stream seconds processed per wall-clock second actually elapsed. Live (a port, or a
        replay paced in real time): from the stream's beginning on the host's clock
        (:attr:`ArrivalClock.origin`) to the publication of the latest window, so about 1.0
        when the pipeline keeps up with the board and less when it falls behind, whatever held
        it up (the network, the start-up, another thread, the machine). A file read flat out
        has no real time to keep: its stream seconds per wall second from the first published
        window (Brian2's build excluded)."""
        if self.last_window is None:
            return float("nan")
        if self.origin is not None:
            return self.last_window[2] / max(self.last_published - self.origin, 1e-9)
        return self._steady_factor(waiting_excluded=False)

    @property
    def compute_realtime_factor(self) -> float:
        """Stream seconds per wall-clock second spent computing, from the first published window
        to the latest with the time spent waiting for the port taken out: the headroom, not
        what happened."""
        return self._steady_factor(waiting_excluded=True)

    def _steady_factor(self, waiting_excluded: bool) -> float:
        if self.first_window is None:
            return float("nan")
        (t0, w0, s0), (t1, w1, s1) = self.first_window, self.last_window
        if s1 <= s0:
            return float("nan")
        return (s1 - s0) / max((t1 - t0) - (w1 - w0 if waiting_excluded else 0.0), 1e-9)

    @property
    def cpu_realtime_factor(self) -> float:
        """Simulated seconds per CPU second of this process (all its threads) in the steady
        state: what the pipeline would reach on a core of its own, however loaded the machine
        is with other work."""
        if len(self.cpu_marks) < 2:
            return float("nan")
        (s0, c0), (s1, c1) = self.cpu_marks[0], self.cpu_marks[-1]
        return (s1 - s0) / max(c1 - c0, 1e-9)

    # ---- a WindowHandler (bridge/wire/handler.py) -------------------------------------------
    def window(self, window) -> None:
        """Note a published rate-map window (stream time, its latency, the time spent waiting
        for the port so far, the process's CPU time every CPU_EVERY_WINDOWS)."""
        published = window.published
        if published is None:
            return
        if self.first_window is None:           # steady state starts here (Brian2 is built)
            self.first_window = self.last_window = (time.perf_counter(), window.waiting_s,
                                                    window.end_s)
        if self.published % CPU_EVERY_WINDOWS == 0:
            self.cpu_marks.append((window.end_s, time.process_time()))
        self.published += 1
        latency_ms = published.latency_ms
        if latency_ms is not None:
            self.latencies_ms.append(latency_ms)
        self.last_published = time.time()
        if (latency_ms is not None and not self.caught_up_at
                and window.waiting_s - self.last_window[1] > 0.1 * published.window_s):
            # The pipeline had to wait for the port: any start-up backlog is gone.
            self.caught_up_at = len(self.latencies_ms)
        self.last_window = (time.perf_counter(), window.waiting_s, window.end_s)

    def as_dict(self, parts, counts: dict) -> dict:
        def summary(values):
            if not len(values):
                return {"median": None, "p95": None, "max": None, "windows": 0}
            lat = np.asarray(values)
            return {"median": round(float(np.median(lat)), 2),
                    "p95": round(float(np.percentile(lat, 95)), 2),
                    "max": round(float(lat.max()), 2), "windows": len(values)}

        return {
            "samples": self.samples, "windows": self.windows,
            "simulated_s": round(self.simulated_s, 3), "wall_s": round(self.wall_s, 3),
            "waiting_s": round(self.waiting_s, 3),
            "startup_s": (round(self.first_window[0] - self.started, 3) if self.first_window
                          else None),
            "realtime_factor": _rounded(self.realtime_factor),
            "compute_realtime_factor": _rounded(self.compute_realtime_factor),
            "cpu_realtime_factor": _rounded(self.cpu_realtime_factor),
            # From a sample's arrival on the host to the rate-map window that includes it:
            # all windows, and those after the start-up backlog was worked off (live only).
            "latency_ms": summary(self.latencies_ms),
            "steady_latency_ms": summary(self.latencies_ms[self.caught_up_at:]
                                         if self.caught_up_at else []),
            "window_s": parts.window_s,
            "network": {"n_neurons": parts.array.n_neurons, "dt_ms": parts.array.dt_ms,
                        "target": parts.array.target, "method": parts.array.method},
            "contacts": self.contacts, "counts": counts,
        }


def _rounded(value: float) -> float | None:
    return round(value, 2) if np.isfinite(value) else None
