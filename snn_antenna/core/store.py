"""The result store of a sweep: one xarray Dataset in one zarr store, written chunk by chunk.

    store = SweepStore("out/tuning/results.zarr")
    done = store.prepare(coords, outputs, block_shape, n_chunks, attrs=attrs)  # or reopen
    store.write_chunk(chunk_id, region, {"spike_count": block})            # as blocks arrive
    ds = store.load()

``prepare`` writes the metadata of every variable (dims = the grid's axes, each a named
coordinate) without data, so each chunk's results are written into their own region
(``to_zarr(region=...)``) as they arrive: a sweep chunk is exactly one zarr chunk of every
variable, so no write touches another chunk's files. Only the process that runs the sweep
writes (Dask workers return their blocks to it), so a cluster needs no shared folder.

After a chunk's data are written, its element of the ``chunk_done`` array (zarr chunks of
one element; zarr's local store writes each file by an atomic rename) is set. A chunk without
its mark is redone on resume, whatever part of its data had reached the disk; a marked chunk
is never recomputed. Before a store is resumed it is walked without following anything, and
a link, device or hard-linked file anywhere inside it is refused by name
(``files.check_tree``): zarr writes by path, and would write through it. The store's
``fingerprint`` attribute (grid, outputs, chunking, the
study's resolved settings and the code that computes them) must match to resume: a changed
spec or changed code is refused, ``fresh=True`` starts over.
"""
from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import files
from .errors import SpecError
from .provenance import code_hash, code_identity

DONE = "chunk_done"


def write_dataset(ds, path: str | Path, **to_zarr) -> None:
    """Write ``ds`` as the zarr store ``path``: atomically, and in data types Zarr v3 specifies.

    The store is written under a staging name beside ``path`` (``files.staging_name``, made
    exclusively and journaled first) and renamed into place, so an interrupted write never
    leaves a half store to be taken for a finished one, and never touches an entry of the
    user's that bears a staging-like name. Text (method
    or material names) is stored as variable-length UTF-8, Zarr v3's ``string`` type: numpy's
    fixed-width unicode has no Zarr v3 specification, and other readers may refuse it.
    Metadata are not consolidated (no part of Zarr v3 either). ``to_zarr`` is passed on
    (``compute=False`` writes the metadata only, for a store filled region by region).
    """
    path = Path(path)
    text = {name: var.astype(object) for name, var in ds.variables.items()
            if var.dtype.kind == "U"}
    ds = ds.assign_coords({k: v for k, v in text.items() if k in ds.coords}).assign(
        {k: v for k, v in text.items() if k not in ds.coords})
    files.refuse_symlink(path, "store")
    files.make_folder(path.parent)
    files.declare(path)                             # the user's entry of that name is refused
    tmp, _ = files.make_staging(path, "partial", os.mkdir)   # never a name already there
    try:
        ds.to_zarr(tmp, mode="w-", zarr_format=3, consolidated=False, **to_zarr)
        files.remove_entry(path)
        os.rename(tmp, path)
    except BaseException:
        if os.path.isdir(tmp) and not os.path.islink(tmp):
            files.remove_entry(tmp)
        raise
    files.note(path, settled=True)


def read_dataset(path: str | Path):
    """The zarr store ``path`` (written by ``write_dataset``) as an in-memory xarray Dataset.

    Zarr v3 hands its variable-length strings back as NumPy's ``StringDType``, which the rest
    of the code (``values.astype(str)``, ``np.isin`` against lists of names, JSON) does not
    expect: ``StringDType`` cannot even be cast to ``str``. Text is therefore returned as plain
    NumPy unicode, exactly the type it had before it was written, so a cached store and a
    freshly built data set are interchangeable. Every reader of a store goes through here.
    """
    import xarray as xr

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ds = xr.open_zarr(Path(path), consolidated=False).load()
    except Exception as exc:          # zarr, numcodecs, OS: whatever broke, name the store
        raise DamagedStore(path, exc) from None
    return plain_text(ds)


class DamagedStore(SpecError):
    """A zarr store that cannot be read back whole: named in one line with what to do."""

    def __init__(self, path, reason, remedy: str = "pass --fresh to compute it again, or "
                                                  "move it away"):
        self.path, self.reason, self.remedy = path, reason, remedy
        super().__init__("store", str(path), f"a store that reads back whole; this one is "
                                             f"damaged ({short_reason(reason)}): {remedy}")

    def __reduce__(self):
        return type(self), (self.path, self.reason, self.remedy)


def short_reason(reason) -> str:
    text = f"{type(reason).__name__}: {reason}" if isinstance(reason, BaseException) \
        else str(reason)
    text = " ".join(text.split())
    return text if len(text) <= 100 else text[:99] + "…"


def plain_text(ds):
    """``ds`` with every ``StringDType`` variable (coordinates too) as plain NumPy unicode."""
    text = {name: var.copy(data=np.asarray(var.values.astype(object), dtype=str))
            for name, var in ds.variables.items() if _is_variable_text(var.dtype)}
    return ds.assign_coords({k: v for k, v in text.items() if k in ds.coords}).assign(
        {k: v for k, v in text.items() if k not in ds.coords})


def _is_variable_text(dtype) -> bool:
    string_dtype = getattr(np.dtypes, "StringDType", None)  # numpy >= 2 only
    return string_dtype is not None and isinstance(dtype, string_dtype)


@dataclass(frozen=True)
class Output:
    """One result variable of a sweep: a value per grid point."""
    dtype: str = "f8"
    units: str = ""
    long_name: str = ""


def fingerprint(coords: dict, outputs: dict, block_shape, settings,
                computed_by: str | None = None) -> str:
    """What makes two sweeps the same: the grid, the outputs, the chunking, the settings and
    the code that computes them: module ``computed_by`` and its imports, or the whole
    package when it is not named (``provenance.code_hash``)."""
    h = hashlib.sha256(_code(computed_by).encode())
    for name, values in coords.items():
        h.update(name.encode())
        h.update(np.ascontiguousarray(values, dtype=float).tobytes())
    h.update(json.dumps({k: [o.dtype, o.units] for k, o in outputs.items()}).encode())
    h.update(json.dumps(list(map(int, block_shape))).encode())
    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def _code(computed_by: str | None) -> str:
    return code_hash(computed_by) if computed_by else code_hash()


class SweepStore:
    """A zarr store holding one sweep (see the module docstring)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    # -- set-up (client side) -----------------------------------------------------------------
    def prepare(self, coords: dict, outputs: dict[str, Output], block_shape, n_chunks: int, *,
                attrs: dict | None = None, settings=None, fresh: bool = False,
                computed_by: str | None = None) -> set[int]:
        """Create the store, or reopen a matching one; return the ids of finished chunks.
        ``computed_by``: the module whose code computes the results (see ``fingerprint``)."""
        import dask.array as da
        import xarray as xr

        attrs = dict(attrs or {})
        key = fingerprint(coords, outputs, block_shape, settings, computed_by)
        files.refuse_symlink(self.path, "store")
        files.declare(self.path)                    # resumed or made: this run writes it
        if fresh and self.path.exists():
            files.remove_entry(self.path)
        if self.path.exists():
            files.check_tree(self.path)             # nothing inside is written through
            existing = self._read_attrs()
            if existing.get("fingerprint") != key:
                code = _code(computed_by)
                other_code = existing.get("computed_by_sha256") != code
                what = (f"this one was computed by other code (snn-antenna "
                        f"{existing.get('snn_antenna_version', '?')}, "
                        f"{existing.get('computed_by', 'the package')} "
                        f"{existing.get('computed_by_sha256', 'unrecorded')}; this is "
                        f"{code})" if other_code else "this one holds a different sweep")
                raise SpecError("store", str(self.path),
                                "a store written by the same sweep (grid, outputs, chunking, "
                                f"settings and code all unchanged); {what}: pass --fresh to "
                                "start over, or choose another --out")
            return self.done_chunks()
        dims = tuple(coords)
        shape = tuple(len(v) for v in coords.values())
        data_vars = {
            name: (dims, da.zeros(shape, dtype=out.dtype, chunks=tuple(block_shape)),
                   {"units": out.units, "long_name": out.long_name or name})
            for name, out in outputs.items()}
        data_vars[DONE] = (("sweep_chunk",), da.zeros(n_chunks, dtype="u1", chunks=1),
                           {"long_name": "1 once the chunk's results are complete"})
        ds = xr.Dataset(data_vars, coords={name: (name, np.asarray(v)) for name, v in
                                           coords.items()},
                        attrs={**{k: _attr(v) for k, v in attrs.items()}, **code_identity(),
                               "computed_by": computed_by or "the package",
                               "computed_by_sha256": _code(computed_by),
                               "fingerprint": key,
                               "block_shape": list(map(int, block_shape))})
        write_dataset(ds, self.path, compute=False)  # never a half-created store
        files.note(self.path)           # being written chunk by chunk: finished at the run's end
        return set()

    def _read_attrs(self) -> dict:
        import zarr
        try:
            return dict(zarr.open_group(self.path, mode="r").attrs)
        except Exception as exc:  # not a zarr store at all
            raise DamagedStore(self.path, exc, "pass --fresh to replace it") from None

    def done_chunks(self) -> set[int]:
        """The chunks marked done whose data are all on disk. A marked chunk whose data file
        of some output is missing (deleted, lost) is said in one line and computed again."""
        import sys

        import zarr
        try:
            flags = zarr.open_array(self.path / DONE, mode="r")[:]
            root = zarr.open_group(self.path, mode="r")
            block = tuple(root.attrs["block_shape"])
            shapes = {name: (arr.shape, arr.chunks) for name, arr in root.arrays()
                      if name != DONE and tuple(arr.chunks) == block}   # the outputs
        except Exception as exc:
            raise DamagedStore(self.path, exc) from None
        done, lost = set(map(int, np.flatnonzero(flags))), {}
        for name, (shape, chunks) in shapes.items():
            counts = [-(-n // c) for n, c in zip(shape, chunks)]
            for chunk in sorted(done):
                index = np.unravel_index(chunk, counts)
                key = self.path.joinpath(name, "c", *map(str, index))
                if not key.is_file():
                    lost.setdefault(chunk, name)
        if lost:
            print(f"store: {self.path}: {len(lost)} chunk(s) marked done have no data on disk "
                  f"(e.g. chunk {min(lost)} of {lost[min(lost)]!r}); computing them again",
                  file=sys.stderr, flush=True)
        return done - set(lost)

    # -- writing (the sweep's own process) ------------------------------------------------------
    def write_chunk(self, chunk_id: int, region: dict[str, slice], data: dict[str, np.ndarray]):
        """Write one chunk's block of every output, then mark the chunk done."""
        import xarray as xr
        import zarr

        dims = tuple(region)
        ds = xr.Dataset({name: (dims, np.asarray(block)) for name, block in data.items()})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # every chunk written, also one equal to the fill value, so that a done chunk
            # without its file is known to be lost (``done_chunks``)
            ds.to_zarr(self.path, region=dict(region), mode="r+", consolidated=False,
                       write_empty_chunks=True)
        zarr.open_array(self.path / DONE, mode="r+")[chunk_id] = 1

    # -- reading --------------------------------------------------------------------------------
    def load(self):
        """The sweep as an in-memory xarray Dataset (without the bookkeeping array)."""
        ds = read_dataset(self.path)
        ds.attrs = {k: _unattr(v) for k, v in ds.attrs.items()}
        return ds.drop_vars(DONE)


def _attr(value):
    """zarr attributes are JSON: store nested settings as JSON text."""
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, default=str)
    return value


def _unattr(value):
    if isinstance(value, str) and value[:1] in "[{":
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            return value
    return value
