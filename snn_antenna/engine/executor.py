"""Where a sweep runs: this process, an embedded local Dask cluster, or a running scheduler.

``dask_client(workers, scheduler)``: a context manager; ``scheduler="tcp://HOST:PORT"``
attaches to an existing cluster, otherwise a LocalCluster of worker *processes* (Brian2 holds
the GIL) is started and closed again. Workers never open the store: a cluster spanning
machines needs no shared folder, only the snn_antenna package on every worker.
``prepare_workers`` makes a cluster's workers fit to run Brian2.
"""
from __future__ import annotations

import functools
import os
from contextlib import contextmanager

from ..core.errors import SpecError, check
from .cost import max_workers


def prepare_workers(client) -> None:
    """Make ``client``'s workers (current and future) fit to run Brian2 (``_PrepareWorker``).
    Call it before submitting any Brian2 task; registering again is harmless."""
    client.register_plugin(_prepare_worker_class()(), name="snn-antenna-prepare-worker")


@functools.cache
def _prepare_worker_class():
    # Defined on first use: importing distributed costs half a second, which a refusal of a
    # bad spec (this module is imported to size the grid) should not pay. Pickled by
    # reference through the module's __getattr__ below, as a module-level class would be.
    from distributed.diagnostics.plugin import WorkerPlugin

    class _PrepareWorker(WorkerPlugin):
        """Worker plugin, run in each worker's main thread (restarted workers too, and the workers
        of a cluster given by ``--scheduler``):

        - import Brian2 there, where it may install its SIGINT handler (importing it first inside
          a task thread fails);
        - stop Dask's statistical profiler, which deadlocks workers: every 10 ms it calls
          ``sys._current_frames()``, which holds the interpreter's thread-list lock while it
          allocates; a garbage collection there runs Brian2's weakref callbacks, and a task thread
          starting a thread then waits forever (seen when workers still wrote their chunks:
          one stuck in zarr's I/O pool's ``Thread.start`` with its main thread in Brian2's
          ``InstanceTrackerSet.remove`` under ``Worker.trigger_profile``; the sweep hung).
        """

        def setup(self, worker):
            import brian2  # noqa: F401

            for name in ("profile", "profile-cycle"):
                callback = worker.periodic_callbacks.pop(name, None)
                if callback is not None:
                    callback.stop()

    _PrepareWorker.__module__, _PrepareWorker.__qualname__ = __name__, "_PrepareWorker"
    return _PrepareWorker


def __getattr__(name):
    if name == "_PrepareWorker":
        return _prepare_worker_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


SCHEDULER_PROBE_S = 8.0


def _probe_scheduler(address: str, timeout_s: float = SCHEDULER_PROBE_S) -> None:
    """Ask ``address`` who it is, within ``timeout_s``, before a Client waits on it: a silent
    port would hold the Client for minutes, and one that speaks first (an SSH or HTTP banner)
    is read by Dask as a frame length of exabytes."""
    import asyncio

    from distributed.comm import connect

    async def identity():
        comm = await connect(address, timeout=timeout_s)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    accepted = "the address of a running Dask scheduler"
    try:
        reply = asyncio.run(asyncio.wait_for(identity(), timeout_s))
    except (asyncio.TimeoutError, TimeoutError):
        raise SpecError("--scheduler", address, f"{accepted} (no answer within "
                        f"{timeout_s:g} s: not a Dask scheduler)") from None
    except Exception as exc:        # refused, reset, or bytes that are not Dask's protocol
        raise SpecError("--scheduler", address,
                        f"{accepted} ({type(exc).__name__}: {str(exc)[:120]})") from None
    if not (isinstance(reply, dict) and reply.get("type") == "Scheduler"):
        raise SpecError("--scheduler", address,
                        f"{accepted} (it answered as {str(reply)[:80]!r})")


@contextmanager
def dask_client(workers: int = 0, scheduler: str | None = None, quiet: bool = True):
    """A Dask client: attach to ``scheduler`` (tcp://HOST:PORT) or start a local cluster.

    The local cluster runs ``workers`` processes (0: one per CPU core) of one thread each:
    Brian2 holds the GIL, so threads would not run chunks in parallel.
    """
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        check(isinstance(scheduler, str) and "://" in scheduler, "--scheduler", scheduler,
              "a Dask scheduler address such as tcp://HOST:8786")
        _probe_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise SpecError("--scheduler", scheduler,
                            f"the address of a running Dask scheduler ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    check(isinstance(workers, int) and not isinstance(workers, bool) and workers >= 0,
          "sweep.workers", workers, "an integer >= 0 (0: one per core)")
    # Never more processes than the machine has cores and memory for (500 workers on 2
    # cores took ~10 GB in a minute and ran no faster).
    n = min(workers or os.cpu_count() or 1, max_workers())
    # No dashboard; the scheduler's HTTP server (health routes) on a free port: on its default,
    # 8787, two clusters at once (two sweeps, parallel tests) warned "already in use".
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address=None,
                           scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
                           silence_logs=logging.ERROR if quiet else logging.WARNING)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


@contextmanager
def executor(workers: int = 0, scheduler: str | None = None, log=None):
    """Where a study's sweep runs: ``None`` (this process, for ``run_sweep(client=None)``)
    when ``workers == 1`` and no scheduler is given, otherwise a ``dask_client``."""
    if scheduler is None and workers == 1:
        yield None
        return
    with dask_client(workers, scheduler) as client:
        if log is not None:
            log(f"      Dask: {len(client.scheduler_info()['workers'])} worker(s) at "
                f"{client.scheduler.address}")
        yield client
