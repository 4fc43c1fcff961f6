"""Physics of the bionic antenna: an elastic rod with a 2-axis accelerometer at its tip.

A contact at ``distance_cm`` from the base clamps the rod there; the free end beyond it rings
as a damped oscillation with a low and a high mode. What comes from the paper (Patanè et al.
2012, Fig. 2C and 5D; see REFERENCE.md) and what is our documented assumption:

- Mode frequencies (paper): ``log10 F_low = 0.0268 d + 0.69``, ``log10 F_high = 0.0305 d + 1.52``.
  Contact-to-contact scatter (calibrated by the bench issue against the paper's signal
  numbers as measured by the paper's own processing in ``events.py``): 0.007 dex for the low
  mode and 0.024 dex for the high one. Most of the low peak's measured spread (0.0166 dex,
  the paper's 6.2 mm single-contact precision, r² = 0.995) is then the FFT's resolution of
  short event windows (1/T of 1.5–4 Hz at 8–50 Hz), not physics; the high mode's spread is
  what leaves r² = 0.987.
- Decay (paper, in kind): τ falls almost linearly with distance, wood and aluminium differ.
  Assumed values: τ_low falls from 0.30 s at 8 cm to 0.10 s at 37.5 cm and τ_high from 60 ms to
  15 ms, scaled per material (see ``MATERIALS``).
- Materials (paper, Fig. 5C): at one site, ten wood and ten aluminium contacts differed by
  t = 3.1 (τ_low), 7.7 (τ_high), 3.7 (A_low), 5.9 (A_high), i.e. by 1.4, 3.5, 1.6 and 2.6
  within-material standard deviations, with a coefficient of variation of τ_low below 1 %.
  Our assumptions: contact-to-contact scatter of τ_low 0.8 %, τ_high 3 %, impact amplitude 5 %
  and high/low amplitude ratio 5 % (``*_CV``). The wood–aluminium differences are those
  multiples of the within-material spread that the event processing (``events.py``) measures
  on our signals (``MEASURED_CV``: τ_low 2.8 %, τ_high 3.4 %, A_low 7.2 %, A_high 7.3 %, the
  median over materials and sites at 14–36 cm with 12 contacts each; the extraction, not the
  generator, sets most of it, as it must have in the paper, whose t-values include its own
  extraction; the paper's τ_low CV below 1 % is therefore not reached, see the bench report).
  Every other material sits on the same two axes by its textbook
  loss factor (how much energy the contact absorbs: the decay times) and Young's modulus (how
  stiff the contact is: how much of the impact reaches the high mode, and the amplitude),
  both on a log scale normalised so aluminium is 0 and wood is 1. Material differences are
  therefore subtle, as in the paper, and the physics makes brass, copper and aluminium close
  (similar stiffness and loss) and the three polymers close.
- Self-motion (paper, in kind): the driving robot shakes the probe at its natural frequency near
  7.8 Hz and the ground adds broadband jolts. Assumed: both grow with the square of speed
  (0.25 g and 0.024 g rms at 12 cm/s on flat ground), which makes the threshold that hides them
  at 27 cm/s about five times that at 12 cm/s, as the paper measured (Fig. 9).
- Impact (physics, one assumed constant): when a moving rod meets a post the contact point
  stops and the free end beyond it keeps the speed it had, so the low mode starts with a tip
  velocity amplitude equal to the tip's speed normal to the rod, and its acceleration amplitude
  is 2π·F_low·v_tip (``impact_amplitude_g``). ``IMPACT_TRANSFER`` is the share of that speed
  which survives the soft contact of a compliant tube on a post (the rest goes into sliding,
  bending around the post and higher modes); it is assumed, 0.1, chosen so that impacts in the
  course scenes fall in the range of the self-motion they compete with, which is what the
  paper's Fig. 9 reports of its signals (doubling Th* lost true positives at 12 and at 27 cm/s,
  so contact signals sat within a factor two of a threshold that rose more than five-fold).
  With the paper's sweep (±40°, 2 s) the sweep sets most of the tip's speed (≈ 90 cm/s
  mid-sweep), so impacts on posts the 7–30 Hz array sees have a median near 1 g (10–90 %:
  0.4–1.8 g) at every robot speed: above the self-motion at 12 cm/s (0.25 g rms), below it at
  30 cm/s (1.6 g rms), where the held rod's forced ringing carries the contact instead
  (``tests/test_scenes.py`` checks that range). Scripted contacts (``stimuli.RobotScene``, the
  bench) keep an explicit ``impact_g``.
- Sensor: ADXL321-like, ±18 g into a 10-bit ADC (35 mg per count), white noise 10 mg; modes
  above 0.45 × the sample rate are removed, as the sensor's anti-aliasing bandwidth would.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SpecError, check

ROD_LENGTH_CM = 41.3          # total feeler length (paper: 413 mm)
CALIBRATED_RANGE_CM = (8.0, 37.5)  # where the paper measured the frequency laws
LOW_LAW = (0.0268, 0.69)      # log10 F_low = slope * d + intercept
HIGH_LAW = (0.0305, 1.52)
LOW_SCATTER_DEX = 0.007      # calibrated, see the module docstring
HIGH_SCATTER_DEX = 0.024
NATURAL_HZ = 7.8              # free probe's self-oscillation while driving (paper)
NATURAL_TAU_S = 1.0
SELF_MOTION_G_AT_12 = 0.25    # self-oscillation amplitude at 12 cm/s (assumed)
SPEED_LIMIT_CM_S = 60.0
IMPACT_TRANSFER = 0.1         # share of the tip's normal speed that rings the low mode (assumed)
G_CM_S2 = 980.665             # standard gravity, cm/s²


# Contact-to-contact scatter (coefficients of variation; assumed, see the module docstring).
TAU_LOW_CV = 0.008
TAU_HIGH_CV = 0.03
AMPLITUDE_CV = 0.05
HIGH_RATIO_CV = 0.05
# Within-material spread of the extracted features (measured, see the module docstring) and
# wood minus aluminium in units of it (paper, Fig. 5C; signs assumed: wood absorbs more).
MEASURED_CV = {"tau_low": 0.028, "tau_high": 0.034, "amplitude": 0.072, "high_ratio": 0.073}
WOOD_VS_ALUMINIUM_SD = {"tau_low": 1.4, "tau_high": 3.5, "amplitude": 1.6, "high_ratio": 2.6}
BASE_HIGH_RATIO = 0.45        # high-mode amplitude relative to the low mode for aluminium


@dataclass(frozen=True)
class Material:
    """How a contacted object changes the ringing (assumed; see the module docstring).

    ``tau_scale`` multiplies τ_low, ``high_tau_scale`` τ_high, ``low_amplitude`` the impact
    amplitude; ``high_amplitude`` is the high mode's amplitude relative to the low mode.
    """
    name: str
    tau_scale: float
    high_amplitude: float
    high_tau_scale: float = 1.0
    low_amplitude: float = 1.0


# Textbook values: Young's modulus (GPa; wood across the grain) and loss factor η.
MATERIAL_PROPERTIES = {
    "stainless_steel": (193.0, 0.0006),
    "brass": (100.0, 0.001),
    "copper": (117.0, 0.002),
    "aluminium": (69.0, 0.001),
    "acrylic_glass": (3.2, 0.04),
    "pvc": (3.0, 0.03),
    "pom": (2.9, 0.02),
    "wood": (11.0, 0.015),
}


def _material(name: str, youngs_gpa: float, loss: float) -> Material:
    (e_al, l_al), (e_wood, l_wood) = MATERIAL_PROPERTIES["aluminium"], MATERIAL_PROPERTIES["wood"]
    absorb = np.log(loss / l_al) / np.log(l_wood / l_al)          # 0 aluminium, 1 wood
    soft = np.log(e_al / youngs_gpa) / np.log(e_al / e_wood)      # 0 aluminium, 1 wood
    # wood minus aluminium, as a fraction, for each quantity
    diff = {k: WOOD_VS_ALUMINIUM_SD[k] * MEASURED_CV[k] for k in MEASURED_CV}
    return Material(name,
                    tau_scale=float(1 - diff["tau_low"] * absorb),
                    high_amplitude=float(BASE_HIGH_RATIO * (1 - diff["high_ratio"] * soft)),
                    high_tau_scale=float(1 - diff["tau_high"] * absorb),
                    low_amplitude=float(1 - diff["amplitude"] * soft))


MATERIALS: dict[str, Material] = {name: _material(name, *props)
                                  for name, props in MATERIAL_PROPERTIES.items()}


def check_distance(distance_cm) -> np.ndarray:
    d = np.asarray(distance_cm, dtype=float)
    if not np.all(np.isfinite(d)) or np.any(d <= 0) or np.any(d >= ROD_LENGTH_CM):
        raise SpecError("distance_cm", distance_cm,
                        f"contact distances along the rod in (0, {ROD_LENGTH_CM}) cm "
                        f"(the frequency law was measured for {CALIBRATED_RANGE_CM[0]}–"
                        f"{CALIBRATED_RANGE_CM[1]} cm)")
    return d


def check_material(material: str) -> Material:
    if material not in MATERIALS:
        raise SpecError("material", material, f"one of {sorted(MATERIALS)}")
    return MATERIALS[material]


def low_mode_hz(distance_cm):
    d = check_distance(distance_cm)
    return 10 ** (LOW_LAW[0] * d + LOW_LAW[1])


def high_mode_hz(distance_cm):
    d = check_distance(distance_cm)
    return 10 ** (HIGH_LAW[0] * d + HIGH_LAW[1])


def distance_from_low_hz(freq_hz):
    """Inverse of the low-mode law: the contact distance (cm) that rings at ``freq_hz``."""
    f = np.asarray(freq_hz, dtype=float)
    if not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise SpecError("freq_hz", freq_hz, "finite frequencies > 0 Hz")
    return (np.log10(f) - LOW_LAW[1]) / LOW_LAW[0]


def decay_times_s(distance_cm, material: str = "wood") -> tuple[np.ndarray, np.ndarray]:
    """(τ_low, τ_high) in s: linear fall with distance, scaled by the material."""
    d = check_distance(distance_cm)
    m = check_material(material)
    lo, hi = CALIBRATED_RANGE_CM
    x = (d - lo) / (hi - lo)
    tau_low = (0.30 - 0.20 * x) * m.tau_scale
    tau_high = (0.060 - 0.045 * x) * m.high_tau_scale
    return np.maximum(tau_low, 0.03), np.maximum(tau_high, 0.005)


def contact_ringing(distance_cm: float, material: str, rate_hz: float, n_samples: int,
                    rng: np.random.Generator, amplitude_g: float = 2.0,
                    scatter: bool = True) -> np.ndarray:
    """The free end's damped two-mode oscillation after an impact, in g along the main axis.

    With ``scatter``, every contact differs from the next by the paper's measured spread of the
    frequencies and the assumed spread of decay times and amplitudes (``*_CV``); modes above
    the sensor bandwidth (0.45 × ``rate_hz``) are left out rather than aliased.
    """
    m = check_material(material)
    f_low = float(low_mode_hz(distance_cm))
    if f_low >= 0.45 * rate_hz:
        raise SpecError("rate_hz", rate_hz,
                        f"a sample rate above {f_low / 0.45:.0f} Hz for a contact at "
                        f"{distance_cm} cm (its low mode rings at {f_low:.1f} Hz)")
    f_high = float(high_mode_hz(distance_cm))
    tau_low, tau_high = (float(x) for x in decay_times_s(distance_cm, material))
    a_low, ratio = amplitude_g * m.low_amplitude, m.high_amplitude
    if scatter:
        f_low *= 10 ** rng.normal(0, LOW_SCATTER_DEX)
        f_high *= 10 ** rng.normal(0, HIGH_SCATTER_DEX)
        tau_low *= 1 + rng.normal(0, TAU_LOW_CV)
        tau_high *= 1 + rng.normal(0, TAU_HIGH_CV)
        a_low *= 1 + rng.normal(0, AMPLITUDE_CV)
        ratio *= 1 + rng.normal(0, HIGH_RATIO_CV)
    t = np.arange(n_samples) / rate_hz
    # Impact: the rod is deflected and released, so both modes start near a peak.
    out = a_low * np.exp(-t / tau_low) * np.cos(2 * np.pi * f_low * t + rng.normal(0, 0.2))
    if f_high < 0.45 * rate_hz:
        out += a_low * ratio * np.exp(-t / tau_high) * np.cos(
            2 * np.pi * f_high * t + rng.uniform(0, 2 * np.pi))
    return out


def impact_amplitude_g(distance_cm, tip_speed_cm_s, transfer: float = IMPACT_TRANSFER):
    """Low-mode amplitude (g) of a contact at ``distance_cm`` met with the rod's tip moving at
    ``tip_speed_cm_s`` normal to the rod: 2π·F_low·v·transfer / g (see the module docstring)."""
    v = np.abs(np.asarray(tip_speed_cm_s, dtype=float))
    check(bool(np.all(np.isfinite(v))), "tip_speed_cm_s", tip_speed_cm_s, "finite speeds in cm/s")
    check(np.isfinite(transfer) and 0 < transfer <= 1, "impact_transfer", transfer,
          "a share in (0, 1]")
    return 2 * np.pi * low_mode_hz(distance_cm) * v * transfer / G_CM_S2


def resonant_noise(freq_hz: float, tau_s: float, rms_g, rate_hz: float,
                   rng: np.random.Generator, n_samples: int) -> np.ndarray:
    """White noise through a mode at ``freq_hz`` with decay ``tau_s``: a driven ringing rod.

    ``rms_g`` may be a scalar or one value per sample (amplitude following the robot's speed);
    the filter's steady-state gain is normalised so the output has that rms.
    """
    from scipy.signal import lfilter

    b, a = mode_filter(freq_hz, tau_s, rate_hz)
    drive = rng.standard_normal(n_samples) * np.broadcast_to(rms_g, (n_samples,))
    return lfilter(b, a, drive)


def mode_filter(freq_hz: float, tau_s: float, rate_hz: float) -> tuple[list, list]:
    """(b, a) of a two-pole resonator at ``freq_hz`` decaying with ``tau_s``, gain normalised
    so unit-variance white noise comes out with unit rms (for ``scipy.signal.lfilter``)."""
    from scipy.signal import lfilter

    r = np.exp(-1.0 / (tau_s * rate_hz))
    a = [1.0, -2 * r * np.cos(2 * np.pi * freq_hz / rate_hz), r * r]
    # The output variance for unit-variance input is the impulse response's energy.
    impulse = lfilter([1.0], a, np.r_[1.0, np.zeros(int(20 * tau_s * rate_hz) + 10)])
    return [1.0 / np.sqrt(np.sum(impulse ** 2))], a


# Broadband jolts from the ground at 12 cm/s (rms g, assumed). Like the self-oscillation they
# grow with the square of speed (the energy of the bumps the wheels take), so the threshold
# that hides self-motion at 27 cm/s is (27/12)² ≈ 5 times that at 12 cm/s: the paper's
# measurement ("more than five-fold", Fig. 9) of the signal, not of a classifier.
TERRAIN_NOISE_G_AT_12 = {"flat": 0.024, "rough": 0.12}


def terrain_noise_rms_g(speed_cm_s, terrain: str = "flat") -> np.ndarray:
    """Broadband terrain noise (rms g) at ``speed_cm_s`` on ``terrain`` (assumed ∝ v²)."""
    if terrain not in TERRAIN_NOISE_G_AT_12:
        raise SpecError("terrain", terrain, f"one of {sorted(TERRAIN_NOISE_G_AT_12)}")
    return TERRAIN_NOISE_G_AT_12[terrain] * (self_motion_rms_g(speed_cm_s) / SELF_MOTION_G_AT_12)


def self_motion_rms_g(speed_cm_s) -> np.ndarray:
    """Self-oscillation amplitude (rms g) of the probe while the robot drives (assumed ∝ v²)."""
    v = np.asarray(speed_cm_s, dtype=float)
    if not np.all(np.isfinite(v)) or np.any(v < 0) or np.any(v > SPEED_LIMIT_CM_S):
        raise SpecError("speed_cm_s", speed_cm_s,
                        f"finite robot speeds in [0, {SPEED_LIMIT_CM_S}] cm/s")
    return SELF_MOTION_G_AT_12 * (v / 12.0) ** 2


def project(main_axis_g: np.ndarray, orientation_deg: float,
            gravity_g: tuple[float, float] = (0.0, 1.0)) -> np.ndarray:
    """Project the tip's oscillation onto the sensor's two axes; gravity adds a DC offset."""
    th = np.deg2rad(orientation_deg)
    xy = np.outer(main_axis_g, [np.cos(th), np.sin(th)])
    return xy + np.asarray(gravity_g)


@dataclass(frozen=True)
class ADC:
    """An accelerometer into an ADC: counts = round(mid + g / lsb), clipped to the rails."""
    bits: int = 10
    full_scale_g: float = 18.0   # ± range of the sensor (ADXL321: ±18 g)

    def __post_init__(self):
        check(isinstance(self.bits, int) and 4 <= self.bits <= 24, "adc_bits", self.bits,
              "an integer number of bits in [4, 24]")
        check(np.isfinite(self.full_scale_g) and self.full_scale_g > 0, "full_scale_g",
              self.full_scale_g, "a range > 0 g")

    @property
    def levels(self) -> int:
        return 2 ** self.bits

    @property
    def lsb_g(self) -> float:
        return 2 * self.full_scale_g / self.levels

    def to_counts(self, g: np.ndarray) -> np.ndarray:
        counts = np.round(self.levels / 2 + np.asarray(g) / self.lsb_g)
        return np.clip(counts, 0, self.levels - 1).astype(np.int32)

    def to_g(self, counts: np.ndarray) -> np.ndarray:
        return (np.asarray(counts, dtype=float) - self.levels / 2) * self.lsb_g
