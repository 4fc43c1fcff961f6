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

from ..core import bounds
from ..core.errors import SpecError, check, is_integer, is_number
from ..networks.resonators import SELF_MOTION_BAND_HZ, tuned_above
from ..sources import antenna
from ..core import spec as specs


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

    The contact rule, the one definition that the offline read-out, the live pipeline
    (``bridge.online``) and, as synapses, the control layer (``networks.control``) follow:
    a window is a contact window when the summed rate of the neurons tuned above
    ``motion_band_hz[1]`` (``resonators.tuned_above``) reaches ``min_rate_hz`` and exceeds the
    summed rate in and below the band. Contact windows separated by at most
    ``max_gap_windows`` other windows form one episode (:class:`EpisodeTracker`).
    """
    motion_band_hz: tuple[float, float] = SELF_MOTION_BAND_HZ
    min_rate_hz: float = 20.0
    max_gap_windows: int = 1

    def __post_init__(self):
        bounds.declared(self)
        band = self.motion_band_hz
        band_ok = (isinstance(band, (list, tuple, np.ndarray)) and len(band) == 2
                   and all(is_number(x) for x in band))
        check(band_ok and 0 <= band[0] <= band[1], "motion_band_hz", band,
              "[low, high] Hz, 0 <= low <= high")
        check(is_number(self.min_rate_hz) and self.min_rate_hz > 0, "min_rate_hz",
              self.min_rate_hz, "a rate > 0 Hz")
        check(is_integer(self.max_gap_windows) and self.max_gap_windows >= 0,
              "max_gap_windows", self.max_gap_windows, "an integer >= 0")

    def is_contact_window(self, rates: np.ndarray, above: np.ndarray) -> bool:
        """The rule for one window: ``rates`` (Hz, one per neuron), ``above`` the neurons'
        ``tuned_above`` mask. Always called on one window's contiguous rates, offline and live,
        so the sums (and any tie) come out the same bit for bit."""
        high, low = rates[above].sum(), rates[~above].sum()
        return bool(high >= self.min_rate_hz and high > low)

    def contact_windows(self, rates: xr.DataArray) -> xr.DataArray:
        """The rule over a rate map: a bool per window (dim ``window_s``)."""
        values = np.asarray(rates.transpose("neuron_hz", "window_s").values, dtype=float)
        above = tuned_above(rates.neuron_hz.values, self.motion_band_hz)
        hit = [self.is_contact_window(np.ascontiguousarray(values[:, j]), above)
               for j in range(values.shape[1])]
        return xr.DataArray(np.array(hit, dtype=bool), dims=("window_s",),
                            coords={"window_s": rates.window_s.values})

    def estimate(self, rates: np.ndarray, neuron_hz: np.ndarray, starts_s: list[float],
                 window_s: float) -> ContactEstimate:
        """One episode's estimate from its contact windows' ``rates`` (neuron × window):
        the centroid of the above-band activity, and the distance whose low mode rings there."""
        episode = xr.DataArray(rates, dims=("neuron_hz", "window_s"),
                               coords={"neuron_hz": neuron_hz, "window_s": starts_s})
        above = xr.DataArray(tuned_above(neuron_hz, self.motion_band_hz), dims="neuron_hz",
                             coords={"neuron_hz": neuron_hz})
        f = float(centroid_hz(episode.where(above, 0), dim=("neuron_hz", "window_s")))
        return ContactEstimate(onset_s=float(starts_s[0]), end_s=float(starts_s[-1] + window_s),
                               frequency_hz=f, distance_cm=float(antenna.distance_from_low_hz(f)))

    def detect(self, rates: xr.DataArray, window_s: float | None = None) -> list[ContactEstimate]:
        """Contact episodes of a rate map, first to last: its windows fed in order to the
        :class:`EpisodeTracker` the live pipeline feeds as they come.

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
        tracker = EpisodeTracker(self, rates.neuron_hz.values, window)
        values = np.asarray(rates.transpose("neuron_hz", "window_s").values, dtype=float)
        for t_s, j in zip(rates.window_s.values, range(values.shape[1])):
            tracker.update(float(t_s), np.ascontiguousarray(values[:, j]))
        tracker.close()
        return tracker.estimates

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


def preferred_hz(field: str, neuron_hz) -> np.ndarray:
    """``neuron_hz`` as an array of the neurons' preferred frequencies, or a SpecError: one
    finite frequency > 0 Hz per neuron, at least one."""
    values = np.asarray(neuron_hz) if not isinstance(neuron_hz, str) else np.asarray([])
    ok = values.ndim == 1 and values.size >= 1 and values.dtype.kind in "iuf"
    check(ok and bool(np.all(np.isfinite(values) & (values > 0)
                             & (values <= bounds.MAX_RATE_HZ))), field, neuron_hz,
          f"one preferred frequency in (0, {bounds.MAX_RATE_HZ:g}] Hz per neuron")
    return values.astype(float)


class EpisodeTracker:
    """Contact episodes, window by window: the one episode logic, fed offline by
    :meth:`ContactDetector.detect` and live by ``bridge.online``.

    ``update`` reports the onset as soon as an episode's first contact window arrives, and the
    estimate once ``max_gap_windows`` + 1 windows in a row were not contact windows (or at
    ``close``). An episode's estimate uses its contact windows only; the bridged ones between
    them count for nothing but holding it open.
    """

    def __init__(self, detector: ContactDetector, neuron_hz, window_s: float):
        bounds.declared(self, detector=detector, neuron_hz=neuron_hz, window_s=window_s)
        bounds.number("window_s", window_s, 0.0, lo_open=True, unit=" s")
        self.detector, self.window_s = detector, window_s
        self.neuron_hz = preferred_hz("neuron_hz", neuron_hz)
        self._above = tuned_above(self.neuron_hz, detector.motion_band_hz)
        self._rates: list[np.ndarray] = []      # the open episode's contact windows
        self._starts: list[float] = []
        self._quiet = 0                         # windows since its last contact window
        self.estimates: list[ContactEstimate] = []

    def update(self, t_s: float, rates: np.ndarray,
               window_s: float | None = None) -> tuple[str, object] | None:
        """Feed one window (its start, a rate per neuron, and its length when the windows
        change length as they come: an episode's estimate takes its last window's); returns
        ("onset", t_s), ("contact", ContactEstimate) or None."""
        if window_s is not None:
            self.window_s = window_s
        if self.detector.is_contact_window(rates, self._above):
            onset = not self._rates
            self._rates.append(rates)
            self._starts.append(t_s)
            self._quiet = 0
            return ("onset", t_s) if onset else None
        if not self._rates:
            return None
        self._quiet += 1
        return self.close() if self._quiet > self.detector.max_gap_windows else None

    def close(self) -> tuple[str, ContactEstimate] | None:
        """End the open episode, if any: ("contact", its estimate)."""
        if not self._rates:
            return None
        # Neuron × window with each window's rates contiguous: the layout a rate map's
        # selected windows have, so the centroid's sums run in the same order, to the last bit.
        found = self.detector.estimate(np.array(self._rates).T, self.neuron_hz, self._starts,
                                       self.window_s)
        self._rates, self._starts, self._quiet = [], [], 0
        self.estimates.append(found)
        return "contact", found


def detector_from_spec(spec: dict) -> tuple[ContactDetector, float]:
    """The ``[readout]`` table of a spec → (``ContactDetector``, rate-map window in s).

    Every study and the live pipeline read the section here, so its keys, defaults and
    errors are the same everywhere (``window_s`` defaults to 0.1 s)."""
    with specs.section("readout"):
        read = dict(specs.check_section(spec, "readout", ContactDetector, extra=["window_s"]))
        window_s = float(read.pop("window_s", 0.1))
        detector = ContactDetector(**{k: tuple(v) if isinstance(v, list) else v
                                      for k, v in read.items()})
    return detector, window_s
