"""A sweep on a Dask cluster that shares no folder with the client.

A ``dask scheduler`` and a ``dask worker`` run as separate processes, each in its own working
directory (as on other machines), on 127.0.0.1. The worker is additionally forbidden to
write any zarr store (its store functions raise), as a worker on another machine could not
reach the client's disk: the results must travel back to the client, which alone writes
them.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.engine.evaluators import NeuronSweep
from snn_antenna.engine.grid import Grid
from snn_antenna.engine.sweep import run_sweep
from snn_antenna.core.errors import NumericalInstabilityError, SpecError
from snn_antenna.core.store import Output, SweepStore

REPO = Path(__file__).resolve().parents[1]
FAST = NeuronSweep(duration_s=0.4, settle_s=0.1, engine="numpy")
GRID = {"k": [0.5, 1.0], "I": [0.15, 0.5], "input_hz": [6.0, 10.0, 14.0, 18.0, 22.0, 26.0]}
START_TIMEOUT_S = 60


def _no_store_on_this_machine():
    """Run on the worker: any attempt to write a zarr store fails, as it would on a machine
    that cannot see the client's folder."""
    import xarray as xr
    import zarr

    from snn_antenna.core import store

    def refuse(*args, **kwargs):
        raise OSError("this worker has no access to the client's disk")

    store.SweepStore.write_chunk = refuse
    store.SweepStore.prepare = refuse
    xr.Dataset.to_zarr = refuse
    zarr.open_array = refuse
    zarr.open_group = refuse
    return os.getcwd()


def _wait_for(path: Path, proc: subprocess.Popen, what: str) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while not path.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{what} did not start: "
                               f"{proc.stderr.read() if proc.poll() else ''}")
        time.sleep(0.1)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture(scope="module")
def remote(tmp_path_factory):
    """(client, worker_dir, client_dir): one scheduler and one single-threaded worker."""
    from distributed import Client

    root = tmp_path_factory.mktemp("cluster")
    scheduler_dir, worker_dir, client_dir = (root / d for d in ("scheduler", "worker", "client"))
    for d in (scheduler_dir, worker_dir, client_dir):
        d.mkdir()
    scheduler_file = scheduler_dir / "scheduler.json"
    # the worker imports snn_antenna (and this module, for its test evaluators) by path, as
    # a worker machine with the package installed would
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tests")])}
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
         "--no-dashboard", "--scheduler-file", str(scheduler_file)],
        cwd=scheduler_dir, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        text=True)
    processes = [scheduler]
    client = None
    try:
        _wait_for(scheduler_file, scheduler, "dask scheduler")
        address = json.loads(scheduler_file.read_text())["address"]
        worker = subprocess.Popen(
            [sys.executable, "-m", "dask", "worker", address, "--host", "127.0.0.1",
             "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
             "--local-directory", str(worker_dir / "scratch")],
            cwd=worker_dir, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        processes.append(worker)
        client = Client(address, timeout="30s")
        client.wait_for_workers(1, timeout=START_TIMEOUT_S)
        cwds = set(client.run(_no_store_on_this_machine).values())
        assert cwds == {str(worker_dir)}, "the worker runs in its own directory"
        yield client, worker_dir, client_dir
    finally:
        if client is not None:
            client.close()
        for proc in reversed(processes):
            _stop(proc)


def _store_files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.suffix == ".zarr" or p.name in
            ("zarr.json", "chunk_done", ".zarray", ".zgroup")]


def test_a_worker_in_another_directory_sends_results_the_client_stores(remote):
    client, worker_dir, client_dir = remote
    grid = Grid(GRID)
    serial = run_sweep(grid, FAST, client_dir / "serial.zarr", NeuronSweep.OUTPUTS,
                       chunk_points=6, progress=False)
    path = client_dir / "remote.zarr"
    out = run_sweep(grid, FAST, path, NeuronSweep.OUTPUTS, chunk_points=6, client=client,
                    progress=False)
    assert out.chunks_computed == list(range(out.chunks_total)) and out.chunks_total == 4
    assert all(str(os.getpid()) not in who for who in out.workers)  # computed elsewhere
    assert sum(out.workers.values()) == out.chunks_total
    assert out.data.spike_count.equals(serial.data.spike_count)
    assert out.data.rate_hz.equals(serial.data.rate_hz)
    assert serial.data.spike_count.values.sum() > 0
    assert SweepStore(path).done_chunks() == set(range(4))
    assert _store_files(worker_dir) == []  # nothing landed where the worker runs
    # resume on the cluster: an unfinished chunk is redone there, the others are skipped
    import zarr
    zarr.open_array(path / "chunk_done", mode="r+")[2] = 0
    zarr.open_array(path / "spike_count", mode="r+")[1, 0, :] = -1
    again = run_sweep(grid, FAST, path, NeuronSweep.OUTPUTS, chunk_points=6, client=client,
                      progress=False)
    assert again.chunks_computed == [2] and again.chunks_skipped == [0, 1, 3]
    assert again.data.spike_count.equals(serial.data.spike_count)


# -- errors raised on the worker reach the client intact ------------------------------------------
OUTS = {"y": Output("f8")}


def unstable_at_three(points):
    """x² except that x == 3 'runs away' (as a neuron past its stable step does)."""
    x = points["x"]
    if np.any(x == 3.0):
        raise NumericalInstabilityError(neuron=int(np.argmax(x == 3.0)), params={"k": 3.0},
                                        dt_ms=0.1, method="euler", t_ms=12.5, safe_dt_ms=0.05)
    return {"y": x ** 2}


def refuses_negative(points):
    if np.any(points["x"] < 0):
        raise SpecError("axes.x", float(points["x"].min()), "x >= 0")
    return {"y": points["x"] ** 2}


def test_worker_errors_cross_the_process_boundary_and_finished_chunks_stay(remote):
    client, worker_dir, client_dir = remote
    path = client_dir / "unstable.zarr"
    with pytest.raises(NumericalInstabilityError) as err:
        run_sweep(Grid({"x": np.arange(6.0)}), unstable_at_three, path, OUTS, chunk_points=2,
                  client=client, progress=False)
    assert (err.value.neuron, err.value.params, err.value.safe_dt_ms) == (1, {"k": 3.0}, 0.05)
    assert 1 not in SweepStore(path).done_chunks()  # the failed chunk is not marked
    with pytest.raises(SpecError) as err:
        run_sweep(Grid({"x": [-2.0, 1.0]}), refuses_negative, client_dir / "neg.zarr", OUTS,
                  client=client, progress=False)
    assert (err.value.field, err.value.value, err.value.accepted) == ("axes.x", -2.0, "x >= 0")
    assert _store_files(worker_dir) == []


# -- memory stays bounded: only a window of chunks is out at a time -------------------------------
def square(points):
    return {"y": points["x"] ** 2}


class CountingClient:
    """The cluster's client, noting at each submission how many chunks are out (submitted,
    not yet in the store): the blocks a sweep can have waiting in memory."""

    def __init__(self, client, store: SweepStore):
        self._client, self._store, self.submitted, self.out = client, store, 0, []

    def submit(self, *args, **kwargs):
        self.submitted += 1
        done = len(self._store.done_chunks()) if (self._store.path / "chunk_done").exists() else 0
        self.out.append(self.submitted - done)
        return self._client.submit(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._client, name)


def test_only_a_window_of_chunks_is_out_at_a_time(remote):
    client, _, client_dir = remote
    path = client_dir / "window.zarr"
    counting = CountingClient(client, SweepStore(path))
    out = run_sweep(Grid({"x": np.arange(24.0)}), square, path, OUTS, chunk_points=2,
                    client=counting, progress=False)
    assert np.array_equal(out.data.y.values, np.arange(24.0) ** 2)
    assert counting.submitted == 12
    window = 2 * sum(client.nthreads().values())  # one single-threaded worker: 2
    assert max(counting.out) <= window < 12
