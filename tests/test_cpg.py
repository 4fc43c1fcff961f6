"""The CPG ring in Brian2: period, pan/tilt phase, ranges, speed modulation, recovery."""
import numpy as np
import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.networks.cpg import CPG, cycle_periods, phase_lag_deg


@pytest.fixture(scope="module")
def cpg():
    return CPG(period_s=2.0, phase_offset_deg=90.0)


@pytest.fixture(scope="module")
def at_rest(cpg):
    return cpg.run(0.0, 9.0)


def test_period_and_phase_offset_match_the_spec(cpg, at_rest):
    periods = cycle_periods(at_rest["t_s"], at_rest["pan_deg"])
    assert len(periods) >= 3
    assert np.all(np.abs(periods / 2.0 - 1) < 0.05), periods
    lag = phase_lag_deg(at_rest["t_s"], at_rest["pan_deg"], at_rest["tilt_deg"], 2.0)
    assert abs(lag - 90.0) < 10.0
    assert np.all(np.abs(cycle_periods(at_rest["t_s"], at_rest["tilt_deg"]) / 2.0 - 1) < 0.05)


def test_angles_stay_in_the_antennas_range(at_rest):
    pan, tilt = at_rest["pan_deg"], at_rest["tilt_deg"]
    assert pan.min() >= 0 - 1e-9 and pan.max() <= 80 + 1e-9      # 80° centred 40° to the side
    assert tilt.min() >= -35 - 1e-9 and tilt.max() <= 55 + 1e-9  # 90° centred 10° above
    assert np.ptp(pan) > 70 and np.ptp(tilt) > 80                  # and it uses the range


def test_frequency_rises_with_speed(cpg):
    freqs = []
    for v in (0.0, 15.0, 30.0):
        r = cpg.run(v, 5.0)
        freqs.append(1 / np.median(cycle_periods(r["t_s"], r["pan_deg"])))
    assert freqs[0] < freqs[1] < freqs[2]
    assert freqs[2] == pytest.approx(cpg.frequency_hz(30.0), rel=0.05)


def test_the_rhythm_recovers_after_a_perturbation(cpg):
    hold = np.zeros(1000)
    hold[400:440] = 5.0                  # a 0.4 s inhibitory pulse at 4 s stalls the ring
    r = cpg.run(0.0, 10.0, hold=hold)
    t_cross_periods = cycle_periods(r["t_s"], r["pan_deg"])
    assert t_cross_periods.max() > 2.2   # the perturbation did disturb it
    assert abs(t_cross_periods[-1] / 2.0 - 1) < 0.05   # and the period came back
    # One token went round: every neuron fired as often as the others.
    spikes_per_cycle = np.bincount(r["spike_i"])
    assert spikes_per_cycle.max() - spikes_per_cycle.min() <= 1


def test_bad_settings_are_refused():
    with pytest.raises(SpecError, match="period_s"):
        CPG(period_s=-1.0)
    with pytest.raises(SpecError, match="speed_cm_s"):
        CPG().run(-3.0, 1.0)


def test_brians_order_warning_is_silenced_for_the_rings_token_alone():
    """The ring's all-to-all token write makes Brian2 warn that its outcome may depend on the
    synapses' order (it would only for two ring neurons firing in one step); the warning is
    dropped for that statement, and Brian2 still warns about any other such statement."""
    import brian2 as b2
    from brian2.utils.logger import catch_logs

    def order_warnings(logs):
        return [message for _, _, message in logs if "may not be well-defined" in message]

    with catch_logs() as logs:
        CPG(n_neurons=4).run(0.0, 0.05)
    assert order_warnings(logs) == []
    with catch_logs() as logs:
        b2.start_scope()
        group = b2.NeuronGroup(3, "x : 1", threshold="True")
        others = b2.Synapses(group, group, on_pre="x_post = i")
        others.connect()
        b2.Network(group, others).run(1 * b2.ms)
    assert len(order_warnings(logs)) == 1
