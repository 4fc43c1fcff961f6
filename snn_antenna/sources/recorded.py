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

DATASET, EXCLUSIONS, IMPORT_FILE = "bench.zarr", "exclusions.csv", "import.json"
KIND = "snn-antenna recorded data set"
FORMAT_VERSION = 1
ACCEPTED = ("a folder written by `snn-antenna data import` (import.json, bench.zarr, "
            "exclusions.csv)")


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
        return sorted(set(self.dataset["material"].values.astype(str)))

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
    """The imported data set at ``path``, checked whole: its ``import.json`` names it, its store
    reads back, and its content is the one the import recorded (``key``)."""
    from ..core.store import DamagedStore, read_dataset

    folder = Path(path)
    if not folder.is_dir():
        raise SpecError("data", str(path), ACCEPTED)
    meta_path = folder / IMPORT_FILE
    if not meta_path.is_file() or not (folder / DATASET).is_dir():
        raise SpecError("data", str(path), f"{ACCEPTED}; {IMPORT_FILE if not meta_path.is_file() else DATASET} "
                                           "is missing (an import that did not finish writes "
                                           "no import.json): import it again")
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
    try:
        ds = read_dataset(folder / DATASET)
    except DamagedStore as exc:
        raise SpecError("data", str(path), f"{ACCEPTED}; {exc.accepted}") from None
    if ds.attrs.get("key") != meta.get("key") or ds.sizes.get("event") != meta["counts"]["events"]:
        raise SpecError("data", str(path), f"{ACCEPTED}; its {DATASET} is not the one its "
                                           f"{IMPORT_FILE} describes: import it again")
    return RecordedBench(folder, ds, meta, seed=seed, n_jobs=n_jobs, cache_dir=cache_dir)


def provenance_rows(bench_source) -> list[tuple[str, str]]:
    """(what, value) rows saying where a study's contacts came from, for its report."""
    if not getattr(bench_source, "recorded", False):
        return []
    meta = bench_source.provenance
    counts = meta["counts"]
    rows = [("data", str(Path(bench_source.path).resolve())),
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


__all__ = ["RecordedBench", "open_bench", "provenance_rows", "summary_entry", "DATASET",
           "EXCLUSIONS", "IMPORT_FILE", "KIND", "FORMAT_VERSION"]
