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


# -- whole spec trees, flags x studies, and --check against the run ------------------------------
# Run in the default suite with the Hypothesis profile's count ("suite": a hundred each, the same
# every run; HYPOTHESIS_PROFILE=slow: ten thousand); the slow-marked copies always take ten
# thousand.
from snn_antenna.studies import STUDIES, runner  # noqa: E402

QUICK_SPECS = {name: specs.load(ROOT / "studies" / f"{name}.toml", [], quick=True)
               for name in sorted(STUDIES)}


RAW = "\0"   # marks a value written as raw TOML text (deep nesting, long numbers)
raw_texts = st.one_of(
    st.integers(1, 6000).map(lambda n: "9" * n),                          # long numbers
    st.integers(1, 4000).map(lambda d: "[" * d + "1" + "]" * d),          # deep lists
    st.integers(1, 400).map(lambda d: "{a = " * d + "1" + "}" * d),       # deep tables
    st.integers(0, 3000).map(lambda w: "[" + ", ".join(["0.5"] * w) + "]"),   # wide lists
    st.sampled_from(["1e400", "-1e400", "0x7fffffffffffffffff", "inf", "nan", "1979-05-27",
                     "[1, 'a', [2]]", "{}", "[]"]))


def _put(spec: dict, dotted: str, value) -> dict:
    """A copy of ``spec`` with the leaf ``dotted`` replaced (tables along the way copied)."""
    out = dict(spec)
    node, *rest = dotted.split(".")
    if rest and isinstance(out.get(node), dict):
        out[node] = _put(out[node], ".".join(rest), value)
    else:
        out[node] = value
    return out


@st.composite
def spec_trees(draw):
    """A shipped study's quick spec with one field (or a new key) replaced by any tree."""
    study = draw(st.sampled_from(sorted(STUDIES)))
    spec = QUICK_SPECS[study]
    keys = [k for k in _leaves(spec) if k != "study"] + ["bogus", "network.bogus"]
    key = draw(st.sampled_from(keys))
    if draw(st.booleans()):
        text = draw(raw_texts)
        top, *rest = key.split(".")
        if rest:     # a raw value deep in a table: write its table's other keys around it
            return study, spec, key, text
        return study, _put(spec, key, RAW + text), key, None
    return study, _put(spec, key, draw(values)), key, None


def _write_tree(path: Path, spec: dict, key: str, raw: str | None) -> None:
    lines = []
    for top, value in spec.items():
        if raw is not None and key.split(".")[0] == top:
            continue
        lines.append(f"{top} = {value[1:]}" if isinstance(value, str) and value.startswith(RAW)
                     else f"{top} = {toml_value(value)}")
    if raw is not None:
        top, *rest = key.split(".")
        table = spec.get(top) if isinstance(spec.get(top), dict) else {}
        lines.append(f"[{top}]")
        inner = ".".join(rest)
        lines += [f"{k} = {toml_value(v)}" for k, v in table.items() if k != inner]
        lines.append(f"{inner} = {raw}")
    path.write_text("\n".join(lines) + "\n")


def _one_line_or_accepted(status: int, err: str, what: str) -> None:
    assert status in (0, 2, 3), f"{what}: {err[-2000:]}"
    assert "internal error" not in err and "Traceback" not in err, f"{what}: {err[-2000:]}"
    if status == 2:
        errors = [line for line in err.strip().splitlines() if "error" in line]
        assert len(errors) == 1 and errors[0] == err.strip().splitlines()[-1], err[-2000:]
        assert len(errors[0]) < 1000, errors[0][:300]


def _check_tree(tmp_path, capsys, tree) -> None:
    study, spec, key, raw = tree
    path = tmp_path / "tree.toml"
    _write_tree(path, spec, key, raw)
    try:
        status = main(["run", str(path), "--check", "--out", str(tmp_path / "out")])
    except SystemExit as exc:
        status = exc.code
    _one_line_or_accepted(status, capsys.readouterr().err, f"{study} {key}")


@given(tree=spec_trees())
def test_any_spec_tree_is_checked_or_refused_in_one_line(tmp_path, capsys, tree):
    _check_tree(tmp_path, capsys, tree)


@pytest.mark.slow
@settings(settings.get_profile("slow"))
@given(tree=spec_trees())
def test_any_spec_tree_thoroughly(tmp_path, capsys, tree):
    _check_tree(tmp_path, capsys, tree)


@st.composite
def commands(draw, tmp_path: Path):
    """``snn-antenna run`` of a shipped study with any flags (some with odd values) and maybe
    a ``--set`` of any value to any field."""
    study = draw(st.sampled_from(sorted(STUDIES)))
    argv = ["run", str(ROOT / "studies" / f"{study}.toml")]
    folder, afile = tmp_path / "recordings", tmp_path / "afile"
    flags = {
        "--quick": [[]], "--yes": [[]], "--force": [[]], "--fresh": [[]],
        "--scheduler": [["tcp://127.0.0.1:8786"], [""], ["garbage"], ["tcp://h:99999"]],
        "--data": [[str(folder)], [str(afile)], [str(tmp_path / "missing")], [""]],
        "--out": [[str(tmp_path / "out")], [str(afile)], [str(tmp_path / ("x" * 300))],
                  [str(tmp_path / "mine")], [str(tmp_path / "dangling")]],
    }
    takes = {f"--{o}" for o in runner(study).OPTIONS} | {"--out"}
    for name in sorted(flags):
        # --out always; a flag the study takes half the time, one it does not now and then
        if name == "--out" or draw(st.integers(0, 1 if name in takes else 7)) == 0:
            argv += [name, *draw(st.sampled_from(flags[name]))]
    if draw(st.booleans()):
        key = draw(st.sampled_from([k for s, k in FIELDS if s == f"{study}.toml"]))
        argv += ["--set", f"{key}={draw(settings_text)}"]
    return study, argv


def _check_then_run(tmp_path, capsys, monkeypatch, study, argv) -> None:
    """--check's answer, then the run's with the study's work replaced by a record of its
    being reached: both accept, or both refuse with the same line."""
    (tmp_path / "recordings").mkdir(exist_ok=True)
    (tmp_path / "afile").write_text("mine")
    (tmp_path / "mine").mkdir(exist_ok=True)           # a folder of the user's, with a report
    (tmp_path / "mine" / "report.html").write_text("mine")
    if not (tmp_path / "dangling").is_symlink():
        (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    reached = []
    monkeypatch.setattr(runner(study), "run",
                        lambda plan, out_dir, options, log=print: reached.append(plan) or {})
    answers = []
    for extra in (["--check"], []):
        try:
            status = main([*argv, *extra])
        except SystemExit as exc:
            status = exc.code
        err = capsys.readouterr().err
        _one_line_or_accepted(status, err, " ".join(argv)[-300:])
        answers.append((status, err.strip().splitlines()[-1] if status else ""))
    assert answers[0] == answers[1], answers
    assert bool(reached) == (answers[1][0] == 0)
    assert (tmp_path / "afile").read_text() == "mine"
    assert (tmp_path / "mine" / "report.html").read_text() == "mine"


@given(data=st.data())
def test_check_and_run_give_the_same_answer_for_any_command(tmp_path, capsys, monkeypatch,
                                                            data):
    study, argv = data.draw(commands(tmp_path))
    _check_then_run(tmp_path, capsys, monkeypatch, study, argv)


@pytest.mark.slow
@settings(settings.get_profile("slow"))
@given(data=st.data())
def test_check_and_run_give_the_same_answer_thoroughly(tmp_path, capsys, monkeypatch, data):
    study, argv = data.draw(commands(tmp_path))
    _check_then_run(tmp_path, capsys, monkeypatch, study, argv)


# What the tree property found (each an internal error before its fix), kept as examples.
FOUND_TREES = [("speed_accuracy", "bands.materials", 3),
               ("speed_accuracy", "stability.k_dt_min", 0),
               ("baseline_comparison", "spiking.tuned.tuning.range_hz", []),
               ("tuning_sweep", "axes.k", [1, 10**400]),
               ("exploration", "loop.duration_s", 10**400),
               ("gating_threshold", "sweep.scene_s", 10**400),
               ("speed_accuracy", "tuning.n_freqs", 10**400)]


@pytest.mark.parametrize("study, key, value", FOUND_TREES)
def test_what_the_tree_property_found_stays_answered(tmp_path, capsys, study, key, value):
    _check_tree(tmp_path, capsys, (study, _put(QUICK_SPECS[study], key, value), key, None))
