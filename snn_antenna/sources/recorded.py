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
and intervals work unchanged; it answers what every source answers (``source.Source``), so
the report lists its provenance rows and the summary keeps its entry.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import SpecError, check
from ..core.signals import Recording
from ..core.store import DamagedStore, read_dataset
from ..core.truth import Event, GroundTruth

DATASET, DRIVES = "bench.zarr", "drives.zarr"
EXCLUSIONS, IMPORT_FILE = "exclusions.csv", "import.json"
KIND = "snn-antenna recorded data set"
FORMAT_VERSION = 2
CALIBRATION_REPETITIONS = 1   # seed stream of the repetitions held out to calibrate on
ACCEPTED = ("a folder written by `snn-antenna data import` (import.json, bench.zarr or "
            "drives.zarr, exclusions.csv)")


@dataclass
class ImportedSet:
    """A folder written by ``snn-antenna data import``, opened and checked: its data set
    (the generator's layout) and its ``import.json``; what a study's report and summary say of
    its origin (``source.Source``)."""
    path: Path
    dataset: object                      # xarray.Dataset, the generator's layout
    provenance: dict

    @property
    def rate_hz(self) -> float:
        return float(self.dataset.attrs["rate_hz"])

    @property
    def adc_bits(self) -> int:
        return int(self.dataset.attrs["adc_bits"])

    @property
    def full_scale_g(self) -> float:
        return float(self.dataset.attrs["full_scale_g"])

    def provenance_rows(self) -> list[tuple[str, str]]:
        """(what, value) rows saying where the data came from, for a study's report."""
        meta = self.provenance
        counts = meta["counts"]
        rows = [("data", f"{meta['data']} recordings imported into "
                         f"{Path(self.path).resolve()} (data set {meta['key']})"),
                ("labels", f"{meta['labels']['file']} (sha256 {meta['labels']['sha256']})"),
                ("contacts imported", f"{counts['events']} of {counts['labels']} labelled "
                                      f"({_excluded_text(counts['excluded'])})")]
        rows += [(f"recording {r['name']}", f"{r['kind']}, {r['samples']} samples at "
                                            f"{r['rate_hz']:g} Hz; sha256 "
                                            + ", ".join(f"{f['file']} {f['sha256'][:16]}…"
                                                        for f in r["files"]))
                 for r in meta["recordings"]]
        return rows

    def summary_entry(self) -> dict:
        """What a study's ``summary.json`` keeps of the data's origin."""
        meta = self.provenance
        return {"path": str(Path(self.path).resolve()), "key": meta["key"],
                "labels": meta["labels"], "counts": meta["counts"],
                "recordings": meta["recordings"]}


@dataclass
class RecordedBench(ImportedSet):
    """Contacts imported from recordings, in place of a ``bench.BenchSpec``: the fields and
    methods the studies read of a bench set (``source.BenchSet``), answered from the data set
    itself."""
    seed: int = 0
    n_jobs: int = 1
    cache_dir: str = "out/.cache"

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
    def pre_trigger_s(self) -> float:
        return float(self.dataset.attrs["pre_trigger_s"])

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

    def describe(self) -> str:
        return (f"recorded data set: {self.n_events} events at {self.rate_hz:g} Hz, imported "
                f"into {self.path}")

    def open_dataset(self, log=print, fresh: bool = False):
        """The imported data set (nothing to make, so ``fresh`` changes nothing)."""
        log(f"data: {self.n_events} recorded contacts from {self.path}")
        return self.dataset

    def calibration_repetitions(self, n: int, field: str) -> list[int]:
        """``n`` of the recorded repetitions, drawn with the study's seed, whose contacts
        calibrate and leave every split; checked to leave at least two to split by (``field``
        names ``n`` in the refusal)."""
        have = sorted(set(int(r) for r in self.dataset["repetition"].values))
        check(n <= len(have) - 2, field, n,
              f"at most {len(have) - 2} of the recorded set's {len(have)} repetitions (their "
              "contacts calibrate and leave every split; two must remain to split by)")
        rng = np.random.default_rng(np.random.SeedSequence(
            self.seed, spawn_key=(CALIBRATION_REPETITIONS,)))
        return sorted(rng.choice(have, size=n, replace=False).tolist())


def open_bench(path, seed: int = 0, n_jobs: int = 1,
               cache_dir: str = "out/.cache") -> RecordedBench:
    """The imported bench contacts at ``path``, checked whole: its ``import.json`` names it, its
    store reads back, and its content is the one the import recorded (``key``)."""
    ds, meta = _open(path, "bench", DATASET)
    return RecordedBench(Path(path), ds, meta, seed=seed, n_jobs=n_jobs, cache_dir=cache_dir)


@dataclass
class RecordedDrives(ImportedSet):
    """Drives imported from recordings: ``recording(d)`` gives each as a labelled Recording,
    ``scene(d)`` as a ``RecordedScene``."""

    @property
    def names(self) -> list[str]:
        return [str(n) for n in self.dataset["drive"].values]

    def recording(self, drive: int = 0) -> Recording:
        """Drive ``drive`` as a ``Recording`` of ADC counts, its labelled contacts as truth,
        its speed command per sample and lost samples in ``meta``."""
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
        rec = self.recording(drive)
        return RecordedScene(rec, self, rec.rate_hz, self.adc_bits, self.full_scale_g,
                             rec.duration_s, rec.truth.contacts, _mostly(rec.meta["speed_cm_s"]))


def _mostly(speed: np.ndarray) -> float | None:
    """The speed command most of a drive ran at (None when none was logged)."""
    known = speed[np.isfinite(speed)]
    if not len(known):
        return None
    values, counts = np.unique(known, return_counts=True)
    return float(values[np.argmax(counts)])


@dataclass(frozen=True)
class RecordedScene:
    """A recorded drive standing where a ``RobotScene`` stands (``source.Scene``): the
    sensor's settings, the drive's length, its labelled contacts and the speed it mostly ran
    at; ``generate`` gives the recording (whatever the seed: it was recorded once)."""
    recording: Recording
    drives: RecordedDrives               # where it came from
    rate_hz: float
    adc_bits: int
    full_scale_g: float
    duration_s: float
    contacts: tuple
    speed_cm_s: float | None

    def validate(self) -> None:
        """Checked when opened (:func:`open_drives`)."""

    def generate(self, seed: int = 0) -> Recording:
        return self.recording

    def describe(self) -> str:
        touches = "; ".join(f"at {c.t_s:g} s{f' on {c.material}' if c.material else ''} "
                            f"{c.distance_cm:g} cm along the rod" for c in self.contacts)
        speed = f" at {self.speed_cm_s:g} cm/s" if self.speed_cm_s else ""
        return (f"A recorded drive ({self.recording.meta['source']}, {self.duration_s:g} s"
                f"{speed}, sampled at {self.rate_hz:g} Hz): its labels say the antenna "
                f"touched {touches or 'nothing'}.")

    def provenance_rows(self) -> list[tuple[str, str]]:
        return self.drives.provenance_rows()

    def summary_entry(self) -> dict:
        return self.drives.summary_entry()

    def calibrated(self) -> list:
        """Nothing: a recording was set to match no number."""
        return []


def open_drives(path) -> RecordedDrives:
    """The imported drives at ``path``, checked as :func:`open_bench` checks bench contacts."""
    ds, meta = _open(path, "drives", DRIVES)
    return RecordedDrives(Path(path), ds, meta)


def _open(path, kind: str, store: str):
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


def _excluded_text(excluded: dict) -> str:
    shown = [f"{n} {reason.replace('_', ' ')}" for reason, n in excluded.items() if n]
    return "excluded: " + ", ".join(shown) if shown else "none excluded"


__all__ = ["ImportedSet", "RecordedBench", "RecordedDrives", "RecordedScene", "open_bench",
           "open_drives", "DATASET", "DRIVES",
           "EXCLUSIONS", "IMPORT_FILE", "KIND", "FORMAT_VERSION"]
