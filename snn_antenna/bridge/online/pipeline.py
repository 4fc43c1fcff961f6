"""The online pipeline: live samples → streaming preprocessing → Brian2 resonator array → rate
map and contact events, while the recorder keeps everything.

All spiking is Brian2: the array runs in runtime mode through
:meth:`snn_antenna.networks.resonators.ResonatorArray.stream`, whose port (:class:`LiveStream`)
is built here: the network asks it for each block of coded input and hands it each window, the
only two calls out of the network. What this module adds on top of the foundation's streaming
API:

- calibration: the PCA alignment needs a fit, so the first ``calibration_s`` of samples fit the
  chain (``preprocess.CalibratedChain``), then go through it like every later sample (same
  numbers as the offline chain);
- the live inputs: the coder's Th, the rate-map window and the speed command are the input
  schedule's (bridge/online/schedule.py), which the handlers submit changes to; the pipeline
  codes each piece with the schedule's Th and announces each change it applied;
- timing, measured on the host's clocks: each sample's arrival time (when its bytes were read)
  is kept until its window is published, giving the latency from arrival to the rate map; the
  real-time factor is stream seconds processed per wall-clock second actually elapsed (below 1
  means the pipeline fell behind the board); the compute-only factor, with the time spent
  waiting for the port taken out, says how much headroom there is;
- online contact episodes: each window goes to the read-out's
  :class:`~snn_antenna.readout.contacts.EpisodeTracker`, the episode logic that
  ``ContactDetector.detect`` runs offline, so live and offline detections are the same.

- a composed network (``networks/live_robot.toml``): its speed gate, CPG and control layer run
  in Brian2 in the array's own network (bridge/online/robot.py), and each of the network's windows
  is coded with the gate's Th once the network has integrated the window before it.

Gaps in the stream are not filled: the network sees the received samples back to back.
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError
from ...engine.spec_rules import check_spec
from ...networks.assembly import configure
from ...networks.gate import GateTraining
from ...networks.resonators import ChunkFeed, ResonatorArray, array_section, check_rates
from ...preprocess import CalibratedChain, chain_section
from ...readout.contacts import ContactDetector, EpisodeTracker, detector_from_spec
from ..wire.handler import Published, Window, WindowHandler
from ..wire.protocol import BOARD_ADC_BITS, BOARD_FULL_SCALE_G, BOARD_RATE_HZ
from ..wire.source import SourceLoop
from .report import OnlineReport
from .robot import LiveRobot, check_live_parts, check_speed, speed_range, trained_gate
from .schedule import InputSchedule

SECTIONS = ("network", "preprocess", "readout")


@dataclass
class OnlineParts:
    array: ResonatorArray
    chain: object                       # sklearn Pipeline from make_chain
    detector: ContactDetector
    window_s: float
    spec: dict
    robot: object = None                # online/robot.py's LiveRobot: a composed spec's parts

    @property
    def handlers(self) -> tuple:
        """The network's own window handlers: a composed network's other parts."""
        return () if self.robot is None else (self.robot,)

    @property
    def companions(self):
        """What builds a composed network's other parts beside the array (None: nothing)."""
        return None if self.robot is None else self.robot.build

    @property
    def th_g(self) -> float:
        """The coder's Th as the spec sets it: the stream starts with it."""
        return float(self.chain.named_steps["coder"].threshold)

    @property
    def speed_cm_s(self) -> float | None:
        """The speed command the stream starts at (None: no part of the network reads one)."""
        if self.robot is None or self.robot.speed_range is None:
            return None
        return self.robot.start_speed


def build_online(network_path, overrides=(), rate_hz: float = BOARD_RATE_HZ,
                 speed_cm_s: float | None = None) -> OnlineParts:
    """The parts the ``--network`` file names, checked before any port is opened.

    A network file (``networks/*.toml``, the fields of ResonatorArray) or a study-style file
    with ``[network]``, ``[preprocess]`` and ``[readout]`` tables; ``--set`` overrides apply to
    the study form (``--set preprocess.threshold=0.05``). A composed network (``parts = [...]``,
    e.g. networks/live_robot.toml) runs its other parts beside the array (bridge/online/robot.py),
    starting at the speed command ``speed_cm_s``; its gate learns from ``[gate_training]``.
    """
    path = Path(network_path)
    if not path.is_file():
        raise SpecError("network", str(path), "the path of a network spec, e.g. "
                                              "networks/resonator_array.toml")
    raw = specs.load(path)
    raw.pop("seed", None)
    training = raw.pop("gate_training", None)
    spec = ({k: raw.get(k, {}) for k in SECTIONS} if isinstance(raw.get("network"), dict)
            else {"network": raw, "preprocess": {}, "readout": {}})
    if training is not None:
        spec["gate_training"] = training
    for item in overrides:              # e.g. --set gate_training.from_summary=...
        specs.apply_override(spec, item)
    training = spec.pop("gate_training", None)
    for key in spec:
        if key not in SECTIONS:
            raise SpecError(key, spec[key], f"a section of an online spec: {', '.join(SECTIONS)}")
    # The rules joining the sections, named by the spec's keys (the rate is the board's).
    check_spec(spec, [item.split("=", 1)[0].strip() for item in overrides], rate_hz=rate_hz)
    composed = "parts" in spec["network"]
    if composed:
        configured, examples = _composed(spec["network"], training, speed_cm_s)
        array = configured["resonators"]
    else:
        for name, value in (("gate_training", training), ("speed", speed_cm_s)):
            if value is not None:
                raise SpecError(name, value, "none for a network without a speed gate (a "
                                             "composed spec such as networks/live_robot.toml "
                                             "takes one)")
        array = array_section(spec)
    board = SimpleNamespace(rate_hz=rate_hz, adc_bits=BOARD_ADC_BITS,
                            full_scale_g=BOARD_FULL_SCALE_G)     # the sensor the board reads
    check_rates(array, [board])
    chain = chain_section(spec, [board])[0].chain(board)
    detector, window_s = detector_from_spec(spec)
    robot = None
    if composed:
        if examples is not None:
            configured["gate"] = trained_gate(configured["gate"], *examples)
        robot = LiveRobot(configured, speed_cm_s)
    return OnlineParts(array, chain, detector, window_s, spec, robot)


def _composed(table: dict, training, speed_cm_s) -> tuple[dict, tuple | None]:
    """A composed network's parts, configured and checked for the live stream (nothing
    built, the gate not trained yet), and the gate's examples (speeds, Th*) from
    ``training`` (None without a gate)."""
    check_live_parts(table.get("parts", []))
    with specs.section("network"):
        configured = configure(table)
    examples = None
    if "gate" in configured:
        if not isinstance(training, dict):
            raise SpecError("gate_training", training,
                            "a [gate_training] table (speeds_cm_s and th_star_g, or "
                            "from_summary: also --set gate_training.from_summary=PATH): what "
                            "the speed gate learns before the stream")
        with specs.section("gate_training"):
            table = specs.check_section({"gate_training": training}, "gate_training",
                                        GateTraining)
            examples = GateTraining(**table).examples()
            configured["gate"].check_speeds(examples[0], "speeds_cm_s")
    elif training is not None:
        raise SpecError("gate_training", training, "none: the network has no speed gate")
    if speed_cm_s is None and speed_range(configured) is not None:
        readers = ", ".join(name for name in configured if name in ("gate", "cpg"))
        raise SpecError("speed", None, f"the robot's speed command in cm/s (--speed): "
                                       f"{readers} read it")
    if speed_cm_s is not None:
        check_speed(speed_cm_s, speed_range(configured))
    return configured, examples


def warm_up(parts: OnlineParts) -> None:
    """Run the array (and a composed network's other parts) on 50 ms of silence, so that
    Brian2 generates and compiles its code (cached on disk afterwards) before a port is opened
    and samples start to queue up."""
    parts.array.stream(ChunkFeed([np.zeros(int(0.05 * BOARD_RATE_HZ))]), BOARD_RATE_HZ,
                       window_s=0.05, companions=parts.companions)


class ArrivalClock:
    """Host arrival time of every sample index, kept only until its window is published; and
    when the stream began by the host's clock (``origin``): the earliest of arrival minus
    stream time over all samples. A port read continuously gives its first sample's arrival;
    a source read late (a replay paced in real time waits for Brian2's build) is caught by
    the later samples that arrive on time."""

    def __init__(self, rate_hz: float = BOARD_RATE_HZ):
        bounds.declared(self, rate_hz=rate_hz)
        bounds.rate_hz("rate_hz", rate_hz)
        self._chunks: deque[tuple[int, float]] = deque()    # (end index, arrival time)
        self.n = 0
        self.rate_hz = rate_hz
        self.origin = float("inf")

    def add(self, n_samples: int, arrival_s: float) -> None:
        self.n += n_samples
        self._chunks.append((self.n, arrival_s))
        self.origin = min(self.origin, arrival_s - (self.n - 1) / self.rate_hz)

    def arrival(self, index: int) -> float:
        while self._chunks and self._chunks[0][0] <= index:
            self._chunks.popleft()
        return self._chunks[0][1]


class RateWindow:
    """The rate-map window being summed: the network's windows since the last one published."""

    def __init__(self):
        self.start_s = 0.0
        self.counts: np.ndarray | None = None
        self.n = 0

    def add(self, t_s: float, counts: np.ndarray) -> None:
        if self.n == 0:
            self.start_s, self.counts = t_s, counts.astype(float)
        else:
            self.counts = self.counts + counts
        self.n += 1

    def take(self, base_window_s: float) -> tuple[float, float, np.ndarray]:
        """(start, length, spikes/s per neuron) of the summed window; the next starts empty."""
        window_s = self.n * base_window_s
        self.n = 0
        return self.start_s, window_s, self.counts / window_s


def run_online(source, parts: OnlineParts, handlers=(), *, duration_s: float | None = None,
               no_data_timeout_s: float = 5.0, stop=None, calibration_s: float = 1.0) -> dict:
    """Stream a started source (serial or replay) through the network; returns the report.

    ``handlers`` are :class:`~snn_antenna.bridge.wire.handler.WindowHandler` objects (the
    recorder, the view, the terminal's lines, a replay's journaled changes), each handed, in
    order, every batch of the source, the stream's start with its input schedule, each chunk
    the coder coded, each of the network's windows, each change the schedule applied, and the
    stream's end. The run's own report sees every window first (the real-time factor the
    others see counts the window), then the network's own parts (``parts.handlers``: a composed
    network's other parts read the network before anyone is shown it). The report's
    ``controls`` lists the changes the schedule applied."""
    if not 0 < calibration_s <= 60:
        raise SpecError("calibration_s", calibration_s, "seconds in (0, 60]")
    handlers = tuple(handlers)
    for handler in handlers:
        if not isinstance(handler, WindowHandler):
            raise SpecError("handlers", type(handler).__name__,
                            "WindowHandler instances (bridge/wire/handler.py)")
    report = OnlineReport()
    followers = (*parts.handlers, *handlers)
    loop = SourceLoop(source, (report, *followers), duration_s, no_data_timeout_s, stop)
    chain = CalibratedChain(parts.chain, int(calibration_s * BOARD_RATE_HZ))
    schedule = InputSchedule(parts.th_g, parts.window_s, BOARD_RATE_HZ, chain.n_calibration,
                             parts.speed_cm_s)
    for handler in (report, *followers):
        handler.stream_started(parts, schedule)
    stream = LiveStream(parts, loop, source, chain, schedule, report, followers)
    t0 = report.started = time.perf_counter()
    stats = parts.array.stream(stream, BOARD_RATE_HZ, window_s=parts.window_s,
                               companions=parts.companions)
    report.wall_s = time.perf_counter() - t0
    report.waiting_s = loop.waiting_s
    report.samples, report.windows, report.simulated_s = (stats.samples, stats.windows,
                                                          stats.simulated_s)
    final = stream.tracker.close()
    for handler in (report, *followers):
        handler.stream_ended(final)
    report.contacts = [e.as_dict() for e in stream.tracker.estimates]
    result = report.as_dict(parts, source.counts())
    result["controls"] = schedule.events
    return result


class LiveStream:
    """The network's port (``networks.resonators.StreamPort``) on a live source: the stream
    goes down the layers once per block. ``fill`` reads the source's batches (each sample's
    arrival noted on the clock), calibrates the chain and codes the samples with the input
    schedule's Th; ``window`` publishes the network's window to the handlers and has the
    schedule apply the changes due at its end.

    The schedule says how far the coder may run ahead of the network (with a speed gate, to
    the end of the window the gate's latest Th codes: the next is recalled once the network
    has integrated this one); ``ResonatorArray.stream`` hands over a window before it asks for
    the next block, so the same samples get the same Th however the source chunked them (live
    or replayed). Gaps in the stream are not filled: the network sees the received samples
    back to back."""

    def __init__(self, parts: OnlineParts, loop: SourceLoop, source, chain: CalibratedChain,
                 schedule: InputSchedule, report: OnlineReport, handlers: tuple):
        self.loop, self.source, self.chain, self.schedule = loop, source, chain, schedule
        self.report, self.handlers = report, handlers
        self.base_window_s = parts.window_s
        self.tracker = EpisodeTracker(parts.detector, parts.array.neuron_hz, parts.window_s)
        self.clock = ArrivalClock()
        self.rate_window = RateWindow()
        # A replay read flat out delivers seconds of samples at once: arrival-to-rate-map
        # latency only means something for a live port (or a replay paced in real time).
        self.live = getattr(source, "realtime", True)
        self._batches = iter(loop)
        self._waiting: list = []            # samples received, not handed to the chain yet
        self._ready: deque[np.ndarray] = deque()    # counts the chain may code, in order
        self._coded: deque[np.ndarray] = deque()    # coded samples the network has not taken
        self._taken = 0                     # of the first coded piece, samples taken
        self._ended = False

    # ---- the network's port ----------------------------------------------------------------
    def fill(self, block: np.ndarray) -> int:
        n = 0
        while n < len(block):
            if not self._coded and not self._code_more():
                return n
            piece = self._coded[0]
            m = min(len(block) - n, len(piece) - self._taken)
            block[n:n + m] = piece[self._taken:self._taken + m]
            n += m
            self._taken += m
            if self._taken == len(piece):
                self._coded.popleft()
                self._taken = 0
        return n

    def window(self, t_s: float, counts: np.ndarray) -> None:
        end_s = t_s + self.base_window_s
        end_index = int(round(end_s * BOARD_RATE_HZ))
        self.rate_window.add(t_s, counts)
        published = None
        if self.rate_window.n >= self.schedule.windows:
            start_s, window_s, rates = self.rate_window.take(self.base_window_s)
            arrived = self.clock.arrival(max(end_index - 1, 0)) if self.live else None
            if self.live:
                self.report.origin = self.clock.origin
            published = Published(start_s, window_s, rates,
                                   self.tracker.update(start_s, rates, window_s), arrived,
                                   None if arrived is None else (time.time() - arrived) * 1e3,
                                   float("nan"))
        window = Window(end_s, end_index, self.loop.waiting_s, published)
        self.report.window(window)
        if published is not None:
            window = replace(window, published=replace(
                published, realtime_factor=self.report.realtime_factor))
        for handler in self.handlers:
            handler.window(window)
        self._announce(self.schedule.window_ended(end_index, published is not None))

    # ---- coding ----------------------------------------------------------------------------
    def _code_more(self) -> bool:
        """Code what may be coded, reading the source until something is; False once the
        source ended."""
        while True:
            self._code_ready()
            if self._coded:
                return True
            if self._ended:
                return False
            batch = next(self._batches, None)
            if batch is None:
                self._ended = True
                continue
            if batch.samples:
                self._waiting += batch.samples
                self.clock.add(len(batch.samples), batch.host_time_s)
            # A live port delivers a frame or two per read; the chain costs the same for one
            # sample as for a hundred, so take everything already queued in one go.
            if not self._waiting or self.source.pending():
                continue
            counts = self.chain.take(np.asarray(self._waiting, dtype=float)[:, 1:])
            self._waiting = []
            if counts is not None:
                self._ready.append(counts)

    def _code_ready(self) -> None:
        """Code the ready counts as far as the schedule knows their Th, each piece with its
        Th, handing every piece to the handlers as the coder coded it."""
        while self._ready:
            counts = self._ready[0]
            until = self.schedule.coded_until()
            n = len(counts) if until is None else min(len(counts),
                                                      until - self.schedule.position)
            if n <= 0:
                return
            pieces, events = self.schedule.code(n)
            start = 0
            for end, th_g in pieces:
                signal, coded = self.chain.code(counts[start:end], th_g)
                for handler in self.handlers:
                    handler.coded(signal, th_g, coded)
                self._coded.append(coded)
                start = end
            self._announce(events)
            if n == len(counts):
                self._ready.popleft()
            else:
                self._ready[0] = counts[n:]

    def _announce(self, events: list[dict]) -> None:
        for event in events:
            for handler in self.handlers:
                handler.changed(event)
