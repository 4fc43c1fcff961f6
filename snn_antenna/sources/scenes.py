"""Robot scenes with a course: a speed profile, obstacles in the plane, a sweeping antenna.

The robot drives along +x from ``start_x_cm`` with speed ``profile`` (constant, steps or ramp,
0–30 cm/s in the studies). The antenna's base rides on the robot; the rod points ``pan_deg``
to the left of the heading, tilted ``tilt_deg`` above the horizon, and sweeps as the paper's
pan-tilt unit did (a limit cycle, 2 s by default; amplitude 0 holds it still). Obstacles are
vertical posts (the paper's 12 mm test rods). A contact arises when the rod enters a post:
its distance along the rod is where it touches (the post's centre projected on the rod), the
rod stays clamped there for ``hold_s`` (1 s), and contacts do not overlap (a touch during a
held contact is part of it). Posts met beyond the rod's tip are not touched. How hard the rod
rings depends on how fast it met the post: the tip's speed normal to the rod, from the robot's
motion and the sweep (``tip_normal_speed_cm_s``), sets the impact (``antenna.impact_amplitude_g``),
so a post met at a sweep's turning point while standing still barely rings, and one met
mid-sweep or at speed rings hard.

What shakes the probe is modelled in one place each: the self-oscillation near 7.8 Hz grows
with the square of speed (``antenna.self_motion_rms_g``), the terrain's broadband jolts grow
with the square of speed too, five times more on ``rough`` ground than on ``flat``
(``antenna.terrain_noise_rms_g``). These laws and the impact share
(``antenna.IMPACT_TRANSFER``) are calibration choices, not measurements: the speed² law was
chosen so that the best threshold at 27 cm/s is about five times that at 12 cm/s, and the
impact share so that doubling that threshold loses contacts (the paper's Fig. 9,
docs/reference.md). A study that finds those two numbers again reports them as calibrated. The
pan-tilt sweep itself is assumed smooth: it adds no
vibration, so a robot standing still produces no self-motion at all. When the robot stops
after a contact (``stop_after_contact_s``) the antenna stops sweeping too.

``CourseScene.generate`` returns the usual Recording (2 axes of ADC counts, contacts labelled
as events) with the robot's path, speed and antenna angles in ``meta``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..core import bounds
from ..core.errors import SpecError, check
from ..core.signals import Recording
from ..core.spec import check_section
from . import antenna
from .stimuli import Contact, RobotScene

SPEED_RANGE_CM_S = (0.0, antenna.SPEED_LIMIT_CM_S)
PROFILE_KINDS = ("constant", "steps", "ramp")


@dataclass
class SpeedProfile:
    """Robot speed over time (cm/s).

    ``constant``: ``speed_cm_s`` throughout. ``steps``: ``points`` = [[t_s, speed], ...], each
    speed held from its time on (before the first point: the first speed). ``ramp``: linear
    between the points, held flat outside them.
    """
    kind: str = "constant"
    speed_cm_s: float = 12.0
    points: list = field(default_factory=list)

    def __post_init__(self):
        bounds.declared(self)
        self.validate()

    def validate(self) -> None:
        bounds.choice("speed.kind", self.kind, PROFILE_KINDS)
        if self.kind == "constant":
            bounds.number("speed.speed_cm_s", self.speed_cm_s, *SPEED_RANGE_CM_S, unit=" cm/s")
            return
        pairs = isinstance(self.points, (list, tuple)) and all(
            isinstance(p, (list, tuple)) and len(p) == 2 and all(
                bounds._real(v) and abs(v) < 1e300 for v in p) for p in self.points)
        check(pairs and len(self.points) >= 1, "speed.points", self.points,
              "a list of [t_s, speed_cm_s] pairs of numbers")
        pts = np.asarray(self.points, dtype=float)
        check(pts.ndim == 2 and pts.shape[1] == 2 and len(pts) >= 1, "speed.points",
              self.points, "a list of [t_s, speed_cm_s] pairs")
        check(bool(np.all(np.isfinite(pts[:, 0]))) and bool(np.all(np.diff(pts[:, 0]) > 0))
              and pts[0, 0] >= 0, "speed.points", self.points,
              "times >= 0 s in increasing order")
        try:
            antenna.self_motion_rms_g(pts[:, 1])
        except SpecError as exc:
            raise SpecError("speed.points", self.points, exc.accepted) from None

    def at(self, t_s) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        if self.kind == "constant":
            return np.full(t.shape, float(self.speed_cm_s))
        pts = np.asarray(self.points, dtype=float)
        if self.kind == "ramp":
            return np.interp(t, pts[:, 0], pts[:, 1])
        idx = np.searchsorted(pts[:, 0], t, side="right") - 1
        return pts[np.clip(idx, 0, None), 1]


@dataclass
class Obstacle:
    """A vertical post at (x_cm, y_cm) in the plane (y to the robot's left)."""
    x_cm: float
    y_cm: float
    radius_cm: float = 0.6
    material: str = "wood"

    def __post_init__(self):
        bounds.declared(self)
        self.validate()

    def validate(self, i: int = 0) -> None:
        bounds.number(f"obstacles[{i}].x_cm", self.x_cm, -1e9, 1e9, unit=" cm")
        bounds.number(f"obstacles[{i}].y_cm", self.y_cm, -1e9, 1e9, unit=" cm")
        bounds.number(f"obstacles[{i}].radius_cm", self.radius_cm, 0.0, 20.0, lo_open=True,
                      hi_open=True, unit=" cm")
        bounds.choice(f"obstacles[{i}].material", self.material, sorted(antenna.MATERIALS))


def rod_touch(base_xy: np.ndarray, pan_deg, tilt_deg, obstacle: Obstacle,
              length_cm: float = antenna.ROD_LENGTH_CM) -> tuple[np.ndarray, np.ndarray]:
    """Per pose: does the rod touch the post, and at which distance along the rod (cm)?

    ``base_xy`` has shape (n, 2); angles are scalars or one per pose. The rod's shadow in the
    plane has length L·cos(tilt); a vertical post is touched where that shadow passes within
    the post's radius, at the along-rod distance (planar distance) / cos(tilt).
    """
    pan = np.deg2rad(np.asarray(pan_deg, dtype=float))
    tilt = np.deg2rad(np.asarray(tilt_deg, dtype=float))
    direction = np.stack(np.broadcast_arrays(np.cos(pan), np.sin(pan)), axis=-1)
    rel = np.array([obstacle.x_cm, obstacle.y_cm]) - np.asarray(base_xy, dtype=float)
    along = np.sum(rel * direction, axis=-1)                     # planar, from the base
    across = np.abs(rel[..., 0] * direction[..., 1] - rel[..., 1] * direction[..., 0])
    cos_tilt = np.cos(tilt)
    distance_cm = along / cos_tilt
    touching = (across <= obstacle.radius_cm) & (along > 0) & (distance_cm < length_cm - 0.05)
    return touching, distance_cm


def tip_normal_speed_cm_s(speed_cm_s, pan_deg, tilt_deg, rate_hz: float,
                          length_cm: float = antenna.ROD_LENGTH_CM) -> np.ndarray:
    """Speed (cm/s, signed) of the rod's tip across the rod, in the plane, per pose.

    The robot's velocity (speed along +x) seen across a rod at ``pan_deg`` plus the sweep's
    angular speed times the tip's planar radius; the tilt's own motion slides the rod along a
    vertical post and does not strike it.
    """
    pan = np.deg2rad(np.asarray(pan_deg, dtype=float))
    pan_rate = np.gradient(pan) * rate_hz if pan.size > 1 else np.zeros_like(pan)
    radius = length_cm * np.cos(np.deg2rad(np.asarray(tilt_deg, dtype=float)))
    return -np.asarray(speed_cm_s, dtype=float) * np.sin(pan) + radius * pan_rate


def contacts_from_poses(t_s: np.ndarray, base_xy: np.ndarray, pan_deg, tilt_deg,
                        obstacles: list[Obstacle], hold_s: float = 1.0,
                        tip_speed_cm_s=None, transfer: float = antenna.IMPACT_TRANSFER
                        ) -> list[Contact]:
    """Contacts where the rod enters a post; none begins while another is held.

    With ``tip_speed_cm_s`` (one per pose) each contact's ringing amplitude follows from the
    tip's speed at the moment of touch (``antenna.impact_amplitude_g``); without it the scene's
    ``impact_g`` applies.
    """
    entries = []
    for ob in obstacles:
        touching, distance = rod_touch(base_xy, pan_deg, tilt_deg, ob)
        touching = np.broadcast_to(touching, t_s.shape)
        distance = np.broadcast_to(distance, t_s.shape)
        starts = np.flatnonzero(touching[1:] & ~touching[:-1]) + 1
        entries += [(float(t_s[i]), float(distance[i]), ob.material, i) for i in starts]
    contacts, free_from = [], -np.inf
    for t, d, material, i in sorted(entries):
        if t >= free_from:
            amplitude = None if tip_speed_cm_s is None else float(
                antenna.impact_amplitude_g(d, np.broadcast_to(tip_speed_cm_s, t_s.shape)[i],
                                           transfer))
            contacts.append(Contact(t_s=t, distance_cm=d, material=material, hold_s=hold_s,
                                    amplitude_g=amplitude))
            free_from = t + hold_s
    return contacts


@dataclass
class CourseScene(RobotScene):
    """A RobotScene whose speed follows ``speed`` and whose contacts come from ``obstacles``.

    Explicit ``contacts`` (inherited) are kept as well, for scripted touches. Every field is
    a TOML key of a ``kind = "course"`` stimulus spec (see ``stimuli/robot_course.toml``).
    """
    speed: SpeedProfile | None = None        # None: constant ``speed_cm_s``
    obstacles: list[Obstacle] = field(default_factory=list)
    start_x_cm: float = 0.0
    pan_deg: float = 40.0                    # sweep centre, left of the heading (paper: 40°)
    pan_amplitude_deg: float = 0.0           # ± around the centre (paper's range: ±40°)
    tilt_deg: float = 0.0
    tilt_amplitude_deg: float = 0.0          # paper's range: ±45° around 10° above the horizon
    sweep_period_s: float = 2.0              # paper: a limit cycle of 2 s
    tilt_phase_deg: float = 90.0             # tilt leads pan: the tip sweeps an area
    hold_s: float = 1.0                      # how long each contact clamps the rod
    impact_transfer: float = antenna.IMPACT_TRANSFER  # see antenna.impact_amplitude_g

    @property
    def profile(self) -> SpeedProfile:
        return self.speed if self.speed is not None else SpeedProfile("constant", self.speed_cm_s)

    def describe(self) -> str:
        speed = self.profile
        pace = (f"at {speed.speed_cm_s:g} cm/s" if speed.kind == "constant" else
                f"at speeds {speed.kind} through " + ", ".join(f"{v:g}" for _, v in speed.points)
                + " cm/s")
        return (f"A robot drives {pace} for {self.duration_s:g} s (sampled at "
                f"{self.rate_hz:g} Hz) past {len(self.obstacles)} post(s).")

    def validate(self) -> None:
        bounds.instance("speed", self.speed, (SpeedProfile, type(None)), "a SpeedProfile")
        self.profile.validate()
        super().validate()
        bounds.instance("obstacles", self.obstacles, (list, tuple), "a list of Obstacle")
        for i, ob in enumerate(self.obstacles):
            bounds.instance(f"obstacles[{i}]", ob, Obstacle, "an Obstacle(x_cm, y_cm, ...)")
            ob.validate(i)
        for name in ("start_x_cm", "pan_deg", "pan_amplitude_deg", "tilt_deg",
                     "tilt_amplitude_deg", "tilt_phase_deg"):
            bounds.number(name, getattr(self, name), -1e9, 1e9)
        check(abs(self.tilt_deg) + abs(self.tilt_amplitude_deg) < 85, "tilt_amplitude_deg",
              self.tilt_amplitude_deg, "a tilt range within ±85° of the horizon")
        bounds.number("sweep_period_s", self.sweep_period_s, 0.0, lo_open=True, unit=" s")
        bounds.number("hold_s", self.hold_s, 0.0, lo_open=True, unit=" s")
        bounds.number("impact_transfer", self.impact_transfer, 0.0, 1.0, lo_open=True)

    def time(self) -> np.ndarray:
        return np.arange(int(round(self.duration_s * self.rate_hz))) / self.rate_hz

    def angles(self, t_s: np.ndarray, moving: np.ndarray | None = None):
        """Pan and tilt (deg) over time; the sweep's phase advances only while ``moving``."""
        dt = 1.0 / self.rate_hz
        active = np.ones(len(t_s), bool) if moving is None else moving
        phase = 2 * np.pi * np.cumsum(np.r_[0.0, active[:-1]] * dt) / self.sweep_period_s
        pan = self.pan_deg + self.pan_amplitude_deg * np.sin(phase)
        tilt = self.tilt_deg + self.tilt_amplitude_deg * np.sin(
            phase + np.deg2rad(self.tilt_phase_deg))
        return pan, tilt

    def plan(self) -> dict:
        """Kinematics and contacts: robot path, speed, angles, and the contacts they make."""
        t = self.time()
        dt = 1.0 / self.rate_hz
        speed = self.profile.at(t)
        moving = np.ones(len(t), bool)
        contacts = self._touches(t, speed, moving)
        if self.stop_after_contact_s is not None and contacts:
            stop = min(c.t_s for c in contacts) + self.stop_after_contact_s
            speed = np.where(t >= stop, 0.0, speed)
            moving = t < stop
            contacts = [c for c in self._touches(t, speed, moving) if c.t_s < stop]
        x = self.start_x_cm + np.cumsum(np.r_[0.0, speed[:-1]]) * dt
        pan, tilt = self.angles(t, moving)
        return {"t_s": t, "speed_cm_s": speed, "robot_x_cm": x, "pan_deg": pan,
                "tilt_deg": tilt, "contacts": contacts}

    def _touches(self, t, speed, moving) -> list[Contact]:
        dt = 1.0 / self.rate_hz
        x = self.start_x_cm + np.cumsum(np.r_[0.0, speed[:-1]]) * dt
        pan, tilt = self.angles(t, moving)
        base = np.c_[x, np.zeros_like(x)]
        tip = tip_normal_speed_cm_s(speed, pan, tilt, self.rate_hz)
        found = contacts_from_poses(t, base, pan, tilt, self.obstacles, self.hold_s, tip,
                                    self.impact_transfer)
        scripted = list(self.contacts)
        return sorted(scripted + found, key=lambda c: c.t_s)

    def speed_profile(self) -> np.ndarray:
        return self.plan()["speed_cm_s"]

    def generate(self, seed: int = 0) -> Recording:
        self.validate()
        bounds.seed("seed", seed)
        plan = self.plan()
        # The planned contacts become scripted ones: the base class rings the rod for each and
        # stops the robot after the first, exactly as planned.
        fixed = replace(self, obstacles=[], contacts=plan["contacts"])
        rec = RobotScene.generate(fixed, seed)
        rec.meta.update({k: plan[k] for k in ("robot_x_cm", "pan_deg", "tilt_deg")})
        rec.meta["speed_cm_s"] = plan["speed_cm_s"]
        return rec


def random_course(rng: np.random.Generator, length_cm: float, spacing_cm: float = 45.0,
                  lateral_cm: tuple = (8.0, 30.0), materials: tuple = ("wood",),
                  first_reach_cm: tuple = (12.0, 28.0), first_angle_deg: tuple = (20.0, 60.0),
                  radius_cm: float = 0.6) -> list[Obstacle]:
    """Posts along the path: one every ``spacing_cm`` (±30 %), at random lateral offsets.

    The first post stands within reach of the antenna at the start (``first_reach_cm`` from
    its base, ``first_angle_deg`` left of the heading), so a robot standing still touches
    something too as its antenna sweeps.
    """
    check(np.isfinite(spacing_cm) and spacing_cm > 0, "spacing_cm", spacing_cm,
          "a spacing > 0 cm")
    check(np.isfinite(length_cm) and length_cm > 0, "length_cm", length_cm, "a length > 0 cm")
    reach, angle = rng.uniform(*first_reach_cm), np.deg2rad(rng.uniform(*first_angle_deg))
    posts = [(reach * np.cos(angle), reach * np.sin(angle))]
    x = posts[0][0] + spacing_cm * rng.uniform(0.7, 1.3)
    while x < length_cm:
        posts.append((x, rng.uniform(*lateral_cm)))
        x += spacing_cm * rng.uniform(0.7, 1.3)
    return [Obstacle(float(px), float(py), radius_cm, str(rng.choice(list(materials))))
            for px, py in posts]


@dataclass(frozen=True)
class CourseLayout:
    """How posts are laid out along a course (``random_course``'s settings, a spec table)."""
    spacing_cm: float = 45.0
    lateral_cm: tuple = (8.0, 30.0)
    materials: tuple = ("wood",)
    first_reach_cm: tuple = (12.0, 28.0)
    first_angle_deg: tuple = (20.0, 60.0)

    def __post_init__(self):
        bounds.declared(self)
        bounds.number("spacing_cm", self.spacing_cm, 0.0, 1e9, lo_open=True, unit=" cm")
        bounds.pair("lateral_cm", self.lateral_cm, lo=-1e9, unit=" cm")
        bounds.pair("first_reach_cm", self.first_reach_cm, unit=" cm")
        bounds.pair("first_angle_deg", self.first_angle_deg, lo=-360.0, unit=" deg")

    def posts(self, rng: np.random.Generator, length_cm: float) -> list[Obstacle]:
        return random_course(rng, length_cm, self.spacing_cm, tuple(self.lateral_cm),
                             tuple(self.materials), tuple(self.first_reach_cm),
                             tuple(self.first_angle_deg))


# Posts are laid this far beyond the distance driven: the rod reaches ahead of the robot.
COURSE_MARGIN_CM = 80.0
PROFILE_SAMPLES = 50   # points at which a profile's top speed is read to size the course


def drive(base: CourseScene, speed: SpeedProfile, duration_s: float,
          obstacles: list[Obstacle], terrain: str | None = None) -> CourseScene:
    """``base`` driven along ``speed`` for ``duration_s`` past ``obstacles``: no scripted
    contacts and no stop after a contact (the scene is scored, not steered)."""
    return replace(base, duration_s=float(duration_s), speed=speed,
                   speed_cm_s=float(speed.at(0.0)), obstacles=list(obstacles), contacts=[],
                   stop_after_contact_s=None, terrain=base.terrain if terrain is None else terrain)


def course_drive(base: CourseScene, speed: SpeedProfile, duration_s: float,
                 layout: CourseLayout, rng: np.random.Generator,
                 terrain: str | None = None) -> CourseScene:
    """``drive`` along a new random course (``layout``) long enough for the whole drive."""
    top = float(np.max(speed.at(np.linspace(0, duration_s, PROFILE_SAMPLES))))
    return drive(base, speed, duration_s, layout.posts(rng, top * duration_s + COURSE_MARGIN_CM),
                 terrain)


def ramp(low_cm_s: float, high_cm_s: float, duration_s: float) -> SpeedProfile:
    """From ``low_cm_s`` at the start to ``high_cm_s`` at ``duration_s``."""
    return SpeedProfile("ramp", points=[[0.0, float(low_cm_s)], [float(duration_s),
                                                                float(high_cm_s)]])


def random_steps(rng: np.random.Generator, low_cm_s: float, high_cm_s: float,
                 duration_s: float, n_steps: int) -> SpeedProfile:
    """``n_steps`` equally long speeds drawn uniformly from [low, high]."""
    times = np.linspace(0.0, duration_s, n_steps + 1)[:-1]
    speeds = rng.uniform(low_cm_s, high_cm_s, n_steps)
    return SpeedProfile("steps", points=[[float(t), float(v)] for t, v in zip(times, speeds)])


def scene_from_spec(spec: dict) -> RobotScene:
    """Build a scene from a ``[stimulus]`` table: ``kind = "robot"`` (a ``RobotScene``, the
    default) or ``kind = "course"`` (a ``CourseScene``: obstacles, a speed profile). The one
    way every study, sweep and the emulator turn a stimulus table into a scene."""
    spec = dict(spec)
    kind = spec.pop("kind", "robot")
    check(kind in ("robot", "course"), "stimulus.kind", kind, "'robot' or 'course'")
    if kind == "course":
        check_section({"stimulus": spec}, "stimulus", CourseScene)
    if spec.get("stop_after_contact_s") == "never":   # TOML has no null
        spec["stop_after_contact_s"] = None
    contacts = []
    for i, table in enumerate(spec.pop("contacts", [])):
        check_section({f"contacts[{i}]": table}, f"contacts[{i}]", Contact)
        contacts.append(Contact(**table))
    if kind == "robot":
        return RobotScene(contacts=contacts, **spec)
    obstacles = []
    for i, table in enumerate(spec.pop("obstacles", [])):
        check_section({f"obstacles[{i}]": table}, f"obstacles[{i}]", Obstacle)
        obstacles.append(Obstacle(**table))
    speed = spec.pop("speed", None)
    if speed is not None:
        check_section({"speed": speed}, "speed", SpeedProfile)
        speed = SpeedProfile(**speed)
    return CourseScene(contacts=contacts, obstacles=obstacles, speed=speed, **spec)


class OnlineAntenna:
    """A course scene sample by sample, for closed loops: the caller moves robot and antenna.

    Each ``step(n, speed_cm_s, pan_deg, tilt_deg)`` advances the robot by n samples at that
    speed with the antenna at that pose, starts a contact where the rod enters a post (none
    while another is held), and returns the n samples the sensor board sends (2 axes of ADC
    counts). The physics is ``CourseScene.generate``'s, in streaming form: the driven mode's
    filter state carries over between calls (``antenna.resonant_noise`` with memory).
    """

    def __init__(self, scene: CourseScene, seed: int = 0):
        bounds.declared(self, scene=scene)
        bounds.seed("seed", seed)
        scene.validate()
        self.scene = scene
        self.rng = np.random.default_rng(seed)
        self.adc = antenna.ADC(scene.adc_bits, scene.full_scale_g)
        self.t_s = 0.0
        self.x_cm = float(scene.start_x_cm)
        self.contacts: list[Contact] = []
        self._touching = [False] * len(scene.obstacles)
        self._held_until = -np.inf
        self._mode = (antenna.NATURAL_HZ, antenna.NATURAL_TAU_S)
        self._zi = np.zeros(2)
        self._ringing = np.empty(0)
        self._pose = None

    def _filter(self):
        """The ringing mode's filter (the same one the offline scenes use)."""
        f, tau = self._mode
        return antenna.mode_filter(f, tau, self.scene.rate_hz)

    def step(self, n: int, speed_cm_s: float, pan_deg: float, tilt_deg: float) -> np.ndarray:
        from scipy.signal import lfilter

        sc = self.scene
        antenna.self_motion_rms_g(speed_cm_s)
        # The rod sweeps through the chunk: poses interpolated sample by sample from the last
        # call's, so a post passed between two calls is still met.
        first = self._pose is None
        last = (pan_deg, tilt_deg) if first else self._pose
        frac = np.arange(1, n + 1) / n
        pan = last[0] + (pan_deg - last[0]) * frac
        tilt = last[1] + (tilt_deg - last[1]) * frac
        base = np.c_[self.x_cm + speed_cm_s * np.arange(n) / sc.rate_hz, np.zeros(n)]
        self._pose = (pan_deg, tilt_deg)
        tip = tip_normal_speed_cm_s(speed_cm_s, np.r_[last[0], pan], np.r_[last[1], tilt],
                                    sc.rate_hz)[1:]
        entries = []
        for k, ob in enumerate(sc.obstacles):
            touching, distance = rod_touch(base, pan, tilt, ob)
            # A rod that starts inside a post has not entered it (as in ``contacts_from_poses``).
            was = np.r_[touching[0] if first else self._touching[k], touching[:-1]]
            entries += [(i, float(distance[i]), ob.material)
                        for i in np.flatnonzero(touching & ~was)]
            self._touching[k] = bool(touching[-1])
        for i, d, material in sorted(entries):
            t_i = self.t_s + i / sc.rate_hz
            if t_i < self._held_until:
                continue
            amplitude = float(antenna.impact_amplitude_g(d, tip[i], sc.impact_transfer))
            self.contacts.append(Contact(t_i, d, material, sc.hold_s, amplitude))
            self._held_until = t_i + sc.hold_s
            self._mode = (float(antenna.low_mode_hz(d)),
                          float(antenna.decay_times_s(d, material)[0]))
            self._ringing = np.r_[np.zeros(i), antenna.contact_ringing(
                d, material, sc.rate_hz, int(round(sc.hold_s * sc.rate_hz)), self.rng,
                amplitude)]
        if self.t_s >= self._held_until and self._mode[0] != antenna.NATURAL_HZ:
            self._mode = (antenna.NATURAL_HZ, antenna.NATURAL_TAU_S)
        b, a = self._filter()
        drive = self.rng.standard_normal(n) * float(antenna.self_motion_rms_g(speed_cm_s))
        main, self._zi = lfilter(b, a, drive, zi=self._zi)
        main = main + self.rng.standard_normal(n) * float(
            antenna.terrain_noise_rms_g(speed_cm_s, sc.terrain))
        ring, self._ringing = self._ringing[:n], self._ringing[n:]
        main[:len(ring)] += ring
        xy = antenna.project(main, sc.orientation_deg)
        xy += self.rng.standard_normal(xy.shape) * sc.sensor_noise_g
        self.t_s += n / sc.rate_hz
        self.x_cm += speed_cm_s * n / sc.rate_hz
        return self.adc.to_counts(xy)
