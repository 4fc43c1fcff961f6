"""The gating study on recorded drives (``data = "DIR"``: drives imported with their speed log).

With recorded drives every stage reads recordings, none a generated scene:

- the **calibration drive** (the first drive without labelled contacts: a drive in the open)
  fits the preprocessing chain, as the scenes' chain is fitted on a drive in the open;
- the drives with labelled contacts are **split by drive**, seeded (``SeedSequence(seed,
  spawn_key=(DRIVE_SPLIT,))``): ``evaluation.held_out_drives`` of them are held out for the
  evaluation, the rest are the **training drives**;
- the **sweep** codes every training drive at every Th once and scores its detections per
  logged speed (``score_by_speed``: a contact counts at the speed the robot drove when it was
  touched, a false positive at the speed of its onset, minutes at each speed from the speed
  log), so Th*(speed) and the gate's training targets come from the training drives only;
- the **evaluation** reads the held-out drives out blind with each method's Th (fixed, the
  lookup table's and the gate's, both from the drive's logged speed command), one held-out
  drive per paired unit (as a seed slot is for scenes): intervals over drives, with their n.

Nothing is scored on what trained it. A set too small to split, or whose training drives lack
a speed the sweep needs, is refused in one line when the spec is checked (``split_drives``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...engine.batches import Batches, DetectColumns
from ...evaluation.scoring import Score, first_match, score, score_columns
from ...evaluation.thresholds import MethodScores, fixed_method
from .drives import (CATEGORY, SPEED_TOLERANCE_CM_S, RecordedSplit, at_speed,
                     contacts_by_speed, speed_at)
from .plan import make_parts
from .scenes import coded_at, condition

def score_by_speed(readout, detections: list, rec, speeds) -> list[Score]:
    """A whole drive's detections scored separately at each of ``speeds``: a contact counts at
    the speed logged when it was touched; a detection at the speed of the contact it falls
    on, failing one at the speed of its onset; the minutes at each speed from the speed log
    (after the settling time)."""
    window, settle = readout.window_s, readout.settle_s
    v = np.asarray(rec.meta["speed_cm_s"], dtype=float)
    contacts = list(rec.truth.contacts)

    def speed_of(d) -> float:
        on = [c for c in contacts if first_match([d], c, window) is not None]
        return speed_at(rec, on[0].t_s if on else d.onset_s)

    scores = []
    for s, mine in zip(speeds, contacts_by_speed(rec, speeds, settle)):
        seconds = float(np.sum(np.abs(v[int(settle * rec.rate_hz):] - s)
                               <= SPEED_TOLERANCE_CM_S)) / rec.rate_hz
        dets = [d for d in detections if at_speed(speed_of(d), s)]
        sc = score(dets, mine, rec.duration_s, readout.detector, readout.array, window, settle)
        scores.append(replace(sc, minutes=seconds / 60.0))
    return scores


@dataclass(frozen=True)
class RecordedSweep:
    """The Th × speed sweep on the training drives as a ``run_sweep`` evaluator over
    speed_cm_s × scene (a training drive) × threshold_g: each (drive, Th) of a chunk is coded
    and read out once and scored at each speed of the chunk. It holds the resolved spec, so it
    pickles; ``make_parts`` re-opens the drives on the worker."""
    spec: dict

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        parts = make_parts(self.spec)
        split = parts.data
        pairs = np.stack([points["scene"], points["threshold_g"]], axis=1)
        unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
        columns, recs = [], {}
        for scene in np.unique(unique[:, 0]).astype(int):
            rec = recs[scene] = split.recording(split.training[scene])
            x, coder = condition(parts, rec)
            columns += coded_at(coder, x, unique[unique[:, 0] == scene, 1])
        runs = Batches(DetectColumns(parts.readout), parts.sweep.codings_per_run).run(columns)
        speeds = parts.sweep.speeds_cm_s
        by_pair = [score_by_speed(parts.readout, detections, recs[int(scene)], speeds)
                   for (scene, _), (detections, _) in zip(unique, runs)]
        return score_columns([by_pair[p][int(np.flatnonzero(speeds == v)[0])]
                              for p, v in zip(inverse.ravel(), points["speed_cm_s"])])


def evaluate_drives(parts, fixed_th: np.ndarray, recall, codings, others: dict, log):
    """Every held-out drive read out blind with each method's Th: a ``MethodScores`` with one
    slot per held-out drive, and the first drive's online Th and rate map (the example)."""
    split, scores = parts.data, MethodScores([CATEGORY])
    items, keys, example = [], [], None
    for slot, d in enumerate(split.held_out):
        rec = split.recording(d)
        x, coder = condition(parts, rec)
        speed = np.asarray(rec.meta["speed_cm_s"], dtype=float)[:, None]
        gated = parts.gate.thresholds(speed, rec.rate_hz)[:, 0]
        lookup = recall.table(speed)[:, 0]
        items += [(rec, c) for c in coded_at(coder, x, fixed_th)]
        items += [(rec, coder.partial_transform(x, threshold=lookup)),
                  (rec, coder.partial_transform(x, threshold=gated))]
        items += [(rec, other.fit(x).partial_transform(x, threshold=gated))   # the gate's Th,
                  for other in others.values()]                               # another coder
        keys += [(m, slot) for m in [*(fixed_method(t) for t in fixed_th), "lookup", "gated",
                                     *others]]
        if example is None:
            example = {"rec": rec, "gated_th": gated, "lookup_th": lookup,
                       "key": ("gated", slot)}
    n_contacts = sum(len(split.recording(d).truth.contacts) for d in split.held_out)
    log(f"[4/5] evaluation on {len(split.held_out)} held-out recorded drive(s) "
        f"({n_contacts} labelled contacts): {len(fixed_th)} fixed Th, the lookup table and "
        "the gate")
    results, maps = codings.run(items, "held-out drives")
    for (method, slot), sc, rates in zip(keys, results, maps):
        scores.add(method, slot, 0, sc)
        if (method, slot) == example["key"]:
            example["map"] = rates
    return scores, example


def summary_entry(split: RecordedSplit) -> dict:
    """What ``summary.json`` keeps: the data's origin and which drive played which part."""
    def labelled(drives) -> int:
        return sum(len(split.recording(d).truth.contacts) for d in drives)

    return {**split.roles(), "data": split.drives.summary_entry(),
            "labelled_contacts": {"training drives": labelled(split.training),
                                  "held-out drives": labelled(split.held_out)},
            "parts_from_recordings": ["preprocessing (calibration drive)",
                                      "Th x speed sweep and Th*(speed) (training drives)",
                                      "the gate's training targets (training drives)",
                                      "evaluation (held-out drives)"],
            "provenance": split.drives.provenance_rows()}


def report_section(rep, s: dict) -> None:
    """Where the recorded drives came from and which part each played, in the report."""
    rec = s.get("recorded")
    if not rec:
        return
    rep.heading("The recorded drives")
    rep.text(f"This run read recorded drives in place of the scenes above, at every stage: "
             f"the preprocessing was fitted on {rec['calibration drive']} (no labelled "
             "contact); the Th × speed sweep, Th*(speed) "
             f"and the gate's training targets came from the training drives "
             f"({', '.join(rec['training drives'])}); the evaluation scored only the held-out "
             f"drives ({', '.join(rec['held-out drives'])}), split by drive with the study's "
             f"seed ({rec['labelled_contacts']['training drives']} and "
             f"{rec['labelled_contacts']['held-out drives']} labelled contacts). No generated "
             "scene entered any number on this page.")
    rep.table([{"what": w, "value": v} for w, v in rec["provenance"]],
              "Where the recorded drives came from")
