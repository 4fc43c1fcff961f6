"""``snn-antenna data import``: check everything, then write the data set whole or not at all.

:func:`plan_import` reads every recording and the labels table, finds and matches the contacts
and builds the data set in memory; any bad input is refused there, with one line naming the
file, the line and the field, before the output folder is touched. :func:`write_import` then
writes it into an output folder of the toolkit's (``core.outputs``: a journal of what it
wrote, one writer at a time, the user's files kept): the store under a staging name renamed
into place (``core.store.write_dataset``), the exclusions table, and ``import.json`` last, so
a folder without ``import.json`` is never read as a data set (``sources.recorded``).
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.errors import SpecError
from ..sources import recorded
from . import inputs, labels as label_table, segment
from .segment import REASONS, Segmentation
from ..core.files import atomic_write, write_json
from ..core.store import write_dataset

STUDY = "data import"


@dataclass
class ImportPlan:
    dataset: object                 # xarray.Dataset in the generator's layout
    exclusions: list[segment.Exclusion]
    meta: dict                      # import.json


def plan_import(recordings_dir, labels_path, options: inputs.Options,
                seg: Segmentation = Segmentation(), log=print,
                clock_offset_s: float = 0.0) -> ImportPlan:
    """Read and check the recordings and labels; find, match and cut the contacts.
    ``clock_offset_s`` is added to every label's time (the labels' clock behind the
    recordings' by that much), declared on the command line, never guessed."""
    _check_settings(seg)
    inputs.check_options(options)
    if not np.isfinite(clock_offset_s):
        raise SpecError("--clock-offset-s", clock_offset_s, "a finite number of seconds")
    entries = inputs.recording_entries(recordings_dir)
    streams = [inputs.read_stream(p, options) for p in entries]
    first = streams[0]
    for s in streams[1:]:
        for name in ("rate_hz", "adc_bits", "full_scale_g"):
            mine, theirs = getattr(s, name), getattr(first, name)
            same = (abs(mine - theirs) <= inputs.RATE_TOLERANCE * theirs if name == "rate_hz"
                    else mine == theirs)
            if not same:
                raise SpecError(f"{s.name} {name}", mine,
                                f"{theirs:g}, as {first.name}: one data set holds one "
                                "sensor's samples at one rate")
    _check_quiet(first.rate_hz, seg)
    table = label_table.read_labels(labels_path, _names(streams))
    if clock_offset_s:
        table = [replace(lab, onset_s=lab.onset_s + clock_offset_s) for lab in table]
    drive = label_table.is_drive_table(labels_path)
    spans = {s.name: s.span_s for s in streams}
    heading = (f"data: {len(streams)} recording(s), {len(table)} labelled contacts in "
               f"{Path(labels_path).name}")
    if drive:
        label_table.check_times(Path(labels_path).name, table, spans, drive=True)
        log(heading)
        return _plan_drives(streams, table, labels_path, options, seg, log, clock_offset_s)
    found = {s.name: segment.onsets(s, seg) for s in streams}
    clocks = [_clock(s, table, found[s.name], seg, labels_path, clock_offset_s)
              for s in streams]
    label_table.check_times(Path(labels_path).name, table, spans)
    log(heading)
    for clock in clocks:
        _log_clock(clock, log)
    contacts, excluded = [], []
    by_name = {s.name: s for s in streams}
    for s in streams:
        mine = [(k, lab) for k, lab in enumerate(table) if lab.recording == s.name]
        kept, left_out = segment.reconcile(s, mine, seg, found[s.name])
        contacts += [(s, c) for c in kept]
        excluded += left_out
    counts = {"labels": len(table), "events": len(contacts),
              "excluded": {r: sum(e.reason == r for e in excluded) for r in REASONS},
              "excluded_by_position": _by_position(excluded)}
    log(f"data: {len(contacts)} contacts imported; left out: "
        + (", ".join(f"{n} {r}" for r, n in counts["excluded"].items() if n) or "none"))
    if not contacts:
        raise SpecError("labels", str(labels_path),
                        "labels of which at least one matches a contact found in its "
                        f"recording (none did: {counts['excluded']}); check onset_s against "
                        "the recordings' clocks, or --onset-threshold-g")
    labels_hash = inputs.sha256_of(Path(labels_path))
    settings = {**asdict(seg), **asdict(options), "clock_offset_s": clock_offset_s}
    key = _key(streams, labels_hash["sha256"], settings)
    ds = _dataset(contacts, table, by_name, seg, key)
    meta = {"kind": recorded.KIND, "format_version": recorded.FORMAT_VERSION, "key": key,
            "content_sha256": recorded.content_sha256(ds), "data": "bench",
            "package_version": __version__,
            "labels": {"file": Path(labels_path).name, **labels_hash},
            "recordings": [s.describe() for s in streams], "settings": settings,
            "clocks": [c.row() for c in clocks],
            "counts": counts, "exclusions": [e.row() for e in excluded]}
    return ImportPlan(ds, excluded, meta)


def _by_position(excluded) -> dict[str, dict[str, int]]:
    """Labelled contacts left out, counted by position (cm) and reason: a position the import
    lost most of is seen, not only a total."""
    out = {}
    for e in excluded:
        if e.distance_cm is not None:
            row = out.setdefault(f"{e.distance_cm:g}", {})
            row[e.reason] = row.get(e.reason, 0) + 1
    return dict(sorted(out.items(), key=lambda kv: float(kv[0])))


def _names(streams) -> dict[str, str]:
    """Every name a labels table may give a recording → its name (a file's stem only when no
    other recording shares it)."""
    names = {s.name: s.name for s in streams}
    stems = {}
    for s in streams:
        for alias in s.aliases()[1:]:
            stems.setdefault(alias, []).append(s.name)
    names.update({alias: owners[0] for alias, owners in stems.items()
                  if len(owners) == 1 and alias not in names})
    return names


def _clock(stream, table, found, seg: Segmentation, labels_path,
           clock_offset_s: float) -> segment.Clock:
    """How the labels of ``stream`` sit on its clock; a shift that explains them far better
    than their times as written is refused (named, with the option that applies it)."""
    name = Path(labels_path).name
    mine = np.asarray([lab.onset_s for lab in table if lab.recording == stream.name])
    clock = segment.clock_fit(stream, mine, found, seg)
    if clock.offset_s is not None:
        suggested = clock_offset_s + clock.offset_s
        raise SpecError(f"{name} onset_s", f"{clock.matched} of {clock.labels} labels of "
                                           f"{stream.name} on a contact",
                        f"labels on {stream.name}'s own clock (its first sample at "
                        f"{stream.origin_s:.6f} s): shifted by {clock.offset_s:+.3f} s, "
                        f"{clock.offset_matched} of them fall on a contact; if the labels' "
                        f"clock is off by that much, import with --clock-offset-s "
                        f"{suggested:.3f}, else correct onset_s")
    return clock


def _log_clock(clock: segment.Clock, log) -> None:
    """One line per recording: how many labels fell on a contact and their median lag (a
    consistent lag is reported, never applied); few matches are said to be few."""
    if not clock.labels:
        return
    lag = "" if clock.lag_s is None else f", the onsets {clock.lag_s * 1e3:+.1f} ms from " \
                                         "their labels (median)"
    few = " — few: check onset_s against the recording's clock" \
        if clock.matched < clock.labels / 2 else ""
    log(f"data: {clock.recording}: {clock.matched} of {clock.labels} labels on a contact"
        f"{lag}{few}")


def _plan_drives(streams, table, labels_path, options, seg: Segmentation, log,
                 clock_offset_s: float) -> ImportPlan:
    """Drives are kept whole (finding their contacts is the studies' read-out's job): each
    label is checked against its recording's lost and clipped stretches around it."""
    by_name = {s.name: s for s in streams}
    kept, excluded = [], []
    for _k, lab in enumerate(table):
        s = by_name[lab.recording]
        reason = segment.stretch_problem(s, lab.onset_s, seg)
        if reason:
            excluded.append(segment.Exclusion(s.name, lab.onset_s, lab.line, reason,
                                              lab.distance_cm))
        else:
            kept.append(lab)
    counts = {"labels": len(table), "events": len(kept), "drives": len(streams),
              "excluded": {r: sum(e.reason == r for e in excluded) for r in REASONS},
              "excluded_by_position": _by_position(excluded)}
    log(f"data: {len(streams)} drive(s), {len(kept)} contacts kept; left out: "
        + (", ".join(f"{n} {r}" for r, n in counts["excluded"].items() if n) or "none"))
    labels_hash = inputs.sha256_of(Path(labels_path))
    settings = {**asdict(seg), **asdict(options), "clock_offset_s": clock_offset_s}
    key = _key(streams, labels_hash["sha256"], settings)
    meta = {"kind": recorded.KIND, "format_version": recorded.FORMAT_VERSION, "key": key,
            "data": "drives", "package_version": __version__,
            "labels": {"file": Path(labels_path).name, **labels_hash},
            "recordings": [s.describe() for s in streams], "settings": settings,
            "counts": counts, "exclusions": [e.row() for e in excluded]}
    ds = _drives_dataset(streams, kept, key)
    meta["content_sha256"] = recorded.content_sha256(ds)
    return ImportPlan(ds, excluded, meta)


def _drives_dataset(streams, kept, key: str):
    """Each drive on its own clock from its first sample (lost samples hold the last value and
    are marked), its speed command per sample (NaN: not logged), and the labelled contacts."""
    import xarray as xr

    first = streams[0]
    lengths = [int(s.frames[-1] - s.frames[0]) + 1 for s in streams]
    n = max(lengths)
    mid = 2 ** (first.adc_bits - 1)
    counts = np.full((len(streams), n, 2), mid, dtype=np.int64)
    lost = np.ones((len(streams), n), dtype=bool)
    speed = np.full((len(streams), n), np.nan, dtype=np.float32)
    for d, s in enumerate(streams):
        index = s.frames - s.frames[0]
        lost[d, index] = False
        held = np.maximum.accumulate(np.where(lost[d, :lengths[d]], 0, np.arange(lengths[d])))
        timeline = np.zeros((lengths[d], 2), dtype=np.int64)
        timeline[index] = s.counts
        counts[d, :lengths[d]] = timeline[held]
        for frame, value in sorted(s.speed_log):
            speed[d, max(frame - int(s.frames[0]), 0):lengths[d]] = value
    order = {s.name: d for d, s in enumerate(streams)}
    start = {s.name: float(s.time_of(s.frames[0])) for s in streams}
    dtype = np.uint16 if first.adc_bits <= 16 else np.int32
    return xr.Dataset(
        {"counts": (("drive", "sample", "axis"), counts.astype(dtype), {"units": "ADC counts"}),
         "lost": (("drive", "sample"), lost),
         "speed_cm_s": (("drive", "sample"), speed, {"units": "cm/s"}),
         "n_samples": ("drive", np.asarray(lengths)),
         "start_s": ("drive", np.asarray([start[s.name] for s in streams]), {"units": "s"}),
         "contact_drive": ("contact", np.asarray([order[lab.recording] for lab in kept],
                                                 dtype=int)),
         "contact_t_s": ("contact", np.asarray([lab.onset_s - start[lab.recording]
                                                for lab in kept], dtype=float)),
         "contact_distance_cm": ("contact", np.asarray([lab.distance_cm for lab in kept],
                                                       dtype=float)),
         "contact_material": ("contact", np.asarray([lab.material for lab in kept], dtype=str)),
         "contact_line": ("contact", np.asarray([lab.line for lab in kept], dtype=int))},
        coords={"drive": np.asarray([s.name for s in streams], dtype=str), "axis": ["x", "y"]},
        attrs={"rate_hz": float(first.rate_hz), "adc_bits": int(first.adc_bits),
               "full_scale_g": float(first.full_scale_g), "key": key, "source": "recorded"})


def _check_settings(seg: Segmentation) -> None:
    for name in ("onset_threshold_g", "quiet_s", "dead_s", "match_s", "duration_s"):
        value = getattr(seg, name)
        if not (np.isfinite(value) and value > 0):
            raise SpecError(f"--{name.replace('_', '-')}", value, "a number > 0")
    if not (np.isfinite(seg.pre_trigger_s) and 0 <= seg.pre_trigger_s < 1):
        raise SpecError("--pre-trigger-s", seg.pre_trigger_s, "a lead-in in [0, 1) s")


def _check_quiet(rate_hz: float, seg: Segmentation) -> None:
    if seg.quiet_s * rate_hz < 1:
        raise SpecError("--quiet-s", seg.quiet_s, f"at least one sample ({1 / rate_hz:g} s "
                                                  f"at {rate_hz:g} Hz)")


def _key(streams, labels_sha: str, settings: dict) -> str:
    h = hashlib.sha256(labels_sha.encode())
    for s in streams:
        for f in s.files:
            h.update(f"{s.name}/{f['file']}:{f['sha256']}".encode())
    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    return "recorded-" + h.hexdigest()[:16]


def _dataset(contacts, table, by_name, seg: Segmentation, key: str):
    """The contacts in the generator's layout (``sources.bench.generate``), in time order per
    recording, with where each came from."""
    import xarray as xr

    first = next(iter(by_name.values()))
    contacts = sorted(contacts, key=lambda sc: (sc[0].name, sc[1].onset_frame))
    reps = label_table.repetitions(table)
    windows = np.stack([segment.cut(s, c.onset_frame, seg) for s, c in contacts])
    distances = np.asarray([c.label.distance_cm for _, c in contacts], dtype=float)
    sites = np.unique(distances)
    dtype = np.uint16 if first.adc_bits <= 16 else np.int32
    return xr.Dataset(
        {"counts": (("event", "sample", "axis"), windows.astype(dtype), {"units": "ADC counts"})},
        coords={"event": np.arange(len(contacts)),
                "material": ("event", np.asarray([c.label.material for _, c in contacts],
                                                 dtype=str)),
                "distance_cm": ("event", distances, {"units": "cm"}),
                "position": ("event", np.searchsorted(sites, distances)),
                "repetition": ("event", np.asarray([reps[c.index] for _, c in contacts])),
                "axis": ["x", "y"],
                "recording": ("event", np.asarray([s.name for s, _ in contacts], dtype=str)),
                "onset_s": ("event", np.asarray([s.time_of(c.onset_frame)
                                                 for s, c in contacts]), {"units": "s"}),
                "label_line": ("event", np.asarray([c.label.line for _, c in contacts]))},
        attrs={"rate_hz": float(first.rate_hz), "pre_trigger_s": float(seg.pre_trigger_s),
               "adc_bits": int(first.adc_bits), "full_scale_g": float(first.full_scale_g),
               "key": key, "source": "recorded",
               "spec": json.dumps({"segmentation": asdict(seg)})})


def exclusions_csv(exclusions: list[segment.Exclusion]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, ["recording", "t_s", "label_line", "reason", "distance_cm"],
                            lineterminator="\n")
    writer.writeheader()
    for e in exclusions:
        writer.writerow(e.row())
    return out.getvalue()


def write_import(plan: ImportPlan, out, log=print) -> Path:
    """Write the planned data set into ``out``, an output folder its caller has claimed
    (``outputs.output_folder``: the command checks it before reading anything)."""
    out = Path(out)
    store = recorded.DRIVES if plan.meta["data"] == "drives" else recorded.DATASET
    write_dataset(plan.dataset, out.absolute() / store)
    atomic_write(out / recorded.EXCLUSIONS, exclusions_csv(plan.exclusions))
    write_json(out / recorded.IMPORT_FILE, plan.meta)
    log(f"data: wrote {out} ({plan.meta['counts']['events']} contacts; "
        f"{len(plan.exclusions)} left out, listed in {recorded.EXCLUSIONS})")
    return out


def check_outside_recordings(out, recordings) -> None:
    """Refuse an output folder inside the recordings folder, before any reading: the raw
    recordings are never written to, and the next import of that folder would meet the data
    set among its recordings."""
    raw, target = Path(recordings).resolve(), Path(out).resolve()
    if target == raw or raw in target.parents:
        raise SpecError("--out", str(out), f"a folder outside the recordings folder {raw} "
                                           "(an import writes nothing among the raw "
                                           "recordings)")
