"""The speed gate (Brian2 associative memory) and contact scoring under a threshold."""
import numpy as np
import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.networks.gate import SpeedGate
from snn_antenna.networks.resonators import ResonatorArray
from snn_antenna.preprocess import make_chain
from snn_antenna.readout.contacts import ContactDetector, ContactEstimate
from snn_antenna.evaluation.scoring import Score, score
from snn_antenna.readout.detection import run_codings
from snn_antenna.core.truth import Event
from snn_antenna.sources.scenes import CourseScene, Obstacle

# Recalled Th within a factor 1.6 of Th* on speeds never trained: one step of the gating
# study's threshold grid, i.e. the resolution at which Th* itself is known.
RECALL_TOLERANCE = 1.6
TRAIN = np.array([0.0, 6.0, 12.0, 18.0, 24.0, 30.0])
HELD_OUT = np.array([3.0, 15.0, 27.0])


def th_star(v):
    return 0.03 * np.exp(np.asarray(v, float) / 10.0)   # 0.03 g at rest, 0.6 g at 30 cm/s


@pytest.fixture(scope="module")
def gate():
    return SpeedGate(curve_points=1, target="numpy", seed=1).fit(
        TRAIN, th_star(TRAIN), test_speeds=np.r_[TRAIN, HELD_OUT])


def test_recall_on_held_out_speeds_is_within_tolerance(gate):
    recalled = gate.predict(HELD_OUT)
    ratio = recalled / th_star(HELD_OUT)
    assert np.all(ratio < RECALL_TOLERANCE) and np.all(ratio > 1 / RECALL_TOLERANCE), ratio
    # Learning happened: before training the read-out is silent (Th at the bottom of its code).
    curve = gate.learning_curve_
    err = np.abs(np.log(curve / th_star(curve.speed_cm_s)))
    assert float(err.isel(epoch=-1).mean()) < 0.5 * float(err.isel(epoch=0).mean())


def test_the_gate_sets_the_coder_threshold_online(gate):
    speed = np.r_[np.zeros(1500), np.full(1500, 30.0)]
    th = gate.thresholds(speed, 1000.0)
    assert th.shape == speed.shape and np.all(np.isfinite(th))
    slow, fast = np.median(th[1000:1500]), np.median(th[-500:])
    assert fast / slow > 0.5 * th_star(30) / th_star(0)
    chain = make_chain(1000.0).fit(np.zeros((10, 2)))
    x = np.full(3000, 0.3)
    coded = chain.named_steps["coder"].partial_transform(x, threshold=th)
    assert np.all(coded[1000:1500] != 0) and np.all(coded[-500:] == 0)   # 0.3 g: seen, then hidden


@pytest.mark.parametrize("speeds", [[-1.0, 10.0], [float("nan"), 10.0], [0.0, float("inf")]])
def test_negative_or_non_finite_speeds_are_refused(gate, speeds):
    with pytest.raises(SpecError, match="speed"):
        gate.predict(speeds)
    with pytest.raises(SpecError, match="speed"):
        gate.thresholds(np.array(speeds), 1000.0)
    with pytest.raises(SpecError, match="speeds"):
        SpeedGate(target="numpy").fit(speeds, [0.1, 0.2])


def test_threshold_beyond_the_signal_gives_no_detections_not_an_error():
    scene = CourseScene(duration_s=4.0, speed_cm_s=12.0, stop_after_contact_s=None,
                        obstacles=[Obstacle(30.0, 12.0)])
    rec = scene.generate(seed=2)
    assert rec.truth.contacts
    chain = make_chain(rec.rate_hz).fit(rec.samples)
    x = rec.samples
    for _, step in chain.steps[:-1]:
        x = step.transform(x)
    coder = chain.named_steps["coder"]
    coded = coder.partial_transform(np.c_[x, x], threshold=np.array([[0.1, 1e6]]))
    array = ResonatorArray(target="numpy")
    low, huge = run_codings(array, coded, rec.rate_hz)
    assert float(low.sum()) > 0 and float(huge.sum()) == 0
    detector = ContactDetector()
    assert detector.detect(huge) == []
    s = score([], rec.truth.contacts, rec.duration_s, detector, array, 0.1, settle_s=0.5)
    assert s.tp == 0 and s.fp == 0 and s.f1 in (0.0, None)


def test_a_scene_at_speed_zero_gives_no_self_motion_activity():
    array, detector = ResonatorArray(target="numpy"), ContactDetector()

    def spikes_in_motion_band(speed):
        rec = CourseScene(duration_s=2.0, speed_cm_s=speed, pan_amplitude_deg=40.0,
                          terrain="rough").generate(seed=4)
        chain = make_chain(rec.rate_hz, threshold=0.03).fit(rec.samples)
        rates = array.run(rec.with_samples(chain.transform(rec.samples), "coded")).rate_map
        band = rates.neuron_hz <= detector.motion_band_hz[1]
        return float(rates.where(band, 0).sum()), float(rates.sum())

    motion, total = spikes_in_motion_band(0.0)
    assert motion == 0 and total == 0
    motion, _ = spikes_in_motion_band(12.0)   # the same coder sees the driving robot's shaking
    assert motion > 0


def test_scoring_per_contact():
    array, detector = ResonatorArray(target="numpy"), ContactDetector()
    contacts = [Event("contact", 2.0, 1.0, 19.0), Event("contact", 5.0, 1.0, 19.0),
                Event("contact", 8.0, 1.0, 40.0)]           # 40 cm rings above the band
    det = [ContactEstimate(1.9, 2.5, 15.0, 19.0), ContactEstimate(2.6, 2.9, 15.0, 19.0),
           ContactEstimate(3.5, 3.8, 15.0, 19.0), ContactEstimate(8.1, 8.4, 40.0, 30.0),
           ContactEstimate(0.2, 0.4, 15.0, 19.0)]           # before settling: not scored
    s = score(det, contacts, 10.0, detector, array, window_s=0.1, settle_s=1.0)
    # The detection at 8.1 s fell on the out-of-band contact: its own category, decided here
    # from the true distance, neither a true nor a false positive (and never dropped earlier).
    assert (s.tp, s.fp, s.misses, s.duplicates) == (1, 1, 1, 1)
    assert (s.out_of_band_contacts, s.out_of_band_hits) == (1, 1)
    assert score(det[:3] + det[4:], contacts, 10.0, detector, array, 0.1,
                 1.0).out_of_band_hits == 0
    assert s.latencies_s == pytest.approx([0.0])
    assert s.f1 == pytest.approx(2 / 4) and s.fp_per_min == pytest.approx(1 / 0.15)
    total = s + Score(tp=1, minutes=1.5)
    assert total.tp == 2 and total.minutes == pytest.approx(1.65)


def test_study_spec_refuses_bad_speeds_before_any_work():
    from snn_antenna.core import spec as specs
    from snn_antenna.studies import gating_threshold
    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    for bad in ("[-3.0, 12.0]", "[0.0, nan]", "[0.0, 90.0]"):
        spec = specs.load(root / "studies" / "gating_threshold.toml",
                          [f"sweep.speeds_cm_s={bad}"], quick=True)
        with pytest.raises(SpecError, match="speed"):
            gating_threshold.plan(spec)
    spec = specs.load(root / "studies" / "gating_threshold.toml",
                      ["gate.train_speeds_cm_s=[0.0, 13.0]"], quick=True)
    with pytest.raises(SpecError, match="train_speeds_cm_s"):
        gating_threshold.plan(spec)


def test_th_star_is_the_monotone_fit_of_each_speeds_best_threshold():
    from snn_antenna.evaluation.thresholds import choose_th_star, monotone_th_star
    speeds = np.array([0.0, 6.0, 12.0, 18.0, 24.0])
    rising = np.array([0.03, 0.05, 0.1, 0.3, 0.6])
    assert monotone_th_star(speeds, rising, np.ones(5)) == pytest.approx(rising)
    # A speed whose best Th dips below a slower one's is pooled with it (geometric mean,
    # weighted by the contacts each speed scored); the result never falls with speed.
    dip = np.array([0.03, 0.1, 0.025, 0.3, 0.6])
    fitted = monotone_th_star(speeds, dip, np.array([5, 1, 3, 5, 5]))
    assert np.all(np.diff(fitted) >= 0)
    assert fitted[1] == pytest.approx(fitted[2]) == pytest.approx(np.exp(
        (np.log(0.1) + 3 * np.log(0.025)) / 4))
    assert fitted[0] == pytest.approx(0.03) and fitted[3:] == pytest.approx([0.3, 0.6])
    # Each speed's best Th: the middle of the widest F1 plateau, not its lucky edge.
    grid = np.array([0.0, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0])
    assert choose_th_star(grid, np.array([0.2, 0.5, 0.9, 0.9, 0.9, 0.4, 0.0])) == 0.1
