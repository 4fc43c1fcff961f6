"""The quickstart's two stages, kept apart so the ground truth cannot reach the read-out:
``read_out`` sees only the sensor's samples, ``score`` compares its detections with the
scene's contacts afterwards; ``run`` chains them and writes the report."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ...core.logfile import logged
from ...core.signals import Recording
from ...evaluation.scoring import contact_rows
from ...evaluation.scoring import score as score_detections
from ...preprocess import fit_warmup
from ...readout.contacts import ContactEstimate, centroid_hz, dominant_hz
from ...report.stats import poisson_interval
from ..contract import Options, Plan
from .plan import Parts
from .report import human_summary, write_report


@dataclass
class ReadOut:
    """What the robot knows after reading its sensor: no ground truth in here."""
    coded: np.ndarray
    rates: xr.DataArray
    detections: list[ContactEstimate]
    dominant_hz: list[float]      # most active neuron of each detection's episode
    motion_hz: float | None       # activity centroid outside detections, after the warm-up
    n_spikes: int
    simulation_wall_s: float


def read_out(samples: np.ndarray, rate_hz: float, parts: Parts) -> ReadOut:
    """Detect contacts from the sensor's samples alone (ADC counts, shape (n, 2))."""
    fit_warmup(parts.chain, samples, rate_hz, parts.warmup_s)
    coded = parts.chain.transform(samples)
    result = parts.array.run(Recording(coded, rate_hz, units="coded"),
                             window_s=parts.window_s)
    rates = result.rate_map
    # Nothing is read out while the chain calibrates.
    detections = [d for d in parts.detector.detect(rates) if d.onset_s >= parts.warmup_s]
    dominant = [float(dominant_hz(rates.sel(window_s=slice(d.onset_s, d.end_s - 1e-9))
                                  .sum("window_s"))) for d in detections]
    start = rates.window_s.values
    quiet = start >= parts.warmup_s
    for d in detections:
        quiet &= ~((start >= d.onset_s) & (start < d.end_s))
    motion = float(centroid_hz(rates.isel(window_s=np.flatnonzero(quiet)),
                               dim=("neuron_hz", "window_s"))) if quiet.any() else 0.0
    return ReadOut(coded, rates, detections, dominant, motion or None,
                   int(len(result.spike_i)), result.wall_s)


def score(readout: ReadOut, contacts, duration_s: float, parts: Parts) -> dict:
    """Score the read-out against the ground truth, after it has run."""
    s = score_detections(readout.detections, contacts, duration_s, parts.detector,
                         parts.array, parts.window_s, settle_s=parts.warmup_s)
    low, high = poisson_interval(s.fp)
    per_contact = contact_rows(readout.detections, readout.dominant_hz, contacts,
                               parts.window_s, parts.warmup_s)
    errors = [abs(p["distance_error_cm"]) for p in per_contact if p["distance_cm"] is not None]
    return {**s.as_dict(), "scored_minutes": s.minutes,
            "fp_per_min_interval": [low / s.minutes, high / s.minutes],
            "mean_abs_distance_error_cm": float(np.mean(errors)) if errors else None,
            "contacts": per_contact}


@logged
def run(plan: Plan, out_dir, options: Options = Options(), log=print) -> dict:
    spec, parts, quick = plan.spec, plan.parts, options.quick
    scene, array = parts.scene, parts.array
    seed = plan.seed
    t_start = time.perf_counter()
    log(f"[1/4] the scene: {scene.describe()}")
    rec = scene.generate(seed)
    log(f"[2/4] reading out from the samples alone: chain fitted on the first "
        f"{parts.warmup_s:g} s, then {array.n_neurons} resonators ({array.band_hz[0]:g}–"
        f"{array.band_hz[1]:g} Hz) in Brian2 ({array.target}, dt {array.dt_ms:g} ms)")
    out = read_out(rec.samples, rec.rate_hz, parts)
    log("[3/4] scoring every detection against the scene's contacts")
    scored = score(out, rec.truth.contacts, rec.duration_s, parts)
    log("[4/4] writing the report")

    first = scored["contacts"][0] if scored["contacts"] else None
    summary = {
        "motion_dominant_hz": out.motion_hz,
        "detections": [{**d.as_dict(), "dominant_hz": f}
                       for d, f in zip(out.detections, out.dominant_hz)],
        "score": scored,
        # the first scored contact, for a quick look
        "contact_detected_s": first["detected_s"] if first else None,
        "contact_frequency_hz": first["frequency_hz"] if first else None,
        "contact_dominant_hz": first["dominant_hz"] if first else None,
        "distance_cm": first["distance_cm"] if first else None,
        "true_contact_s": first["true_t_s"] if first else None,
        "true_distance_cm": first["true_distance_cm"] if first else None,
        "warmup_s": parts.warmup_s,
        "n_spikes": out.n_spikes,
        "simulation_wall_s": out.simulation_wall_s,
        "total_wall_s": time.perf_counter() - t_start,
    }
    summary = write_report(out_dir, spec, parts, rec, out, scored, summary, quick)
    log(human_summary(summary, out_dir))
    return summary
