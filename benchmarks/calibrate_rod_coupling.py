"""Calibrate ``antenna.ROD_COUPLING``: the coupling at which the full-spectrum FFT-MLP reads
the paper's 94.2 % on the whole bench set.

    nice -n 10 python benchmarks/calibrate_rod_coupling.py [--bracket 0.017 0.022] \\
        [--curve 0.016 0.017 0.018] [--fit 0.016 0.022] [--target 0.942] \\
        [--set stimulus.repetitions=20] [--out PATH.json]

The baseline study's spec (``studies/baseline_comparison.toml``, its bench set of 100
repetitions and its five splits) with the coupling as its one free value
(``snn_antenna.studies.baseline_comparison.coupling``): ``--curve`` couplings are measured
first, then ``brentq`` on ``--bracket`` (ends on either side of the target) finds the root of
mean accuracy − target; ``--fit`` also gives where a line through the couplings measured in
its range meets the target (near the target one coupling's mean wanders by a few tenths of a
point from split noise: the line averages it). Each coupling's bench set and features are
cached under the spec's ``cache_dir``. Prints and writes every coupling measured: its mean
accuracy over the splits with the 95 % interval and n, the roots, and the load average.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from snn_antenna.core import spec as specs  # noqa: E402
from snn_antenna.report.results import write_benchmark_json  # noqa: E402
from snn_antenna.sources import antenna  # noqa: E402
from snn_antenna.studies import baseline_comparison as study  # noqa: E402
from snn_antenna.studies.baseline_comparison import coupling as calibration  # noqa: E402

STUDY = Path(__file__).resolve().parents[1] / "studies" / "baseline_comparison.toml"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bracket", type=float, nargs=2, metavar=("LOW", "HIGH"),
                    help="couplings on either side of the target (brentq's bracket)")
    ap.add_argument("--curve", type=float, nargs="*", default=[],
                    help="couplings measured besides the root's search")
    ap.add_argument("--target", type=float, default=calibration.PAPER_ACCURACY)
    ap.add_argument("--fit", type=float, nargs=2, metavar=("LOW", "HIGH"),
                    help="also the root of a line through the couplings measured in LOW-HIGH")
    ap.add_argument("--xtol", type=float, default=2e-4, help="the root's tolerance (coupling)")
    ap.add_argument("--set", action="append", default=[], dest="overrides",
                    help="a study spec override, e.g. stimulus.repetitions=20")
    ap.add_argument("--out", default="out/calibrate_rod_coupling.json")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    parts = study.plan(specs.load(STUDY, args.overrides)).parts
    points = {float(c): calibration.accuracy(parts, float(c)) for c in args.curve}
    root = None
    if args.bracket:
        root, points = calibration.calibrate(parts, tuple(args.bracket), args.target,
                                             args.xtol, points)
    rows = calibration.curve_rows(points)
    fitted = calibration.fitted_root(points, args.target, tuple(args.fit)) if args.fit else None
    for r in rows:
        print(f"coupling {r['coupling']:.5f}  accuracy {100 * r['accuracy']:6.2f} % "
              f"[{100 * r['interval'][0]:.2f}, {100 * r['interval'][1]:.2f}] n={r['n']}")
    if root is not None:
        print(f"root (brentq): ROD_COUPLING = {root:.4f} (target {100 * args.target:.1f} %)")
    if fitted is not None:
        print(f"root (line through {args.fit[0]:g}-{args.fit[1]:g}): ROD_COUPLING = "
              f"{fitted[0]:.4f}; slope {fitted[1] / 10:.2f} points per 0.001")
    load = os.getloadavg()
    print(f"load average {load[0]:.1f}; {time.perf_counter() - t0:.0f} s")
    out = {"target": args.target, "source": "paper (docs/reference.md)",
           "rod_coupling_in_code": antenna.ROD_COUPLING, "root": root,
           "fitted": None if fitted is None else {"within": args.fit, "root": fitted[0],
                                                  "slope_per_unit": fitted[1]},
           "curve": rows,
           "overrides": args.overrides, "seconds": time.perf_counter() - t0,
           "load_average": load}
    write_benchmark_json(args.out, out)
    return out


if __name__ == "__main__":
    main()
