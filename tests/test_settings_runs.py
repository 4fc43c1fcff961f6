"""Scenes × integration settings on the compiled engine give the runtime runs' spikes."""
import numpy as np
import pytest

from snn_antenna.core import spec as specs
from snn_antenna.core.errors import NumericalInstabilityError
from snn_antenna.engine.devices import Setting
from snn_antenna.engine.settings_runs import SceneDrive, scene_drive, settings_spikes
from snn_antenna.studies import runner
from snn_antenna.studies.speed_accuracy.run import prepare_workloads

from test_speed_accuracy import DEFAULT_SUITE, SPEC


def test_every_setting_of_one_compiled_run_spikes_as_its_runtime_run():
    # the speed/accuracy default-suite run's own structure: its compiled project is shared
    spec = specs.load(SPEC, DEFAULT_SUITE, quick=True)
    parts = runner("speed_accuracy").plan(spec).parts
    workloads = prepare_workloads(parts, 1, lambda *a: None)
    bench = workloads["bench"]
    methods, dts = spec["sweep"]["methods"], sorted(spec["sweep"]["dt_ms"])
    compiled = settings_spikes([scene_drive(bench)], methods, dts)
    assert set(compiled) == {("bench", m, dt) for m in methods for dt in dts}
    counts = set()
    for (_, method, dt), run in compiled.items():
        runtime = bench.run(Setting(method, dt, "numpy"))
        assert np.array_equal(run.spike_i, runtime.spike_i), (method, dt)
        np.testing.assert_allclose(run.spike_t_ms, runtime.spike_t_ms, atol=1e-9)
        counts.add(len(run.spike_i))
    assert len(counts) > 1          # the settings differ, so each run is its own
    # the process's one cpp_standalone device has built and run that project; a standalone
    # run of the cost sweep after it builds its own
    standalone = bench.run(Setting(methods[0], dts[0], "cpp_standalone"))
    assert len(standalone.spike_i) > 0


@pytest.mark.slow
def test_a_blow_up_is_the_error_of_its_scene_alone():
    n_samples, rate_hz = 200, 1000.0
    calm = SceneDrive("calm", np.full((n_samples, 1), 0.15), rate_hz, np.full(4, 0.5),
                      np.zeros(4, int), np.full(4, -65.0), np.full(4, -13.0), 0.2)
    wild = SceneDrive("wild", np.full((n_samples, 1), 20.0), rate_hz, np.full(4, 60.0),
                      np.zeros(4, int), np.full(4, -65.0), np.full(4, -13.0), 0.2)
    out = settings_spikes([calm, wild], ["euler"], [1.0])
    assert isinstance(out[("wild", "euler", 1.0)], NumericalInstabilityError)
    assert not isinstance(out[("calm", "euler", 1.0)], Exception)
