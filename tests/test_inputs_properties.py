"""The property: whatever a careless user types, the answer is a result or one line.

For every field of every shipped study spec (its networks and stimuli included, as resolved),
random values of every type (huge, tiny, negative, NaN, inf, strings, lists, nested tables,
bools, broken TOML) go through ``--set`` into ``run --check``, which performs every check a
run performs and stops. The only outcomes allowed are acceptance (0), ``SpecError`` (2) and
``NumericalInstabilityError`` (3), each within a few seconds; never "internal error" (1) or an
exception. The public constructors get random arguments the same way. A few examples per field
run in the default suite; the thorough run is behind the slow marker.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from snn_antenna.core import spec as specs
from snn_antenna.cli import main
from snn_antenna.core.errors import NumericalInstabilityError, SpecError

ROOT = Path(__file__).resolve().parents[1]
STUDIES = sorted((ROOT / "studies").glob("*.toml"))


def _leaves(table: dict, prefix: str = ""):
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            yield from _leaves(value, dotted + ".")
        else:
            yield dotted


FIELDS = sorted({(path.name, key) for path in STUDIES
                 for key in _leaves(specs.load(path, [], quick=True)) if key != "study"})


def toml_value(value) -> str:
    """``value`` written as a TOML inline value (what ``--set key=VALUE`` parses)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return '"' + value.encode("unicode_escape").decode("ascii").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(value)


scalars = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, 1, -1, 2, 10**6, 10**18, -(10**12)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-308, 5e-324, 1e308, -1e308, 1e-9, 0.5, 1e9]),
    st.booleans(),
    st.text(max_size=12),
    st.sampled_from(["", "x", "cython", "numpy", "euler", "rk4", "wood", "ramp", "🦗"]),
)
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4),
    st.dictionaries(st.from_regex(r"[a-z]{1,6}", fullmatch=True), inner, max_size=3)),
    max_leaves=6)
settings_text = st.one_of(values.map(toml_value),
                          st.text(max_size=20),                      # not TOML at all
                          st.binary(max_size=12).map(lambda b: b.decode("latin-1")))


def _outcome(tmp_path, spec_name: str, key: str, text: str) -> int:
    try:
        return main(["run", str(ROOT / "studies" / spec_name), "--quick", "--check",
                     "--out", str(tmp_path / "out"), "--set", f"{key}={text}"])
    except SystemExit as exc:                     # argparse refusing an option
        return exc.code


def _check_field(tmp_path, field, text, capsys):
    spec_name, key = field
    status = _outcome(tmp_path, spec_name, key, text)
    err = capsys.readouterr().err
    assert status in (0, 2, 3), f"{spec_name} --set {key}={text!r}: {err}"
    assert "internal error" not in err and "Traceback" not in err
    if status == 2:
        last = err.strip().splitlines()[-1]
        assert len(last) < 1000, last                  # values are cut, never echoed whole


@settings(max_examples=3, deadline=10_000, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                 HealthCheck.too_slow])
@given(text=settings_text)
@pytest.mark.parametrize("field", FIELDS, ids=[f"{s}:{k}" for s, k in FIELDS])
def test_any_value_of_any_field_is_accepted_or_refused_in_one_line(tmp_path, capsys, field,
                                                                    text):
    _check_field(tmp_path, field, text, capsys)


# What the property found (each ended in "internal error" before its fix), kept as examples.
FOUND = [("baseline_comparison.toml", "stimulus.positions_cm", ":"),
         ("baseline_comparison.toml", "stimulus.positions_cm", "{a = 0}"),
         ("baseline_comparison.toml", "spiking.bank.bin_edges_s", "''"),
         ("baseline_comparison.toml", "spiking.designs", "00"),
         ("baseline_comparison.toml", "spiking.designs", "{a = 0}"),
         ("exploration.toml", "gate_training.speeds_cm_s", ""),
         ("exploration.toml", "gate_training.th_star_g", ""),
         ("exploration.toml", "loop.speed_cm_s", ""),
         ("exploration.toml", "network.control.motion_band_hz", "[]"),
         ("exploration.toml", "network.gate.speed_range_cm_s", "[]"),
         ("gating_threshold.toml", "calibration.speed_cm_s", ""),
         ("gating_threshold.toml", "gate.train_speeds_cm_s", ""),
         ("gating_threshold.toml", "sweep.speeds_cm_s", ""),
         ("gating_threshold.toml", "sweep.thresholds_g", ""),
         ("gating_threshold.toml", "preprocess.coder_amplitude", "-9223372036854775809"),
         ("quickstart.toml", "preprocess.warmup_s", ""),
         ("speed_accuracy.toml", "preprocess.lowpass_hz", "5e-324"),
         ("tuning_sweep.toml", "neuron.dt_ms", "1e-308")]


@pytest.mark.parametrize("spec_name, key, text", FOUND)
def test_what_the_property_found_stays_answered(tmp_path, capsys, spec_name, key, text):
    _check_field(tmp_path, (spec_name, key), text, capsys)


@pytest.mark.slow
@settings(max_examples=60, deadline=10_000,
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                 HealthCheck.too_slow])
@given(text=settings_text)
@pytest.mark.parametrize("field", FIELDS, ids=[f"{s}:{k}" for s, k in FIELDS])
def test_any_value_of_any_field_thoroughly(tmp_path, capsys, field, text):
    _check_field(tmp_path, field, text, capsys)


# -- the public constructors ----------------------------------------------------------------------
def _calls():
    from snn_antenna.preprocess import make_chain
    from snn_antenna.sources import stimuli
    from snn_antenna.sources.stimuli import Contact, RobotScene

    anything = st.one_of(values, st.none(), st.tuples(scalars, scalars))
    small = st.one_of(st.floats(0.01, 0.5), anything)        # valid values stay cheap
    return st.one_of(
        st.builds(lambda a, b, c: (stimuli.square, (a, b), {"amplitude": c}),
                  anything, small, anything),
        st.builds(lambda a, b: (stimuli.sine, (a, b), {}), anything, small),
        st.builds(lambda a: (stimuli.silence, (a,), {}), small),
        st.builds(lambda a, r: (stimuli.dc, (1.0, a), {"rate_hz": r}), small, anything),
        st.builds(lambda d, s, c: (lambda: RobotScene(duration_s=d,
                                                      contacts=c() if callable(c) else c
                                                      ).generate(s), (), {}),
                  small, anything, st.one_of(anything, st.lists(
                      st.tuples(anything, anything), max_size=2).map(
                      lambda pairs: lambda: [Contact(*p) for p in pairs]))),
        st.builds(lambda r, t, h: (make_chain, (r,), {"threshold": t, "highpass_hz": h}),
                  anything, anything, anything),
    )


def _call(made):
    """What the call answered: its result, or the clear error it raised."""
    func, args, kwargs = made
    try:
        return func(*args, **kwargs)
    except (SpecError, NumericalInstabilityError) as exc:
        return exc


def _answered_clearly(answer) -> bool:
    """A refusal names the field it refused (a result is an answer too)."""
    return not isinstance(answer, SpecError) or bool(answer.field)


@settings(max_examples=60, deadline=10_000, derandomize=True)
@given(st.data())
def test_public_constructors_answer_any_argument_by_name(data):
    assert _answered_clearly(_call(data.draw(_calls())))


@pytest.mark.slow
@settings(max_examples=3000, deadline=10_000)
@given(st.data())
def test_public_constructors_answer_any_argument_thoroughly(data):
    assert _answered_clearly(_call(data.draw(_calls())))
