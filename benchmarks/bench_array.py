"""The quickstart's resonator array against real time and against hand-written kernels.

    python benchmarks/bench_array.py [--seconds 8] [--neurons 24]

Runs the same coded input through the 24-neuron array in Brian2 (numpy and cython runtime
targets), a hand-written numba Euler kernel of the same equations, and a plain Python loop,
all in this one process, and prints the ratios (absolute times drift on shared machines;
ratios hold). Spike counts are printed too, so a fast but wrong kernel shows.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from snn_antenna.networks import neurons
from snn_antenna.networks.resonators import ResonatorArray
from snn_antenna.preprocess import make_chain
from snn_antenna.core.signals import Recording
from snn_antenna.report.results import write_benchmark_json
from snn_antenna.sources.stimuli import Contact, RobotScene


def python_loop(current, rate_hz, dt_ms, k, p):
    """Forward Euler over every neuron and step in plain Python: the naive baseline."""
    v0, u0 = neurons.resting_state("resonator")
    n = len(k)
    v, u, spikes = [v0] * n, [u0] * n, 0
    per_sample = int(round(1000.0 / rate_hz / dt_ms))
    for I in current:
        for _ in range(per_sample):
            for j in range(n):
                dv = k[j] * (0.04 * v[j] * v[j] + 5 * v[j] + 140 - u[j] + I)
                du = p.a * k[j] * (p.b * v[j] - u[j])
                v[j] += dt_ms * dv
                u[j] += dt_ms * du
                if v[j] >= 30:
                    v[j], u[j], spikes = p.c, u[j] + p.d, spikes + 1
    return spikes


def numba_kernel():
    from numba import njit

    @njit(cache=True, fastmath=False)
    def run(current, per_sample, dt_ms, k, a, b, c, d, v0, u0):
        n = k.shape[0]
        v = np.full(n, v0)
        u = np.full(n, u0)
        counts = np.zeros(n, np.int64)
        for I in current:
            for _ in range(per_sample):
                for j in range(n):
                    vj = v[j]
                    dv = k[j] * (0.04 * vj * vj + 5 * vj + 140 - u[j] + I)
                    du = a * k[j] * (b * vj - u[j])
                    v[j] = vj + dt_ms * dv
                    u[j] += dt_ms * du
                    if v[j] >= 30:
                        v[j] = c
                        u[j] += d
                        counts[j] += 1
        return counts
    return run


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--neurons", type=int, default=24)
    ap.add_argument("--python-seconds", type=float, default=0.5,
                    help="simulated seconds for the (slow) plain Python loop, scaled up")
    ap.add_argument("--json", metavar="PATH",
                    help="also write the measured values and their provenance as JSON "
                         "(for snn-antenna results)")
    args = ap.parse_args(argv)

    rec = RobotScene(duration_s=args.seconds, contacts=[Contact(args.seconds * 0.7, 19.0)]
                     ).generate(seed=1)
    chain = make_chain(rec.rate_hz, threshold=0.05).fit(rec.samples)
    coded = rec.with_samples(chain.transform(rec.samples), "coded")
    rows = []

    for target in ("numpy", "cython"):
        array = ResonatorArray(n_neurons=args.neurons, target=target)
        array.run(Recording(coded.samples[:200], rec.rate_hz))  # compile / warm up
        t0 = time.perf_counter()
        result = array.run(coded)
        rows.append((f"Brian2 {target}", time.perf_counter() - t0, len(result.spike_i)))
    array = ResonatorArray(n_neurons=args.neurons)
    p = neurons.PRESETS["resonator"]
    v0, u0 = neurons.resting_state("resonator")
    per_sample = int(round(1000.0 / rec.rate_hz / array.dt_ms))
    run = numba_kernel()
    run(coded.samples[:10], per_sample, array.dt_ms, array.k, p.a, p.b, p.c, p.d, v0, u0)
    t0 = time.perf_counter()
    counts = run(coded.samples, per_sample, array.dt_ms, array.k, p.a, p.b, p.c, p.d, v0, u0)
    rows.append(("numba kernel (hand-written)", time.perf_counter() - t0, int(counts.sum())))
    n_py = int(args.python_seconds * rec.rate_hz)
    t0 = time.perf_counter()
    python_loop(coded.samples[:n_py], rec.rate_hz, array.dt_ms, list(array.k), p)
    scale = len(coded.samples) / n_py
    rows.append((f"plain Python loop (x{scale:.0f} extrapolated)",
                 (time.perf_counter() - t0) * scale, None))

    steps = args.seconds * 1000 / array.dt_ms * args.neurons
    ref = rows[1][1]
    print(f"{args.neurons} resonators, {args.seconds:g} s of 1 kHz input, dt {array.dt_ms} ms "
          f"({steps:.3g} neuron-steps)")
    print(f"{'implementation':44s} {'wall s':>8s} {'x real time':>11s} {'ns/neuron-step':>15s} "
          f"{'vs cython':>9s} {'spikes':>7s}")
    for name, wall, n_spikes in rows:
        print(f"{name:44s} {wall:8.3f} {args.seconds / wall:11.1f} {wall / steps * 1e9:15.1f} "
              f"{ref / wall:9.2f} {'' if n_spikes is None else n_spikes:>7}")
    if args.json:
        write_benchmark_json(args.json, {
            "neurons": args.neurons, "seconds": args.seconds, "dt_ms": array.dt_ms,
            "implementations": {
                name: {"wall_s": wall, "x_real_time": args.seconds / wall,
                       "ns_per_neuron_step": wall / steps * 1e9, "of_cython": ref / wall,
                       "spikes": n_spikes}
                for name, wall, n_spikes in rows}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
