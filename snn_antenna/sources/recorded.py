"""A data set imported from recordings of a real antenna, read the way the generated one is.

``snn-antenna data import RECORDINGS LABELS --out DIR`` (``snn_antenna.data``) writes a folder:

``bench.zarr``      the contacts cut from the recordings, in the generator's layout
                    (``sources.bench.generate``): ``counts`` (event, sample, axis) with the labels
                    ``material``, ``distance_cm``, ``position``, ``repetition`` per event, and the
                    attributes ``rate_hz``, ``pre_trigger_s``, ``adc_bits``, ``full_scale_g``,
                    ``key``; besides, where each event came from (``recording``, ``onset_s``,
                    ``label_line``).
``exclusions.csv``  every labelled or detected contact left out, with its recording, time, label
                    line and the reason.
``import.json``     the provenance (the sha256 of every raw file and of the labels table, the
                    settings, the counts); written last, so a folder without it is not a data set.

Recordings of drives (a labels table with ``contact_s``) are kept whole in ``drives.zarr``:
``counts`` (drive, sample, axis) on each drive's clock from its first sample, ``lost`` (samples
the link lost, holding the last value), ``speed_cm_s`` (the logged speed command; NaN where none
was logged), ``n_samples`` and ``start_s`` per drive, and the labelled contacts along
``contact`` (``contact_drive``, ``contact_t_s``, ``contact_distance_cm``, ``contact_material``);
:func:`open_drives` gives them as ``Recording`` objects whose ``truth`` holds the contacts.

A study whose spec names such a folder at its top level (``data = "DIR"``) reads its contacts in
place of the generator's: :func:`open_bench` gives an object that stands where a
``bench.BenchSpec`` stands (``bench.load`` returns its data set), so splits by repetition, seeds
and intervals work unchanged, and the report lists :func:`provenance_rows`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import SpecError

DATASET, DRIVES = "bench.zarr", "drives.zarr"
EXCLUSIONS, IMPORT_FILE = "exclusions.csv", "import.json"
KIND = "snn-antenna recorded data set"
FORMAT_VERSION = 2
ACCEPTED = ("a folder written by `snn-antenna data import` (import.json, bench.zarr or "
            "drives.zarr, exclusions.csv)")


@dataclass
class RecordedBench:
    """Contacts imported from recordings, in place of a ``bench.BenchSpec``: the fields and
    methods the studies read of a spec, answered from the data set itself."""
    path: Path
    dataset: object                      # xarray.Dataset, the generator's layout
    provenance: dict
    seed: int = 0
    n_jobs: int = 1
    cache_dir: str = "out/.cache"
    recorded: bool = field(default=True, init=False)

    @property
    def materials(self) -> list[str]:
        return sorted(set(str(m) for m in self.dataset["material"].values))

    @property
    def positions_cm(self) -> list[float]:
        return sorted(set(float(d) for d in self.dataset["distance_cm"].values))

    @property
    def repetitions(self) -> int:
        return int(self.dataset["repetition"].values.max()) + 1

    @property
    def rate_hz(self) -> float:
        return float(self.dataset.attrs["rate_hz"])

    @property
    def pre_trigger_s(self) -> float:
        return float(self.dataset.attrs["pre_trigger_s"])

    @property
    def adc_bits(self) -> int:
        return int(self.dataset.attrs["adc_bits"])

    @property
    def full_scale_g(self) -> float:
        return float(self.dataset.attrs["full_scale_g"])

    @property
    def n_events(self) -> int:
        return int(self.dataset.sizes["event"])

    @property
    def n_samples(self) -> int:
        return int(self.dataset.sizes["sample"])

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.rate_hz - self.pre_trigger_s

    def key(self) -> str:
        """The data's identity: the hash of the raw files, the labels and the import settings
        (``import.json``), so caches of features computed from it follow the recordings."""
        return str(self.dataset.attrs["key"])

    def validate(self) -> None:
        """Checked when opened (:func:`open_bench`)."""


def open_bench(path, seed: int = 0, n_jobs: int = 1,
               cache_dir: str = "out/.cache") -> RecordedBench:
    """The imported bench contacts at ``path``, checked whole: its ``import.json`` names it, its
    store reads back, and its content is the one the import recorded (``key``)."""
    ds, meta = _open(path, "bench", DATASET)
    return RecordedBench(Path(path), ds, meta, seed=seed, n_jobs=n_jobs, cache_dir=cache_dir)


@dataclass
class RecordedDrives:
    """Drives imported from recordings: ``recordings()`` gives each as a labelled Recording."""
    path: Path
    dataset: object
    provenance: dict
    recorded: bool = field(default=True, init=False)

    @property
    def rate_hz(self) -> float:
        return float(self.dataset.attrs["rate_hz"])

    @property
    def adc_bits(self) -> int:
        return int(self.dataset.attrs["adc_bits"])

    @property
    def full_scale_g(self) -> float:
        return float(self.dataset.attrs["full_scale_g"])

    @property
    def names(self) -> list[str]:
        return [str(n) for n in self.dataset["drive"].values]

    def recording(self, drive: int = 0):
        """Drive ``drive`` as a ``Recording`` of ADC counts, its labelled contacts as truth,
        its speed command per sample and lost samples in ``meta``."""
        from ..core.signals import Recording
        from ..core.truth import Event, GroundTruth

        ds = self.dataset.isel(drive=drive)
        n = int(ds["n_samples"])
        mine = np.flatnonzero(self.dataset["contact_drive"].values == drive)
        contacts = tuple(Event("contact", float(self.dataset["contact_t_s"].values[c]), 0.0,
                               float(self.dataset["contact_distance_cm"].values[c]),
                               str(self.dataset["contact_material"].values[c]) or None)
                         for c in mine)
        return Recording(np.asarray(ds["counts"].values[:n], dtype=np.int32), self.rate_hz,
                         GroundTruth(tuple(sorted(contacts, key=lambda e: e.t_s))),
                         units="counts",
                         meta={"adc_bits": self.adc_bits, "full_scale_g": self.full_scale_g,
                               "source": f"{self.path}/{self.names[drive]}",
                               "speed_cm_s": ds["speed_cm_s"].values[:n],
                               "lost": ds["lost"].values[:n]})


    def scene(self, drive: int = 0) -> RecordedScene:
        """Drive ``drive`` where a study reads a generated scene."""
        return RecordedScene(self, self.recording(drive))


@dataclass
class RecordedScene:
    """A recorded drive standing where a ``RobotScene`` stands: ``generate`` gives the
    recording (whatever the seed: it was recorded once)."""
    source: RecordedDrives
    drive: object                       # the Recording
    recorded: bool = field(default=True, init=False)

    @property
    def path(self) -> Path:
        return self.source.path

    @property
    def provenance(self) -> dict:
        return self.source.provenance

    @property
    def rate_hz(self) -> float:
        return self.drive.rate_hz

    @property
    def adc_bits(self) -> int:
        return self.source.adc_bits

    @property
    def full_scale_g(self) -> float:
        return self.source.full_scale_g

    @property
    def duration_s(self) -> float:
        return self.drive.duration_s

    @property
    def contacts(self):
        return self.drive.truth.contacts

    @property
    def speed_cm_s(self) -> float | None:
        """The speed command most of the drive ran at (None when none was logged)."""
        speed = self.drive.meta["speed_cm_s"]
        known = speed[np.isfinite(speed)]
        if not len(known):
            return None
        values, counts = np.unique(known, return_counts=True)
        return float(values[np.argmax(counts)])

    def validate(self) -> None:
        """Checked when opened (:func:`open_drives`)."""

    def generate(self, seed: int = 0):
        return self.drive


def open_drives(path) -> RecordedDrives:
    """The imported drives at ``path``, checked as :func:`open_bench` checks bench contacts."""
    ds, meta = _open(path, "drives", DRIVES)
    return RecordedDrives(Path(path), ds, meta)


def _open(path, kind: str, store: str):
    from ..core.store import DamagedStore, read_dataset

    folder = Path(path)
    if not folder.is_dir():
        raise SpecError("data", str(path), ACCEPTED)
    meta_path = folder / IMPORT_FILE
    if not meta_path.is_file():
        raise SpecError("data", str(path), f"{ACCEPTED}; {IMPORT_FILE} is missing (an import "
                                           "that did not finish writes none): import it again")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError) as exc:
        raise SpecError("data", str(path), f"{ACCEPTED}; its {IMPORT_FILE} is damaged "
                                           f"({type(exc).__name__}): import it again") from None
    if not isinstance(meta, dict) or meta.get("kind") != KIND:
        raise SpecError("data", str(path), f"{ACCEPTED}; its {IMPORT_FILE} is not one")
    if meta.get("format_version") != FORMAT_VERSION:
        raise SpecError(f"{IMPORT_FILE} format_version", meta.get("format_version"),
                        f"{FORMAT_VERSION} (this version of snn-antenna)")
    if meta.get("data") != kind:
        raise SpecError("data", str(path), f"imported {kind} recordings (a labels table with "
                                           f"{'onset_s' if kind == 'bench' else 'contact_s'}); "
                                           f"this folder holds {meta.get('data')}")
    try:
        ds = read_dataset(folder / store)
    except DamagedStore as exc:
        raise SpecError("data", str(path), f"{ACCEPTED}; {exc.accepted}") from None
    size = ds.sizes.get("event" if kind == "bench" else "contact", 0)
    if ds.attrs.get("key") != meta.get("key") or size != meta["counts"]["events"]:
        raise SpecError("data", str(path), f"{ACCEPTED}; its {store} is not the one its "
                                           f"{IMPORT_FILE} describes: import it again")
    if content_sha256(ds) != meta.get("content_sha256"):
        raise SpecError("data", str(path), f"{ACCEPTED}; its {store} changed after the import "
                                           f"(its content is not the one {IMPORT_FILE} "
                                           "hashed: a file of it changed or is missing): "
                                           "import it again")
    return ds, meta


def content_sha256(ds) -> str:
    """The sha256 of a data set's every variable and coordinate (name, type, shape, values):
    what the import wrote, checked when a study opens it, so a store changed or with a file
    missing after the import is never read, nor any cache made from it."""
    import hashlib

    h = hashlib.sha256()
    for name in sorted(map(str, ds.variables)):
        values = np.ascontiguousarray(ds[name].values)
        if values.dtype.kind in "UO":
            values = np.asarray([str(v) for v in values.ravel()], dtype=str)
        h.update(f"{name}:{values.dtype.str}:{values.shape}".encode())
        h.update(values.tobytes())
    return h.hexdigest()


def provenance_rows(bench_source) -> list[tuple[str, str]]:
    """(what, value) rows saying where a study's contacts came from, for its report."""
    if not getattr(bench_source, "recorded", False):
        return []
    meta = bench_source.provenance
    counts = meta["counts"]
    rows = [("data", f"{meta['data']} recordings imported into "
                     f"{Path(bench_source.path).resolve()} (data set {meta['key']})"),
            ("labels", f"{meta['labels']['file']} (sha256 {meta['labels']['sha256']})"),
            ("contacts imported", f"{counts['events']} of {counts['labels']} labelled "
                                  f"({_excluded_text(counts['excluded'])})")]
    rows += [(f"recording {r['name']}", f"{r['kind']}, {r['samples']} samples at "
                                        f"{r['rate_hz']:g} Hz; sha256 "
                                        + ", ".join(f"{f['file']} {f['sha256'][:16]}…"
                                                    for f in r["files"]))
             for r in meta["recordings"]]
    return rows


def _excluded_text(excluded: dict) -> str:
    shown = [f"{n} {reason.replace('_', ' ')}" for reason, n in excluded.items() if n]
    return "excluded: " + ", ".join(shown) if shown else "none excluded"


def summary_entry(bench_source) -> dict | None:
    """What a study's ``summary.json`` keeps of the data's origin (None: generated data)."""
    if not getattr(bench_source, "recorded", False):
        return None
    meta = bench_source.provenance
    return {"path": str(Path(bench_source.path).resolve()), "key": meta["key"],
            "labels": meta["labels"], "counts": meta["counts"],
            "recordings": meta["recordings"]}


__all__ = ["RecordedBench", "RecordedDrives", "RecordedScene", "open_bench", "open_drives",
           "provenance_rows",
           "summary_entry", "DATASET", "DRIVES",
           "EXCLUSIONS", "IMPORT_FILE", "KIND", "FORMAT_VERSION"]
