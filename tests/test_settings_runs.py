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


def test_a_timed_sample_is_the_runtime_run_stopped_early_and_costs_by_steps():
    # the default-suite run's bench scene and structure (its compiled project is shared)
    from snn_antenna.studies.speed_accuracy import timing

    spec = specs.load(SPEC, DEFAULT_SUITE, quick=True)
    parts = runner("speed_accuracy").plan(spec).parts
    bench = prepare_workloads(parts, 1, lambda *a: None)["bench"]
    dt = sorted(spec["sweep"]["dt_ms"])[0]
    setting = Setting("rk2", dt, "numpy")
    whole = bench.run(setting)
    sample = timing.timed_sample(bench, setting, bench.coded.duration_s, sample_s=0.6)
    assert sample["status"] == "ok" and sample["sample_s"] == 0.6
    early = timing.spikes_before(whole.spike_i, whole.spike_t_ms, dt, 0.6)
    assert 0 < early < len(whole.spike_i)      # the window holds some spikes, not all
    assert sample["sample_spikes"] == early
    compiled = settings_spikes([scene_drive(bench)], ["rk2"], [dt])[("bench", "rk2", dt)]
    assert timing.agrees(sample, compiled, dt)
    steps = bench.coded.duration_s * 1000.0 / dt
    assert sample["cpu_s"] == pytest.approx(sample["fixed_cpu_s"]
                                            + sample["per_step_cpu_s"] * steps)
    assert sample["per_step_cpu_s"] > 0


@pytest.mark.slow
def test_the_compiled_driven_tuning_counts_as_the_runtime_one():
    from snn_antenna.evaluation import bands
    from snn_antenna.studies.speed_accuracy.main_sweep import tuning_spikes

    band, setting = bands.BENCH_BANDS["high"], bands.BandSetting("rk4", 0.005)
    freqs = np.geomspace(100.0, 400.0, 6)
    runtime = bands.driven_tuning(band, setting, 2000.0, freqs, 0.2, target="numpy")
    compiled = bands.driven_tuning(band, setting, 2000.0, freqs, 0.2, compiled=tuning_spikes)
    assert runtime.values.sum() > 0
    # the same run up to the compiler's rounding: at 40,000 steps a neuron near a spike
    # may fire one or two spikes more or fewer (measured: 1 of 144 cells, 2 spikes)
    spikes = np.abs(compiled.values - runtime.values) * 0.2
    assert spikes.max() <= 2 and np.mean(spikes > 0) <= 0.02
    np.testing.assert_array_equal(bands.peak_hz(compiled), bands.peak_hz(runtime))
