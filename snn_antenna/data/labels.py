"""The labels table of an import: what happened when, as the lab wrote it down.

A CSV file with a header. For bench contacts (a stationary antenna struck at known places):

``recording``    the recording's name in the recordings folder (a ``record`` folder's or a
                 file's name, with or without its extension); may be left out when there is
                 one recording
``onset_s``      when the contact happened, in seconds on the recording's own clock (a
                 ``record`` folder's sample at its sequence number over the rate, a CSV's
                 ``t_s``, a bag's header stamps in seconds since 1970, an ``.npz``'s
                 ``start_s``; else its first sample is at 0)
``distance_cm``  where along the rod, in cm from its base
``material``     what was struck: a lowercase name (letters, digits, ``_``); the lab's own
                 materials are the names its labels use
``repetition``   optional: the repetition's number (from 0) at that site; splits are by
                 repetition, so repeated contacts at a site must be numbered apart; without it,
                 contacts at a site are numbered in time order

For drives (a robot driving with its antenna out, touching what it meets), a table whose header
names ``contact_s`` in place of ``onset_s``:

``recording``    as above
``contact_s``    when the antenna touched, in seconds on the recording's clock
``distance_cm``  where along the rod
``material``     optional: what it touched

The speed command of a drive is the recording's own log (a ``record`` folder keeps the speed it
started at in ``meta.json`` and every change in ``events.jsonl``).

Every refusal names the file, the line and the column; lines are counted as an editor counts
them (the header is line 1).
"""
from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import SpecError
from ..sources import antenna

REQUIRED = ("onset_s", "distance_cm", "material")
OPTIONAL = ("recording", "repetition")
COLUMNS = REQUIRED + OPTIONAL
DRIVE_REQUIRED = ("contact_s", "distance_cm")
DRIVE_OPTIONAL = ("recording", "material")
DRIVE_COLUMNS = DRIVE_REQUIRED + DRIVE_OPTIONAL


def is_drive_table(path) -> bool:
    """A drives table names ``contact_s`` in its header (a bench table ``onset_s``)."""
    try:
        first = Path(path).read_text(encoding="utf-8-sig").splitlines()[:1]
    except (OSError, UnicodeDecodeError):
        return False
    return bool(first) and "contact_s" in [h.strip() for h in first[0].split(",")]


@dataclass(frozen=True)
class Label:
    line: int
    recording: str
    onset_s: float
    distance_cm: float
    material: str
    repetition: int | None


MATERIAL_NAME = re.compile(r"[a-z][a-z0-9_]*")
MISSING = ("nan", "none", "null", "na", "n_a")


def read_labels(path, recordings: dict[str, str]) -> list[Label]:
    """The rows of the labels table at ``path``, each checked (``recordings``: every name a row
    may give → the recording's name): a refusal names the file, line and column. A drives
    table's rows carry ``contact_s`` as their ``onset_s`` and no repetition. Times are checked
    against the recordings' clocks by :func:`check_times`."""
    path = Path(path)
    drive = is_drive_table(path)
    required, optional = (DRIVE_REQUIRED, DRIVE_OPTIONAL) if drive else (REQUIRED, OPTIONAL)
    columns = required + optional
    name = path.name
    if not path.is_file():
        raise SpecError("labels", str(path), "an existing CSV file of labels")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise SpecError("labels", str(path), f"a UTF-8 text CSV file ({type(exc).__name__})") \
            from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise SpecError("labels", str(path), f"a CSV whose header names {', '.join(REQUIRED)} "
                                             f"(and optionally {', '.join(OPTIONAL)}), or for "
                                             f"drives {', '.join(DRIVE_REQUIRED)} (and "
                                             f"optionally {', '.join(DRIVE_OPTIONAL)}); this "
                                             "one is empty")
    header = [h.strip() for h in rows[0]]
    for column in header:
        if column not in columns:
            raise SpecError(f"{name} line 1", column,
                            f"a column of the {'drives' if drive else 'bench'} labels table: "
                            f"{', '.join(columns)}")
    if len(set(header)) != len(header):
        raise SpecError(f"{name} line 1", ",".join(header), "each column named once")
    missing = [c for c in required if c not in header]
    if missing:
        raise SpecError(f"{name} line 1", ",".join(header),
                        f"a header naming {', '.join(required)}; {', '.join(missing)} missing")
    n_recordings = len(set(recordings.values()))
    if "recording" not in header and n_recordings != 1:
        raise SpecError(f"{name} line 1", ",".join(header),
                        f"a 'recording' column naming which of the {n_recordings} "
                        "recordings each row belongs to")
    labels, seen = [], {}
    for line, row in enumerate(rows[1:], start=2):
        if not row or not any(cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise SpecError(f"{name} line {line}", ",".join(row),
                            f"{len(header)} fields ({','.join(header)}): the file is "
                            "truncated or damaged")
        cells = {c: v.strip() for c, v in zip(header, row)}
        if drive:
            cells["onset_s"] = cells.pop("contact_s")
        label = _label(name, line, cells, recordings, drive)
        key = (label.recording, label.onset_s)
        if key in seen:
            raise SpecError(f"{name} line {line} onset_s", label.onset_s,
                            f"one label per contact; line {seen[key]} labels the same contact "
                            f"of {label.recording} (a duplicated row)")
        seen[key] = line
        labels.append(label)
    if not labels:
        raise SpecError("labels", str(path), "a CSV with at least one labelled contact; this "
                                             "one has a header only")
    _check_repetitions(name, labels)
    return labels


def _label(name: str, line: int, cells: dict, recordings: dict[str, str],
           drive: bool = False) -> Label:
    def field(column):
        return f"{name} line {line} {'contact_s' if drive and column == 'onset_s' else column}"

    names = sorted(set(recordings.values()))
    given = cells.get("recording") or (names[0] if len(names) == 1 else "")
    if given not in recordings:
        raise SpecError(field("recording"), given,
                        f"the name of a recording in the folder: {names}")
    recording = recordings[given]
    numbers = {}
    for column in ("onset_s", "distance_cm"):
        try:
            numbers[column] = float(cells[column])
        except ValueError:
            raise SpecError(field(column), cells[column], "a number") from None
        if not np.isfinite(numbers[column]):
            raise SpecError(field(column), cells[column], "a finite number")
    try:
        antenna.check_distance(numbers["distance_cm"])
    except SpecError as exc:
        raise SpecError(field("distance_cm"), numbers["distance_cm"], exc.accepted) from None
    material = cells.get("material", "")
    if not (drive and material == "") and (not MATERIAL_NAME.fullmatch(material)
                                           or material in MISSING):
        raise SpecError(field("material"), cells["material"],
                        "a material's name: lowercase letters, digits and _, starting with a "
                        f"letter (the paper's: {', '.join(sorted(antenna.MATERIALS))})")
    repetition = None
    if cells.get("repetition", "") != "":
        try:
            repetition = int(cells["repetition"])
        except ValueError:
            raise SpecError(field("repetition"), cells["repetition"],
                            "an integer >= 0") from None
        if repetition < 0:
            raise SpecError(field("repetition"), repetition, "an integer >= 0")
    return Label(line, recording, numbers["onset_s"], numbers["distance_cm"], material,
                 repetition)


def check_times(name: str, labels: list[Label], spans: dict[str, tuple[float, float]],
                drive: bool = False) -> None:
    """Every label's time inside its recording's span on that recording's clock."""
    for lab in labels:
        start, end = spans[lab.recording]
        if not start <= lab.onset_s < end:
            raise SpecError(f"{name} line {lab.line} {'contact_s' if drive else 'onset_s'}",
                            lab.onset_s, f"a time inside {lab.recording}, which spans "
                                         f"[{start:.9g}, {end:.9g}) s on its own clock")


def _check_repetitions(name: str, labels: list[Label]) -> None:
    """Either every row numbers its repetition or none does; a (material, distance,
    repetition) names one contact."""
    given = [lab.repetition is not None for lab in labels]
    if any(given) and not all(given):
        first = labels[given.index(False)]
        raise SpecError(f"{name} line {first.line} repetition", "",
                        "a repetition on every row once one row has one")
    if not any(given):
        return
    seen = {}
    for lab in labels:
        key = (lab.material, lab.distance_cm, lab.repetition)
        if key in seen:
            raise SpecError(f"{name} line {lab.line} repetition", lab.repetition,
                            f"a repetition not already used at {lab.material}, "
                            f"{lab.distance_cm:g} cm (line {seen[key]}: a duplicated row)")
        seen[key] = lab.line


def repetitions(labels: list[Label]) -> list[int]:
    """Each label's repetition: its own, or its number in time order at its site."""
    if labels and labels[0].repetition is not None:
        return [lab.repetition for lab in labels]
    order = sorted(range(len(labels)), key=lambda i: (labels[i].recording, labels[i].onset_s))
    counter, out = {}, [0] * len(labels)
    for i in order:
        site = (labels[i].material, labels[i].distance_cm)
        out[i] = counter.get(site, 0)
        counter[site] = out[i] + 1
    return out


def from_emulator_log(log: dict, recording: str, drive: bool = False) -> str:
    """The labels table (CSV text) of what ``snn-antenna emulate --log`` says it streamed: each
    contact's onset on the stream's clock (frame over rate), distance and material; a bench
    table, or a drives table when ``drive``. A recording of that stream made from its first
    frame shares the clock (the firmware numbers its samples from 0)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["recording", "contact_s" if drive else "onset_s", "distance_cm",
                     "material"])
    for event in log.get("events", []):
        if event.get("kind") == "contact":
            writer.writerow([recording, repr(float(event["t_s"])),
                             repr(float(event["distance_cm"])), event["material"]])
    return out.getvalue()
