"""The baseline study's coder comparison alone: each coder × bank size × read-out, its
neuron-free ceiling, the full-spectrum MLP and the costs, on the same contacts and splits, at
``CODER_SIZES`` resonators (the study compares its coders at the one size it scores).

    python benchmarks/bench_coders.py [--repetitions 100] [--out out/bench_coders.json]
    python benchmarks/bench_coders.py --cost-only [--set spiking.cost_sample_events=400]

The study's own code (``studies/baseline_comparison.toml``'s ``[spiking.tuned]``: the channels
placed from calibration contacts of another seed, ``coder_stage``, ``best_costs``,
``Comparison.coder_table``) on the bench set's first ``--repetitions`` repetitions of every
material and site (100: the whole set, what ``snn-antenna run
studies/baseline_comparison.toml`` measures with everything else), split by repetition for
every seed of ``[evaluation] seeds``. Without the study's hand-set bands, designs, NMF curve
and accuracy curve, which do not depend on the coder. Prints the table and writes it as JSON.
``--cost-only`` JSON carries its own name (``bench_coders_cost_only``): on the results page it
is a section of its own, beside the full run's.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from snn_antenna.core import spec as specs  # noqa: E402
from snn_antenna.evaluation import crossval as cv  # noqa: E402
from snn_antenna.evaluation.comparison import coder_rows  # noqa: E402
from snn_antenna.readout import baselines as bl  # noqa: E402
from snn_antenna.report.results import write_benchmark_json  # noqa: E402
from snn_antenna.studies import baseline_comparison as study  # noqa: E402
from snn_antenna.studies.baseline_comparison.run import signal_stage  # noqa: E402
from snn_antenna.studies.baseline_comparison.tuned import (  # noqa: E402
    best_costs,
    calibration_bands,
    coder_banks,
    coder_stage,
)

STUDY = Path(__file__).resolve().parents[1] / "studies" / "baseline_comparison.toml"


def bench_set(repetitions: int, overrides: list[str]):
    """The baseline study's parts and tuned plan on the bench set of ``repetitions``, its signal
    stage (data and FFT comparison) and the bands calibrated on it, with where they came from:
    what this benchmark and bench_stage_ceilings.py read their banks from."""
    spec = specs.load(STUDY, [f"stimulus.repetitions={repetitions}", *overrides])
    parts = study.plan(spec).parts
    plan = parts.plan.tuned_plan()
    data, cmp, _ = signal_stage(parts, 3, print, False)
    bands, where = calibration_bands(parts, data, plan, print, False)
    return parts, plan, data, cmp, bands, where


#: the bank sizes the coders are compared at (the study's own spec compares one)
CODER_SIZES = (24, 48)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repetitions", type=int, default=100,
                    help="contacts per material and site (100: the whole bench set)")
    ap.add_argument("--out", default="out/bench_coders.json")
    ap.add_argument("--cost-only", action="store_true",
                    help="only the cost per event of the FFT and of every coder's bank")
    ap.add_argument("--set", action="append", default=[], dest="overrides",
                    help="a study spec override, e.g. spiking.tuned.coder_sizes=[24]")
    args = ap.parse_args(argv)
    # the study scores one bank size; the benchmark asks what a bigger bank buys
    args.overrides = [f"spiking.tuned.coder_sizes={list(CODER_SIZES)}", *args.overrides]
    t0 = time.perf_counter()
    parts, plan, data, cmp, bands, where = bench_set(args.repetitions, args.overrides)
    if args.cost_only:
        costs = best_costs(data, parts, cmp.features["event"].values,
                           coder_banks(plan, bands, parts.bank), plan.cost_repeats, print)
        fft_us = costs["fft"]["features_us_per_event"]
        for k, c in costs.items():
            print(f"{k:20s} {c['features_us_per_event']:9.0f} µs/event = "
                  f"{c['features_us_per_event'] / fft_us:5.2f} × FFT")
        print(f"load average {os.getloadavg()[0]:.1f}")
        write_benchmark_json(args.out, {"costs": costs, "load_average": os.getloadavg()},
                             name=f"{Path(__file__).stem}_cost_only")
        return costs
    chosen = coder_stage(parts, data, cmp, bands, plan, print, False, None)
    banks = cmp.coders.pop("banks")
    costs = best_costs(data, parts, cmp.features["event"].values, banks, plan.cost_repeats,
                       print)
    cmp.costs["fft"] = costs.pop("fft")
    cmp.coders["costs"] = costs
    fft = bl.material_baselines([], parts.evaluation.material_mlp,
                                parts.evaluation.nmf_max_iter)[0]
    cmp.results = cv.evaluate(cmp.features, [fft, *chosen], parts.evaluation, print)
    table = cmp.coder_table()
    fft_acc = cmp.results[fft.name].values("accuracy")
    out = {"events": int(cmp.features.sizes["event"]), "repetitions": args.repetitions,
           "seeds": parts.evaluation.seeds, **where, "fft_mlp_accuracy": fft_acc.tolist(),
           "fft_cost": cmp.costs["fft"], "coders": table,
           "load_average": os.getloadavg(), "wall_s": time.perf_counter() - t0}
    write_benchmark_json(args.out, out)
    print(f"{out['events']} events, {len(parts.evaluation.seeds)} splits; FFT-MLP "
          f"{100 * fft_acc.mean():.1f} %, FFT {cmp.costs['fft']['features_us_per_event']:.0f} "
          f"µs/event (best of {plan.cost_repeats}); load average {os.getloadavg()[0]:.1f}")
    rows = coder_rows({"spiking": {"coders": table}})
    keys = list(rows[0]) if rows else []
    print(" | ".join(keys))
    for r in rows:
        print(" | ".join(str(r[k]) for k in keys))
    print(f"written {args.out}")
    return out


if __name__ == "__main__":
    main()
