"""Course scenes: speed profiles, contacts where the rod meets a post, refusals."""
import tomllib
from pathlib import Path

import numpy as np
import pytest

from snn_antenna import antenna
from snn_antenna.errors import SpecError
from snn_antenna.scenes import (CourseScene, Obstacle, SpeedProfile, random_course, rod_touch,
                                scene_from_spec)

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
    (event,) = rec.contacts
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
    for c in rec.contacts:
        assert 0 < c.distance_cm < antenna.ROD_LENGTH_CM


@pytest.mark.parametrize("profile", [
    SpeedProfile("constant", -5.0), SpeedProfile("constant", float("nan")),
    SpeedProfile("steps", points=[[0, 6], [3, -1]]),
    SpeedProfile("ramp", points=[[0, 0], [5, float("inf")]]),
    SpeedProfile("ramp", points=[[3, 0], [1, 10]]), SpeedProfile("zigzag")])
def test_bad_speeds_are_refused_with_the_field(profile):
    with pytest.raises(SpecError, match="speed"):
        CourseScene(speed=profile).generate()


def test_unknown_keys_and_kinds_are_refused():
    with pytest.raises(SpecError, match="stimulus.kind"):
        scene_from_spec({"kind": "maze"})
    with pytest.raises(SpecError, match="obstacles\\[0\\].colour"):
        scene_from_spec({"kind": "course", "obstacles": [{"x_cm": 1, "y_cm": 2, "colour": 3}]})
    with pytest.raises(SpecError, match="material"):
        CourseScene(obstacles=[Obstacle(10, 10, material="granite")]).validate()
