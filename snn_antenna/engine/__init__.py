"""Bulk runs: a grid of points, evaluated chunk by chunk on Dask, into a resumable zarr store.

    grid = Grid({"k": [0.5, 1, 2], "input_hz": {"start": 2, "stop": 60, "num": 59}})
    evaluate = NeuronSweep(duration_s=2.0)
    with dask_client(workers=0) as client:
        outcome = run_sweep(grid, evaluate, "out/results.zarr", NeuronSweep.OUTPUTS,
                            client=client)

- ``grid``: ``Grid`` (named axes, their product, chunks that keep trailing axes whole) and
  ``axis_values``.
- ``cost``: what a sweep needs before it starts: ``check_memory`` refuses results or chunks
  that would not fit, ``estimate`` sizes a neuron sweep's wall time (``job_estimate`` and
  ``stages_estimate`` a study's runs), ``max_workers`` the processes this machine can run,
  ``LONG_SWEEP_S`` the CLI's limit without ``--yes``.
- ``executor``: where it runs: ``executor`` (this process or Dask), ``dask_client`` (an
  embedded local cluster or a scheduler's address), ``prepare_workers``.
- ``evaluators``: what each point computes: ``NeuronSweep`` (square-wave input) and
  ``SceneSweep`` (coded robot scenes), each chunk one NeuronGroup.
- ``standalone``: ``NeuronSweep``'s compiled cpp_standalone project, one per process.
- ``sweep``: ``run_sweep``, the resumable chunk loop; ``snn_antenna.core.store`` writes the
  results.
- ``batches``: batches of scored codings submitted now and collected later (Dask or this
  process), for stages that are not grids (the gating study's evaluation); a read-out with
  target ``"standalone"`` runs them on ``codings``' compiled group (one per process).
- ``rates``: the engines' rates every estimate multiplies by, probed on this machine or
  from the written table, each with its source.
- ``devices`` and ``runlog``: one-off timed runs per code target and precision, and their
  resumable log (the speed/accuracy study).
"""
