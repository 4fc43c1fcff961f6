"""Tuning curves read from a rate grid: peak, centroid, band width, and the calibration of
Hz per unit k, on hand-made curves whose answers are known."""
import numpy as np
import pytest
import xarray as xr

from snn_antenna.networks import neurons
from snn_antenna.evaluation import tuning

F = np.geomspace(2.0, 60.0, 41)


def _rates(k_values, hz_per_k):
    """Log-Gaussian tuning curves peaking at hz_per_k · k (k = 0 never fires)."""
    curves = [np.exp(-0.5 * (np.log(F / (hz_per_k * k)) / 0.3) ** 2) * 50 if k > 0
              else np.zeros_like(F) for k in k_values]
    return xr.DataArray(np.array(curves), dims=("k", "input_hz"),
                        coords={"k": k_values, "input_hz": F}, name="rate_hz")


def test_fwhm_interpolates_the_half_crossings_and_flags_the_edge():
    f = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    width, at_edge = tuning.fwhm(f, np.array([0.0, 1.0, 2.0, 1.0, 0.0]), peak=2)
    assert width == pytest.approx(2.0) and not at_edge
    width, at_edge = tuning.fwhm(f, np.array([2.0, 1.5, 0.5, 0.0, 0.0]), peak=0)
    assert at_edge and width == pytest.approx(1.5)


def test_derive_finds_each_peak_and_leaves_a_silent_curve_empty():
    maps = tuning.derive(_rates([0.0, 0.5, 1.0], hz_per_k=20.0))
    peak = maps.peak_hz.values
    assert np.isnan(peak[0]) and np.isnan(maps.fwhm_hz.values[0])
    assert peak[1:] == pytest.approx([10.0, 20.0], rel=0.05)
    assert maps.centroid_hz.values[2] == pytest.approx(20.0, rel=0.02)


def test_the_calibration_recovers_the_slope_and_judges_the_constant():
    point = tuning.ReadPoint()
    true = neurons.DRIVEN_HZ_PER_K
    rates = _rates([0.0, 0.5, 1.0, 1.5], hz_per_k=true)
    summary = tuning.summarise(tuning.derive(rates), F, point)
    cal = summary["calibration"]
    assert cal["hz_per_k_centroid"] == pytest.approx(true, rel=0.02)
    assert cal["driven_hz_per_k_holds"] and cal["responding_k"] == 3
    assert summary["k_to_peak_hz"]["peak_hz"][0] is None     # null, never a number
    off = tuning.summarise(tuning.derive(_rates([0.5, 1.0], hz_per_k=1.5 * true)), F, point)
    assert not off["calibration"]["driven_hz_per_k_holds"]
