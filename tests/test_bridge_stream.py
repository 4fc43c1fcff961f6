"""The online pipeline live on a pty: emulator → stream (Brian2) → contacts, rate map, record."""
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from snn_antenna.bridge import load_recording
from snn_antenna.bridge.emulate.emulator import Emulator
from snn_antenna.bridge.emulate.links import PeerGone, PtyLink
from snn_antenna.bridge.online.pipeline import build_online, run_online
from snn_antenna.preprocess import CalibratedChain
from snn_antenna.bridge.wire.recorder import record_counts
from snn_antenna.bridge.wire.replay import ReplaySource
from snn_antenna.core.errors import SpecError
from snn_antenna.readout.contacts import ContactDetector, EpisodeTracker
from snn_antenna.core.signals import Recording
from snn_antenna.sources.stimuli import Contact, RobotScene

ROOT = Path(__file__).resolve().parents[1]
NETWORK = ROOT / "networks" / "resonator_array.toml"
CLI = [sys.executable, "-m", "snn_antenna.cli"]


def test_stream_detects_a_contact_live_and_records_everything(tmp_path):
    scene = RobotScene(duration_s=4.0, contacts=[Contact(2.0, 19.0)])
    counts = scene.generate(seed=3).samples
    link = PtyLink(tmp_path / "tty")
    emulator = Emulator(counts)

    def serve():
        try:
            emulator.run(link, peer_timeout_s=120)
        except PeerGone:
            pass
        link.disconnect()               # the board is unplugged once the scene is over

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    try:
        result = subprocess.run(
            [*CLI, "stream", "--port", link.path, "--network", NETWORK, "--out",
             tmp_path / "rec", "--duration", "8", "--json", "--set", "preprocess.threshold=0.05"],
            capture_output=True, text=True, timeout=150)
    finally:
        server.join(10)
        link.close()
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout[result.stdout.index("{\n"):])
    assert "rate map: 24 resonators" in result.stdout and "|" in result.stdout
    assert "contact onset" in result.stdout and "distance" in result.stdout
    assert len(report["contacts"]) == 1
    contact = report["contacts"][0]
    assert 1.9 <= contact["onset_s"] <= 2.5 and abs(contact["distance_cm"] - 19.0) < 3.0
    assert report["samples"] >= 3900 and report["compute_realtime_factor"] > 1.0
    # Steady-state latency exists only once the start-up backlog (compile, PCA calibration
    # second) is worked off; on a machine loaded by other jobs a 4 s scene may end first, so
    # latency is checked where it was measured, and its size is the benchmark's business.
    steady = report["steady_latency_ms"]
    if steady["windows"] > 0:
        assert 0 < steady["median"] < float("inf")
    rec = load_recording(tmp_path / "rec")
    assert rec.n_samples == len(emulator.log.written) == 4000
    assert np.array_equal(np.column_stack([rec.x, rec.y]), counts)


def test_online_contact_rule_matches_the_readout(tmp_path):
    """The live pipeline's episodes come from the read-out's EpisodeTracker, whose rule is the
    one stated in ContactDetector's docstring: checked here against that statement written
    out independently, over a whole rate map."""
    rng = np.random.default_rng(0)
    detector = ContactDetector()
    neuron_hz = np.geomspace(7, 30, 24)
    rates = rng.exponential(20, (24, 300)) * rng.integers(0, 2, (24, 300))
    frame = xr.DataArray(rates, dims=("neuron_hz", "window_s"),
                         coords={"neuron_hz": neuron_hz, "window_s": np.arange(300) * 0.1})
    above = frame.neuron_hz > detector.motion_band_hz[1]
    high, low = frame.where(above, 0).sum("neuron_hz"), frame.where(~above, 0).sum("neuron_hz")
    stated = ((high >= detector.min_rate_hz) & (high > low)).values
    assert stated.any() and not stated.all()
    assert detector.contact_windows(frame).values.tolist() == stated.tolist()
    tracker = EpisodeTracker(detector, neuron_hz, 0.1)
    onsets = [e[1] for t, r in zip(frame.window_s.values, rates.T)
              if (e := tracker.update(float(t), r)) and e[0] == "onset"]
    assert onsets == pytest.approx([e.onset_s for e in detector.detect(frame)])


def test_bad_network_spec_fails_before_the_port_opens(tmp_path):
    spec = tmp_path / "net.toml"
    spec.write_text("n_neurons = 24\nbandwidth = 3\n")
    with pytest.raises(SpecError, match="network.bandwidth"):
        build_online(spec)
    result = subprocess.run([*CLI, "stream", "--port", "/dev/ttyDOESNOTEXIST", "--network",
                             NETWORK, "--set", "network.dt_ms=5"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "network.dt_ms" in result.stderr


def test_calibrated_chain_does_not_depend_on_chunking():
    """The same samples chunked as a port might deliver them give the same coded signal."""
    counts = RobotScene(duration_s=3.0, contacts=[Contact(1.5, 19.0)]).generate(seed=5).samples
    parts = build_online(NETWORK, ["preprocess.threshold=0.05"])
    outputs, means = [], []
    for cuts in ([3000], [1, 998, 2, 700, 1299], list(np.diff(np.r_[0:3000:37, 3000]))):
        chain = CalibratedChain(parts.chain, 1000)
        pieces, start = [], 0
        for n in cuts:
            coded = chain.push(counts[start:start + n].astype(float))
            start += n
            if coded is not None:
                pieces.append(coded)
        outputs.append(np.concatenate(pieces))
        means.append(parts.chain.named_steps["align"].mean_.copy())
    # Fitted on exactly the first 1000 samples, whatever chunk crossed that mark.
    first_g = parts.chain.named_steps["to_g"].transform(counts[:1000].astype(float))
    for mean in means:
        assert np.allclose(mean, first_g.mean(axis=0), rtol=0, atol=1e-12)
    assert len(outputs[0]) == 3000 and np.count_nonzero(outputs[0]) > 100
    for other in outputs[1:]:
        assert np.array_equal(other, outputs[0])


LIVE_NETWORK = ROOT / "networks" / "live.toml"


def test_live_setting_detects_what_offline_detects(tmp_path):
    """networks/live.toml end to end (recording → decoder → chain → Brian2 stream → tracker)
    reports exactly the contacts that the offline array and read-out find in the same coded
    samples, and they are the scene's."""
    scene = RobotScene(duration_s=6.0, contacts=[Contact(2.0, 19.0), Contact(4.0, 27.0)])
    counts = scene.generate(seed=1).samples
    rec = record_counts(tmp_path / "rec", counts)
    overrides = ["preprocess.threshold=0.05"]
    live = run_online(ReplaySource(rec).start(), build_online(LIVE_NETWORK, overrides),
                      no_data_timeout_s=60)
    parts = build_online(LIVE_NETWORK, overrides)
    assert parts.array.dt_ms == 0.5 and parts.array.method == "rk2"
    coded = CalibratedChain(parts.chain, 1000).push(counts.astype(float))
    result = parts.array.run(Recording(coded, 1000.0, units="coded"), window_s=parts.window_s)
    offline = [e.as_dict() for e in parts.detector.detect(result.rate_map)]
    assert live["samples"] == len(counts) and len(live["contacts"]) == 2
    assert [sorted(c) for c in live["contacts"]] == [sorted(c) for c in offline]
    for online_contact, offline_contact in zip(live["contacts"], offline):
        for key, value in offline_contact.items():      # times: t + window in either order
            assert online_contact[key] == pytest.approx(value, rel=0, abs=1e-9), key
    for contact, cm in zip(live["contacts"], (19.0, 27.0)):
        assert abs(contact["distance_cm"] - cm) < 3.0
