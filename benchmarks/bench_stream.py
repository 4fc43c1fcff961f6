"""Online pipeline benchmark: real-time factor and sample-to-rate-map latency, one run each.

    python benchmarks/bench_stream.py [--network networks/live.toml] [--seconds 8]
                                      [--set network.dt_ms=0.25 ...] [--speed 12]
                                      [--baseline networks/resonator_array.toml] [--view]
                                      [--browsers 0,1,3]

1. Throughput: the emulator (its own process) writes a robot scene (contacts at 19 and 27 cm)
   into a pseudo-terminal as fast as the reader takes it; serial source → decoder →
   preprocessing → Brian2 array → rate map. The throughput is the compute-only real-time
   factor: simulated seconds per second of computation in the steady state (Brian2's build
   and the time spent waiting for bytes excluded); per CPU second, it is simulated seconds per
   CPU second of the pipeline's own process (its threads, not the emulator's), which other
   jobs on the machine leave alone. The same throughput run on ``--baseline`` (the offline array,
   dt 0.1 ms;
   ``--baseline none`` skips it) gives the ratio of the two settings measured in one run, which
   a machine loaded by other jobs leaves more telling than either factor alone.
2. Latency: the emulator runs as its own process at 1 kHz real time on a pseudo-terminal; the
   pipeline streams from it. The latency is from a sample's arrival on the host (when its
   bytes were read) to the publication of the rate-map window that contains it (steady state,
   after the start-up backlog is worked off); a window also waits for its own samples, up to
   ``window_s``. The real-time factor of a live run is measured on the wall clock: stream
   seconds processed per second elapsed since the stream began (1.0 = kept up with the board).
3. ``--view``: the throughput run again, alternately without and with the live browser view
   (bridge/view/view.py, its server in a process of its own) and a page open on it (headless
   Chromium, when installed), ``--repeats`` times each on ``--view-seconds`` of input; the
   throughputs are printed side by side. Chromium and the view process run on the same cores
   as the pipeline.
4. ``--reload``: the live run at 1 kHz with the view, without and then with a client loading
   ``GET /`` twice a second (a tab reloading); the wall-clock real-time factor, the latency
   (median, p95), the samples lost or processed late and the view's dropped frames are printed
   side by side.
5. ``--browsers 0,1,3``: for each number of headless Chromium pages open on the live view,
   ``--repeats`` times (each on a fresh view with fresh pages), a live run at 1 kHz
   (wall-clock real-time factor, sample-to-rate-map latency, and the display latency: from
   the arrival of a window's last sample on the host to its rate-map column painted on a
   page, as the pages report it on their rate-map sockets, all pages together), then a
   throughput run with the same pages open (compute-only real-time factor, and per CPU
   second of the pipeline's own process: what the pages' drawing on the same cores leaves
   out); then per number of pages the median [min–max] over the runs. Of the display
   latency, "taken" is the part until the view process took the window from the pipeline's
   hand-off, "sent" until the page's update left the view process, "received" until the
   column was in the page's document (the rest is the browser drawing it); each is a p95 of
   its own. "CPU s/s" is what the view process and the pages' browsers (with their
   renderers) used per second of the live run: on two cores, what the pages' drawing costs.
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from snn_antenna.bridge.online.pipeline import build_online, run_online, warm_up
from snn_antenna.bridge.wire.source import PortError, SerialSource

ROOT = Path(__file__).resolve().parents[1]


def stream_from_emulator(parts, seconds: float, fast: bool, view=None) -> dict:
    """Run the pipeline on an emulator process's pty until the whole scene went through
    (with ``view``, a started LiveView, also feeding the view)."""
    n_frames = int(seconds * 1000)
    with tempfile.TemporaryDirectory() as tmp:
        link = os.path.join(tmp, "tty")
        emulator = subprocess.Popen(
            [sys.executable, "-m", "snn_antenna.cli", "emulate", "--pty", "--link", link,
             # More frames than measured: an emulator that ends closes the pty, and bytes
             # still unread in it would be lost (the run would wait for them in vain). Flat
             # out, it ends as soon as the reader has taken all but the pty's buffer (tens of
             # kB): 20,000 frames more than fill it.
             "--frames", str(n_frames + (20_000 if fast else 500)),
             *(["--fast"] if fast else [])],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            emulator.stdout.readline()              # the pty exists once its path is printed
            source = SerialSource(link).start()
            report = run_online(source, parts, [view] if view else [],
                                stop=_stop_when_consumed(source, n_frames))
            source.stop()
        finally:
            emulator.kill()
            _, said = emulator.communicate()
        # The run ends by closing the pty under the emulator, which says so: expected here.
        sys.stderr.writelines(line for line in said.splitlines(keepends=True)
                              if "the reader closed" not in line)
    return report


def _stop_when_consumed(source, n_frames):
    """Stop once every frame was decoded and handed to the pipeline."""
    stop = threading.Event()

    def watch():
        while source.decoder.stats.frames < n_frames or source.pending():
            time.sleep(0.005)
        stop.set()

    threading.Thread(target=watch, daemon=True).start()
    return stop


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--network", default=str(ROOT / "networks" / "live.toml"))
    ap.add_argument("--baseline", default=str(ROOT / "networks" / "resonator_array.toml"),
                    help="a second network, throughput only, for the ratio ('none': skip)")
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--speed", type=float, default=12.0,
                    help="the speed command (cm/s) for a network whose gate or CPG reads one "
                         "(networks/live_robot.toml); ignored by the others")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--view", action="store_true",
                    help="also compare the real-time factor with the live view open")
    ap.add_argument("--repeats", type=int, default=3,
                    help="runs each, with --view or --browsers (the median and range printed)")
    ap.add_argument("--view-seconds", type=float, default=30.0,
                    help="seconds of input per run, with --view (longer runs, steadier ratio)")
    ap.add_argument("--browsers", default=None, metavar="N,N,...",
                    help="live and throughput runs with this many headless Chromium pages "
                         "open on the view, e.g. 0,1,3")
    ap.add_argument("--reload", action="store_true",
                    help="also compare live runs with the view, without / with a client "
                         "loading the page twice a second")
    args = ap.parse_args(argv)
    overrides = ["preprocess.threshold=0.05", *args.set]
    parts = online_parts(args.network, overrides, args.speed)
    warm_up(parts)
    robot = (f" + {', '.join(parts.robot.names)} at {args.speed:g} cm/s" if parts.robot
             else "")
    print(f"network {args.network} {' '.join(args.set)}: {parts.array.n_neurons} resonators"
          f"{robot}, dt {parts.array.dt_ms} ms, target {parts.array.target}; "
          f"machine: {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    fast = stream_from_emulator(parts, args.seconds, fast=True)
    print(f"throughput (compute-only real-time factor): {fast['compute_realtime_factor']:.1f}x "
          f"({fast['simulated_s']:.1f} s of 1 kHz input; Brian2 start-up "
          f"{fast['startup_s']:.1f} s "
          f"not included); per CPU second of the pipeline's process: "
          f"{fast['cpu_realtime_factor']:.1f}x")
    if args.baseline != "none":
        compare_baseline(args, overrides, fast)
    live = stream_from_emulator(parts, args.seconds, fast=False)
    steady = live["steady_latency_ms"]
    print(f"live at 1 kHz: real-time factor (wall clock) {live['realtime_factor']:.2f}x, "
          f"compute-only {live['compute_realtime_factor']:.1f}x, "
          f"caught up with the start-up backlog after {live['windows'] - steady['windows']} "
          f"of {live['windows']} windows")
    if steady["windows"]:
        print(f"sample-to-rate-map latency: median {steady['median']:.1f} ms, "
              f"p95 {steady['p95']:.1f} ms, max {steady['max']:.1f} ms "
              f"(+ up to {live['window_s'] * 1000:.0f} ms for a sample to wait for the end of "
              "its window)")
    else:
        print("sample-to-rate-map latency: the pipeline never caught up with real time")
    print("contacts (fast run): " + "; ".join(
        f"{c['onset_s']:.1f} s → {c['distance_cm']:.1f} cm" for c in fast["contacts"]))
    if args.view:
        compare_view(args, overrides)
    if args.reload:
        compare_reload(args, overrides)
    if args.browsers:
        compare_browsers(args, overrides, [int(n) for n in args.browsers.split(",")])
    return 0


def online_parts(network, overrides, speed_cm_s: float):
    """``build_online`` with the speed command where the network reads one (a composed spec
    with a gate or CPG: bridge/online/robot.py)."""
    from snn_antenna.core import spec as specs

    raw = specs.load(network)
    table = raw["network"] if isinstance(raw.get("network"), dict) else raw
    reads_speed = bool({"gate", "cpg"} & set(table.get("parts", ())))
    return build_online(network, overrides, speed_cm_s=speed_cm_s if reads_speed else None)


def compare_browsers(args, overrides, counts: list[int]) -> None:
    """With 0, 1, 3... pages open, ``--repeats`` runs each: the live run's real-time factor and
    latencies, the display latency the pages report, and the throughput; then, per number
    of pages, the median and range over the runs."""
    rows = [browsers_run(args, overrides, n) for n in counts for _ in range(args.repeats)]
    print(f"live view with browsers open ({args.view_seconds:g} s live at 1 kHz, then "
          f"{args.seconds:g} s flat out; {args.repeats} run(s) each; load "
          f"{os.getloadavg()[0]:.1f}):")
    print(f"  {'pages':>5s}  {'rt factor live':>14s}  {'throughput':>10s}  {'per CPU s':>9s}  "
          f"{'rate map p95':>12s}  {'on screen median':>16s}  {'p95':>8s}  {'paints':>6s}  "
          f"{'of it: taken p95':>16s}  {'sent p95':>8s}  {'received p95':>12s}  "
          f"{'frames dropped':>14s}  {'CPU s/s: view':>13s}  {'pages':>5s}")
    for n, sessions, live, shown, fast, summary, cpu in rows:
        steady = live["steady_latency_ms"]
        p95 = f"{steady['p95']:.1f} ms" if steady["windows"] else "behind"
        screen = ((f"{shown['median']:.0f} ms", f"{shown['p95']:.0f} ms") if shown["n"]
                  else ("–", "–"))
        taken, sent, received = ("–" if shown.get(key) is None else f"{shown[key]:.0f} ms"
                                 for key in ("taken_p95", "sent_p95", "received_p95"))
        print(f"  {sessions:>2d}/{n:<2d}  {live['realtime_factor']:13.2f}x  "
              f"{fast['compute_realtime_factor']:9.1f}x  {fast['cpu_realtime_factor']:8.1f}x  "
              f"{p95:>12s}  {screen[0]:>16s}  "
              f"{screen[1]:>8s}  {shown['n']:>6d}  {taken:>16s}  {sent:>8s}  {received:>12s}  "
              f"{summary['frames_dropped']!s:>5s} of {summary['frames_published']:<6d}  "
              f"{cpu[0]:13.2f}  {cpu[1]:5.2f}")
    for n in counts:
        runs = [row for row in rows if row[0] == n]
        throughput = [row[4]["compute_realtime_factor"] for row in runs]
        shown = [row[3] for row in runs if row[3]["n"]]
        line = (f"  {n} page(s), median [min–max] of {len(runs)} run(s): throughput "
                f"{_spread(throughput, '.1f')}x")
        if shown:
            line += (f"; on screen median {_spread([s['median'] for s in shown], '.0f')} ms, "
                     f"p95 {_spread([s['p95'] for s in shown], '.0f')} ms")
        print(line)


def _spread(values, fmt: str) -> str:
    return (f"{statistics.median(values):{fmt}} [{min(values):{fmt}}–{max(values):{fmt}}]")


def browsers_run(args, overrides, n: int) -> tuple:
    """One live run and one throughput run with ``n`` headless Chromium pages open on a
    fresh view: (n, sessions, live report, display latency, throughput report, the view's
    summary, CPU s/s of the view process and of the pages)."""
    from snn_antenna.bridge.view.view import LiveView

    parts = online_parts(args.network, overrides, args.speed)
    warm_up(parts)
    view = LiveView(parts, port=0)
    url = view.start()
    pages = [OpenPage(url) for _ in range(n)]
    try:
        deadline = time.monotonic() + 90
        while _state(url)["sessions"] < n and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(2.0)                     # the pages drew once and follow the stream
        busy = _cpu_s([view.process.pid]), _cpu_s([page.pid for page in pages if page.pid])
        began = time.monotonic()
        live = stream_from_emulator(parts, args.view_seconds, False, view)
        elapsed = time.monotonic() - began
        state = _state(url)
        cpu = ((_cpu_s([view.process.pid]) - busy[0]) / elapsed,
               (_cpu_s([page.pid for page in pages if page.pid]) - busy[1]) / elapsed)
        fast = stream_from_emulator(parts, args.seconds, True, view)
    finally:
        for page in pages:
            page.close()
        summary = view.stop()
    return n, state["sessions"], live, state["display_latency_ms"], fast, summary, cpu


def _cpu_s(pids) -> float:
    """CPU seconds used so far by these processes and all their children (a browser's
    renderers and GPU process are its children)."""
    import psutil

    total = 0.0
    for pid in pids:
        try:
            top = psutil.Process(pid)
            for proc in [top, *top.children(recursive=True)]:
                times = proc.cpu_times()
                total += times.user + times.system
        except psutil.NoSuchProcess:
            pass
    return total


def compare_baseline(args, overrides, fast) -> None:
    """The throughput run on the baseline network, right after the shipped one's."""
    base_parts = online_parts(args.baseline, overrides, args.speed)
    warm_up(base_parts)
    base = stream_from_emulator(base_parts, args.seconds, fast=True)
    print(f"  baseline {Path(args.baseline).name} (dt {base_parts.array.dt_ms} ms, "
          f"{base_parts.array.method}): {base['compute_realtime_factor']:.1f}x "
          f"({base['cpu_realtime_factor']:.1f}x per CPU second); shipped / baseline "
          f"{fast['compute_realtime_factor'] / base['compute_realtime_factor']:.2f} (load "
          f"{os.getloadavg()[0]:.1f})")


def compare_view(args, overrides) -> None:
    """Throughput runs alternating without / with the view and an open page."""
    from snn_antenna.bridge.view.view import LiveView

    plain_parts = online_parts(args.network, overrides, args.speed)
    # the view taps its chain's coder
    view_parts = online_parts(args.network, overrides, args.speed)
    view = LiveView(view_parts, port=0)
    url = view.start()
    page = OpenPage(url)
    try:
        deadline = time.monotonic() + 60
        while page.kind.startswith("headless") and _state(url)["sessions"] < 1 \
                and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(2.0)                         # the page has loaded BokehJS and connected
        without, with_view = [], []
        for _ in range(args.repeats):
            without.append(_rtf(plain_parts, args.view_seconds))
            with_view.append(_rtf(view_parts, args.view_seconds, view))
        sessions = _state(url)["sessions"]
    finally:
        page.close()
        summary = view.stop()
    a, b = statistics.median(without), statistics.median(with_view)
    print(f"live view ({page.kind}, {sessions} page(s) open, "
          f"{summary['frames_dropped']} of {summary['frames_published']} view frames dropped):")
    for name, median, runs in (("without view", a, without), ("with view", b, with_view)):
        print(f"  throughput {name:13s} {median:6.1f}x   (runs: "
              + ", ".join(f"{v:.1f}x" for v in runs) + ")")
    print(f"  with / without: {b / a:.2f} (median of {args.repeats} alternating runs each)")


def compare_reload(args, overrides) -> None:
    """Live (1 kHz) runs with the view: nobody reading it, then a client reloading the page."""
    from snn_antenna.bridge.view.view import LiveView

    rows = []
    for reloading in (False, True):
        parts = online_parts(args.network, overrides, args.speed)
        warm_up(parts)
        view = LiveView(parts, port=0)
        url = view.start()
        reloader = Reloader(url) if reloading else None
        try:
            report = stream_from_emulator(parts, args.view_seconds, False, view)
        finally:
            if reloader:
                reloader.close()
            summary = view.stop()
        rows.append((reloading, report, reloader.loads if reloader else 0, summary))
    print(f"live view at 1 kHz, {args.view_seconds:g} s of input, without / with a page "
          f"loaded twice a second (load {os.getloadavg()[0]:.1f}):")
    print(f"  {'client':10s} {'loads':>5s}  {'real-time factor':>16s}  {'latency median':>14s}"
          f"  {'p95':>8s}  {'lost':>4s}  {'late':>4s}  {'view frames dropped':>19s}")
    for reloading, report, loads, summary in rows:
        steady, counts = report["steady_latency_ms"], report.get("counts", {})
        median, p95 = ((f"{steady['median']:.1f} ms", f"{steady['p95']:.1f} ms")
                       if steady["windows"] else ("never caught up", "–"))
        print(f"  {'reloading' if reloading else 'no client':10s} {loads:5d}  "
              f"{report['realtime_factor']:15.3f}x  {median:>14s}  {p95:>8s}  "
              f"{counts.get('lost_samples', 'n/a'):>4}  {counts.get('late', 'n/a'):>4}  "
              f"{summary['frames_dropped']!s:>9s} of {summary['frames_published']:<6d}")


def _state(url: str) -> dict:
    import json
    import urllib.request

    with urllib.request.urlopen(url + "state.json", timeout=30) as reply:
        return json.loads(reply.read())


class Reloader:
    """A client loading the page twice a second over HTTP, in its own process (as a browser
    tab is). Each load builds a Bokeh session in the view's process, torn down later."""

    # Loads due every period (not a period after the last answer): twice a second as long
    # as the view process answers within half a second, and catching up when it did not.
    SCRIPT = ("import sys, time, urllib.request\n"
              "due = time.monotonic()\n"
              "while True:\n"
              "    due += float(sys.argv[2])\n"
              "    time.sleep(max(0.0, due - time.monotonic()))\n"
              "    try:\n"
              "        urllib.request.urlopen(sys.argv[1], timeout=5).read()\n"
              "        print('.', end='', flush=True)\n"
              "    except OSError:\n"
              "        pass\n")

    def __init__(self, url: str, period_s: float = 0.5):
        self.loads = 0
        self._proc = subprocess.Popen([sys.executable, "-c", self.SCRIPT, url, str(period_s)],
                                      stdout=subprocess.PIPE, text=True)

    def close(self) -> None:
        self._proc.terminate()
        self.loads = self._proc.communicate(timeout=10)[0].count(".")


def _rtf(parts, seconds: float, view=None) -> float:
    """One throughput run's real-time factor. On a loaded machine the emulator's pty now and
    then loses its reader mid-run; such a run is said and done again, not counted."""
    for _attempt in range(3):
        try:
            return stream_from_emulator(parts, seconds, True, view)["compute_realtime_factor"]
        except PortError as exc:
            print(f"  (run lost its port, repeated: {exc})")
    raise PortError("the emulator's pty failed three runs in a row")


class OpenPage:
    """A page kept open on ``url`` by headless Chromium, when it is installed."""

    def __init__(self, url: str):
        chromium = shutil.which("chromium") or shutil.which("chromium-browser")
        self.kind = "headless Chromium" if chromium else "no Chromium installed: no page"
        self._proc = chromium and subprocess.Popen(
            [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--window-size=1200,900",
             url], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc else None

    def close(self) -> None:
        if self._proc:
            self._proc.terminate()
            self._proc.wait(10)


if __name__ == "__main__":
    sys.exit(main())
