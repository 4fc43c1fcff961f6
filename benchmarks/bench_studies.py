"""Every study's run against its own estimate: measured wall time ÷ what ``--check`` prints.

    python benchmarks/bench_studies.py [--studies quickstart gating_threshold ...]
        [--profile quick|full] [--probe] [--set STUDY:KEY=VALUE ...] [--json PATH]

For each study (default: all of ``snn_antenna.studies.STUDIES``): the plan's estimate (the
number ``snn-antenna run studies/NAME.toml --check`` prints, from the plan's parts and the
engines' rates, ``engine.rates``), then the study itself run as a user runs it (``snn-antenna
run studies/NAME.toml [--quick] --yes --out TMP``, a fresh process and output folder, the
toolkit's compile cache as it is), timed from start to exit. The table gives both, their
ratio and the machine's load average before and after each run, and under each row what the
estimate's seconds pay for; the line above it says where the rates came from. ``--probe``
measures the rates on this machine first (``engine.rates.probe``, stored for the estimates
that follow). ``--set STUDY:KEY=VALUE`` passes ``--set KEY=VALUE`` to that study's estimate
and run alike.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from snn_antenna.core import spec as specs  # noqa: E402
from snn_antenna.engine import cost, rates  # noqa: E402
from snn_antenna.report.results import write_benchmark_json  # noqa: E402
from snn_antenna.studies import STUDIES, runner  # noqa: E402


def estimate(study: str, quick: bool, settings: list[str]):
    """The plan's estimate of ``studies/STUDY.toml`` (what ``--check`` prints)."""
    spec = specs.load(str(ROOT / "studies" / f"{study}.toml"), settings, quick=quick)
    return runner(study).plan(spec).estimate()


def measure(study: str, quick: bool, settings: list[str], out: Path) -> float:
    """Wall seconds of ``snn-antenna run`` on the study, in a process of its own."""
    command = [sys.executable, "-m", "snn_antenna.cli", "run",
               str(ROOT / "studies" / f"{study}.toml"), "--yes", "--out", str(out)]
    command += ["--quick"] if quick else []
    for setting in settings:
        command += ["--set", setting]
    t0 = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        tail = (done.stderr.strip().splitlines() or [""])[-1]
        raise SystemExit(f"{study}: the run exited {done.returncode}: {tail}")
    return wall


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--studies", nargs="+", default=sorted(STUDIES),
                        choices=sorted(STUDIES), metavar="STUDY")
    parser.add_argument("--profile", choices=("quick", "full"), default="quick")
    parser.add_argument("--probe", action="store_true",
                        help="measure the engines' rates on this machine first")
    parser.add_argument("--set", action="append", default=[], metavar="STUDY:KEY=VALUE",
                        help="a --set for one study's estimate and run")
    parser.add_argument("--json", metavar="PATH", help="write the table as JSON here")
    args = parser.parse_args(argv)
    settings: dict[str, list[str]] = {s: [] for s in args.studies}
    for item in args.set:
        study, _, setting = item.partition(":")
        if study not in settings or "=" not in setting:
            parser.error(f"--set {item}: STUDY:KEY=VALUE for one of {args.studies}")
        settings[study].append(setting)
    quick = args.profile == "quick"
    if args.probe:
        print("probing the engines' rates", flush=True)
        rates.probe()
    table = rates.rates()
    print(rates.sources(table), flush=True)
    rows = []
    print(f"{'study':22} {'profile':7} {'estimate':>9} {'measured':>9} {'ratio':>6}  load",
          flush=True)
    with tempfile.TemporaryDirectory(prefix="bench_studies_") as tmp:
        for study in args.studies:
            guess = estimate(study, quick, settings[study])
            seconds = guess.seconds if guess is not None else 0.0
            load_before = os.getloadavg()[0]
            wall = measure(study, quick, settings[study], Path(tmp) / study)
            load_after = os.getloadavg()[0]
            ratio = wall / seconds if seconds > 0 else float("inf")
            rows.append({"study": study, "profile": args.profile, "estimate_s": seconds,
                         "measured_s": wall, "measured_over_estimate": ratio,
                         "load_before": load_before, "load_after": load_after,
                         "settings": settings[study],
                         "estimate_parts_s": dict(getattr(guess, "parts", {}) or {})})
            print(f"{study:22} {args.profile:7} {seconds:8.0f}s {wall:8.0f}s {ratio:5.2f}x  "
                  f"{load_before:.1f} -> {load_after:.1f}", flush=True)
            if guess is not None and getattr(guess, "parts", None):
                print(f"    estimate: {cost.describe_parts(guess.parts)}", flush=True)
    within = [r for r in rows if 1 / 1.5 <= r["measured_over_estimate"] <= 1.5]
    print(f"within x1.5 of the estimate: {len(within)} of {len(rows)}")
    if args.json:
        write_benchmark_json(args.json, {"profile": args.profile, "rows": rows,
                                         "rates": rates.as_json(table),
                                         "cpus": os.cpu_count()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
