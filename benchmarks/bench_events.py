"""Bench read-out on the sweep engine: the whole bench set, per neuron-step beside the sweeps.

    python benchmarks/bench_events.py [--events 12800] [--workers 2] [--runtime-events 400]
    python benchmarks/bench_events.py --cost-only [--cost-events 400] [--sizes 24 48]
    ... [--json PATH]   (the measured values with their provenance, for ``snn-antenna results``)

Every event (the real preprocessing chain, 0.5 s at 2 kHz) drives the 24-resonator low band
at dt 0.1 ms (``engine.events.run_bank``: grid event × neuron, ``batch_events`` events per
chunk). Measured in one run and printed side by side, each with the machine's load average:

- ``sweep engine``: ``bench_sweep.py``'s standalone ``NeuronSweep`` (a 10^4-point grid, the
  same duration and dt) in this process: the reference cost per neuron-step;
- ``event engine, this process``: the bench events through ``run_bank`` with target
  ``standalone`` in this process: per neuron-step for the whole run (coding, Brian2, store
  writes) and for Brian2 alone (the compiled binary's runs);
- ``runtime path``: the same events with target ``cython`` (``neurons.simulate``, one group
  per chunk with a 2-D input and ``input_index``: the runtime read-out path),
  for the ratio; the spike counts of both paths are compared neuron by neuron;
- ``whole bench set``: all ``--events`` events on a Dask LocalCluster of ``--workers``
  processes (timed on a second run: cluster start and each worker's compile excluded).

- ``spiking vs FFT, cost per event`` (``--cost-only`` runs this part alone): the
  FFT pipeline's feature extraction (``events.extraction_cost``, the baseline study's
  ``[events]``) and the baseline study's tuned bank (``[spiking.tuned]``: channels placed
  from calibration contacts of another seed, each channel at the coarsest step within the
  rod band's validated k·dt) at each ``--sizes`` number of resonators, on the same events
  in one run: every contact of a batch in one Brian2 run (``batch_events`` copies of the
  bank, the channels sharing a step in one NeuronGroup), and, for the smallest size, one
  run per contact, so the per-run overhead is measured rather than assumed. Each is the
  best of three runs taken in turn (``run_cost``), with its ns per neuron-step of Brian2
  time (the compiled run with its inputs' and results' files).

Every timed run follows a warm-up (code generation, compiling; cached on disk).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_sweep import grid_of  # noqa: E402  (this folder)

from snn_antenna.engine.evaluators import NeuronSweep  # noqa: E402
from snn_antenna.core import spec as specs  # noqa: E402
from snn_antenna.engine.events import run_bank, run_cost  # noqa: E402
from snn_antenna.engine.executor import dask_client  # noqa: E402
from snn_antenna.engine.sweep import run_sweep  # noqa: E402
from snn_antenna.readout.spiking import LOW_BAND, SpikingBank  # noqa: E402
from snn_antenna.readout.events import extraction_cost  # noqa: E402
from snn_antenna.report.results import write_benchmark_json  # noqa: E402
from snn_antenna.sources import bench  # noqa: E402
from snn_antenna.studies import baseline_comparison as study  # noqa: E402
from snn_antenna.studies.baseline_comparison.tuned import calibration_bands  # noqa: E402

STUDY = Path(__file__).resolve().parents[1] / "studies" / "baseline_comparison.toml"


def load() -> str:
    return f"load average {os.getloadavg()[0]:.1f}"


def sweep_reference(duration_s: float, points: int, tmp: Path) -> float:
    """ns per neuron-step of the standalone NeuronSweep (bench_sweep.py's grid), compile
    excluded, store writes included."""
    sweep = NeuronSweep(duration_s=duration_s, settle_s=duration_s / 4)
    grid = grid_of(points)
    run_sweep(grid, sweep, tmp / "warm.zarr", NeuronSweep.OUTPUTS, chunk_points=10_000,
              progress=False)
    t0 = time.perf_counter()
    run_sweep(grid, sweep, tmp / "sweep.zarr", NeuronSweep.OUTPUTS, chunk_points=10_000,
              progress=False)
    steps = grid.size * duration_s * 1000 / sweep.dt_ms
    return 1e9 * (time.perf_counter() - t0) / steps


def timed(bank, counts, attrs, warm_events: int = 2, **kw):
    run_bank(bank, counts[:warm_events], *attrs, progress=False, **kw)  # warm-up
    t0 = time.perf_counter()
    f = run_bank(bank, counts, *attrs, progress=False, **kw)
    return f, time.perf_counter() - t0


def spiking_vs_fft(data, n_events: int, sizes, per_contact_events: int = 5,
                   repeats: int = 3) -> dict:
    """Cost per event of the FFT pipeline and of the tuned spiking bank, measured now, each
    the best of ``repeats`` runs taken in turn (on a shared machine a single run of either
    can land in another process's burst: one such run read the FFT 7x its idle cost)."""
    parts = study.plan(specs.load(str(STUDY))).parts
    plan = parts.plan.tuned_plan()
    plan.curve = sorted(set(sizes))
    bands, _ = calibration_bands(parts, data, plan, lambda *_: None, False)
    ids = np.linspace(0, data.sizes["event"] - 1, n_events).astype(int)
    banks = {n: plan.bank(bands[n], parts.bank) for n in plan.curve}
    fft, spiking = [], {n: [] for n in plan.curve}
    for _ in range(repeats):
        fft.append(extraction_cost(data, parts.processor, ids)["features_us_per_event"])
        for n, bank in banks.items():
            spiking[n].append(run_cost(data, bank, n_events))
    print(f"FFT pipeline (onset, spectrum, peaks, decay fits; {n_events} events): best "
          f"{min(fft):8.0f} µs per event of {', '.join(f'{x:.0f}' for x in fft)} ({load()})",
          flush=True)
    measured = {"fft_pipeline": {"events": n_events, "us_per_event": min(fft),
                                 "runs_us_per_event": fft, "load_average": os.getloadavg()[0]},
                "tuned_banks": []}
    fft = min(fft)
    for n, bank in banks.items():
        c = min(spiking[n], key=lambda r: r["features_us_per_event"])
        print(f"tuned spiking bank, {n:3d} resonators in {len(bank.bands):2d} channels, "
              f"{bank.batch_events} contacts per Brian2 run: best "
              f"{c['features_us_per_event']:8.0f} "
              f"µs per event = {c['features_us_per_event'] / fft:5.1f}x the FFT pipeline "
              f"({c['neuron_steps_per_event']:.3g} neuron-steps, {c['ns_per_neuron_step']:.1f} "
              f"ns each; {load()})", flush=True)
        row = {"resonators": n, "channels": len(bank.bands),
               "contacts_per_run": bank.batch_events,
               "us_per_event": c["features_us_per_event"],
               "of_fft": c["features_us_per_event"] / fft,
               "neuron_steps_per_event": c["neuron_steps_per_event"],
               "ns_per_neuron_step": c["ns_per_neuron_step"],
               "load_average": os.getloadavg()[0]}
        measured["tuned_banks"].append(row)
        if n == plan.curve[0]:
            one = dataclasses.replace(bank, batch_events=1)
            counts = data["counts"].values[ids[:per_contact_events]]
            _, seconds = timed(one, counts, (data.attrs["rate_hz"], data.attrs["adc_bits"],
                                             data.attrs["full_scale_g"]), warm_events=1)
            per = 1e6 * seconds / len(counts)
            print(f"  the same bank, one Brian2 run per contact ({len(counts)} contacts): "
                  f"{per:8.0f} µs per event = {per / c['features_us_per_event']:.2f}x the "
                  f"batched run ({load()})", flush=True)
            measured["one_run_per_contact"] = {
                "resonators": n, "contacts": len(counts), "us_per_event": per,
                "of_batched": per / c["features_us_per_event"]}
    return measured


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=int, default=12_800, help="events of the whole set")
    ap.add_argument("--workers", type=int, nargs="+", default=[2])
    ap.add_argument("--runtime-events", type=int, default=400,
                    help="events run by both this process's paths (counts compared)")
    ap.add_argument("--batch", type=int, default=400, help="events per chunk (one Brian2 run)")
    ap.add_argument("--duration", type=float, default=0.5, help="seconds per event")
    ap.add_argument("--sweep-points", type=int, default=10_000)
    ap.add_argument("--cost-only", action="store_true",
                    help="only the spiking-vs-FFT cost per event")
    ap.add_argument("--cost-events", type=int, default=400,
                    help="events timed for the spiking-vs-FFT cost")
    ap.add_argument("--sizes", type=int, nargs="+", default=[24, 48],
                    help="resonators of the tuned banks timed beside the FFT pipeline")
    ap.add_argument("--json", metavar="PATH",
                    help="also write the measured values and their provenance as JSON")
    args = ap.parse_args(argv)
    if args.cost_only:
        data = bench.generate(bench.BenchSpec(repetitions=max(1, -(-args.cost_events // 128)),
                                              n_jobs=2), log=lambda *_: None)
        print(f"# {os.cpu_count()} CPU cores; spiking vs FFT, cost per event")
        cost = spiking_vs_fft(data, args.cost_events, args.sizes)
        if args.json:
            write_benchmark_json(args.json, {"cpus": os.cpu_count(), **cost})
        return 0

    tmp = Path(tempfile.mkdtemp(prefix="bench_events_"))
    spec = bench.BenchSpec(repetitions=max(1, -(-args.events // 128)), n_jobs=2)
    data = bench.generate(spec, log=lambda *_: None)
    counts = data["counts"].values[:args.events]
    attrs = (spec.rate_hz, spec.adc_bits, spec.full_scale_g)
    bank = SpikingBank(bands={"low": LOW_BAND}, duration_s=args.duration, target="standalone",
                       batch_events=args.batch)
    steps_per_event = LOW_BAND.n_neurons * args.duration * 1000 / bank.dt_ms
    print(f"# {os.cpu_count()} CPU cores; {LOW_BAND.n_neurons} resonators per event, dt "
          f"{bank.dt_ms} ms, {args.duration} s per event = {steps_per_event:,.0f} neuron-steps; "
          f"{args.batch} events per chunk")

    ref = sweep_reference(args.duration, args.sweep_points, tmp)
    print(f"sweep engine (NeuronSweep, standalone, {args.sweep_points:,} points): "
          f"{ref:5.2f} ns per neuron-step ({load()})", flush=True)

    sample = counts[:args.runtime_events]
    fs, fs_s = timed(bank, sample, attrs)
    ns_whole, ns_brian = 1e9 * fs_s / fs.neuron_steps, 1e9 * fs.wall_s / fs.neuron_steps
    print(f"event engine, this process ({len(sample)} events): {ns_whole:5.2f} ns per "
          f"neuron-step (coding + Brian2 + store), {ns_brian:.2f} in Brian2 ({load()})",
          flush=True)
    fr, fr_s = timed(dataclasses.replace(bank, target="cython"), sample, attrs)
    ns_runtime = 1e9 * fr_s / fr.neuron_steps
    print(f"runtime path, cython ({len(sample)} events):    {ns_runtime:5.2f} ns per neuron-step "
          f"(coding + Brian2 + store), {1e9 * fr.wall_s / fr.neuron_steps:.2f} in Brian2 "
          f"({load()})", flush=True)
    diff = np.abs(fs.counts - fr.counts)
    print(f"spike counts, standalone vs cython on {len(sample)} shared events: "
          f"{int((diff == 0).sum())} of {diff.size} neurons equal, max |Δ| {int(diff.max())}, "
          f"{int(diff.sum())} spikes of {int(fr.counts.sum())} differ; first-spike times "
          f"equal for {100 * np.mean(fs.latency_s == fr.latency_s):.2f} % of neurons")

    whole = {}
    for w in args.workers:
        with dask_client(workers=w) as client:
            # warm-up: two chunks per worker, so each compiles (or loads) its project
            f, seconds = timed(bank, counts, attrs, warm_events=2 * w * args.batch,
                               client=client)
        whole[w] = seconds
        print(f"whole bench set, {len(counts):,} events on {w} Dask worker(s): {seconds:5.2f} s, "
              f"{len(counts) / seconds:,.0f} events/s, {1e9 * seconds / f.neuron_steps:.2f} ns "
              f"per neuron-step of wall time; Brian2 {f.wall_s:.1f} s summed over the workers "
              f"({1e9 * f.wall_s / f.neuron_steps:.2f} ns per neuron-step) ({load()})", flush=True)

    cost = spiking_vs_fft(data, args.cost_events, args.sizes)

    print("\n## summary (measured in this run)")
    print(f"  event engine / sweep engine, ns per neuron-step: whole run {ns_whole / ref:.2f}x, "
          f"Brian2 alone {ns_brian / ref:.2f}x")
    print(f"  runtime path / event engine: {ns_runtime / ns_whole:.1f}x slower "
          f"({ns_runtime:.2f} vs {ns_whole:.2f} ns per neuron-step)")
    for w, seconds in whole.items():
        print(f"  whole bench set on {w} worker(s): {seconds:.1f} s (aim: <= 8 s)")
    if args.json:
        diff_share = float((diff == 0).mean())
        write_benchmark_json(args.json, {
            "cpus": os.cpu_count(), "events": len(counts), "sweep_ns_per_neuron_step": ref,
            "event_engine": {"ns_per_neuron_step": ns_whole, "brian2_ns_per_neuron_step": ns_brian,
                             "of_sweep": ns_whole / ref},
            "runtime_path": {"ns_per_neuron_step": ns_runtime, "of_event_engine":
                             ns_runtime / ns_whole},
            "counts_equal_share": diff_share,
            "whole_set": [{"workers": w, "seconds": s} for w, s in whole.items()],
            **cost})
    return 0


if __name__ == "__main__":
    sys.exit(main())
