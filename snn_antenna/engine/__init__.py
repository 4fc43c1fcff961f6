"""Bulk runs: a grid of points, evaluated chunk by chunk on Dask, into a resumable zarr store.

``sweep`` holds the grid, the executor (embedded local cluster or a scheduler address) and
the evaluators (``NeuronSweep``, ``SceneSweep``); ``snn_antenna.store`` writes the results.
"""
