"""Recordings: sampled signals that carry their sample rate, units and ground truth.

A Recording is what every source produces (the antenna model, scenes, the serial bridge, a
replay) and what every stage consumes, so a stage never has to guess the rate or the units.
Its ground truth (``truth``, a ``truth.GroundTruth``) travels with it for scoring, afterwards;
read-outs never read it (``truth``'s docstring says how that is enforced).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from . import bounds
from .errors import SpecError, check
from .truth import GroundTruth


@dataclass(frozen=True)
class Recording:
    """Samples of one or more channels at a fixed rate.

    ``samples`` has shape (n_samples,) for one channel or (n_samples, n_channels);
    ``units`` says what a sample is (``"g"`` for acceleration, ``"counts"`` for ADC counts,
    ``"coded"`` for the square-wave coder output).
    """
    samples: np.ndarray
    rate_hz: float
    truth: GroundTruth = GroundTruth()
    units: str = "g"
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        bounds.declared(self)
        validate_samples(self.samples, "samples")
        check(isinstance(self.truth, GroundTruth), "truth", type(self.truth).__name__,
              "a truth.GroundTruth (labelled events for scoring)")
        check(np.isfinite(self.rate_hz) and self.rate_hz > 0, "rate_hz", self.rate_hz,
              "a finite sample rate > 0 Hz")

    @property
    def n_samples(self) -> int:
        return int(self.samples.shape[0])

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.rate_hz

    @property
    def t_s(self) -> np.ndarray:
        return np.arange(self.n_samples) / self.rate_hz

    def with_samples(self, samples: np.ndarray, units: str | None = None) -> Recording:
        """The same recording (rate, truth) with new samples, e.g. after a processing stage."""
        return replace(self, samples=np.asarray(samples), units=units or self.units)


def validate_samples(samples, name: str = "samples") -> np.ndarray:
    """Refuse empty or non-finite signals before they reach a filter or a simulator."""
    arr = np.asarray(samples)
    if arr.ndim not in (1, 2) or arr.shape[0] == 0:
        raise SpecError(name, f"array of shape {arr.shape}",
                        "a non-empty array of shape (n_samples,) or (n_samples, n_channels)")
    if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
        raise SpecError(name, f"dtype {arr.dtype}", "real numeric samples")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.argwhere(bad)[0][0])
        raise SpecError(name, f"{int(bad.sum())} non-finite values (first at sample {first})",
                        "finite samples only; drop or interpolate NaN/inf samples first")
    return arr
