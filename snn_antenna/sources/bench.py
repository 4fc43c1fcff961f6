"""The bench data set: contacts on a stationary antenna, following the paper's protocol.

8 materials × 16 positions (80–360 mm in 20 mm steps, and 375 mm) × 100 repetitions = 12,800
contact events (Patanè et al. 2012, "Materials and methods"). Each event is a short recording
of what the sensor board sends: a little quiet before the impact, then the rod ringing in its
two modes (``antenna.contact_ringing``), projected onto the accelerometer's two axes, with
sensor noise, through the ADC.

The sample rate must hold the high mode: it reaches 10^(0.0305·37.5 + 1.52) ≈ 460 Hz at the
most distal position (more with contact-to-contact scatter), and the sensor model keeps only
modes below 0.45 × the rate, so the default is 2 kHz (the robot's 1 kHz board would lose the
high mode beyond ~30 cm).

Generation is seeded per (material, position) block, so the data are the same whatever the
number of worker processes, and the result is cached on disk under a hash of the spec and of
the generator's source: a changed spec or changed physics makes a new data set.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from collections.abc import Callable, Sequence

import numpy as np
import xarray as xr

from ..core import bounds
from ..core.errors import SpecError, check
from ..core.parallel import parallel_map
from ..core.signals import Recording
from ..core.truth import Event, GroundTruth
from ..core.files import refuse_symlink
from ..core.provenance import code_hash, code_identity
from ..core.spec import check_section
from ..core.store import DamagedStore, short_reason, read_dataset, write_dataset
from . import antenna, contact_models, recorded
from .source import Generated

PAPER_POSITIONS_CM = tuple([float(d) for d in range(8, 37, 2)] + [37.5])


@dataclass
class BenchSpec(Generated):
    """What to generate; every field is a key of ``stimuli/bench.toml``."""
    materials: Sequence[str] = tuple(antenna.MATERIALS)
    positions_cm: Sequence[float] = PAPER_POSITIONS_CM
    repetitions: int = 100
    rate_hz: float = 2000.0
    pre_trigger_s: float = 0.05
    duration_s: float = 1.0
    impact_g: float = 2.0
    sensor_noise_g: float = 0.01
    orientation_deg: float = 30.0
    adc_bits: int = 16
    full_scale_g: float = 10.0
    # The contact mechanism(s) and the factor on their free constant (sources/contact_models.py;
    # chosen by the model-selection study, studies/model_selection.toml).
    physics: str = contact_models.DEFAULT_MECHANISM
    physics_strength: float = 1.0
    seed: int = 0
    n_jobs: int = 1
    cache_dir: str = "out/.cache"

    def __post_init__(self):
        bounds.declared(self)
        self.validate()

    def validate(self) -> None:
        for name in ("rate_hz", "pre_trigger_s", "duration_s", "impact_g", "sensor_noise_g",
                     "orientation_deg", "physics_strength"):
            bounds.number(name, getattr(self, name), -bounds.MAX_AMPLITUDE,
                          bounds.MAX_AMPLITUDE)
        bounds.integer("repetitions", self.repetitions, 1, 100_000)
        bounds.integer("n_jobs", self.n_jobs, 1, 4096)
        bounds.seed("seed", self.seed)
        check(len(self.materials) >= 1 and len(set(self.materials)) == len(self.materials),
              "materials", list(self.materials), "a non-empty list of distinct material names")
        for m in self.materials:
            antenna.check_material(m)
        check(len(self.positions_cm) >= 1, "positions_cm", self.positions_cm,
              "a non-empty list of contact distances (cm)")
        antenna.check_distance(list(self.positions_cm))
        check(isinstance(self.repetitions, int) and 1 <= self.repetitions <= 100_000,
              "repetitions", self.repetitions, "an integer in [1, 100000]")
        f_high = float(antenna.high_mode_hz(max(self.positions_cm)))
        check(np.isfinite(self.rate_hz) and f_high < 0.45 * self.rate_hz, "rate_hz",
              self.rate_hz, f"a sample rate above {f_high / 0.45:.0f} Hz (the high mode of the "
                            f"most distal position rings at {f_high:.0f} Hz; the sensor keeps "
                            f"modes below 0.45 × the rate)")
        check(np.isfinite(self.pre_trigger_s) and 0 <= self.pre_trigger_s < 1, "pre_trigger_s",
              self.pre_trigger_s, "a quiet lead-in in [0, 1) s")
        check(np.isfinite(self.duration_s) and 0.05 <= self.duration_s <= 10, "duration_s",
              self.duration_s, "a ringing duration in [0.05, 10] s")
        check(np.isfinite(self.impact_g) and self.impact_g > 0, "impact_g", self.impact_g,
              "an impact amplitude > 0 g")
        check(np.isfinite(self.sensor_noise_g) and self.sensor_noise_g >= 0, "sensor_noise_g",
              self.sensor_noise_g, "a noise level >= 0 g")
        check(isinstance(self.n_jobs, int) and self.n_jobs >= 1, "n_jobs", self.n_jobs,
              "an integer >= 1 (worker processes)")
        check(isinstance(self.seed, int) and self.seed >= 0, "seed", self.seed, "an integer >= 0")
        antenna.ADC(self.adc_bits, self.full_scale_g)
        _ = self.contact_physics    # names physics or physics_strength when they are bad

    @property
    def contact_physics(self) -> contact_models.ContactPhysics:
        return contact_models.ContactPhysics(self.physics, self.physics_strength)

    @property
    def n_events(self) -> int:
        return len(self.materials) * len(self.positions_cm) * self.repetitions

    @property
    def n_samples(self) -> int:
        return int(round((self.pre_trigger_s + self.duration_s) * self.rate_hz))

    def describe(self) -> str:
        return (f"bench data set: {self.n_events} events at {self.rate_hz:g} Hz, generated "
                f"({len(self.materials)} materials × {len(self.positions_cm)} positions × "
                f"{self.repetitions} repetitions, seed {self.seed})")

    def open_dataset(self, log=print, fresh: bool = False) -> xr.Dataset:
        """The data set, from the cache when it was made before."""
        self.validate()
        path = Path(self.cache_dir) / f"bench-{self.key()}.zarr"
        return cached(path, lambda: generate(self, log), __name__, log, fresh)

    def calibration_repetitions(self, n: int, field: str) -> list[int]:
        """None of its repetitions: a generator makes calibration contacts afresh, with
        another seed, so no evaluated contact is spent on calibration."""
        return []

    def key(self) -> str:
        """Hash of everything that changes the data: the spec (not where or how fast it is
        made) and the source of the generator and of the antenna physics."""
        fields = {k: v for k, v in asdict(self).items() if k not in ("n_jobs", "cache_dir")}
        fields["materials"] = list(fields["materials"])
        fields["positions_cm"] = [float(x) for x in fields["positions_cm"]]
        return cache_key(fields, __name__)


def cache_key(fields: dict, computed_by: str) -> str:
    """Hash of JSON-able ``fields`` and of the code that computes from them: module
    ``computed_by`` (the caller passes its ``__name__``) and every package module it imports
    (``provenance.code_hash``): a cache made by other code is never found."""
    h = hashlib.sha256(json.dumps(fields, sort_keys=True).encode())
    h.update(code_hash(computed_by).encode())
    return h.hexdigest()[:16]


def _generate_block(spec: BenchSpec, mi: int, pi: int) -> np.ndarray:
    """All repetitions of one (material, position): ADC counts (repetitions, samples, 2)."""
    rng = np.random.default_rng(np.random.SeedSequence(spec.seed, spawn_key=(mi, pi)))
    material, d = spec.materials[mi], float(spec.positions_cm[pi])
    adc = antenna.ADC(spec.adc_bits, spec.full_scale_g)
    n, n_pre = spec.n_samples, int(round(spec.pre_trigger_s * spec.rate_hz))
    out = np.empty((spec.repetitions, n, 2), dtype=_counts_dtype(spec.adc_bits))
    physics = spec.contact_physics
    for r in range(spec.repetitions):
        main = np.zeros(n)
        main[n_pre:] = antenna.contact_ringing(d, material, spec.rate_hz, n - n_pre, rng,
                                               spec.impact_g, physics=physics)
        xy = antenna.project(main, spec.orientation_deg)
        xy += rng.standard_normal(xy.shape) * spec.sensor_noise_g
        out[r] = adc.to_counts(xy)
    return out


def _counts_dtype(bits: int):
    return np.uint16 if bits <= 16 else np.int32


def generate(spec: BenchSpec, log=print) -> xr.Dataset:
    """Make the data set (no cache): ``counts`` (event, sample, axis) with labels per event."""
    spec.validate()
    blocks = [(spec, mi, pi) for mi in range(len(spec.materials))
              for pi in range(len(spec.positions_cm))]
    log(f"bench: generating {spec.n_events} contact events ({len(spec.materials)} materials × "
        f"{len(spec.positions_cm)} positions × {spec.repetitions} repetitions) at "
        f"{spec.rate_hz:g} Hz on {spec.n_jobs} process(es)")
    counts = np.concatenate(parallel_map(_generate_block, blocks, spec.n_jobs, "generating"))
    mi, pi, rep = (a.ravel() for a in np.meshgrid(np.arange(len(spec.materials)),
                                                  np.arange(len(spec.positions_cm)),
                                                  np.arange(spec.repetitions), indexing="ij"))
    positions = np.asarray(spec.positions_cm, dtype=float)
    return xr.Dataset(
        {"counts": (("event", "sample", "axis"), counts, {"units": "ADC counts"})},
        coords={"event": np.arange(len(counts)),
                "material": ("event", np.asarray(spec.materials, dtype=str)[mi]),
                "distance_cm": ("event", positions[pi], {"units": "cm"}),
                "position": ("event", pi), "repetition": ("event", rep),
                "axis": ["x", "y"]},
        attrs={"rate_hz": float(spec.rate_hz), "pre_trigger_s": float(spec.pre_trigger_s),
               "adc_bits": int(spec.adc_bits), "full_scale_g": float(spec.full_scale_g),
               "key": spec.key(), "spec": json.dumps(_spec_dict(spec))})


def _spec_dict(spec: BenchSpec) -> dict:
    d = asdict(spec)
    d["materials"], d["positions_cm"] = list(d["materials"]), list(d["positions_cm"])
    return d


def cached(path: Path, build: Callable[[], xr.Dataset], computed_by: str, log=print,
           fresh: bool = False) -> xr.Dataset:
    """Open the zarr store at ``path``, or build the data set and store it there first.

    A store is written under a temporary name and renamed into place, so an interrupted run
    leaves no half store behind to be mistaken for a finished one.
    Caches are disposable: a store that cannot be read back, holds non-finite numbers, or was
    made by other code (module ``computed_by`` and its imports) is rebuilt, and the log says so.
    """
    path = Path(path)
    refuse_symlink(path, "cache")
    if path.exists() and not fresh:
        try:
            ds = read_dataset(path)     # text comes back as plain numpy str
            problem = _cache_problem(ds, computed_by)
        except DamagedStore as exc:
            problem = short_reason(exc.reason)
        if problem is None:
            log(f"cache: reusing {path}")
            return ds
        log(f"cache: {path} is unusable ({problem}); rebuilding it")
    ds = build()
    ds.attrs.update({k: v for k, v in code_identity().items() if v is not None})
    ds.attrs.update({"computed_by": computed_by, "computed_by_sha256": code_hash(computed_by)})
    write_dataset(ds, path.absolute())
    log(f"cache: stored {path}")
    return ds


def _cache_problem(ds: xr.Dataset, computed_by: str) -> str | None:
    if ds.attrs.get("computed_by_sha256") != code_hash(computed_by):
        return (f"made by other code: {computed_by} and its imports were "
                f"{ds.attrs.get('computed_by_sha256', 'unrecorded')}, "
                f"now {code_hash(computed_by)}")
    for name, var in ds.data_vars.items():
        if var.dtype.kind in "fc" and not np.isfinite(var.values).all():
            return f"{name} holds NaN or infinite values"
    return None


def load(source, log=print, fresh: bool = False) -> xr.Dataset:
    """The data set of a bench source (``source.BenchSet``): a ``BenchSpec``'s, generated or
    from the cache; a ``recorded.RecordedBench``'s, as imported."""
    return source.open_dataset(log, fresh)


def event_recording(ds: xr.Dataset, i: int) -> Recording:
    """Event ``i`` of a bench data set as a labelled Recording (ADC counts, two axes)."""
    ev = ds.isel(event=i)
    contact = Event("contact", float(ds.attrs["pre_trigger_s"]),
                    ev.sizes["sample"] / ds.attrs["rate_hz"] - ds.attrs["pre_trigger_s"],
                    float(ev.distance_cm), str(ev.material.values))
    return Recording(np.asarray(ev.counts.values, dtype=np.int32), float(ds.attrs["rate_hz"]),
                     GroundTruth((contact,)), units="counts",
                     meta={"adc_bits": int(ds.attrs["adc_bits"]),
                           "full_scale_g": float(ds.attrs["full_scale_g"])})


def spec_from_table(table: dict, seed: int = 0) -> BenchSpec:
    """Build a BenchSpec from the ``[stimulus]`` table of a study spec (``kind = "bench"``)."""
    table = dict(table)
    kind = table.pop("kind", "bench")
    if kind != "bench":
        raise SpecError("kind", kind, "'bench'")
    check_section({"stimulus": table}, "stimulus", BenchSpec, exclude=["seed"])
    return BenchSpec(seed=seed, **table)


def source_from_spec(spec: dict):
    """The bench contacts a study reads: the imported recordings its top-level ``data`` names
    (``recorded.open_bench``; its ``[stimulus]`` then gives only ``n_jobs`` and ``cache_dir``),
    or the generator's contacts of its ``[stimulus]`` table."""
    seed, table = int(spec.get("seed", 0)), dict(spec.get("stimulus", {}))
    if spec.get("data") is None:
        return spec_from_table(table, seed)
    if not isinstance(spec["data"], str):
        raise SpecError("data", spec["data"], "the path of a folder written by "
                                              "`snn-antenna data import`")
    defaults = BenchSpec()
    return recorded.open_bench(spec["data"], seed, n_jobs=table.get("n_jobs", defaults.n_jobs),
                               cache_dir=table.get("cache_dir", defaults.cache_dir))


__all__ = ["BenchSpec", "generate", "load", "cached", "event_recording", "spec_from_table",
           "source_from_spec",
           "cache_key", "PAPER_POSITIONS_CM"]
