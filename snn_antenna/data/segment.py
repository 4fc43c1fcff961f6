"""Contacts found in a continuous recording by the paper's onset rule, matched to the labels.

The onset rule is the event processing's (``readout.events``): the two axes in g, aligned to
their main axis (as ``main_axis_g`` aligns them: PCA over the recording, its mean removed, so
the sensor's resting offset is not a contact), and a contact starts where |x| first exceeds
``onset_threshold_g``. In a continuous recording two more conditions make one contact one
onset: |x| stayed below the threshold for ``quiet_s`` just before (a ringing rod dips below it
between its swings, never for that long while it is loud), and at least ``dead_s`` passed since
the previous onset (the ringing of one contact is not the next).

Every contact is then cut as the generator cuts its events: ``pre_trigger_s`` before the
onset to ``duration_s`` after it. Left out, each with its recording, time and label line:

``no_contact``      a label with no onset within ``match_s`` of it
``unlabelled``      an onset no label claims
``gap``             the window holds samples the link lost (the recording's sequence numbers)
``clipped``         the window holds a count at either rail of the ADC
``beyond_end``      the window runs past either end of the recording
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import bounds
from ..readout.events import EventProcessor
from ..sources.antenna import ADC
from .inputs import CHUNK_ROWS as BLOCK, Stream
from .labels import Label

REASONS = ("no_contact", "unlabelled", "gap", "clipped", "beyond_end")
CLOCK_LABELS = 400      # labels whose differences to every onset are searched for a shift


@dataclass(frozen=True)
class Segmentation:
    """How contacts are found and cut (the ``data import`` options)."""
    onset_threshold_g: float = EventProcessor.onset_threshold_g
    # a period of the slowest low mode (7 Hz): a decaying ringing dips below the threshold
    # between its swings for a fraction of a period only
    quiet_s: float = 0.15
    dead_s: float = 0.5
    match_s: float = 0.1
    pre_trigger_s: float = 0.05
    duration_s: float = 1.0

    def __post_init__(self):
        bounds.declared(self)
        bounds.number("onset_threshold_g", self.onset_threshold_g, 0.0, lo_open=True, unit=" g")
        for name in ("quiet_s", "dead_s", "match_s", "pre_trigger_s"):
            bounds.seconds(name, getattr(self, name))
        bounds.positive_seconds("duration_s", self.duration_s)

    def n_samples(self, rate_hz: float) -> int:
        return int(round((self.pre_trigger_s + self.duration_s) * rate_hz))


@dataclass(frozen=True)
class Contact:
    """A labelled contact found and cut: the label and its window's first frame."""
    label: Label
    index: int              # the label's position in the table
    onset_frame: int


@dataclass(frozen=True)
class Exclusion:
    recording: str
    t_s: float
    line: int | None        # the label's line, None for an unlabelled onset
    reason: str
    distance_cm: float | None = None    # the label's position, None for an unlabelled onset

    def row(self) -> dict:
        return {"recording": self.recording, "t_s": round(self.t_s, 6),
                "label_line": "" if self.line is None else self.line, "reason": self.reason,
                "distance_cm": "" if self.distance_cm is None else self.distance_cm}


def onsets(stream: Stream, seg: Segmentation) -> np.ndarray:
    """Indexes (into ``stream.counts``) of the contacts' onsets (see the module docstring)."""
    above = np.flatnonzero(above_threshold(stream, seg.onset_threshold_g))
    quiet = max(1, int(round(seg.quiet_s * stream.rate_hz)))
    # an onset: above the threshold, none of the ``quiet`` samples before it above
    candidates = above[np.concatenate([[True], np.diff(above) > quiet])] if len(above) \
        else above
    dead = seg.dead_s * stream.rate_hz
    chosen, last = [], -np.inf
    frames = stream.frames
    for i in candidates:
        if frames[i] - last >= dead:
            chosen.append(i)
            last = frames[i]
    return np.asarray(chosen, dtype=np.int64)


def above_threshold(stream: Stream, threshold_g: float) -> np.ndarray:
    """|main axis| > ``threshold_g`` per sample: the two axes in g aligned to their main axis
    as ``main_axis_g`` aligns them (PCA over the recording, its mean removed), worked through
    in blocks so that memory follows a block, not the recording."""
    counts, n = stream.counts, len(stream.counts)
    blocks = range(0, n, BLOCK)
    adc = ADC(stream.adc_bits, stream.full_scale_g)

    def g(lo):
        return adc.to_g(counts[lo:lo + BLOCK])

    mean = sum(g(lo).sum(axis=0) for lo in blocks) / n
    scatter = np.zeros((2, 2))
    for lo in blocks:
        centred = g(lo) - mean
        scatter += centred.T @ centred
    _, eigvec = np.linalg.eigh(scatter / max(n - 1, 1))
    axis = eigvec[:, -1]
    out = np.empty(n, dtype=bool)
    for lo in blocks:
        out[lo:lo + BLOCK] = np.abs((g(lo) - mean) @ axis) > threshold_g
    return out


def reconcile(stream: Stream, labels: list[tuple[int, Label]], seg: Segmentation,
              found: np.ndarray | None = None) -> tuple[list[Contact], list[Exclusion]]:
    """Match ``labels`` (their table positions and rows, this recording's) to the onsets
    found in ``stream`` (``found``, or found here); every label and onset ends up either a
    contact or an exclusion."""
    found = onsets(stream, seg) if found is None else found
    t_found = stream.time_of(stream.frames[found])
    pairs = sorted((abs(t_found[j] - lab.onset_s), k, j) for k, (_, lab) in enumerate(labels)
                   for j in np.flatnonzero(np.abs(t_found - lab.onset_s) <= seg.match_s))
    label_of, onset_of = {}, {}
    for _, k, j in pairs:
        if k not in label_of and j not in onset_of:
            label_of[k], onset_of[j] = j, k
    contacts, excluded = [], []
    for k, (index, lab) in enumerate(labels):
        if k not in label_of:
            excluded.append(Exclusion(stream.name, lab.onset_s, lab.line, "no_contact",
                                      lab.distance_cm))
            continue
        i = found[label_of[k]]
        reason = window_problem(stream, i, seg)
        if reason:
            excluded.append(Exclusion(stream.name, float(t_found[label_of[k]]), lab.line, reason,
                                      lab.distance_cm))
        else:
            contacts.append(Contact(lab, index, int(stream.frames[i])))
    excluded += [Exclusion(stream.name, float(t_found[j]), None, "unlabelled")
                 for j in range(len(found)) if j not in onset_of]
    return contacts, sorted(excluded, key=lambda e: e.t_s)


@dataclass(frozen=True)
class Clock:
    """How a recording's labels sit on its clock: of ``labels``, ``matched`` lie within
    ``match_s`` of an onset found; ``lag_s`` is the median time from label to onset of those
    (a consistent lag is reported, never applied); ``offset_s`` a shift of every label that
    would match ``offset_matched`` of them, when it explains the labels far better than none
    (else None)."""
    recording: str
    labels: int
    matched: int
    lag_s: float | None
    offset_s: float | None
    offset_matched: int

    def row(self) -> dict:
        return {"recording": self.recording, "labels": self.labels, "matched": self.matched,
                "median_lag_s": None if self.lag_s is None else round(self.lag_s, 6),
                "offset_s": None if self.offset_s is None else round(self.offset_s, 6),
                "offset_matched": self.offset_matched}


def clock_fit(stream: Stream, label_s: np.ndarray, found: np.ndarray,
              seg: Segmentation) -> Clock:
    """How the label times ``label_s`` sit against the onsets ``found`` in ``stream``: the
    shift matching most labels (a window of 2 ``match_s`` slid over the label-to-onset
    differences of up to ``CLOCK_LABELS`` labels; onsets are ``dead_s`` apart, so a label
    matches one onset per window), counted over every label."""
    t_found = stream.time_of(stream.frames[found])
    label_s = np.asarray(label_s, dtype=float)
    if not len(label_s) or not len(t_found):
        return Clock(stream.name, len(label_s), 0, None, None, 0)

    def nearest(times):           # signed time from each label to its nearest onset
        j = np.clip(np.searchsorted(t_found, times), 1, len(t_found) - 1)
        left, right = t_found[j - 1] - times, t_found[j] - times
        return np.where(np.abs(left) <= np.abs(right), left, right) if len(t_found) > 1 \
            else t_found[0] - times

    lags = nearest(label_s)
    near = np.abs(lags) <= seg.match_s
    matched = int(near.sum())
    lag = float(np.median(lags[near])) if matched else None
    sample = label_s[np.linspace(0, len(label_s) - 1, min(len(label_s), CLOCK_LABELS))
                     .astype(int)]
    flat = np.sort((t_found[None, :] - sample[:, None]).ravel())
    inside = np.searchsorted(flat, flat + 2 * seg.match_s, side="right") - np.arange(len(flat))
    best = int(np.argmax(inside))
    shift = float(np.median(flat[best:best + inside[best]]))
    shifted = int((np.abs(nearest(label_s + shift)) <= seg.match_s).sum())
    found_offset = (abs(shift) > seg.match_s and shifted >= 3 and shifted >= 2 * matched
                    and shifted >= len(label_s) / 2)
    return Clock(stream.name, len(label_s), matched, lag, shift if found_offset else None,
                 shifted if found_offset else 0)


def window_problem(stream: Stream, i: int, seg: Segmentation) -> str | None:
    """Why the window of the onset at index ``i`` cannot be a contact event, or None."""
    start, n = window_bounds(stream, i, seg)
    frames = stream.frames
    if start < frames[0] or start + n > frames[-1] + 1:
        return "beyond_end"
    lo, hi = np.searchsorted(frames, [start, start + n])
    if hi - lo != n:
        return "gap"
    window = stream.counts[lo:hi]
    if np.any(window <= 0) or np.any(window >= 2 ** stream.adc_bits - 1):
        return "clipped"
    return None


def stretch_problem(stream: Stream, t_s: float, seg: Segmentation) -> str | None:
    """Why the stretch of a drive around a labelled contact at ``t_s`` (from ``pre_trigger_s``
    before to ``duration_s`` after, within the recording) cannot be scored, or None."""
    start = max(int(round(stream.frame_at(t_s - seg.pre_trigger_s))), int(stream.frames[0]))
    stop = min(int(round(stream.frame_at(t_s + seg.duration_s))), int(stream.frames[-1]) + 1)
    lo, hi = np.searchsorted(stream.frames, [start, stop])
    if hi - lo != stop - start:
        return "gap"
    window = stream.counts[lo:hi]
    if np.any(window <= 0) or np.any(window >= 2 ** stream.adc_bits - 1):
        return "clipped"
    return None


def window_bounds(stream: Stream, i: int, seg: Segmentation) -> tuple[int, int]:
    """(first frame, samples) of the event window around the onset at index ``i``."""
    pre = int(round(seg.pre_trigger_s * stream.rate_hz))
    return int(stream.frames[i]) - pre, seg.n_samples(stream.rate_hz)


def cut(stream: Stream, onset_frame: int, seg: Segmentation) -> np.ndarray:
    """The event window (samples, 2) of a contact whose onset is at ``onset_frame``."""
    start = onset_frame - int(round(seg.pre_trigger_s * stream.rate_hz))
    lo = int(np.searchsorted(stream.frames, start))
    return stream.counts[lo:lo + seg.n_samples(stream.rate_hz)]
