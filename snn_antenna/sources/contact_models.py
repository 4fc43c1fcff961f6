"""Candidate contact mechanisms: what else a rod's material does to the antenna's ringing.

Every candidate shares the antenna's two modes (the paper's frequency laws), their own decay,
and the viscoelastic loss the resting contact takes out of them (``Material.contact_loss``,
docs/materials.md, ingredient 3). They differ in the one mechanism that carries the rest of a
material's signature, each with ONE free constant, scaled by ``ContactPhysics.strength``
(1.0 = the reference value below; the model-selection study searches it on a small grid):

- ``current`` — the struck rod's own first bending mode reaches the tip as a narrow line
  (free constant: ``antenna.ROD_COUPLING``); the impact's Hertz duration weights each mode at
  its reference effective mass. The default generator.
- ``boundary`` — the contact is not a rigid clamp: the rod is a spring k_s = 3EI/L³ at its
  end, carrying its modal mass, in series with the antenna's stiffness k_b at the contact
  (free constant: ``BOUNDARY_STIFFNESS_N_M``). The antenna's modes move to
  f = f_clamped · √(k_s,dyn / (k_s,dyn + k_b)), with k_s,dyn = k_s (1 − (f/f_rod)²) for the low
  mode (always below the rod's mode) and the static k_s for the high mode (which may cross
  the rod's mode; a coupled two-mode model is left out). Soft rods lower both modes: a broad,
  material-wide shift rather than a line.
- ``hertz`` — the impact's duration sets the excitation spectrum: t_c ∝ m^(2/5) with m the
  effective mass the rod stops (free constant: ``HERTZ_EFFECTIVE_MASS_KG``, 3 g reference).
  The half-sine's spectrum weights the low and high mode (a low-pass whose corner moves with
  the material's contact modulus): the high-to-low amplitude ratio becomes a material feature.
- ``friction`` — the tube slides a little on the rod each cycle: Coulomb friction removes a
  fixed amplitude per cycle, ΔA = c μ (f / 20 Hz)² g (a force F = μN takes 4F/k of
  displacement per cycle, i.e. ω² · 4F/k of acceleration), so the ring's envelope ends in a
  straight line and stops: A(t) = max((A₀ + Rτ) e^(−t/τ) − Rτ, 0) with R = ΔA f. Free
  constant: c (``FRICTION_G_PER_CYCLE``, through the unknown normal force); μ per material
  from textbook ranges (``FRICTION_COEFFICIENT``).

Mechanisms combine with ``+`` (e.g. ``"boundary+hertz"``); a combination's one strength
scales each of its mechanisms' reference constants, except ``current``'s: in a combination the
rod's line keeps its reference coupling (calibrated alone), so ``"current+hertz"`` asks what
Hertz's excitation spectrum adds to the default model with one free constant, not two.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import bounds
from ..core.errors import SpecError, check

MECHANISMS = ("current", "boundary", "hertz", "friction")
DEFAULT_MECHANISM = "current"

# Reference values of each candidate's free constant (strength 1.0; assumed, then searched).
BOUNDARY_STIFFNESS_N_M = 100.0    # the antenna's stiffness where it rests on the rod
HERTZ_EFFECTIVE_MASS_KG = 0.003   # the tube's effective mass at the contact (antenna.py)
FRICTION_G_PER_CYCLE = 0.01       # amplitude a μ = 1 contact removes per cycle at 20 Hz
FRICTION_REFERENCE_HZ = 20.0

# Dry sliding friction of the PMMA tube on each rod (representative handbook values, ±50 %:
# PMMA on metals 0.4-0.5, on wood ~0.5, POM's low friction ~0.2, PMMA on PVC ~0.45 and on
# PMMA ~0.8); see docs/materials.md.
FRICTION_COEFFICIENT = {
    "aluminium": 0.45, "stainless_steel": 0.4, "copper": 0.4, "brass": 0.35, "wood": 0.5,
    "pom": 0.2, "pvc": 0.45, "acrylic_glass": 0.8,
}


@dataclass(frozen=True)
class ContactPhysics:
    """Which contact mechanism(s) the generator uses and how strong their free constant is."""
    mechanism: str = DEFAULT_MECHANISM
    strength: float = 1.0

    def __post_init__(self):
        bounds.declared(self)
        parts = self.mechanism.split("+") if isinstance(self.mechanism, str) else [None]
        check(all(p in MECHANISMS for p in parts) and len(set(parts)) == len(parts),
              "physics", self.mechanism,
              f"one of {list(MECHANISMS)} or several joined by '+' (e.g. 'boundary+hertz')")
        check(isinstance(self.strength, (int, float)) and not isinstance(self.strength, bool)
              and bool(np.isfinite(self.strength)) and 0 < self.strength <= 1e4,
              "physics_strength", self.strength,
              "a factor in (0, 10000] on the mechanism's reference constant")

    def has(self, name: str) -> bool:
        return name in self.mechanism.split("+")

    # -- what each mechanism does ------------------------------------------------------------
    def rod_coupling_scale(self) -> float:
        """Factor on ``ROD_COUPLING``: the rod's line exists only with ``current``; in a
        combination it stays at its reference (the strength is the other mechanism's)."""
        if not self.has("current"):
            return 0.0
        return self.strength if self.mechanism == "current" else 1.0

    def effective_mass_kg(self) -> float:
        """The mass the rod stops, which sets Hertz's contact duration (t_c ∝ m^(2/5))."""
        scale = self.strength if self.has("hertz") else 1.0
        return HERTZ_EFFECTIVE_MASS_KG * scale

    def frequency_factors(self, material, f_low: float, f_high: float) -> tuple[float, float]:
        """(low, high) factors on the clamped-contact mode frequencies (``boundary`` only)."""
        if not self.has("boundary"):
            return 1.0, 1.0
        k_b = BOUNDARY_STIFFNESS_N_M * self.strength
        k_s = material.rod_stiffness_n_m
        k_low = k_s * (1.0 - (f_low / material.rod_mode_hz()) ** 2)
        if k_low <= 0:
            raise SpecError("physics", self.mechanism,
                            f"a contact whose low mode ({f_low:.0f} Hz) is below the rod's "
                            f"own mode ({material.rod_mode_hz():.0f} Hz)")
        return float(np.sqrt(k_low / (k_low + k_b))), float(np.sqrt(k_s / (k_s + k_b)))

    def envelope(self, t: np.ndarray, tau_s: float, freq_hz: float, amplitude_g: float,
                 material_name: str) -> np.ndarray:
        """The ring's envelope relative to its start: e^(−t/τ), or with Coulomb friction
        ``max((A₀ + Rτ) e^(−t/τ) − Rτ, 0) / A₀``."""
        decay = np.exp(-t / tau_s)
        if not self.has("friction") or amplitude_g <= 0:
            return decay
        per_cycle = (FRICTION_G_PER_CYCLE * self.strength * FRICTION_COEFFICIENT[material_name]
                     * (freq_hz / FRICTION_REFERENCE_HZ) ** 2)
        r_tau = per_cycle * freq_hz * tau_s / amplitude_g
        return np.maximum((1.0 + r_tau) * decay - r_tau, 0.0)


DEFAULT = ContactPhysics()

__all__ = ["ContactPhysics", "DEFAULT", "MECHANISMS", "DEFAULT_MECHANISM",
           "FRICTION_COEFFICIENT", "BOUNDARY_STIFFNESS_N_M", "HERTZ_EFFECTIVE_MASS_KG",
           "FRICTION_G_PER_CYCLE"]
