"""Stability limits: measured, enforced before a run, and blow-ups caught during it."""
import numpy as np
import pytest

from snn_antenna.core.errors import NumericalInstabilityError, SpecError
from snn_antenna.networks import neurons
from snn_antenna.networks.resonators import ResonatorArray
from snn_antenna.evaluation import accuracy

# The study's map grid; each limit is its largest finite point, rounded down.
K_DT_GRID = np.geomspace(0.01, 50, 25)
DRIVES = [-50.0, -30.0, 0.5, 2.0]  # the drives that break first (see the study's map)


@pytest.mark.slow
@pytest.mark.parametrize("method", neurons.METHODS)
def test_each_limit_is_finite_at_and_runs_away_one_grid_step_beyond(method):
    # As long as the study's map ran (40,000 steps): rare runaways need time to show.
    limit = neurons.MAX_STABLE_K_DT[method]
    beyond = K_DT_GRID[K_DT_GRID > 1.1 * limit][0]     # the next grid point of the map
    runaway, *_ = accuracy.run_drives(method, [limit, beyond], DRIVES, 40_000)
    runaway = runaway.reshape(2, len(DRIVES))
    assert not runaway[0].any(), f"{method} ran away at its limit"
    assert runaway[1].any(), f"{method} stayed finite beyond its limit"


def test_every_limit_holds_for_every_drive_over_a_short_run():
    # The quick side of the check above (the default suite; the slow one runs 40,000 steps).
    for method, limit in neurons.MAX_STABLE_K_DT.items():
        runaway, *_ = accuracy.run_drives(method, [limit / 4, limit], DRIVES + [-10.0, 20.0],
                                          2000)
        assert not runaway.any(), method


def test_stability_map_marks_fine_steps_accurate_and_reports_limits():
    smap = accuracy.stability_map(["euler"], [0.02, 20.0], [-5.0, 0.0, 2.0], model_ms=60.0)
    status = smap.status.sel(integrator="euler").values
    assert (status[0] == accuracy.ACCURATE).all()
    assert (status[1] == accuracy.NON_FINITE).any()
    assert float(smap.max_stable_k_dt.sel(integrator="euler")) == pytest.approx(0.02)
    assert set(smap.status.dims) == {"integrator", "k_dt", "I"}


def test_the_compiled_map_runs_every_cell_as_its_runtime_run():
    # the speed/accuracy default-suite run's map grid (its methods, 4 k·dt from 0.5 to 50 and
    # its drives, 100 model-ms at the finest): the compiled project it builds is shared
    from snn_antenna.engine.settings_runs import drives_runs

    methods, k_dt, drives = ["euler", "rk2"], np.geomspace(0.5, 50.0, 4), [-20.0, 0.0, 0.5, 20.0]
    steps = 200
    compiled = drives_runs(methods, k_dt, drives, steps)
    assert list(compiled) == methods
    for method in methods:
        runaway, spike_i, spike_t, kk, drive = accuracy.run_drives(method, k_dt, drives, steps)
        c_runaway, c_i, c_t, c_kk, c_drive = compiled[method]
        assert np.array_equal(c_kk, kk) and np.array_equal(c_drive, drive)
        assert np.array_equal(c_runaway, runaway), method
        assert runaway.any() and not runaway.all()     # both kinds of cell are compared
        # finite cells up to k·dt 5 spike at the steps of their runtime runs (coarser finite
        # cells are chaotic: rounding moves their spikes, the map reads only their rates)
        calm = np.flatnonzero(~runaway & (kk <= 5.0))
        assert len(calm) >= 4
        for j in calm:     # dt is 1 ms: a spike's time is its step
            assert np.array_equal(np.sort(np.rint(c_t[c_i == j])),
                                  np.sort(np.rint(spike_t[spike_i == j]))), (method, j)
    smap = accuracy.stability_map(methods, k_dt, drives, model_ms=100.0, compiled=drives_runs)
    runtime = accuracy.stability_map(methods, k_dt, drives, model_ms=100.0)
    assert np.array_equal(smap.status.values, runtime.status.values)
    assert "compiled" in smap.attrs["engine"] and "numpy" in runtime.attrs["engine"]


@pytest.mark.parametrize("method", neurons.METHODS)
def test_blow_up_raises_during_the_run_with_a_safe_dt(method):
    k = 4.0
    dt = 3 * neurons.MAX_STABLE_K_DT[method] / k
    current = np.full(400, 2.0)  # 4 s of a drive that breaks every method at 3x its limit
    with pytest.raises(NumericalInstabilityError) as info:
        neurons.simulate("resonator", current, dt_ms=dt, k=[0.01, k], method=method,
                         input_dt_ms=10.0, force=True, check_every_ms=10.0)
    err = info.value
    assert err.neuron == 1 and err.method == method and err.dt_ms == dt
    assert err.params["k"] == k and set(err.params) == {"k", "a", "b", "c", "d"}
    assert err.t_ms < 2000.0                       # stopped during the run, not after it
    assert err.safe_dt_ms == pytest.approx(neurons.MAX_STABLE_K_DT[method] / k)
    assert f"{err.safe_dt_ms:.4g}" in str(err)


@pytest.mark.parametrize("method", neurons.METHODS)
def test_specs_beyond_the_limit_are_refused_unless_forced(method):
    limit = neurons.MAX_STABLE_K_DT[method]
    array = ResonatorArray(method=method, dt_ms=min(1.0, 0.99 * limit / 1.5), target="numpy")
    k_max = float(array.k.max())
    assert neurons.max_stable_dt_ms(array.k, method) == pytest.approx(limit / k_max)
    too_coarse = 1.01 * limit / k_max
    if too_coarse <= 1.0:   # ResonatorArray caps dt at 1 ms anyway
        with pytest.raises(SpecError, match="dt_ms"):
            ResonatorArray(method=method, dt_ms=too_coarse, target="numpy")
        ResonatorArray(method=method, dt_ms=too_coarse, target="numpy", force=True)
    with pytest.raises(SpecError, match="force=True"):
        neurons.simulate("resonator", np.zeros(5), dt_ms=1.01 * limit / 2.0, k=2.0,
                         method=method)


def test_unknown_method_is_refused_with_the_list():
    with pytest.raises(SpecError, match="izhikevich"):
        neurons.simulate("resonator", np.zeros(5), method="heun")
    with pytest.raises(SpecError, match="method"):
        ResonatorArray(method="midpoint", target="numpy")
