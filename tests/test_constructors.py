"""Public constructors check what they are given with the specs' bounded checkers: a value no
physics allows (non-finite, of the wrong sign, beyond the bounds, a seed NumPy cannot take)
is refused in one SpecError naming the field, when the object is made, before any work."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.core.bounds import MAX_SEED
from snn_antenna.evaluation.accuracy import StabilityGrid
from snn_antenna.evaluation.bands import BandStudy
from snn_antenna.core.errors import SpecError
from snn_antenna.networks.control import ControlLayer, MaterialUnit
from snn_antenna.networks.cpg import CPG
from snn_antenna.networks.gate import SpeedGate
from snn_antenna.networks.resonators import ResonatorArray
from snn_antenna.readout.band_tuning import Tuning
from snn_antenna.readout.baselines import Mlp, NMFFilterBank
from snn_antenna.readout.closed_loop import LoopSettings
from snn_antenna.readout.events import EventProcessor
from snn_antenna.sources.bench import BenchSpec
from snn_antenna.sources.scenes import CourseLayout, CourseScene, Obstacle, SpeedProfile
from snn_antenna.sources.stimuli import Contact, RobotScene


def _fit_nmf(**kw):
    NMFFilterBank(**kw).fit(np.abs(np.random.default_rng(0).normal(size=(20, 12))))


# (what makes it, its required arguments, {field: kind of value})
CASES = [
    (BenchSpec, {}, {"rate_hz": "positive", "pre_trigger_s": "nonnegative",
                     "duration_s": "positive", "impact_g": "positive",
                     "sensor_noise_g": "nonnegative", "orientation_deg": "finite",
                     "physics_strength": "positive", "seed": "seed",
                     "repetitions": "count", "n_jobs": "count"}),
    (RobotScene, {}, {"duration_s": "positive", "rate_hz": "positive",
                      "speed_cm_s": "nonnegative", "stop_after_contact_s": "nonnegative",
                      "orientation_deg": "finite", "impact_g": "positive",
                      "sensor_noise_g": "nonnegative", "full_scale_g": "positive",
                      "adc_bits": "count"}),
    (CourseScene, {}, {"start_x_cm": "finite", "pan_deg": "finite", "tilt_deg": "finite",
                       "sweep_period_s": "positive", "hold_s": "positive",
                       "impact_transfer": "positive", "rate_hz": "positive"}),
    (SpeedProfile, {}, {"speed_cm_s": "nonnegative"}),
    (Obstacle, {"x_cm": 10.0, "y_cm": 5.0}, {"x_cm": "finite", "y_cm": "finite",
                                             "radius_cm": "positive"}),
    (Contact, {"t_s": 1.0, "distance_cm": 10.0}, {"t_s": "nonnegative",
                                                  "distance_cm": "positive",
                                                  "hold_s": "positive",
                                                  "amplitude_g": "nonnegative"}),
    (CPG, {}, {"period_s": "positive", "tau_ms": "positive", "trace_ms": "positive",
               "dt_ms": "positive", "token_drive": "positive", "speed_gain": "nonnegative",
               "pan_centre_deg": "finite", "tilt_amplitude_deg": "finite"}),
    (SpeedGate, {}, {"seed": "seed", "tau_syn_ms": "positive", "tau_trace_s": "positive",
                     "tau_read_s": "positive", "max_rate_hz": "positive", "dt_ms": "positive",
                     "eta": "positive", "readout_bias": "finite", "epochs": "count"}),
    (ControlLayer, {}, {"bias": "finite", "tau_syn_ms": "positive", "dt_ms": "positive",
                        "w_motor": "positive"}),
    (MaterialUnit, {}, {"window_s": "positive", "drive": "positive", "bias": "finite",
                        "dt_ms": "positive", "min_spikes": "count"}),
    (ResonatorArray, {}, {"b": "finite", "hz_per_k": "positive", "dt_ms": "positive"}),
    (Tuning, {}, {"threshold_g": "nonnegative", "coder_amplitude": "positive",
                  "hz_per_k": "positive", "max_k_dt": "positive"}),
    (Mlp, {}, {"max_iter": "count", "batch_size": "count", "learning_rate_init": "positive",
               "alpha": "nonnegative"}),
    (LoopSettings, {}, {"duration_s": "positive", "chunk_ms": "positive",
                        "calibration_s": "positive", "speed_cm_s": "nonnegative"}),
    (EventProcessor, {}, {"rate_hz": "positive", "onset_threshold_g": "positive",
                          "extreme_min_interval_ms": "nonnegative",
                          "extreme_min_fraction": "nonnegative"}),
    (CourseLayout, {}, {"spacing_cm": "positive"}),
    (StabilityGrid, {}, {"k_dt_min": "positive", "n_k_dt": "count", "model_ms": "positive",
                         "rate_tolerance": "positive"}),
    (BandStudy, {}, {"repetitions": "count", "duration_s": "positive",
                     "tuning_duration_s": "positive"}),
    (_fit_nmf, {}, {"max_iter": "count", "max_fit_samples": "count",
                    "random_state": "seed"}),
]
FIELDS = [(make, given_, name, kind) for make, given_, fields in CASES
          for name, kind in fields.items()]

NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])
HUGE = st.floats(min_value=1e10, max_value=1e308) | st.floats(min_value=-1e308,
                                                              max_value=-1e10)
BAD = {
    "finite": NON_FINITE | HUGE,
    "positive": NON_FINITE | HUGE.filter(lambda v: v < 0) | st.just(0.0)
    | st.floats(min_value=-1e6, max_value=-1e-9),
    "nonnegative": NON_FINITE | st.floats(min_value=-1e300, max_value=-1e-9),
    "seed": st.integers(max_value=-1) | st.integers(min_value=MAX_SEED + 1)
    | st.floats(allow_nan=True) | st.just(True),
    "count": st.integers(max_value=0) | NON_FINITE | st.floats(0.5, 1e6).filter(
        lambda v: v != int(v)),
}


@pytest.mark.parametrize("make, name, value", [
    (Tuning, "range_hz", []), (Tuning, "range_hz", [80.0]), (Tuning, "range_hz", [0.0, 450.0]),
    (Tuning, "range_hz", [450.0, 80.0]), (Tuning, "range_hz", ["80", 450.0]),
    (StabilityGrid, "drives", []), (StabilityGrid, "drives", [1.0, math.nan]),
    (StabilityGrid, "k_dt_max", 0.001), (BandStudy, "materials", []),
    (BandStudy, "materials", ["granite"]), (BandStudy, "positions_cm", "10"),
    (BandStudy, "positions_cm", [10.0, 80.0]), (BandStudy, "methods", "rk4"),
])
def test_lists_and_ranges_are_refused_by_name(make, name, value):
    err = _refused(make, {}, name, value)
    assert name in err.field and "\n" not in str(err), (name, value, err.field)


def _refused(make, given_, name, value) -> SpecError:
    with pytest.raises(SpecError) as err:
        make(**{**given_, name: value})
    return err.value


def test_every_listed_field_is_made_well_with_its_default():
    for make, given_, _fields in CASES:
        made = make(**given_)
        assert not isinstance(make, type) or isinstance(made, make), (make, made)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(FIELDS).flatmap(lambda case: st.tuples(st.just(case), BAD[case[3]])))
def test_a_value_no_physics_allows_is_one_line_naming_the_field(drawn):
    (make, given_, name, _), value = drawn
    err = _refused(make, given_, name, value)
    assert name in err.field and "\n" not in str(err), (make, name, value, err.field)


@pytest.mark.slow
@settings(max_examples=10_000, deadline=None)
@given(st.sampled_from(FIELDS).flatmap(lambda case: st.tuples(st.just(case), BAD[case[3]])))
def test_a_value_no_physics_allows_is_one_line_naming_the_field_thoroughly(drawn):
    (make, given_, name, _), value = drawn
    err = _refused(make, given_, name, value)
    assert name in err.field and "\n" not in str(err), (make, name, value, err.field)
