"""The recorded drives of the gating study and their roles: the calibration drive, the
training drives and the held-out drives, split by drive, seeded, within the speed each drive
mostly ran at; checked when the spec is (``split_drives``), before any work."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.errors import SpecError
from ...sources import recorded

DRIVE_SPLIT = 3                # seed stream of the split (the scenes' streams are 0, 1, 2)
SPEED_TOLERANCE_CM_S = 0.05    # a logged command this close to a swept speed is that speed
CATEGORY = "held-out recorded drives"


@dataclass
class RecordedSplit:
    """The imported drives and their roles: the calibration drive, training and held-out
    drives (indices into ``drives.names``)."""
    drives: object               # sources.recorded.RecordedDrives
    calibration: int
    training: list
    held_out: list

    def recording(self, drive: int):
        return self.drives.recording(drive)

    def name(self, drive: int) -> str:
        return self.drives.names[drive]

    def roles(self) -> dict:
        return {"calibration drive": self.name(self.calibration),
                "training drives": [self.name(d) for d in self.training],
                "held-out drives": [self.name(d) for d in self.held_out]}


def split_drives(spec: dict, scene, sweep, held_out_share: float, seed: int
                 ) -> RecordedSplit | None:
    """The drives the spec names, checked and split (None without ``data``), before any work:
    the rate the array is checked at, a calibration drive, at least one training and one
    held-out drive with labelled contacts, a speed log on each, and every swept speed driven
    with labelled contacts on the training drives."""
    if spec.get("data") is None:
        return None
    path = spec["data"]
    drives = recorded.open_drives(path)
    if drives.rate_hz != scene.rate_hz:
        raise SpecError("data", path, f"drives sampled at the scenes' rate, {scene.rate_hz:g} "
                                      f"Hz (these: {drives.rate_hz:g})")
    recs = [drives.recording(d) for d in range(len(drives.names))]
    scored = [d for d, r in enumerate(recs) if r.truth.contacts]
    open_space = [d for d, r in enumerate(recs) if not r.truth.contacts]
    if not open_space:
        raise SpecError("data", path, "drives of which one holds no labelled contact (the "
                                      "calibration drive the preprocessing is fitted on)")
    if len(scored) < 2:
        raise SpecError("data", path, "at least two drives with labelled contacts (one to "
                                      "train on, one held out to score; these hold "
                                      f"{len(scored)})")
    for d in scored:
        if not np.isfinite(recs[d].meta["speed_cm_s"]).all():
            raise SpecError("data", f"{path}/{drives.names[d]}",
                            "a drive whose speed command is logged from its first sample "
                            "(`record` keeps it in meta.json and events.jsonl)")
    held = held_out_drives(recs, scored, held_out_share, seed)
    if not held:
        per_speed = {}
        for d in scored:
            per_speed[mostly_at(recs[d])] = per_speed.get(mostly_at(recs[d]), 0) + 1
        raise SpecError("evaluation.held_out_drives", held_out_share,
                        "a share that holds out at least one drive: of the n drives at each "
                        "logged speed round(share × n) are held out, one always kept to train "
                        f"on (drives per speed here: {per_speed})")
    split = RecordedSplit(drives, open_space[0], [d for d in scored if d not in held], held)
    driven = {}
    for d in split.training:
        for s, c in zip(sweep.speeds_cm_s, contacts_by_speed(recs[d], sweep.speeds_cm_s,
                                                             sweep.settle_s)):
            driven[float(s)] = driven.get(float(s), 0) + len(c)
    missing = [s for s, n in driven.items() if n == 0]
    if missing:
        ran_at = logged_speeds([recs[d] for d in split.training])
        raise SpecError("sweep.speeds_cm_s", sweep.speeds_cm_s.tolist(),
                        "speeds the training drives ran at with labelled contacts (training "
                        f"drives {', '.join(split.roles()['training drives'])} hold none at "
                        f"{missing}; they ran at {ran_at}: set the sweep's and the gate's speeds "
                        "to those, or record more drives)")
    return split


def held_out_drives(recs, scored: list, share: float, seed: int) -> list:
    """The drives held out for the evaluation: within each group of drives that ran mostly
    at one speed, ``share`` of them (rounded) drawn with ``seed``, always keeping one to
    train on, so the training drives cover every speed the set drove at."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(DRIVE_SPLIT,)))
    groups = {}
    for d in scored:
        groups.setdefault(mostly_at(recs[d]), []).append(d)
    held = []
    for _, members in sorted(groups.items()):
        n = int(min(round(share * len(members)), len(members) - 1))
        held += rng.permutation(members)[:n].tolist()
    return sorted(held)


def mostly_at(rec) -> float:
    values, counts = np.unique(np.round(np.asarray(rec.meta["speed_cm_s"], float), 2),
                               return_counts=True)
    return float(values[np.argmax(counts)])


def logged_speeds(recs) -> list[float]:
    """The distinct speed commands logged in ``recs``."""
    values = np.concatenate([np.asarray(r.meta["speed_cm_s"], dtype=float) for r in recs])
    return sorted(set(np.round(values[np.isfinite(values)], 2).tolist()))


def speed_at(rec, t_s: float) -> float:
    v = rec.meta["speed_cm_s"]
    return float(v[min(max(int(t_s * rec.rate_hz), 0), len(v) - 1)])


def at_speed(value: float, speed: float) -> bool:
    return abs(value - speed) <= SPEED_TOLERANCE_CM_S


def contacts_by_speed(rec, speeds, settle_s: float) -> list[list]:
    """The drive's labelled contacts after ``settle_s`` at each of ``speeds``."""
    return [[c for c in rec.truth.contacts
             if c.t_s >= settle_s and at_speed(speed_at(rec, c.t_s), s)] for s in speeds]
