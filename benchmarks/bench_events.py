"""Events per second of the spiking read-out: one NeuronGroup for many events vs one run each.

    python benchmarks/bench_events.py [--target cython] [--naive 20] [--batch 400]

Both paths use the same coded inputs (the real preprocessing chain) and the same 24-neuron
low band at dt 0.1 ms; the naive path calls ``ResonatorArray.run`` once per event (a Brian2
``run()`` per event), the vectorised path puts ``--batch`` events × 24 neurons in ONE group
(``SpikingBank.run`` → ``neurons.simulate`` with a 2-D input and ``input_index``). Each is
warmed up once (code generation, cython compilation) before it is timed. The spike counts of
the events both paths ran are compared, so the speed-up is for the same answer.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from snn_antenna.readout.spiking import LOW_BAND, SpikingBank
from snn_antenna.signals import Recording
from snn_antenna.sources import bench


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", default="cython", choices=["numpy", "cython"])
    parser.add_argument("--naive", type=int, default=20, help="events run one by one")
    parser.add_argument("--batch", type=int, default=400, help="events in one NeuronGroup")
    parser.add_argument("--duration", type=float, default=0.5, help="seconds per event")
    args = parser.parse_args()

    spec = bench.BenchSpec(repetitions=max(1, -(-args.batch // 128)), n_jobs=1)
    data = bench.generate(spec, log=lambda *_: None)
    counts = data["counts"].values[:args.batch]
    rate, bits, fs = spec.rate_hz, spec.adc_bits, spec.full_scale_g
    bank = SpikingBank(bands={"low": LOW_BAND}, duration_s=args.duration, target=args.target,
                       batch_events=args.batch)
    coded = bank.code(counts, rate, bits, fs)          # (samples, events): same for both paths
    array = LOW_BAND.array(bank.dt_ms, bank.method, args.target)

    def naive(n):
        out = []
        for e in range(n):
            res = array.run(Recording(np.ascontiguousarray(coded[:, e]), rate, units="coded"))
            out.append(np.bincount(res.spike_i, minlength=array.n_neurons))
        return np.array(out)

    naive(1)                                           # warm-up: code generation, compiling
    t0 = time.perf_counter()
    naive_counts = naive(args.naive)
    naive_s = time.perf_counter() - t0

    bank.run(counts[:2], rate, bits, fs, progress=False)  # warm-up
    t0 = time.perf_counter()
    feats = bank.run(counts, rate, bits, fs, progress=False)
    vector_s = time.perf_counter() - t0

    same = np.abs(feats.counts[:args.naive] - naive_counts).sum()
    naive_rate, vector_rate = args.naive / naive_s, len(counts) / vector_s
    steps = feats.neuron_steps / len(counts)
    print(f"target {args.target}, {array.n_neurons} resonators per event, dt {bank.dt_ms} ms, "
          f"{args.duration} s per event ({steps:.3g} neuron-steps per event)")
    print(f"naive  (one Brian2 run per event, {args.naive} events): {naive_rate:8.2f} events/s")
    print(f"vector ({len(counts)} events in one NeuronGroup):      {vector_rate:8.2f} events/s "
          f"({1e9 * feats.wall_s / feats.neuron_steps:.1f} ns per neuron-step in Brian2, "
          f"coding included in events/s)")
    print(f"speed-up {vector_rate / naive_rate:.1f}x; spike-count difference on the "
          f"{args.naive} shared events: {same} spikes of {naive_counts.sum()}")
    print(f"whole bench set (12,800 events) at this rate: {12800 / vector_rate:.0f} s")


if __name__ == "__main__":
    main()
