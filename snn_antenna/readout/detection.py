"""The blind read-out of coded scenes: many codings at once, contacts decided from spikes only.

The square-wave coder's threshold Th hides the robot's self-motion but, set too high, hides
contacts too (the paper's Fig. 9). Measuring that trade needs the resonator array run on many
codings of many scenes: ``run_codings`` runs them all as ONE Brian2 NeuronGroup (one copy of
the array per coding, each copy reading its own column of a 2-D TimedArray through
``neurons.simulate``), and ``BlindReadOut`` turns each copy's rate map into detections with
the contact rule (``contacts.ContactDetector``). It sees only coded columns, as a robot would:
how good its detections were is ``evaluation.scoring``'s work, afterwards.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..core import bounds
from ..networks import neurons
from ..networks.resonators import ResonatorArray, rate_map
from .contacts import ContactDetector


def run_codings(array: ResonatorArray, coded: np.ndarray, rate_hz: float,
                window_s: float = 0.1, target: str | None = None) -> list[xr.DataArray]:
    """Rate maps of the array driven by each column of ``coded`` (n_samples, n_codings)."""
    coded = np.asarray(coded, dtype=float)
    if coded.ndim == 1:
        coded = coded[:, None]
    array.check_rate(rate_hz)
    n_codings, n = coded.shape[1], array.n_neurons
    result = neurons.simulate(
        "resonator", coded, dt_ms=array.dt_ms, k=np.tile(array.k, n_codings), b=array.b,
        method=array.method, input_index=np.repeat(np.arange(n_codings), n),
        input_dt_ms=1000.0 / rate_hz, target=target or array.target, force=array.force)
    return copy_rate_maps(array, result.spike_i, result.spike_t_ms / 1000.0, n_codings,
                          coded.shape[0] / rate_hz, window_s)


def copy_rate_maps(array: ResonatorArray, spike_i, spike_t_s, n_codings: int,
                   duration_s: float, window_s: float) -> list[xr.DataArray]:
    """The rate map of each of ``n_codings`` copies of ``array`` in one group (copy c holds
    neurons c·n … c·n + n − 1), from the group's spikes."""
    n = array.n_neurons
    spike_i, spike_t_s = np.asarray(spike_i, dtype=int), np.asarray(spike_t_s, dtype=float)
    order = np.argsort(spike_i // n, kind="stable")
    spike_i, spike_t_s = spike_i[order], spike_t_s[order]
    ends = np.searchsorted(spike_i // n, np.arange(n_codings + 1))
    return [rate_map(spike_i[ends[c]:ends[c + 1]] - c * n, spike_t_s[ends[c]:ends[c + 1]],
                     array.neuron_hz, duration_s, window_s) for c in range(n_codings)]


@dataclass(frozen=True)
class BlindReadOut:
    """The read-out a robot has: coded columns in, detections and rate maps out.

    ``detect`` sees only coded columns (``run_codings`` then the detector on each rate map).
    It pickles, so it can run on a Dask worker while the labels stay with the caller; the
    caller scores its detections afterwards (``evaluation.scoring.score_with``).
    """
    array: ResonatorArray
    detector: ContactDetector
    window_s: float
    rate_hz: float
    settle_s: float = 1.0
    target: str | None = None

    def __post_init__(self):
        bounds.declared(self)
        if self.target is not None:
            bounds.choice("target", self.target, ("numpy", "cython", "standalone"))
        bounds.number("window_s", self.window_s, 0.0, lo_open=True, unit=" s")
        bounds.rate_hz("rate_hz", self.rate_hz)
        bounds.seconds("settle_s", self.settle_s)

    def detect(self, coded: np.ndarray) -> tuple[list, list[xr.DataArray]]:
        """(detections, rate map) of each column of ``coded``."""
        maps = run_codings(self.array, coded, self.rate_hz, self.window_s, self.target)
        return [self.detector.detect(rates) for rates in maps], maps
