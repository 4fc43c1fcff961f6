"""Ground-truth scramble tests: every read-out the studies use decides the same with lying labels.

For each read-out, a generated recording (or bench data set) is read twice: as generated, and
with its labels moved, deleted and invented (``scrambles``) while its samples stay untouched.
The decisions must be identical; only the scores, computed afterwards from the labels, may
change. ``tests/test_layout.py`` keeps the read-outs from importing the labels at all; these
tests check the behaviour end to end, through the studies' own code paths.

The quickstart and gating studies' read-outs are scrambled in their own test files
(``test_quickstart.py``, ``test_gating_study.py``), with ``scrambles`` from here.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.core.truth import BENCH_LABELS, Event, GroundTruth


# -- the scrambles --------------------------------------------------------------------------
def scrambles(truth: GroundTruth, duration_s: float, seed: int = 0) -> dict[str, GroundTruth]:
    """The labels of one recording, lied about three ways (samples are never touched):
    ``moved`` (every event at another time, distance and material), ``deleted`` (no events)
    and ``invented`` (the true events plus three that never happened)."""
    rng = np.random.default_rng(seed)

    def anywhere(kind="contact", hold_s=0.5):
        return Event(kind, float(rng.uniform(0.1, duration_s - hold_s)), hold_s,
                     float(rng.uniform(8.0, 40.0)), str(rng.choice(["brass", "wood", "pvc"])))

    moved = tuple(anywhere(e.kind, min(e.duration_s, duration_s / 4)) for e in truth.events)
    return {"moved": GroundTruth(moved), "deleted": GroundTruth(()),
            "invented": GroundTruth(truth.events + tuple(anywhere() for _ in range(3)))}


def scrambled_bench(data, seed: int = 0) -> dict:
    """A bench data set with its labels (``truth.BENCH_LABELS``) lied about: ``moved``
    (each label permuted over the events), ``deleted`` (every event the same label) and
    ``invented`` (labels no bench ever had)."""
    rng = np.random.default_rng(seed)
    n = data.sizes["event"]
    moved = {name: ("event", rng.permutation(data[name].values)) for name in BENCH_LABELS}
    deleted = {name: ("event", np.repeat(data[name].values[:1], n)) for name in BENCH_LABELS}
    invented = {"material": ("event", np.array(["unobtainium"] * n)),
                "distance_cm": ("event", rng.uniform(-5, 90, n)),
                "position": ("event", rng.integers(100, 200, n)),
                "repetition": ("event", rng.integers(0, 3, n))}
    return {how: data.assign_coords(labels) for how, labels in
            (("moved", moved), ("deleted", deleted), ("invented", invented))}


def test_scrambles_change_every_label_and_no_sample():
    truth = GroundTruth((Event("contact", 2.0, 1.0, 19.0, "wood"),))
    lies = scrambles(truth, 10.0)
    assert lies["moved"].contacts[0] != truth.contacts[0]
    assert not lies["deleted"].contacts
    assert set(truth.contacts) < set(lies["invented"].contacts)


# -- bench features and spiking decoders ------------------------------------------------------
@pytest.fixture(scope="module")
def bench_data():
    from snn_antenna.sources import bench

    return bench.generate(bench.BenchSpec(materials=("wood", "aluminium", "brass"),
                                          positions_cm=(12.0, 24.0, 36.0), repetitions=2,
                                          duration_s=0.25), log=lambda *_: None)


def test_bench_features_and_spiking_decoders_ignore_the_labels(bench_data):
    """The paper's FFT/parametric features, the spiking bank's features, the decoders' input
    matrices and the training-free decoders' decisions are the same under lying labels; the
    scores against the labels (afterwards) are not."""
    from snn_antenna.engine.events import run_bank
    from snn_antenna.evaluation.crossval import Evaluation, score
    from snn_antenna.evaluation.signal import with_labels
    from snn_antenna.readout import events
    from snn_antenna.readout.spiking import LOW_BAND, SpikingBank, recording_attrs
    from snn_antenna.readout.spiking_decoders import decoder_inputs, spiking_baselines

    processor = events.EventProcessor(rate_hz=float(bench_data.attrs["rate_hz"]))
    bank = SpikingBank(bands={"low": LOW_BAND}, duration_s=0.2, batch_events=32,
                       target="numpy")
    quiet = dict(log=lambda *_: None)

    def decide(data):
        feats = events.process(data, processor, **quiet)
        spikes = run_bank(bank, data["counts"].values, *recording_attrs(data),
                          progress=False).to_dataset(data["event"].values, bank.bin_edges_s)
        inputs = decoder_inputs(with_labels(feats, data), spikes)
        X = inputs["spiking_low_counts"].values
        dominant = {b.name: b.build(0).fit(X).predict(X)
                    for b in spiking_baselines(spikes, Evaluation())
                    if b.inputs == "spiking_low_counts"}
        return feats, spikes, inputs, dominant

    honest = decide(bench_data)
    true_d = bench_data["distance_cm"].values.astype(float)
    for how, lying in scrambled_bench(bench_data).items():
        feats, spikes, inputs, dominant = decide(lying)
        assert feats.drop_attrs().identical(honest[0].drop_attrs()), how
        for name in spikes.data_vars:
            np.testing.assert_array_equal(spikes[name].values, honest[1][name].values)
        for name in ("spiking_low", "spiking_low_counts"):
            np.testing.assert_array_equal(inputs[name].values, honest[2][name].values)
        for name, prediction in dominant.items():
            np.testing.assert_array_equal(prediction, honest[3][name])
            # the same decisions, scored against other labels, score differently
            lied_d = lying["distance_cm"].values.astype(float)
            if not np.array_equal(lied_d, true_d):
                assert (score("distance", lied_d, prediction)
                        != score("distance", true_d, prediction)), (how, name)


def test_bench_features_carry_no_labels_until_evaluation_joins_them(bench_data):
    """The read-out's feature set has no label coordinates; ``with_labels`` (evaluation)
    joins the data set's, event by event."""
    from snn_antenna.evaluation.signal import with_labels
    from snn_antenna.readout import events

    feats = events.process(bench_data, events.EventProcessor(
        rate_hz=float(bench_data.attrs["rate_hz"])), log=lambda *_: None)
    assert not set(BENCH_LABELS) & set(feats.coords)
    joined = with_labels(feats.isel(event=[4, 1]), bench_data)
    for name in BENCH_LABELS:
        np.testing.assert_array_equal(joined[name].values, bench_data[name].values[[4, 1]])


# -- the live tracker ---------------------------------------------------------------------------
def test_the_live_tracker_ignores_the_labels(tmp_path):
    """A scene streamed through the live pipeline (replayed from a recording of its counts):
    the contacts it reports are one list, whatever the scene's labels say; scoring them
    against the true and the lying labels differs."""
    from snn_antenna.bridge.online.pipeline import build_online, run_online
    from snn_antenna.bridge.wire.recorder import record_counts
    from snn_antenna.bridge.wire.replay import ReplaySource
    from snn_antenna.evaluation.scoring import score
    from snn_antenna.readout.contacts import ContactEstimate
    from snn_antenna.sources.stimuli import Contact, RobotScene

    network = Path(__file__).resolve().parents[1] / "networks" / "resonator_array.toml"
    rec = RobotScene(duration_s=6.0, contacts=[Contact(3.0, 19.0)]).generate(seed=5)

    def live_contacts(recording):
        path = record_counts(tmp_path / f"r{len(list(tmp_path.iterdir()))}", recording.samples)
        parts = build_online(network)
        report = run_online(ReplaySource(path).start(), parts,
                            no_data_timeout_s=60)
        return parts, report["contacts"]

    parts, honest = live_contacts(rec)
    assert honest, "the scene's contact should be found live"
    estimates = [ContactEstimate(**{k: c[k] for k in ("onset_s", "end_s", "frequency_hz",
                                                      "distance_cm")}) for c in honest]

    def scored(truth):
        return score(estimates, truth.contacts, rec.duration_s, parts.detector, parts.array,
                     parts.window_s, settle_s=1.0).as_dict()

    lies = scrambles(rec.truth, rec.duration_s)
    # The live path takes counts only (a recording's labels never reach the link), so one
    # lying run stands for all three: the same decisions, whatever the labels.
    _, lied_to = live_contacts(dataclasses.replace(rec, truth=lies["moved"]))
    assert lied_to == honest
    for how, truth in lies.items():
        assert scored(truth) != scored(rec.truth), how
