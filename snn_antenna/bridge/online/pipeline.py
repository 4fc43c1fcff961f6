"""The online pipeline: live samples → streaming preprocessing → Brian2 resonator array → rate
map and contact events, while the recorder keeps everything.

All spiking is Brian2: the array runs in runtime mode through
:meth:`snn_antenna.networks.resonators.ResonatorArray.stream`, which pulls coded samples from the
generator built here. What this module adds on top of the foundation's streaming API:

- calibration: the PCA alignment needs a fit, so the first ``calibration_s`` of samples fit the
  chain, then go through it like every later sample (same numbers as the offline chain);
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

import numpy as np

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError
from ...networks.resonators import ResonatorArray
from ...preprocess import make_chain, partial_transform, reset
from ...readout.contacts import ContactDetector, EpisodeTracker, detector_from_spec
from ...engine.spec_rules import check_spec
from ..wire.protocol import BOARD_ADC_BITS, BOARD_FULL_SCALE_G, BOARD_RATE_HZ
from .report import OnlineReport
from ..wire.source import SourceLoop
from .handler import Published, Window
from .terminal import LiveDisplay

SECTIONS = ("network", "preprocess", "readout")


@dataclass
class OnlineParts:
    array: ResonatorArray
    chain: object                       # sklearn Pipeline from make_chain
    detector: ContactDetector
    window_s: float
    spec: dict
    robot: object = None                # online/robot.py's LiveRobot: a composed spec's parts


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
        with specs.section("network"):
            array = ResonatorArray(**specs.check_section(spec, "network", ResonatorArray))
    with specs.section("network"):
        array.check_rate(rate_hz)
    with specs.section("preprocess"):
        pre = specs.check_section(spec, "preprocess", make_chain,
                                  exclude=["rate_hz", "adc_bits", "full_scale_g"])
        chain = make_chain(rate_hz, BOARD_ADC_BITS, BOARD_FULL_SCALE_G, **pre)
    detector, window_s = detector_from_spec(spec)
    robot = None
    if composed:
        from .robot import LiveRobot, trained_gate

        if examples is not None:
            configured["gate"] = trained_gate(configured["gate"], *examples)
        robot = LiveRobot(configured, speed_cm_s)
    return OnlineParts(array, chain, detector, window_s, spec, robot)


def _composed(table: dict, training, speed_cm_s) -> tuple[dict, tuple | None]:
    """A composed network's parts, configured and checked for the live stream (nothing
    built, the gate not trained yet), and the gate's examples (speeds, Th*) from
    ``training`` (None without a gate)."""
    from ...networks.assembly import configure
    from ...networks.gate import GateTraining
    from .robot import check_live_parts, check_speed, speed_range

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
    parts.array.stream(iter([np.zeros(int(0.05 * BOARD_RATE_HZ))]), BOARD_RATE_HZ, window_s=0.05,
                       companions=parts.robot.build if parts.robot else None)


class CalibratedChain:
    """The preprocessing chain on a stream whose first ``n_calibration`` samples fit it.

    The PCA alignment needs a fit. The first samples are held back until there are
    ``n_calibration`` of them; the chain is fitted on exactly those (however the port chunked
    them, the same data give the same numbers), then they and every later chunk are streamed
    through it with ``partial_transform``.
    """

    def __init__(self, chain, n_calibration: int):
        self.chain, self.n_calibration = chain, n_calibration
        self._held: list[np.ndarray] = []
        self.fitted = False

    def push(self, counts: np.ndarray) -> np.ndarray | None:
        """ADC counts (n, 2) in, coded samples out (None while calibrating)."""
        counts = self.take(counts)
        return None if counts is None else self.code(counts)

    def take(self, counts: np.ndarray) -> np.ndarray | None:
        """ADC counts (n, 2) in; the counts ready to code out (the held ones first, once the
        chain is fitted on them), None while calibrating."""
        if not self.fitted:
            self._held.append(counts)
            counts = np.concatenate(self._held)
            if len(counts) < self.n_calibration:
                self._held = [counts]
                return None
            reset(self.chain.fit(counts[:self.n_calibration]))
            self._held, self.fitted = [], True
        return counts

    def code(self, counts: np.ndarray) -> np.ndarray:
        """Counts that ``take`` made ready, through the fitted chain (the coder's Th now)."""
        return partial_transform(self.chain, counts)


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


def run_online(source, parts: OnlineParts, *, handlers=(), duration_s: float | None = None,
               no_data_timeout_s: float = 5.0, stop=None, display: LiveDisplay | None = None,
               calibration_s: float = 1.0, view=None, controls=None) -> dict:
    """Stream a started source (serial or replay) through the network; returns the report.
    ``handlers`` see the source's batches (bridge/wire/source.py's SourceLoop: the recorder,
    the view). The run report, a composed network's parts, ``controls`` (bridge/online/
    controls.py: Th, the rate-map window, the speed at window boundaries), ``view``
    (bridge/view/view.py's LiveView: it only copies) and ``display`` (the terminal's lines)
    are WindowHandlers (bridge/online/handler.py), in that order; the
    report's ``controls`` lists what the controls applied."""
    if not 0 < calibration_s <= 60:
        raise SpecError("calibration_s", calibration_s, "seconds in (0, 60]")
    loop = SourceLoop(source, tuple(handlers), duration_s, no_data_timeout_s, stop)
    clock, report = ArrivalClock(), OnlineReport()
    robot = parts.robot
    # The report first: the real-time factor the others see counts the window.
    followers = [h for h in (robot, controls, view, display) if h is not None]
    for handler in (report, *followers):
        handler.stream_started(parts)
    tracker = EpisodeTracker(parts.detector, parts.array.neuron_hz, parts.window_s)
    # A replay read flat out delivers seconds of samples at once: arrival-to-rate-map latency
    # only means something for a live port (or a replay paced in real time).
    live = getattr(source, "realtime", True)
    summed = {"t_s": None, "counts": None, "n": 0}      # network windows summed so far

    def on_window(t_s: float, spike_counts: np.ndarray) -> None:
        # ResonatorArray.stream hands over a window once its last sample has been integrated,
        # before it asks for the next one. The published window sums ``controls.windows`` of
        # the network's (one without controls).
        end_s = t_s + parts.window_s
        end_index = int(round(end_s * BOARD_RATE_HZ))
        if summed["n"] == 0:
            summed["t_s"], summed["counts"] = t_s, spike_counts.astype(float)
        else:
            summed["counts"] = summed["counts"] + spike_counts
        summed["n"] += 1
        published = None
        if controls is None or summed["n"] >= controls.windows:
            start_s, window_s = summed["t_s"], summed["n"] * parts.window_s
            rates, summed["n"] = summed["counts"] / window_s, 0
            arrived = clock.arrival(max(end_index - 1, 0)) if live else None
            if live:
                report.origin = clock.origin
            tracker.window_s = window_s
            published = Published(start_s, window_s, rates, tracker.update(start_s, rates),
                                  arrived, None if arrived is None
                                  else (time.time() - arrived) * 1e3, float("nan"))
        window = Window(end_s, end_index, loop.waiting_s, published)
        report.window(window)
        if published is not None:
            window = replace(window, published=replace(
                published, realtime_factor=report.realtime_factor))
        for handler in followers:
            handler.window(window)

    t0 = report.started = time.perf_counter()
    chunks = coded_chunks(loop, source, CalibratedChain(
        parts.chain, int(calibration_s * BOARD_RATE_HZ)), clock, controls, robot,
        int(round(parts.window_s * BOARD_RATE_HZ)))
    stats = parts.array.stream(chunks, BOARD_RATE_HZ, window_s=parts.window_s,
                               on_window=on_window, companions=robot.build if robot else None)
    report.wall_s = time.perf_counter() - t0
    report.waiting_s = loop.waiting_s
    report.samples, report.windows, report.simulated_s = (stats.samples, stats.windows,
                                                          stats.simulated_s)
    final = tracker.close()
    for handler in (report, *followers):
        handler.stream_ended(final)
    report.contacts = [e.as_dict() for e in tracker.estimates]
    result = report.as_dict(parts, source.counts())
    if controls is not None:
        result["controls"] = controls.events
    return result


def coded_chunks(loop: SourceLoop, source, chain: CalibratedChain, clock: ArrivalClock,
                 controls=None, robot=None, window_samples: int = 0):
    """The coded input for the network, chunk by chunk, from the source's batches (noting
    each sample's arrival on ``clock``); a Th change is applied at its sample index.

    With a composed network (``robot``), each of the network's windows (``window_samples``)
    is coded with the gate's Th only once the network has integrated the window before it:
    the pieces are yielded one window at a time, and the stream asks for the next only after
    publishing that window (``ResonatorArray.stream``), so the same samples get the same Th
    however the source chunked them (live or replayed)."""
    coder = chain.chain.named_steps["coder"]
    waiting: list = []
    pushed = 0                          # samples handed to the chain so far
    coded = 0                           # of those, coded (the rest are held for calibration)
    for batch in loop:
        if batch.samples:
            waiting += batch.samples
            clock.add(len(batch.samples), batch.host_time_s)
        if controls is not None:
            controls.poll(pushed, chain.n_calibration)
        # A live port delivers a frame or two per read; the chain costs the same for one
        # sample as for a hundred, so take everything already queued in one go.
        if not waiting or source.pending():
            continue
        counts = chain.take(np.asarray(waiting, dtype=float)[:, 1:])
        pushed += len(waiting)
        waiting = []
        if counts is None:
            continue
        cuts: dict[int, list] = {}          # offset → the Th changes due there
        for item in controls.due(coded, coded + len(counts)) if controls else []:
            cuts.setdefault(item[0] - coded, []).append(item)
        if robot is not None:               # and every window boundary
            for at in range(-coded % window_samples, len(counts), window_samples):
                cuts.setdefault(at, [])
        pieces, start = [], 0
        for at in sorted(cuts) + [len(counts)]:
            if at > start:
                piece = chain.code(counts[start:at])
                if robot is None:
                    pieces.append(piece)
                else:
                    yield piece
            if at < len(counts):
                if robot is not None and (coded + at) % window_samples == 0 \
                        and robot.next_th() is not None:
                    coder.threshold = robot.next_th()
                for item in cuts[at]:
                    controls.apply_th(item)
            start = at
        coded += len(counts)
        if pieces:
            yield np.concatenate(pieces) if len(pieces) > 1 else pieces[0]
