"""The gate on recorded drives (``data = "DIR"``: drives imported with their speed log).

After the gate has learned Th*(speed), every recorded drive that holds labelled contacts is read
out blind with the Th each method sets: the gate's online Th and the lookup table's (both from
the drive's logged speed command only), each fixed Th evaluated on the scenes, and the fixed Th
chosen on the sweep. The preprocessing is fitted on the recordings' own calibration drive (the
first drive without labelled contacts: as the scenes' chain is fitted on a drive in the open),
never on a scored drive; the detections are then scored against the labels.
"""
from __future__ import annotations

import numpy as np

from ...core.errors import SpecError
from ...evaluation.scoring import Score
from ...evaluation.thresholds import fixed_method
from ...preprocess import make_chain
from ...sources import recorded


def open_drives(spec: dict, scene):
    """The imported drives the spec names (None without ``data``), checked against the
    scenes the study is calibrated on, before any work."""
    if spec.get("data") is None:
        return None
    drives = recorded.open_drives(spec["data"])
    if drives.rate_hz != scene.rate_hz:
        raise SpecError("data", spec["data"], f"drives sampled at the scenes' rate, "
                                              f"{scene.rate_hz:g} Hz (these: {drives.rate_hz:g})")
    recs = [drives.recording(d) for d in range(len(drives.names))]
    scored = [r for r in recs if r.truth.contacts]
    if not scored or len(scored) == len(recs):
        raise SpecError("data", spec["data"], "drives of which at least one holds labelled "
                                              "contacts (scored) and one none (the calibration "
                                              "drive the preprocessing is fitted on)")
    for name, rec in zip(drives.names, recs):
        if rec.truth.contacts and not np.isfinite(rec.meta["speed_cm_s"]).all():
            raise SpecError("data", f"{spec['data']}/{name}",
                            "a drive whose speed command is logged from its first sample "
                            "(`record` keeps it in meta.json and events.jsonl)")
    return drives


def score_drives(parts, drives, fixed_th: np.ndarray, sweep_th: float, recall, codings, log
                 ) -> dict:
    """Each method's score pooled over the recorded drives, and the data's origin."""
    recs = [drives.recording(d) for d in range(len(drives.names))]
    calibration = next(r for r in recs if not r.truth.contacts)
    scored = [r for r in recs if r.truth.contacts]
    chain = make_chain(drives.rate_hz, drives.adc_bits, drives.full_scale_g,
                       **parts.preprocess).fit(calibration.samples)
    coder = chain.named_steps["coder"]
    log(f"      recorded drives: {len(scored)} scored "
        f"({sum(len(r.truth.contacts) for r in scored)}"
        f" labelled contacts), the chain fitted on {calibration.meta['source']}")
    items, keys = [], []
    fixed = np.unique(np.r_[fixed_th, sweep_th])
    for rec in scored:
        x = rec.samples
        for _, step in chain.steps[:-1]:
            x = step.transform(x)
        speed = rec.meta["speed_cm_s"].astype(float)[:, None]
        gated = parts.gate.thresholds(speed, drives.rate_hz)[:, 0]
        lookup = recall.table(speed)[:, 0]
        coded = coder.partial_transform(np.repeat(x[:, None], len(fixed), axis=1),
                                        threshold=fixed[None, :])
        items += [(rec, coded[:, j]) for j in range(len(fixed))]
        keys += [fixed_method(t) for t in fixed]
        items += [(rec, coder.partial_transform(x, threshold=lookup)),
                  (rec, coder.partial_transform(x, threshold=gated))]
        keys += ["lookup", "gated"]
    scores, _ = codings.run(items, "recorded drives")
    totals = {}
    for key, sc in zip(keys, scores):
        totals[key] = totals.get(key, Score()) + sc
    best = max((fixed_method(t) for t in fixed), key=lambda k: totals[k].f1 or 0.0)
    rows = [{"method": name, **totals[key].as_dict()} for name, key in (
        ("gate (online Th from the logged speed)", "gated"), ("lookup table", "lookup"),
        ("fixed Th chosen on the sweep", fixed_method(sweep_th)),
        ("best fixed Th on these drives (hindsight)", best))]
    return {"rows": rows, "drives": [r.meta["source"] for r in scored],
            "calibration_drive": calibration.meta["source"],
            "data": recorded.summary_entry(drives),
            "provenance": recorded.provenance_rows(drives)}


def report_section(rep, s: dict) -> None:
    """The recorded drives' scores and where they came from, in the study's report."""
    rec = s.get("recorded")
    if not rec:
        return
    rep.heading("The gate on recorded drives")
    rep.text(f"{len(rec['drives'])} recorded drive(s) with their logged speed command, read out "
             f"blind with the chain fitted on {rec['calibration_drive']}; every method's "
             "detections scored against the drives' labels, pooled over the drives. One "
             "recording set, no seeds: no interval.")
    rep.table(rec["rows"], "Detections on the recorded drives per Th method")
    rep.table([{"what": w, "value": v} for w, v in rec["provenance"]],
              "Where the recorded drives came from")
