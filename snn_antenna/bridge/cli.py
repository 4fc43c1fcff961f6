"""The bridge's subcommands: ``record``, ``replay``, ``emulate``, ``stream``, declared in
:data:`COMMANDS` (``snn_antenna.cli`` mounts them). Every command exits non-zero with a one-line
message for a port that does not exist, is busy, or stays silent, and never waits forever for
one.
"""
from __future__ import annotations

import dataclasses
import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from ..core import bounds
from ..core.commands import LIST, POSITIONAL, SWITCH, Command, Option
from ..core.errors import PipelineError, SpecError
from ..core.outputs import output_folder
from .wire.handler import BatchHandler
from .emulate.command import cmd_emulate, faults_help
from .wire.protocol import WIRE_FORMATS
from .wire.recorder import COUNT_FIELDS, RECORDING, Recorder
from .wire.source import DEFAULT_BAUDRATE, PortError, SerialSource, run_source, stop_on_signals
from .view.view import live_view
from .wire.recorder import read_meta
from .online.controls import RecordedChanges, recorded_events
from .wire.replay import ReplaySource
from .online.terminal import LiveDisplay
from .wire.replay import live_comparison
from ..report.page import fmt

EXIT_MISMATCH = 1                       # a replay whose counts differ from what was recorded


def _speed(field: str, value) -> float:
    """A speed in cm/s (the running network's gate names its own range: bridge/online/robot.py)."""
    return bounds.number(field, value, 0.0, None, unit=" cm/s")


def _view_port(field: str, value) -> int:
    return bounds.integer(field, value, 0, 65535)


PORT = (
    Option("port", "device path (/dev/ttyACM0) or pyserial URL (socket://host:port, ...)",
           required=True),
    Option("format", "wire format the board sends (default binary)", choices=WIRE_FORMATS,
           default="binary"),
    Option("baudrate", f"serial speed in bit/s (default {DEFAULT_BAUDRATE}; ignored by URLs)",
           check=bounds.baudrate, default=DEFAULT_BAUDRATE),
    Option("no_data_timeout", "fail when no valid frame arrives for this many seconds (default "
                              "5; a board reset by opening the port is silent for 1-3 s)",
           check=bounds.positive_seconds, default=5.0),
    Option("reconnect_timeout", "how long to retry a port that disappeared (default 30 s)",
           check=bounds.positive_seconds, default=30.0),
)
DURATION = Option("duration", "seconds (default: until Ctrl-C)", check=bounds.positive_seconds)
SET = Option("set", "override a field of the network spec, e.g. --set network.dt_ms=0.25, "
                    "--set preprocess.threshold=0.05, --set readout.window_s=0.05",
             kind=LIST, metavar="KEY=VALUE")


def speed_option(help_text: str) -> Option:
    return Option("speed", help_text, check=_speed, metavar="CM_S")


VIEW = (
    Option("view", "serve a live browser view (rate map, coded input, contacts) and print its "
                   "URL", kind=SWITCH),
    Option("view_host", "address the view listens on (default 127.0.0.1: this machine only; "
                        "0.0.0.0 exposes it to the network deliberately)", default="127.0.0.1"),
    Option("view_port", "port of the view (default 5006; 0 = any free port)", check=_view_port,
           default=5006),
    Option("view_save", "where the page's 'save view' button writes (default: the recording's "
                        "views/ folder for stream, out/views for replay)", metavar="DIR"),
    Option("view_hold", "seconds to keep the view up after the stream ends (default: until "
                        "Ctrl-C; 0 closes it at once)", check=bounds.seconds),
)


def open_source(args) -> SerialSource:
    return SerialSource(args.port, wire_format=args.format, baudrate=args.baudrate,
                        reconnect_timeout_s=args.reconnect_timeout).start()


SHOWN_COUNTS = COUNT_FIELDS


def format_counts(counts: dict) -> str:
    return "  ".join(f"{k}={counts.get(k, 0)}" for k in SHOWN_COUNTS)


class Progress(BatchHandler):
    """A recording's counts on stderr: redrawn twice a second on a terminal, a line every
    10 s in a log; link losses and reconnections get their own line at once."""

    def __init__(self, file=sys.stderr):
        self.file = file
        self.tty = file.isatty()
        self.interval_s = 0.5 if self.tty else 10.0
        self.counts: dict = {}
        self.t0 = self._last = time.monotonic()

    def handle(self, batch) -> None:
        self.counts = batch.counts or self.counts
        if batch.event in ("lost", "reconnected"):
            print(("\n" if self.tty else "") + f"port {batch.event}"
                  + (f": {batch.message}" if batch.message else ""), file=self.file, flush=True)
        self.idle()

    def idle(self) -> None:
        now = time.monotonic()
        if now - self._last >= self.interval_s:
            self._last = now
            line = f"{now - self.t0:7.1f} s  {format_counts(self.counts)}"
            print(("\r" + line) if self.tty else line, end="" if self.tty else "\n",
                  file=self.file, flush=True)


@contextmanager
def recording_session(options, folder, extra_meta: dict | None = None):
    """Open the port, then the recording in ``folder`` (an output folder the caller has
    checked: ``outputs.output_folder``); yield (source, recorder, stop). However the session
    ends, the port is released and the recording closed with that ending as its status."""
    stop = stop_on_signals()
    source = open_source(options)
    try:
        recorder = Recorder(folder, port=options.port, wire_format=options.format,
                            baudrate=options.baudrate, extra_meta=extra_meta)
    except BaseException:
        source.stop()
        raise
    status, message, complete = "ok", "", True
    try:
        yield source, recorder, stop
        if stop.is_set():
            status = "stopped"
    except PortError as exc:
        status, message = "port-error", str(exc)
        raise
    except BaseException as exc:        # the pipeline failed: never "complete", "ok"
        status, complete = "failed", False
        message = str(exc) or type(exc).__name__
        if isinstance(exc, KeyboardInterrupt):
            status, message = "interrupted", "interrupted"
        if isinstance(exc, PipelineError):
            raise PipelineError(exc.stage, f"{exc.reason} (the recording in {folder.path} is "
                                           "kept, marked incomplete)") from exc
        raise
    finally:
        source.stop()
        recorder.close(status, message, complete=complete)
        print(f"\nrecording in {folder.path}: {format_counts(recorder.counts)}",
              file=sys.stderr, flush=True)


def cmd_record(options) -> int:
    """Record a serial stream into ``--out``."""
    with output_folder(options.out, RECORDING, new=True) as folder, \
            recording_session(options, folder) as (source, recorder, stop):
        run_source(source, [recorder, Progress()], duration_s=options.duration,
                   no_data_timeout_s=options.no_data_timeout, stop=stop)
    return 0


def replay_overrides(args) -> list[str]:
    """The ``--set`` a replay runs with: the ones the recording was streamed with (its
    meta.json), then the explicit ones, which win. Said on stderr, so that a replay that
    reports other contacts than the live run says why."""
    meta = read_meta(args.recording)
    recorded = [str(item) for item in meta.get("set") or []]
    network = meta.get("network")
    if network and Path(network).resolve() != Path(args.network).resolve():
        print(f"replay: the recording was streamed with --network {network}; replaying with "
              f"{args.network}", file=sys.stderr)
    if recorded:
        print(f"replay: applying the recording's --set {' '.join(recorded)} (from meta.json)"
              + (f", then the explicit --set {' '.join(args.set)}" if args.set else ""),
              file=sys.stderr)
    return recorded + list(args.set)


def replay_speed(args) -> float | None:
    """The speed command a replay starts at: ``--speed``, else the recording's (meta.json)."""
    if getattr(args, "speed", None) is not None:
        return args.speed
    speed = read_meta(args.recording).get("speed_cm_s")
    if speed is not None:
        print(f"replay: starting at the recording's speed command {speed:g} cm/s (meta.json)",
              file=sys.stderr)
    return speed


def cmd_replay(args) -> int:
    """Replay a recording; without --network, check that it decodes to what was recorded."""
    if args.view and not args.network:
        raise SpecError("view", True, "--view with --network (the view shows the network)")
    if args.network:
        # lazy: scikit-learn loads with a network, not with the command line
        from .online.pipeline import build_online, run_online

        live = live_comparison(read_meta(args.recording), args.network, args.set,
                               getattr(args, "speed", None))
        if live["settings_differ"]:
            print(f"replay: its settings differ from the live run's "
                  f"({'; '.join(live['settings_differ'])}): its contacts are its own, with the "
                  "live run's beside them (\"live\" in the report)", file=sys.stderr)
        parts = build_online(args.network, replay_overrides(args),
                             speed_cm_s=replay_speed(args))
        # The live run's control changes, at the samples they applied at.
        scheduled = recorded_events(args.recording)
        if scheduled:
            print(f"replay: applying the recording's {len(scheduled)} control change(s) "
                  "(events.jsonl)", file=sys.stderr)
        recorded = RecordedChanges(parts, scheduled)
        with live_view(args, parts) as view:        # None without --view
            source = ReplaySource(args.recording, realtime=args.realtime).start()
            report = run_online(source, parts,
                                [recorded, *([view] if view else []), LiveDisplay(sys.stdout)],
                                no_data_timeout_s=1e9)
        if view is not None:            # stopped by now: its process counted what it dropped
            report["view"] = view.summary()
        report["live"] = live
        print(json.dumps(report, indent=1))
        return 0
    source = ReplaySource(args.recording, realtime=args.realtime).start()
    result = run_source(source, [], no_data_timeout_s=1e9)
    recording = source.recording
    recorded = {k: recording.counts.get(k) for k in result.counts if k in recording.counts}
    replayed = {k: result.counts[k] for k in recorded}
    same = replayed == recorded
    print(json.dumps({"replayed": replayed, "recorded": recorded, "match": same}, indent=1))
    if not same and recording.complete:
        print("error: the replayed counts differ from meta.json", file=sys.stderr)
        return EXIT_MISMATCH
    return 0


def cmd_stream(options) -> int:
    """Run the online pipeline on a live port, recording while streaming."""
    # lazy: scikit-learn loads with a network, not with the command line
    from .online.pipeline import build_online, run_online, warm_up

    # A bad spec (or speed) fails before the port opens.
    parts = build_online(options.network, options.set, speed_cm_s=options.speed)
    if options.out is None:
        options = dataclasses.replace(
            options, out=str(Path("out") / time.strftime("stream-%Y%m%d-%H%M%S")))
    with output_folder(options.out, RECORDING, new=True) as folder:   # before the warm-up
        print("preparing the network (Brian2 compiles on the first run, then uses its cache)",
              file=sys.stderr, flush=True)
        warm_up(parts)
        with live_view(options, parts) as view, recording_session(
                options, folder, {"network": str(options.network), "set": options.set,
                                  "speed_cm_s": options.speed}) as (source, recorder, stop):
            report = run_online(source, parts,
                                [recorder, *([view] if view else []), LiveDisplay(sys.stdout)],
                                duration_s=options.duration,
                                no_data_timeout_s=options.no_data_timeout, stop=stop)
            recorder.note_outcome(contacts=report.get("contacts"))
    if view is not None:                # stopped by now: its process counted what it dropped
        report["view"] = view.summary()
    print(json.dumps(report, indent=1) if options.json
          else stream_summary(report, options.out))
    return 0


def stream_summary(report: dict, out) -> str:
    """What a person wants at the end of a live run, in four lines (--json has the rest)."""
    lat = report["latency_ms"]
    contacts = report.get("contacts")
    n_contacts = len(contacts) if isinstance(contacts, (list, tuple)) else contacts
    return "\n".join([
        f"streamed {fmt(report['simulated_s'], 's')} of signal ({report['samples']} samples, "
        f"{report['windows']} windows) in {fmt(report['wall_s'], 's')}: "
        f"{fmt(report['realtime_factor'])}× real time",
        f"latency, sample to rate map: median {fmt(lat['median'], 'ms')}, "
        f"95th percentile {fmt(lat['p95'], 'ms')}, max {fmt(lat['max'], 'ms')}",
        f"contacts: {fmt(n_contacts)}; link: {format_counts(report['counts'])}",
        f"recording in {out} (--json prints the full report)"])


COMMANDS = (
    Command("record", "record a serial stream (raw bytes, samples, counts)", cmd_record, (
        *PORT,
        Option("out", "recording directory (new or empty)", check=bounds.out_path, text=True,
               required=True),
        DURATION),
        description="Record every byte and every valid sample from a serial port; survives "
                    "kill -9 with at most the last 100 ms missing."),
    Command("replay", "replay a recording through the decoder (and a network)", cmd_replay, (
        Option("recording", "directory written by `record` or `stream`", kind=POSITIONAL),
        Option("realtime", "pace at the recorded sample rate (default: as fast as possible)",
               kind=SWITCH),
        Option("network", "networks/NAME.toml: run the online pipeline on the replay "
                          "(networks/live.toml: the live setting)"),
        SET,
        speed_option("the speed command at the start (default: the recording's, from its "
                     "meta.json)"),
        *VIEW)),
    Command("emulate", "emulate the sensor board (pty or URL), with faults", cmd_emulate, (
        Option("pty", "create a pseudo-terminal and print its path", kind=SWITCH),
        Option("port", "pyserial URL or device to write to"),
        Option("link", "with --pty: a symlink path to the pty that survives disconnect "
                       "faults"),
        Option("stimulus", "stimuli/NAME.toml to stream: a scene, or the bench's contact "
                           "events back to back (default: a robot scene with contacts at 19 "
                           "and 27 cm)"),
        Option("frames", "frames to send (default: the stimulus's length; a scene loops)",
               check=bounds.positive_integer),
        Option("faults", faults_help(), default=""),
        Option("no_boot_frame", "send no boot frame at start and reset (a board whose "
                                "restarts the host must infer)", kind=SWITCH),
        Option("seed", "seed of the stimulus noise and of where faults fall (default 0)",
               check=bounds.seed, default=0),
        Option("format", "wire format of the frames (default binary)", choices=WIRE_FORMATS,
               default="binary"),
        Option("fast", "as fast as the link takes, not 1 kHz", kind=SWITCH),
        Option("peer_timeout", "give up if nobody opens the pty within this many seconds",
               check=bounds.positive_seconds),
        Option("log", "write the injected faults, expected counts and the stimulus's "
                      "labelled contacts (JSON) here"),
        Option("force", "replace an existing --log file", kind=SWITCH),
        Option("firmware", "run the board's own firmware instead, in simavr (with --pty): DIR "
                           "is its folder (firmware/antenna_stream), built with make and fed "
                           "the stimulus's counts; prints the simulated-to-real-time ratio",
               metavar="DIR")),
        one_of=("pty", "port")),
    Command("stream", "run the network live on a serial stream", cmd_stream, (
        *PORT,
        Option("network", "networks/NAME.toml; networks/live.toml is the array set for live "
                          "use (rk2 at dt 0.5 ms: 5x fewer steps than resonator_array.toml, "
                          "the same read-out)", required=True),
        Option("out", "recording directory (default: out/stream-YYYYmmdd-HHMMSS)",
               check=bounds.out_path, text=True),
        DURATION,
        SET,
        speed_option("the robot's speed command at the start, for a network whose speed gate "
                     "or CPG reads it (networks/live_robot.toml); the page's speed control "
                     "changes it"),
        *VIEW,
        Option("json", "end with the full run report as JSON (for machines) instead of the "
                       "short summary", kind=SWITCH))),
)
