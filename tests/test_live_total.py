"""The live path is total: every rate-map shape is read out, and a failure inside the Brian2
network operation surfaces as the project's own error with the recording marked incomplete.

The crash this guards against: a contact that lasts exactly one window made
``ContactDetector.detect`` read the spacing of the first two windows of a one-window map
(IndexError inside Brian2's network operation, "unexpected error … please report", and a
``meta.json`` that still said complete/ok).
"""
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from snn_antenna.bridge import cli as bridge_cli
from snn_antenna.cli import main
from snn_antenna.bridge import load_recording
from snn_antenna.bridge.emulate.emulator import Emulator
from snn_antenna.bridge.emulate.links import PeerGone, PtyLink
from snn_antenna.bridge.online.pipeline import build_online, run_online
from snn_antenna.bridge.wire.recorder import record_counts
from snn_antenna.bridge.wire.replay import ReplaySource
from snn_antenna.core.errors import PipelineError, SpecError
from snn_antenna.readout.contacts import ContactDetector, EpisodeTracker
from snn_antenna.sources.stimuli import Contact, RobotScene

ROOT = Path(__file__).resolve().parents[1]
NETWORK = ROOT / "networks" / "resonator_array.toml"
CLI = [sys.executable, "-m", "snn_antenna.cli"]
# A contact 50 ms into a 1 s window rings out (≈ 0.3 s) inside that window: the episode is
# exactly one window long, the shape that crashed the read-out.
ONE_WINDOW = ["--set", "readout.window_s=1.0", "--set", "preprocess.threshold=0.05"]


@pytest.fixture(scope="module")
def one_window_counts():
    return RobotScene(duration_s=5.0, contacts=[Contact(2.05, 19.0)]).generate(seed=3).samples


def assert_one_window_contact(report: dict) -> None:
    assert len(report["contacts"]) == 1, report["contacts"]
    contact = report["contacts"][0]
    assert contact["end_s"] - contact["onset_s"] == pytest.approx(1.0)   # one window
    assert contact["onset_s"] == pytest.approx(2.0)
    assert abs(contact["distance_cm"] - 19.0) < 3.0


# -- the offline read-out on every shape --------------------------------------------------------
def rate_frame(rates, starts, window_s=0.1, attrs=True):
    neuron_hz = np.geomspace(7, 30, rates.shape[0])
    return xr.DataArray(rates, dims=("neuron_hz", "window_s"),
                        coords={"neuron_hz": neuron_hz, "window_s": np.asarray(starts, float)},
                        attrs={"window_s": window_s} if attrs else {})


NEURON_HZ = np.geomspace(7, 30, 24)
CONTACT = np.where(NEURON_HZ > 15, 40.0, 0.0)       # above the self-motion band
QUIET = np.where(NEURON_HZ < 10.5, 30.0, 0.0)       # self-motion only


@pytest.mark.parametrize("columns, expected", [
    ([], []),                                        # no window at all
    ([CONTACT], [(0.0, 0.1)]),                       # one window, a contact
    ([QUIET], []),                                   # one window, no contact
    ([CONTACT, QUIET, QUIET], [(0.0, 0.1)]),         # contact at the start
    ([QUIET, QUIET, CONTACT], [(0.2, 0.3)]),         # contact in the last window
    ([CONTACT, QUIET, CONTACT], [(0.0, 0.3)]),       # a gap of max_gap_windows bridged
])
def test_detect_reads_out_every_shape(columns, expected):
    rates = np.column_stack(columns) if columns else np.zeros((24, 0))
    found = ContactDetector().detect(rate_frame(rates, np.arange(len(columns)) * 0.1))
    assert [t for e in found for t in (e.onset_s, e.end_s)] == pytest.approx(
        [t for pair in expected for t in pair])


def test_detect_one_window_without_a_width_is_a_clear_error():
    one = rate_frame(CONTACT[:, None], [0.0], attrs=False)
    with pytest.raises(SpecError, match="window_s"):
        ContactDetector().detect(one)
    assert ContactDetector().detect(one, window_s=0.25)[0].end_s == pytest.approx(0.25)


def test_detect_refuses_what_is_not_a_rate_map():
    with pytest.raises(SpecError, match="rates"):
        ContactDetector().detect(np.zeros((24, 3)))
    with pytest.raises(SpecError, match="rates"):
        ContactDetector().detect(rate_frame(np.full((24, 2), np.nan), [0, 0.1]))


# -- the online read-out against the offline one (hypothesis) ----------------------------------
window_columns = st.lists(
    st.one_of(st.just(CONTACT), st.just(QUIET), st.just(np.zeros(24)),
              st.lists(st.floats(0, 200), min_size=24, max_size=24).map(np.array)),
    max_size=40)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(columns=window_columns, max_gap=st.integers(0, 3),
       window_s=st.sampled_from([0.01, 0.1, 0.25, 1.0]),
       gaps=st.lists(st.integers(0, 3), min_size=40, max_size=40))
def test_online_readout_is_total_and_agrees_with_offline(columns, max_gap, window_s, gaps):
    """Random window sequences (empty, one window, contacts at either end, holes in the
    time axis where samples were lost): the tracker never raises, and what it reports, window
    by window, is exactly what the offline read-out finds in the whole map."""
    detector = ContactDetector(max_gap_windows=max_gap)
    tracker = EpisodeTracker(detector, NEURON_HZ, window_s)
    starts = np.cumsum([0] + [1 + g for g in gaps[:max(len(columns) - 1, 0)]]) * window_s
    starts = starts[:len(columns)]
    for t_s, rates in zip(starts, columns):
        tracker.update(float(t_s), rates)
    tracker.close()
    rates = np.column_stack(columns) if columns else np.zeros((24, 0))
    offline = detector.detect(rate_frame(rates, starts, window_s))
    def flat(estimates):
        return [v for e in estimates for v in e.as_dict().values()]

    assert len(tracker.estimates) == len(offline)
    assert flat(tracker.estimates) == pytest.approx(flat(offline))


# -- the one-window contact through replay and stream ------------------------------------------
def test_one_window_contact_replays(tmp_path, one_window_counts):
    rec = record_counts(tmp_path / "rec", one_window_counts)
    result = subprocess.run([*CLI, "replay", str(rec), "--network", str(NETWORK), *ONE_WINDOW],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert_one_window_contact(json.loads(result.stdout[result.stdout.index("{\n"):]))


def serve(link, counts):
    """The emulator paced at 1 kHz on ``link`` in a thread; returns (emulator, thread)."""
    emulator = Emulator(counts)

    def run():
        try:
            emulator.run(link, peer_timeout_s=240)
        except PeerGone:
            pass
        link.disconnect()               # the board is unplugged once the scene is over

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return emulator, thread


@pytest.mark.slow    # 9 s at 1 kHz; the stream path is in the default suite by test_bridge_stream
def test_one_window_contact_streams(tmp_path, one_window_counts):
    link = PtyLink(tmp_path / "tty")
    _, server = serve(link, one_window_counts)
    try:
        result = subprocess.run(
            [*CLI, "stream", "--port", link.path, "--network", str(NETWORK), "--out",
             str(tmp_path / "rec"), "--duration", "9", "--json", *ONE_WINDOW],
            capture_output=True, text=True, timeout=300)
    finally:
        server.join(10)
        link.close()
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr and "please report" not in result.stderr
    assert_one_window_contact(json.loads(result.stdout[result.stdout.index("{\n"):]))
    rec = load_recording(tmp_path / "rec")
    assert rec.complete and rec.meta["status"] in ("ok", "port-error")


# -- a failure inside the network operation ----------------------------------------------------
def broken_update(self, t_s, rates, window_s=None):
    raise ZeroDivisionError("a bug in a read-out stage")


def test_failure_in_the_network_operation_is_a_pipeline_error(tmp_path, monkeypatch,
                                                              one_window_counts):
    rec = record_counts(tmp_path / "rec", one_window_counts[:1500])
    monkeypatch.setattr(EpisodeTracker, "update", broken_update)
    parts = build_online(NETWORK)
    with pytest.raises(PipelineError, match="ZeroDivisionError.*a bug in a read-out stage") as exc:
        run_online(ReplaySource(rec).start(), parts, no_data_timeout_s=60)
    assert isinstance(exc.value.__cause__, ZeroDivisionError)


def test_stream_failure_marks_the_recording_incomplete(tmp_path, monkeypatch, capsys,
                                                       one_window_counts):
    """In-process, so that the failure can be injected: one line, status 1, and meta.json says
    the session failed and why (never complete/ok)."""
    monkeypatch.setattr(EpisodeTracker, "update", broken_update)
    monkeypatch.setattr(bridge_cli, "stop_on_signals", threading.Event)  # pytest owns SIGINT
    link = PtyLink(tmp_path / "tty")
    _, server = serve(link, one_window_counts[:2500])
    try:
        code = main(["stream", "--port", link.path, "--network", str(NETWORK),
                                "--out", str(tmp_path / "rec"), "--duration", "9"])
    finally:
        link.close()
        server.join(10)
    err = capsys.readouterr().err
    assert code == 1
    assert "the live pipeline failed: ZeroDivisionError" in err and "Traceback" not in err
    meta = json.loads((tmp_path / "rec" / "meta.json").read_text())
    assert meta["complete"] is False and meta["status"] == "failed"
    assert "a bug in a read-out stage" in meta["message"]
