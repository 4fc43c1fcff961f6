"""The board's own firmware in the loop:
``snn-antenna emulate --pty --firmware firmware/antenna_stream``.

The shipped firmware (``main.c``, unmodified) is built for the ATmega328P and run in simavr by
the harness ``firmware/antenna_stream/sim/antenna_sim.c``: the stimulus's ADC counts are fed to
the firmware's own Timer1-triggered conversions, and every byte its UART sends at 250000 baud is
written to a pseudo-terminal (the same :class:`~snn_antenna.bridge.emulate.links.PtyLink` as
``emulate
--pty``), so ``record``, ``stream`` and ``replay`` read it as they read the board. Faults are the
firmware's own: a UART the harness holds (``holds``) fills the firmware's queue, and what it drops
reaches the host as a counted gap in the sequence numbers.

The simulated clock is paced to the wall clock (``fast``: as fast as simavr and the reader go);
the summary gives the ratio of simulated to wall time and the share of the wall time simavr was
busy, i.e. how far above real time it could run.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...core.errors import PipelineError, SpecError
from .links import PeerGone, PtyLink, check_link_path
from .stimulus import played_events, stimulus_recording

MCU = "atmega328p"
HARNESS = "antenna_sim"
HARNESS_PEER_GONE = 3           # antenna_sim's exit status when the reader closed the port
TOOLS = {"make": "make", "avr-gcc": "gcc-avr avr-libc", "cc": "build-essential"}
SIMAVR_HEADER = Path("/usr/include/simavr/sim_avr.h")
INSTALL_HINT = "apt-get install gcc-avr avr-libc simavr libsimavr-dev"


def missing_tools() -> list[str]:
    """What building and running the firmware in simavr needs and this machine lacks."""
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    if not SIMAVR_HEADER.is_file():
        missing.append("libsimavr-dev")
    return missing


def check_firmware_dir(path) -> Path:
    """The firmware folder (its Makefile builds the .elf and the harness)."""
    folder = Path(path)
    if not ((folder / "Makefile").is_file() and (folder / "main.c").is_file()
            and (folder / "sim" / f"{HARNESS}.c").is_file()):
        raise SpecError("firmware", str(path), "the firmware folder holding Makefile, main.c and "
                                               f"sim/{HARNESS}.c (firmware/antenna_stream)")
    missing = missing_tools()
    if missing:
        raise SpecError("firmware", str(path), f"a machine with {', '.join(missing)} to build "
                                               f"and simulate it (Debian: {INSTALL_HINT})")
    return folder


@dataclass
class Built:
    """The firmware's .elf and the harness, built into a folder of their own."""
    elf: Path
    harness: Path


def build(firmware_dir, build_dir) -> Built:
    """``make sim`` into ``build_dir``: the .elf from the firmware's sources and the harness."""
    folder, out = Path(firmware_dir).resolve(), Path(build_dir).resolve()
    result = subprocess.run(["make", "-C", str(folder), f"BUILD={out}", f"MCU={MCU}", "sim"],
                            capture_output=True, text=True, timeout=300)
    if result.returncode != 0:
        lines = (result.stderr or result.stdout).strip().splitlines()
        first_error = next((line for line in lines if "error" in line.lower()), lines[-1])
        raise PipelineError(f"building the firmware for simavr (make sim in {folder})",
                            first_error.strip())
    return Built(out / f"antenna_stream-{MCU}.elf", out / HARNESS)


def write_counts(path, counts: np.ndarray) -> None:
    """The harness's input: one sample a line, ``x y`` in ADC counts."""
    np.savetxt(path, np.asarray(counts, dtype=np.int64).reshape(-1, 2), fmt="%d")


def looped(samples: np.ndarray, n_frames: int) -> np.ndarray:
    """The first ``n_frames`` samples of a stimulus played in a loop (as ``emulate`` plays it)."""
    reps = -(-n_frames // len(samples))
    return np.tile(samples, (reps, 1))[:n_frames]


def run_harness(built: Built, counts_file, link: PtyLink, *, fast: bool = False,
                holds: tuple[tuple[float, float], ...] = (), resets: tuple[float, ...] = (),
                stop: threading.Event | None = None) -> dict:
    """Run the firmware on ``counts_file`` into ``link`` until every sample is sent, ``stop``
    is set or the reader leaves; the harness's summary (simulated and wall seconds, ratio, bytes,
    line load, held time, ``stopped``: why it ended early, or None)."""
    stop = stop or threading.Event()
    cmd = [str(built.harness), "--mcu", MCU, "--fd", str(link.master)]
    if fast:
        cmd.append("--fast")
    for at_ms, for_ms in holds:
        cmd += ["--hold-uart", f"{at_ms:g}:{for_ms:g}"]
    for at_ms in resets:                # the RESET pin: the firmware boots again, counts from 0
        cmd += ["--reset-at", f"{at_ms:g}"]
    cmd += [str(built.elf), str(counts_file)]
    with tempfile.TemporaryFile("w+") as err:     # a file: a chatty harness never blocks
        proc = subprocess.Popen(cmd, pass_fds=(link.master,), stdout=subprocess.DEVNULL,
                                stderr=err, text=True)
        try:
            while proc.poll() is None:
                if stop.is_set():
                    proc.terminate()    # the harness stops at once and reports what it did
                try:
                    proc.wait(0.1)
                except subprocess.TimeoutExpired:
                    pass
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        err.seek(0)
        lines = err.read().strip().splitlines()
    if proc.returncode not in (0, HARNESS_PEER_GONE) or not lines or not lines[-1].startswith("{"):
        raise PipelineError("the firmware in simavr", f"exit {proc.returncode}: "
                            + (lines[-1] if lines else "no output"))
    return json.loads(lines[-1])


def describe(summary: dict) -> str:
    """The harness's clock and line, for a person."""
    busy = max(summary["busy_fraction"], 1e-9)
    return (f"firmware in simavr: {summary['simulated_s']:.2f} s simulated in "
            f"{summary['wall_s']:.2f} s, {summary['realtime_ratio']:.2f}× real time "
            f"(simavr busy {100 * summary['busy_fraction']:.0f} % of it: "
            f"up to {summary['realtime_ratio'] / busy:.1f}× real time); UART line load "
            f"{100 * summary['line_load']:.1f} % of 250000 baud; "
            f"held {summary['held_s']:.3f} s")


def check_args(args) -> None:
    """What ``emulate --firmware`` cannot do, refused before anything is built or opened."""
    if not args.pty:
        raise SpecError("firmware", args.firmware, "with --pty (the harness writes to a "
                                                   "pseudo-terminal)")
    if args.faults:
        raise SpecError("faults", args.faults, "none with --firmware (the firmware's faults are "
                                               "its own: a held UART drops samples as gaps)")
    if args.link:
        check_link_path(Path(args.link))
    if args.format != "binary":
        raise SpecError("format", args.format, "binary with --firmware (the firmware's wire "
                                               "format)")
    check_firmware_dir(args.firmware)


def emulate_firmware(args, stop: threading.Event, log=print) -> dict:
    """``snn-antenna emulate --pty --firmware DIR``: build, wait for a reader, run, summarise.

    ``args`` are the ``emulate`` options (stimulus, frames, seed, link, fast, peer_timeout,
    checked with :func:`check_args`); the pty path goes to ``log`` first, as ``emulate --pty``
    prints it. The summary's ``stopped`` says why the run ended early (None: every frame sent).
    """
    stimulus = stimulus_recording(args.stimulus, args.seed, args.frames)
    n_frames = args.frames or stimulus.n_samples
    with tempfile.TemporaryDirectory(prefix="snn-antenna-firmware-") as tmp:
        built = build(args.firmware, tmp)
        counts_file = Path(tmp) / "counts.txt"
        write_counts(counts_file, looped(stimulus.samples, n_frames))
        link = PtyLink(args.link)
        t0 = time.monotonic()
        summary = {"samples_fed": 0, "stopped": None}
        try:
            log(link.path)
            link.wait_for_peer(args.peer_timeout, stop)
            summary = run_harness(built, counts_file, link, fast=args.fast, stop=stop)
            if not summary["stopped"]:
                link.drain()
        except PeerGone as exc:
            summary["stopped"] = str(exc)
        finally:
            link.close()
    if "wall_s" in summary:
        print(describe(summary), file=sys.stderr, flush=True)
    return {"path": link.path, "seconds": round(time.monotonic() - t0, 3),
            "frames_fed": summary["samples_fed"], "stopped": summary["stopped"],
            "firmware": str(args.firmware), "mcu": MCU, "simavr": summary,
            "events": played_events(stimulus, summary["samples_fed"])}
