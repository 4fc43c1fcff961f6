"""The bridge's subcommands: ``record``, ``replay``, ``emulate``, ``stream``.

``snn_antenna.cli`` mounts them with :func:`add_subcommands`; ``python -m snn_antenna.bridge.cli``
runs them on their own. Every command exits non-zero with a one-line message for a port that
does not exist, is busy, or stays silent, and never waits forever for one.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from ..core import bounds
from ..core.bounds import option
from ..core.errors import NumericalInstabilityError, PipelineError, SpecError, guarded
from .wire.handler import BatchHandler
from .wire.protocol import WIRE_FORMATS
from .wire.recorder import COUNT_FIELDS
from .emulate.command import cmd_emulate, faults_help
from .wire.source import DEFAULT_BAUDRATE, PortError, SerialSource, run_source, stop_on_signals
from .view.view import add_view_args, live_view

EXIT_BAD_INPUT, EXIT_PORT, EXIT_INSTABILITY = 2, 1, 3
EXIT_FAILED = 1                         # a stage of the pipeline itself failed


def add_subcommands(subparsers) -> None:
    """Add ``record``, ``replay``, ``emulate`` and ``stream`` to an argparse subparsers object."""
    p = subparsers.add_parser("record", help="record a serial stream (raw bytes, samples, counts)",
                              description="Record every byte and every valid sample from a "
                                          "serial port; survives kill -9 with at most the last "
                                          "100 ms missing.")
    _port_args(p)
    p.add_argument("--out", required=True, type=option(bounds.out_path, text=True),
                   help="recording directory (new or empty)")
    p.add_argument("--duration", type=option(bounds.positive_seconds), default=None,
                   help="seconds (default: until Ctrl-C)")
    p.set_defaults(func=cmd_record)

    p = subparsers.add_parser("replay", help="replay a recording through the decoder "
                                             "(and a network)")
    p.add_argument("recording", help="directory written by `record` or `stream`")
    p.add_argument("--realtime", action="store_true",
                   help="pace at the recorded sample rate (default: as fast as possible)")
    p.add_argument("--network", default=None,
                   help="networks/NAME.toml: run the online pipeline on the replay "
                        "(networks/live.toml: the live setting)")
    _set_arg(p)
    _speed_arg(p, "the speed command at the start (default: the recording's, from its "
                  "meta.json)")
    add_view_args(p)
    _retype(p, "--view-hold", option(bounds.seconds))
    p.set_defaults(func=cmd_replay)

    p = subparsers.add_parser("emulate", help="emulate the sensor board (pty or URL), with faults")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true",
                       help="create a pseudo-terminal and print its path")
    where.add_argument("--port", help="pyserial URL or device to write to")
    p.add_argument("--link", default=None,
                   help="with --pty: a symlink path to the pty that survives disconnect faults")
    p.add_argument("--stimulus", default=None,
                   help="stimuli/NAME.toml to stream: a scene, or the bench's contact events "
                        "back to back (default: a robot scene with contacts at 19 and 27 cm)")
    p.add_argument("--frames", type=option(bounds.positive_integer), default=None,
                   help="frames to send (default: the stimulus's length; a scene loops)")
    p.add_argument("--faults", default="", help=faults_help())
    p.add_argument("--no-boot-frame", action="store_true",
                   help="send no boot frame at start and reset (a board whose restarts the "
                        "host must infer)")
    p.add_argument("--seed", type=option(bounds.seed), default=0,
                   help="seed of the stimulus noise and of where faults fall (default 0)")
    p.add_argument("--format", choices=WIRE_FORMATS, default="binary",
                   help="wire format of the frames (default binary)")
    p.add_argument("--fast", action="store_true", help="as fast as the link takes, not 1 kHz")
    p.add_argument("--peer-timeout", type=option(bounds.positive_seconds), default=None,
                   help="give up if nobody opens the pty within this many seconds")
    p.add_argument("--log", default=None, help="write the injected faults, expected counts and "
                                                "the stimulus's labelled contacts (JSON) here")
    p.add_argument("--force", action="store_true", help="replace an existing --log file")
    p.add_argument("--firmware", default=None, metavar="DIR",
                   help="run the board's own firmware instead, in simavr (with --pty): DIR is "
                        "its folder (firmware/antenna_stream), built with make and fed the "
                        "stimulus's counts; prints the simulated-to-real-time ratio")
    p.set_defaults(func=_guarded(cmd_emulate))

    p = subparsers.add_parser("stream", help="run the network live on a serial stream")
    _port_args(p)
    p.add_argument("--network", required=True,
                   help="networks/NAME.toml; networks/live.toml is the array set for live "
                        "use (rk2 at dt 0.5 ms: 5x fewer steps than resonator_array.toml, "
                        "the same read-out)")
    p.add_argument("--out", default=None, type=option(bounds.out_path, text=True),
                   help="recording directory (default: out/stream-YYYYmmdd-HHMMSS)")
    p.add_argument("--duration", type=option(bounds.positive_seconds), default=None,
                   help="seconds (default: until Ctrl-C)")
    _set_arg(p)
    _speed_arg(p, "the robot's speed command at the start, for a network whose speed gate or "
                  "CPG reads it (networks/live_robot.toml); the page's speed control changes it")
    add_view_args(p)
    p.add_argument("--json", action="store_true",
                   help="end with the full run report as JSON (for machines) instead of the "
                        "short summary")
    _retype(p, "--view-hold", option(bounds.seconds))
    p.set_defaults(func=cmd_stream)


def _set_arg(p) -> None:
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a field of the network spec, e.g. --set network.dt_ms=0.25, "
                        "--set preprocess.threshold=0.05, --set readout.window_s=0.05")


def _speed_arg(p, text: str) -> None:
    p.add_argument("--speed", type=option(_speed), default=None, metavar="CM_S", help=text)


def _speed(field: str, value) -> float:
    """A speed in cm/s (the running network's gate names its own range: bridge/online/robot.py)."""
    return bounds.number(field, value, 0.0, None, unit=" cm/s")


def _port_args(p) -> None:
    p.add_argument("--port", required=True,
                   help="device path (/dev/ttyACM0) or pyserial URL (socket://host:port, ...)")
    p.add_argument("--format", choices=WIRE_FORMATS, default="binary",
                   help="wire format the board sends (default binary)")
    p.add_argument("--baudrate", type=option(bounds.baudrate), default=DEFAULT_BAUDRATE,
                   help=f"serial speed in bit/s (default {DEFAULT_BAUDRATE}; ignored by URLs)")
    p.add_argument("--no-data-timeout", type=option(bounds.positive_seconds), default=5.0,
                   help="fail when no valid frame arrives for this many seconds (default 5; a "
                        "board reset by opening the port is silent for 1-3 s)")
    p.add_argument("--reconnect-timeout", type=option(bounds.positive_seconds), default=30.0,
                   help="how long to retry a port that disappeared (default 30 s)")


def _retype(parser, flag: str, parse) -> None:
    """Give an option another parser defines (``--view-hold``) its bounded type."""
    for action in parser._actions:
        if flag in action.option_strings:
            action.type = parse


def _guarded(command):
    """Run a command; bad input and port trouble become one line on stderr and an exit code."""
    def run(args) -> int:
        try:
            return command(args)
        except SpecError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        except PortError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_PORT
        except NumericalInstabilityError as exc:
            print(f"numerical instability: {exc}", file=sys.stderr)
            return EXIT_INSTABILITY
        except PipelineError as exc:
            where = getattr(args, "out", None)
            kept = f" (the recording in {where} is kept, marked incomplete)" if where else ""
            print(f"error: {exc}{kept}", file=sys.stderr)
            return EXIT_FAILED
    run.__name__ = command.__name__
    run.__doc__ = command.__doc__
    return run


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
def recording_session(args, extra_meta: dict | None = None):
    """Open the port, then the recording; yield (source, recorder, stop). However the session
    ends, the port is released and the recording closed with that ending as its status."""
    from .wire.recorder import Recorder

    _check_recording_dir(args.out)          # before the port is opened
    stop = stop_on_signals()
    source = open_source(args)
    try:
        recorder = Recorder(args.out, port=args.port, wire_format=args.format,
                            baudrate=args.baudrate, extra_meta=extra_meta)
    except SpecError:
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
        raise
    finally:
        source.stop()
        recorder.close(status, message, complete=complete)
        print(f"\nrecording in {args.out}: {format_counts(recorder.counts)}", file=sys.stderr,
              flush=True)


@_guarded
def cmd_record(args) -> int:
    """Record a serial stream into ``args.out``."""
    _check_duration(args.duration)
    with recording_session(args) as (source, recorder, stop):
        run_source(source, [recorder, Progress()], duration_s=args.duration,
                   no_data_timeout_s=args.no_data_timeout, stop=stop)
    return 0


@_guarded
def replay_overrides(args) -> list[str]:
    """The ``--set`` a replay runs with: the ones the recording was streamed with (its
    meta.json), then the explicit ones, which win. Said on stderr, so that a replay that
    reports other contacts than the live run says why."""
    from .wire.recorder import read_meta

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
    from .wire.recorder import read_meta

    if getattr(args, "speed", None) is not None:
        return args.speed
    speed = read_meta(args.recording).get("speed_cm_s")
    if speed is not None:
        print(f"replay: starting at the recording's speed command {speed:g} cm/s (meta.json)",
              file=sys.stderr)
    return speed


def cmd_replay(args) -> int:
    """Replay a recording; without --network, check that it decodes to what was recorded."""
    from .online.controls import RecordedChanges, recorded_events
    from .wire.replay import ReplaySource

    if args.view and not args.network:
        raise SpecError("view", True, "--view with --network (the view shows the network)")
    if args.network:
        from .online.pipeline import build_online, run_online
        from .online.terminal import LiveDisplay
        from .wire.recorder import read_meta
        from .wire.replay import live_comparison

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
        return EXIT_PORT
    return 0


def _check_recording_dir(path) -> None:
    """A recording goes into a new or empty folder: never beside (or into) a user's files."""
    from ..core.outputs import check_writable

    path = check_writable(path)
    if path.is_dir() and any(path.iterdir()):
        raise SpecError("out", str(path), "a new or empty directory (an existing recording or "
                                          "other files are never written into)")


@_guarded
def cmd_stream(args) -> int:
    """Run the online pipeline on a live port, recording while streaming."""
    from .online.pipeline import build_online, run_online, warm_up
    from .online.terminal import LiveDisplay

    _check_duration(args.duration)
    # A bad spec (or speed) fails before the port opens.
    parts = build_online(args.network, args.set, speed_cm_s=args.speed)
    if args.out is None:
        args.out = str(Path("out") / time.strftime("stream-%Y%m%d-%H%M%S"))
    _check_recording_dir(args.out)
    print("preparing the network (Brian2 compiles on the first run, then uses its cache)",
          file=sys.stderr, flush=True)
    warm_up(parts)
    with live_view(args, parts) as view, recording_session(
            args, {"network": str(args.network), "set": args.set,
                   "speed_cm_s": args.speed}) as (source, recorder, stop):
        report = run_online(source, parts,
                            [recorder, *([view] if view else []), LiveDisplay(sys.stdout)],
                            duration_s=args.duration, no_data_timeout_s=args.no_data_timeout,
                            stop=stop)
        recorder.note_outcome(contacts=report.get("contacts"))
    if view is not None:                # stopped by now: its process counted what it dropped
        report["view"] = view.summary()
    print(json.dumps(report, indent=1) if args.json else stream_summary(report, args.out))
    return 0


def stream_summary(report: dict, out) -> str:
    """What a person wants at the end of a live run, in four lines (--json has the rest)."""
    from ..report.page import fmt

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


def _check_duration(duration) -> None:
    if duration is not None and not duration > 0:
        raise SpecError("duration", duration, "a number of seconds > 0")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="snn-antenna", description="snn-antenna serial bridge")
    add_subcommands(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return guarded(args.func, args, "snn-antenna")


if __name__ == "__main__":
    sys.exit(main())
