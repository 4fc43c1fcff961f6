"""``parallel_map``: a list of independent calls on a few local processes, in order, with a
progress bar. For grids of points (chunked, resumable, on a Dask cluster) use
``snn_antenna.engine.sweep`` instead."""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from collections.abc import Callable, Iterable


def _star(args):
    fn, a = args
    return fn(*a)


def parallel_map(fn: Callable, args: Iterable[tuple], n_jobs: int = 1, desc: str = "",
                 total: int | None = None) -> list:
    """``[fn(*a) for a in args]`` in order, on ``n_jobs`` processes, with a progress bar."""
    from tqdm.auto import tqdm

    args = list(args)
    bar = tqdm(total=total or len(args), desc=desc, unit="block", leave=False)
    try:
        if n_jobs == 1:
            out = []
            for a in args:
                out.append(fn(*a))
                bar.update()
            return out
        with ProcessPoolExecutor(n_jobs) as pool:
            out = []
            for res in pool.map(_star, [(fn, a) for a in args]):
                out.append(res)
                bar.update()
            return out
    finally:
        bar.close()
