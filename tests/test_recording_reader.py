"""A recording folder read defensively: ``load_recording`` checks meta.json (every field it
uses: present, of its type, in its range), events.jsonl (every change a replay would apply) and
the data files (regular files, sizes that agree with meta.json). Whatever a folder holds, the
answer is the recording or one line naming the file, the field and the value: never a hang,
never a traceback."""
import json
import os
import shutil
import signal
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from snn_antenna.bridge import load_recording
from snn_antenna.bridge.online.controls import journaled_change
from snn_antenna.bridge.wire.protocol import Sample, encode_binary
from snn_antenna.bridge.wire.recorder import (
    EVENTS_FILE,
    META_FIELDS,
    META_FILE,
    RAW_FILE,
    SAMPLES_FILE,
    Recorder,
)
from snn_antenna.bridge.wire.source import Batch
from snn_antenna.core.errors import SpecError

CLI = [sys.executable, "-m", "snn_antenna.cli"]
FILES = (META_FILE, SAMPLES_FILE, RAW_FILE, EVENTS_FILE)
ODD_VALUES = [None, "x", -1, 0, 1.5, [], {}, True, float("inf"), 2 ** 70, "binary", [1, 2]]


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """A sound recording: 200 samples, two control changes."""
    folder = tmp_path_factory.mktemp("template") / "rec"
    recorder = Recorder(folder, port="test://", wire_format="binary", baudrate=250000)
    samples = [Sample(s, s % 1024, 1023 - s % 1024) for s in range(200)]
    raw = b"".join(encode_binary(*s) for s in samples)
    recorder.handle(Batch(100.0, raw, samples, {"frames": 200}))
    recorder.note_event({"sample": 100, "field": "th_g", "value": 0.05})
    recorder.note_event({"sample": 150, "field": "window_s", "value": 0.2})
    recorder.close()
    return folder


@contextmanager
def deadline(seconds=10):
    """A read that would hang (a fifo, a device) fails the test instead of stalling it."""
    def expired(*_):
        raise TimeoutError(f"load_recording did not return within {seconds} s")
    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def read_or_refuse(folder):
    """The recording, or the SpecError's one line; anything else fails the test."""
    with deadline():
        try:
            return load_recording(folder)
        except SpecError as exc:
            message = str(exc)
            assert "\n" not in message and len(message) < 600, message
            return message


def fresh_copy(template, tmp_path_factory):
    folder = tmp_path_factory.mktemp("case") / "rec"
    shutil.copytree(template, folder)
    return folder


def meta_of(folder):
    return json.loads((folder / META_FILE).read_text())


def write_meta(folder, meta):
    (folder / META_FILE).write_text(json.dumps(meta))


def test_the_template_reads_back(template):
    rec = read_or_refuse(template)
    assert rec.n_samples == 200 and [e["field"] for e in rec.events] == ["th_g", "window_s"]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(sorted(META_FIELDS)), value=st.sampled_from(ODD_VALUES),
       remove=st.booleans())
def test_a_meta_field_removed_or_retyped_is_named(template, tmp_path_factory, field, value,
                                                   remove):
    folder = fresh_copy(template, tmp_path_factory)
    meta = meta_of(folder)
    if remove:
        del meta[field]
    else:
        meta[field] = value
    write_meta(folder, meta)
    answer = read_or_refuse(folder)
    if isinstance(answer, str):
        assert field in answer and META_FILE in answer
    else:                                   # the value happened to be one the field takes
        check, _ = META_FIELDS[field]
        assert not remove and check(value)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from([SAMPLES_FILE, RAW_FILE]), cut=st.integers(0, 4000),
       grow=st.booleans(), complete=st.booleans())
def test_a_data_file_of_another_size_than_meta_says_is_named(template, tmp_path_factory, name,
                                                            cut, grow, complete):
    folder = fresh_copy(template, tmp_path_factory)
    meta = meta_of(folder)
    meta["complete"] = complete
    write_meta(folder, meta)
    path = folder / name
    data = path.read_bytes()
    path.write_bytes(data + b"\x01" * cut if grow else data[:max(0, len(data) - cut)])
    answer = read_or_refuse(folder)
    size = path.stat().st_size
    whole = size - size % 16 if name == SAMPLES_FILE else size
    if isinstance(answer, str):
        assert name in answer and META_FILE in answer, answer
        assert whole < len(data) or complete
    else:                                   # as written, or more of it after a crash
        assert whole == len(data) or (not complete and whole > len(data))


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("kind", ["folder", "fifo", "device", "missing"])
def test_a_data_file_that_is_not_a_regular_file_is_refused_without_hanging(
        template, tmp_path_factory, name, kind):
    folder = fresh_copy(template, tmp_path_factory)
    path = folder / name
    path.unlink()
    if kind == "folder":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        path.symlink_to("/dev/zero")
    answer = read_or_refuse(folder)
    if kind == "missing" and name == EVENTS_FILE:
        assert answer.events == []          # no control change was made: no journal
        return
    assert isinstance(answer, str) and name in answer, answer


BAD_EVENTS = [
    ('{"sample": 10, "field": "th_g", "value": "high"}', "line 1 value"),
    ('{"sample": -3, "field": "th_g", "value": 0.1}', "line 1 sample"),
    ('{"sample": 10, "field": "gain", "value": 0.1}', "line 1 field"),
    ('{"sample": 10, "field": "th_g", "value": NaN}', "line 1 value"),
    ('{"sample": 99999, "field": "th_g", "value": 0.1}', "line 1 sample"),
    ('[1, 2, 3]', "line 1"),
    ('not json at all', "line 1"),
]


@pytest.mark.parametrize("line, named", BAD_EVENTS)
def test_a_control_change_a_replay_could_not_apply_is_named_with_its_line(
        template, tmp_path_factory, line, named):
    folder = fresh_copy(template, tmp_path_factory)
    (folder / EVENTS_FILE).write_text(line + "\n" + '{"sample": 1, "field": "th_g", '
                                                    '"value": 0.1}\n')
    answer = read_or_refuse(folder)
    assert isinstance(answer, str) and EVENTS_FILE in answer and named in answer, answer


def test_a_torn_last_event_line_from_a_killed_process_is_dropped(template, tmp_path_factory):
    folder = fresh_copy(template, tmp_path_factory)
    with open(folder / EVENTS_FILE, "a") as f:
        f.write('{"sample": 180, "field": "th_g", "va')
    assert len(read_or_refuse(folder).events) == 2


@pytest.mark.parametrize("field, value, named", [
    ("th_g", 99.0, "th_g"), ("window_s", 0.15, "window_s"), ("window_s", 100.0, "window_s")])
def test_a_journaled_change_this_network_cannot_take_is_refused_not_applied(field, value, named):
    with pytest.raises(SpecError) as caught:
        journaled_change({"sample": 120, "field": field, "value": value}, 0.1)
    assert f"{EVENTS_FILE} sample 120 {named}" in str(caught.value)


def test_a_window_journaled_in_seconds_replays_at_that_length_on_any_base_window():
    event = {"sample": 120, "field": "window_s", "value": 0.2}
    assert journaled_change(event, 0.1).value == 2.0        # two windows of 0.1 s
    assert journaled_change(event, 0.05).value == 4.0       # four of 0.05 s: still 0.2 s


@pytest.mark.parametrize("damage", ["not-json", "no-rate", "fifo-samples"])
def test_replay_of_a_damaged_recording_is_one_line_and_exit_2(template, tmp_path_factory, damage):
    folder = fresh_copy(template, tmp_path_factory)
    if damage == "not-json":
        (folder / META_FILE).write_bytes(b"\xff\xfe{")
    elif damage == "no-rate":
        meta = meta_of(folder)
        del meta["rate_hz"]
        write_meta(folder, meta)
    else:
        (folder / SAMPLES_FILE).unlink()
        os.mkfifo(folder / SAMPLES_FILE)
    done = subprocess.run([*CLI, "replay", str(folder)], capture_output=True, text=True,
                          timeout=60)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert "Traceback" not in done.stderr and str(Path(folder).name) in lines[0]


@pytest.mark.slow
@settings(max_examples=2000, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(sorted(META_FIELDS)),
       value=st.one_of(st.sampled_from(ODD_VALUES), st.integers(), st.floats(), st.text(),
                       st.lists(st.integers(), max_size=3)),
       remove=st.booleans())
def test_many_more_meta_fields_removed_or_retyped(template, tmp_path_factory, field, value,
                                                  remove):
    test_a_meta_field_removed_or_retyped_is_named.hypothesis.inner_test(
        template, tmp_path_factory, field, value, remove)
