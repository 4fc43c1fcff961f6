"""Course scenes: speed profiles, contacts where the rod meets a post, refusals."""
import tomllib
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.sources import antenna
from snn_antenna.sources.scenes import (
    CourseScene,
    Obstacle,
    OnlineAntenna,
    SpeedProfile,
    random_course,
    rod_touch,
    scene_from_spec,
)

ROOT = Path(__file__).resolve().parents[1]


def test_speed_profiles_constant_steps_and_ramp():
    t = np.array([0.0, 1.0, 2.9, 3.0, 5.0, 9.0])
    assert np.all(SpeedProfile("constant", 12.0).at(t) == 12.0)
    steps = SpeedProfile("steps", points=[[0, 6], [3, 18], [6, 27]])
    assert steps.at(t).tolist() == [6, 6, 6, 18, 18, 27]
    ramp = SpeedProfile("ramp", points=[[0, 0], [10, 30]])
    assert ramp.at(t) == pytest.approx(3 * t)


def test_a_post_is_touched_where_the_rod_meets_it():
    """Antenna held 40° to the left; driving past a post of radius r at lateral offset y, the
    rod first meets it when the robot has come (r + y cos 40°) / sin 40° close, at
    (y + r cos 40°) / sin 40° along the rod."""
    pan, y, x0, v = 40.0, 12.0, 150.0, 20.0
    scene = CourseScene(duration_s=10.0, speed_cm_s=v, pan_deg=pan, stop_after_contact_s=None,
                        obstacles=[Obstacle(x0, y, radius_cm=0.6)])
    (contact,) = scene.plan()["contacts"]
    s, c = np.sin(np.deg2rad(pan)), np.cos(np.deg2rad(pan))
    dx = (0.6 + y * c) / s                         # base-to-post x offset at first touch
    assert contact.t_s == pytest.approx((x0 - dx) / v, abs=2e-3)
    assert contact.distance_cm == pytest.approx(dx * c + y * s, abs=0.05)
    assert contact.distance_cm == pytest.approx((y + 0.6 * c) / s, abs=0.05)
    assert contact.hold_s == 1.0
    rec = scene.generate(seed=1)
    (event,) = rec.truth.contacts
    assert event.t_s == contact.t_s and event.distance_cm == contact.distance_cm
    assert rec.samples.shape == (10000, 2) and rec.units == "counts"


def test_posts_beyond_the_tip_are_not_touched_and_contacts_do_not_overlap():
    far = Obstacle(100.0, antenna.ROD_LENGTH_CM * np.sin(np.deg2rad(40)) + 2.0)
    scene = CourseScene(duration_s=10.0, speed_cm_s=20.0, stop_after_contact_s=None,
                        obstacles=[far])
    assert scene.plan()["contacts"] == []
    touching, _ = rod_touch(np.zeros((1, 2)), 40.0, 0.0, far)
    assert not touching.any()
    # A robot standing still with its antenna sweeping touches the near post again and again,
    # never while the previous contact is still held.
    still = CourseScene(duration_s=12.0, speed_cm_s=0.0, pan_amplitude_deg=40.0,
                        obstacles=[Obstacle(15.0, 12.0)], stop_after_contact_s=None)
    contacts = still.plan()["contacts"]
    assert len(contacts) >= 4
    starts = np.array([c.t_s for c in contacts])
    assert np.all(np.diff(starts) >= 1.0)
    assert np.allclose([c.distance_cm for c in contacts], np.hypot(15.0, 12.0), atol=0.1)


def test_impact_rings_with_the_tip_speed_at_the_touch():
    """A still antenna driven past a post: the tip crosses the rod at v·sin(pan), so the impact
    is 2π·F_low·v·sin(pan)·transfer / g and doubles with speed; standing still, a post met at
    the sweep's turning point rings far less than one met mid-sweep."""
    pan, transfer = 40.0, 0.05
    amplitudes = []
    for v in (10.0, 20.0):
        scene = CourseScene(duration_s=20.0, speed_cm_s=v, pan_deg=pan, impact_transfer=transfer,
                            stop_after_contact_s=None, obstacles=[Obstacle(150.0, 12.0)])
        (contact,) = scene.plan()["contacts"]
        expected = (2 * np.pi * antenna.low_mode_hz(contact.distance_cm) * v
                    * np.sin(np.deg2rad(pan)) * transfer / antenna.G_CM_S2)
        assert contact.amplitude_g == pytest.approx(expected, rel=1e-3)
        amplitudes.append(contact.amplitude_g)
    assert amplitudes[1] == pytest.approx(2 * amplitudes[0], rel=1e-3)

    def still(bearing_deg):   # a post 20 cm out; the rod sweeps 40° ± 40°, 2 s per cycle
        b = np.deg2rad(bearing_deg)
        scene = CourseScene(duration_s=6.0, speed_cm_s=0.0, pan_amplitude_deg=40.0,
                            stop_after_contact_s=None,
                            obstacles=[Obstacle(20 * np.cos(b), 20 * np.sin(b))])
        return np.median([c.amplitude_g for c in scene.plan()["contacts"]])

    peak_tip = 41.3 * np.deg2rad(40.0) * 2 * np.pi / 2.0   # ω·L mid-sweep, cm/s
    assert still(40.0) == pytest.approx(float(antenna.impact_amplitude_g(20.0, peak_tip)),
                                        rel=0.05)
    # Near the turning point the rod's edge meets the post (radius 0.6 cm, 1.7° at 20 cm) where
    # the sweep's speed has fallen to cos(asin((78° − 1.7° − 40°) / 40°)) ≈ 0.42 of its peak.
    edge = np.rad2deg(np.arcsin(0.6 / 20.0))
    slow = np.cos(np.arcsin((78.0 - edge - 40.0) / 40.0))
    assert still(78.0) == pytest.approx(slow * still(40.0), rel=0.05)
    rec = CourseScene(duration_s=3.0, speed_cm_s=0.0, pan_amplitude_deg=40.0,
                      sensor_noise_g=0.0, obstacles=[Obstacle(15.3, 12.9)]).generate(seed=2)
    assert np.ptp(rec.samples, axis=0).max() > 0     # that touch does ring the rod
    with pytest.raises(SpecError, match="impact_transfer"):
        CourseScene(impact_transfer=1.5).validate()
    with pytest.raises(SpecError, match="tip_speed_cm_s"):
        antenna.impact_amplitude_g(20.0, np.nan)


def test_the_online_antenna_rings_like_the_planned_scene():
    """The closed loop's antenna, stepped along the planned poses, meets the same posts with
    the same impact amplitudes as ``CourseScene.plan``."""
    scene = CourseScene(duration_s=8.0, speed_cm_s=15.0, pan_amplitude_deg=40.0,
                        stop_after_contact_s=None,
                        obstacles=random_course(np.random.default_rng(4), 150.0))
    plan = scene.plan()
    world = OnlineAntenna(scene, seed=0)
    world.step(1, 15.0, plan["pan_deg"][0], plan["tilt_deg"][0])
    for i in range(1, len(plan["t_s"]) - 10, 10):
        world.step(10, 15.0, plan["pan_deg"][i + 9], plan["tilt_deg"][i + 9])
    assert len(world.contacts) == len(plan["contacts"]) >= 3
    for online, planned in zip(world.contacts, plan["contacts"]):
        assert online.t_s == pytest.approx(planned.t_s, abs=0.011)
        assert online.amplitude_g == pytest.approx(planned.amplitude_g, rel=0.1)


def test_the_robot_stops_after_a_contact_and_the_antenna_with_it():
    scene = CourseScene(duration_s=10.0, speed_cm_s=20.0, pan_amplitude_deg=30.0,
                        stop_after_contact_s=0.3, obstacles=random_course(
                            np.random.default_rng(2), 250.0))
    plan = scene.plan()
    first = plan["contacts"][0].t_s
    after = plan["t_s"] >= first + 0.3
    assert np.all(plan["speed_cm_s"][after] == 0) and len(plan["contacts"]) == 1
    assert np.ptp(plan["pan_deg"][after]) == 0


def test_a_robot_standing_still_does_not_shake_its_antenna():
    rec = CourseScene(duration_s=3.0, speed_cm_s=0.0, pan_amplitude_deg=40.0,
                      sensor_noise_g=0.0).generate(seed=3)
    assert np.ptp(rec.samples, axis=0).max() == 0   # gravity only: constant ADC counts


@pytest.mark.parametrize("name", ["robot_course", "robot_ramp", "robot_steps"])
def test_stimulus_specs_load_and_generate(name):
    with open(ROOT / "stimuli" / f"{name}.toml", "rb") as f:
        scene = scene_from_spec(tomllib.load(f))
    rec = scene.generate(seed=0)
    assert rec.n_samples == int(scene.duration_s * scene.rate_hz)
    speed = rec.meta["speed_cm_s"]
    assert speed.min() >= 0 and speed.max() <= 30
    for c in rec.truth.contacts:
        assert 0 < c.distance_cm < antenna.ROD_LENGTH_CM


@pytest.mark.parametrize("profile", [
    dict(kind="constant", speed_cm_s=-5.0), dict(kind="constant", speed_cm_s=float("nan")),
    dict(kind="steps", points=[[0, 6], [3, -1]]),
    dict(kind="ramp", points=[[0, 0], [5, float("inf")]]),
    dict(kind="ramp", points=[[3, 0], [1, 10]]), dict(kind="zigzag")])
def test_bad_speeds_are_refused_with_the_field(profile):
    with pytest.raises(SpecError, match="speed"):
        CourseScene(speed=SpeedProfile(**profile)).generate()


def test_unknown_keys_and_kinds_are_refused():
    with pytest.raises(SpecError, match="stimulus.kind"):
        scene_from_spec({"kind": "maze"})
    with pytest.raises(SpecError, match="obstacles\\[0\\].colour"):
        scene_from_spec({"kind": "course", "obstacles": [{"x_cm": 1, "y_cm": 2, "colour": 3}]})
    with pytest.raises(SpecError, match="material"):
        CourseScene(obstacles=[Obstacle(10, 10, material="granite")]).validate()


def test_course_impacts_sit_between_the_self_motion_at_low_and_high_speed():
    """The documented calibration of ``antenna.IMPACT_TRANSFER``: in the gating study's courses
    the impacts on posts the array can see are of the size of the shaking they compete with,
    above the self-motion at 12 cm/s and below twice that at 27 cm/s (the paper's Fig. 9)."""
    amplitudes = []
    for v in (0.0, 12.0, 27.0):
        for seed in range(6):
            obstacles = random_course(np.random.default_rng([seed, 7]), v * 15 + 80,
                                      materials=("wood", "aluminium"))
            scene = CourseScene(duration_s=15.0, speed_cm_s=v, pan_amplitude_deg=40.0,
                                stop_after_contact_s=None, obstacles=obstacles)
            amplitudes += [c.amplitude_g for c in scene.plan()["contacts"]
                           if 10.5 < antenna.low_mode_hz(c.distance_cm) <= 30.0]
    median = np.median(amplitudes)
    assert len(amplitudes) > 30
    assert antenna.self_motion_rms_g(12.0) < median < 2 * antenna.self_motion_rms_g(27.0)


def test_a_course_drive_lays_posts_for_the_whole_drive_from_its_own_stream():
    from snn_antenna.sources.scenes import (
        COURSE_MARGIN_CM,
        CourseLayout,
        course_drive,
        ramp,
        random_steps,
    )

    base = CourseScene(duration_s=2.0)
    layout = CourseLayout(spacing_cm=30.0, materials=("wood", "brass"))
    speed = ramp(0.0, 20.0, 10.0)
    scene = course_drive(base, speed, 10.0, layout, np.random.default_rng(1))
    assert scene.duration_s == 10.0 and scene.contacts == [] and scene.stop_after_contact_s is None
    assert max(o.x_cm for o in scene.obstacles) >= 20.0 * 10.0 + COURSE_MARGIN_CM - 1.3 * 30.0
    again = course_drive(base, speed, 10.0, layout, np.random.default_rng(1), terrain="rough")
    assert again.obstacles == scene.obstacles and again.terrain == "rough"
    steps = random_steps(np.random.default_rng(2), 5.0, 25.0, 8.0, 4)
    assert [p[0] for p in steps.points] == [0.0, 2.0, 4.0, 6.0]
    assert all(5.0 <= p[1] <= 25.0 for p in steps.points)
