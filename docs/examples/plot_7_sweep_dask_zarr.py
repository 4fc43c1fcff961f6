"""
A sweep on Dask into zarr, opened with xarray
=============================================

A grid of named axes is evaluated chunk by chunk on Dask workers into a resumable zarr store;
the result is one xarray ``Dataset``. Here one Brian2 neuron per grid point over k and the
input frequency, on a Dask cluster inside this process with one worker thread (Brian2 runs one
network at a time per process). ``snn_antenna.engine.executor.dask_client(workers=N)`` starts
N worker processes instead, and ``dask_client(scheduler="tcp://HOST:8786")`` attaches to a
cluster of yours; the sweep is the same call.
"""

import tempfile

import brian2  # noqa: F401  (imported in the main thread: Brian2 sets a signal handler then)
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from distributed import Client, LocalCluster

from snn_antenna.engine.evaluators import NeuronSweep
from snn_antenna.engine.grid import Grid
from snn_antenna.engine.sweep import run_sweep

grid = Grid({"k": [0.25, 0.5, 1.0], "input_hz": np.arange(3.0, 30.5, 1.0)})
evaluate = NeuronSweep(duration_s=0.5, engine="numpy")
folder = tempfile.mkdtemp()
with LocalCluster(n_workers=1, threads_per_worker=1, processes=False) as cluster, \
        Client(cluster) as client:
    run_sweep(grid, evaluate, f"{folder}/results.zarr", NeuronSweep.OUTPUTS, client=client,
              chunk_points=28, progress=False)

# %%
# The store is an ordinary zarr store (written chunk by chunk, so its metadata is not
# consolidated): xarray opens it with its coordinates and units.

ds = xr.open_zarr(f"{folder}/results.zarr", consolidated=False)
print(ds)

# %%
# Spikes per input cycle over the grid: each k has its band of input frequencies, and the
# band moves in proportion to k (k = 0.25 near 5 Hz, 0.5 near 10 Hz, 1 near 20 Hz).

per_cycle = ds.spike_count / (ds.input_hz * 0.5)
fig, ax = plt.subplots(figsize=(6, 3.4), layout="constrained")
per_cycle.plot.line(ax=ax, x="input_hz", hue="k", marker=".")
ax.set(xlabel="input frequency (Hz)", ylabel="spikes per input cycle",
       title="a k × frequency sweep from zarr")
plt.show()
