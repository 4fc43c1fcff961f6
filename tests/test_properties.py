"""Property-based: whatever the parameters and inputs, a run returns finite, sane results or
raises a clear error (SpecError before running, NumericalInstabilityError during it)."""
import os
import resource

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from snn_antenna.core.errors import NumericalInstabilityError, SpecError
from snn_antenna.networks import neurons
from snn_antenna.networks.resonators import ChunkFeed, ResonatorArray
from snn_antenna.preprocess import make_chain
from snn_antenna.core.signals import Recording

# Each example builds a Brian2 network: few examples by default, many under -m slow.
FEW = settings(max_examples=8, deadline=None, derandomize=True,
               suppress_health_check=[HealthCheck.too_slow])
MANY = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _assert_sane(result, n_steps_max):
    assert np.all(np.isfinite(result.spike_t_ms))
    assert np.all((result.spike_t_ms >= 0) & (result.spike_t_ms < result.duration_ms))
    assert np.all((result.spike_i >= 0) & (result.spike_i < result.n_neurons))
    assert result.spike_counts.max(initial=0) <= n_steps_max   # at most one spike per step


neuron_cases = dict(
    k=st.floats(0.01, 50.0),
    drive=st.floats(-50.0, 50.0),
    b=st.floats(-0.5, 0.5),
    dt=st.sampled_from([0.01, 0.05, 0.1, 0.25, 0.5, 1.0]),
    method=st.sampled_from(neurons.METHODS),
    shape=st.sampled_from(["dc", "square", "single_sample"]),
    force=st.booleans(),
)


def _check_neuron(k, drive, b, dt, method, shape, force):
    n_samples = 40                               # 40 ms of input at 1 kHz
    current = np.zeros(n_samples)
    if shape == "dc":
        current[:] = drive
    elif shape == "square":
        current[:] = np.where((np.arange(n_samples) // 5) % 2 == 0, drive, -drive)
    else:
        current[n_samples // 2] = drive
    beyond = k * dt > neurons.MAX_STABLE_K_DT[method]
    try:
        result = neurons.simulate("resonator", current, dt, k, method, input_dt_ms=1.0,
                                  b=b, force=force)
    except SpecError as exc:
        assert beyond and not force and exc.field == "dt_ms"
        return
    except NumericalInstabilityError as exc:   # only ever beyond the limit, when forced
        assert force and beyond and exc.method == method and exc.dt_ms == dt
        assert exc.safe_dt_ms == pytest.approx(neurons.MAX_STABLE_K_DT[method] / k)
        return
    assert not beyond or force
    _assert_sane(result, int(round(n_samples / dt)))


@FEW
@given(**neuron_cases)
def test_any_neuron_run_is_sane_or_raises_clearly(**case):
    _check_neuron(**case)


@pytest.mark.slow
@MANY
@given(**neuron_cases)
def test_any_neuron_run_is_sane_or_raises_clearly_thorough(**case):
    _check_neuron(**case)


def _counts(parts, rate_hz=1000.0, bits=10):
    """An ADC recording (2 axes) assembled from awkward pieces."""
    full = 2 ** bits - 1
    chunks = []
    for kind, value in parts:
        n = 60
        if kind == "silence":
            x = np.full((n, 2), full / 2)
        elif kind == "dc_offset":
            x = np.full((n, 2), full / 2 + value * full / 2)
        elif kind == "clipped":
            t = np.arange(n) / rate_hz
            x = np.clip(full / 2 + 3 * full * np.sin(2 * np.pi * 15 * t), 0, full)[:, None] \
                * np.ones(2)
        elif kind == "spike":
            x = np.full((n, 2), full / 2)
            x[n // 2] = full if value > 0 else 0
        else:  # "nan"
            x = np.full((n, 2), full / 2)
            x[n // 3, 0] = np.nan
        chunks.append(x)
    return np.round(np.concatenate(chunks)) if not any(k == "nan" for k, _ in parts) \
        else np.concatenate(chunks)


recording_parts = st.lists(
    st.tuples(st.sampled_from(["silence", "dc_offset", "clipped", "spike", "nan"]),
              st.floats(-1.0, 1.0)), min_size=2, max_size=5)


def _check_array(parts, method, dt):
    counts = _counts(parts)
    array = ResonatorArray(n_neurons=6, method=method, dt_ms=dt, target="numpy")
    chain = make_chain(1000.0, threshold=0.05)
    try:
        rec = Recording(counts, 1000.0, units="counts")
        chain.fit(counts)
        coded = rec.with_samples(chain.transform(counts), "coded")
        result = array.run(coded, window_s=0.03)
    except SpecError as exc:
        assert any(k == "nan" for k, _ in parts), exc
        assert "non-finite" in str(exc) or "finite" in exc.accepted
        return
    assert not any(k == "nan" for k, _ in parts)
    rates = result.rate_map
    assert np.all(np.isfinite(rates.values)) and np.all(rates.values >= 0)
    assert np.all((result.spike_t_s >= 0) & (result.spike_t_s < coded.duration_s))


array_cases = dict(parts=recording_parts, method=st.sampled_from(neurons.METHODS),
                   dt=st.sampled_from([0.1, 0.25]))


@settings(FEW, max_examples=5)
@given(**array_cases)
def test_array_on_awkward_recordings_is_sane_or_refuses_nan(**case):
    _check_array(**case)


@pytest.mark.slow
@MANY
@given(**array_cases)
def test_array_on_awkward_recordings_is_sane_or_refuses_nan_thorough(**case):
    _check_array(**case)


def _rss_mb() -> float:
    with open(f"/proc/{os.getpid()}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


@pytest.mark.slow
def test_one_hour_of_streaming_keeps_memory_bounded_and_values_finite():
    """3,600 s of coded input through the 24-neuron array, one window every 0.1 s."""
    rate_hz, hour_s = 1000.0, 3600
    rng = np.random.default_rng(0)

    def chunks():
        t = np.arange(int(rate_hz)) / rate_hz
        for second in range(hour_s):
            f = rng.uniform(5, 35)
            x = 0.15 * np.sign(np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)))
            if second % 10 == 9:
                x[:] = 0.0        # a silent second now and then
            yield x

    seen = {"windows": 0, "spikes": 0, "rss": []}

    def on_window(t_s, counts):
        assert np.all(np.isfinite(counts)) and np.all(counts >= 0)
        seen["windows"] += 1
        seen["spikes"] += int(counts.sum())
        if seen["windows"] % 6000 == 0:          # every 10 simulated minutes
            seen["rss"].append(_rss_mb())

    array = ResonatorArray(dt_ms=0.5, method="euler", target="cython")
    stats = array.stream(ChunkFeed(chunks(), on_window), rate_hz, window_s=0.1)
    assert stats.simulated_s == pytest.approx(hour_s)
    assert seen["windows"] >= hour_s * 10 - 1
    assert seen["spikes"] > 1000
    growth = seen["rss"][-1] - seen["rss"][0]
    print(f"\n1 h streamed in {stats.wall_s:.0f} s wall ({stats.realtime_factor:.1f}x real "
          f"time), {seen['spikes']} spikes, RSS {seen['rss'][0]:.0f} -> "
          f"{seen['rss'][-1]:.0f} MB")
    assert growth < 20.0
