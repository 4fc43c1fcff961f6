"""The bench bands' settings against the exact reference: error and cost side by side.

    python benchmarks/bench_bands.py [--bands high rod] [--target cython]
    python benchmarks/bench_bands.py --bands high --materials wood --seconds 0.1   # a short run
    ... [--json PATH]   (the rows with their provenance, for ``snn-antenna results``)

For each band of the bench's spiking read-out (``evaluation.bands.BENCH_BANDS``), on the same
8 sample bench events (4 materials × 10/30 cm, 0.5 s each): the bank's own setting
(``bands.SMALL_SIGNAL_EULER``: euler 0.1 ms, 24.52 Hz per k), the shipped (``bands.CHOSEN``)
and the stability map's accurate step for euler and rk4, each against the exact reference
(``networks.reference``, solve_ivp) at the same Hz per unit k: k·dt, spike-count and
rate-map error, CPU ms per event and the cost ratio to the bank's own setting, measured in
one run with the load average printed. The speed/accuracy study's "bands" section chooses
``CHOSEN``; this prints the trade for a reader without the whole study. ``--materials`` and
``--seconds`` shrink the sample (fewer materials, shorter events) for a quick look; its errors
then rest on fewer spikes.
"""
from __future__ import annotations

import argparse
import os
import sys

from snn_antenna.evaluation import bands
from snn_antenna.report.results import write_benchmark_json

#: what a row of the JSON keeps of ``bands.measure``'s: the setting, its errors and its cost
ROW_KEYS = ("band", "role", "method", "dt_ms", "hz_per_k", "k_dt_max", "accurate_k_dt",
            "status", "spike_count_error", "rate_map_error", "cpu_ms_per_event",
            "cost_of_own_setting", "events_timed")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bands", nargs="+", default=list(bands.CHOSEN), choices=list(bands.CHOSEN))
    ap.add_argument("--target", default="cython", choices=["numpy", "cython"])
    ap.add_argument("--cost-events", type=int, default=48, help="events per timed group")
    ap.add_argument("--materials", nargs="+", metavar="NAME",
                    help="the sample events' materials (default: the study's four)")
    ap.add_argument("--seconds", type=float, help="seconds per event (default: the study's)")
    ap.add_argument("--json", metavar="PATH", help="write the rows as JSON here")
    args = ap.parse_args(argv)
    study = bands.BandStudy(**{field: value for field, value in (
        ("materials", args.materials), ("duration_s", args.seconds)) if value is not None})
    data = bands.sample_data(study.materials, study.positions_cm, study.repetitions)
    print(f"# {data.sizes['event']} bench events, {study.duration_s} s each, target "
          f"{args.target}; load average {os.getloadavg()[0]:.1f}")
    rows = []
    for name in args.bands:
        band, shipped = bands.BENCH_BANDS[name], bands.CHOSEN[name]
        events = bands.code_events(name, band, data, study.duration_s)
        refs = {}   # each setting against the exact solution of the same tuning (Hz per k)
        settings = [("bank's own", bands.SMALL_SIGNAL_EULER), ("shipped", shipped)] + [
            (f"map-accurate {m}", bands.BandSetting(m, bands.accurate_dt_ms(band, m,
                                                                           shipped.hz_per_k),
                                                    shipped.hz_per_k))
            for m in ("euler", "rk4")]
        base = None
        print(f"\n{name} band {band.band_hz[0]:g}-{band.band_hz[1]:g} Hz")
        print(f"  {'setting':<34} {'k·dt max':>9} {'counts':>8} {'rate map':>9} "
              f"{'ms/event':>9} {'cost':>6}")
        for role, setting in settings:
            if setting.hz_per_k not in refs:
                refs[setting.hz_per_k] = bands.reference_spikes(events, setting.hz_per_k)
            row = bands.measure(events, setting, refs[setting.hz_per_k], args.target,
                                args.cost_events)
            base = base or row["cpu_ms_per_event"]
            row = dict(row, role=role, cost_of_own_setting=row["cpu_ms_per_event"] / base)
            rows.append({key: row[key] for key in ROW_KEYS if key in row})
            print(f"  {role + ': ' + setting.label():<34} {row['k_dt_max']:>9.3g} "
                  f"{row['spike_count_error']:>8.1%} {row['rate_map_error']:>9.1%} "
                  f"{row['cpu_ms_per_event']:>9.1f} {row['cpu_ms_per_event'] / base:>5.1f}x")
    print(f"\nload average {os.getloadavg()[0]:.1f}")
    if args.json:
        write_benchmark_json(args.json, {
            "events": int(data.sizes["event"]), "seconds_per_event": study.duration_s,
            "target": args.target, "settings": rows, "load_average": os.getloadavg()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
