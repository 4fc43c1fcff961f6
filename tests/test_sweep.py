"""Sweeps: grids, bad-grid refusal, the resumable store, Dask = single process, kill + resume."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.engine.cost import check_memory
from snn_antenna.engine.evaluators import NeuronSweep
from snn_antenna.engine.grid import Grid, axis_values
from snn_antenna.engine.sweep import run_sweep
from snn_antenna.core.errors import SpecError
from snn_antenna.networks import neurons
from snn_antenna.core.store import Output, SweepStore

REPO = Path(__file__).resolve().parents[1]
SMALL = {"k": [0.5, 1.0], "I": [0.15, 0.5], "input_hz": [6.0, 10.0, 14.0, 18.0, 22.0, 26.0]}
FAST = NeuronSweep(duration_s=0.4, settle_s=0.1, engine="numpy")


# -- grids ------------------------------------------------------------------------------------
def test_axis_values_lists_and_ranges():
    assert np.allclose(axis_values("k", {"start": 1, "stop": 4, "num": 3, "scale": "log"}),
                       [1, 2, 4])
    assert np.allclose(axis_values("x", {"start": 2, "stop": 60, "num": 59}), np.arange(2, 61))
    assert np.allclose(axis_values("b", [0.2, 0.26]), [0.2, 0.26])
    assert np.allclose(axis_values("b", 0.26), [0.26])


def test_blocks_tile_the_grid_once_and_keep_trailing_axes_whole():
    grid = Grid({"k": [1, 2, 3], "b": [1, 2, 3, 4, 5], "f": np.arange(7)})
    assert grid.block_shape(20) == (1, 2, 7)
    seen = np.zeros(grid.shape, int)
    for region in grid.blocks(20):
        seen[tuple(region.values())] += 1
        pts = grid.points(region)
        assert len(pts["k"]) == np.prod([s.stop - s.start for s in region.values()]) <= 20
    assert (seen == 1).all()
    assert grid.block_shape(1000) == grid.shape
    assert grid.block_shape(3) == (1, 1, 3)


@pytest.mark.parametrize("axes, field, why", [
    ({"k": []}, "axes.k", "empty"),
    ({"k": {"start": 1, "stop": 2, "num": 0}}, "axes.k.num", ">= 1"),
    ({"k": [1.0, 1.0]}, "axes.k", "distinct"),
    ({"k": {"start": 0, "stop": 2, "num": 3, "scale": "log"}}, "axes.k", "> 0"),
    ({"k": [1.0, float("nan")]}, "axes.k", "finite"),
])
def test_malformed_axes_are_refused(axes, field, why):
    with pytest.raises(SpecError, match=why) as err:
        Grid(axes)
    assert err.value.field == field


def test_bad_neuron_grids_are_refused_before_any_work(tmp_path):
    store = tmp_path / "r.zarr"
    cases = [
        (Grid({"tau": [1.0]}), "axes.tau", "a parameter of the neuron sweep"),
        (Grid({"k": [1.0, 100.0]}), "axes.k", "MAX_STABLE_K_DT"),
        (Grid({"input_hz": [10.0, 400.0]}), "axes.input_hz", "4 samples per cycle"),
        (Grid({"k": [-1.0, 1.0]}), "axes.k", "> 0"),
    ]
    for grid, field, why in cases:
        with pytest.raises(SpecError, match=why) as err:
            run_sweep(grid, FAST, store, NeuronSweep.OUTPUTS, progress=False)
        assert err.value.field == field
    # the stable limit is the foundation's: exactly at the limit passes the check
    k_limit = neurons.MAX_STABLE_K_DT["euler"] / FAST.dt_ms
    FAST.for_grid(Grid({"k": [k_limit]}), (1,))
    # 10^12 points: far more than memory, refused as the grid is sized (nothing made)
    with pytest.raises(SpecError, match="fit in memory"):
        Grid({"k": {"start": 0.5, "stop": 1, "num": 10_000},
              "b": {"start": 0.2, "stop": 0.3, "num": 10_000},
              "input_hz": {"start": 2, "stop": 60, "num": 10_000}})
    with pytest.raises(SpecError, match="a grid whose results fit in memory"):
        check_memory(Grid({"k": [1.0, 2.0]}), NeuronSweep.OUTPUTS, 2, budget=8)
    with pytest.raises(SpecError, match="chunks that fit"):
        check_memory(Grid({"k": [1.0, 2.0]}), NeuronSweep.OUTPUTS, 2, 10**12)
    assert not store.exists()  # nothing was started


def test_study_spec_refuses_unknown_axis_before_work(tmp_path):
    from snn_antenna.core import spec as specs
    from snn_antenna.studies import tuning_sweep

    spec = specs.load(REPO / "studies/tuning_sweep.toml", ["axes.q=[1, 2]"], quick=True)
    with pytest.raises(SpecError) as err:
        tuning_sweep.plan(spec)
    assert err.value.field == "axes.q"
    spec = specs.load(REPO / "studies/tuning_sweep.toml", ["axes.k=[]"], quick=True)
    with pytest.raises(SpecError, match="empty"):
        tuning_sweep.plan(spec)
    assert not (tmp_path / "out").exists()


# -- the store --------------------------------------------------------------------------------
def polynomial(points):
    """A cheap deterministic evaluator for store tests."""
    return {"y": points["x"] ** 2 + 10 * points["z"], "n": (points["x"] * 3).astype(int)}


OUTS = {"y": Output("f8"), "n": Output("i4")}


def test_store_resumes_skips_finished_and_redoes_partial_chunks(tmp_path):
    grid = Grid({"x": np.arange(5.0), "z": [0.5, 1.5, 2.5]})
    path = tmp_path / "s.zarr"
    first = run_sweep(grid, polynomial, path, OUTS, chunk_points=3, progress=False,
                      attrs={"spec": {"a": 1}})
    assert first.chunks_computed == list(range(5)) and first.chunks_skipped == []
    x, z = np.meshgrid(grid.axes["x"], grid.axes["z"], indexing="ij")
    assert np.array_equal(first.data.y.values, x ** 2 + 10 * z)
    assert first.data.attrs["spec"] == {"a": 1}
    assert list(first.data.y.dims) == ["x", "z"]
    # a chunk whose data reached the disk but whose mark did not: redone
    store = SweepStore(path)
    import zarr
    zarr.open_array(path / "chunk_done", mode="r+")[3] = 0
    zarr.open_array(path / "y", mode="r+")[3, :] = -1.0
    again = run_sweep(grid, polynomial, path, OUTS, chunk_points=3, progress=False)
    assert again.chunks_computed == [3] and len(again.chunks_skipped) == 4
    assert again.data.equals(first.data)
    assert store.done_chunks() == set(range(5))
    # another grid in the same store is refused; fresh starts over
    with pytest.raises(SpecError, match="--fresh"):
        run_sweep(Grid({"x": [1.0], "z": [1.0]}), polynomial, path, OUTS, progress=False)
    fresh = run_sweep(grid, polynomial, path, OUTS, chunk_points=3, fresh=True, progress=False)
    assert fresh.chunks_computed == list(range(5))


def test_datasets_are_written_atomically_with_text_as_zarr_v3_strings(tmp_path, monkeypatch):
    """Every store (sweep, bench cache, stability map) is written by ``write_dataset``: text
    labels become Zarr v3's specified ``string`` type (numpy's fixed-width unicode has no
    Zarr v3 spec: other readers may refuse it), and a write that fails leaves no store."""
    import warnings

    import xarray as xr
    import zarr

    from snn_antenna.core.store import write_dataset

    ds = xr.Dataset({"status": (("method", "k_dt"), np.arange(6).reshape(2, 3)),
                     "label": ("method", np.array(["fine", "blown"]))},
                    coords={"method": ["euler", "rk2"], "k_dt": [0.1, 1.0, 10.0]})
    path = tmp_path / "map.zarr"
    with warnings.catch_warnings():
        warnings.simplefilter("error")        # no "no Zarr V3 specification" warning
        write_dataset(ds, path)
    group = zarr.open_group(path, mode="r")
    assert group.metadata.zarr_format == 3
    assert {group["method"].metadata.data_type.to_json(zarr_format=3),
            group["label"].metadata.data_type.to_json(zarr_format=3)} == {"string"}
    back = xr.open_zarr(path, consolidated=False).load()
    assert list(back.method.values) == ["euler", "rk2"] and list(back.label.values) == \
        ["fine", "blown"]
    assert np.array_equal(back.status.values, ds.status.values)

    # A write that dies half way leaves the finished store as it was and no half store.
    def broken(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_zarr", broken)
    with pytest.raises(OSError):
        write_dataset(ds.assign(status=ds.status * 0), path)
    assert np.array_equal(xr.open_zarr(path, consolidated=False).status.values,
                          ds.status.values)


# -- the neuron evaluator ---------------------------------------------------------------------
def euler_reference(p, sweep: NeuronSweep):
    """Hand-written Euler loop of the same equations and coder input (independent of Brian2)."""
    pre = neurons.PRESETS[sweep.preset]
    p2, p1, p0 = pre.quadratic
    v, u = (np.array(x, float) for x in sweep.initial_state(p))
    n_steps = int(round(sweep.duration_s * 1000 / sweep.dt_ms))
    count = np.zeros(len(v), int)
    per_sample = int(round(1000 / sweep.input_rate_hz / sweep.dt_ms))
    for step in range(n_steps):
        t_in = (step // per_sample) / sweep.input_rate_hz
        I = p["I"] * np.where(np.floor(2 * p["input_hz"] * t_in) % 2 == 0, 1.0, -1.0)
        dv = p["k"] * (p2 * v * v + p1 * v + p0 - u + I)
        du = p["a"] * p["k"] * (p["b"] * v - u)
        v, u = v + sweep.dt_ms * dv, u + sweep.dt_ms * du
        fired = v >= neurons.V_PEAK
        v[fired] = p["c"][fired]
        u[fired] += p["d"][fired]
        count += fired & (step * sweep.dt_ms >= sweep.settle_s * 1000 - 1e-9)
    return count


def test_vectorised_runtime_sweep_matches_a_hand_written_euler_loop():
    grid = Grid(SMALL)
    points = grid.points()
    brian = FAST(points)["spike_count"]
    ref = euler_reference(FAST.parameters(points), FAST)
    assert brian.sum() > 20  # the grid has responding and silent neurons
    assert (brian == 0).sum() > 3
    assert np.abs(brian - ref).max() <= 1


@pytest.mark.parametrize("dtype, axes", [
    ("float64", {**SMALL, "b": [0.2, 0.26]}),   # every parameter per point (b too)
    ("float64", SMALL),   # a, b, c, d not swept: one shared value each
    ("float32", SMALL)], ids=["float64-b swept", "float64", "float32"])
def test_standalone_engine_matches_runtime_engine(dtype, axes):
    # one compile per case (~10-20 s on a fresh machine; reused from the cache after).
    # The compiled engine fuses threshold and reset into a state update that advances every
    # neuron through one input sample's steps per clock tick, four grid points per element
    # of the group (standalone.LANES); the runtime engine is Brian2's plain NeuronGroup
    # (float64) with its own threshold and reset, one step per tick.
    grid = Grid(axes)
    points = grid.points()
    sweep = NeuronSweep(duration_s=0.4, settle_s=0.1, engine="standalone", dtype=dtype)
    sweep = sweep.for_grid(grid, (grid.size + 6,))   # padded: lanes and elements not full
    assert sweep.shared == tuple(name for name in ("a", "b", "c", "d") if name not in axes)
    standalone = sweep(points)["spike_count"]
    runtime = FAST(points)["spike_count"]
    assert np.abs(standalone - runtime).max() <= 1
    assert standalone.sum() > 20
    if "b" in axes:   # b reaches each point: the two b values give other counts
        assert not np.array_equal(standalone[points["b"] == 0.2], standalone[points["b"] == 0.26])
    # compiled with one make job per core, not Brian2's unbounded "make -j"
    import os

    from brian2 import prefs
    assert prefs.devices.cpp_standalone.extra_make_args_unix == [
        f"-j{len(os.sched_getaffinity(0))}"]


def test_lanes_copy_equations_and_statements_with_each_name_suffixed():
    from snn_antenna.engine.standalone import in_lanes

    text = "dv/dt = k*(v**2 - u + I_held)/ms : 1\nd : 1 (constant)\nv = where(v >= 30, c, v)"
    lanes = in_lanes(text, {"v", "u", "k", "d", "I_held"}, 2).splitlines()
    assert lanes == ["dv_0/dt = k_0*(v_0**2 - u_0 + I_held_0)/ms : 1", "d_0 : 1 (constant)",
                     "v_0 = where(v_0 >= 30, c, v_0)",
                     "dv_1/dt = k_1*(v_1**2 - u_1 + I_held_1)/ms : 1", "d_1 : 1 (constant)",
                     "v_1 = where(v_1 >= 30, c, v_1)"]   # c is not a lane's: left alone


def test_a_parameter_declared_shared_that_varies_is_refused_before_compiling():
    points = Grid(SMALL).points()
    sweep = NeuronSweep(duration_s=0.4, settle_s=0.1, shared=("k",))   # k varies in SMALL
    with pytest.raises(ValueError, match="k is declared shared"):
        sweep(points)


def test_a_float_type_outside_brian2s_is_refused():
    with pytest.raises(SpecError) as info:
        NeuronSweep(dtype="float16")
    assert info.value.field == "dtype" and "float32" in str(info.value)


# -- parallel execution -----------------------------------------------------------------------
def _profiler_callbacks(dask_worker):
    return sorted(name for name in dask_worker.periodic_callbacks if name.startswith("profile"))


@pytest.mark.slow    # a local Dask cluster: test_cluster.py and test_event_engine.py run one too
def test_dask_local_cluster_gives_the_single_process_numbers(tmp_path):
    from snn_antenna.engine.executor import dask_client

    grid = Grid(SMALL)
    serial = run_sweep(grid, FAST, tmp_path / "serial.zarr", NeuronSweep.OUTPUTS,
                       chunk_points=6, progress=False)
    with dask_client(workers=2) as own:  # the embedded default: a LocalCluster of processes
        assert len(own.scheduler_info()["workers"]) == 2
        # its HTTP server on a free port, not Dask's shared default (two clusters would clash)
        assert own.cluster.scheduler.http_server.port != 8787
        # attach to it as --scheduler tcp://HOST:PORT does for an existing cluster
        with dask_client(scheduler=own.scheduler.address) as client:
            parallel = run_sweep(grid, FAST, tmp_path / "dask.zarr", NeuronSweep.OUTPUTS,
                                 chunk_points=6, client=client, progress=False)
            # The sweep stopped Dask's statistical profiler on the workers it used: it
            # deadlocked a worker writing its chunk (see executor._PrepareWorker).
            assert set(map(tuple, client.run(_profiler_callbacks).values())) == {()}
    assert parallel.chunks_computed and len(parallel.workers) >= 1
    assert all(str(os.getpid()) not in w for w in parallel.workers)  # really other processes
    assert parallel.data.spike_count.equals(serial.data.spike_count)
    assert parallel.data.rate_hz.equals(serial.data.rate_hz)
    assert serial.data.spike_count.values.sum() > 0


KILLED_SWEEP = textwrap.dedent("""
    import sys
    from snn_antenna.engine.evaluators import NeuronSweep
    from snn_antenna.engine.grid import Grid
    from snn_antenna.engine.sweep import run_sweep
    grid = Grid({"k": [0.5, 0.75, 1.0, 1.25, 1.5, 2.0], "input_hz": [8.0, 14.0, 20.0, 26.0]})
    run_sweep(grid, NeuronSweep(duration_s=0.4, settle_s=0.1, engine="numpy"), sys.argv[1],
              NeuronSweep.OUTPUTS, chunk_points=4, progress=False)
""")


@pytest.fixture(scope="module")
def whole_sweep(tmp_path_factory):
    grid = Grid({"k": [0.5, 0.75, 1.0, 1.25, 1.5, 2.0], "input_hz": [8.0, 14.0, 20.0, 26.0]})
    return run_sweep(grid, FAST, tmp_path_factory.mktemp("whole") / "w.zarr",
                     NeuronSweep.OUTPUTS, chunk_points=4, progress=False)


@pytest.mark.parametrize("sig", [signal.SIGKILL,
                                 pytest.param(signal.SIGINT, marks=pytest.mark.slow)],
                         ids=["SIGKILL", "Ctrl-C"])   # Ctrl-C's resume: the same path, slow
def test_killed_sweep_resumes_without_recomputing(tmp_path, sig, whole_sweep):
    path = tmp_path / "killed.zarr"
    proc = subprocess.Popen([sys.executable, "-c", KILLED_SWEEP, str(path)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    store = SweepStore(path)
    deadline = time.monotonic() + 90
    try:
        while time.monotonic() < deadline:
            if (path / "chunk_done").exists() and len(store.done_chunks()) >= 2:
                break
            time.sleep(0.05)
        proc.send_signal(sig)
    finally:
        returncode = proc.wait(timeout=30)
    assert returncode != 0  # it was stopped, it did not finish
    done_before = store.done_chunks()
    assert 2 <= len(done_before) < 6, "the sweep must be killed mid-way"
    grid = Grid({"k": [0.5, 0.75, 1.0, 1.25, 1.5, 2.0], "input_hz": [8.0, 14.0, 20.0, 26.0]})
    resumed = run_sweep(grid, FAST, path, NeuronSweep.OUTPUTS, chunk_points=4, progress=False)
    assert set(resumed.chunks_skipped) == done_before
    assert set(resumed.chunks_computed) == set(range(6)) - done_before
    whole = whole_sweep
    assert resumed.data.spike_count.equals(whole.data.spike_count)
    assert whole.data.spike_count.values.sum() > 0


# -- the study --------------------------------------------------------------------------------
def test_tuning_study_quick_run_and_resume(tmp_path):
    from snn_antenna.cli import main

    out = tmp_path / "tuning"
    args = ["run", str(REPO / "studies/tuning_sweep.toml"), "--quick", "--out", str(out),
            "--set", "axes.k=[0.5, 1.0, 1.5]", "--set", "axes.b=[0.26]",
            "--set", "neuron.duration_s=0.6"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert (out / "report.html").is_file() and (out / "results.zarr").is_dir()
    assert set(summary["figures"]) == {"tuning_curves.png", "heatmaps.png", "maps.png"}
    peaks = summary["k_to_peak_hz"]["centroid_hz"]
    assert all(p is not None for p in peaks) and peaks == sorted(peaks)  # tuned by k
    width = dict(zip(summary["fwhm_vs_I"]["I"], summary["fwhm_vs_I"]["fwhm_hz"]))
    assert width[0.5] > width[0.15]  # the amplitude widens the band (Fig. 8G)
    assert summary["chunks_computed"] == summary["chunks"]
    assert main(args) == 0  # again: everything is read back from the store
    again = json.loads((out / "summary.json").read_text())
    assert again["chunks_computed"] == 0 and again["chunks_skipped"] == summary["chunks"]
    assert again["k_to_peak_hz"] == summary["k_to_peak_hz"]


# -- scene axes -------------------------------------------------------------------------------
def short_scene():
    import tomllib
    with open(REPO / "stimuli/quickstart_scene.toml", "rb") as f:
        scene = tomllib.load(f)
    scene["duration_s"] = 0.6
    scene["contacts"] = scene["contacts"][:1]  # the later contacts start after 0.6 s
    scene["contacts"][0].update(t_s=0.1, hold_s=0.5)
    return scene


def test_scene_axes_group_points_by_scene_and_match_single_runs(tmp_path):
    from snn_antenna.engine.evaluators import SceneSweep
    from snn_antenna.preprocess import make_chain
    from snn_antenna.sources.scenes import scene_from_spec

    sweep = SceneSweep(stimulus=short_scene(), preprocess={"coder_amplitude": 0.3},
                       engine="numpy", count_from_s=0.1)
    with pytest.raises(SpecError) as err:  # refused before any scene is generated
        run_sweep(Grid({"stimulus.speed": [1.0]}), sweep, tmp_path / "x.zarr",
                  SceneSweep.OUTPUTS, progress=False)
    assert err.value.field == "axes.stimulus.speed"
    with pytest.raises(SpecError, match="distance"):
        run_sweep(Grid({"stimulus.contacts.0.distance_cm": [19.0, 500.0]}), sweep,
                  tmp_path / "x.zarr", SceneSweep.OUTPUTS, progress=False)
    grid = Grid({"stimulus.contacts.0.distance_cm": [12.0, 26.0], "k": [0.6, 0.9, 1.3]})
    out = run_sweep(grid, sweep, tmp_path / "s.zarr", SceneSweep.OUTPUTS, progress=False)
    counts = out.data.spike_count
    assert counts.dims == ("stimulus.contacts.0.distance_cm", "k")
    for distance in (12.0, 26.0):  # each scene on its own, through the foundation directly
        table = short_scene()
        table["contacts"][0]["distance_cm"] = distance
        scene = scene_from_spec(table)
        rec = scene.generate(0)
        chain = make_chain(scene.rate_hz, coder_amplitude=0.3).fit(rec.samples)
        alone = neurons.simulate("resonator", chain.transform(rec.samples), 0.1,
                                 k=grid.axes["k"], input_dt_ms=1.0, target="numpy")
        late = alone.spike_t_ms >= 100.0
        expected = np.bincount(alone.spike_i[late], minlength=3)
        assert np.array_equal(counts.sel({"stimulus.contacts.0.distance_cm": distance}).values,
                              expected)
    assert counts.values.sum() > 0


@pytest.mark.slow
def test_a_killed_dask_worker_loses_nothing(tmp_path, whole_sweep):
    """SIGKILL one worker process mid-sweep: Dask reruns its chunk elsewhere, same numbers."""
    import threading

    from snn_antenna.engine.executor import dask_client

    grid = Grid({"k": [0.5, 0.75, 1.0, 1.25, 1.5, 2.0], "input_hz": [8.0, 14.0, 20.0, 26.0]})
    path = tmp_path / "k.zarr"
    store = SweepStore(path)
    with dask_client(workers=2) as client:
        victim = next(iter(client.run(os.getpid).values()))

        def kill_when_two_chunks_are_done():
            while not ((path / "chunk_done").exists() and len(store.done_chunks()) >= 2):
                time.sleep(0.02)
            os.kill(victim, signal.SIGKILL)

        threading.Thread(target=kill_when_two_chunks_are_done, daemon=True).start()
        out = run_sweep(grid, FAST, path, NeuronSweep.OUTPUTS, chunk_points=4, client=client,
                        progress=False)
        assert victim not in client.run(os.getpid).values()  # it really died
    assert out.data.spike_count.equals(whole_sweep.data.spike_count)
