"""Read-out of a rate map: dominant neuron, contact detection and distance decoding.

While the robot drives, its self-motion keeps the neurons near the probe's natural frequency
(≈ 7.8 Hz) busy. A contact clamps the rod and its free end rings faster, so activity shifts
to neurons tuned above the self-motion band (the paper's Fig. 10H): that shift is the contact.
The ringing frequency gives the distance through the inverse of the low-mode law.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import xarray as xr

from ..sources import antenna
from ..errors import SpecError, check, is_integer, is_number


def dominant_hz(rates: xr.DataArray, tie: float = 0.9) -> xr.DataArray:
    """Preferred frequency of the most active neuron (0 where all neurons are silent).

    A resonator fires once per input cycle across the plateau of its tuning curve, so several
    neighbours often tie; the neurons within ``tie`` × the maximum rate form the plateau and
    the one nearest its geometric centre is the dominant neuron (a plain argmax would always
    pick the plateau's lowest neuron). Reduces over ``neuron_hz``; other dims are kept.
    """
    peak = rates.max("neuron_hz")
    plateau = rates.where(rates >= tie * peak, 0.0)
    centre = np.log(centroid_hz(plateau).where(peak > 0, 1.0))
    distance = np.abs(np.log(rates.neuron_hz) - centre)
    idx = distance.where(plateau > 0).fillna(np.inf).argmin("neuron_hz")
    out = rates.neuron_hz[idx].where(peak > 0, 0.0)
    return out.drop_vars("neuron_hz").rename("dominant_hz").assign_attrs(units="Hz")


def centroid_hz(rates: xr.DataArray, dim=("neuron_hz",)) -> xr.DataArray:
    """Rate-weighted geometric mean of the preferred frequencies (0 where silent).

    With log-spaced neurons this is unbiased: the array's tuning is scale-invariant, and the
    preferred frequency of each neuron is its own tuning curve's geometric centroid.
    """
    w = rates.sum(dim)
    logf = np.log(rates.neuron_hz)
    c = np.exp((rates * logf).sum(dim) / w.where(w > 0))
    return c.fillna(0.0).rename("centroid_hz").assign_attrs(units="Hz")


@dataclass
class ContactEstimate:
    onset_s: float            # start of the first window of the episode
    end_s: float
    frequency_hz: float       # centroid of the above-band activity over the episode
    distance_cm: float

    def as_dict(self) -> dict:
        return {k: float(v) for k, v in asdict(self).items()}


@dataclass
class ContactDetector:
    """Find contacts as windows where activity above the self-motion band dominates.

    A window is a contact window when the summed rate of neurons tuned above
    ``motion_band_hz[1]`` exceeds ``min_rate_hz`` and the summed rate in and below the band.
    Contact windows separated by at most ``max_gap_windows`` silent windows form one episode.
    """
    motion_band_hz: tuple[float, float] = (7.0, 10.5)
    min_rate_hz: float = 20.0
    max_gap_windows: int = 1

    def __post_init__(self):
        band = self.motion_band_hz
        band_ok = (isinstance(band, (list, tuple, np.ndarray)) and len(band) == 2
                   and all(is_number(x) for x in band))
        check(band_ok and 0 <= band[0] <= band[1], "motion_band_hz", band,
              "[low, high] Hz, 0 <= low <= high")
        check(is_number(self.min_rate_hz) and self.min_rate_hz > 0, "min_rate_hz",
              self.min_rate_hz, "a rate > 0 Hz")
        check(is_integer(self.max_gap_windows) and self.max_gap_windows >= 0,
              "max_gap_windows", self.max_gap_windows, "an integer >= 0")

    def contact_windows(self, rates: xr.DataArray) -> xr.DataArray:
        above = rates.neuron_hz > self.motion_band_hz[1]
        high = rates.where(above, 0).sum("neuron_hz")
        low = rates.where(~above, 0).sum("neuron_hz")
        return (high >= self.min_rate_hz) & (high > low)

    def detect(self, rates: xr.DataArray, window_s: float | None = None) -> list[ContactEstimate]:
        """Contact episodes of a rate map, first to last.

        Total over every rate map with dims ``neuron_hz`` and ``window_s``: no window, one
        window, gaps between windows, a contact in the first or the last window. The window's
        width comes from ``window_s``, else ``rates.attrs["window_s"]`` (``rate_map`` sets it),
        else the spacing of the first two windows; a single window with none of these has no
        knowable end and is refused.
        """
        check(isinstance(rates, xr.DataArray) and set(rates.dims) == {"neuron_hz", "window_s"},
              "rates", type(rates).__name__ if not isinstance(rates, xr.DataArray)
              else f"DataArray with dims {rates.dims}",
              "a rate map (DataArray with dims neuron_hz and window_s, e.g. network.rate_map)")
        check(bool(np.all(np.isfinite(rates.values))) and not bool(np.any(rates.values < 0)),
              "rates", "non-finite or negative rates", "finite rates >= 0 Hz")
        window = self._window_width(rates, window_s)
        hit = self.contact_windows(rates).transpose("window_s").values
        starts = rates.window_s.values
        episodes, current, gap = [], [], 0
        for j, h in enumerate(hit):
            if h:
                current.append(j)
                gap = 0
            elif current:
                gap += 1
                if gap > self.max_gap_windows:
                    episodes.append(current)
                    current, gap = [], 0
        if current:
            episodes.append(current)
        out = []
        above = rates.neuron_hz > self.motion_band_hz[1]
        for ep in episodes:
            sub = rates.isel(window_s=ep).where(above, 0)
            f = float(centroid_hz(sub, dim=("neuron_hz", "window_s")))
            out.append(ContactEstimate(onset_s=float(starts[ep[0]]),
                                       end_s=float(starts[ep[-1]] + window),
                                       frequency_hz=f,
                                       distance_cm=float(antenna.distance_from_low_hz(f))))
        return out

    @staticmethod
    def _window_width(rates: xr.DataArray, window_s: float | None) -> float:
        # Only where it is needed is the coordinate spacing read: a one-window map has none.
        if window_s is None:
            window_s = rates.attrs.get("window_s")
        if window_s is None and rates.sizes["window_s"] >= 2:
            window_s = float(np.diff(rates.window_s.values[:2])[0])
        if window_s is None:
            if rates.sizes["window_s"] == 0:
                return 0.0            # nothing to end: no episode can be found
            raise SpecError("window_s", None, "the window width in s (pass window_s=, or a "
                                              "rate map with attrs['window_s'] as "
                                              "network.rate_map makes): one window has no "
                                              "spacing to read it from")
        check(is_number(window_s) and window_s > 0, "window_s", window_s,
              "a window width > 0 s")
        return float(window_s)


def band_activity_hz(rates: xr.DataArray, t0_s: float, t1_s: float,
                     band_hz: tuple[float, float] | None = None) -> float:
    """Centroid frequency of the activity between t0_s and t1_s (optionally within a band)."""
    sub = rates.sel(window_s=slice(t0_s, t1_s - 1e-9))
    if band_hz is not None:
        inside = (sub.neuron_hz >= band_hz[0]) & (sub.neuron_hz <= band_hz[1])
        sub = sub.where(inside, 0)
    return float(centroid_hz(sub, dim=("neuron_hz", "window_s")))


def detector_from_spec(spec: dict) -> tuple["ContactDetector", float]:
    """The ``[readout]`` table of a spec → (``ContactDetector``, rate-map window in s).

    Every study and the live pipeline read the section here, so its keys, defaults and
    errors are the same everywhere (``window_s`` defaults to 0.1 s)."""
    from .. import spec as specs

    with specs.section("readout"):
        read = dict(specs.check_section(spec, "readout", ContactDetector, extra=["window_s"]))
        window_s = float(read.pop("window_s", 0.1))
        detector = ContactDetector(**{k: tuple(v) if isinstance(v, list) else v
                                      for k, v in read.items()})
    return detector, window_s
