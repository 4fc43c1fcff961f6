"""Stimuli: test waveforms and antenna scenes, each returned as a labelled Recording.

Waveforms (``sine``, ``square``, ``chirp``, ``pulse_train``, ``silence``, ``dc``) are one
channel in arbitrary units: they drive neurons directly when tuning k, b and I. Scenes model
the antenna on the robot and return what the sensor board sends: two axes of ADC counts at its
sample rate, with the contacts labelled.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import bounds
from ..core.errors import check
from ..core.signals import Recording
from ..core.truth import Event, GroundTruth
from ..report.page import Calibrated
from . import antenna
from .source import Generated


def _n(duration_s: float, rate_hz: float, bytes_per_sample: int = 16) -> int:
    """Samples in ``duration_s`` at ``rate_hz``: both bounded, and at least one sample that
    fits in memory (``bounds.n_samples``)."""
    rate = bounds.rate_hz("rate_hz", rate_hz)
    n = bounds.n_samples("duration_s", duration_s, rate, bytes_per_sample)
    check(n >= 1, "duration_s", duration_s, f"a duration of at least one sample "
                                            f"({1 / rate:g} s at {rate:g} Hz)")
    return n


def _time(duration_s: float, rate_hz: float) -> np.ndarray:
    return np.arange(_n(duration_s, rate_hz)) / rate_hz


def _check_freq(freq_hz: float, rate_hz: float, name: str = "freq_hz") -> None:
    bounds.number(name, freq_hz, 0.0, rate_hz / 2, lo_open=True, hi_open=True,
                  unit=f" Hz (below Nyquist at {rate_hz:g} Hz)")


def sine(freq_hz: float, duration_s: float, rate_hz: float = 1000.0,
         amplitude: float = 1.0, phase: float = 0.0) -> Recording:
    t = _time(duration_s, rate_hz)
    _check_freq(freq_hz, rate_hz)
    bounds.amplitude("amplitude", amplitude)
    bounds.number("phase", phase, -1e6, 1e6)
    return Recording(amplitude * np.sin(2 * np.pi * freq_hz * t + phase), rate_hz, units="a.u.")


def square(freq_hz: float, duration_s: float, rate_hz: float = 1000.0,
           amplitude: float = 1.0) -> Recording:
    t = _time(duration_s, rate_hz)
    _check_freq(freq_hz, rate_hz)
    bounds.amplitude("amplitude", amplitude)
    # Half-period index parity avoids sign(0) = 0 at the sampled zero crossings.
    half = np.floor(2 * freq_hz * t).astype(int)
    return Recording(amplitude * np.where(half % 2 == 0, 1.0, -1.0), rate_hz, units="a.u.")


def chirp(f0_hz: float, f1_hz: float, duration_s: float, rate_hz: float = 1000.0,
          amplitude: float = 1.0, method: str = "logarithmic") -> Recording:
    from scipy.signal import chirp as scipy_chirp

    t = _time(duration_s, rate_hz)
    _check_freq(f0_hz, rate_hz, "f0_hz")
    _check_freq(f1_hz, rate_hz, "f1_hz")
    bounds.amplitude("amplitude", amplitude)
    check(method in ("linear", "logarithmic"), "method", method, "'linear' or 'logarithmic'")
    return Recording(amplitude * scipy_chirp(t, f0_hz, t[-1] if len(t) > 1 else 1.0, f1_hz,
                                             method=method), rate_hz, units="a.u.")


def pulse_train(rate_per_s: float, duration_s: float, rate_hz: float = 1000.0,
                amplitude: float = 1.0, width_s: float | None = None) -> Recording:
    t = _time(duration_s, rate_hz)
    _check_freq(rate_per_s, rate_hz, "rate_per_s")
    bounds.amplitude("amplitude", amplitude)
    width_s = 1.0 / rate_hz if width_s is None else width_s
    bounds.number("width_s", width_s, 0.0, 1.0 / rate_per_s, lo_open=True, hi_open=True,
                  unit=" s")
    return Recording(amplitude * ((t * rate_per_s) % 1.0 < width_s * rate_per_s), rate_hz,
                     units="a.u.")


def silence(duration_s: float, rate_hz: float = 1000.0) -> Recording:
    return Recording(np.zeros_like(_time(duration_s, rate_hz)), rate_hz, units="a.u.")


def dc(level: float, duration_s: float, rate_hz: float = 1000.0) -> Recording:
    bounds.amplitude("level", level)
    return Recording(np.full_like(_time(duration_s, rate_hz), level), rate_hz, units="a.u.")


def self_motion(speed_cm_s: float, duration_s: float, rate_hz: float = 1000.0,
                seed: int = 0, terrain: str = "flat") -> Recording:
    """The probe's own oscillation while the robot drives, in g along the main axis."""
    t = _time(duration_s, rate_hz)
    rng = np.random.default_rng(bounds.seed("seed", seed))
    rms = antenna.self_motion_rms_g(bounds.number("speed_cm_s", speed_cm_s))
    bounds.choice("terrain", terrain, sorted(antenna.TERRAIN_NOISE_G_AT_12))
    return Recording(_motion(np.full(len(t), rms), np.full(len(t), antenna.NATURAL_HZ),
                             np.full(len(t), antenna.NATURAL_TAU_S), speed_cm_s, terrain,
                             rate_hz, rng), rate_hz)


def _motion(rms_g, freq_hz, tau_s, speed_cm_s, terrain, rate_hz, rng) -> np.ndarray:
    """Driven ringing in segments of constant mode, plus broadband terrain noise."""
    n = len(rms_g)
    jolts = antenna.terrain_noise_rms_g(np.broadcast_to(speed_cm_s, (n,)), terrain)
    out = np.zeros(n)
    # Segment boundaries where the ringing mode changes (contact begins or ends).
    change = np.flatnonzero(np.diff(freq_hz) != 0) + 1
    for lo, hi in zip(np.r_[0, change], np.r_[change, n]):
        out[lo:hi] = antenna.resonant_noise(freq_hz[lo], tau_s[lo], rms_g[lo:hi], rate_hz, rng,
                                            hi - lo)
    return out + rng.standard_normal(n) * jolts


@dataclass
class Contact:
    t_s: float
    distance_cm: float
    material: str = "wood"
    hold_s: float = 1.0
    amplitude_g: float | None = None   # the impact's ringing; None: the scene's ``impact_g``

    def __post_init__(self):
        """Bounded alone; the scene checks it against its duration and sample rate."""
        bounds.declared(self)
        bounds.choice("material", self.material, sorted(antenna.MATERIALS))
        bounds.number("t_s", self.t_s, 0.0, bounds.MAX_SECONDS, unit=" s")
        bounds.number("hold_s", self.hold_s, 0.0, bounds.MAX_SECONDS, lo_open=True, unit=" s")
        bounds.number("distance_cm", self.distance_cm, 0.0, antenna.ROD_LENGTH_CM,
                      lo_open=True, hi_open=True, unit=" cm")
        if self.amplitude_g is not None:
            bounds.number("amplitude_g", self.amplitude_g, 0.0, bounds.MAX_AMPLITUDE)


@dataclass
class RobotScene(Generated):
    """A robot driving at ``speed_cm_s`` whose antenna touches objects.

    On each contact the rod is clamped at ``distance_cm`` for ``hold_s``: the impact makes it
    ring in its two modes, and while the robot still moves its shaking drives the clamped rod at
    its new low mode instead of the free rod's 7.8 Hz. The robot stops ``stop_after_contact_s``
    after the first contact (the control layer's reflex; ``None``, ``"never"`` in a spec, keeps
    driving); once stopped there is no more self-motion and the ringing decays.
    """
    duration_s: float = 8.0
    rate_hz: float = 1000.0
    speed_cm_s: float = 12.0
    terrain: str = "flat"
    contacts: list[Contact] = field(default_factory=list)
    stop_after_contact_s: float | None = 0.3
    orientation_deg: float = 30.0
    impact_g: float = 2.0
    sensor_noise_g: float = 0.01
    adc_bits: int = 10
    full_scale_g: float = 18.0

    def __post_init__(self):
        bounds.declared(self)
        self.validate()

    def validate(self) -> None:
        """Every field typed and bounded, before a sample is made (the scene's memory too)."""
        _n(self.duration_s, self.rate_hz, bounds.SCENE_BYTES_PER_SAMPLE)
        check(antenna.NATURAL_HZ < 0.45 * self.rate_hz, "rate_hz", self.rate_hz,
              f"a sample rate above {antenna.NATURAL_HZ / 0.45:.0f} Hz (the probe's "
              f"self-oscillation at {antenna.NATURAL_HZ} Hz must be sampled)")
        speed = bounds.number("speed_cm_s", self.speed_cm_s, 0.0, antenna.SPEED_LIMIT_CM_S,
                              unit=" cm/s")
        antenna.self_motion_rms_g(speed)
        bounds.choice("terrain", self.terrain, sorted(antenna.TERRAIN_NOISE_G_AT_12))
        if self.stop_after_contact_s is not None:
            bounds.number("stop_after_contact_s", self.stop_after_contact_s, 0.0, unit=" s")
        bounds.number("orientation_deg", self.orientation_deg, -360.0, 360.0)
        bounds.number("sensor_noise_g", self.sensor_noise_g, 0.0, bounds.MAX_AMPLITUDE)
        bounds.number("impact_g", self.impact_g, 0.0, bounds.MAX_AMPLITUDE, lo_open=True)
        bounds.integer("adc_bits", self.adc_bits, 4, 24)
        bounds.number("full_scale_g", self.full_scale_g, 0.0, bounds.MAX_AMPLITUDE, lo_open=True)
        bounds.instance("contacts", self.contacts, (list, tuple), "a list of Contact")
        for i, c in enumerate(self.contacts):
            bounds.instance(f"contacts[{i}]", c, Contact,
                            "a stimuli.Contact(t_s, distance_cm, material, hold_s)")
            bounds.number(f"contacts[{i}].t_s", c.t_s, 0.0, self.duration_s, hi_open=True,
                          unit=" s")
            bounds.number(f"contacts[{i}].hold_s", c.hold_s, 0.0, lo_open=True, unit=" s")
            bounds.number(f"contacts[{i}].distance_cm", c.distance_cm, 0.0,
                          antenna.ROD_LENGTH_CM, lo_open=True, hi_open=True, unit=" cm")
            bounds.choice(f"contacts[{i}].material", c.material, sorted(antenna.MATERIALS))
            if c.amplitude_g is not None:
                bounds.number(f"contacts[{i}].amplitude_g", c.amplitude_g, 0.0,
                              bounds.MAX_AMPLITUDE)
            f_low = float(antenna.low_mode_hz(c.distance_cm))
            check(f_low < 0.45 * self.rate_hz, "rate_hz", self.rate_hz,
                  f"a sample rate above {f_low / 0.45:.0f} Hz for the contact at "
                  f"{c.distance_cm} cm")
        antenna.ADC(self.adc_bits, self.full_scale_g)

    def describe(self) -> str:
        touches = "; ".join(f"at {c.t_s:g} s on {c.material} {c.distance_cm:g} cm along the rod"
                            for c in self.contacts) or "nothing"
        last = max((c.t_s for c in self.contacts), default=0.0)
        return (f"A robot drives at {self.speed_cm_s:g} cm/s for {self.duration_s:g} s "
                f"(sampled at {self.rate_hz:g} Hz); its antenna touches {touches}, then it "
                f"drives on for {self.duration_s - last:g} s.")

    def calibrated(self) -> list[Calibrated]:
        """The generator's constants set to the paper's numbers."""
        return [
            Calibrated("free probe's self-oscillation while driving (generator)",
                       antenna.NATURAL_HZ, 7.8, "Hz", "docs/reference.md, robot experiments "
                       "(paper: Results, spiking-based processing)",
                       "antenna.NATURAL_HZ set to the paper's peak"),
            Calibrated("low-mode frequency law (generator)",
                       f"log10 F = {antenna.LOW_LAW[0]} d + {antenna.LOW_LAW[1]}",
                       "log10 F = 0.0268 d + 0.69", "", "docs/reference.md, Fig. 2C",
                       "antenna.LOW_LAW: the clamped rod rings at the paper's law"),
            Calibrated("self-motion amplitude at 27 vs 12 cm/s (∝ speed²), made to match the "
                       "optimal threshold's ratio", (27 / 12) ** 2, "> 5", "×",
                       "docs/reference.md, Fig. 9",
                       "antenna.SELF_MOTION_G_AT_12 (0.25 g, assumed) and the speed² law")]

    def speed_profile(self) -> np.ndarray:
        t = np.arange(int(round(self.duration_s * self.rate_hz))) / self.rate_hz
        speed = np.full(len(t), float(self.speed_cm_s))
        if self.contacts and self.stop_after_contact_s is not None:
            first = min(c.t_s for c in self.contacts)
            speed[t >= first + self.stop_after_contact_s] = 0.0
        return speed

    def generate(self, seed: int = 0) -> Recording:
        self.validate()
        rng = np.random.default_rng(bounds.seed("seed", seed))
        n = int(round(self.duration_s * self.rate_hz))
        t = np.arange(n) / self.rate_hz
        speed = self.speed_profile()
        freq = np.full(n, antenna.NATURAL_HZ)
        tau = np.full(n, antenna.NATURAL_TAU_S)
        for c in self.contacts:
            held = (t >= c.t_s) & (t < c.t_s + c.hold_s)
            freq[held] = float(antenna.low_mode_hz(c.distance_cm))
            tau[held] = float(antenna.decay_times_s(c.distance_cm, c.material)[0])
        main = _motion(antenna.self_motion_rms_g(speed), freq, tau, speed, self.terrain,
                       self.rate_hz, rng)
        events = []
        for c in self.contacts:
            i0 = int(round(c.t_s * self.rate_hz))
            i1 = min(n, int(round((c.t_s + c.hold_s) * self.rate_hz)))
            main[i0:i1] += antenna.contact_ringing(c.distance_cm, c.material, self.rate_hz,
                                                   i1 - i0, rng, self.impact_g
                                                   if c.amplitude_g is None else c.amplitude_g)
            events.append(Event("contact", c.t_s, c.hold_s, c.distance_cm, c.material))
        xy = antenna.project(main, self.orientation_deg)
        xy += rng.standard_normal(xy.shape) * self.sensor_noise_g
        adc = antenna.ADC(self.adc_bits, self.full_scale_g)
        return Recording(adc.to_counts(xy), self.rate_hz, GroundTruth(events), units="counts",
                         meta={"adc_bits": self.adc_bits, "full_scale_g": self.full_scale_g,
                               "speed_cm_s": speed})
