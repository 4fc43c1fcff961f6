"""Sweep throughput: the Brian2 sweep engine against the hand-written floor, runtime engines,
a naive per-point loop and a numba kernel.

    python benchmarks/bench_sweep.py                 # 10^3, 10^4, 10^5 points
    python benchmarks/bench_sweep.py --sizes 1000 --workers 1 2 --duration-s 0.5
    python benchmarks/bench_sweep.py --sizes 1000000 --runtime-max 0 --naive-sample 1
                                                     # the 10^6-point grid, and on 2 Dask workers

Every grid point is one resonator driven by the coder's square wave (``NeuronSweep``), for
``--duration-s`` at dt 0.1 ms. The grids sweep k, I and input_hz (``--sweep-b``: b too, a k/b/I
tuning grid); the engine keeps what a grid does not sweep as one shared value, the floor reads
every parameter per point (it keeps its blocks in L1, where that costs nothing). Measured in one
run and printed side by side, in neuron-steps per second (points × steps / wall time):

- ``standalone`` / ``standalone32``: ``run_sweep`` with the compiled engine in float64 and
  float32, in this process (store writes included), after a warm-up chunk (the one-off
  compile is cached on disk and paid once per worker process, not per chunk);
- ``floor64`` / ``floor32``: the best kernel written by hand (``benchmarks/floor.c``, compiled
  at benchmark time with the system ``cc -O3 -march=native -ffast-math``: blocks of 64
  neurons kept in L1 for the whole run, lanes innermost, branch-free, one thread). The
  engines and the floors are timed ``--repeat`` times, interleaved, and ours / floor is
  printed per size and precision as median [min–max] of the per-repetition ratios, with
  how far their spike counts agree; float32's counts are compared with float64's;
- ``cython`` / ``numpy``: the runtime engines (grids up to ``--runtime-max`` points);
- ``naive loop``: one ``neurons.simulate`` call (one Brian2 run, numpy target) per point,
  timed on a sample of points and EXTRAPOLATED to the grid (said so in the table);
- ``numba``: a plain Euler kernel (neuron-outer loop, one thread), compile time excluded;
- scaling: the largest grid on a Dask LocalCluster of 1, 2, ... worker processes, in both
  precisions (the workers return their blocks; this process writes the store, as on a
  cluster without a shared folder). Each row prints the machine's load average (1 min)
  before and after it: other jobs holding a core lower the 2-worker ratio, and the load
  says whether they did.

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
from snn_antenna.report.results import write_benchmark_json


def grid_of(n_points: int, sweep_b: bool = False) -> Grid:
    """About n_points: k × I × input_hz with 40 frequencies per tuning curve (and 5 values
    of b with ``sweep_b``: a k/b/I tuning grid, where b is one more array per point)."""
    n_f, n_b = 40, 5 if sweep_b else 1
    rest = max(1, n_points // (n_f * n_b))
    n_i = 5 if rest >= 25 else 1
    n_k = max(1, rest // n_i)
    axes = {"k": {"start": 0.25, "stop": 2.5, "num": n_k, "scale": "log"},
            "I": {"start": 0.1, "stop": 0.8, "num": n_i} if n_i > 1 else [0.15],
            "input_hz": {"start": 2, "stop": 60, "num": n_f}}
    if sweep_b:
        axes["b"] = {"start": 0.2, "stop": 0.26, "num": n_b}
    return Grid(axes)


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
FLOOR_FLAGS = ["-O3", "-march=native", "-ffast-math"]


def build_for(march: str) -> None:
    """Compile the floor and Brian2's code (engine and runtime targets, in this process) for
    gcc's ``-march=MARCH`` in place of ``native``: ``haswell`` gives an AVX2-only build (16
    vector registers, no AVX-512) on an AVX-512 machine, so one machine measures both."""
    from brian2 import prefs

    flag = f"-march={march}"
    FLOOR_FLAGS[:] = [flag if f.startswith("-march=") else f for f in FLOOR_FLAGS]
    prefs.codegen.cpp.extra_compile_args_gcc = [
        flag if f.startswith("-march=") else f for f in prefs.codegen.cpp.extra_compile_args_gcc]
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
    # compiled with -ffast-math, linked without: linking with it would add crtfastmath.o, which
    # sets flush-to-zero for this whole process (numpy and Brian2 included) when it loads
    subprocess.run([cc, *FLOOR_FLAGS, "-fPIC", "-c", str(FLOOR_C), "-o",
                    str(build_dir / "floor.o")], check=True)
    subprocess.run([cc, "-shared", str(build_dir / "floor.o"), "-o", str(library)], check=True)
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


def counts_agree(a: np.ndarray, b: np.ndarray) -> str:
    """How far two engines' spike counts are apart: the share of points with equal counts,
    and the largest difference."""
    diff = np.abs(np.asarray(a, np.int64) - np.asarray(b, np.int64))
    return f"{np.mean(diff == 0) * 100:.1f}% same, max |Δ| {int(diff.max())}"


def spread(values) -> str:
    """Median [min–max] of repeated measurements."""
    v = np.asarray(values, float)
    return f"{np.median(v):.2f} [{v.min():.2f}–{v.max():.2f}]"


PRECISIONS = {"standalone": ("float64", "floor64"), "standalone32": ("float32", "floor32")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10_000, 100_000])
    ap.add_argument("--duration-s", type=float, default=1.0)
    ap.add_argument("--chunk-points", type=int, default=100_000,
                    help="points per chunk (one run of the compiled project; each run has "
                         "a fixed cost of tens of ms, so large chunks amortise it)")
    ap.add_argument("--repeat", type=int, default=3,
                    help="timings of the standalone engines and the floors, interleaved")
    ap.add_argument("--runtime-max", type=int, default=10_000,
                    help="largest grid also run with the cython and numpy runtime engines")
    ap.add_argument("--naive-sample", type=int, default=5)
    ap.add_argument("--sweep-b", action="store_true",
                    help="grids over k, b, I and input_hz (b per point), not k, I and input_hz")
    ap.add_argument("--workers", type=int, nargs="*", default=[1, 2],
                    help="Dask worker counts of the scaling rows (none: no scaling rows)")
    ap.add_argument("--march", default="native",
                    help="gcc -march of both the engine and the floor (e.g. haswell: an AVX2 "
                         "build on an AVX-512 machine); this process only, so no scaling rows")
    ap.add_argument("--json", metavar="PATH",
                    help="also write the measured values and their provenance as JSON "
                         "(for snn-antenna results)")
    args = ap.parse_args(argv)
    if args.march != "native":
        if args.workers:
            ap.error("--march other than native builds in this process only: add --workers "
                     "with no count (Dask workers would compile for the machine)")
        build_for(args.march)

    base = NeuronSweep(duration_s=args.duration_s, settle_s=min(0.25, args.duration_s / 4))
    steps = int(round(base.duration_s * 1000 / base.dt_ms))
    tmp = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    print(f"# {os.cpu_count()} CPU cores, load average {load():.1f}; "
          f"{base.duration_s:g} s per point at dt {base.dt_ms:g} ms = {steps:,} steps; "
          f"engine and floor compiled with -march={args.march}")
    kernel = numba_kernel()
    run_kernel(kernel, base, grid_of(40).points())  # compile outside the timings
    floors = floor_kernels(tmp)
    for floor in floors.values():
        run_kernel(floor, base, grid_of(40).points())
    sweeps = {"standalone": base, "standalone32": dataclasses.replace(base, dtype="float32"),
              "cython": dataclasses.replace(base, engine="cython"),
              "numpy": dataclasses.replace(base, engine="numpy")}

    chunk = args.chunk_points
    rows = []
    for size in args.sizes:
        grid = grid_of(size, args.sweep_b)
        n = grid.size
        points = grid.points()
        work = n * steps
        row = {"points": n, "neuron_steps": work, "load_before": load()}
        counts, seconds = {}, {}
        first_block = Grid({d: grid.axes[d][r] for d, r in grid.blocks(chunk)[0].items()})

        def sweep_seconds(name, first_block=first_block, grid=grid, n=n, counts=counts):
            # warm-up on the first chunk: compiles (standalone, cython) outside the timing
            run_sweep(first_block, sweeps[name], tmp / f"warm-{name}-{n}.zarr",
                      NeuronSweep.OUTPUTS, chunk_points=chunk, progress=False, fresh=True)
            t0 = time.perf_counter()
            out = run_sweep(grid, sweeps[name], tmp / f"{name}-{n}.zarr", NeuronSweep.OUTPUTS,
                            chunk_points=chunk, progress=False, fresh=True)
            counts[name] = out.data.spike_count.values.ravel()
            return time.perf_counter() - t0

        def floor_seconds(name, counts=counts, points=points):
            t0 = time.perf_counter()
            counts[name] = run_kernel(floors[name], base, points)
            return time.perf_counter() - t0

        for _ in range(args.repeat):   # interleaved: a load change hits both sides of a ratio
            for name, (_, floor) in PRECISIONS.items():
                seconds.setdefault(name, []).append(sweep_seconds(name))
                seconds.setdefault(floor, []).append(floor_seconds(floor))
        for name, (_, floor) in PRECISIONS.items():
            row[name] = work / np.median(seconds[name])
            row[f"{name}_s"] = float(np.median(seconds[name]))
            row[floor] = work / np.median(seconds[floor])
            row[f"{name}/{floor}"] = [a / b for a, b in zip(seconds[name], seconds[floor])]
            row[f"{floor} counts"] = counts_agree(counts[floor], counts[name])
        row["float32 counts"] = counts_agree(counts["standalone32"], counts["standalone"])
        if n <= args.runtime_max:
            for name in ("cython", "numpy"):
                row[name] = work / sweep_seconds(name)
        t0 = time.perf_counter()
        numba_counts = run_kernel(kernel, base, points)
        row["numba"] = work / (time.perf_counter() - t0)
        row["numba counts"] = counts_agree(numba_counts, counts["standalone"])
        row["naive"] = steps / naive_seconds_per_point(base, points, args.naive_sample)
        row["load_after"] = load()
        rows.append(row)
        print(f"  {n:>9,} points: standalone {row['standalone']:.3g} (float64), "
              f"{row['standalone32']:.3g} (float32) neuron-steps/s; the grid took "
              f"{row['standalone_s']:.1f} s / {row['standalone32_s']:.1f} s on one core "
              f"(median of {args.repeat}, compile excluded; load average "
              f"{row['load_before']:.1f} before, {row['load_after']:.1f} after)", flush=True)

    print("\n## throughput (neuron-steps per second) and ratios, measured in this run")
    print(f"{'points':>9} {'standalone':>11} {'cython':>9} {'numpy':>9} {'numba':>9} "
          f"{'naive*':>9} {'sa/naive':>9} {'sa/numba':>9}  numba vs standalone counts")
    for r in rows:
        def fmt(key, r=r):
            return f"{r[key]:.3g}" if key in r else "-"
        print(f"{r['points']:>9,} {fmt('standalone'):>11} {fmt('cython'):>9} {fmt('numpy'):>9} "
              f"{fmt('numba'):>9} {fmt('naive'):>9} {r['standalone'] / r['naive']:>8.0f}x "
              f"{r['standalone'] / r['numba']:>8.2f}x  {r['numba counts']}")
    print(f"* naive: one neurons.simulate (Brian2 numpy) run per point, {args.naive_sample} "
          "points timed and extrapolated to the grid")
    print("  sweep engines run in this process (one core) after a warm-up chunk: the one-off "
          "compiles (standalone, cython) are excluded; store writes are included")

    print("\n## the floor: hand-written blocked C kernels (benchmarks/floor.c, cc "
          f"{' '.join(FLOOR_FLAGS)}; blocks of 64 neurons in L1, lanes innermost, "
          "branch-free; one core)")
    print(f"{'points':>9} {'prec.':>7} {'standalone':>11} {'floor':>9} "
          f"{'ours/floor (time), median [min–max]':>36}  floor vs standalone counts")
    for r in rows:
        for name, (dtype, floor) in PRECISIONS.items():
            print(f"{r['points']:>9,} {dtype:>7} {r[name]:>11.3g} {r[floor]:>9.3g} "
                  f"{spread(r[f'{name}/{floor}']):>36}  {r[f'{floor} counts']}")
    print(f"  {args.repeat} interleaved timings per engine; the ratio is taken within each "
          "repetition. Counts differ at rounding-sensitive points (fast-math: fused "
          "multiply-adds and order differ between compilations)")
    print("\n## float32 against float64 (the standalone engine, same grid)")
    for r in rows:
        print(f"{r['points']:>9,} points: {r['float32 counts']}; float32 "
              f"{r['standalone32'] / r['standalone']:.2f}x the float64 throughput")

    scaling = []
    if args.workers:
        grid = grid_of(max(args.sizes), args.sweep_b)
        work = grid.size * steps
        print(f"\n## scaling with Dask worker processes ({grid.size:,} points, standalone; "
              "timed on a second run: cluster start and each worker's compile excluded; "
              f"{os.cpu_count()} cores, load average = runnable processes, 1 min)")
        for name, (dtype, _) in PRECISIONS.items():
            first = None
            for w in args.workers:
                with dask_client(workers=w) as client:
                    for _attempt in ("warm-up", "timed"):
                        before = load()
                        t0 = time.perf_counter()
                        run_sweep(grid, sweeps[name], tmp / f"dask-{name}-{w}.zarr",
                                  NeuronSweep.OUTPUTS, chunk_points=chunk, client=client,
                                  progress=False, fresh=True)
                        seconds = time.perf_counter() - t0
                rate = work / seconds
                first = first or rate
                print(f"  {dtype}, {w} worker(s): {rate:.3g} neuron-steps/s, "
                      f"{rate / first:.2f}x of 1 worker, {seconds:.1f} s for the grid; load "
                      f"average {before:.1f} before, {load():.1f} after", flush=True)
                scaling.append({"precision": dtype, "workers": w, "points": grid.size,
                                "neuron_steps_per_s": rate, "of_first": rate / first,
                                "seconds": seconds, "load_before": before})
    if args.json:
        shown = {}   # per grid: throughputs (neuron-steps/s) and the ratios to the C floor
        for r in rows:
            shown[f"{r['points']} points"] = {
                **{k: r[k] for k in ("standalone", "standalone32", "floor64", "floor32",
                                     "cython", "numpy", "numba", "naive") if k in r},
                "standalone/floor64": float(np.median(r["standalone/floor64"])),
                "standalone32/floor32": float(np.median(r["standalone32/floor32"])),
                "float32 counts": r["float32 counts"],
                "load_before": r["load_before"], "load_after": r["load_after"]}
        write_benchmark_json(args.json, {
            "cpus": os.cpu_count(), "duration_s": base.duration_s, "dt_ms": base.dt_ms,
            "repeat": args.repeat, "per_grid": shown, "scaling": scaling})
    return 0


if __name__ == "__main__":
    sys.exit(main())
