"""The bench's processed events beside their labels, and the signal's statistics beside the
paper's measurements of its signal.

``load_features`` gives the bench data set and its event features (``readout.events``: the
features see only each event's counts), with the events' labels (``truth.BENCH_LABELS``)
joined as coordinates for training and scoring; ``signal_statistics`` reads the frequency
laws, their scatter and the τ statistics per material and site (``PAPER_SIGNAL`` holds the
paper's numbers, docs/reference.md).
"""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import xarray as xr

from ..readout.events import EventProcessor, process
from ..core.truth import bench_labels
from ..sources import bench


def features_path(bench_spec, processor: EventProcessor) -> Path:
    """Where ``load_features`` caches the features of ``bench_spec``'s events: keyed by both
    specs and the code that computes them (``bench.cache_key``)."""
    key = bench.cache_key({"bench": bench_spec.key(), "events": asdict(processor)}, __name__)
    return Path(bench_spec.cache_dir) / f"features-{key}.zarr"


def load_features(bench_spec, processor: EventProcessor, log=print, fresh: bool = False
                  ) -> tuple[xr.Dataset, xr.Dataset]:
    """The bench data set of ``bench_spec`` (a ``bench.BenchSpec``) and its event features
    with the events' labels joined; both cached on disk (``features_path``)."""
    data = bench.load(bench_spec, log, fresh)
    path = features_path(bench_spec, processor)
    features = bench.cached(path, lambda: process(data, processor, bench_spec.n_jobs, log=log),
                            __name__, log, fresh)
    return data, with_labels(features, data)


def with_labels(features: xr.Dataset, data: xr.Dataset) -> xr.Dataset:
    """Features of a bench data set's events with the events' labels as coordinates."""
    labels = bench_labels(data.sel(event=features["event"].values))
    return features.assign_coords({name: ("event", np.asarray(v.values))
                                   for name, v in labels.items()})


# -- the signal's statistics beside the paper's measurements of its signal -----------------
PAPER_SIGNAL = {
    "r2_low": 0.995, "r2_high": 0.987, "spread_ratio_high_to_low": 3.0,
    "single_contact_precision_mm": 6.2, "tau_low_cv_max": 0.01,
    "wood_aluminium_sites_differing": 12, "wood_aluminium_sites": 16,
    "low_law": [0.0268, 0.69], "high_law": [0.0305, 1.52],
}
# The paper's wood/aluminium τ test: ten contacts per material and site (its t = 3.14 at
# p = 0.0057 means 18 degrees of freedom).
PAPER_CONTACTS_PER_SITE = 10


def signal_statistics(features: xr.Dataset) -> dict:
    """The processed events' frequency laws, their scatter, the single-contact precision and
    the τ_low statistics, keyed as ``PAPER_SIGNAL`` (docs/reference.md)."""
    from scipy import stats

    p = features["params"]
    d = features["distance_cm"].values.astype(float)
    out, residual_sd = {}, {}
    for mode in ("low", "high"):
        logf = np.log10(p.sel(parameter=f"F_{mode}").values)
        fit = stats.linregress(d, logf)
        res = logf - (fit.slope * d + fit.intercept)
        out[f"{mode}_law"] = [float(fit.slope), float(fit.intercept)]
        out[f"r2_{mode}"] = _finite(fit.rvalue ** 2)    # None: the peak never moved
        residual_sd[mode] = float(res.std(ddof=2))
    out["residual_sd_dex"] = residual_sd
    out["spread_ratio_high_to_low"] = spread_ratio([residual_sd["high"]], [residual_sd["low"]])
    f_low, f_high = (p.sel(parameter=n).values for n in ("F_low", "F_high"))
    groups = [g for g in _site_groups(features) if len(g) > 1]
    out["spread_ratio_high_to_low_hz"] = spread_ratio(
        [f_high[g].std(ddof=1) for g in groups], [f_low[g].std(ddof=1) for g in groups])
    # the law may fall with distance (another antenna's): the precision is a length either way
    slope = abs(out["low_law"][0])
    out["single_contact_precision_mm"] = (10 * residual_sd["low"] / slope if slope > 0
                                          else None)    # a peak that never moves with distance
    tau = p.sel(parameter="tau_low").values
    out["tau_low_cv_median"] = float(np.median([tau[g].std(ddof=1) / tau[g].mean()
                                                for g in groups]))
    materials = features["material"].values.astype(str)
    # a material whose processed contacts sit at one distance has no slope to fit
    out["tau_low_slope_s_per_cm"] = {
        str(m): float(stats.linregress(d[materials == m], tau[materials == m]).slope)
        for m in np.unique(materials) if len(np.unique(d[materials == m])) > 1}
    out.update(wood_vs_aluminium(features, tau))
    return out


def _finite(value) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def spread_ratio(high_sd, low_sd) -> float | None:
    """The high peak's spread over the low one's within a site, pooled over the sites (mean
    sd over mean sd); None where the low peak never moves within a site (every contact on one
    FFT bin: the ratio has no finite value, and a per-site ratio would divide by zero)."""
    low = float(np.mean(low_sd)) if len(low_sd) else 0.0
    return float(np.mean(high_sd)) / low if low > 0 else None


def _site_groups(features: xr.Dataset) -> list[np.ndarray]:
    """Event indices of each (material, position)."""
    m = features["material"].values.astype(str)
    pos = features["position"].values
    return [np.flatnonzero((m == a) & (pos == b)) for a in np.unique(m) for b in np.unique(pos)]


def wood_vs_aluminium(features: xr.Dataset, tau: np.ndarray,
                      per_group: int = PAPER_CONTACTS_PER_SITE) -> dict:
    """Sites where wood and aluminium τ_low differ (t-test, p < 0.05) on the first
    ``per_group`` contacts per material and site; {} without both materials."""
    from scipy import stats

    m = features["material"].values.astype(str)
    if not {"wood", "aluminium"} <= set(m):
        return {}
    pos = features["position"].values
    differing, sites, t_values = 0, 0, []
    for site in np.unique(pos):
        a = tau[(m == "wood") & (pos == site)][:per_group]
        b = tau[(m == "aluminium") & (pos == site)][:per_group]
        if len(a) < 3 or len(b) < 3:
            continue
        t, pval = stats.ttest_ind(a, b)
        sites += 1
        differing += int(pval < 0.05)
        t_values.append(float(t))
    return {"wood_aluminium_sites_differing": differing, "wood_aluminium_sites": sites,
            "wood_aluminium_t": t_values, "contacts_per_site_in_test": per_group}
