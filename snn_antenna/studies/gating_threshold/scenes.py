"""The gating study's scenes and their blind read-out: seeded courses, the calibration
drive that fits the chain (or the recordings' drive in the open), the signal just before the
coder, its codings at many thresholds, and the Th × speed sweep's evaluator."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engine.batches import ScoredCodings
from ...evaluation.scoring import score_columns
from ...sources.scenes import CourseScene, SpeedProfile, course_drive, drive
from .plan import COURSE_DRAW, NOISE_DRAW, SWEEP_SCENES, Parts, make_parts


def make_scene(parts: Parts, speed: SpeedProfile, key: tuple, terrain: str | None = None
               ) -> tuple[CourseScene, np.random.SeedSequence]:
    """A new course scene along ``speed`` and the seed of its recording, both from the
    stream ``key`` of the study's seed."""
    course_rng = np.random.default_rng(np.random.SeedSequence(parts.seed,
                                                              spawn_key=(*key, COURSE_DRAW)))
    scene = course_drive(parts.scene, speed, parts.sweep.scene_s, parts.course, course_rng,
                         terrain)
    return scene, np.random.SeedSequence(parts.seed, spawn_key=(*key, NOISE_DRAW))


def calibrated_chain(parts: Parts):
    """The preprocessing chain fitted on a separate calibration drive, never on a test scene:
    ``calibration.duration_s`` at ``calibration.speed_cm_s`` in the open (no posts, so no
    contact can leak in); the scenes are then transformed causally from their first sample."""
    if parts.chain is None and parts.data is not None:    # the recordings' own drive
        rec = parts.data.recording(parts.data.calibration)
        parts.chain = parts.preprocess.chain(parts.data.drives).fit(rec.samples)
    if parts.chain is None:
        cal, scene = parts.calibration, parts.scene
        rec = drive(scene, SpeedProfile("constant", float(cal.speed_cm_s)), cal.duration_s,
                    []).generate(cal.seed)
        assert not rec.truth.contacts   # an open-space drive: nothing to touch
        parts.chain = parts.preprocess.chain(scene).fit(rec.samples)
    return parts.chain


def condition(parts: Parts, rec):
    """The recording's signal just before the coder (g, one channel) and the coder: only
    ``rec.samples`` is read."""
    chain = calibrated_chain(parts)
    x = rec.samples
    for _, step in chain.steps[:-1]:
        x = step.transform(x)
    return x, chain.named_steps["coder"]


def sweep_scene(parts: Parts, speed_cm_s: float, scene: int):
    """The sweep's course scene ``scene`` at a constant speed: recording, conditioned signal,
    coder. The same course and noise at every speed (speeds are compared on equal scenes)."""
    course, seed = make_scene(parts, SpeedProfile("constant", float(speed_cm_s)),
                              (SWEEP_SCENES, int(scene)))
    rec = course.generate(seed)
    return (rec, *condition(parts, rec))


def coded_at(coder, x: np.ndarray, thresholds) -> list[np.ndarray]:
    """``x`` coded at each of ``thresholds``: one column each."""
    th = np.asarray(thresholds, dtype=float)
    coded = coder.partial_transform(np.repeat(x[:, None], len(th), axis=1), threshold=th[None, :])
    return [coded[:, j] for j in range(len(th))]


@dataclass(frozen=True)
class ThresholdSweep:
    """The Th × speed sweep as a ``run_sweep`` evaluator over speed_cm_s × scene ×
    threshold_g: each (speed, scene) of a chunk is generated and conditioned once, coded at
    its thresholds, and the chunk's codings run as one Brian2 group. It holds the resolved
    spec, so it pickles; ``make_parts`` re-checks it on the worker (milliseconds)."""
    spec: dict

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        parts = make_parts(self.spec)
        items, order = [], []
        pairs = np.stack([points["speed_cm_s"], points["scene"]], axis=1)
        for v, scene in np.unique(pairs, axis=0):
            idx = np.flatnonzero((pairs[:, 0] == v) & (pairs[:, 1] == scene))
            rec, x, coder = sweep_scene(parts, v, scene)
            items += [(rec, c) for c in coded_at(coder, x, points["threshold_g"][idx])]
            order += list(idx)
        scores, _ = ScoredCodings(parts.readout, parts.sweep.codings_per_run).run(items)
        ordered = [None] * len(order)
        for i, sc in zip(order, scores):
            ordered[i] = sc
        return score_columns(ordered)
