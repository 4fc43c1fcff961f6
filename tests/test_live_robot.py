"""The robot network, live (bridge/online/robot.py, networks/live_robot.toml): the speed gate, CPG
and control layer run in Brian2 in the array's stream network; the gate's Th codes each next
window, a speed command (``--speed``, the page's) is applied at a window boundary, journaled
and replayed; the control layer stops the robot on contact; each part has its panel and a
part the spec lacks has none. Replays read flat out (a few seconds each)."""
import math
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.bridge.cli import _speed
from snn_antenna.bridge.online.controls import RecordedChanges, recorded_events
from snn_antenna.bridge.online.pipeline import build_online
from snn_antenna.bridge.view.page import panels_html
from snn_antenna.bridge.wire.recorder import Recorder, record_counts
from snn_antenna.bridge.online.robot import check_speed
from snn_antenna.core.errors import SpecError
from snn_antenna.sources.stimuli import Contact, RobotScene
from tests.test_live_view_panels import ABSENT, NETWORK, replay_into_view

ROBOT = NETWORK.parent / "live_robot.toml"
SPEED = 12.0
# The page's changes, as events.jsonl journals them: a faster speed at 1.5 s, the robot driven
# on at 4.0 s after the contact (2.5 s) stopped it, and Th set by hand at 5.0 s.
# The live spec's parts on Brian2's numpy target (the spec's cython target is what a user runs).
NUMPY = ['network.resonators.target="numpy"', 'network.gate.target="numpy"']
CHANGES = [{"sample": 1500, "field": "speed_cm_s", "value": 24.0},
           {"sample": 4000, "field": "speed_cm_s", "value": 6.0},
           {"sample": 5000, "field": "th_g", "value": 0.3}]


@pytest.fixture(scope="module", autouse=True)
def _brian_target_restored():
    """The parts set Brian2's global code target as they build; the worker's later tests get
    back the one they had."""
    import brian2 as b2

    before = b2.prefs.codegen.target
    yield
    b2.prefs.codegen.target = before


@pytest.fixture(scope="module")
def robot_parts():
    """Built once (the gate learns Th*(speed) for ~5 s); each run takes a deep copy. On Brian2's
    numpy target: these tests check what the parts decide and in what order, and the cython
    target would compile the robot network's few dozen code objects for them alone."""
    return build_online(ROBOT, NUMPY, speed_cm_s=SPEED)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A robot driving, one contact at 2.5 s, 19 cm from the base; 6 s."""
    counts = RobotScene(duration_s=6.0, contacts=[Contact(2.5, 19.0)]).generate(seed=3).samples
    return record_counts(tmp_path_factory.mktemp("robot") / "rec", counts)


def _replay(recording, parts, scheduled=(), chunk_bytes=800, journal=None):
    """(report, history, what each window decided) of a replay into a never-started view."""
    return replay_into_view(recording, parts, scheduled, chunk_bytes, journal)[:3]


@pytest.fixture(scope="module")
def driven(recording, robot_parts, tmp_path_factory):
    """The replay with the page's changes, journaled as a live run journals them."""
    out = tmp_path_factory.mktemp("journal") / "live"
    recorder = Recorder(out, port="test://", wire_format="binary", baudrate=1)
    result = _replay(recording, robot_parts, CHANGES, journal=recorder)
    recorder.close()
    return (*result, out)


def test_the_robot_network_has_a_panel_per_part(driven):
    _, history, decided, _ = driven
    state = history.state()["network"]
    assert state["parts"] == ["resonators", "gate", "cpg", "control"]
    # The gate's panel holds the Th in force: no fixed-Th panel beside it.
    assert list(state["panels"]) == ["gate", "cpg", "control", "readout"]
    assert all(set(d) == set(state["panels"]) for d in decided)
    html = panels_html(history)
    for shown in ("Speed gate", "speed (cm/s)", "recalled Th (g)", "CPG", "phase (°)",
                  "pan (°)", "Control layer: stop signal", "motor unit spikes"):
        assert shown in html
    assert not [word for word in ABSENT if word not in html]


def test_the_gates_recalled_th_codes_the_next_window_until_th_is_set_by_hand(driven):
    _, _, decided, _ = driven
    gate = [d["gate"] for d in decided]
    manual = [i for i, g in enumerate(gate) if g["th_source"] == "manual"]
    assert manual[0] == 50 and manual == list(range(50, len(gate)))   # from 5.0 s on
    for before, now in zip(gate[:49], gate[1:50]):
        assert now["th_source"] == "gate"
        assert now["th_g"] == pytest.approx(before["recalled_th_g"], abs=2e-6)
    assert {g["th_g"] for g in gate[50:]} == {0.3}
    # The gate follows the speed in force: faster → higher Th; stopped → the lowest.
    at = {round(d["readout"]["t_s"], 1): d["gate"] for d in decided}
    assert at[1.4]["speed_cm_s"] == SPEED and at[1.5]["speed_cm_s"] == 24.0
    assert at[2.4]["recalled_th_g"] > 1.5 * at[1.4]["recalled_th_g"]
    assert at[3.9]["speed_cm_s"] == 0.0 and at[3.9]["recalled_th_g"] < at[1.4]["recalled_th_g"]


def test_the_control_layer_stops_the_robot_on_contact_and_a_speed_command_drives_it_on(driven):
    report, _, decided, _ = driven
    (contact,) = report["contacts"]
    assert abs(contact["onset_s"] - 2.5) < 0.15 and abs(contact["distance_cm"] - 19.0) < 3.0
    control = [(d["readout"]["t_s"], d["control"], d["cpg"]) for d in decided]
    stops = {c["stopped_since_s"] for _, c, _ in control if c["stopped_since_s"] is not None}
    (stopped,) = stops
    assert contact["onset_s"] <= stopped <= contact["end_s"]
    assert all(c["motor_unit_spikes"] == 0 for t, c, _ in control if t < stopped - 0.1)
    assert sum(c["contact_unit_spikes"] for t, c, _ in control if t < stopped) > 0
    # The sweep: about the CPG's frequency while driving at 12 cm/s, frozen while stopped,
    # going again once the speed command comes at 4.0 s.
    phases = {round(t, 1): p["phase_deg"] for t, _, p in control}
    turned = (phases[1.4] - phases[0.4]) % 360          # 1 s at 12 cm/s: 0.7 cycles
    assert 0.6 * 360 < turned < 0.8 * 360
    frozen = [p for t, c, p in control if stopped + 0.3 <= t < 3.9]
    assert frozen and all(p["frozen"] for p in frozen)
    assert max(p["phase_deg"] for p in frozen) - min(p["phase_deg"] for p in frozen) < 3.0
    assert not any(p["frozen"] for t, _, p in control if t >= 4.0)
    assert (phases[5.9] - phases[4.9]) % 360 > 0.3 * 360


def test_a_replay_of_the_journal_reproduces_the_run(driven, recording, robot_parts):
    """events.jsonl holds the speed and Th changes at their samples; a replay that applies
    them again, however the bytes were chunked, decides the same and finds the same contacts."""
    report, _, decided, out = driven
    events = recorded_events(out)
    assert [(e["sample"], e["field"], e["value"]) for e in events] == \
        [(c["sample"], c["field"], c["value"]) for c in CHANGES]
    assert [e["was"] for e in events][:2] == [SPEED, 24.0]
    again, _, decided_again = _replay(recording, robot_parts, events, chunk_bytes=333)
    assert again["contacts"] == report["contacts"]
    assert decided_again == decided
    # Without the changes the run is another one: the journal is what reproduces it.
    plain, _, decided_plain = _replay(recording, robot_parts)
    assert decided_plain != decided


def test_the_parts_run_on_one_clock_with_no_monitor(robot_parts):
    """In Brian2's runtime mode every object is a Python call per step of its clock, and the
    loop looks at every clock at every step: the robot's parts share one clock of their step
    (the array's where it is the same: the control layer's synapses step with the resonators
    whose spikes they carry), keep no monitor (the units count their own spikes), and the
    gate carries no learning (it learned before the stream)."""
    import copy

    import brian2 as b2

    parts = copy.deepcopy(robot_parts)
    b2.start_scope()
    group = parts.array.build_group("I_ext", "I_ext : 1", {})
    objects = parts.robot.build(group)
    every = [*objects, *(inner for obj in objects for inner in obj.contained_objects)]
    steps = {}
    for obj in every:
        steps.setdefault(float(obj.clock.dt / b2.ms), set()).add(obj.clock)
    assert {dt: len(clocks) for dt, clocks in steps.items()} == {1.0: 1, 0.5: 1}
    assert steps[0.5] == {group.clock}
    assert not [obj for obj in every if isinstance(obj, (b2.SpikeMonitor, b2.StateMonitor))]
    names = {obj.name for obj in objects}
    assert {"speed_population", "readout", "plastic", "control_contact"} <= names
    assert not names & {"teacher", "teaching"}


def test_a_composed_spec_is_refused_live_only_where_a_part_cannot_run(recording, tmp_path):
    with pytest.raises(SpecError, match=r"network.parts = 'material'.*fit offline"):
        build_online(NETWORK.parent / "bench_material.toml")
    with pytest.raises(SpecError, match=r"speed = None .*--speed.*gate, cpg"):
        build_online(ROBOT)
    with pytest.raises(SpecError, match=r"speed = 45 .*\[0, 30\]"):
        build_online(ROBOT, speed_cm_s=45)
    with pytest.raises(SpecError, match=r"gate_training = None .*\[gate_training\] table.*--set"):
        build_online(NETWORK.parent / "robot.toml", speed_cm_s=SPEED)
    # --set reaches the gate's training examples (here one threshold short: named).
    with pytest.raises(SpecError, match=r"gate_training.th_star_g = \[0.1\] .*one threshold per"):
        build_online(NETWORK.parent / "robot.toml", ["gate_training.speeds_cm_s=[0, 30]",
                                                     "gate_training.th_star_g=[0.1]"],
                     speed_cm_s=SPEED)
    with pytest.raises(SpecError, match=r"speed = 10.0 .*none for a network without a speed"):
        build_online(NETWORK, speed_cm_s=10.0)
    # A recording whose journal changes the speed, replayed on a network without one.
    with pytest.raises(SpecError, match=r"network = .*events.jsonl changes the speed"):
        RecordedChanges(build_online(NETWORK), CHANGES[:1])


@settings(max_examples=200, deadline=None)
@given(value=st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                       st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=6)),
       accepted=st.sampled_from([None, (0.0, 30.0), (5.0, 12.5)]))
def test_a_speed_is_accepted_exactly_within_the_networks_range(value, accepted):
    """The one check of a speed command (``--speed``, the page's ``speed_cm_s``, a replayed
    event): accepted exactly within the running network's range, else a one-line SpecError
    naming the field, the value and the range."""
    # a number as every bound takes one: finite, and 0 or normal (a subnormal underflows)
    number = isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value) and (value == 0 or abs(value) >= sys.float_info.min)
    if number and accepted and accepted[0] <= value <= accepted[1]:
        assert check_speed(value, accepted) == float(value)
    else:
        with pytest.raises(SpecError) as caught:
            check_speed(value, accepted)
        message = str(caught.value)
        assert caught.value.field == "speed" and "\n" not in message
        assert (f"[{accepted[0]:g}, {accepted[1]:g}]" if accepted else "no part") in message
    # The command line's --speed: any finite number >= 0 passes to the network's check.
    if number and value >= 0:
        assert _speed("speed", value) == float(value)
    else:
        with pytest.raises(SpecError):
            _speed("speed", value)


def test_stream_refuses_a_bad_speed_before_opening_the_port(capsys, tmp_path):
    """``--speed`` is checked with the network, before the port (which does not exist here)."""
    from snn_antenna.cli import main

    port = str(tmp_path / "no-such-port")
    assert main(["stream", "--port", port, "--network", str(NETWORK), "--speed", "5",
                 "--out", str(tmp_path / "a")]) == 2
    assert "speed = 5.0 is not accepted: none for a network without a speed gate" in \
        capsys.readouterr().err
    assert main(["stream", "--port", port, "--network", str(ROBOT), "--out",
                 str(tmp_path / "b")]) == 2
    assert "--speed" in capsys.readouterr().err
    assert main(["stream", "--port", port, "--network", str(ROBOT), "--speed", "-3"]) == 2
    assert ">= 0 cm/s" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_trained_gate_is_kept_and_recalls_as_the_one_that_learned(tmp_path, capsys):
    """The gate's training is cached (bench.cached, keyed on the gate, its examples and the
    code): the second stream start reuses it, with the same weights and Th range a fit gives;
    other examples learn anew."""
    from snn_antenna.bridge.online.robot import trained_gate
    from snn_antenna.networks.gate import SpeedGate

    def small(**changes):
        return SpeedGate(n_speed_neurons=4, epochs=1, present_s=0.2, curve_points=1, **changes)

    examples = ([0.0, 30.0], [0.05, 0.4])
    fitted = small().fit(*examples)
    first = trained_gate(small(), *examples, cache_dir=tmp_path)
    assert "cache: stored" in capsys.readouterr().err
    again = trained_gate(small(), *examples, cache_dir=tmp_path)
    assert "cache: reusing" in capsys.readouterr().err
    for gate in (first, again):
        assert np.array_equal(gate.weights_, fitted.weights_)
        assert gate.th_range_ == fitted.th_range_
    trained_gate(small(), [0.0, 30.0], [0.05, 0.5], cache_dir=tmp_path)
    assert "cache: stored" in capsys.readouterr().err
    assert len(list(tmp_path.glob("gate-*.zarr"))) == 2


def test_brians_dt_mismatch_warning_is_silenced_for_the_control_layers_sense_pathway_alone(
        recording, robot_parts):
    """The control layer's sense pathway steps with the array whose spikes it carries, finer
    than the units it feeds: Brian2's mismatch warning is this design and is dropped for that
    pathway; any other pathway's mismatch still warns."""
    import brian2 as b2
    from brian2.utils.logger import catch_logs

    def mismatch(logs):
        return [message for _, _, message in logs if "will run on the clock" in message]

    with catch_logs() as logs:
        _replay(recording, robot_parts)
    assert mismatch(logs) == []
    with catch_logs() as logs:
        b2.start_scope()
        fine = b2.NeuronGroup(1, "v : 1", threshold="True", dt=0.5 * b2.ms)
        coarse = b2.NeuronGroup(1, "v : 1", dt=1 * b2.ms)
        others = b2.Synapses(fine, coarse, on_pre="v_post += 1", dt=1 * b2.ms)
        others.connect()
        b2.Network(fine, coarse, others).run(2 * b2.ms)
    assert len(mismatch(logs)) == 1
