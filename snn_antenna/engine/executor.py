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
SCHEDULER_ACCEPTED = "the address of a running Dask scheduler, tcp://HOST:PORT"
# A Dask message starts with its length as a little-endian u64; the scheduler's first message
# (the comm handshake) is a few hundred bytes. Anything beyond this is another protocol's bytes.
DASK_FIRST_MESSAGE_MAX = 1 << 20


def probe_scheduler(address: str | None, timeout_s: float = SCHEDULER_PROBE_S) -> None:
    """Refuse, in one line and within ``timeout_s``, a ``--scheduler`` address that is not a
    running Dask scheduler of this toolkit's ``distributed`` version, naming what is there:
    nothing listening, a server of another protocol (an SSH or HTTP banner, or a silent port),
    or Dask of another version. ``None`` (no scheduler given) passes. Callers run it before
    any output folder is created, and :func:`dask_client` runs it again before attaching."""
    if address is None:
        return
    check(isinstance(address, str) and address.startswith("tcp://"), "--scheduler", address,
          SCHEDULER_ACCEPTED)
    host, _, port = address[len("tcp://"):].rpartition(":")
    host = host.strip("[]")
    check(bool(host) and port.isdigit() and 0 < int(port) < 65536, "--scheduler", address,
          SCHEDULER_ACCEPTED)
    _first_message(address, host, int(port), timeout_s)
    _check_identity(address, timeout_s)


def _refuse(address: str, found: str):
    return SpecError("--scheduler", address, f"{SCHEDULER_ACCEPTED}; {found}")


def _first_message(address: str, host: str, port: int, timeout_s: float) -> None:
    """A Dask scheduler speaks first: its handshake, a length-prefixed message. Read the
    length with a plain socket, so that another protocol's bytes are never taken for one."""
    import socket
    import struct

    try:
        conn = socket.create_connection((host, port), timeout=timeout_s)
    except ConnectionRefusedError:
        raise _refuse(address, f"nothing is listening on {host}:{port} (connection refused)"
                      ) from None
    except socket.gaierror as exc:
        raise _refuse(address, f"the host {host!r} is not known ({exc.strerror})") from None
    except TimeoutError:
        raise _refuse(address, f"no answer from {host}:{port} within {timeout_s:g} s (the host "
                               "is down, or a firewall drops the connection)") from None
    except OSError as exc:
        raise _refuse(address, f"{host}:{port} cannot be reached ({exc.strerror or exc})"
                      ) from None
    head = b""
    try:
        with conn:
            conn.settimeout(timeout_s)
            while len(head) < 8:
                piece = conn.recv(8 - len(head))
                if not piece:
                    break
                head += piece
    except TimeoutError:
        pass
    except OSError as exc:
        raise _refuse(address, f"{host}:{port} dropped the connection ({exc.strerror or exc})"
                      ) from None
    if not head:
        raise _refuse(address, f"a server listens on {host}:{port} but does not speak Dask's "
                               f"protocol (it sent nothing within {timeout_s:g} s)")
    if len(head) < 8:
        raise _refuse(address, f"a server listens on {host}:{port} but does not speak Dask's "
                               f"protocol (it sent {head!r} and closed)")
    (length,) = struct.unpack("<Q", head)
    if not 0 < length <= DASK_FIRST_MESSAGE_MAX:
        raise _refuse(address, f"a server listens on {host}:{port} but speaks another protocol "
                               f"than Dask's (it began with {head!r})")


def _check_identity(address: str, timeout_s: float) -> None:
    """Ask the Dask peer who it is and which ``distributed`` it runs."""
    import asyncio

    import distributed
    from distributed.comm import connect

    async def ask():
        comm = await connect(address, timeout=timeout_s)
        try:
            await comm.write({"op": "identity", "reply": True})
            identity = await comm.read()
            versions = None
            if isinstance(identity, dict) and identity.get("type") == "Scheduler":
                await comm.write({"op": "versions", "reply": True})
                versions = await comm.read()
            return identity, versions
        finally:
            comm.abort()

    try:
        identity, versions = asyncio.run(asyncio.wait_for(ask(), timeout_s))
    except TimeoutError:
        raise _refuse(address, f"a Dask peer that did not say who it is within {timeout_s:g} s"
                      ) from None
    except Exception as exc:        # reset, closed, or a reply that is not Dask's
        raise _refuse(address, f"it does not answer as Dask does ({type(exc).__name__}: "
                               f"{str(exc)[:100]})") from None
    if not (isinstance(identity, dict) and identity.get("type") == "Scheduler"):
        kind = identity.get("type") if isinstance(identity, dict) else str(identity)[:60]
        raise _refuse(address, f"a Dask {kind!s}, not a scheduler")
    packages = versions.get("packages", {}) if isinstance(versions, dict) else {}
    theirs = packages.get("distributed")
    if theirs != distributed.__version__:
        raise _refuse(address, f"a Dask scheduler of distributed {theirs}, while this toolkit "
                               f"runs {distributed.__version__} (install the same version on "
                               "both sides)")


@contextmanager
def dask_client(workers: int = 0, scheduler: str | None = None, quiet: bool = True):
    """A Dask client: attach to ``scheduler`` (tcp://HOST:PORT) or start a local cluster.

    The local cluster runs ``workers`` processes (0: one per CPU core) of one thread each:
    Brian2 holds the GIL, so threads would not run chunks in parallel.
    """
    probe_scheduler(scheduler)          # in seconds, before distributed is even imported
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
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
