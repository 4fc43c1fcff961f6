"""Sweep throughput: vectorised Brian2 grids vs a naive per-point loop vs numba kernels.

    python benchmarks/bench_sweep.py                 # 10^3, 10^4, 10^5 points
    python benchmarks/bench_sweep.py --sizes 1000 --workers 1 2 --duration-s 0.5
    python benchmarks/bench_sweep.py --sizes 1000000 # a 10^6-point grid's time, and on Dask

Every grid point is one resonator driven by the coder's square wave (``NeuronSweep``), for
``--duration-s`` at dt 0.1 ms. Measured in one run and printed side by side, in neuron-steps
per second (points × steps / wall time):

- ``sweep/<engine>``: ``run_sweep`` in this process (store writes included); the standalone
  engine's one-off compile is timed separately and excluded from its rate (it is cached on
  disk and paid once per worker process, not per chunk);
- ``naive loop``: one ``neurons.simulate`` call (one Brian2 run, numpy target) per point,
  timed on a sample of points and EXTRAPOLATED to the grid (said so in the table);
- ``numba``: a hand-written Euler kernel of the same equations and input (neuron-outer loop,
  one thread), compile time excluded; its spike counts are compared with Brian2's;
- ``floor64`` / ``floor32``: the best kernel written by hand (``benchmarks/floor.c``, compiled
  at benchmark time with the system ``cc -O3 -march=native -ffast-math``: blocks of 64
  neurons kept in L1 for the whole run, lanes innermost, branch-free, one thread),
  in float64 and float32; spike counts compared with Brian2's; ours / floor printed per size;
- scaling: the largest grid on a Dask LocalCluster of 1, 2, ... worker processes (the
  workers return their blocks; this process writes the store, as on a cluster without a
  shared folder). Each row prints the machine's load average (1 min) before and after it:
  other jobs holding a core lower the 2-worker ratio, and the load says whether they did.

Every row also gives the grid's wall time, so ``--sizes 1000000`` answers "how long does a
10^6-point grid take here".
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from snn_antenna.engine.evaluators import NeuronSweep
from snn_antenna.engine.executor import dask_client
from snn_antenna.engine.grid import Grid
from snn_antenna.engine.sweep import run_sweep
from snn_antenna.networks import neurons


def grid_of(n_points: int) -> Grid:
    """About n_points: k × I × input_hz with 40 frequencies per tuning curve."""
    n_f = 40
    rest = max(1, n_points // n_f)
    n_i = 5 if rest >= 25 else 1
    n_k = max(1, rest // n_i)
    return Grid({"k": {"start": 0.25, "stop": 2.5, "num": n_k, "scale": "log"},
                 "I": {"start": 0.1, "stop": 0.8, "num": n_i} if n_i > 1 else [0.15],
                 "input_hz": {"start": 2, "stop": 60, "num": n_f}})


def numba_kernel():
    import numba

    @numba.njit(cache=True)
    def euler_counts(k, a, b, c, d, f_in, I_amp, v0, u0, n_steps, dt, per_sample, rate,
                     settle_step, p2, p1, p0, v_peak):
        n = k.shape[0]
        counts = np.zeros(n, np.int64)
        for i in range(n):
            v, u, count = v0[i], u0[i], 0
            for step in range(n_steps):
                half = math.floor((2.0 * f_in[i]) * ((step // per_sample) / rate))
                I = I_amp[i] if half % 2 == 0 else -I_amp[i]
                dv = k[i] * (p2 * v * v + p1 * v + p0 - u + I)
                du = a[i] * k[i] * (b[i] * v - u)
                v += dt * dv
                u += dt * du
                if v >= v_peak:
                    v = c[i]
                    u += d[i]
                    if step >= settle_step:
                        count += 1
            counts[i] = count
        return counts

    return euler_counts


FLOOR_C = Path(__file__).with_name("floor.c")
FLOOR_FLAGS = ["-O3", "-march=native", "-ffast-math", "-shared", "-fPIC"]
FLOORS = {"floor64": "floor_counts_f64", "floor32": "floor_counts_f32"}


def floor_kernels(build_dir: Path) -> dict:
    """The honest floor (``benchmarks/floor.c``): the same Euler equations and input written
    by hand for the machine (blocks of 64 neurons kept in L1 for the whole run, lanes
    innermost, branch-free threshold and reset, the input's sign once per input sample),
    compiled now with the system compiler (``cc -O3 -march=native -ffast-math``) and called
    through ctypes on one thread, in float64 and float32."""
    import ctypes
    import shutil
    import subprocess

    cc = os.environ.get("CC") or shutil.which("cc")
    if cc is None:
        raise SystemExit("bench_sweep: no C compiler (cc) for the floor kernels; set CC")
    library = build_dir / "floor.so"
    subprocess.run([cc, *FLOOR_FLAGS, str(FLOOR_C), "-o", str(library)], check=True)
    lib = ctypes.CDLL(str(library))
    f64 = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")
    i32 = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
    i64, dbl = ctypes.c_int64, ctypes.c_double
    kernels = {}
    for name, symbol in FLOORS.items():
        fn = getattr(lib, symbol)
        fn.restype = None
        fn.argtypes = [f64] * 9 + [i64, i64, dbl, i64, dbl, i64, dbl, dbl, dbl, dbl, i32]

        def kernel(k, a, b, c, d, f_in, I_amp, v0, u0, n_steps, dt, per_sample, rate,
                   settle_step, p2, p1, p0, v_peak, fn=fn):
            arrays = [np.ascontiguousarray(x, dtype=np.float64)
                      for x in (k, a, b, c, d, f_in, I_amp, v0, u0)]
            counts = np.zeros(len(arrays[0]), np.int32)
            fn(*arrays, len(counts), n_steps, dt, per_sample, rate, settle_step,
               p2, p1, p0, v_peak, counts)
            return counts

        kernels[name] = kernel
    return kernels


def run_kernel(kernel, sweep: NeuronSweep, points):
    p = sweep.parameters(points)
    v0, u0 = sweep.initial_state(p)
    p2, p1, p0 = neurons.PRESETS[sweep.preset].quadratic
    n_steps = int(round(sweep.duration_s * 1000 / sweep.dt_ms))
    per_sample = int(round(1000 / sweep.input_rate_hz / sweep.dt_ms))
    settle_step = int(math.ceil(sweep.settle_s * 1000 / sweep.dt_ms - 1e-9))
    return kernel(p["k"], p["a"], p["b"], p["c"], p["d"], p["input_hz"], p["I"], v0, u0,
                  n_steps, sweep.dt_ms, per_sample, sweep.input_rate_hz, settle_step,
                  p2, p1, p0, neurons.V_PEAK)


def naive_seconds_per_point(sweep: NeuronSweep, points, sample: int) -> float:
    """One Brian2 run per point (numpy target), on ``sample`` points spread over the grid."""
    from snn_antenna.sources.stimuli import square

    n = len(points["k"])
    idx = np.linspace(0, n - 1, sample).astype(int)
    p = sweep.parameters(points)
    t0 = time.perf_counter()
    for i in idx:
        current = square(p["input_hz"][i], sweep.duration_s, sweep.input_rate_hz,
                         amplitude=p["I"][i]).samples
        neurons.simulate(sweep.preset, current, sweep.dt_ms, k=p["k"][i],
                         input_dt_ms=1000 / sweep.input_rate_hz, target="numpy",
                         b=p["b"][i])
    return (time.perf_counter() - t0) / sample


def load() -> float:
    """The machine's 1-minute load average: runnable processes, ours included."""
    return os.getloadavg()[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10_000, 100_000])
    ap.add_argument("--duration-s", type=float, default=1.0)
    ap.add_argument("--chunk-points", type=int, default=10_000)
    ap.add_argument("--runtime-max", type=int, default=10_000,
                    help="largest grid also run with the cython and numpy runtime engines")
    ap.add_argument("--naive-sample", type=int, default=5)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args(argv)

    base = NeuronSweep(duration_s=args.duration_s, settle_s=min(0.25, args.duration_s / 4))
    steps = int(round(base.duration_s * 1000 / base.dt_ms))
    tmp = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    print(f"# {os.cpu_count()} CPU cores, load average {os.getloadavg()[0]:.1f}; "
          f"{base.duration_s:g} s per point at dt {base.dt_ms:g} ms = {steps:,} steps")
    kernel = numba_kernel()
    run_kernel(kernel, base, grid_of(40).points())  # compile outside the timings
    floors = floor_kernels(tmp)
    for floor in floors.values():
        run_kernel(floor, base, grid_of(40).points())

    chunk = args.chunk_points
    rows = []
    for size in args.sizes:
        grid = grid_of(size)
        n = grid.size
        points = grid.points()
        work = n * steps
        row = {"points": n, "neuron_steps": work}
        engines = ["standalone"] + (["cython", "numpy"] if n <= args.runtime_max else [])
        counts = {}
        first_block = Grid({d: grid.axes[d][r] for d, r in grid.blocks(chunk)[0].items()})
        for engine in engines:
            sweep = dataclasses.replace(base, engine=engine)
            # warm-up on the first chunk: compiles (standalone, cython) outside the timing
            run_sweep(first_block, sweep, tmp / f"warm-{engine}-{n}.zarr", NeuronSweep.OUTPUTS,
                      chunk_points=chunk, progress=False)
            t0 = time.perf_counter()
            out = run_sweep(grid, sweep, tmp / f"{engine}-{n}.zarr", NeuronSweep.OUTPUTS,
                            chunk_points=chunk, progress=False)
            row[f"{engine}_s"] = time.perf_counter() - t0
            row[engine] = work / row[f"{engine}_s"]
            counts[engine] = out.data.spike_count.values.ravel()
        t0 = time.perf_counter()
        numba_counts = run_kernel(kernel, base, points)
        row["numba"] = work / (time.perf_counter() - t0)
        diff = np.abs(numba_counts - counts["standalone"])
        row["max_count_diff_numba"] = int(diff.max())
        row["same_count_numba"] = float(np.mean(diff == 0))
        for name, floor in floors.items():
            t0 = time.perf_counter()
            floor_counts = run_kernel(floor, base, points)
            row[name] = work / (time.perf_counter() - t0)
            diff = np.abs(floor_counts - counts["standalone"])
            row[f"max_count_diff_{name}"] = int(diff.max())
            row[f"same_count_{name}"] = float(np.mean(diff == 0))
        row["naive"] = steps / naive_seconds_per_point(base, points, args.naive_sample)
        rows.append(row)
        print(f"  {n:>9,} points: standalone {row['standalone']:.3g}, numba {row['numba']:.3g}, "
              f"naive {row['naive']:.3g} neuron-steps/s; the grid took "
              f"{row['standalone_s']:.1f} s on one core (standalone, compile excluded; "
              f"load average {load():.1f})", flush=True)

    print("\n## throughput (neuron-steps per second) and ratios, measured in this run")
    print(f"{'points':>8} {'standalone':>11} {'cython':>9} {'numpy':>9} {'numba':>9} "
          f"{'naive*':>9} {'sa/naive':>9} {'sa/numba':>9} {'numba=sa counts':>16} {'max |Δ|':>8}")
    for r in rows:
        def fmt(key):
            return f"{r[key]:.3g}" if key in r else "-"
        print(f"{r['points']:>8,} {fmt('standalone'):>11} {fmt('cython'):>9} {fmt('numpy'):>9} "
              f"{fmt('numba'):>9} {fmt('naive'):>9} {r['standalone'] / r['naive']:>8.0f}x "
              f"{r['standalone'] / r['numba']:>8.2f}x {r['same_count_numba'] * 100:>15.1f}% "
              f"{r['max_count_diff_numba']:>8}")
    print(f"* naive: one neurons.simulate (Brian2 numpy) run per point, {args.naive_sample} "
          "points timed and extrapolated to the grid")
    print("  sweep engines run in this process (one core) after a warm-up chunk: the one-off "
          "compiles (standalone, cython) are excluded; store writes are included")

    print("\n## the floor: hand-written blocked C kernels (benchmarks/floor.c, cc "
          f"{' '.join(FLOOR_FLAGS[:3])}; blocks of 64 neurons in L1, lanes innermost, "
          "branch-free; one core)")
    print(f"{'points':>8} {'floor f64':>10} {'floor f32':>10} {'sa/floor64':>11} "
          f"{'floor64=sa counts':>18} {'max |Δ|':>8} {'floor32=sa counts':>18} {'max |Δ|':>8}")
    for r in rows:
        print(f"{r['points']:>8,} {r['floor64']:>10.3g} {r['floor32']:>10.3g} "
              f"{r['floor64'] / r['standalone']:>10.2f}x "
              f"{r['same_count_floor64'] * 100:>17.1f}% {r['max_count_diff_floor64']:>8} "
              f"{r['same_count_floor32'] * 100:>17.1f}% {r['max_count_diff_floor32']:>8}")
    print("  sa/floor64: how many times slower the standalone engine (float64) is than the "
          "float64 floor (ours / floor, in time)")

    if args.workers:
        grid = grid_of(max(args.sizes))
        work = grid.size * steps
        print(f"\n## scaling with Dask worker processes ({grid.size:,} points, standalone; "
              "timed on a second run: cluster start and each worker's compile excluded; "
              f"{os.cpu_count()} cores, load average = runnable processes, 1 min)")
        first = None
        for w in args.workers:
            with dask_client(workers=w) as client:
                for attempt in ("warm-up", "timed"):
                    before = load()
                    t0 = time.perf_counter()
                    run_sweep(grid, base, tmp / f"dask-{w}.zarr", NeuronSweep.OUTPUTS,
                              chunk_points=chunk, client=client, progress=False, fresh=True)
                    seconds = time.perf_counter() - t0
            rate = work / seconds
            first = first or rate
            print(f"  {w} worker(s): {rate:.3g} neuron-steps/s, {rate / first:.2f}x of 1 worker, "
                  f"{seconds:.1f} s for the grid; load average {before:.1f} before, "
                  f"{load():.1f} after", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
