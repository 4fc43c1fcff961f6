"""The ``emulate`` command: the sensor board emulated on a pty or a port, with faults (or the
board's own firmware in simavr), its faults and the stimulus's contacts logged as JSON.
Declared with its options in bridge/cli.py; ``core.errors.guarded`` turns its errors into one
line and an exit status."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

from ...core.errors import SpecError
from ..wire.source import PortError, stop_on_signals
from .emulator import FAULT_DESCRIPTIONS, FAULT_SECONDS
from .emulator import Emulator, FaultPlan
from .links import PeerGone
from .stimulus import played_events, stimulus_recording
from ...core.files import write_new
from .firmware_loop import check_args, emulate_firmware
from .links import PtyLink, SerialLink
from ..wire.source import describe_open_error
from ...core.files import refuse_symlink


def faults_help() -> str:
    """``--faults``' help: every fault's name and what it does."""
    kinds = "; ".join(f"{name}: {text}" for name, text in FAULT_DESCRIPTIONS.items())
    return (f"comma-separated NAME=COUNT, e.g. dup=2,swap=1,reset=1,stall_s=0.5. Faults: {kinds}. "
            f"Seconds: {', '.join(FAULT_SECONDS)}")


def cmd_emulate(args) -> int:
    """Emulate the board: stream a stimulus (labelled in ``--log``) to a pty or a port."""
    if args.firmware:
        return _emulate_firmware(args)
    # Everything checked before the pty exists or a byte is written.
    plan = FaultPlan.parse(args.faults)
    if args.link and not args.pty:
        raise SpecError("link", args.link, "only with --pty")
    if plan.disconnect and not args.link:
        raise SpecError("faults.disconnect", plan.disconnect,
                        "0 unless the emulator owns a pty with a stable --link path")
    if args.log:
        _check_output_file("log", args.log, args.force)
    stimulus = stimulus_recording(args.stimulus, args.seed, args.frames)
    emulator = Emulator(stimulus.samples, rate_hz=stimulus.rate_hz, faults=plan, seed=args.seed,
                        wire_format=args.format,
                        boot_frames=not args.no_boot_frame)
    n_frames = args.frames or len(emulator.counts)
    emulator.schedule(n_frames)
    link = _emulator_link(args)
    print(link.path, flush=True)
    t0 = time.monotonic()
    ended = None
    try:
        emulator.run(link, n_frames, realtime=not args.fast, stop=stop_on_signals(),
                     peer_timeout_s=args.peer_timeout)
    except PeerGone as exc:
        ended = f"emulator stopped: {exc}"
    except OSError as exc:             # the device went away under us (pyserial's errors too)
        ended = f"emulator stopped: the port {args.port or link.path} failed: {exc}"
    finally:
        link.close()
        log = emulator.log
        summary = {"path": link.path, "seconds": round(time.monotonic() - t0, 3),
                   "frames_written": len(log.written), "injected": log.injected(),
                   "expected_counts": log.expected_counts(), "stopped": ended,
                   "faults": [list(f) for f in log.faults],
                   "events": played_events(stimulus, log.frames_due)}
        if args.log:                    # whoever stopped first, the log says what was sent
            write_new(args.log, json.dumps(summary, indent=1), force=args.force)
    if ended:
        raise PortError(ended)
    shown = {k: v for k, v in summary.items() if k not in ("faults", "stopped", "events")}
    print(json.dumps({**shown, "events": len(summary["events"])}), flush=True)
    return 0


def _emulate_firmware(args) -> int:
    """``emulate --pty --firmware DIR``: the firmware in simavr streams the stimulus."""
    check_args(args)
    if args.log:
        _check_output_file("log", args.log, args.force)
    summary = emulate_firmware(args, stop_on_signals(), log=lambda path: print(path, flush=True))
    if args.log:                        # however the run ended
        write_new(args.log, json.dumps(summary, indent=1), force=args.force)
    if summary["stopped"]:
        raise PortError(f"emulator stopped: {summary['stopped']}")
    print(json.dumps({**{k: v for k, v in summary.items() if k not in ("events", "stopped")},
                      "events": len(summary["events"])}), flush=True)
    return 0


def _emulator_link(args):
    """The pty the emulator creates (``--pty``), or the port or URL it writes to."""
    if args.pty:
        return PtyLink(args.link)
    try:
        return SerialLink(args.port)
    except Exception as exc:       # pyserial's open errors, as for a reader
        raise describe_open_error(args.port, exc) from exc


def _check_output_file(name: str, path, force: bool = False) -> None:
    """A new file in a writable folder; an existing one only with ``--force``; a symlink
    never (the toolkit does not write through links)."""
    path = Path(path)
    refuse_symlink(path, "file")
    if path.is_dir() or not path.parent.is_dir() or not os.access(path.parent, os.W_OK):
        raise SpecError(name, str(path), "a file path in a folder you can write to")
    if path.exists() and not force:
        raise SpecError(name, str(path), "a path that does not exist yet (this file would be "
                                         "overwritten): choose another, or pass --force")
