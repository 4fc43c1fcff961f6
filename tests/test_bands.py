"""Bench bands inside the accurate range: the measured limits, the chosen steps, the
errors against the reference and the tuning read-outs."""
import numpy as np
import pytest
import xarray as xr

from snn_antenna.core.errors import SpecError
from snn_antenna.evaluation import accuracy, bands
from snn_antenna.readout.spiking import Band

K_DT_GRID = np.geomspace(0.01, 50, 25)      # the study's stability-map grid
MAP_DRIVES = [-50, -40, -30, -20, -10, -5, -1, -0.5, -0.15, 0, 0.15, 0.5, 1, 2, 5, 10, 20,
              30, 40, 50]


def test_bench_bands_are_the_baseline_studys():
    from snn_antenna.core import spec as specs

    tables = specs.load("studies/baseline_comparison.toml")["spiking"]["bank"]["bands"]
    for name, band in bands.BENCH_BANDS.items():
        table = dict(tables[name], band_hz=tuple(tables[name]["band_hz"]))
        assert Band(**table) == band, name


# Brian2 runs at the limit and one grid point past it (~27 s for rk4, ~17 s for euler): behind
# the slow marker to keep the default suite under 6 minutes; the default suite keeps the
# range arithmetic (test_accurate_step_is_the_largest_inside_the_range) and the shipped bands'
# runs at their chosen settings
@pytest.mark.slow
@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_accurate_limit_is_accurate_and_the_next_grid_point_is_not(method):
    limit = bands.ACCURATE_K_DT[method]
    beyond = K_DT_GRID[K_DT_GRID > 1.1 * limit][0]
    # The map's own conditions: its finest k·dt (0.01) sets 40,000 steps over 400 model-ms
    smap = accuracy.stability_map([method], [0.01, limit, beyond], MAP_DRIVES, model_ms=400.0)
    status = smap.status.sel(integrator=method).values
    assert (status[:2] == accuracy.ACCURATE).all()
    assert (status[2] != accuracy.ACCURATE).any()
    assert float(smap.max_accurate_k_dt.sel(integrator=method)) == pytest.approx(limit, rel=1e-3)


@pytest.mark.parametrize("name", list(bands.BENCH_BANDS))
@pytest.mark.parametrize("method", list(bands.ACCURATE_K_DT))
def test_accurate_step_is_the_largest_inside_the_range(name, method):
    band = bands.BENCH_BANDS[name]
    dt = bands.accurate_dt_ms(band, method)
    assert 0.5 / dt == pytest.approx(round(0.5 / dt))          # divides the input interval
    _, k_dt = bands.k_dt_range(band, bands.BandSetting(method, dt))
    assert k_dt <= bands.ACCURATE_K_DT[method]
    larger = [s for s in bands.DT_STEPS_MS if s > dt]
    if larger:
        _, k_dt = bands.k_dt_range(band, bands.BandSetting(method, min(larger)))
        assert k_dt > bands.ACCURATE_K_DT[method]


def test_before_setting_is_far_outside_the_range_for_the_high_band():
    _, k_dt = bands.k_dt_range(bands.BENCH_BANDS["high"], bands.SMALL_SIGNAL_EULER)
    assert k_dt > 20 * bands.ACCURATE_K_DT["euler"]


# ~37 s of Brian2 runs; behind the slow marker with the accurate-limit checks above
@pytest.mark.slow
def test_high_band_inside_the_range_is_closer_to_the_reference_than_before():
    data = bands.sample_data(["aluminium"], [30.0])
    events = bands.code_events("high", bands.BENCH_BANDS["high"], data, duration_s=0.1)
    ref = bands.reference_spikes(events)
    before = bands.measure(events, bands.SMALL_SIGNAL_EULER, ref, target="numpy")
    inside = bands.BandSetting("rk4", bands.accurate_dt_ms(events.band, "rk4"))
    after = bands.measure(events, inside, ref, target="numpy")
    assert after["inside_accurate_range"] and not before["inside_accurate_range"]
    assert after["rate_map_error"] < before["rate_map_error"]
    assert after["spike_count_error"] <= 0.05
    assert after["cpu_ms_per_event"] > 0 and after["ns_per_neuron_step"] > 0
    chosen = bands.choose([before, after], 0.05)
    assert chosen is after
    assert "step 0.001 ms, rk4 integration" in bands.apply_line("high", chosen)


def test_truncation_error_counts_the_reference_spikes_after_the_window():
    ref = bands.Spikes(np.array([0, 0, 1, 1]), np.array([10.0, 60.0, 20.0, 90.0]))
    assert bands.truncation_error(ref, 2, 0.1, 0.05) == pytest.approx(0.5)
    assert bands.truncation_error(ref, 2, 0.1, 0.1) == 0.0


def _rates(neuron_hz, peaks, freqs, k):
    rates = np.zeros((len(neuron_hz), len(freqs)))
    for j, p in enumerate(peaks):
        rates[j] = np.exp(-np.log(freqs / p) ** 2 / 0.01)
    return xr.DataArray(rates, dims=("neuron_hz", "input_hz"),
                        coords={"neuron_hz": neuron_hz, "input_hz": freqs,
                                "k": ("neuron_hz", k)}, attrs={"setting": "synthetic"})


def test_peak_calibration_puts_peaks_on_target_and_counts_channels():
    freqs = np.geomspace(40, 700, 400)
    neuron_hz = np.geomspace(55, 500, 8)
    k = neuron_hz / 25.0
    true_hz_per_k = 23.0                         # peaks at 23 Hz per k: below target
    peaks = freqs[np.argmin(np.abs(np.log(freqs[None] / (true_hz_per_k * k)[:, None])),
                            axis=1)]
    rates = _rates(neuron_hz, peaks, freqs, k)
    assert bands.peak_hz_per_k(rates) == pytest.approx(true_hz_per_k, rel=0.01)
    channel = np.log(neuron_hz[1] / neuron_hz[0])
    expected = np.log(23.0 / 25.0) / channel
    assert np.allclose(bands.peak_offsets(rates), expected, atol=0.02)
    summary = bands.tuning_summary(rates)
    assert summary["silent"] == 0 and summary["within_one_channel"] == 8


@pytest.mark.parametrize("kwargs, field", [
    ({"method": "heun"}, "method"), ({"dt_ms": 0.0}, "dt_ms"),
    ({"hz_per_k": -1.0}, "hz_per_k"), ({"duration_s": 0.0}, "duration_s")])
def test_bad_settings_are_refused_naming_the_field(kwargs, field):
    with pytest.raises(SpecError) as info:
        bands.BandSetting(**kwargs)
    assert info.value.field == field


def test_band_study_refuses_unknown_bands():
    with pytest.raises(SpecError, match="bands"):
        bands.BandStudy(bands=["ultra"])


@pytest.mark.parametrize("name", list(bands.CHOSEN))
def test_the_shipped_bands_run_at_the_chosen_settings(name):
    """What the bank runs is what was measured, and it is a candidate the study tries."""
    setting, band = bands.CHOSEN[name], bands.BENCH_BANDS[name]
    assert (band.method, band.dt_ms, band.hz_per_k) == (setting.method, setting.dt_ms,
                                                        setting.hz_per_k)
    assert setting.dt_ms in bands.candidate_steps(band, setting.method, setting.hz_per_k,
                                                  bands.BandStudy().coarser_steps)
    assert band.array(0.1, "euler", "numpy").dt_ms == setting.dt_ms   # not the bank's step


def test_candidates_start_at_the_maps_step_and_go_coarser():
    band = bands.BENCH_BANDS["high"]
    fine = bands.accurate_dt_ms(band, "rk4")
    steps = bands.candidate_steps(band, "rk4", None, 2)
    assert steps[0] == fine and len(steps) == 3 and steps == sorted(steps)
    assert bands.candidate_steps(band, "rk4", None, 0) == [fine]


def test_choice_follows_the_measured_error_not_the_map():
    """A coarser step outside the map's constant-drive range is chosen when the run against
    the reference says it is within tolerance and it is cheaper; never the "before" row."""
    rows = [dict(status="ok", role="before", rate_map_error=0.0, cpu_ms_per_event=1.0,
                 inside_accurate_range=False),
            dict(status="ok", role="candidate", rate_map_error=0.01, cpu_ms_per_event=300.0,
                 inside_accurate_range=True),
            dict(status="ok", role="candidate", rate_map_error=0.03, cpu_ms_per_event=80.0,
                 inside_accurate_range=False),
            dict(status="ok", role="candidate", rate_map_error=0.2, cpu_ms_per_event=10.0,
                 inside_accurate_range=False)]
    assert bands.choose(rows, 0.05) is rows[2]
    assert bands.choose(rows, 0.005) is None
